/*
 * A mavlink link in C: what MavlinkFraming does with a unit (its frames cut by libvstig's byte-at-a-time
 * receiver, each checked, signed ones against the replay table) and the state it sends with (sequence, key,
 * signing timestamps); framing.c's Receiver and Encoder hold these for the data path.
 *
 * Reference: vstig_hw/framing/mavlink.py (held equal by tests/native; the index of the twins:
 *   vstig_hw/_vstig.pyi).
 *
 * The replay table is Signing's: the last timestamp accepted per (sysid, compid, link id), the 1024 streams
 * heard last (a chained hash and a list from the least to the most recently heard), a stream not in it
 * starting at most 60 s behind the newest timestamp accepted.
 */
#include "mavlink.h"

#include <string.h>
#include <time.h>

#define NONE 0xFFFFu

static const char *const DROP_NAMES[VSTIG_MAVLINK_DROP_REASONS] = {
    "noise", "incompat_flags", "crc", "truncated", "mavlink1", "unsigned", "signature", "replay",
    "other_message", "other_payload_type", "not_for_us", "bad_length",
};

/* ---- the replay table ------------------------------------------------------------------ */

static uint32_t bucket_of(uint32_t stream) { return (stream * 2654435761u) >> 21; /* 11 bits: 2048 buckets */ }

static void replay_init(vx_replay_t *r) {
    memset(r, 0, sizeof *r);
    r->oldest = r->newest_entry = NONE;
}

static void unlist(vx_replay_t *r, uint16_t e) {
    if (r->older[e] != NONE) r->newer[r->older[e]] = r->newer[e];
    else r->oldest = r->newer[e];
    if (r->newer[e] != NONE) r->older[r->newer[e]] = r->older[e];
    else r->newest_entry = r->older[e];
}

static void list_newest(vx_replay_t *r, uint16_t e) {
    r->older[e] = r->newest_entry;
    r->newer[e] = NONE;
    if (r->newest_entry != NONE) r->newer[r->newest_entry] = e;
    else r->oldest = e;
    r->newest_entry = e;
}

static void unchain(vx_replay_t *r, uint16_t e) {
    uint16_t *at = &r->bucket[bucket_of(r->stream[e])];
    while (*at != (uint16_t)(e + 1u)) at = &r->chain[*at - 1u];
    *at = r->chain[e];
}

static int find(const vx_replay_t *r, uint32_t stream) {
    uint16_t e = r->bucket[bucket_of(stream)];
    for (; e != 0; e = r->chain[e - 1u])
        if (r->stream[e - 1u] == stream) return e - 1;
    return -1;
}

/* Signing.check's last step: 1 if `stamp` is a replay on `stream`, else 0 and the stamp kept. */
static int replayed(vx_replay_t *r, uint32_t stream, long long stamp) {
    int found = find(r, stream);
    uint16_t e;
    if (stamp <= (found < 0 ? r->newest - VX_NEW_STREAM_WINDOW : r->stamp[found])) return 1;
    if (found >= 0) {
        e = (uint16_t)found;
        unlist(r, e);
    } else {
        if (r->used < VX_STREAMS_KEPT) {
            e = r->used++;
        } else { /* the least recently heard stream is forgotten */
            e = r->oldest;
            unlist(r, e);
            unchain(r, e);
        }
        r->stream[e] = stream;
        r->chain[e] = r->bucket[bucket_of(stream)];
        r->bucket[bucket_of(stream)] = (uint16_t)(e + 1u);
    }
    r->stamp[e] = stamp;
    list_newest(r, e);
    if (stamp > r->newest) r->newest = stamp;
    return 0;
}

/* ---- receiving ------------------------------------------------------------------------- */

static int key_bytes(PyObject *key, uint8_t out[VSTIG_MAVLINK_KEY_SIZE]) {
    Py_buffer data;
    int ok;
    if (PyObject_GetBuffer(key, &data, PyBUF_SIMPLE) < 0) return -1;
    ok = data.len == (Py_ssize_t)VSTIG_MAVLINK_KEY_SIZE;
    if (ok) memcpy(out, data.buf, VSTIG_MAVLINK_KEY_SIZE);
    else PyErr_Format(PyExc_ValueError, "a MAVLink signing key is %d bytes, got %zd", (int)VSTIG_MAVLINK_KEY_SIZE,
                      data.len);
    PyBuffer_Release(&data);
    return ok ? 0 : -1;
}

static int in_range(const char *what, int value, int low) {
    if (value >= low && value <= 255) return 0;
    PyErr_Format(PyExc_ValueError, "mavlink %s must be %d..255, got %d", what, low, value);
    return -1;
}

int vx_mav_rx_init(vx_mav_rx_t *m, int sysid, int compid, PyObject *key) {
    vstig_mavlink_rx_init(&m->rx);
    m->replay = NULL;
    m->keyed = 0;
    if (in_range("sysid", sysid, 1) < 0 || in_range("compid", compid, 1) < 0) return -1;
    m->sysid = (uint8_t)sysid;
    m->compid = (uint8_t)compid;
    if (key == Py_None) return 0;
    if (key_bytes(key, m->key) < 0) return -1;
    if ((m->replay = PyMem_Malloc(sizeof *m->replay)) == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    replay_init(m->replay);
    m->keyed = 1;
    return 0;
}

void vx_mav_rx_free(vx_mav_rx_t *m) {
    PyMem_Free(m->replay);
    m->replay = NULL;
}

/* MavlinkFraming._messages: one whole frame's messages at out, or none and the reason counted. */
static uint8_t frame_messages(vx_mav_rx_t *m, const uint8_t *frame, uint16_t len, vstig_msg_t *out,
                              uint8_t *has_sender, unsigned long long *sender) {
    uint8_t link_id, stamp[6], sysid, compid, n, i;
    long long when = 0;
    if (!vstig_mavlink_check(&m->rx, frame, len, m->keyed ? m->key : NULL)) return 0;
    if (m->keyed) {
        (void)vstig_mavlink_timestamp(frame, len, &link_id, stamp); /* checked: it is signed */
        for (i = 6; i-- > 0;) when = when << 8 | stamp[i];
        if (replayed(m->replay, (uint32_t)frame[5] << 16 | (uint32_t)frame[6] << 8 | link_id, when)) {
            vstig_mavlink_count(&m->rx, VSTIG_MAVLINK_DROP_REPLAY);
            return 0;
        }
    }
    n = vstig_mavlink_messages(&m->rx, frame, m->sysid, m->compid, out, &sysid, &compid);
    if (n && !*has_sender) {
        *has_sender = 1;
        *sender = (unsigned long long)sysid << 8 | compid;
    }
    return n;
}

size_t vx_mav_feed(vx_mav_rx_t *m, const uint8_t *data, size_t len, vstig_msg_t *out, uint8_t *has_sender,
                   unsigned long long *sender) {
    size_t i, n = 0;
    *has_sender = 0;
    if (len <= 0xFFFFu && vstig_mavlink_whole(data, (uint16_t)len)) /* the common unit (MavlinkFraming._frames') */
        return frame_messages(m, data, (uint16_t)len, out, has_sender, sender);
    for (i = 0; i <= len; i++) {
        if (i < len ? !vstig_mavlink_feed(&m->rx, data[i]) : !vstig_mavlink_flush(&m->rx)) continue;
        do n += frame_messages(m, vstig_mavlink_frame(&m->rx), vstig_mavlink_frame_len(&m->rx), out + n, has_sender,
                               sender);
        while (vstig_mavlink_next(&m->rx));
    }
    return n;
}

size_t vx_mav_cut(vstig_mavlink_rx_t *cutter, uint8_t *data, size_t len, uint16_t *unit_len) {
    size_t i, n = 0, at = 0;
    for (i = 0; i <= len; i++) {
        if (i < len ? !vstig_mavlink_feed(cutter, data[i]) : !vstig_mavlink_flush(cutter)) continue;
        do { /* its bytes were all fed (the cutter keeps its own copy): the frames so far end at or before them */
            uint16_t size = vstig_mavlink_frame_len(cutter);
            memmove(data + at, vstig_mavlink_frame(cutter), size);
            unit_len[n++] = size;
            at += size;
        } while (vstig_mavlink_next(cutter));
    }
    return n;
}

/* The reasons counted, each added to counters[prefix + its name], and cleared. */
static int harvest(uint16_t drops[VSTIG_MAVLINK_DROP_REASONS], PyObject *counters, const char *prefix) {
    int reason;
    for (reason = 0; reason < (int)VSTIG_MAVLINK_DROP_REASONS; reason++) {
        uint16_t count = drops[reason];
        char named[64];
        PyObject *name;
        if (count == 0) continue;
        drops[reason] = 0;
        PyOS_snprintf(named, sizeof named, "%s%s", prefix, DROP_NAMES[reason]);
        if ((name = vx_name(named)) == NULL || vx_count(counters, name, count) < 0) return -1;
    }
    return 0;
}

int vx_mav_harvest(vx_mav_rx_t *m, PyObject *drops) { return harvest(m->rx.drops, drops, ""); }

int vx_mav_harvest_device(vstig_mavlink_rx_t *cutter, PyObject *counters) {
    return harvest(cutter->drops, counters, "drop_");
}

/* ---- sending --------------------------------------------------------------------------- */

int vx_mav_tx_init(vx_mav_tx_t *m, int sysid, int compid, int target, PyObject *key, int link_id) {
    if (in_range("sysid", sysid, 1) < 0 || in_range("compid", compid, 1) < 0 || in_range("target", target, 0) < 0 ||
        in_range("link id", link_id, 0) < 0)
        return -1;
    vstig_mavlink_tx_init(&m->tx, (uint8_t)sysid, (uint8_t)compid, NULL);
    m->tx.target_system = (uint8_t)target;
    m->tx.link_id = (uint8_t)link_id;
    if (key == Py_None) return 0;
    if (key_bytes(key, m->key) < 0) return -1;
    m->tx.key = m->key;
    return 0;
}

long long vx_mav_tx_timestamp(const vx_mav_tx_t *m) {
    long long stamp = 0;
    int i;
    for (i = 6; i-- > 0;) stamp = stamp << 8 | m->tx.timestamp[i];
    return stamp;
}

void vx_mav_tx_clock(vx_mav_tx_t *m) {
    struct timespec now;
    long long stamp, last = 0;
    int i;
    if (m->tx.key == NULL || clock_gettime(CLOCK_REALTIME, &now) != 0) return;
    /* signing_timestamp(time.time()): 10 us units since 2015 */
    stamp = ((long long)now.tv_sec - VX_EPOCH_2015) * 100000ll + now.tv_nsec / 10000l;
    last = vx_mav_tx_timestamp(m);
    if (stamp - 1 <= last) return; /* frame_out takes last + 1 */
    for (i = 0; i < 6; i++) m->tx.timestamp[i] = (uint8_t)((stamp - 1) >> (8 * i));
}
