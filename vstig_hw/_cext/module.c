/*
 * vstig_hw._vstig: the module, `setup`, and the conversions every type shares. See ext.h.
 *
 * Reference: vstig_hw/native.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 */
#include "ext.h"

#include <stdarg.h>
#include <string.h>
#include <structmember.h>
#ifdef __linux__
#include <time.h>
#endif

#include "path.h"
#include "pending.h"
#include "peers.h"
#include "roster.h"

vx_python_t vx_py;
vx_names_t vx_n;

/* The declared Python types (or modules) the data path reads or calls attributes of, as `module:qualname`. */
#define DELIVERY_STATE "vstig_hw.gateway.delivery_state:DeliveryState"
#define WAKEUP "vstig_hw.wakeup:Wakeup"
#define HANDLE "vstig_hw.transports.base:CompiledHandle"
#define DEVICE_TRANSPORT "vstig_hw.transports.base:DeviceTransport"
#define CAN_TRANSPORT "vstig_hw.transports.can:CanTransport"
#define XBEE_TRANSPORT "vstig_hw.transports.xbee:XBeeTransport"
#define MAVLINK_UDP "vstig_hw.transports.mavlink:MavlinkUdpTransport"
#define SOCKETCAN_BUS "vstig_hw.transports.socketcan_drops:KernelDropCountingBus"
#define LINK "vstig_hw.links.link:Link"
#define WRITER "vstig_hw.gateway.writer:LinkWriter"
#define FAIR_QUEUE "vstig_hw.gateway.fairshare:FairQueue"
#define FAIR_FIFO "vstig_hw.gateway.fairshare:FairFifo"
#define GUARD "vstig_hw.gateway.guard:Guard"
#define ENGINE "vstig_hw.engine:Stigmergy"
#define ENCODER "vstig_hw._vstig:Encoder"
#define LOCK "_thread:RLock"
#define CAN_MESSAGE_TYPE "can.message:Message"
#define CAN_BUS "can.bus:BusABC"
#define TIME "time"
#define HEARD "vstig_hw.links.link:Heard"
#define COUNTERS "vstig_hw.counters:Counters"

/* The one list of the names the data path uses: each with the declared type it belongs to (NULL: a counter). A
 * name used on two types is listed under each. */
static const struct {
    PyObject **slot;
    const char *name;
    const char *declared_on;
} NAMES[] = {
    {&vx_n.in, "in", NULL}, {&vx_n.out, "out", NULL}, {&vx_n.tx, "tx", NULL}, {&vx_n.tx_bytes, "tx_bytes", NULL},
    {&vx_n.rx, "rx", NULL}, {&vx_n.rx_bytes, "rx_bytes", NULL}, {&vx_n.superseded, "superseded", NULL},
    {&vx_n.drop_overflow, "drop_overflow", NULL}, {&vx_n.not_echoed, "not_echoed", NULL},
    {&vx_n.drop_write_error, "drop_write_error", NULL}, {&vx_n.drop_intake, "drop_intake", NULL},
    {&vx_n.unsent_at_close, "unsent_at_close", NULL}, {&vx_n.drop_jump, "drop_jump", NULL},
    {&vx_n.dropped_at_stop, "dropped_at_stop", NULL}, {&vx_n.rx_datagrams, "rx_datagrams", NULL},
    {&vx_n.tx_refused, "tx_refused", NULL}, {&vx_n.tx_no_peer, "tx_no_peer", NULL}, {&vx_n.tx_busy, "tx_busy", NULL},
    {&vx_n.tx_dropped, "tx_dropped", NULL},
    {&vx_n.reader_thread, "reader_thread", DELIVERY_STATE}, {&vx_n.failure, "failure", DELIVERY_STATE},
    {&vx_n.wake, "wake", DELIVERY_STATE}, {&vx_n.retry_at, "retry_at", DELIVERY_STATE},
    {&vx_n.sleep_until, "sleep_until", DELIVERY_STATE}, {&vx_n.wake_on_arrival, "wake_on_arrival", DELIVERY_STATE},
    {&vx_n.set, "set", WAKEUP},
    {&vx_n.fd, "fd", HANDLE}, {&vx_n.fresh, "fresh", HANDLE}, {&vx_n.preamble, "preamble", HANDLE},
    {&vx_n.device, "device", HANDLE}, {&vx_n.outage, "outage", HANDLE}, {&vx_n.peers, "peers", HANDLE},
    {&vx_n.writing, "writing", HANDLE},
    {&vx_n.compiled_handle, "compiled_handle", DEVICE_TRANSPORT}, {&vx_n.counters, "counters", DEVICE_TRANSPORT},
    {&vx_n.failed, "failed", DEVICE_TRANSPORT},
    {&vx_n.channel, "channel", CAN_TRANSPORT}, {&vx_n.note_error_frame, "note_error_frame", CAN_TRANSPORT},
    {&vx_n.api, "api", XBEE_TRANSPORT}, {&vx_n.quiet_after, "quiet_after", XBEE_TRANSPORT},
    {&vx_n.holds, "holds", XBEE_TRANSPORT}, {&vx_n.note_report, "note_report", XBEE_TRANSPORT},
    {&vx_n.beat, "beat", MAVLINK_UDP},
    {&vx_n.fileno, "fileno", SOCKETCAN_BUS}, {&vx_n.read_elsewhere, "read_elsewhere", SOCKETCAN_BUS},
    {&vx_n.poll_counts, "poll_counts", SOCKETCAN_BUS}, {&vx_n.note_kernel_drops, "note_kernel_drops", SOCKETCAN_BUS},
    {&vx_n.name, "name", LINK}, {&vx_n.counters, "counters", LINK}, {&vx_n.transport, "transport", LINK},
    {&vx_n.units_of, "units_of", LINK}, {&vx_n.one_domain, "one_domain", LINK},
    {&vx_n.idle, "idle", WRITER}, {&vx_n.submit, "submit", WRITER}, {&vx_n.room, "room", WRITER},
    {&vx_n.close, "close", WRITER}, {&vx_n.hold, "hold", WRITER},
    {&vx_n.active, "active", FAIR_QUEUE}, {&vx_n.sparse, "sparse", FAIR_QUEUE}, {&vx_n.push, "push", FAIR_QUEUE},
    {&vx_n.drain, "drain", FAIR_QUEUE},
    {&vx_n.active, "active", FAIR_FIFO}, {&vx_n.sparse, "sparse", FAIR_FIFO}, {&vx_n.push, "push", FAIR_FIFO},
    {&vx_n.drain, "drain", FAIR_FIFO},
    {&vx_n.filter, "filter", GUARD}, {&vx_n.check, "check", GUARD}, {&vx_n.read_only, "read_only", GUARD},
    {&vx_n.confines, "confines", GUARD},
    {&vx_n.put, "put", ENGINE}, {&vx_n.get, "get", ENGINE}, {&vx_n.encode_batch, "encode_batch", ENCODER},
    {&vx_n.acquire, "acquire", LOCK}, {&vx_n.release, "release", LOCK},
    {&vx_n.arbitration_id, "arbitration_id", CAN_MESSAGE_TYPE}, {&vx_n.is_extended_id, "is_extended_id",
    CAN_MESSAGE_TYPE}, {&vx_n.is_fd, "is_fd", CAN_MESSAGE_TYPE}, {&vx_n.is_remote_frame, "is_remote_frame",
    CAN_MESSAGE_TYPE}, {&vx_n.is_error_frame, "is_error_frame", CAN_MESSAGE_TYPE},
    {&vx_n.data, "data", CAN_MESSAGE_TYPE}, {&vx_n.timestamp, "timestamp", CAN_MESSAGE_TYPE},
    {&vx_n.send, "send", CAN_BUS}, {&vx_n.recv, "recv", CAN_BUS},
    {&vx_n.message, "message", HEARD}, {&vx_n.t, "t", HEARD}, {&vx_n.sender, "sender", HEARD},
    {&vx_n.time, "time", TIME}, {&vx_n.monotonic, "monotonic", TIME},
    {&vx_n.pending, "pending", COUNTERS}, {&vx_n.keep_pending, "keep_pending", COUNTERS},
};

static int intern_names(void) {
    size_t i;
    for (i = 0; i < sizeof NAMES / sizeof NAMES[0]; i++) {
        if ((*NAMES[i].slot = vx_name(NAMES[i].name)) == NULL) return -1;
    }
    return 0;
}

/* DECLARED: {"module:qualname": (attribute names...)} from NAMES, for the test that holds them declared. */
static PyObject *declared_names(void) {
    PyObject *declared = PyDict_New();
    size_t i;
    for (i = 0; declared != NULL && i < sizeof NAMES / sizeof NAMES[0]; i++) {
        PyObject *names, *one, *grown;
        if (NAMES[i].declared_on == NULL) continue;
        names = PyDict_GetItemString(declared, NAMES[i].declared_on); /* borrowed */
        one = PyTuple_Pack(1, *NAMES[i].slot);
        grown = one == NULL || names == NULL ? Py_XNewRef(one) : PySequence_Concat(names, one);
        if (grown == NULL || PyDict_SetItemString(declared, NAMES[i].declared_on, grown) < 0) Py_CLEAR(declared);
        Py_XDECREF(one);
        Py_XDECREF(grown);
    }
    return declared;
}

PyObject *vx_live_device(PyObject *handle) {
    static vx_slot_t slots[2]; /* CompiledHandle's `device` and `outage` */
    static const PyTypeObject *tried;
    PyObject *const names[2] = {vx_n.device, vx_n.outage}, *device, *outage;
    int recovering;
    vx_slots_resolve_once(slots, names, 2, handle, &tried);
    device = vx_slot_get(&slots[0], handle, vx_n.device);
    if (device == NULL || device == Py_None) return device;
    outage = vx_slot_get(&slots[1], handle, vx_n.outage);
    recovering = outage == NULL ? -1 : PyObject_IsTrue(outage);
    Py_XDECREF(outage);
    if (recovering == 0) return device;
    Py_DECREF(device);
    return recovering < 0 ? NULL : Py_NewRef(Py_None);
}

PyObject *vx_call(PyObject *obj, PyObject *name, const char *format, ...) {
    PyObject *method = PyObject_GetAttr(obj, name), *args, *result;
    va_list va;
    if (method == NULL) return NULL;
    va_start(va, format);
    args = Py_VaBuildValue(format, va);
    va_end(va);
    if (args == NULL || !PyTuple_Check(args)) {
        if (args != NULL) PyErr_Format(PyExc_SystemError, "vx_call's format must build a tuple: %s", format);
        Py_DECREF(method);
        Py_XDECREF(args);
        return NULL;
    }
    result = PyObject_Call(method, args, NULL);
    Py_DECREF(method);
    Py_DECREF(args);
    return result;
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
    Py_ssize_t was = -1;
    int status;
    if (n == 0) return 0; /* Counters compare missing names as 0 */
    old = PyDict_GetItemWithError(counters, name);
    if (old == NULL && PyErr_Occurred()) return -1;
    if (old != NULL && PyLong_CheckExact(old) && (was = PyLong_AsSsize_t(old)) == -1 && PyErr_Occurred())
        PyErr_Clear(); /* beyond a Py_ssize_t: PyNumber_Add below */
    if (old == NULL || (n > 0 && was >= 0 && was <= PY_SSIZE_T_MAX - n)) { /* the common case: no int object more */
        sum = PyLong_FromSsize_t(old == NULL ? n : was + n);
    } else {
        add = PyLong_FromSsize_t(n);
        if (add == NULL) return -1;
        sum = PyNumber_Add(old, add);
        Py_DECREF(add);
    }
    if (sum == NULL) return -1;
    status = PyDict_SetItem(counters, name, sum);
    Py_DECREF(sum);
    return status;
}

void vx_slot_resolve(vx_slot_t *slot, PyObject *obj, PyObject *name) {
    PyObject *descr = PyObject_GetAttr((PyObject *)Py_TYPE(obj), name); /* a slot: the class's member descriptor */
    slot->type = NULL;
    slot->offset = 0;
    if (descr == NULL) {
        PyErr_Clear(); /* no such attribute on the class: GetAttr then tells the name */
        return;
    }
    if (Py_IS_TYPE(descr, &PyMemberDescr_Type) && ((PyMemberDescrObject *)descr)->d_member->type == T_OBJECT_EX &&
        !(((PyMemberDescrObject *)descr)->d_member->flags & READONLY)) {
        slot->type = (PyTypeObject *)Py_NewRef((PyObject *)Py_TYPE(obj)); /* a class: held for the process's life */
        slot->offset = ((PyMemberDescrObject *)descr)->d_member->offset;
    }
    Py_DECREF(descr);
}

void vx_slots_resolve_once(vx_slot_t *slots, PyObject *const *names, int n, PyObject *obj,
                           const PyTypeObject **tried) {
    int i;
    if (slots[0].offset != 0 || Py_TYPE(obj) == *tried) return;
    *tried = Py_TYPE(obj);
    for (i = 0; i < n; i++) vx_slot_resolve(&slots[i], obj, names[i]);
}

PyObject *vx_slot_get(const vx_slot_t *slot, PyObject *obj, PyObject *name) {
    PyObject *value;
    if (slot->offset == 0 || Py_TYPE(obj) != slot->type) return PyObject_GetAttr(obj, name);
    value = *(PyObject **)((char *)obj + slot->offset);
    return value == NULL ? PyObject_GetAttr(obj, name) : Py_NewRef(value); /* unset: GetAttr raises as Python does */
}

int vx_slot_set(const vx_slot_t *slot, PyObject *obj, PyObject *name, PyObject *value) {
    PyObject **field, *old;
    if (slot->offset == 0 || Py_TYPE(obj) != slot->type) return PyObject_SetAttr(obj, name, value);
    field = (PyObject **)((char *)obj + slot->offset);
    old = *field;
    *field = Py_NewRef(value);
    Py_XDECREF(old);
    return 0;
}

#ifdef __linux__
static double clock_seconds(clockid_t clock) {
    struct timespec now;
    if (clock_gettime(clock, &now) != 0) {
        PyErr_SetFromErrno(PyExc_OSError);
        return -1.0;
    }
    return (double)now.tv_sec + (double)now.tv_nsec * 1e-9; /* as pytime.c's _PyTime_AsSecondsDouble rounds */
}

double vx_time_time(void) { return clock_seconds(CLOCK_REALTIME); }

double vx_time_monotonic(void) { return clock_seconds(CLOCK_MONOTONIC); }
#else
static double python_clock(PyObject *name) {
    PyObject *time_module = PyImport_ImportModule("time"), *now;
    double seconds;
    if (time_module == NULL) return -1.0;
    now = PyObject_CallMethodNoArgs(time_module, name);
    Py_DECREF(time_module);
    seconds = now == NULL ? -1.0 : PyFloat_AsDouble(now);
    Py_XDECREF(now);
    return seconds;
}

double vx_time_time(void) { return python_clock(vx_n.time); }

double vx_time_monotonic(void) { return python_clock(vx_n.monotonic); }
#endif

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
    PyObject *module = PyModule_Create(&module_def), *declared;
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
        add_type(module, &vx_PathType, "Path") < 0 ||
        add_type(module, &vx_RosterTallyType, "RosterTally") < 0 ||
        add_type(module, &vx_UdpPeersType, "UdpPeers") < 0 ||
        add_type(module, &vx_PendingCountsType, "PendingCounts") < 0)
        goto fail;
    if (PyModule_AddIntConstant(module, "KEYS", VSTIG_KEYS) < 0) goto fail;
    if ((declared = declared_names()) == NULL || PyModule_AddObject(module, "DECLARED", declared) < 0) {
        Py_XDECREF(declared);
        goto fail;
    }
    return module;
fail:
    Py_DECREF(module);
    return NULL;
}
