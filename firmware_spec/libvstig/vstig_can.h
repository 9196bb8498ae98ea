/*
 * vstig_can: the CAN ID scheme and payloads (SPEC.md 6.5), classic frames and CAN FD batches.
 *
 *   11-bit:  id = base | op << 8  | sender                  base in {0x000, 0x200, 0x400, 0x600}
 *   29-bit:  id = base | stigmergy << 17 | op << 16 | sender  base in bits 28..25 only
 *
 * A frame here is plain data: the caller's CAN driver moves it. Part of libvstig.
 */
#ifndef VSTIG_CAN_H
#define VSTIG_CAN_H

#include "vstig_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

#define VSTIG_CAN_DEFAULT_BASE 0xFFFFFFFFul /* base: 0x600 on 11 bits, 0x18000000 on 29 */
#define VSTIG_CAN_FD_MAX 64u                /* data bytes of the largest frame: 8 messages */

typedef struct {
    uint32_t id;
    uint8_t extended; /* IDE: 29-bit ID */
    uint8_t fd;       /* a CAN FD frame */
    uint8_t brs;      /* FD bit-rate switch */
    uint8_t rtr;      /* a remote frame */
    uint8_t error;    /* an error frame */
    uint8_t len;      /* data bytes */
    uint8_t data[VSTIG_CAN_FD_MAX];
} vstig_can_frame_t;

typedef struct {
    uint32_t match_mask, match_value; /* the acceptance filter of SPEC.md 6.5.4 */
    uint32_t ids[2];                  /* the IDs this node sends PUTs [0] and GETs [1] under */
    uint16_t sender_mask;
    uint8_t extended, op_shift, fd, brs;
    vstig_drops_t drops;
} vstig_can_t;

/* One scheme (width, base, stigmergy) and this node's id (0 for a node that only listens);
 * fd: send CAN FD batches (brs: with bit-rate switch). 0, or VSTIG_ERR_ARG for a base not
 * allowed on the width, a stigmergy on 11 bits (or above 255), or a sender above 255 (11
 * bits: never truncated, SPEC.md 6.5.2). */
int vstig_can_init(vstig_can_t *c, uint8_t extended, uint32_t base, uint8_t stigmergy, uint16_t sender,
                   uint8_t fd, uint8_t brs);
/* The ID `sender` sends `op` messages under in this scheme: 1 and *id, or 0 (sender out of range). */
uint8_t vstig_can_id(const vstig_can_t *c, uint8_t op, uint16_t sender, uint32_t *id);
/* Receive one frame (SPEC.md 6.5.6): its messages into out (up to 8), the sender from its ID
 * into *sender; returns how many. Drops are counted in c->drops. */
size_t vstig_can_receive(vstig_can_t *c, const vstig_can_frame_t *frame, vstig_msg_t out[8], uint16_t *sender);
/* Frames carrying n messages, into frames (room for n): one classic frame each, in order; or
 * FD frames packed as full as the allowed sizes permit, PUTs first. Returns how many frames. */
size_t vstig_can_encode(const vstig_can_t *c, const vstig_msg_t *msgs, size_t n, vstig_can_frame_t *frames);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_CAN_H */
