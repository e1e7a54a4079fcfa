/*
 * ghj_dump - decode a joint-stream capture and print one JSON object per frame,
 * then {"stats": {...}} (with a "config" counter only if that error occurred).
 * Used by the test suite and `make check` to compare the C decoder with the
 * shared vectors (tests/vectors/joint_stream) and with the Python decoder.
 *
 * usage: ghj_dump [-c CHUNK] [-n] FILE|-
 *   -c CHUNK  feed the decoder CHUNK bytes per ghj_feed() call, 1..4096
 *             (default 4096; 1 exercises byte-at-a-time streaming)
 *   -n        counters only: pass out = NULL and result = NULL to ghj_feed()
 *             and print only the stats line
 *
 * Exit status: 0 when the file was read, 2 on a usage or I/O error.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ghjoints.h"

static void print_header(const ghj_header *h)
{
    printf("\"version\":%u,\"flags\":%u,\"seq\":%" PRIu32 ",\"capture_us\":%" PRIu64 ",\"send_us\":%" PRIu64,
           (unsigned)h->version, (unsigned)h->flags, h->seq, h->capture_us, h->send_us);
}

/* Strings from the decoder are printable ASCII; only '"' and '\\' need escaping. */
static void print_string(const char *s)
{
    putchar('"');
    for (; *s; s++) {
        if (*s == '"' || *s == '\\') putchar('\\');
        putchar(*s);
    }
    putchar('"');
}

static void print_packet(const ghj_packet *p)
{
    unsigned i;
    switch (p->header.msg_type) {
    case GHJ_MSG_JOINTS:
        printf("{\"type\":\"JOINTS\",");
        print_header(&p->header);
        printf(",\"joint_set\":%u,\"joints\":[", (unsigned)p->u.joints.joint_set);
        for (i = 0; i < p->u.joints.count; i++) {
            const ghj_joint3d *j = &p->u.joints.joints[i];
            printf("%s[%d,%d,%d,%u,%u]", i ? "," : "", j->x, j->y, j->z, (unsigned)j->conf, (unsigned)j->missing);
        }
        printf("]}\n");
        break;
    case GHJ_MSG_JOINTS_2D:
        printf("{\"type\":\"JOINTS_2D\",");
        print_header(&p->header);
        printf(",\"camera\":%u,\"joint_set\":%u,\"joints\":[", (unsigned)p->u.joints2d.camera,
               (unsigned)p->u.joints2d.joint_set);
        for (i = 0; i < p->u.joints2d.count; i++) {
            const ghj_joint2d *j = &p->u.joints2d.joints[i];
            printf("%s[%d,%d,%u,%u]", i ? "," : "", j->u, j->v, (unsigned)j->conf, (unsigned)j->missing);
        }
        printf("]}\n");
        break;
    case GHJ_MSG_STATUS:
        printf("{\"type\":\"STATUS\",");
        print_header(&p->header);
        printf(",\"fps_centi\":%u,\"latency_us\":%" PRIu32 ",\"dropped\":%" PRIu32 ",\"decimated\":%" PRIu32
               ",\"fault\":%u}\n",
               (unsigned)p->u.status.fps_centi, p->u.status.latency_us, p->u.status.dropped,
               p->u.status.decimated, (unsigned)p->u.status.fault);
        break;
    case GHJ_MSG_HELLO:
        printf("{\"type\":\"HELLO\",");
        print_header(&p->header);
        printf(",\"protocol_version\":%u,\"joint_set\":%u,\"joint_count\":%u,\"units\":%u,\"frame\":%u,\"rig_id\":",
               (unsigned)p->u.hello.protocol_version, (unsigned)p->u.hello.joint_set,
               (unsigned)p->u.hello.joint_count, (unsigned)p->u.hello.units, (unsigned)p->u.hello.frame);
        print_string(p->u.hello.rig_id);
        printf(",\"cameras\":[");
        for (i = 0; i < p->u.hello.n_cameras; i++) {
            if (i) putchar(',');
            print_string(p->u.hello.cameras[i]);
        }
        printf("]}\n");
        break;
    default:
        printf("{\"error\":\"driver: unexpected type %u\"}\n", (unsigned)p->header.msg_type);
        break;
    }
}

static void print_result(ghj_result r, const ghj_packet *p, const ghj_decoder *d)
{
    if (r == GHJ_PACKET) {
        print_packet(p);
    } else if (r == GHJ_SKIPPED) {
        /* *p is untouched on GHJ_SKIPPED; the decoder keeps the skipped type. */
        printf("{\"skipped\":\"unknown\",\"msg_type\":%u}\n", (unsigned)d->skipped_type);
    } else {
        printf("{\"error\":\"%s\"}\n", ghj_result_name(r));
    }
}

int main(int argc, char **argv)
{
    static ghj_decoder dec;
    static ghj_packet pkt;
    static uint8_t buf[4096];
    size_t chunk = sizeof buf, n;
    const char *path = NULL;
    FILE *f;
    int i, counters_only = 0;

    for (i = 1; i < argc; i++) {
        if (strcmp(argv[i], "-c") == 0 && i + 1 < argc) {
            /* A bad CHUNK is a usage error: falling back to 4096 made `-c 0` or `-c 5000` test another chunking
             * than the one asked for, silently. */
            char *end;
            unsigned long v = strtoul(argv[++i], &end, 10);
            if (*argv[i] < '0' || *argv[i] > '9' || *end != '\0' || v == 0 || v > sizeof buf) {
                fprintf(stderr, "ghj_dump: -c %s: CHUNK must be 1..%u\n", argv[i], (unsigned)sizeof buf);
                return 2;
            }
            chunk = (size_t)v;
        } else if (strcmp(argv[i], "-n") == 0) {
            counters_only = 1;
        } else if (path == NULL && (argv[i][0] != '-' || argv[i][1] == '\0')) {
            path = argv[i];
        } else {
            path = NULL; /* an unknown option, a second file or -c without CHUNK */
            break;
        }
    }
    if (!path) {
        fprintf(stderr, "usage: ghj_dump [-c CHUNK] [-n] FILE|-   (CHUNK 1..%u)\n", (unsigned)sizeof buf);
        return 2;
    }
    f = strcmp(path, "-") == 0 ? stdin : fopen(path, "rb");
    if (!f) {
        perror(path);
        return 2;
    }
    ghj_init(&dec);
    while ((n = fread(buf, 1, chunk, f)) > 0) {
        size_t off = 0;
        while (off < n) {
            ghj_result r;
            if (counters_only) {
                off += ghj_feed(&dec, buf + off, n - off, NULL, NULL);
                continue;
            }
            off += ghj_feed(&dec, buf + off, n - off, &r, &pkt);
            if (r != GHJ_NONE) print_result(r, &pkt, &dec);
        }
    }
    if (ferror(f)) {
        perror(path);
        return 2;
    }
    if (f != stdin) fclose(f);
    printf("{\"stats\":{\"frames\":%" PRIu32 ",\"messages\":%" PRIu32 ",\"skipped\":%" PRIu32
           ",\"oversize\":%" PRIu32 ",\"cobs\":%" PRIu32 ",\"short\":%" PRIu32 ",\"crc\":%" PRIu32
           ",\"version\":%" PRIu32 ",\"malformed\":%" PRIu32,
           dec.stats.frames, dec.stats.messages, dec.stats.skipped, dec.stats.err_oversize, dec.stats.err_cobs,
           dec.stats.err_short, dec.stats.err_crc, dec.stats.err_version, dec.stats.err_malformed);
    /* Not a protocol result (the Python decoder has no such counter): shown only when it happened. */
    if (dec.stats.err_config) printf(",\"config\":%" PRIu32, dec.stats.err_config);
    printf("}}\n");
    return 0;
}
