/*
 * Engine: libvstig's engine with vstig_hw.engine.Stigmergy's interface (put, get, has, size,
 * entry, entries, counts, receive, drain, pending; onconflict and onconflictlost settable).
 *
 * Reference: vstig_hw/engine.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 * Given the swarm key (`swarm_key=`), it is vstig_hw/gateway/signing.py's SignedEngine instead (tags.c).
 *
 * The conflict rule: Stigmergy's ready-made rules run as their libvstig twins; any other
 * callable is called back from C with Entry objects, and what it raises (or a winner the
 * Python engine refuses) is raised from `receive` as the Python engine raises it.
 */
#include "engine.h"

static vstig_resolver_t c_twin(PyObject *rule) {
    static const vstig_resolver_t twins[3] = {vstig_higher_robot_wins, vstig_larger_value_wins, vstig_sum_merge};
    Py_ssize_t i;
    for (i = 0; i < PyTuple_GET_SIZE(vx_py.rules) && i < 3; i++) {
        if (PyTuple_GET_ITEM(vx_py.rules, i) == rule) return twins[i];
    }
    return NULL;
}

/* Stashes the exception raised in a callback: it cannot cross libvstig, so the caller raises it. */
static void stash(vx_engine_t *self) {
    if (self->error_type == NULL) {
        PyErr_Fetch(&self->error_type, &self->error_value, &self->error_tb);
    } else {
        PyErr_Clear(); /* the first one wins, as in Python, where the first would have ended the call */
    }
}

static int raise_stashed(vx_engine_t *self) {
    if (self->error_type == NULL) return 0;
    PyErr_Restore(self->error_type, self->error_value, self->error_tb);
    self->error_type = self->error_value = self->error_tb = NULL;
    return -1;
}

/* A Python rule, called back from libvstig. Mirrors Stigmergy._resolve and _merged_winner: what
 * it returns must be an Entry-like 3-tuple, and a new value must name this robot or a writer. */
static uint8_t python_rule(void *ctx, uint16_t key, const vstig_entry_t *local, const vstig_entry_t *remote,
                           vstig_entry_t *chosen) {
    vx_engine_t *self = ctx;
    PyObject *l = NULL, *r = NULL, *got = NULL, *shown = NULL;
    long value, robot;
    uint8_t ok = 0;
    if (self->error_type != NULL) return 0; /* an earlier callback of this call raised: Python stopped there */
    l = vx_entry(local);
    r = vx_entry(remote);
    if (l == NULL || r == NULL) goto done;
    got = PyObject_CallFunction(self->onconflict, "iOO", (int)key, l, r);
    if (got == NULL) goto done;
    if (got == l || got == r) { /* one of the two: its fields are valid */
        chosen->value = (got == l ? local : remote)->value;
        chosen->robot = (got == l ? local : remote)->robot;
        chosen->timestamp = local->timestamp;
        ok = 1;
        goto done;
    }
    if (!PyTuple_Check(got) || PyTuple_GET_SIZE(got) != 3) {
        PyErr_Format(PyExc_TypeError, "onconflict must return an Entry(value, timestamp, robot), got %R", got);
        goto done;
    }
    value = PyLong_Check(PyTuple_GET_ITEM(got, 0)) ? PyLong_AsLong(PyTuple_GET_ITEM(got, 0)) : -1;
    robot = PyLong_Check(PyTuple_GET_ITEM(got, 2)) ? PyLong_AsLong(PyTuple_GET_ITEM(got, 2)) : -1;
    if (PyErr_Occurred()) goto done;
    if (robot == (long)self->engine.robot && !(value >= 0 && value <= 0xFFFF)) {
        /* a merge named for us: Python builds Message(...), whose check refuses the value */
        if (vx_field("value", 0xFFFF, PyTuple_GET_ITEM(got, 0)) < 0) goto done;
    }
    if (robot != (long)local->robot && robot != (long)remote->robot && robot != (long)self->engine.robot) {
        shown = PyObject_CallFunction((PyObject *)vx_py.entry, "OiO", PyTuple_GET_ITEM(got, 0), (int)local->timestamp,
                                      PyTuple_GET_ITEM(got, 2));
        if (shown == NULL) goto done;
        PyErr_Format(PyExc_ValueError,
                     "onconflict returned %R for key %d: a new value must name this robot (%d) or the writer of "
                     "one of the two entries (%d or %d)",
                     shown, (int)key, (int)self->engine.robot, (int)local->robot, (int)remote->robot);
        goto done;
    }
    chosen->value = (uint16_t)(value & 0xFFFF); /* ignored unless it names a writer with this very value */
    chosen->timestamp = local->timestamp;
    chosen->robot = (uint16_t)robot;
    ok = 1;
done:
    if (!ok) stash(self);
    Py_XDECREF(l);
    Py_XDECREF(r);
    Py_XDECREF(got);
    Py_XDECREF(shown);
    return ok;
}

static void python_lost(void *ctx, uint16_t key, const vstig_entry_t *lost) {
    vx_engine_t *self = ctx;
    PyObject *entry, *got;
    if (self->onconflictlost == Py_None) return;
    entry = vx_entry(lost);
    got = entry == NULL ? NULL : PyObject_CallFunction(self->onconflictlost, "iO", (int)key, entry);
    Py_XDECREF(entry);
    if (got == NULL) {
        stash(self);
        self->lost_raised = 1;
    }
    Py_XDECREF(got);
}

static void use_rule(vx_engine_t *self) {
    vstig_resolver_t twin = c_twin(self->onconflict);
    self->engine.onconflict = twin != NULL ? twin : python_rule;
}

/* ---- the data path's calls ----------------------------------------------------------- */

int vx_engine_calls_python(const vx_engine_t *self) {
    return self->engine.onconflict == python_rule || self->onconflictlost != Py_None;
}

vstig_outcome_t vx_engine_receive(vx_engine_t *self, const vstig_msg_t *msg) {
    uint16_t before = self->engine.size;
    vstig_outcome_t outcome;
    if (self->tags != NULL) {
        int done = vx_tags_receive(self->tags, msg);
        if (done < 0) { /* a record that is none: raised as a callback's error is, the message not received */
            stash(self);
            return VSTIG_STALE;
        }
        outcome = (vstig_outcome_t)done;
    } else {
        outcome = vstig_engine_receive(&self->engine, msg);
    }
    if (self->engine.size != before) self->order[self->engine.size - 1u] = (uint16_t)(msg->key & VSTIG_KEY_MAX);
    if (self->lost_raised) { /* Python's receive raised before counting the outcome */
        self->lost_raised = 0;
        self->engine.counts[outcome]--;
    }
    return outcome;
}

int vx_engine_raise(vx_engine_t *self, vstig_outcome_t outcome) {
    if (raise_stashed(self) < 0) return -1;
    if (outcome == VSTIG_BAD_WINNER) { /* only the Python rule says so, and it stashed why */
        PyErr_SetString(PyExc_SystemError, "the conflict rule refused without saying why");
        return -1;
    }
    if (outcome == VSTIG_FULL) { /* a table of every key is never full */
        PyErr_SetString(PyExc_MemoryError, "the engine's table is full");
        return -1;
    }
    return 0;
}

/* ---- the Python type ------------------------------------------------------------------ */

static PyObject *Engine_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"robot_id", "onconflict", "onconflictlost", "swarm_key", "stigmergy", "policies",
                             "record", NULL};
    PyObject *robot_obj, *onconflict = Py_None, *onconflictlost = Py_None, *swarm_key = Py_None;
    PyObject *policies = Py_None, *record = Py_None;
    int stigmergy = 0;
    vx_engine_t *self;
    long robot;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|OO$OiOO", kwlist, &robot_obj, &onconflict, &onconflictlost,
                                     &swarm_key, &stigmergy, &policies, &record))
        return NULL;
    if ((robot = vx_field("robot_id", 0xFFFF, robot_obj)) < 0) return NULL;
    self = (vx_engine_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->order = PyMem_Calloc(VSTIG_KEYS, sizeof *self->order);
    if (self->order == NULL ||
        vstig_engine_init(&self->engine, (uint16_t)robot, NULL, python_lost, self) != 0) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    if (swarm_key != Py_None &&
        (self->tags = vx_tags_new(&self->engine, swarm_key, stigmergy, policies, record)) == NULL) {
        Py_DECREF(self);
        return NULL;
    }
    self->onconflict = onconflict == Py_None ? PyTuple_GET_ITEM(vx_py.rules, 0) : onconflict;
    Py_INCREF(self->onconflict);
    Py_INCREF(onconflictlost);
    self->onconflictlost = onconflictlost;
    use_rule(self);
    return (PyObject *)self;
}

static int Engine_traverse(vx_engine_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->onconflict);
    Py_VISIT(self->onconflictlost);
    return vx_tags_traverse(self->tags, visit, arg);
}

static int Engine_clear(vx_engine_t *self) {
    Py_CLEAR(self->onconflict);
    Py_CLEAR(self->onconflictlost);
    vx_tags_clear(self->tags);
    return 0;
}

static void Engine_dealloc(vx_engine_t *self) {
    PyObject_GC_UnTrack(self);
    Engine_clear(self);
    Py_XDECREF(self->error_type);
    Py_XDECREF(self->error_value);
    Py_XDECREF(self->error_tb);
    PyMem_Free(self->order);
    vx_tags_free(self->tags);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Engine_put(vx_engine_t *self, PyObject *const *args, Py_ssize_t nargs) {
    long key, value;
    uint16_t before = self->engine.size;
    if (nargs != 2) return PyErr_Format(PyExc_TypeError, "put() takes key and value, got %zd arguments", nargs);
    if ((key = vx_field("key", VSTIG_KEY_MAX, args[0])) < 0 || (value = vx_field("value", 0xFFFF, args[1])) < 0)
        return NULL;
    if ((self->tags != NULL ? vstig_tagged_put(&self->tags->tagged, (uint16_t)key, (uint16_t)value)
                            : vstig_engine_put(&self->engine, (uint16_t)key, (uint16_t)value)) != 0)
        return PyErr_NoMemory();
    if (self->engine.size != before) self->order[before] = (uint16_t)key;
    Py_RETURN_NONE;
}

static PyObject *Engine_get(vx_engine_t *self, PyObject *key_obj) {
    long key = vx_field("key", VSTIG_KEY_MAX, key_obj);
    uint16_t value;
    if (key < 0) return NULL;
    if (vstig_engine_get(&self->engine, (uint16_t)key, &value) != 1) Py_RETURN_NONE;
    return PyLong_FromLong(value);
}

/* The key a lookup means, as a dict lookup of Stigmergy's table would: -1 when no entry can match. */
static long lookup_key(PyObject *key_obj) {
    long key;
    if (!PyLong_Check(key_obj)) return -1;
    key = PyLong_AsLong(key_obj);
    if (key == -1 && PyErr_Occurred()) PyErr_Clear();
    return key >= 0 && key <= (long)VSTIG_KEY_MAX ? key : -1;
}

static PyObject *Engine_has(vx_engine_t *self, PyObject *key_obj) {
    long key = lookup_key(key_obj);
    vstig_entry_t entry;
    return PyBool_FromLong(key >= 0 && vstig_engine_entry(&self->engine, (uint16_t)key, &entry));
}

static PyObject *Engine_size(vx_engine_t *self, PyObject *unused) {
    (void)unused;
    return PyLong_FromLong(self->engine.size);
}

static PyObject *Engine_entry(vx_engine_t *self, PyObject *key_obj) {
    long key = lookup_key(key_obj);
    vstig_entry_t entry;
    if (key < 0 || !vstig_engine_entry(&self->engine, (uint16_t)key, &entry)) Py_RETURN_NONE;
    return vx_entry(&entry);
}

static PyObject *Engine_entries(vx_engine_t *self, PyObject *unused) {
    /* a snapshot in the order keys were first stored, as Stigmergy's dict iterates */
    PyObject *list = PyList_New(self->engine.size), *iter;
    uint16_t i;
    vstig_entry_t entry;
    (void)unused;
    if (list == NULL) return NULL;
    for (i = 0; i < self->engine.size; i++) {
        PyObject *pair;
        (void)vstig_engine_entry(&self->engine, self->order[i], &entry);
        pair = Py_BuildValue("(iN)", (int)self->order[i], vx_entry(&entry));
        if (pair == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, pair);
    }
    iter = PyObject_GetIter(list);
    Py_DECREF(list);
    return iter;
}

static PyObject *Engine_counts(vx_engine_t *self, void *closure) {
    PyObject *counts = PyDict_New();
    Py_ssize_t i;
    (void)closure;
    if (counts == NULL) return NULL;
    for (i = 0; i < PyTuple_GET_SIZE(vx_py.outcomes); i++) {
        /* a replayed old write (older by epoch and timestamp) counts as stale, as SignedEngine.counts has it */
        unsigned long extra = self->tags != NULL && i == VSTIG_STALE ? self->tags->tagged.replays : 0ul;
        PyObject *n = PyLong_FromUnsignedLong(self->engine.counts[i] + extra);
        if (n == NULL || PyDict_SetItem(counts, PyTuple_GET_ITEM(vx_py.outcomes, i), n) < 0) {
            Py_XDECREF(n);
            Py_DECREF(counts);
            return NULL;
        }
        Py_DECREF(n);
    }
    return counts;
}

static PyObject *Engine_receive(vx_engine_t *self, PyObject *msg_obj) {
    vstig_msg_t msg;
    vstig_outcome_t outcome;
    if (vx_msg_of(msg_obj, &msg) < 0) return NULL;
    outcome = vx_engine_receive(self, &msg);
    if (vx_engine_raise(self, outcome) < 0) return NULL;
    return Py_NewRef(PyTuple_GET_ITEM(vx_py.outcomes, outcome));
}

PyObject *vx_drain_list(const vstig_msg_t *out, size_t n) {
    PyObject *list = PyList_New((Py_ssize_t)n);
    size_t i;
    if (list == NULL) return NULL;
    for (i = 0; i < n; i++) {
        PyObject *m = vx_message(&out[i]);
        if (m == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, (Py_ssize_t)i, m);
    }
    return list;
}

/* OutQueue.drain's budget: None or at least what is pending is all of it; below 0 is refused. */
int vx_budget(PyObject *args, PyObject *kwds, size_t pending, size_t *budget) {
    static char *kwlist[] = {"budget", NULL};
    PyObject *given = Py_None;
    long asked;
    *budget = pending;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|O:drain", kwlist, &given)) return -1;
    if (given == Py_None) return 0;
    asked = PyLong_AsLong(given);
    if (asked == -1 && PyErr_Occurred()) return -1;
    if (asked >= (long)pending) return 0;
    if (asked < 0) {
        PyErr_Format(PyExc_ValueError, "budget must be >= 0, got %ld", asked);
        return -1;
    }
    *budget = (size_t)asked;
    return 0;
}

static PyObject *Engine_drain(vx_engine_t *self, PyObject *args, PyObject *kwds) {
    size_t budget, n;
    vstig_msg_t *out;
    PyObject *list;
    if (vx_budget(args, kwds, self->engine.out.len, &budget) < 0) return NULL;
    out = PyMem_Malloc((budget ? budget : 1u) * sizeof *out);
    if (out == NULL) return PyErr_NoMemory();
    n = vstig_engine_drain(&self->engine, out, budget);
    list = vx_drain_list(out, n);
    PyMem_Free(out);
    return list;
}

static PyObject *Engine_pending(vx_engine_t *self, PyObject *unused) {
    (void)unused;
    return PyLong_FromLong(self->engine.out.len);
}

static PyObject *Engine_get_robot(vx_engine_t *self, void *closure) {
    (void)closure;
    return PyLong_FromLong(self->engine.robot);
}

static PyObject *Engine_get_onconflict(vx_engine_t *self, void *closure) {
    (void)closure;
    return Py_NewRef(self->onconflict);
}

static int Engine_set_onconflict(vx_engine_t *self, PyObject *value, void *closure) {
    (void)closure;
    if (value == NULL || !PyCallable_Check(value)) {
        PyErr_SetString(PyExc_TypeError, "onconflict must be a callable (key, local, remote) -> Entry");
        return -1;
    }
    Py_INCREF(value);
    Py_SETREF(self->onconflict, value);
    use_rule(self);
    return 0;
}

static PyObject *Engine_get_onconflictlost(vx_engine_t *self, void *closure) {
    (void)closure;
    return Py_NewRef(self->onconflictlost);
}

static int Engine_set_onconflictlost(vx_engine_t *self, PyObject *value, void *closure) {
    (void)closure;
    if (value == NULL) value = Py_None;
    Py_INCREF(value);
    Py_SETREF(self->onconflictlost, value);
    return 0;
}

/* SignedEngine's own: what a swarm key adds (tags.c); AttributeError without one, as a Stigmergy has none */
static int has_tags(vx_engine_t *self, const char *what) {
    if (self->tags != NULL) return 1;
    PyErr_Format(PyExc_AttributeError, "an Engine without swarm_key has no %s", what);
    return 0;
}

static PyObject *Engine_record_of(vx_engine_t *self, PyObject *msg) {
    return has_tags(self, "record_of") ? vx_tags_record_of(self->tags, msg) : NULL;
}

static PyObject *Engine_get_policy(vx_engine_t *self, void *closure) {
    (void)closure;
    return has_tags(self, "policy") ? vx_tags_get_policy(self->tags) : NULL;
}

static int Engine_set_policy(vx_engine_t *self, PyObject *value, void *closure) {
    (void)closure;
    return has_tags(self, "policy") ? vx_tags_set_policy(self->tags, value) : -1;
}

static PyObject *Engine_get_records(vx_engine_t *self, void *closure) {
    (void)closure;
    return has_tags(self, "records") ? vx_tags_get_records(self->tags) : NULL;
}

static int Engine_set_records(vx_engine_t *self, PyObject *value, void *closure) {
    (void)closure;
    return has_tags(self, "records") ? vx_tags_set_records(self->tags, value) : -1;
}

static PyObject *Engine_get_replays(vx_engine_t *self, void *closure) {
    (void)closure;
    return has_tags(self, "replays") ? PyLong_FromUnsignedLong(self->tags->tagged.replays) : NULL;
}

static PyMethodDef Engine_methods[] = {
    {"put", (PyCFunction)(void (*)(void))Engine_put, METH_FASTCALL, "Write locally and queue a PUT."},
    {"get", (PyCFunction)Engine_get, METH_O, "The local value (None if unknown); queues a GET."},
    {"has", (PyCFunction)Engine_has, METH_O, NULL},
    {"size", (PyCFunction)Engine_size, METH_NOARGS, NULL},
    {"entry", (PyCFunction)Engine_entry, METH_O, NULL},
    {"entries", (PyCFunction)Engine_entries, METH_NOARGS, "Every (key, entry), a snapshot, in the order stored."},
    {"receive", (PyCFunction)Engine_receive, METH_O, "Apply one message heard from a neighbour."},
    {"drain", (PyCFunction)(void (*)(void))Engine_drain, METH_VARARGS | METH_KEYWORDS, "Messages to broadcast now."},
    {"pending", (PyCFunction)Engine_pending, METH_NOARGS, NULL},
    {"record_of", (PyCFunction)Engine_record_of, METH_O, "A drained message with its entry's proof, or None."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Engine_getset[] = {
    {"robot_id", (getter)Engine_get_robot, NULL, NULL, NULL},
    {"counts", (getter)Engine_counts, NULL, "How many received messages had each outcome.", NULL},
    {"onconflict", (getter)Engine_get_onconflict, (setter)Engine_set_onconflict, NULL, NULL},
    {"onconflictlost", (getter)Engine_get_onconflictlost, (setter)Engine_set_onconflictlost, NULL, NULL},
    {"policy", (getter)Engine_get_policy, (setter)Engine_set_policy, "The policy of the link being received.", NULL},
    {"records", (getter)Engine_get_records, (setter)Engine_set_records, "The unit's records (Signing's).", NULL},
    {"replays", (getter)Engine_get_replays, NULL, "Tagged messages older by (epoch, timestamp): lost.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject vx_EngineType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Engine",
    .tp_doc = "One robot's view of one virtual stigmergy: libvstig's engine with Stigmergy's interface.",
    .tp_basicsize = sizeof(vx_engine_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = Engine_new,
    .tp_dealloc = (destructor)Engine_dealloc,
    .tp_traverse = (traverseproc)Engine_traverse,
    .tp_clear = (inquiry)Engine_clear,
    .tp_methods = Engine_methods,
    .tp_getset = Engine_getset,
};
