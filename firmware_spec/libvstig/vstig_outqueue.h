/*
 * vstig_outqueue: the outgoing queue of SPEC.md section 5. At most one pending message
 * per key; a newer one replaces it, and so does one of the same timestamp carrying
 * another entry (a conflict's winner replaces its loser); a replacement of the same op
 * keeps its place in line. Drained PUTs first, then GETs, each oldest first.
 *
 * An engine keeps one; a gateway can keep one more per link, fed from the engine's
 * drains (the same rule then drops a loser still waiting for bandwidth). Part of libvstig.
 */
#ifndef VSTIG_OUTQUEUE_H
#define VSTIG_OUTQUEUE_H

#include "vstig_wire.h"

#ifdef __cplusplus
extern "C" {
#endif

#if VSTIG_QUEUE <= 128u
typedef uint8_t vstig_qslot_t; /* a slot number: one byte where it fits (small robots) */
#define VSTIG_QNIL 0xFFu
#else
typedef uint16_t vstig_qslot_t;
#define VSTIG_QNIL 0xFFFFu
#endif

typedef struct {
    vstig_msg_t msg[VSTIG_QUEUE];
    vstig_qslot_t next[VSTIG_QUEUE];  /* the next slot in its line (or in the free list) */
    vstig_qslot_t prev[VSTIG_QUEUE];  /* the previous slot in its line */
    vstig_qslot_t index[VSTIG_QUEUE]; /* open addressing by key: each pending key's slot, VSTIG_QNIL free */
    vstig_qslot_t head[2], tail[2];   /* the PUT line [0] and the GET line [1], oldest first */
    vstig_qslot_t free;               /* the first free slot */
    uint16_t len;                     /* messages pending */
    uint32_t full;                    /* messages refused because every slot was taken */
} vstig_outqueue_t;

/* What vstig_outqueue_push did with a message. */
#define VSTIG_PUSH_KEPT 0u   /* a message at least as new for its key is pending: that one stays */
#define VSTIG_PUSH_QUEUED 1u /* queued, or replaced the pending one */
#define VSTIG_PUSH_FULL 2u   /* no slot left: refused and counted in `full` */

/* 0, or VSTIG_ERR_CONFIG when the caller was built with another VSTIG_QUEUE than the library. */
#define vstig_outqueue_init(q) vstig_outqueue_init_sized((q), sizeof *(q))
int vstig_outqueue_init_sized(vstig_outqueue_t *q, size_t size);
uint8_t vstig_outqueue_push(vstig_outqueue_t *q, const vstig_msg_t *msg);
/* Up to `budget` messages into out (room for budget), PUTs first, each line oldest first. */
size_t vstig_outqueue_drain(vstig_outqueue_t *q, vstig_msg_t *out, size_t budget);

#ifdef __cplusplus
}
#endif

#endif /* VSTIG_OUTQUEUE_H */
