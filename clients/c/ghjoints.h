/*
 * ghjoints.h - decoder for the joint stream (docs/protocol.md), for firmware.
 *
 * C99, no malloc, no stdio, fixed-size buffers. Drop ghjoints.h and ghjoints.c
 * into a firmware project, feed it the bytes you receive (UART, USB CDC, UDP
 * payloads, in any chunking) and get decoded packets back. Garbage, corrupted
 * and truncated frames are reported and skipped; decoding resumes at the next
 * 0x00 delimiter.
 *
 * RAM: one ghj_decoder plus one ghj_packet; docs/c-decoder.md gives their
 * sizes and the commands that measure them. GHJ_MAX_JOINTS (default 64) sets
 * the joint capacity of a ghj_packet. To save RAM define it smaller (e.g. 25)
 * for EVERY file that includes this header, ghjoints.c included (a compiler
 * flag such as -DGHJ_MAX_JOINTS=25, or edit the default below); packets with
 * more joints are then reported as GHJ_ERR_MALFORMED. A ghjoints.c built with
 * a different value than the caller cannot write past the caller's packet:
 * every frame is then reported as GHJ_ERR_CONFIG and nothing is decoded.
 *
 * Example (see docs/c-decoder.md):
 *
 *     static ghj_decoder dec;
 *     static ghj_packet pkt;
 *     static ghj_joints pose;      (a copy: STATUS and HELLO reuse pkt.u)
 *     ghj_init(&dec);
 *     for (;;) {
 *         int c = uart_getc_nonblocking();
 *         if (c < 0) continue;
 *         if (ghj_feed_byte(&dec, (uint8_t)c, &pkt) == GHJ_PACKET
 *             && pkt.header.msg_type == GHJ_MSG_JOINTS) {
 *             pose = pkt.u.joints;  (joints[0 .. pose.count) were sent)
 *             drive_servos(&pose);
 *         }
 *     }
 */
#ifndef GHJOINTS_H
#define GHJOINTS_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define GHJ_PROTOCOL_VERSION 1u
#define GHJ_HEADER_LEN 23u
#define GHJ_CRC_LEN 2u
#define GHJ_MAX_PACKET_LEN 512u /* decoded packet: header + payload + CRC */
#define GHJ_MAX_FRAME_LEN 515u  /* COBS-encoded bytes between delimiters */
#define GHJ_PROTOCOL_MAX_JOINTS 64u /* the protocol's bound on a joint count; GHJ_MAX_JOINTS may be less */
#ifndef GHJ_MAX_JOINTS
#define GHJ_MAX_JOINTS 64u
#endif
#if GHJ_MAX_JOINTS < 1 || GHJ_MAX_JOINTS > GHJ_PROTOCOL_MAX_JOINTS
#error "GHJ_MAX_JOINTS must be 1..64 (the protocol's maximum is 64)"
#endif
#define GHJ_MAX_RIG_ID_LEN 32u
#define GHJ_MAX_CAMERAS 8u
#define GHJ_MAX_CAMERA_NAME_LEN 16u

/* Message types (header byte 1). */
#define GHJ_MSG_HELLO 0x01u
#define GHJ_MSG_STATUS 0x02u
#define GHJ_MSG_JOINTS 0x10u
#define GHJ_MSG_JOINTS_2D 0x11u

/* Header flags (header byte 2; docs/protocol.md, section 3). DECIMATED and DROPPED say why frames are
 * missing before this one. The scene flags say what this frame's estimate is (on its JOINTS and JOINTS_2D);
 * GHJ_FLAG_SEVERAL_PEOPLE says the maps showed two people and the joints are one person's: not that nobody
 * else is near (a second person outside the tracked subject's crop is mostly not flagged). STATUS carries
 * GHJ_FLAG_CALIBRATION_SUSPECT while it lasts; HELLO carries GHJ_SCENE_FLAGS when the sender sets them (an
 * older sender's HELLO has 0: it cannot say), plus GHJ_FLAG_SOMEONE_ELSE (GHJ_ALL_SCENE_FLAGS) only when the
 * sender scans for someone besides its subject: without it a frame's clear bit 6 says nobody looked. Bit 7 is
 * reserved: ignore it. */
#define GHJ_FLAG_DECIMATED 0x01u           /* sender skips frames on purpose to fit the link */
#define GHJ_FLAG_DROPPED 0x02u             /* sender dropped frames since the previous JOINTS */
#define GHJ_FLAG_SEVERAL_PEOPLE 0x04u      /* two people seen: one person's joints only */
#define GHJ_FLAG_PRIOR_FALLBACK 0x08u      /* the skeleton prior disagreed: triangulated joints sent */
#define GHJ_FLAG_SINGLE_VIEW 0x10u         /* one camera only: every 3D joint missing, that camera's 2D */
#define GHJ_FLAG_CALIBRATION_SUSPECT 0x20u /* views disagree or feet left the floor: recalibrate */
#define GHJ_FLAG_SOMEONE_ELSE 0x40u        /* last scan saw someone besides the subject (if HELLO has it) */
#define GHJ_SCENE_FLAGS 0x3Cu              /* SEVERAL_PEOPLE to CALIBRATION_SUSPECT: every HELLO that has any */
#define GHJ_ALL_SCENE_FLAGS 0x7Cu          /* those and SOMEONE_ELSE: the HELLO of a sender that scans */

/* STATUS fault codes. */
#define GHJ_FAULT_OK 0u
#define GHJ_FAULT_RATE_LIMITED 1u
#define GHJ_FAULT_QUEUE_OVERFLOW 2u
#define GHJ_FAULT_LINK_ERRORS 3u
#define GHJ_FAULT_ESTIMATOR_STALLED 4u
#define GHJ_FAULT_CAMERA_FAULT 5u

/* What one call produced. Errors are negative; each frame gives exactly one
 * non-GHJ_NONE result. The checks run in the order listed (docs/protocol.md,
 * section 5), except GHJ_ERR_CONFIG, which is a build error and comes first. */
typedef enum {
    GHJ_NONE = 0,            /* no complete frame yet, or an empty frame */
    GHJ_PACKET = 1,          /* *out holds a decoded message */
    GHJ_SKIPPED = 2,         /* valid packet of a type this decoder does not know; *out untouched */
    GHJ_ERR_OVERSIZE = -1,   /* frame > GHJ_MAX_FRAME_LEN or packet > GHJ_MAX_PACKET_LEN */
    GHJ_ERR_COBS = -2,       /* frame ended inside a COBS block */
    GHJ_ERR_SHORT = -3,      /* shorter than header + CRC */
    GHJ_ERR_CRC = -4,        /* CRC-16/IBM-3740 mismatch */
    GHJ_ERR_VERSION = -5,    /* protocol version other than GHJ_PROTOCOL_VERSION */
    GHJ_ERR_MALFORMED = -6,  /* payload shorter than its fields, or a field out of range */
    GHJ_ERR_CONFIG = -7      /* the caller and ghjoints.c were compiled with different
                              * GHJ_MAX_JOINTS: nothing is decoded (see above) */
} ghj_result;

typedef struct {
    uint8_t version;
    uint8_t msg_type;
    uint8_t flags;
    uint32_t seq;        /* JOINTS, JOINTS_2D: the frame's number (gaps = frames lost); HELLO, STATUS: the
                          * last frame sent, 0xFFFFFFFF before the first (docs/protocol.md, section 3) */
    uint64_t capture_us; /* capture time, sender's monotonic microseconds */
    uint64_t send_us;    /* time the sender wrote the packet, same clock */
} ghj_header;

typedef struct {
    int16_t x, y, z; /* millimetres, rig frame: x right, y down, z forward */
    uint8_t conf;    /* 1..255 when present, 0 when missing */
    uint8_t missing; /* 1 = not estimated (or not sent); x, y, z are 0 */
} ghj_joint3d;

typedef struct {
    int16_t u, v; /* pixels * 4 */
    uint8_t conf;
    uint8_t missing;
} ghj_joint2d;

/* joints[0 .. count) are the packet's joints. The decoder sets every slot from
 * count up to GHJ_MAX_JOINTS to missing (0, 0, 0, conf 0), so an index the
 * sender did not send never holds an older packet's joint; still check count
 * (a BODY_25 sender may send fewer than 25: the protocol only bounds it by 64). */
typedef struct {
    uint8_t joint_set; /* 0 = BODY_25 */
    uint8_t count;
    ghj_joint3d joints[GHJ_MAX_JOINTS];
} ghj_joints;

typedef struct {
    uint8_t camera;
    uint8_t joint_set;
    uint8_t count;
    ghj_joint2d joints[GHJ_MAX_JOINTS]; /* slots from count on: missing, as in ghj_joints */
} ghj_joints2d;

typedef struct {
    uint16_t fps_centi;
    uint32_t latency_us;
    uint32_t dropped;
    uint32_t decimated;
    uint16_t fault;
} ghj_status;

typedef struct {
    uint8_t protocol_version;
    uint8_t joint_set;
    uint8_t joint_count;
    uint8_t units; /* 0 = millimetres */
    uint8_t frame; /* 0 = rig frame */
    char rig_id[GHJ_MAX_RIG_ID_LEN + 1]; /* NUL-terminated printable ASCII */
    uint8_t n_cameras;
    char cameras[GHJ_MAX_CAMERAS][GHJ_MAX_CAMERA_NAME_LEN + 1]; /* NUL-terminated; "" past n_cameras */
} ghj_hello;

/* One decoded message. The payloads share one union: a STATUS or HELLO
 * overwrites the joints of the previous JOINTS. To hold the last good pose,
 * copy pkt.u.joints into a ghj_joints of your own on each JOINTS packet. */
typedef struct {
    ghj_header header;
    union {
        ghj_joints joints;     /* header.msg_type == GHJ_MSG_JOINTS */
        ghj_joints2d joints2d; /* GHJ_MSG_JOINTS_2D */
        ghj_status status;     /* GHJ_MSG_STATUS */
        ghj_hello hello;       /* GHJ_MSG_HELLO */
    } u;
} ghj_packet;

typedef struct {
    uint32_t frames; /* non-empty frames = sum of the counters below */
    uint32_t messages;
    uint32_t skipped;
    uint32_t err_oversize;
    uint32_t err_cobs;
    uint32_t err_short;
    uint32_t err_crc;
    uint32_t err_version;
    uint32_t err_malformed;
    uint32_t err_config;
} ghj_stats;

typedef struct {
    uint8_t buf[GHJ_MAX_FRAME_LEN]; /* decoded bytes of the frame in progress */
    uint16_t enc_len;               /* encoded bytes seen; GHJ_MAX_FRAME_LEN + 1 = too long */
    uint16_t dec_len;
    uint8_t block_left;   /* data bytes left in the current COBS block; 0 = next is a code */
    uint8_t zero_pending; /* previous block implies a 0x00 if more data follows */
    uint8_t skipped_type; /* msg_type of the last GHJ_SKIPPED packet (0 before any) */
    ghj_stats stats;
} ghj_decoder;

/* The wrappers below are static inline (C99, C++); older compilers get the GNU spelling. */
#if defined(__cplusplus) || (defined(__STDC_VERSION__) && __STDC_VERSION__ >= 199901L)
#define GHJ_INLINE static inline
#elif defined(__GNUC__)
#define GHJ_INLINE static __inline__
#else
#define GHJ_INLINE static
#endif

/* Reset the decoder and its counters (also use after a link reconnects). */
void ghj_init(ghj_decoder *d);

/* Feed one received byte. Returns GHJ_NONE while a frame is in progress (and
 * for an empty frame), else that frame's result, counted in d->stats:
 *   GHJ_PACKET        *out holds the message (header.msg_type says which);
 *   GHJ_SKIPPED       unknown type, d->skipped_type holds it; *out untouched;
 *   GHJ_ERR_OVERSIZE, GHJ_ERR_COBS, GHJ_ERR_SHORT, GHJ_ERR_CRC,
 *   GHJ_ERR_VERSION, GHJ_ERR_MALFORMED, GHJ_ERR_CONFIG: *out untouched.
 * So *out is written only on GHJ_PACKET. out may be NULL: frames are then
 * checked and counted (and GHJ_PACKET returned) but nothing is written. */
GHJ_INLINE ghj_result ghj_feed_byte(ghj_decoder *d, uint8_t byte, ghj_packet *out);

/* Feed up to len bytes, stopping after the first byte that ends a non-empty
 * frame. Returns the number of bytes consumed (len if no frame ended; 1..len
 * otherwise); *result is that frame's result as for ghj_feed_byte(), or
 * GHJ_NONE if all bytes were consumed without a frame ending. result and out
 * may be NULL. */
GHJ_INLINE size_t ghj_feed(ghj_decoder *d, const uint8_t *data, size_t len, ghj_result *result,
                          ghj_packet *out);

/* Decode one already COBS-decoded packet (header + payload + CRC) of len
 * bytes. Returns GHJ_PACKET (*out written), GHJ_SKIPPED (the type is
 * packet[1]), GHJ_ERR_OVERSIZE (len > GHJ_MAX_PACKET_LEN), GHJ_ERR_SHORT,
 * GHJ_ERR_CRC, GHJ_ERR_VERSION, GHJ_ERR_MALFORMED or GHJ_ERR_CONFIG; never
 * GHJ_NONE or GHJ_ERR_COBS. Only GHJ_PACKET writes *out; out may be NULL
 * (check only). No decoder is involved, so no counters change. */
GHJ_INLINE ghj_result ghj_parse_packet(const uint8_t *packet, size_t len, ghj_packet *out);

/* What a ghj_packet looks like to the file that includes this header: its
 * size and joint capacity. */
#define GHJ_PACKET_LAYOUT (((uint32_t)sizeof(ghj_packet) << 8) | (uint32_t)GHJ_MAX_JOINTS)

/* The functions behind the three above. layout is GHJ_PACKET_LAYOUT as the
 * caller's file sees it; if it differs from ghjoints.c's own (GHJ_MAX_JOINTS
 * differs between the files) and out is not NULL, every frame gives
 * GHJ_ERR_CONFIG and *out is never written. Call the wrappers, which pass it. */
ghj_result ghj_feed_byte_checked(ghj_decoder *d, uint8_t byte, ghj_packet *out, uint32_t layout);
size_t ghj_feed_checked(ghj_decoder *d, const uint8_t *data, size_t len, ghj_result *result, ghj_packet *out,
                        uint32_t layout);
ghj_result ghj_parse_packet_checked(const uint8_t *packet, size_t len, ghj_packet *out, uint32_t layout);

GHJ_INLINE ghj_result ghj_feed_byte(ghj_decoder *d, uint8_t byte, ghj_packet *out)
{
    return ghj_feed_byte_checked(d, byte, out, GHJ_PACKET_LAYOUT);
}

GHJ_INLINE size_t ghj_feed(ghj_decoder *d, const uint8_t *data, size_t len, ghj_result *result,
                          ghj_packet *out)
{
    return ghj_feed_checked(d, data, len, result, out, GHJ_PACKET_LAYOUT);
}

GHJ_INLINE ghj_result ghj_parse_packet(const uint8_t *packet, size_t len, ghj_packet *out)
{
    return ghj_parse_packet_checked(packet, len, out, GHJ_PACKET_LAYOUT);
}

/* CRC-16/IBM-3740: poly 0x1021, init 0xFFFF, no reflection, no xorout.
 * Start with crc = 0xFFFF; ghj_crc16(0xFFFF, "123456789", 9) == 0x29B1. */
uint16_t ghj_crc16(uint16_t crc, const uint8_t *data, size_t len);

/* "packet", "skipped", "oversize", "cobs", ..., "config"; "none" for GHJ_NONE
 * and "unknown" for a value not in ghj_result (for logs). */
const char *ghj_result_name(ghj_result r);

#ifdef __cplusplus
}
#endif

#endif /* GHJOINTS_H */
