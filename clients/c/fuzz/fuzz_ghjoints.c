/*
 * Fuzz harness for ghjoints.c (libFuzzer entry point; also builds as a plain
 * replay program with -DGHJ_FUZZ_STANDALONE for compilers without libFuzzer).
 *
 * Besides "no crash, no sanitizer report", it checks the decoder's contract:
 *   - the result sequence does not depend on how the bytes are chunked
 *     (byte-at-a-time vs. chunks of a size taken from the input);
 *   - every decoded packet is within bounds (count <= GHJ_MAX_JOINTS, missing
 *     is 0/1, strings are NUL-terminated printable ASCII of legal length),
 *     joints beyond count are marked missing with zero fields and a HELLO's
 *     camera names beyond n_cameras are empty; the comparison
 *     covers every decoded field (header, payload, the skipped type);
 *   - the counters add up: frames == messages + skipped + all errors;
 *   - only GHJ_PACKET writes the caller's ghj_packet: an error or GHJ_SKIPPED
 *     leaves it untouched;
 *   - out == NULL (counters only) classifies every frame the same.
 * A violated check calls abort(), which libFuzzer records as a crash.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ghjoints.h"

#define MAX_EVENTS 4096u

static void check(int ok, const char *what)
{
    if (!ok) {
        fprintf(stderr, "contract violated: %s\n", what);
        abort();
    }
}

static uint32_t fnv(uint32_t h, const void *p, size_t n)
{
    const uint8_t *b = (const uint8_t *)p;
    size_t i;
    for (i = 0; i < n; i++) h = (h ^ b[i]) * 16777619u;
    return h;
}

static void check_string(const char *s, size_t max_len)
{
    size_t n = 0;
    while (n <= max_len && s[n] != '\0') {
        check(s[n] >= 0x20 && s[n] <= 0x7E, "string is printable ASCII");
        n++;
    }
    check(n <= max_len, "string length within bounds");
}

#define HASH(h, field) fnv((h), &(field), sizeof(field))

/* Digest of every field a decoder promises (never of padding): all header
 * fields, every payload field, and joints beyond count, which must be missing.
 * skipped_type is the decoder's record of a GHJ_SKIPPED packet's type. */
static uint32_t digest(ghj_result r, const ghj_packet *p, uint8_t skipped_type)
{
    uint32_t h = fnv(2166136261u, &r, sizeof r);
    unsigned i;
    if (r == GHJ_SKIPPED) return HASH(h, skipped_type);
    if (r != GHJ_PACKET) return h;
    h = HASH(h, p->header.version);
    h = HASH(h, p->header.msg_type);
    h = HASH(h, p->header.flags);
    h = HASH(h, p->header.seq);
    h = HASH(h, p->header.capture_us);
    h = HASH(h, p->header.send_us);
    check(p->header.version == GHJ_PROTOCOL_VERSION, "only version 1 decodes");
    switch (p->header.msg_type) {
    case GHJ_MSG_JOINTS:
        check(p->u.joints.count <= GHJ_MAX_JOINTS, "joints count bound");
        h = HASH(h, p->u.joints.joint_set);
        h = HASH(h, p->u.joints.count);
        for (i = 0; i < GHJ_MAX_JOINTS; i++) {
            const ghj_joint3d *j = &p->u.joints.joints[i];
            check(j->missing <= 1u, "missing is 0/1");
            if (i >= p->u.joints.count) {
                check(j->missing == 1u && j->conf == 0u && j->x == 0 && j->y == 0 && j->z == 0,
                      "joints beyond count are missing and zero");
                continue;
            }
            h = HASH(h, j->x);
            h = HASH(h, j->y);
            h = HASH(h, j->z);
            h = HASH(h, j->conf);
            h = HASH(h, j->missing);
        }
        break;
    case GHJ_MSG_JOINTS_2D:
        check(p->u.joints2d.count <= GHJ_MAX_JOINTS, "joints2d count bound");
        h = HASH(h, p->u.joints2d.camera);
        h = HASH(h, p->u.joints2d.joint_set);
        h = HASH(h, p->u.joints2d.count);
        for (i = 0; i < GHJ_MAX_JOINTS; i++) {
            const ghj_joint2d *j = &p->u.joints2d.joints[i];
            check(j->missing <= 1u, "missing is 0/1");
            if (i >= p->u.joints2d.count) {
                check(j->missing == 1u && j->conf == 0u && j->u == 0 && j->v == 0,
                      "2D joints beyond count are missing and zero");
                continue;
            }
            h = HASH(h, j->u);
            h = HASH(h, j->v);
            h = HASH(h, j->conf);
            h = HASH(h, j->missing);
        }
        break;
    case GHJ_MSG_STATUS:
        h = HASH(h, p->u.status.fps_centi);
        h = HASH(h, p->u.status.latency_us);
        h = HASH(h, p->u.status.dropped);
        h = HASH(h, p->u.status.decimated);
        h = HASH(h, p->u.status.fault);
        break;
    case GHJ_MSG_HELLO:
        check(p->u.hello.n_cameras <= GHJ_MAX_CAMERAS, "camera count bound");
        check(p->u.hello.joint_count <= GHJ_PROTOCOL_MAX_JOINTS, "HELLO joint_count bound");
        h = HASH(h, p->u.hello.protocol_version);
        h = HASH(h, p->u.hello.joint_set);
        h = HASH(h, p->u.hello.joint_count);
        h = HASH(h, p->u.hello.units);
        h = HASH(h, p->u.hello.frame);
        h = HASH(h, p->u.hello.n_cameras);
        check_string(p->u.hello.rig_id, GHJ_MAX_RIG_ID_LEN);
        h = fnv(h, p->u.hello.rig_id, strlen(p->u.hello.rig_id) + 1u); /* + NUL: "a","b" != "ab","" */
        for (i = 0; i < p->u.hello.n_cameras; i++) {
            check_string(p->u.hello.cameras[i], GHJ_MAX_CAMERA_NAME_LEN);
            h = fnv(h, p->u.hello.cameras[i], strlen(p->u.hello.cameras[i]) + 1u);
        }
        /* The slots past n_cameras share the union with joints: a caller scanning all of them must find "". */
        for (; i < GHJ_MAX_CAMERAS; i++) {
            check(p->u.hello.cameras[i][0] == '\0', "camera names past n_cameras are empty");
        }
        break;
    default:
        check(0, "GHJ_PACKET only for known types");
    }
    return h;
}

static void check_stats(const ghj_stats *s)
{
    check(s->frames == s->messages + s->skipped + s->err_oversize + s->err_cobs + s->err_short + s->err_crc +
                           s->err_version + s->err_malformed + s->err_config,
          "counters add up");
    check(s->err_config == 0u, "no GHJ_ERR_CONFIG when built with one GHJ_MAX_JOINTS");
}

/* After a result: check what it may have written, against the packet as it was before. */
static void check_written(ghj_result r, const ghj_packet *now, ghj_packet *before)
{
    if (r == GHJ_NONE) return;
    if (r != GHJ_PACKET) check(memcmp(now, before, sizeof *now) == 0, "only GHJ_PACKET writes *out");
    memcpy(before, now, sizeof *now);
}

static uint32_t events_a[MAX_EVENTS];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static ghj_decoder a, b, c;
    static ghj_packet pa, pb, before;
    size_t i, n_a = 0, n_b = 0, chunk, off = 0;

    /* Pass 1: byte at a time. */
    ghj_init(&a);
    memcpy(&before, &pa, sizeof pa);
    for (i = 0; i < size; i++) {
        ghj_result r = ghj_feed_byte(&a, data[i], &pa);
        check_written(r, &pa, &before);
        if (r != GHJ_NONE) {
            uint32_t h = digest(r, &pa, a.skipped_type);
            if (n_a < MAX_EVENTS) events_a[n_a] = h;
            n_a++;
        }
    }
    check_stats(&a.stats);
    check(a.stats.frames == n_a, "one result per frame");

    /* Pass 2: chunks of 1..64 bytes, chosen by the first input byte. */
    chunk = size ? (size_t)(data[0] % 64u) + 1u : 1u;
    ghj_init(&b);
    while (off < size) {
        size_t len = size - off < chunk ? size - off : chunk;
        size_t used_total = 0;
        while (used_total < len) {
            ghj_result r;
            size_t used = ghj_feed(&b, data + off + used_total, len - used_total, &r, &pb);
            check(used >= 1u && used <= len - used_total, "ghj_feed consumes 1..len bytes");
            used_total += used;
            if (r != GHJ_NONE) {
                uint32_t h = digest(r, &pb, b.skipped_type);
                if (n_b < MAX_EVENTS) check(events_a[n_b] == h, "chunking does not change results");
                n_b++;
            }
        }
        off += len;
    }
    check(n_a == n_b, "same number of results");
    check(memcmp(&a.stats, &b.stats, sizeof a.stats) == 0, "same counters");

    /* Pass 2b: counters only (out and result NULL) classify every frame the same. */
    ghj_init(&c);
    for (off = 0; off < size;) off += ghj_feed(&c, data + off, size - off, NULL, NULL);
    check(memcmp(&a.stats, &c.stats, sizeof a.stats) == 0, "out == NULL gives the same counters");
    check(c.skipped_type == a.skipped_type, "out == NULL records the skipped type");

    /* Pass 3: the input as one packet whose CRC is made valid, in a heap buffer of
     * exactly its size: the fuzzer reaches the payload parsers without having to
     * solve CRCs, and AddressSanitizer sees any read past the packet's end (in
     * the passes above such a read would stay inside the decoder's own buffer). */
    if (size >= GHJ_CRC_LEN && size <= GHJ_MAX_PACKET_LEN) {
        uint8_t *pkt = (uint8_t *)malloc(size);
        uint16_t crc;
        ghj_result r;
        check(pkt != NULL, "malloc");
        memcpy(pkt, data, size);
        crc = ghj_crc16(0xFFFFu, pkt, size - GHJ_CRC_LEN);
        pkt[size - 2u] = (uint8_t)(crc & 0xFFu);
        pkt[size - 1u] = (uint8_t)(crc >> 8);
        memcpy(&before, &pa, sizeof pa);
        r = ghj_parse_packet(pkt, size, &pa);
        check_written(r, &pa, &before);
        check(r != GHJ_NONE && r != GHJ_ERR_COBS && r != GHJ_ERR_CONFIG, "ghj_parse_packet's results");
        check(ghj_parse_packet(pkt, size, NULL) == r, "out == NULL gives the same result");
        (void)digest(r, &pa, pkt[1]);
        free(pkt);
    }
    return 0;
}

#ifdef GHJ_FUZZ_STANDALONE
/* Replay files given on the command line (corpus entries, crash reproducers). */
int main(int argc, char **argv)
{
    static uint8_t buf[1u << 20];
    int i;
    for (i = 1; i < argc; i++) {
        FILE *f = fopen(argv[i], "rb");
        size_t n;
        if (!f) {
            perror(argv[i]);
            return 2;
        }
        n = fread(buf, 1, sizeof buf, f);
        fclose(f);
        LLVMFuzzerTestOneInput(buf, n);
    }
    printf("replayed %d inputs, all contracts held\n", argc - 1);
    return 0;
}
#endif
