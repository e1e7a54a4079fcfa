/*
 * Test driver for tests/clients/test_c_contracts.py: decodes a stream from
 * stdin byte by byte and prints, per frame, one JSON line with what the
 * contract in ghjoints.h promises about the caller's ghj_packet:
 *   {"result":"packet","type":16,"count":3,"tail_missing":1,"j0x":-5}
 *   {"result":"skipped","skipped_type":127,"untouched":1}
 *   {"result":"crc","untouched":1}
 * tail_missing: every slot from count to GHJ_MAX_JOINTS is missing with zero
 * fields (HELLO: every camera name past n_cameras is empty); untouched: the packet is byte-for-byte as before the frame.
 */
#include <stdio.h>
#include <string.h>

#include "ghjoints.h"

static int tail_missing(const ghj_packet *p)
{
    unsigned i;
    if (p->header.msg_type == GHJ_MSG_JOINTS) {
        for (i = p->u.joints.count; i < GHJ_MAX_JOINTS; i++) {
            const ghj_joint3d *j = &p->u.joints.joints[i];
            if (!(j->missing == 1u && j->conf == 0u && j->x == 0 && j->y == 0 && j->z == 0)) return 0;
        }
    } else if (p->header.msg_type == GHJ_MSG_JOINTS_2D) {
        for (i = p->u.joints2d.count; i < GHJ_MAX_JOINTS; i++) {
            const ghj_joint2d *j = &p->u.joints2d.joints[i];
            if (!(j->missing == 1u && j->conf == 0u && j->u == 0 && j->v == 0)) return 0;
        }
    } else if (p->header.msg_type == GHJ_MSG_HELLO) {
        for (i = p->u.hello.n_cameras; i < GHJ_MAX_CAMERAS; i++) {
            if (p->u.hello.cameras[i][0] != '\0') return 0;
        }
    }
    return 1;
}

int main(void)
{
    static ghj_decoder dec;
    static ghj_packet pkt, before;
    int c;
    /* Fill the packet with a pattern that no decode produces by accident. */
    memset(&pkt, 0xA5, sizeof pkt);
    ghj_init(&dec);
    while ((c = getchar()) != EOF) {
        ghj_result r;
        memcpy(&before, &pkt, sizeof pkt);
        r = ghj_feed_byte(&dec, (uint8_t)c, &pkt);
        if (r == GHJ_NONE) continue;
        printf("{\"result\":\"%s\"", ghj_result_name(r));
        if (r == GHJ_PACKET) {
            printf(",\"type\":%u", (unsigned)pkt.header.msg_type);
            if (pkt.header.msg_type == GHJ_MSG_JOINTS) {
                printf(",\"count\":%u,\"tail_missing\":%d,\"j0x\":%d", (unsigned)pkt.u.joints.count,
                       tail_missing(&pkt), pkt.u.joints.count ? pkt.u.joints.joints[0].x : 0);
            } else if (pkt.header.msg_type == GHJ_MSG_JOINTS_2D) {
                printf(",\"count\":%u,\"tail_missing\":%d", (unsigned)pkt.u.joints2d.count, tail_missing(&pkt));
            } else if (pkt.header.msg_type == GHJ_MSG_HELLO) {
                printf(",\"count\":%u,\"tail_missing\":%d", (unsigned)pkt.u.hello.n_cameras, tail_missing(&pkt));
            }
        } else {
            if (r == GHJ_SKIPPED) printf(",\"skipped_type\":%u", (unsigned)dec.skipped_type);
            printf(",\"untouched\":%d", memcmp(&pkt, &before, sizeof pkt) == 0);
        }
        printf("}\n");
    }
    return 0;
}
