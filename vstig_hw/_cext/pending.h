/* The hot counts a compiled path adds between reads (pending.c): vstig_hw.counters.Counters folds them in first. */
#ifndef VSTIG_EXT_PENDING_H
#define VSTIG_EXT_PENDING_H

#include "ext.h"

/* The counts added once or twice a message; every other name goes straight into the dict (vx_count). */
typedef enum {
    VX_HOT_IN, VX_HOT_OUT, VX_HOT_TX, VX_HOT_TX_BYTES, VX_HOT_RX, VX_HOT_RX_BYTES,
    VX_HOT_NOT_ECHOED, /* an engine's copy kept off the one-domain link it came from: once a message on CAN */
    VX_HOT_NAMES
} vx_hot_t;

typedef struct {
    PyObject_HEAD
    Py_ssize_t count[VX_HOT_NAMES]; /* added since the last fold */
    unsigned inked;                 /* a bit a name the dict holds: a count's first add goes there */
} vx_pending_t;

/* counters.pending, made and set on first use (new reference); NULL and no exception for counters that hold none (a
 * plain dict: counted in straight), NULL with an exception on failure. */
vx_pending_t *vx_pending_of(PyObject *counters);

/* counters[name] += n, held in `pending` (when not NULL) until counters is read. A name's first count goes into the
 * dict, so a dict with counts pending is never empty (json's encoder writes an empty dict without asking it). */
int vx_pending_add(vx_pending_t *pending, PyObject *counters, vx_hot_t name, Py_ssize_t n);

/* holder->counters[NAME] += n, for a holder of `counters` and their `pending` (VX_HOT_T: `tcounters` and `tpending`,
 * a link's transport's). */
#define VX_HOT(holder, NAME, n) vx_pending_add((holder)->pending, (holder)->counters, VX_HOT_##NAME, (n))
#define VX_HOT_T(holder, NAME, n) vx_pending_add((holder)->tpending, (holder)->tcounters, VX_HOT_##NAME, (n))

extern PyTypeObject vx_PendingCountsType;

#endif /* VSTIG_EXT_PENDING_H */
