/*
 * vstig_hw._vstig: the gateway's compiled data path, a CPython extension over libvstig
 * (firmware_spec/libvstig, built into it with every table at 32,768 places).
 *
 * Each type here is the twin of one Python class and has its interface. firmware_spec/SPEC.md is normative; the
 * Python is the reference implementation the C is held equal to (tests/native, on random traffic). Every type:
 *
 *   Engine     engine.c   vstig_hw.engine.Stigmergy              (libvstig's engine)
 *   JumpGuard  guard.c    vstig_hw.gateway.guard.Guard           (max_jump and learn only; libvstig's guard)
 *   Receiver   framing.c  a link's framing, receiving side       (libvstig's serial, CAN and XBee receivers)
 *   Encoder    framing.c  a link's framing, sending side         (libvstig's serial, CAN and XBee encoders)
 *   Window     window.c   vstig_hw.gateway.outlet.SendWindow
 *   Outlet     outlet.c   vstig_hw.gateway.outlet.Outlet         (and the transports' write_nowait)
 *   Seat       parts.c    vstig_hw.gateway.parts.Seat
 *   Relay      parts.c    vstig_hw.gateway.parts.RawRelay
 *   Path       path.c     vstig_hw.gateway.node.Node's delivery  (and the transports' reads)
 *   UdpPeers   peers.c    vstig_hw.transports.mavlink.UdpPeers   (a udpin link's peers)
 *   RosterTally roster.c  vstig_hw.gateway.roster.Roster's take and refuse
 *   PendingCounts pending.c  vstig_hw.counters.Counters's hot counts, folded in before any read
 *
 * The index of the twins, by file, is vstig_hw/_vstig.pyi's docstring.
 *
 * Python objects the types hand out (Message, Entry, Outcome...) come from vstig_hw itself,
 * given once by vstig_hw/native.py through `setup`: nothing here imports vstig_hw.
 */
#ifndef VSTIG_EXT_H
#define VSTIG_EXT_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "vstig.h"

/* What vstig_hw/native.py hands over once (module state would cost a lookup per call). */
typedef struct {
    PyTypeObject *message; /* vstig_hw.wire.Message: a tuple of the four wire words */
    PyTypeObject *entry;   /* vstig_hw.engine.Entry: (value, timestamp, robot) */
    PyObject *outcomes;    /* tuple of vstig_hw.engine.Outcome, by value */
    PyObject *rules;       /* tuple: higher_robot_wins, larger_value_wins, sum_merge (their C twins run) */
    PyObject *drop_names;  /* tuple of str: SPEC's name, by vstig_drop_t (a framing's drops) */
    PyObject *device_drop_names; /* the same with "drop_" before it (a transport's counters: XBee's cutting) */
    PyObject *names;       /* dict of interned counter names (str -> str) */
} vx_python_t;

extern vx_python_t vx_py;

/* Every name the data path uses: the counters it adds to, and each attribute or method it reads or calls on a
 * Python object, interned once (module init). module.c's table is the one list: it says which declared Python type
 * (or module) each attribute belongs to, `DECLARED` exports it, and tests/native/test_native_declared.py fails when
 * one is not declared there (a slot, an annotation, a method or property). No attribute is looked up by any other
 * name. */
typedef struct {
    /* counters (keys of a Counters, not attributes) */
    PyObject *in, *out, *tx, *tx_bytes, *rx, *rx_bytes, *superseded, *drop_overflow, *not_echoed, *drop_write_error,
        *drop_intake, *unsent_at_close, *drop_jump, *dropped_at_stop;
    /* vstig_hw.gateway.delivery_state.DeliveryState, and its Wakeup */
    PyObject *reader_thread, *failure, *wake, *retry_at, *sleep_until, *wake_on_arrival, *set;
    /* vstig_hw.transports.base.CompiledHandle, and the transports that give one */
    PyObject *fd, *fresh, *preamble, *device, *outage, *compiled_handle, *counters, *failed, *channel,
        *note_error_frame, *api, *quiet_after, *holds, *note_report, *peers, *writing, *beat;
    /* a MAVLink UDP transport's counters */
    PyObject *rx_datagrams, *tx_refused, *tx_no_peer, *tx_busy, *tx_dropped;
    /* a SocketCAN bus (socketcan_drops.DropCountingBus) and its socket */
    PyObject *socket, *fileno, *read_elsewhere, *poll_counts, *note_kernel_drops;
    /* Link, LinkWriter, the fair share's lines, Guard, Stigmergy, the Encoder, the Node's lock */
    PyObject *name, *transport, *units_of, *one_domain, *idle, *submit, *room, *close, *hold, *active, *sparse,
        *push, *drain, *filter, *check, *read_only, *confines, *put, *get, *encode_batch, *acquire, *release;
    /* a python-can Message; the time module's clocks */
    /* a refused message as told (vstig_hw.links.link.Heard) */
    PyObject *message, *t, *sender;
    PyObject *arbitration_id, *is_extended_id, *is_fd, *is_remote_frame, *is_error_frame, *data, *time, *monotonic;
    /* a python-can bus (can.BusABC), read and written by its own recv and send; a frame's time */
    PyObject *send, *recv, *timestamp;
    /* vstig_hw.counters.Counters: its hot counts held in C (pending.c) */
    PyObject *pending, *keep_pending;
} vx_names_t;

extern vx_names_t vx_n;

/* A counter name, interned once ("in", "out", "drop_jump"...). */
PyObject *vx_name(const char *name);

/* obj.<name>(*args), args built by Py_BuildValue's `format` (in parentheses: always a tuple); new reference. */
PyObject *vx_call(PyObject *obj, PyObject *name, const char *format, ...);

/* counters[name] += n on a Counters (a dict subclass); -1 with an exception set on failure. */
int vx_count(PyObject *counters, PyObject *name, Py_ssize_t n);

/* A CompiledHandle's device while the transport holds it with no outage to end (a reopened device's first call is
 * the transport's own: it ends the outage): new reference; None when not; NULL with an exception. */
PyObject *vx_live_device(PyObject *handle);

/* A declared slot of one Python class (`__slots__`), read and written at its offset in the object rather than by
 * a name lookup per access (what PyObject_GetAttr would find: the class's member descriptor). `type` is the class
 * it was resolved on; an object of any other type, or a name that is no object slot there, takes GetAttr/SetAttr. */
typedef struct {
    PyTypeObject *type; /* borrowed: the resolved object keeps it alive */
    Py_ssize_t offset;  /* 0: not a slot, use the name */
} vx_slot_t;

/* Resolves `name` on obj's class (always succeeds: an unresolved slot falls back to the name). */
void vx_slot_resolve(vx_slot_t *slot, PyObject *obj, PyObject *name);
/* slots[i] for names[i] resolved on obj's class, for objects read through one set of slots (a handle, a frame): once
 * the first resolves (a class met later reads by name where it is another), or on each new class until one does
 * (`tried`: the last class tried, compared only). */
void vx_slots_resolve_once(vx_slot_t *slots, PyObject *const *names, int n, PyObject *obj,
                           const PyTypeObject **tried);
/* obj.<name> (new reference), or NULL with an exception. */
PyObject *vx_slot_get(const vx_slot_t *slot, PyObject *obj, PyObject *name);
/* obj.<name> = value; 0, or -1 with an exception. */
int vx_slot_set(const vx_slot_t *slot, PyObject *obj, PyObject *name, PyObject *value);

/* time.time() and time.monotonic() as Python reads them (the Node compares what we set with them): on Linux the
 * same clock_gettime clocks CPython's pytime.c reads, without a call into Python; elsewhere those very calls. -1.0
 * with an exception on failure. */
double vx_time_time(void);
double vx_time_monotonic(void);

/* A Message of msg's fields (new reference), built as tuple.__new__(Message, words) is. */
PyObject *vx_message(const vstig_msg_t *msg);
/* An Entry (new reference). */
PyObject *vx_entry(const vstig_entry_t *entry);
/* msg's fields from a Message (any tuple of four ints: its wire words); 0, or -1 with TypeError. */
int vx_msg_of(PyObject *obj, vstig_msg_t *msg);

/* An int in 0..limit that is not a bool, as vstig_hw.wire.check_field has it; else -1 and
 * ValueError "<name> must be an integer in 0..<limit>, got <repr>". */
long vx_field(const char *name, long limit, PyObject *value);

/* Adds what `drops` counted to a framing's counters[reason] and clears it; -1 on failure. */
int vx_harvest_drops(vstig_drops_t *drops, PyObject *counters);
/* The same into a transport's counters["drop_<reason>"]. */
int vx_harvest_device_drops(vstig_drops_t *drops, PyObject *counters);

extern PyTypeObject vx_EngineType;
extern PyTypeObject vx_JumpGuardType;
extern PyTypeObject vx_ReceiverType;
extern PyTypeObject vx_EncoderType;

/* The engine inside an Engine object, for the other types of the data path. */
typedef struct vx_engine vx_engine_t;

#endif /* VSTIG_EXT_H */
