/* A mavlink link's receiving and sending state in C (mavlink.c), over libvstig's vstig_mavlink. */
#ifndef VSTIG_EXT_MAVLINK_H
#define VSTIG_EXT_MAVLINK_H

#include "ext.h"

#define VX_STREAMS_KEPT 1024u              /* = framing.mavlink.STREAMS_KEPT */
#define VX_NEW_STREAM_WINDOW 6000000ll     /* = framing.mavlink.NEW_STREAM_WINDOW: 60 s in 10 us units */
#define VX_EPOCH_2015 1420070400ll         /* = framing.mavlink._EPOCH_2015 */
#define VX_REPLAY_BUCKETS 2048u

/* The last timestamp accepted per (sysid, compid, link id): at most VX_STREAMS_KEPT streams, the least recently
 * heard forgotten first (Signing._heard, a dict kept in the order streams were last heard). */
typedef struct {
    uint32_t stream[VX_STREAMS_KEPT]; /* sysid << 16 | compid << 8 | link id */
    long long stamp[VX_STREAMS_KEPT];
    uint16_t older[VX_STREAMS_KEPT], newer[VX_STREAMS_KEPT], chain[VX_STREAMS_KEPT];
    uint16_t bucket[VX_REPLAY_BUCKETS]; /* entry + 1, 0: none */
    uint16_t used, oldest, newest_entry;
    long long newest; /* the newest timestamp accepted on the link */
} vx_replay_t;

typedef struct {
    vstig_mavlink_rx_t rx;
    uint8_t sysid, compid, keyed;
    uint8_t key[VSTIG_MAVLINK_KEY_SIZE];
    vx_replay_t *replay; /* PyMem, with a key */
} vx_mav_rx_t;

typedef struct {
    vstig_mavlink_tx_t tx;
    uint8_t key[VSTIG_MAVLINK_KEY_SIZE]; /* tx.key points here when signing */
    long long written; /* the newest signing timestamp the link wrote (MavlinkFraming.in_order's mark, once shared) */
} vx_mav_tx_t;

/* 0, or -1 with ValueError naming what is wrong (sysid, compid, key). */
int vx_mav_rx_init(vx_mav_rx_t *m, int sysid, int compid, PyObject *key);
void vx_mav_rx_free(vx_mav_rx_t *m);
/* MavlinkFraming.feed: one unit's frames (it is whole: fed, then flushed), their messages into out (room for
 * len / 8 + 1); *has_sender, *sender: sysid << 8 | compid of the first TUNNEL that carried any. */
size_t vx_mav_feed(vx_mav_rx_t *m, const uint8_t *data, size_t len, vstig_msg_t *out, uint8_t *has_sender,
                   unsigned long long *sender);
/* Adds the reasons counted to the framing's drops; -1 on failure. */
int vx_mav_harvest(vx_mav_rx_t *m, PyObject *drops);
/* A mavlink transport's cutting of one whole datagram (MavlinkStreamReader's feed, then flush): its frames moved to
 * data's start, back to back, their sizes into unit_len (room for len / 8 + 1); how many. */
size_t vx_mav_cut(vstig_mavlink_rx_t *cutter, uint8_t *data, size_t len, uint16_t *unit_len);
/* What the cutting counted (noise, incompat_flags, crc, truncated) added to a transport's counters as
 * drop_<reason>; -1 on failure. */
int vx_mav_harvest_device(vstig_mavlink_rx_t *cutter, PyObject *counters);

/* 0, or -1 with ValueError (sysid, compid, target, link id, key). */
int vx_mav_tx_init(vx_mav_tx_t *m, int sysid, int compid, int target, PyObject *key, int link_id);
/* Signing.next_timestamp's rule before a signed frame: the timestamp goes on from max(last + 1, the clock). */
void vx_mav_tx_clock(vx_mav_tx_t *m);
/* The last signing timestamp the encoder signed with (10 us units since 2015). */
long long vx_mav_tx_timestamp(const vx_mav_tx_t *m);
/* Room for n messages' TUNNELs. */
#define VX_MAV_TX_ROOM(n) ((((n) + VSTIG_MAVLINK_MAX_MESSAGES - 1u) / VSTIG_MAVLINK_MAX_MESSAGES) * \
                           VSTIG_MAVLINK_FRAME_MAX)

#endif /* VSTIG_EXT_MAVLINK_H */
