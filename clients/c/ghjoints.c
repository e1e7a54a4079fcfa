/*
 * ghjoints.c - joint-stream decoder (see ghjoints.h and docs/protocol.md).
 *
 * COBS is decoded one byte at a time into d->buf, so no byte is stored twice
 * and the frame never needs to be held encoded. Every index into a buffer is
 * checked against a length first; nothing here allocates. Shifts and
 * arithmetic are done in unsigned types that are wide enough where int has
 * 16 bits (AVR), so nothing relies on int being 32 bits.
 */
#include "ghjoints.h"

#include <string.h>

/* CRC-16/IBM-3740 by nibbles: a 32-byte table instead of 512, 2 lookups per byte.
 * On AVR, const data is copied to SRAM unless it is placed in flash explicitly. */
#if defined(__AVR__)
#include <avr/pgmspace.h>
#define GHJ_FLASH PROGMEM
#define GHJ_TABLE16(t, i) ((uint16_t)pgm_read_word(&(t)[i]))
#else
#define GHJ_FLASH
#define GHJ_TABLE16(t, i) ((t)[i])
#endif

static const uint16_t crc_nibble[16] GHJ_FLASH = {
    0x0000, 0x1021, 0x2042, 0x3063, 0x4084, 0x50A5, 0x60C6, 0x70E7,
    0x8108, 0x9129, 0xA14A, 0xB16B, 0xC18C, 0xD1AD, 0xE1CE, 0xF1EF,
};

uint16_t ghj_crc16(uint16_t crc, const uint8_t *data, size_t len)
{
    size_t i;
    for (i = 0; i < len; i++) {
        unsigned b = data[i];
        /* (unsigned)crc << 4: a uint16_t promotes to int, which overflows on 16-bit int. */
        crc = (uint16_t)(((unsigned)crc << 4) ^ GHJ_TABLE16(crc_nibble, ((unsigned)crc >> 12) ^ (b >> 4)));
        crc = (uint16_t)(((unsigned)crc << 4) ^ GHJ_TABLE16(crc_nibble, ((unsigned)crc >> 12) ^ (b & 0x0Fu)));
    }
    return crc;
}

/* Bytes are widened to unsigned (>= 16 bits) or uint32_t before shifting: shifting
 * a uint8_t promotes it to int, and 0xFF << 8 overflows a 16-bit int. */
static uint16_t rd_u16(const uint8_t *p) { return (uint16_t)((unsigned)p[0] | ((unsigned)p[1] << 8)); }

static int16_t rd_i16(const uint8_t *p)
{
    uint16_t u = rd_u16(p);
    /* Portable two's-complement conversion without implementation-defined casts. */
    return (u & 0x8000u) ? (int16_t)(-(int32_t)(0x10000UL - u)) : (int16_t)u;
}

static uint32_t rd_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static uint64_t rd_u64(const uint8_t *p) { return (uint64_t)rd_u32(p) | ((uint64_t)rd_u32(p + 4) << 32); }

static size_t mask_len(size_t count) { return (count + 7u) / 8u; }

static uint8_t bit(const uint8_t *mask, size_t i)
{
    unsigned byte = mask[i / 8u];
    return (uint8_t)((byte >> (unsigned)(i % 8u)) & 1u);
}

/* Each parser checks the whole payload first and writes *out only when it is
 * valid (out NULL: check only), so an error leaves the caller's packet as it was. */

static ghj_result parse_joints(const uint8_t *p, size_t n, ghj_joints *out)
{
    size_t i, off, count;
    if (n < 2u) return GHJ_ERR_MALFORMED;
    count = p[1];
    if (count > GHJ_PROTOCOL_MAX_JOINTS || count > GHJ_MAX_JOINTS) return GHJ_ERR_MALFORMED;
    off = 2u + mask_len(count);
    if (n < off + 7u * count) return GHJ_ERR_MALFORMED;
    if (!out) return GHJ_PACKET;
    out->joint_set = p[0];
    out->count = (uint8_t)count;
    for (i = 0; i < count; i++) {
        const uint8_t *j = p + off + 7u * i;
        out->joints[i].x = rd_i16(j);
        out->joints[i].y = rd_i16(j + 2);
        out->joints[i].z = rd_i16(j + 4);
        out->joints[i].conf = j[6];
        out->joints[i].missing = bit(p + 2, i);
    }
    for (; i < GHJ_MAX_JOINTS; i++) { /* not sent: missing, never a previous packet's joint */
        out->joints[i].x = 0;
        out->joints[i].y = 0;
        out->joints[i].z = 0;
        out->joints[i].conf = 0u;
        out->joints[i].missing = 1u;
    }
    return GHJ_PACKET;
}

static ghj_result parse_joints2d(const uint8_t *p, size_t n, ghj_joints2d *out)
{
    size_t i, off, count;
    if (n < 3u) return GHJ_ERR_MALFORMED;
    count = p[2];
    if (count > GHJ_PROTOCOL_MAX_JOINTS || count > GHJ_MAX_JOINTS) return GHJ_ERR_MALFORMED;
    off = 3u + mask_len(count);
    if (n < off + 5u * count) return GHJ_ERR_MALFORMED;
    if (!out) return GHJ_PACKET;
    out->camera = p[0];
    out->joint_set = p[1];
    out->count = (uint8_t)count;
    for (i = 0; i < count; i++) {
        const uint8_t *j = p + off + 5u * i;
        out->joints[i].u = rd_i16(j);
        out->joints[i].v = rd_i16(j + 2);
        out->joints[i].conf = j[4];
        out->joints[i].missing = bit(p + 3, i);
    }
    for (; i < GHJ_MAX_JOINTS; i++) {
        out->joints[i].u = 0;
        out->joints[i].v = 0;
        out->joints[i].conf = 0u;
        out->joints[i].missing = 1u;
    }
    return GHJ_PACKET;
}

static ghj_result parse_status(const uint8_t *p, size_t n, ghj_status *out)
{
    if (n < 16u) return GHJ_ERR_MALFORMED;
    if (!out) return GHJ_PACKET;
    out->fps_centi = rd_u16(p);
    out->latency_us = rd_u32(p + 2);
    out->dropped = rd_u32(p + 6);
    out->decimated = rd_u32(p + 10);
    out->fault = rd_u16(p + 14);
    return GHJ_PACKET;
}

/* Checks a length-prefixed printable-ASCII string at p[*off] and copies it to dst
 * (dst NULL: check only); advances *off. */
static int take_ascii(const uint8_t *p, size_t n, size_t *off, size_t max_len, char *dst)
{
    size_t i, len;
    if (*off + 1u > n) return 0;
    len = p[*off];
    if (len > max_len || *off + 1u + len > n) return 0;
    for (i = 0; i < len; i++) {
        uint8_t c = p[*off + 1u + i];
        if (c < 0x20u || c > 0x7Eu) return 0;
        if (dst) dst[i] = (char)c;
    }
    if (dst) dst[len] = '\0';
    *off += 1u + len;
    return 1;
}

/* Walks a HELLO payload: checks it (out NULL), or copies it (out set, payload already checked). */
static int walk_hello(const uint8_t *p, size_t n, ghj_hello *out)
{
    size_t off = 5u, c, cameras;
    if (n < 5u || p[2] > GHJ_PROTOCOL_MAX_JOINTS) return 0;
    if (!take_ascii(p, n, &off, GHJ_MAX_RIG_ID_LEN, out ? out->rig_id : NULL)) return 0;
    if (off + 1u > n || p[off] > GHJ_MAX_CAMERAS) return 0;
    cameras = p[off];
    off += 1u;
    for (c = 0; c < cameras; c++) {
        if (!take_ascii(p, n, &off, GHJ_MAX_CAMERA_NAME_LEN, out ? out->cameras[c] : NULL)) return 0;
    }
    if (out) {
        for (c = cameras; c < GHJ_MAX_CAMERAS; c++) out->cameras[c][0] = '\0'; /* no stale name past n_cameras */
        out->protocol_version = p[0];
        out->joint_set = p[1];
        out->joint_count = p[2];
        out->units = p[3];
        out->frame = p[4];
        out->n_cameras = (uint8_t)cameras;
    }
    return 1;
}

static ghj_result parse_hello(const uint8_t *p, size_t n, ghj_hello *out)
{
    if (!walk_hello(p, n, NULL)) return GHJ_ERR_MALFORMED;
    if (out) walk_hello(p, n, out);
    return GHJ_PACKET;
}

ghj_result ghj_parse_packet_checked(const uint8_t *packet, size_t len, ghj_packet *out, uint32_t layout)
{
    const uint8_t *payload;
    size_t plen;
    ghj_result r;
    if (out && layout != GHJ_PACKET_LAYOUT) return GHJ_ERR_CONFIG; /* GHJ_MAX_JOINTS mismatch */
    if (len > GHJ_MAX_PACKET_LEN) return GHJ_ERR_OVERSIZE;
    if (len < GHJ_HEADER_LEN + GHJ_CRC_LEN) return GHJ_ERR_SHORT;
    if (ghj_crc16(0xFFFFu, packet, len - GHJ_CRC_LEN) != rd_u16(packet + len - GHJ_CRC_LEN)) return GHJ_ERR_CRC;
    if (packet[0] != GHJ_PROTOCOL_VERSION) return GHJ_ERR_VERSION;
    payload = packet + GHJ_HEADER_LEN;
    plen = len - GHJ_HEADER_LEN - GHJ_CRC_LEN;
    switch (packet[1]) {
    case GHJ_MSG_JOINTS: r = parse_joints(payload, plen, out ? &out->u.joints : NULL); break;
    case GHJ_MSG_JOINTS_2D: r = parse_joints2d(payload, plen, out ? &out->u.joints2d : NULL); break;
    case GHJ_MSG_STATUS: r = parse_status(payload, plen, out ? &out->u.status : NULL); break;
    case GHJ_MSG_HELLO: r = parse_hello(payload, plen, out ? &out->u.hello : NULL); break;
    default: return GHJ_SKIPPED; /* the protocol may grow: skip, do not fail; *out untouched */
    }
    if (r == GHJ_PACKET && out) {
        out->header.version = packet[0];
        out->header.msg_type = packet[1];
        out->header.flags = packet[2];
        out->header.seq = rd_u32(packet + 3);
        out->header.capture_us = rd_u64(packet + 7);
        out->header.send_us = rd_u64(packet + 15);
    }
    return r;
}

void ghj_init(ghj_decoder *d)
{
    memset(d, 0, sizeof *d);
}

static void count_result(ghj_stats *s, ghj_result r)
{
    s->frames++;
    switch (r) {
    case GHJ_PACKET: s->messages++; break;
    case GHJ_SKIPPED: s->skipped++; break;
    case GHJ_ERR_OVERSIZE: s->err_oversize++; break;
    case GHJ_ERR_COBS: s->err_cobs++; break;
    case GHJ_ERR_SHORT: s->err_short++; break;
    case GHJ_ERR_CRC: s->err_crc++; break;
    case GHJ_ERR_VERSION: s->err_version++; break;
    case GHJ_ERR_MALFORMED: s->err_malformed++; break;
    case GHJ_ERR_CONFIG: s->err_config++; break;
    case GHJ_NONE: break;
    }
}

static ghj_result end_frame(ghj_decoder *d, ghj_packet *out, uint32_t layout)
{
    ghj_result r;
    if (d->enc_len == 0u) return GHJ_NONE; /* consecutive delimiters: idle or resync */
    if (out && layout != GHJ_PACKET_LAYOUT) {
        r = GHJ_ERR_CONFIG; /* decoding would write past the caller's packet */
    } else if (d->enc_len > GHJ_MAX_FRAME_LEN) {
        r = GHJ_ERR_OVERSIZE;
    } else if (d->block_left != 0u) {
        r = GHJ_ERR_COBS;
    } else if (d->dec_len > GHJ_MAX_PACKET_LEN) {
        r = GHJ_ERR_OVERSIZE;
    } else {
        r = ghj_parse_packet_checked(d->buf, d->dec_len, out, layout);
        if (r == GHJ_SKIPPED) d->skipped_type = d->buf[1];
    }
    count_result(&d->stats, r);
    d->enc_len = 0u;
    d->dec_len = 0u;
    d->block_left = 0u;
    d->zero_pending = 0u;
    return r;
}

ghj_result ghj_feed_byte_checked(ghj_decoder *d, uint8_t byte, ghj_packet *out, uint32_t layout)
{
    if (byte == 0u) return end_frame(d, out, layout);
    if (d->enc_len > GHJ_MAX_FRAME_LEN) return GHJ_NONE; /* already too long: wait for 0x00 */
    d->enc_len++;
    if (d->enc_len > GHJ_MAX_FRAME_LEN) return GHJ_NONE;
    /* dec_len < enc_len <= GHJ_MAX_FRAME_LEN always (the first byte is a code),
     * so the stores below stay inside buf. */
    if (d->block_left == 0u) {
        if (d->zero_pending) d->buf[d->dec_len++] = 0u;
        d->block_left = (uint8_t)(byte - 1u);
        d->zero_pending = (uint8_t)(byte != 0xFFu);
    } else {
        d->buf[d->dec_len++] = byte;
        d->block_left--;
    }
    return GHJ_NONE;
}

size_t ghj_feed_checked(ghj_decoder *d, const uint8_t *data, size_t len, ghj_result *result, ghj_packet *out,
                        uint32_t layout)
{
    size_t i;
    for (i = 0; i < len; i++) {
        ghj_result r = ghj_feed_byte_checked(d, data[i], out, layout);
        if (r != GHJ_NONE) {
            if (result) *result = r;
            return i + 1u;
        }
    }
    if (result) *result = GHJ_NONE;
    return len;
}

const char *ghj_result_name(ghj_result r)
{
    switch (r) {
    case GHJ_NONE: return "none";
    case GHJ_PACKET: return "packet";
    case GHJ_SKIPPED: return "skipped";
    case GHJ_ERR_OVERSIZE: return "oversize";
    case GHJ_ERR_COBS: return "cobs";
    case GHJ_ERR_SHORT: return "short";
    case GHJ_ERR_CRC: return "crc";
    case GHJ_ERR_VERSION: return "version";
    case GHJ_ERR_MALFORMED: return "malformed";
    case GHJ_ERR_CONFIG: return "config";
    }
    return "unknown";
}
