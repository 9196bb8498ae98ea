/* vstig_hw._vstig: the module, `setup`, and the conversions every type shares. See ext.h. */
#include "ext.h"

#include <string.h>

#include "path.h"

vx_python_t vx_py;
vx_names_t vx_n;

static int intern_names(void) {
    struct {
        PyObject **slot;
        const char *name;
    } names[] = {
        {&vx_n.in, "in"}, {&vx_n.out, "out"}, {&vx_n.tx, "tx"}, {&vx_n.tx_bytes, "tx_bytes"}, {&vx_n.rx, "rx"},
        {&vx_n.rx_bytes, "rx_bytes"}, {&vx_n.superseded, "superseded"}, {&vx_n.drop_overflow, "drop_overflow"},
        {&vx_n.not_echoed, "not_echoed"}, {&vx_n.drop_write_error, "drop_write_error"},
        {&vx_n.drop_intake, "drop_intake"}, {&vx_n.unsent_at_close, "unsent_at_close"},
        {&vx_n.drop_jump, "drop_jump"}, {&vx_n.dropped_at_stop, "dropped_at_stop"},
        {&vx_n.a_fd, "_fd"}, {&vx_n.a_fresh, "_fresh"}, {&vx_n.a_preamble, "preamble"}, {&vx_n.a_device, "_device"},
        {&vx_n.a_outage, "_outage"}, {&vx_n.a_idle, "idle"}, {&vx_n.a_active, "active"}, {&vx_n.a_sparse, "sparse"},
        {&vx_n.a_socket, "socket"},
        {&vx_n.m_submit, "submit"}, {&vx_n.m_room, "room"}, {&vx_n.m_push, "push"}, {&vx_n.m_drain, "drain"},
        {&vx_n.m_close, "close"}, {&vx_n.m_units_of, "units_of"}, {&vx_n.m_fileno, "fileno"},
        {&vx_n.m_acquire, "acquire"}, {&vx_n.m_release, "release"},
    };
    size_t i;
    for (i = 0; i < sizeof names / sizeof names[0]; i++) {
        if ((*names[i].slot = vx_name(names[i].name)) == NULL) return -1;
    }
    return 0;
}

PyObject *vx_name(const char *name) {
    PyObject *key = PyUnicode_InternFromString(name), *found;
    if (key == NULL) return NULL;
    found = PyDict_GetItemWithError(vx_py.names, key); /* borrowed: the dict keeps every name alive */
    if (found == NULL && !PyErr_Occurred() && PyDict_SetItem(vx_py.names, key, key) == 0) found = key;
    Py_DECREF(key);
    return found;
}

int vx_count(PyObject *counters, PyObject *name, Py_ssize_t n) {
    PyObject *old, *sum, *add;
    int status;
    if (n == 0) return 0; /* Counters compare missing names as 0 */
    old = PyDict_GetItemWithError(counters, name);
    if (old == NULL && PyErr_Occurred()) return -1;
    add = PyLong_FromSsize_t(n);
    if (add == NULL) return -1;
    sum = old == NULL ? Py_NewRef(add) : PyNumber_Add(old, add);
    Py_DECREF(add);
    if (sum == NULL) return -1;
    status = PyDict_SetItem(counters, name, sum);
    Py_DECREF(sum);
    return status;
}

static PyObject *small_tuple(PyTypeObject *type, Py_ssize_t n, const long *fields) {
    /* what tuple.__new__(type, fields) builds, without the intermediate tuple */
    PyObject *obj = type->tp_alloc(type, n);
    Py_ssize_t i;
    if (obj == NULL) return NULL;
    for (i = 0; i < n; i++) {
        PyObject *item = PyLong_FromLong(fields[i]);
        if (item == NULL) {
            Py_DECREF(obj);
            return NULL;
        }
        PyTuple_SET_ITEM(obj, i, item);
    }
    return obj;
}

PyObject *vx_message(const vstig_msg_t *msg) {
    long words[4];
    words[0] = (long)(((unsigned)(msg->op & 1u) << 15) | (msg->key & VSTIG_KEY_MAX));
    words[1] = msg->value;
    words[2] = msg->timestamp;
    words[3] = msg->robot;
    return small_tuple(vx_py.message, 4, words);
}

PyObject *vx_entry(const vstig_entry_t *entry) {
    long fields[3];
    fields[0] = entry->value;
    fields[1] = entry->timestamp;
    fields[2] = entry->robot;
    return small_tuple(vx_py.entry, 3, fields);
}

int vx_msg_of(PyObject *obj, vstig_msg_t *msg) {
    long words[4];
    Py_ssize_t i;
    if (!PyTuple_Check(obj) || PyTuple_GET_SIZE(obj) != 4) {
        PyErr_Format(PyExc_TypeError, "expected a Message, got %R", obj);
        return -1;
    }
    for (i = 0; i < 4; i++) {
        words[i] = PyLong_AsLong(PyTuple_GET_ITEM(obj, i));
        if (words[i] == -1 && PyErr_Occurred()) return -1;
    }
    msg->op = (uint8_t)((words[0] >> 15) & 1);
    msg->key = (uint16_t)(words[0] & VSTIG_KEY_MAX);
    msg->value = (uint16_t)words[1];
    msg->timestamp = (uint16_t)words[2];
    msg->robot = (uint16_t)words[3];
    return 0;
}

long vx_field(const char *name, long limit, PyObject *value) {
    long n = -1;
    if (PyLong_Check(value) && !PyBool_Check(value)) {
        int overflow;
        n = PyLong_AsLongAndOverflow(value, &overflow);
        if (overflow) n = -1;
    }
    if (n < 0 || n > limit) {
        PyErr_Format(PyExc_ValueError, "%s must be an integer in 0..%ld, got %R", name, limit, value);
        return -1;
    }
    return n;
}

static int harvest(vstig_drops_t *drops, PyObject *counters, PyObject *names) {
    static const vstig_drops_t none;
    int reason;
    if (memcmp(drops, &none, sizeof none) == 0) return 0; /* the common case: a read with nothing dropped */
    for (reason = 0; reason < VSTIG_DROP_REASONS; reason++) {
        uint16_t n = drops->count[reason];
        if (n == 0) continue;
        drops->count[reason] = 0;
        if (vx_count(counters, PyTuple_GET_ITEM(names, reason), n) < 0) return -1;
    }
    return 0;
}

int vx_harvest_drops(vstig_drops_t *drops, PyObject *counters) { return harvest(drops, counters, vx_py.drop_names); }

int vx_harvest_device_drops(vstig_drops_t *drops, PyObject *counters) {
    return harvest(drops, counters, vx_py.device_drop_names);
}

static PyObject *setup(PyObject *module, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"message", "entry", "outcomes", "rules", NULL};
    PyObject *message, *entry, *outcomes, *rules;
    (void)module;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O!O!O!O!", kwlist, &PyType_Type, &message, &PyType_Type, &entry,
                                     &PyTuple_Type, &outcomes, &PyTuple_Type, &rules))
        return NULL;
    if (!PyType_IsSubtype((PyTypeObject *)message, &PyTuple_Type) ||
        !PyType_IsSubtype((PyTypeObject *)entry, &PyTuple_Type) || PyTuple_GET_SIZE(outcomes) != VSTIG_OUTCOMES ||
        PyTuple_GET_SIZE(rules) != 3) {
        PyErr_SetString(PyExc_TypeError, "setup(message, entry, outcomes, rules): Message and Entry are tuple "
                                         "types, the outcomes are Outcome's 7 members, the rules Stigmergy's 3");
        return NULL;
    }
    Py_INCREF(message);
    Py_XSETREF(vx_py.message, (PyTypeObject *)message);
    Py_INCREF(entry);
    Py_XSETREF(vx_py.entry, (PyTypeObject *)entry);
    Py_INCREF(outcomes);
    Py_XSETREF(vx_py.outcomes, outcomes);
    Py_INCREF(rules);
    Py_XSETREF(vx_py.rules, rules);
    Py_RETURN_NONE;
}

static PyMethodDef module_methods[] = {
    {"setup", (PyCFunction)(void (*)(void))setup, METH_VARARGS | METH_KEYWORDS,
     "setup(message, entry, outcomes, rules): the vstig_hw types the compiled objects hand out (once)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "vstig_hw._vstig",
    "The gateway's compiled data path over libvstig (see vstig_hw/native.py; VSTIG_PURE=1 turns it off).", -1,
    module_methods, NULL, NULL, NULL, NULL,
};

static int add_type(PyObject *module, PyTypeObject *type, const char *name) {
    if (PyType_Ready(type) < 0) return -1;
    Py_INCREF(type);
    if (PyModule_AddObject(module, name, (PyObject *)type) < 0) {
        Py_DECREF(type);
        return -1;
    }
    return 0;
}

PyMODINIT_FUNC PyInit__vstig(void) {
    PyObject *module = PyModule_Create(&module_def);
    int reason;
    if (module == NULL) return NULL;
    vx_py.names = PyDict_New();
    vx_py.drop_names = PyTuple_New(VSTIG_DROP_REASONS);
    vx_py.device_drop_names = PyTuple_New(VSTIG_DROP_REASONS);
    if (vx_py.names == NULL || vx_py.drop_names == NULL || vx_py.device_drop_names == NULL) goto fail;
    for (reason = 0; reason < VSTIG_DROP_REASONS; reason++) { /* the framings' drops: SPEC's names */
        char prefixed[64];
        PyObject *name = vx_name(vstig_drop_name((vstig_drop_t)reason)), *device_name;
        if (name == NULL) goto fail;
        PyTuple_SET_ITEM(vx_py.drop_names, reason, Py_NewRef(name));
        PyOS_snprintf(prefixed, sizeof prefixed, "drop_%s", vstig_drop_name((vstig_drop_t)reason));
        if ((device_name = vx_name(prefixed)) == NULL) goto fail;
        PyTuple_SET_ITEM(vx_py.device_drop_names, reason, Py_NewRef(device_name));
    }
    if (intern_names() < 0) goto fail;
    if (add_type(module, &vx_EngineType, "Engine") < 0 || add_type(module, &vx_JumpGuardType, "JumpGuard") < 0 ||
        add_type(module, &vx_ReceiverType, "Receiver") < 0 || add_type(module, &vx_EncoderType, "Encoder") < 0 ||
        add_type(module, &vx_WindowType, "Window") < 0 || add_type(module, &vx_OutletType, "Outlet") < 0 ||
        add_type(module, &vx_SeatType, "Seat") < 0 || add_type(module, &vx_RelayType, "Relay") < 0 ||
        add_type(module, &vx_PathType, "Path") < 0)
        goto fail;
    if (PyModule_AddIntConstant(module, "KEYS", VSTIG_KEYS) < 0) goto fail;
    return module;
fail:
    Py_DECREF(module);
    return NULL;
}
