/*
 * JumpGuard: libvstig's jump bound with vstig_hw.gateway.guard.Guard's interface, for a guard whose
 * only policies are max_jump and learn (Guard.jump_only()): the gateway's default.
 *
 * Reference: vstig_hw/gateway/guard.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 *
 * Time: the Python guard keeps float seconds, libvstig whole units. Here a unit is 1/1024 s
 * (GUARD_UNITS): a time that is a whole number of units (the differential test feeds such
 * times) gives exactly the Python guard's answers; any other is floored to its unit, which
 * moves a key's refill by less than max_jump/1024 steps.
 */
#include "guard.h"

#include <math.h>
#include <structmember.h>

static PyObject *Guard_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"max_jump", "learn", NULL};
    long max_jump;
    PyObject *learn_obj = Py_None;
    uint32_t learn = VSTIG_GUARD_NEVER_LEARNT;
    vx_guard_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "l|O", kwlist, &max_jump, &learn_obj)) return NULL;
    if (max_jump < 1 || max_jump > 0x7FFF) {
        PyErr_Format(PyExc_ValueError, "max_jump must be 1..32767 timestamps, got %ld", max_jump);
        return NULL;
    }
    if (learn_obj != Py_None) {
        double seconds = PyFloat_AsDouble(learn_obj);
        if (seconds == -1.0 && PyErr_Occurred()) return NULL;
        if (!(seconds >= 0.0 && seconds < VX_GUARD_MAX_LEARN)) {
            PyErr_Format(PyExc_ValueError, "learn must be 0..%.0f seconds for the compiled guard, got %R",
                         VX_GUARD_MAX_LEARN, learn_obj);
            return NULL;
        }
        learn = (uint32_t)ceil(seconds * VX_GUARD_UNITS);
    }
    self = (vx_guard_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->max_jump = PyLong_FromLong(max_jump);
    self->learn = Py_NewRef(learn_obj);
    self->warnings = PyList_New(0);
    self->policies = PyDict_New();
    self->jump = vx_name("drop_jump");
    if (self->max_jump == NULL || self->warnings == NULL || self->policies == NULL || self->jump == NULL ||
        vstig_guard_init(&self->guard, (uint16_t)max_jump, VX_GUARD_UNITS, learn) != 0) {
        Py_DECREF(self);
        return NULL;
    }
    return (PyObject *)self;
}

static void Guard_dealloc(vx_guard_t *self) {
    Py_XDECREF(self->max_jump);
    Py_XDECREF(self->learn);
    Py_XDECREF(self->warnings);
    Py_XDECREF(self->policies);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

uint32_t vx_guard_units(double now) {
    /* modulo 2^32 (an integer's conversion to uint32_t), as libvstig compares times: wall-clock seconds since
     * 1970 need 41 bits of 1/1024 s */
    return (uint32_t)(int64_t)floor(now * VX_GUARD_UNITS);
}

uint8_t vx_guard_passes(vx_guard_t *self, const vstig_msg_t *msg, uint32_t now) {
    return vstig_guard_check(&self->guard, msg, now) == VSTIG_GUARD_PASS;
}

/* check(link, sender, msg, now, source=None) -> None or "drop_jump" */
static PyObject *Guard_check(vx_guard_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"link", "sender", "msg", "now", "source", NULL};
    PyObject *link, *sender, *msg_obj, *source = Py_None;
    double now;
    vstig_msg_t msg;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOd|O", kwlist, &link, &sender, &msg_obj, &now, &source))
        return NULL;
    if (vx_msg_of(msg_obj, &msg) < 0) return NULL;
    if (vx_guard_passes(self, &msg, vx_guard_units(now))) Py_RETURN_NONE;
    return Py_NewRef(self->jump);
}

/* filter(link, sender, messages, now, counters, source=None) -> the messages that pass */
static PyObject *Guard_filter(vx_guard_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"link", "sender", "messages", "now", "counters", "source", NULL};
    PyObject *link, *sender, *messages, *counters, *source = Py_None, *kept, *seq;
    double now;
    Py_ssize_t i, n, refused = 0;
    uint32_t units;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOdO|O", kwlist, &link, &sender, &messages, &now, &counters,
                                     &source))
        return NULL;
    seq = PySequence_Fast(messages, "messages must be a sequence of Messages");
    if (seq == NULL) return NULL;
    n = PySequence_Fast_GET_SIZE(seq);
    kept = PyList_New(0);
    units = vx_guard_units(now);
    for (i = 0; kept != NULL && i < n; i++) {
        PyObject *item = PySequence_Fast_GET_ITEM(seq, i);
        vstig_msg_t msg;
        if (vx_msg_of(item, &msg) < 0) {
            Py_CLEAR(kept);
        } else if (vx_guard_passes(self, &msg, units)) {
            if (PyList_Append(kept, item) < 0) Py_CLEAR(kept);
        } else {
            refused++;
        }
    }
    Py_DECREF(seq);
    if (kept != NULL && vx_count(counters, self->jump, refused) < 0) Py_CLEAR(kept);
    return kept;
}

static PyObject *Guard_read_only(vx_guard_t *self, PyObject *link) {
    (void)self;
    (void)link;
    Py_RETURN_FALSE; /* a guard with read-only links is not jump-only: the Python guard runs it */
}

static PyObject *Guard_confined_to(vx_guard_t *self, PyObject *msg) {
    (void)self;
    (void)msg;
    Py_RETURN_NONE;
}

/* view(key) -> (timestamp, robot, value) of the newest entry let through, or None (Guard._view.get) */
static PyObject *Guard_view(vx_guard_t *self, PyObject *key_obj) {
    long key = vx_field("key", VSTIG_KEY_MAX, key_obj);
    uint16_t ts, robot, value;
    if (key < 0) return NULL;
    if (!vstig_guard_view(&self->guard, (uint16_t)key, &ts, &robot, &value)) Py_RETURN_NONE;
    return Py_BuildValue("(iii)", (int)ts, (int)robot, (int)value);
}

static PyObject *Guard_get_false(vx_guard_t *self, void *closure) {
    (void)self;
    (void)closure;
    Py_RETURN_FALSE;
}

static PyMethodDef Guard_methods[] = {
    {"check", (PyCFunction)(void (*)(void))Guard_check, METH_VARARGS | METH_KEYWORDS,
     "None if msg passes, else its drop counter name (drop_jump)."},
    {"filter", (PyCFunction)(void (*)(void))Guard_filter, METH_VARARGS | METH_KEYWORDS,
     "The messages that pass; each refused one is counted in counters as drop_jump."},
    {"read_only", (PyCFunction)Guard_read_only, METH_O, NULL},
    {"confined_to", (PyCFunction)Guard_confined_to, METH_O, NULL},
    {"view", (PyCFunction)Guard_view, METH_O, NULL},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Guard_members[] = {
    {"max_jump", T_OBJECT, offsetof(vx_guard_t, max_jump), READONLY, NULL},
    {"learn", T_OBJECT, offsetof(vx_guard_t, learn), READONLY, NULL},
    {"warnings", T_OBJECT, offsetof(vx_guard_t, warnings), READONLY, NULL},
    {"policies", T_OBJECT, offsetof(vx_guard_t, policies), READONLY, NULL},
    {NULL, 0, 0, 0, NULL},
};

static PyGetSetDef Guard_getset[] = {
    {"confines", (getter)Guard_get_false, NULL, "No read-only links.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject vx_JumpGuardType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.JumpGuard",
    .tp_doc = "A guard of max_jump and learn only: libvstig's jump bound with Guard's interface.",
    .tp_basicsize = sizeof(vx_guard_t),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = Guard_new,
    .tp_dealloc = (destructor)Guard_dealloc,
    .tp_methods = Guard_methods,
    .tp_members = Guard_members,
    .tp_getset = Guard_getset,
};
