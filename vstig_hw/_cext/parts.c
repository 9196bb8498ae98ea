/*
 * Seat and Relay: vstig_hw.gateway.parts' Seat and RawRelay in C, what a Node does with the messages its links
 * heard: judge them with the engine and put its outbox on every outlet, or queue each on every other outlet.
 * The same rules, in the same order; the outlets are Outlets (outlet.c), the engine an Engine (engine.c).
 *
 * Reference: vstig_hw/gateway/parts.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 *
 * The guard is a JumpGuard (no read-only links: nothing confined) or a Python Guard, asked through its own
 * methods (read_only, confines, confined_to) as the Python parts ask it.
 */
#include "parts.h"

#include <string.h>
#include <structmember.h>

#define VX_INTAKE_BURST_TICKS 10 /* parts.INTAKE_BURST_TICKS: a quiet source may give this many periods at once */

/* ---- shared ----------------------------------------------------------------------------- */

static int outlets_of(PyObject *outlets) {
    Py_ssize_t i;
    if (!PyList_Check(outlets)) {
        PyErr_SetString(PyExc_TypeError, "outlets must be a list of Outlets");
        return -1;
    }
    for (i = 0; i < PyList_GET_SIZE(outlets); i++) {
        if (!PyObject_TypeCheck(PyList_GET_ITEM(outlets, i), &vx_OutletType)) {
            PyErr_SetString(PyExc_TypeError, "outlets must be a list of Outlets");
            return -1;
        }
    }
    return 0;
}

#define OUTLET(list, i) ((vx_outlet_t *)PyList_GET_ITEM((list), (i)))

static int is_python_guard(PyObject *guard) { return guard != Py_None && !PyObject_TypeCheck(guard, &vx_JumpGuardType); }

/* ---- Relay ------------------------------------------------------------------------------ */

int vx_relay_take(vx_relay_t *r, Py_ssize_t index, const vstig_msg_t *msgs, size_t n, PyObject *sub) {
    Py_ssize_t i;
    if (r->guard_is_python) { /* heard, never passed on, from a read-only link */
        PyObject *read_only = PyObject_CallMethodOneArg(r->guard, vx_n.read_only, PyList_GET_ITEM(r->names, index));
        int yes = read_only == NULL ? -1 : PyObject_IsTrue(read_only);
        Py_XDECREF(read_only);
        if (yes) return yes < 0 ? -1 : 0;
    }
    for (i = 0; i < PyList_GET_SIZE(r->outlets); i++) {
        if (i != index && vx_outlet_push(OUTLET(r->outlets, i), msgs, n, (long)index, sub) < 0) return -1;
    }
    return 0;
}

static PyObject *Relay_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"outlets", "guard", NULL};
    PyObject *outlets, *guard;
    vx_relay_t *self;
    Py_ssize_t i;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OO", kwlist, &outlets, &guard) || outlets_of(outlets) < 0)
        return NULL;
    self = (vx_relay_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->outlets = Py_NewRef(outlets);
    self->guard = Py_NewRef(guard);
    self->guard_is_python = is_python_guard(guard);
    self->names = PyList_New(PyList_GET_SIZE(outlets));
    for (i = 0; self->names != NULL && i < PyList_GET_SIZE(outlets); i++) {
        PyObject *name = PyObject_GetAttr(OUTLET(outlets, i)->link, vx_n.name);
        if (name == NULL) {
            Py_DECREF(self);
            return NULL;
        }
        PyList_SET_ITEM(self->names, i, name);
    }
    if (self->names == NULL) Py_CLEAR(self);
    return (PyObject *)self;
}

static int Relay_traverse(vx_relay_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->outlets);
    Py_VISIT(self->guard);
    Py_VISIT(self->names);
    return 0;
}

static int Relay_clear(vx_relay_t *self) {
    Py_CLEAR(self->outlets);
    Py_CLEAR(self->guard);
    Py_CLEAR(self->names);
    return 0;
}

static void Relay_dealloc(vx_relay_t *self) {
    PyObject_GC_UnTrack(self);
    Relay_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

extern vstig_msg_t *vx_msgs_of(PyObject *messages, size_t *n);

static PyObject *Relay_take(vx_relay_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"index", "messages", "sender", "sub", NULL};
    PyObject *messages, *sender, *sub = Py_None;
    Py_ssize_t index;
    size_t n;
    vstig_msg_t *msgs;
    int status;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "nOO|O", kwlist, &index, &messages, &sender, &sub)) return NULL;
    if (index < 0 || index >= PyList_GET_SIZE(self->outlets)) return PyErr_Format(PyExc_IndexError, "no link %zd",
                                                                                   index);
    if ((msgs = vx_msgs_of(messages, &n)) == NULL) return NULL;
    status = vx_relay_take(self, index, msgs, n, sub);
    PyMem_Free(msgs);
    if (status < 0) return NULL;
    Py_RETURN_NONE;
}

static PyObject *nothing(PyObject *self, PyObject *unused) {
    (void)self;
    (void)unused;
    Py_RETURN_NONE;
}

static PyMethodDef Relay_methods[] = {
    {"take", (PyCFunction)(void (*)(void))Relay_take, METH_VARARGS | METH_KEYWORDS,
     "Queue what link `index` heard on every other link's outlet."},
    {"queue_out", nothing, METH_NOARGS, "Nothing of its own to send."},
    {"tick", nothing, METH_NOARGS, "Nothing counted per tick."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Relay_members[] = {
    {"guard", T_OBJECT, offsetof(vx_relay_t, guard), READONLY, NULL},
    {NULL, 0, 0, 0, NULL},
};

PyTypeObject vx_RelayType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Relay",
    .tp_doc = "Relay(outlets, guard): RawRelay in C.",
    .tp_basicsize = sizeof(vx_relay_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = Relay_new,
    .tp_dealloc = (destructor)Relay_dealloc,
    .tp_traverse = (traverseproc)Relay_traverse,
    .tp_clear = (inquiry)Relay_clear,
    .tp_methods = Relay_methods,
    .tp_members = Relay_members,
};

/* ---- Seat: the one-domain notes --------------------------------------------------------- */

#define NOT_NOTED (-1)
#define UNNOTED (-2) /* listed in `noted`, its note gone */

static void note(vx_seat_t *s, const vstig_msg_t *msg, Py_ssize_t index) {
    uint16_t key = msg->key;
    if (s->note_link[key] == NOT_NOTED) s->noted[s->nnoted++] = key;
    s->note_link[key] = (int16_t)index;
    s->note_msg[key] = *msg;
}

static int has_notes(const vx_seat_t *s) {
    size_t i;
    for (i = 0; i < s->nnoted; i++) {
        if (s->note_link[s->noted[i]] >= 0) return 1;
    }
    return 0;
}

static void forget_notes(vx_seat_t *s) {
    size_t i;
    for (i = 0; i < s->nnoted; i++) s->note_link[s->noted[i]] = NOT_NOTED;
    s->nnoted = 0;
}

/* Seat._origins: per message, the one-domain link it was heard on (-1: none); the notes are forgotten. A note
 * holds the PUT stored as heard; the outbox hands that very PUT back unless a message for the key replaced it,
 * and a replacement always carries another entry (the out-queue keeps the pending message on the same entry). */
static void origins(vx_seat_t *s, const vstig_msg_t *out, size_t n, int16_t *origin) {
    size_t i;
    for (i = 0; i < n; i++) {
        const vstig_msg_t *m = &out[i], *noted = &s->note_msg[m->key];
        int16_t link = s->note_link[m->key];
        origin[i] = (int16_t)(m->op == VSTIG_PUT && link >= 0 && noted->value == m->value &&
                                      noted->timestamp == m->timestamp && noted->robot == m->robot
                                  ? link
                                  : -1);
    }
    forget_notes(s);
}

/* ---- Seat: what links heard ---------------------------------------------------------------- */

static int one_domain(vx_seat_t *s, Py_ssize_t index) {
    return PyList_GET_SIZE(s->outlets) && PyList_GET_ITEM(s->one_domain, index) == Py_True;
}

/* Receive, noting each PUT stored from a one-domain link (Seat._receive_from_domain when `domain`). */
static int receive(vx_seat_t *s, Py_ssize_t index, const vstig_msg_t *msgs, size_t n, int domain) {
    size_t i;
    for (i = 0; i < n; i++) {
        vstig_outcome_t outcome = vx_engine_receive(s->engine, &msgs[i]);
        if (vx_engine_raise(s->engine, outcome) < 0) return -1;
        if (!domain) continue;
        if (outcome == VSTIG_STORED && msgs[i].op == VSTIG_PUT) {
            note(s, &msgs[i], index);
        } else if (outcome == VSTIG_ANSWERED && s->note_link[msgs[i].key] == index) {
            s->note_link[msgs[i].key] = UNNOTED; /* the answer may be that very entry, merged into the re-broadcast */
        }
    }
    return 0;
}

static int caused_by(vx_seat_t *s, long link, PyObject *sub) {
    int same = link == s->source_link &&
               (sub == s->source_sub || PyObject_RichCompareBool(sub, s->source_sub, Py_EQ) == 1);
    if (PyErr_Occurred()) return -1;
    if (same) return 0;
    if (s->engine->engine.out.len && vx_seat_queue_out(s) < 0) return -1;
    s->source_link = link;
    Py_INCREF(sub);
    Py_SETREF(s->source_sub, sub);
    return 0;
}

/* Seat._tell: the change listeners hear of key's entry if it changed since `old` (NULL: none). */
static int tell(vx_seat_t *s, uint16_t key, const vstig_entry_t *old, PyObject *link_name, PyObject *sender) {
    vstig_entry_t now;
    PyObject *old_obj, *new_obj, *key_obj, *listeners;
    Py_ssize_t i;
    int status = 0;
    if (!vstig_engine_entry(&s->engine->engine, key, &now)) return 0;
    if (old != NULL && old->value == now.value && old->timestamp == now.timestamp && old->robot == now.robot) return 0;
    old_obj = old == NULL ? Py_NewRef(Py_None) : vx_entry(old);
    new_obj = vx_entry(&now);
    key_obj = PyLong_FromLong(key);
    listeners = PySequence_Fast(s->on_change, "on_change must be a sequence of listeners");
    if (old_obj == NULL || new_obj == NULL || key_obj == NULL || listeners == NULL) status = -1;
    for (i = 0; status == 0 && i < PySequence_Fast_GET_SIZE(listeners); i++) {
        PyObject *done = PyObject_CallFunctionObjArgs(PySequence_Fast_GET_ITEM(listeners, i), key_obj, old_obj,
                                                      new_obj, link_name, sender, NULL);
        if (done == NULL) status = -1;
        Py_XDECREF(done);
    }
    Py_XDECREF(old_obj);
    Py_XDECREF(new_obj);
    Py_XDECREF(key_obj);
    Py_XDECREF(listeners);
    return status;
}

/* Seat._receive_telling: one message at a time, telling on_change of every entry that changed. */
static int receive_telling(vx_seat_t *s, Py_ssize_t index, const vstig_msg_t *msgs, size_t n, PyObject *sender) {
    PyObject *link = PyList_GET_ITEM(s->links, index), *name = PyObject_GetAttr(link, vx_n.name);
    int domain = one_domain(s, index), status = 0;
    size_t i;
    if (name == NULL) return -1;
    for (i = 0; status == 0 && i < n; i++) {
        vstig_entry_t old;
        int had = vstig_engine_entry(&s->engine->engine, msgs[i].key, &old);
        status = receive(s, index, &msgs[i], 1, domain);
        if (status == 0) status = tell(s, msgs[i].key, had ? &old : NULL, name, sender);
    }
    Py_DECREF(name);
    return status;
}

int vx_seat_listening(vx_seat_t *s) { return PyObject_IsTrue(s->on_change); }

int vx_seat_take(vx_seat_t *s, Py_ssize_t index, const vstig_msg_t *msgs, size_t n, PyObject *sender, PyObject *sub) {
    int listen;
    if (caused_by(s, (long)index, sub) < 0 || (listen = vx_seat_listening(s)) < 0) return -1;
    if (listen) return receive_telling(s, index, msgs, n, sender);
    return receive(s, index, msgs, n, one_domain(s, index));
}

int vx_seat_admit(vx_seat_t *s, Py_ssize_t index, PyObject *sub, size_t n, double t, size_t *admitted) {
    /* Seat.admit: the source's bucket refilled since its last batch (at `rate`, up to `burst`), then spent */
    PyObject *key = NULL, *got, *value;
    double left = s->burst, since = 0.0;
    int known;
    *admitted = n;
    if (sub == Py_None) {
        known = s->known[index];
        if (known) {
            left = s->left[index];
            since = s->since[index];
        }
    } else {
        if ((key = Py_BuildValue("(nO)", index, sub)) == NULL) return -1;
        got = PyDict_GetItemWithError(s->allowed, key);
        if (got == NULL && PyErr_Occurred()) {
            Py_DECREF(key);
            return -1;
        }
        known = got != NULL;
        if (known) {
            left = PyFloat_AsDouble(PyTuple_GET_ITEM(got, 0));
            since = PyFloat_AsDouble(PyTuple_GET_ITEM(got, 1));
        }
    }
    if (known && t > since) {
        double refilled = left + (t - since) * s->rate;
        left = s->burst <= refilled ? s->burst : refilled;
    }
    if ((double)n > left) {
        size_t room = (size_t)left; /* int(): left is never below 0 */
        PyObject *counters = PyObject_GetAttr(PyList_GET_ITEM(s->links, index), vx_n.counters);
        int status = counters == NULL ? -1 : vx_count(counters, vx_n.drop_intake, (Py_ssize_t)(n - room));
        Py_XDECREF(counters);
        if (status < 0) {
            Py_XDECREF(key);
            return -1;
        }
        *admitted = n = room;
    }
    left -= (double)n;
    if (key == NULL) {
        s->known[index] = 1;
        s->left[index] = left;
        s->since[index] = t;
    } else {
        value = Py_BuildValue("(dd)", left, t);
        if (value == NULL || PyDict_SetItem(s->allowed, key, value) < 0) {
            Py_XDECREF(value);
            Py_DECREF(key);
            return -1;
        }
        Py_DECREF(value);
        Py_DECREF(key);
    }
    if (t > s->latest) s->latest = t;
    return 0;
}

/* ---- Seat: what goes out ------------------------------------------------------------------ */

/* The read-only link the entry `msg` carries was written on (its outlet alone carries it), or NULL. */
static PyObject *confined_to(vx_seat_t *s, const vstig_msg_t *msg) {
    PyObject *m = vx_message(msg), *where, *name = vx_name("confined_to");
    if (m == NULL || name == NULL) {
        Py_XDECREF(m);
        return NULL;
    }
    where = PyObject_CallMethodOneArg(s->guard, name, m); /* one argument: a Message is a tuple */
    Py_DECREF(m);
    return where;
}

/* Seat._push_where_due: each message on every link but the one-domain link it came from and those a guard keeps
 * it off. */
static int push_where_due(vx_seat_t *s, const vstig_msg_t *out, size_t n, int confines) {
    int16_t *origin = PyMem_Malloc((n ? n : 1u) * sizeof *origin);
    vstig_msg_t *due = PyMem_Malloc((n ? n : 1u) * sizeof *due);
    PyObject **where = confines ? PyMem_Calloc(n ? n : 1u, sizeof *where) : NULL;
    Py_ssize_t i;
    size_t k, m;
    int status = -1;
    if (origin == NULL || due == NULL || (confines && where == NULL)) {
        PyErr_NoMemory();
        goto done;
    }
    if (has_notes(s)) origins(s, out, n, origin);
    else {
        for (k = 0; k < n; k++) origin[k] = -1;
        forget_notes(s);
    }
    for (k = 0; confines && k < n; k++) {
        if ((where[k] = confined_to(s, &out[k])) == NULL) goto done;
    }
    for (i = 0; i < PyList_GET_SIZE(s->outlets); i++) {
        vx_outlet_t *outlet = OUTLET(s->outlets, i);
        PyObject *name = NULL;
        Py_ssize_t echoes = 0;
        if (confines && (name = PyObject_GetAttr(outlet->link, vx_n.name)) == NULL) goto done;
        for (k = 0, m = 0; k < n; k++) {
            if (origin[k] == i) { /* every robot on that link heard it already */
                echoes++;
                continue;
            }
            if (confines && where[k] != Py_None) { /* a read-only link's entries stay there */
                int here = PyObject_RichCompareBool(where[k], name, Py_EQ);
                if (here < 0) {
                    Py_DECREF(name);
                    goto done;
                }
                if (!here) continue;
            }
            due[m++] = out[k];
        }
        Py_XDECREF(name);
        if (VX_HOT(outlet, NOT_ECHOED, echoes) < 0 ||
            vx_outlet_push(outlet, due, m, s->source_link, s->source_sub) < 0)
            goto done;
    }
    status = 0;
done:
    for (k = 0; where != NULL && k < n; k++) Py_XDECREF(where[k]);
    PyMem_Free(where);
    PyMem_Free(origin);
    PyMem_Free(due);
    return status;
}

static int guard_confines(vx_seat_t *s) {
    PyObject *confines;
    int yes;
    if (!is_python_guard(s->guard)) return 0;
    confines = PyObject_GetAttr(s->guard, vx_n.confines);
    if (confines == NULL) return -1;
    yes = PyObject_IsTrue(confines);
    Py_DECREF(confines);
    return yes;
}

int vx_seat_queue_out(vx_seat_t *s) {
    vstig_engine_t *engine = &s->engine->engine;
    vstig_msg_t stack[64], *out = stack;
    size_t n = engine->out.len;
    Py_ssize_t i;
    int confines, status = 0;
    if (n == 0) return 0;
    if (n > 64 && (out = PyMem_Malloc(n * sizeof *out)) == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    n = vstig_engine_drain(engine, out, n);
    if ((confines = guard_confines(s)) < 0) {
        status = -1;
    } else if (!confines && !has_notes(s)) { /* the common case: every message to every link */
        forget_notes(s);
        for (i = 0; status == 0 && i < PyList_GET_SIZE(s->outlets); i++)
            status = vx_outlet_push(OUTLET(s->outlets, i), out, n, s->source_link, s->source_sub);
    } else {
        status = push_where_due(s, out, n, confines);
    }
    if (out != stack) PyMem_Free(out);
    return status;
}

/* ---- Seat: the Python type ------------------------------------------------------------------- */

static PyObject *Seat_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"engine", "links", "outlets", "guard", "on_change", "intake", "period", NULL};
    PyObject *engine, *links, *outlets, *guard, *on_change = NULL, *intake = Py_None;
    double period = 0.1;
    long intake_value = 0;
    vx_seat_t *self;
    Py_ssize_t i;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O!O!OO|OOd", kwlist, &vx_EngineType, &engine, &PyList_Type, &links,
                                     &outlets, &guard, &on_change, &intake, &period) ||
        outlets_of(outlets) < 0)
        return NULL;
    if (intake != Py_None && (PyLong_AsLong(intake) < 1 || PyErr_Occurred())) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_ValueError,
                         "the engine's intake per source and tick must be at least 1 message, got %R", intake);
        return NULL;
    }
    self = (vx_seat_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->engine = (vx_engine_t *)Py_NewRef(engine);
    self->links = Py_NewRef(links);
    self->outlets = Py_NewRef(outlets);
    self->guard = Py_NewRef(guard);
    self->on_change = on_change == NULL ? PyTuple_New(0) : Py_NewRef(on_change);
    self->intake_obj = Py_NewRef(intake);
    if (intake != Py_None) intake_value = PyLong_AsLong(intake);
    self->rate = intake == Py_None ? 0.0 : (double)intake_value / period; /* messages a second a source may give */
    self->burst = intake == Py_None ? 0.0 : (double)(intake_value * VX_INTAKE_BURST_TICKS);
    self->nlinks = PyList_GET_SIZE(links);
    self->left = PyMem_Calloc((size_t)(self->nlinks ? self->nlinks : 1), sizeof *self->left);
    self->since = PyMem_Calloc((size_t)(self->nlinks ? self->nlinks : 1), sizeof *self->since);
    self->known = PyMem_Calloc((size_t)(self->nlinks ? self->nlinks : 1), sizeof *self->known);
    self->allowed = PyDict_New();
    self->one_domain = PyList_New(self->nlinks);
    self->source_link = VX_LOCAL;
    self->source_sub = Py_NewRef(Py_None);
    self->note_link = PyMem_Malloc(VSTIG_KEYS * sizeof *self->note_link);
    self->note_msg = PyMem_Malloc(VSTIG_KEYS * sizeof *self->note_msg);
    self->noted = PyMem_Malloc(VSTIG_KEYS * sizeof *self->noted);
    if (self->on_change == NULL || self->left == NULL || self->since == NULL || self->known == NULL ||
        self->allowed == NULL || self->one_domain == NULL ||
        self->note_link == NULL || self->note_msg == NULL || self->noted == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    for (i = 0; i < VSTIG_KEYS; i++) self->note_link[i] = NOT_NOTED;
    for (i = 0; i < self->nlinks; i++) {
        PyObject *domain = PyObject_GetAttr(PyList_GET_ITEM(links, i), vx_n.one_domain);
        int yes = domain == NULL ? -1 : PyObject_IsTrue(domain);
        Py_XDECREF(domain);
        if (yes < 0) {
            Py_DECREF(self);
            return NULL;
        }
        PyList_SET_ITEM(self->one_domain, i, Py_NewRef(yes ? Py_True : Py_False));
    }
    return (PyObject *)self;
}

static int Seat_traverse(vx_seat_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->engine);
    Py_VISIT(self->links);
    Py_VISIT(self->outlets);
    Py_VISIT(self->guard);
    Py_VISIT(self->on_change);
    Py_VISIT(self->allowed);
    Py_VISIT(self->source_sub);
    return 0;
}

static int Seat_clear(vx_seat_t *self) {
    Py_CLEAR(self->engine);
    Py_CLEAR(self->links);
    Py_CLEAR(self->outlets);
    Py_CLEAR(self->guard);
    Py_CLEAR(self->on_change);
    Py_CLEAR(self->allowed);
    Py_CLEAR(self->source_sub);
    Py_CLEAR(self->intake_obj);
    Py_CLEAR(self->one_domain);
    return 0;
}

static void Seat_dealloc(vx_seat_t *self) {
    PyObject_GC_UnTrack(self);
    Seat_clear(self);
    PyMem_Free(self->left);
    PyMem_Free(self->since);
    PyMem_Free(self->known);
    PyMem_Free(self->note_link);
    PyMem_Free(self->note_msg);
    PyMem_Free(self->noted);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Seat_put(vx_seat_t *self, PyObject *args) {
    PyObject *key_obj, *value_obj, *robot;
    long key;
    vstig_entry_t old;
    int listen, had;
    if (!PyArg_ParseTuple(args, "OO:put", &key_obj, &value_obj) || caused_by(self, VX_LOCAL, Py_None) < 0) return NULL;
    if ((listen = vx_seat_listening(self)) < 0 || (key = vx_field("key", VSTIG_KEY_MAX, key_obj)) < 0) return NULL;
    had = vstig_engine_entry(&self->engine->engine, (uint16_t)key, &old);
    {
        PyObject *done = PyObject_CallMethodObjArgs((PyObject *)self->engine, vx_n.put, key_obj, value_obj, NULL);
        if (done == NULL) return NULL;
        Py_DECREF(done);
    }
    if (listen) {
        robot = PyLong_FromLong(self->engine->engine.robot);
        if (robot == NULL || tell(self, (uint16_t)key, had ? &old : NULL, Py_None, robot) < 0) {
            Py_XDECREF(robot);
            return NULL;
        }
        Py_DECREF(robot);
    }
    Py_RETURN_NONE;
}

static PyObject *Seat_get(vx_seat_t *self, PyObject *key_obj) {
    PyObject *value;
    if (caused_by(self, VX_LOCAL, Py_None) < 0) return NULL;
    value = PyObject_CallMethodOneArg((PyObject *)self->engine, vx_n.get, key_obj);
    if (value != NULL) { /* the GET may have merged into the key's pending PUT: send it everywhere */
        long key = PyLong_AsLong(key_obj);
        if (self->note_link[key] >= 0) self->note_link[key] = UNNOTED;
    }
    return value;
}

static PyObject *Seat_ask(vx_seat_t *self, PyObject *key_obj) {
    long key = vx_field("key", VSTIG_KEY_MAX, key_obj);
    vstig_msg_t ask;
    Py_ssize_t i;
    if (key < 0) return NULL;
    ask.op = VSTIG_GET;
    ask.key = (uint16_t)key;
    ask.value = 0;
    ask.timestamp = VSTIG_TS_NONE;
    ask.robot = self->engine->engine.robot;
    for (i = 0; i < PyList_GET_SIZE(self->outlets); i++) { /* (LOCAL) a PUT already queued for the key stays */
        if (vx_outlet_push(OUTLET(self->outlets, i), &ask, 1, VX_LOCAL, Py_None) < 0) return NULL;
    }
    Py_RETURN_NONE;
}

static PyObject *Seat_take(vx_seat_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"index", "messages", "sender", "sub", NULL};
    PyObject *messages, *sender, *sub = Py_None;
    Py_ssize_t index;
    size_t n;
    vstig_msg_t *msgs;
    int status;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "nOO|O", kwlist, &index, &messages, &sender, &sub)) return NULL;
    if (index < 0 || index >= self->nlinks) return PyErr_Format(PyExc_IndexError, "no link %zd", index);
    if ((msgs = vx_msgs_of(messages, &n)) == NULL) return NULL;
    status = vx_seat_take(self, index, msgs, n, sender, sub);
    PyMem_Free(msgs);
    if (status < 0) return NULL;
    Py_RETURN_NONE;
}

static PyObject *Seat_admit(vx_seat_t *self, PyObject *args) {
    PyObject *sub, *messages;
    Py_ssize_t index, n;
    double t;
    size_t admitted;
    if (!PyArg_ParseTuple(args, "nOOd:admit", &index, &sub, &messages, &t)) return NULL;
    if (index < 0 || index >= self->nlinks) return PyErr_Format(PyExc_IndexError, "no link %zd", index);
    if ((n = PyObject_Length(messages)) < 0 || vx_seat_admit(self, index, sub, (size_t)n, t, &admitted) < 0)
        return NULL;
    if ((Py_ssize_t)admitted == n) return Py_NewRef(messages);
    return PySequence_GetSlice(messages, 0, (Py_ssize_t)admitted);
}

static PyObject *Seat_tick(vx_seat_t *self, PyObject *unused) {
    /* Seat.tick: forget the sources whose allowance has refilled whole since they last gave (as good as new) */
    Py_ssize_t i, known = 0, pos = 0;
    PyObject *key, *value, *stale;
    double old;
    (void)unused;
    for (i = 0; i < self->nlinks; i++) known += self->known[i];
    if (known + PyDict_GET_SIZE(self->allowed) <= self->nlinks) Py_RETURN_NONE;
    old = self->latest - (self->rate != 0.0 ? self->burst / self->rate : 0.0);
    for (i = 0; i < self->nlinks; i++) {
        if (self->known[i] && self->since[i] < old) self->known[i] = 0;
    }
    if ((stale = PyList_New(0)) == NULL) return NULL;
    while (PyDict_Next(self->allowed, &pos, &key, &value)) {
        if (PyFloat_AsDouble(PyTuple_GET_ITEM(value, 1)) < old && PyList_Append(stale, key) < 0) {
            Py_DECREF(stale);
            return NULL;
        }
    }
    for (i = 0; i < PyList_GET_SIZE(stale); i++) {
        if (PyDict_DelItem(self->allowed, PyList_GET_ITEM(stale, i)) < 0) {
            Py_DECREF(stale);
            return NULL;
        }
    }
    Py_DECREF(stale);
    Py_RETURN_NONE;
}

static PyObject *Seat_queue_out(vx_seat_t *self, PyObject *unused) {
    (void)unused;
    if (vx_seat_queue_out(self) < 0) return NULL;
    Py_RETURN_NONE;
}

static PyMethodDef Seat_methods[] = {
    {"put", (PyCFunction)Seat_put, METH_VARARGS, NULL},
    {"get", (PyCFunction)Seat_get, METH_O, NULL},
    {"ask", (PyCFunction)Seat_ask, METH_O, "Queue an empty GET for key on every link."},
    {"take", (PyCFunction)(void (*)(void))Seat_take, METH_VARARGS | METH_KEYWORDS, "Judge what link `index` heard."},
    {"admit", (PyCFunction)Seat_admit, METH_VARARGS, "What the engine takes of a batch read at t, within its intake."},
    {"tick", (PyCFunction)Seat_tick, METH_NOARGS, "Forget the sources whose allowance has refilled whole."},
    {"queue_out", (PyCFunction)Seat_queue_out, METH_NOARGS, "Copy the engine's outbox into every outlet."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Seat_members[] = {
    {"engine", T_OBJECT, offsetof(vx_seat_t, engine), READONLY, NULL},
    {"links", T_OBJECT, offsetof(vx_seat_t, links), READONLY, NULL},
    {"outlets", T_OBJECT, offsetof(vx_seat_t, outlets), READONLY, NULL},
    {"guard", T_OBJECT, offsetof(vx_seat_t, guard), READONLY, NULL},
    {"on_change", T_OBJECT_EX, offsetof(vx_seat_t, on_change), 0, "The Node's change listeners (replaced by it)."},
    {"intake", T_OBJECT, offsetof(vx_seat_t, intake_obj), READONLY, NULL},
    {NULL, 0, 0, 0, NULL},
};

PyTypeObject vx_SeatType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Seat",
    .tp_doc = "Seat(engine, links, outlets, guard, on_change=(), intake=None, period=0.1): Seat in C.",
    .tp_basicsize = sizeof(vx_seat_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = Seat_new,
    .tp_dealloc = (destructor)Seat_dealloc,
    .tp_traverse = (traverseproc)Seat_traverse,
    .tp_clear = (inquiry)Seat_clear,
    .tp_methods = Seat_methods,
    .tp_members = Seat_members,
};
