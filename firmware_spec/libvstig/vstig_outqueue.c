/* vstig_outqueue: one pending message per key, newest wins, PUTs first. See vstig_outqueue.h. */
#include "vstig_outqueue.h"

#define MASK ((uint16_t)(VSTIG_QUEUE - 1u))

int vstig_outqueue_init_sized(vstig_outqueue_t *q, size_t size) {
    uint16_t i;
    if (size != sizeof *q) return VSTIG_ERR_CONFIG;
    for (i = 0; i < VSTIG_QUEUE; i++) {
        q->next[i] = (vstig_qslot_t)(i + 1u < VSTIG_QUEUE ? i + 1u : VSTIG_QNIL);
        q->index[i] = VSTIG_QNIL;
    }
    q->head[0] = q->head[1] = q->tail[0] = q->tail[1] = VSTIG_QNIL;
    q->free = 0;
    q->len = 0;
    q->full = 0;
    return 0;
}

/* The index place holding key's slot, or the free place where it would go; VSTIG_QUEUE when
 * neither exists (every place taken by other keys). Linear probing from key & MASK. */
static uint16_t place_of(const vstig_outqueue_t *q, uint16_t key) {
    uint16_t p = (uint16_t)(key & MASK), n;
    for (n = 0; n < VSTIG_QUEUE; n++, p = (uint16_t)((p + 1u) & MASK)) {
        if (q->index[p] == VSTIG_QNIL || q->msg[q->index[p]].key == key) return p;
    }
    return VSTIG_QUEUE;
}

/* Empties index place p, moving later entries of its probe run back so that every lookup
 * still finds them (backward-shift deletion: no tombstones to accumulate). */
static void unindex(vstig_outqueue_t *q, uint16_t p) {
    uint16_t j = p, home;
    for (;;) {
        q->index[p] = VSTIG_QNIL;
        for (;;) {
            j = (uint16_t)((j + 1u) & MASK);
            if (q->index[j] == VSTIG_QNIL) return;
            home = (uint16_t)(q->msg[q->index[j]].key & MASK);
            /* the entry at j stays when its home lies cyclically in (p, j] */
            if (p <= j ? (p < home && home <= j) : (p < home || home <= j)) continue;
            q->index[p] = q->index[j];
            p = j;
            break;
        }
    }
}

static void append(vstig_outqueue_t *q, uint8_t line, vstig_qslot_t s) {
    q->next[s] = VSTIG_QNIL;
    q->prev[s] = q->tail[line];
    if (q->tail[line] == VSTIG_QNIL) q->head[line] = s;
    else q->next[q->tail[line]] = s;
    q->tail[line] = s;
}

static void unlink_slot(vstig_outqueue_t *q, uint8_t line, vstig_qslot_t s) {
    if (q->prev[s] == VSTIG_QNIL) q->head[line] = q->next[s];
    else q->next[q->prev[s]] = q->next[s];
    if (q->next[s] == VSTIG_QNIL) q->tail[line] = q->prev[s];
    else q->prev[q->next[s]] = q->prev[s];
}

uint8_t vstig_outqueue_push(vstig_outqueue_t *q, const vstig_msg_t *msg) {
    uint16_t p = place_of(q, msg->key);
    uint8_t line = (uint8_t)(msg->op & 1u);
    vstig_qslot_t s;
    if (p < VSTIG_QUEUE && q->index[p] != VSTIG_QNIL) {
        vstig_msg_t *pending = &q->msg[q->index[p]];
        s = q->index[p];
        if (msg->timestamp == pending->timestamp) {
            /* every message queued carries its sender's entry of the moment: the same entry
             * again changes nothing, another one at this timestamp is a conflict's winner */
            if (msg->value == pending->value && msg->robot == pending->robot) return VSTIG_PUSH_KEPT;
        } else if (!vstig_ts_newer(msg->timestamp, pending->timestamp)) {
            return VSTIG_PUSH_KEPT;
        }
        if ((pending->op & 1u) != line) { /* a change of op joins the end of the other line */
            unlink_slot(q, (uint8_t)(pending->op & 1u), s);
            append(q, line, s);
        }
        q->msg[s] = *msg;
        return VSTIG_PUSH_QUEUED;
    }
    if (q->free == VSTIG_QNIL) {
        if (q->full != 0xFFFFFFFFul) q->full++;
        return VSTIG_PUSH_FULL;
    }
    s = q->free;
    q->free = q->next[s];
    q->msg[s] = *msg;
    q->index[p] = s; /* a free slot means a free index place: p < VSTIG_QUEUE */
    append(q, line, s);
    q->len++;
    return VSTIG_PUSH_QUEUED;
}

size_t vstig_outqueue_drain(vstig_outqueue_t *q, vstig_msg_t *out, size_t budget) {
    size_t n = 0;
    uint8_t line;
    vstig_qslot_t s;
    for (line = 0; line < 2; line++) {
        while (n < budget && (s = q->head[line]) != VSTIG_QNIL) {
            out[n++] = q->msg[s];
            unlink_slot(q, line, s);
            unindex(q, place_of(q, q->msg[s].key));
            q->next[s] = q->free;
            q->free = s;
            q->len--;
        }
    }
    return n;
}
