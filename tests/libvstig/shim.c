/* What the tests' ctypes layer needs beside libvstig's API: the structures' sizes as this build
 * has them, and the counters that C callers read as fields. */
#include "vstig.h"

size_t shim_sizeof_engine(void) { return sizeof(vstig_engine_t); }
size_t shim_sizeof_outqueue(void) { return sizeof(vstig_outqueue_t); }
size_t shim_sizeof_guard(void) { return sizeof(vstig_guard_t); }
size_t shim_sizeof_can(void) { return sizeof(vstig_can_t); }
size_t shim_sizeof_can_frame(void) { return sizeof(vstig_can_frame_t); }
size_t shim_sizeof_serial_rx(void) { return sizeof(vstig_serial_rx_t); }
size_t shim_sizeof_epuck4(void) { return sizeof(vstig_epuck4_reassembler_t); }
uint32_t shim_keys(void) { return VSTIG_KEYS; }

uint32_t shim_engine_count(const vstig_engine_t *e, unsigned outcome) { return e->counts[outcome]; }
uint16_t shim_engine_size(const vstig_engine_t *e) { return e->size; }
uint16_t shim_engine_pending(const vstig_engine_t *e) { return e->out.len; }
uint32_t shim_engine_queue_full(const vstig_engine_t *e) { return e->out.full; }
uint16_t shim_queue_len(const vstig_outqueue_t *q) { return q->len; }
uint32_t shim_queue_full(const vstig_outqueue_t *q) { return q->full; }
uint32_t shim_guard_full(const vstig_guard_t *g) { return g->full; }
const vstig_drops_t *shim_can_drops(const vstig_can_t *c) { return &c->drops; }
const vstig_drops_t *shim_serial_drops(const vstig_serial_rx_t *rx) { return &rx->deframer.drops; }
const vstig_drops_t *shim_epuck4_drops(const vstig_epuck4_reassembler_t *r) { return &r->drops; }

/* Every (key, entry) of the table, in place order; returns how many (out: room for VSTIG_KEYS). */
uint16_t shim_engine_entries(const vstig_engine_t *e, uint16_t *keys, vstig_entry_t *entries) {
    uint16_t place, n = 0;
    for (place = 0; place < VSTIG_KEYS; place++)
        if (vstig_engine_at(e, place, &keys[n], &entries[n])) n++;
    return n;
}
