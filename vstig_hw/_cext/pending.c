/*
 * PendingCounts: the hot counts of one Counters (in, out, tx, tx_bytes, rx, rx_bytes, not_echoed), added by the
 * compiled path as C integers and folded into the dict by vstig_hw.counters.Counters before any read of it, so no
 * reader ever sees a count missing. A count into a dict is two lookups and an int object (~480 instructions); here
 * it is one add, and a radio relay makes nine a message.
 *
 * Reference: vstig_hw/counters.py's Counters (the dict every count ends in; the pure path counts there straight).
 */
#include "pending.h"

static PyObject **hot_name(vx_hot_t name) {
    switch (name) {
    case VX_HOT_IN: return &vx_n.in;
    case VX_HOT_OUT: return &vx_n.out;
    case VX_HOT_TX: return &vx_n.tx;
    case VX_HOT_TX_BYTES: return &vx_n.tx_bytes;
    case VX_HOT_RX: return &vx_n.rx;
    case VX_HOT_NOT_ECHOED: return &vx_n.not_echoed;
    case VX_HOT_RX_BYTES:
    default: return &vx_n.rx_bytes;
    }
}

vx_pending_t *vx_pending_of(PyObject *counters) {
    PyObject *pending;
    if (PyDict_CheckExact(counters)) return NULL; /* a plain dict has no reader to fold it */
    pending = PyObject_GetAttr(counters, vx_n.pending);
    if (pending == NULL) {
        if (PyErr_ExceptionMatches(PyExc_AttributeError)) PyErr_Clear(); /* a Counter that is no Counters */
        return NULL;
    }
    if (pending == Py_None) { /* from now on the Counters folds before each read */
        PyObject *kept;
        Py_DECREF(pending);
        pending = PyObject_CallNoArgs((PyObject *)&vx_PendingCountsType);
        kept = pending == NULL ? NULL : PyObject_CallMethodOneArg(counters, vx_n.keep_pending, pending);
        if (kept == NULL) {
            Py_XDECREF(pending);
            return NULL;
        }
        Py_DECREF(kept);
    }
    if (!PyObject_TypeCheck(pending, &vx_PendingCountsType)) {
        PyErr_Format(PyExc_TypeError, "a Counters' pending must be a PendingCounts or None, got %R", pending);
        Py_DECREF(pending);
        return NULL;
    }
    return (vx_pending_t *)pending;
}

int vx_pending_add(vx_pending_t *pending, PyObject *counters, vx_hot_t name, Py_ssize_t n) {
    unsigned bit = 1u << name;
    if (pending == NULL || !(pending->inked & bit) || n < 0 || pending->count[name] > PY_SSIZE_T_MAX - n) {
        if (vx_count(counters, *hot_name(name), n) < 0) return -1;
        if (pending != NULL && n != 0) pending->inked |= bit;
        return 0;
    }
    pending->count[name] += n;
    return 0;
}

/* fold(counters): adds what is pending into counters and clears it. */
static PyObject *PendingCounts_fold(vx_pending_t *self, PyObject *counters) {
    int name;
    if (!PyDict_Check(counters)) return PyErr_Format(PyExc_TypeError, "fold needs a Counters, got %R", counters);
    for (name = 0; name < VX_HOT_NAMES; name++) {
        Py_ssize_t n = self->count[name];
        if (n == 0) continue;
        if (vx_count(counters, *hot_name((vx_hot_t)name), n) < 0) return NULL;
        self->count[name] = 0;
    }
    Py_RETURN_NONE;
}

/* forget(): the dict lost names (del, pop, clear): each name's next count goes into the dict again. */
static PyObject *PendingCounts_forget(vx_pending_t *self, PyObject *Py_UNUSED(ignored)) {
    self->inked = 0;
    Py_RETURN_NONE;
}

/* counts: {name: n} of what is pending now (for tests). */
static PyObject *PendingCounts_counts(vx_pending_t *self, void *Py_UNUSED(closure)) {
    PyObject *counts = PyDict_New();
    int name;
    for (name = 0; counts != NULL && name < VX_HOT_NAMES; name++) {
        PyObject *n;
        if (self->count[name] == 0) continue;
        n = PyLong_FromSsize_t(self->count[name]);
        if (n == NULL || PyDict_SetItem(counts, *hot_name((vx_hot_t)name), n) < 0) Py_CLEAR(counts);
        Py_XDECREF(n);
    }
    return counts;
}

static PyMethodDef PendingCounts_methods[] = {
    {"fold", (PyCFunction)PendingCounts_fold, METH_O, "fold(counters): adds what is pending into counters, clears it."},
    {"forget", (PyCFunction)PendingCounts_forget, METH_NOARGS,
     "forget(): counters lost names; each name's next count goes into the dict again."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef PendingCounts_getset[] = {
    {"counts", (getter)PendingCounts_counts, NULL, "{name: n} pending now", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject vx_PendingCountsType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "vstig_hw._vstig.PendingCounts",
    .tp_basicsize = sizeof(vx_pending_t),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_doc = "PendingCounts(): a Counters' hot counts added by the compiled path, folded in before any read.",
    .tp_new = PyType_GenericNew,
    .tp_methods = PendingCounts_methods,
    .tp_getset = PendingCounts_getset,
};
