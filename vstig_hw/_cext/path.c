/*
 * Path: a Node's delivery in C (vstig_hw.gateway.delivery.Delivery.deliver and arrive, then Outbound.spread), one
 * call per read.
 *
 * Reference: vstig_hw/gateway/delivery.py vstig_hw/gateway/outbound.py vstig_hw/gateway/delivery_state.py
 *   vstig_hw/transports/serial.py
 *   vstig_hw/transports/can.py vstig_hw/transports/xbee.py vstig_hw/transports/mavlink.py (held equal by
 *   tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 *
 * `pump(index, timeout)` reads a link's device itself where it has an fd (a serial port, a SocketCAN socket, a
 * MAVLink UDP socket: the GIL is released while it waits), and hands what it read on; `deliver(index, t, units)`
 * takes what a transport's own read returned. Either way, while no listener wants each unit or every `Heard` (`unit`,
 * `heard`) and the Node's lock is free, the whole batch is done here: decode (the link's Receiver), the engine's
 * intake per source, the guard (telling the `refused` listeners), the `messages` listeners, the part (Seat or
 * Relay; a Seat tells the `change` listeners), the engine's outbox onto the outlets, and the outlets' sends
 * (straight to the devices while their writers are idle). Otherwise the batch goes to the
 * Node's Python delivery, the reference, which does the same with the same objects (decoding with the same
 * Receiver, so a frame cut across two reads is whole either way).
 *
 * What it shares with the Node is declared: its lock, and its DeliveryState (vstig_hw/gateway/delivery_state.py):
 * `reader_thread`, `failure` and `wake` (a listener or rule that raised ends the Node's loop, on its thread),
 * `retry_at`, `sleep_until` and `wake_on_arrival` (when the loop must look); a device it reads, through the
 * transport's CompiledHandle. While its readers stop (`stopping`), every batch takes the Python delivery, which
 * decides what a stop hands on and what it counts.
 */
#include "path.h"
#include "peers.h"
#include "roster.h"

#include <errno.h>
#include <time.h>
#include <string.h>
#include <structmember.h>
#ifndef _WIN32
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>
#endif

#define READ_SIZE 65536 /* bytes one serial read takes at most (SerialTransport's _READ_SIZE) */
#define DRAIN_LIMIT 512 /* CAN frames one read takes after the first (CanTransport's _DRAIN_LIMIT) */
#define POLL_COUNTS_S 1.0 /* how often a SocketCAN bus's own drop counts are polled (socketcan_drops) */
#define STATE_POLL_S 1.0  /* how often a python-can bus's read is the transport's (CanTransport's _STATE_POLL_S) */
#define ALONE_S 0.001     /* a frame read within this of its timestamp ends the read (CanTransport's _ALONE_S) */
#define DATAGRAMS_PER_READ 64 /* datagrams one UDP read takes at most (MavlinkUdpTransport's _DATAGRAMS_PER_READ) */
#define DATAGRAM 65535        /* bytes a datagram read takes at most (its _DATAGRAM) */

static PyObject *CAN_MESSAGE;

/* time.time() and time.monotonic() as the Python delivery reads them (ext.h; -1.0 with an exception on failure). */
static double wall_clock(void) { return vx_time_time(); }

static double monotonic(void) { return vx_time_monotonic(); }

/* ---- one batch: _arrive ---------------------------------------------------------------- */

static int room_for(vx_path_t *p, size_t n) {
    vstig_msg_t *grown;
    if (n <= p->cap) return 0;
    grown = PyMem_Realloc(p->msgs, n * sizeof *grown);
    if (grown == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    p->msgs = grown;
    p->cap = n;
    return 0;
}

/* A Python Guard's filter over C messages (its own work: only JumpGuards are C's). */
static int python_guard(vx_path_t *p, vx_link_t *link, PyObject *sender, double t, vstig_msg_t *msgs, size_t *n) {
    PyObject *list = PyList_New((Py_ssize_t)*n), *kept;
    Py_ssize_t i;
    for (i = 0; list != NULL && i < (Py_ssize_t)*n; i++) {
        PyObject *m = vx_message(&msgs[i]);
        if (m == NULL) Py_CLEAR(list);
        else PyList_SET_ITEM(list, i, m);
    }
    if (list == NULL) return -1;
    kept = vx_call(p->guard, vx_n.filter, "(OOOdOO)", link->name, sender, list, t, link->counters, Py_None);
    Py_DECREF(list);
    if (kept == NULL) return -1;
    if (!PyList_Check(kept) || PyList_GET_SIZE(kept) > (Py_ssize_t)*n) {
        Py_DECREF(kept);
        PyErr_SetString(PyExc_TypeError, "a guard's filter returns a list of the messages that pass");
        return -1;
    }
    *n = (size_t)PyList_GET_SIZE(kept);
    for (i = 0; i < (Py_ssize_t)*n; i++) {
        if (vx_msg_of(PyList_GET_ITEM(kept, i), &msgs[i]) < 0) {
            Py_DECREF(kept);
            return -1;
        }
    }
    Py_DECREF(kept);
    return 0;
}

/* The listeners a batch's delivery tells here (tuples: the Node replaces them, never changes them). */
typedef struct {
    PyObject *messages; /* `messages`: what each unit carried past the guard */
    PyObject *refused;  /* `refused`: each message the guard refused, with its drop counter's name */
    Py_ssize_t python_messages, python_refused; /* of them, Python code (a RosterTally is fed here in C) */
} vx_told_t;

/* The Node's `messages` listeners, told what one unit carried past the guard, in their order (Node._arrive); a
 * roster's tally in C, the others with a list of Message built once. */
static int tell_messages(const vx_link_t *link, double t, PyObject *sender, int named, unsigned long long sender_id,
                         const vstig_msg_t *msgs, size_t n, const vx_told_t *told) {
    PyObject *listeners = told->messages, *list = NULL, *when = NULL;
    Py_ssize_t i;
    int status = 0;
    if (told->python_messages) {
        list = PyList_New((Py_ssize_t)n);
        when = PyFloat_FromDouble(t);
        status = list == NULL || when == NULL ? -1 : 0;
    }
    for (i = 0; status == 0 && list != NULL && i < (Py_ssize_t)n; i++) {
        PyObject *m = vx_message(&msgs[i]);
        if (m == NULL) status = -1;
        else PyList_SET_ITEM(list, i, m);
    }
    for (i = 0; status == 0 && i < PyTuple_GET_SIZE(listeners); i++) {
        vx_tally_t *tally = vx_tally_of_take(PyTuple_GET_ITEM(listeners, i));
        PyObject *done;
        if (tally != NULL) {
            status = vx_tally_take(tally, link->name, t, named, sender_id, msgs, n);
            continue;
        }
        done = PyObject_CallFunctionObjArgs(PyTuple_GET_ITEM(listeners, i), link->name, when, sender, list, NULL);
        if (done == NULL) status = -1;
        Py_XDECREF(done);
    }
    Py_XDECREF(list);
    Py_XDECREF(when);
    return status;
}

/* Node._judge_and_tell (no `heard` listeners: they take the Python delivery): the guard asked message by message,
 * each refused one counted, then told to the `refused` listeners as a Heard; the ones that pass kept in place. */
static int judge_telling(vx_path_t *p, const vx_link_t *link, double t, PyObject *sender, vstig_msg_t *msgs,
                         size_t *n, PyObject *refused) {
    int jump = PyObject_TypeCheck(p->guard, &vx_JumpGuardType), status = 0;
    uint32_t now = vx_guard_units(t);
    PyObject *when = PyFloat_FromDouble(t);
    size_t i, kept = 0;
    Py_ssize_t k;
    if (when == NULL) return -1;
    for (i = 0; status == 0 && i < *n; i++) {
        PyObject *m = vx_message(&msgs[i]), *reason = NULL, *heard;
        if (m != NULL && jump) {
            reason = Py_NewRef(vx_guard_passes((vx_guard_t *)p->guard, &msgs[i], now) ? Py_None : vx_n.drop_jump);
        } else if (m != NULL) {
            reason = PyObject_CallMethodObjArgs(p->guard, vx_n.check, link->name, sender, m, when, Py_None, NULL);
        }
        if (reason == NULL || (reason != Py_None && !PyUnicode_Check(reason))) {
            if (reason != NULL) PyErr_Format(PyExc_TypeError, "a guard's check returns None or a counter's name, "
                                             "got %R", reason);
            status = -1;
        } else if (reason == Py_None) {
            msgs[kept++] = msgs[i];
        } else if ((status = vx_count(link->counters, reason, 1)) == 0) {
            heard = PyObject_CallFunctionObjArgs(p->heard, m, link->name, when, sender, NULL);
            status = heard == NULL ? -1 : 0;
            for (k = 0; status == 0 && k < PyTuple_GET_SIZE(refused); k++) {
                PyObject *done = PyObject_CallFunctionObjArgs(PyTuple_GET_ITEM(refused, k), heard, reason, NULL);
                if (done == NULL) status = -1;
                Py_XDECREF(done);
            }
            Py_XDECREF(heard);
        }
        Py_XDECREF(reason);
        Py_XDECREF(m);
    }
    Py_DECREF(when);
    *n = kept;
    return status;
}

/* Past the engine's intake: the guard, the `messages` listeners, the part. `sender`: as Python's (None: unsaid),
 * and as C's (`named`, `sender_id`). */
static int judge_and_take(vx_path_t *p, Py_ssize_t index, double t, vstig_msg_t *msgs, size_t n, PyObject *sender,
                          int named, unsigned long long sender_id, const vx_told_t *told) {
    vx_link_t *link = &p->links[index];
    PyObject *part = p->part;
    int jump = p->guard != Py_None && PyObject_TypeCheck(p->guard, &vx_JumpGuardType);
    if (p->guard != Py_None && PyTuple_GET_SIZE(told->refused) && (told->python_refused || !jump)) {
        if (judge_telling(p, link, t, sender, msgs, &n, told->refused) < 0) return -1;
    } else if (p->guard != Py_None) {
        if (jump) { /* the refused ones told to the rosters' tallies, if any listen, in C */
            uint32_t now = vx_guard_units(t);
            size_t i, kept = 0;
            Py_ssize_t k;
            for (i = 0; i < n; i++) {
                if (vx_guard_passes((vx_guard_t *)p->guard, &msgs[i], now)) msgs[kept++] = msgs[i];
                else for (k = 0; k < PyTuple_GET_SIZE(told->refused); k++)
                    vx_tally_refuse((vx_tally_t *)PyTuple_GET_ITEM(told->refused, k), t, named, sender_id, &msgs[i]);
            }
            if (vx_count(link->counters, vx_n.drop_jump, (Py_ssize_t)(n - kept)) < 0) return -1;
            n = kept;
        } else if (python_guard(p, link, sender, t, msgs, &n) < 0) {
            return -1;
        }
    }
    if (n == 0) return 0;
    if (PyTuple_GET_SIZE(told->messages) && tell_messages(link, t, sender, named, sender_id, msgs, n, told) < 0)
        return -1;
    if (part == Py_None) return 0;
    if (PyObject_TypeCheck(part, &vx_SeatType)) return vx_seat_take((vx_seat_t *)part, index, msgs, n, sender, Py_None);
    return vx_relay_take((vx_relay_t *)part, index, msgs, n, Py_None);
}

/* What one unit carried, after its decoding: Node._arrive's steps for it. `sender`: who the medium says sent it (a
 * CAN node, an XBee module's 64-bit address), when `named`; `told`: this batch's listeners told here. */
static int arrive_checked(vx_path_t *p, Py_ssize_t index, double t, vstig_msg_t *msgs, size_t n, int named,
                          unsigned long long sender, const vx_told_t *told) {
    PyObject *part = p->part, *who;
    int seat = part != Py_None && PyObject_TypeCheck(part, &vx_SeatType), telling = 0, status;
    if (n == 0) return 0;
    if (seat && ((vx_seat_t *)part)->intake_obj != Py_None &&
        vx_seat_admit((vx_seat_t *)part, index, Py_None, n, t, &n) < 0) /* the engine's intake, before any other work */
        return -1;
    if (n == 0) return 0;
    /* the sender as a Python object only where Python code is told it (a Python guard, a listener) */
    if (seat && (telling = vx_seat_listening((vx_seat_t *)part)) < 0) return -1;
    if (!named || !(telling || told->python_messages || told->python_refused ||
                    (p->guard != Py_None && !PyObject_TypeCheck(p->guard, &vx_JumpGuardType))))
        return judge_and_take(p, index, t, msgs, n, Py_None, named, sender, told);
    if ((who = PyLong_FromUnsignedLongLong(sender)) == NULL) return -1;
    status = judge_and_take(p, index, t, msgs, n, who, named, sender, told);
    Py_DECREF(who);
    return status;
}

/* An engine given the swarm key (tags.c): each unit checked by its link's policy before anything else
 * (Signing.check), its records the engine's while it takes the unit. */
static int arrive(vx_path_t *p, Py_ssize_t index, double t, vstig_msg_t *msgs, size_t n, int named,
                  unsigned long long sender, const vx_told_t *told) {
    vx_rx_t *rx = &p->links[index].receiver->rx;
    vx_tags_t *tags = p->part != Py_None && PyObject_TypeCheck(p->part, &vx_SeatType)
                          ? ((vx_seat_t *)p->part)->engine->tags : NULL;
    int status = 0;
    if (tags != NULL && n != 0)
        status = vx_tags_check_unit(tags, rx->policy, &rx->records, rx->refuse, t, msgs, &n, named, sender,
                                    told->refused);
    if (status == 0) status = arrive_checked(p, index, t, msgs, n, named, sender, told);
    if (tags != NULL) vx_tags_unit_done(tags, &rx->records);
    vx_rx_unit_done(rx);
    return status;
}

/* A serial read's bytes: one unit (an XBee or MAVLink transport's: whole frames, which name their sender). */
static int arrive_bytes(vx_path_t *p, Py_ssize_t index, double t, const uint8_t *data, size_t len, size_t *heard,
                        const vx_told_t *told) {
    vx_rx_t *rx = &p->links[index].receiver->rx;
    size_t at = 0, n = 0, used;
    if (room_for(p, len / 4u + 64u) < 0) return -1; /* the shortest frame is 4 bytes: room for all a read holds */
    if (rx->kind == VX_XBEE || rx->kind == VX_MAVLINK) {
        n = vx_rx_whole(rx, data, len, p->msgs);
        if (vx_rx_harvest(rx) < 0) return -1;
        *heard += n;
        return arrive(p, index, t, p->msgs, n, rx->has_sender, rx->sender, told);
    }
    while (at < len) {
        n += vx_rx_bytes(rx, data + at, len - at, &used, p->msgs + n, p->cap - n);
        at += used;
    }
    if (vx_rx_harvest(rx) < 0) return -1;
    *heard += n;
    return arrive(p, index, t, p->msgs, n, 0, 0, told);
}

/* One CAN frame: one unit; its sender is the node its ID names. */
static int arrive_frame(vx_path_t *p, Py_ssize_t index, double t, const vstig_can_frame_t *frame, size_t *heard,
                        const vx_told_t *told) {
    vx_rx_t *rx = &p->links[index].receiver->rx;
    uint16_t sender = 0;
    size_t n;
    if (room_for(p, 8) < 0) return -1;
    n = vx_rx_frame(rx, frame, p->msgs, &sender);
    if (vx_rx_harvest(rx) < 0) return -1;
    *heard += n;
    return arrive(p, index, t, p->msgs, n, n != 0, sender, told);
}

/* ---- _spread --------------------------------------------------------------------------- */

/* The engine's outbox onto the outlets, then every outlet sends what its budget allows; the ones of link
 * `heard_on` last (its robots heard those frames when we did). Node._retry_at: when a window reopens. */
static int spread(vx_path_t *p, Py_ssize_t heard_on, double now, int *held_back, double *when_back) {
    Py_ssize_t i, n = PyList_GET_SIZE(p->outlets), k;
    int any = 0, status = 0;
    double retry = 0.0;
    PyObject *value;
    if (p->part != Py_None && PyObject_TypeCheck(p->part, &vx_SeatType) && vx_seat_queue_out((vx_seat_t *)p->part) < 0)
        return -1;
    for (k = 0; k <= n; k++) {
        double when;
        int again;
        i = k < n ? k : heard_on;
        if (i == heard_on && k < n) continue;
        if (i < 0 || i >= n) continue;
        again = vx_outlet_flush((vx_outlet_t *)PyList_GET_ITEM(p->outlets, i), now, &when);
        if (again < 0) return -1;
        if (again && (!any || when < retry)) {
            retry = when;
            any = 1;
        }
    }
    *held_back = any;
    *when_back = retry;
    value = any ? PyFloat_FromDouble(retry) : Py_NewRef(Py_None);
    if (value == NULL || vx_slot_set(&p->retry_at, p->state, vx_n.retry_at, value) < 0) status = -1;
    Py_XDECREF(value);
    return status;
}

/* ---- _deliver ------------------------------------------------------------------------- */

typedef struct {
    uint8_t kind; /* 0: Python units (a list), 1: bytes, 2: frames, 3: XBee frames (data, each unit_len[i] bytes) */
    PyObject *units;
    const uint8_t *data;
    const uint16_t *unit_len;
    size_t len;
    const vstig_can_frame_t *frames;
    size_t nframes;
} vx_batch_t;

static int arrive_batch(vx_path_t *p, Py_ssize_t index, double t, const vx_batch_t *batch,
                        const vx_told_t *told) {
    vx_link_t *link = &p->links[index];
    size_t heard = 0, i;
    int status = 0;
    if (batch->kind == 1) {
        status = arrive_bytes(p, index, t, batch->data, batch->len, &heard, told);
    } else if (batch->kind == 3) {
        size_t at = 0;
        for (i = 0; status == 0 && i < batch->len; at += batch->unit_len[i++])
            status = arrive_bytes(p, index, t, batch->data + at, batch->unit_len[i], &heard, told);
    } else if (batch->kind == 2) {
        for (i = 0; status == 0 && i < batch->nframes; i++) status = arrive_frame(p, index, t, &batch->frames[i], &heard, told);
    } else {
        for (i = 0; status == 0 && i < (size_t)PyList_GET_SIZE(batch->units); i++) {
            PyObject *unit = PyList_GET_ITEM(batch->units, i);
            if (link->receiver->rx.kind == VX_CAN) {
                vstig_can_frame_t frame;
                status = vx_frame_of(unit, &frame);
                if (status == 0) status = arrive_frame(p, index, t, &frame, &heard, told);
            } else {
                Py_buffer data;
                if ((status = PyObject_GetBuffer(unit, &data, PyBUF_SIMPLE)) == 0) {
                    status = arrive_bytes(p, index, t, data.buf, (size_t)data.len, &heard, told);
                    PyBuffer_Release(&data);
                }
            }
        }
    }
    if (status == 0) status = VX_HOT(link, IN, (Py_ssize_t)heard);
    return status;
}

/* A listener or rule raised on a reader thread: the loop raises it on its thread (Delivery.deliver's rule). */
static void fail(vx_path_t *p) {
    PyObject *type, *value, *tb, *failure, *wake, *done;
    PyErr_Fetch(&type, &value, &tb);
    PyErr_NormalizeException(&type, &value, &tb);
    if (tb != NULL && value != NULL) PyException_SetTraceback(value, tb);
    failure = PyObject_GetAttr(p->state, vx_n.failure);
    if (failure == Py_None && value != NULL) (void)PyObject_SetAttr(p->state, vx_n.failure, value);
    Py_XDECREF(failure);
    wake = PyObject_GetAttr(p->state, vx_n.wake);
    done = wake == NULL ? NULL : PyObject_CallMethodNoArgs(wake, vx_n.set);
    Py_XDECREF(wake);
    Py_XDECREF(done);
    PyErr_Clear();
    Py_XDECREF(type);
    Py_XDECREF(value);
    Py_XDECREF(tb);
}

static PyObject *thread_ident(void) { return PyLong_FromUnsignedLong(PyThread_get_thread_ident()); }

/* Whether Python code of the user's may run within a delivery (a Python guard, a conflict rule, a listener): it
 * may ask whether it runs on the Node's thread (Node.on_node_thread), which the reader thread then must be. 1, 0,
 * or -1 on error. */
static int calls_python(const vx_path_t *p, const vx_told_t *told) {
    int seat = p->part != Py_None && PyObject_TypeCheck(p->part, &vx_SeatType);
    if (told->python_messages || told->python_refused) return 1;
    if (p->guard != Py_None && !PyObject_TypeCheck(p->guard, &vx_JumpGuardType)) return 1;
    if (seat && vx_engine_calls_python(((vx_seat_t *)p->part)->engine)) return 1;
    return seat ? vx_seat_listening((vx_seat_t *)p->part) : 0;
}

/* This batch's listeners told here: the tuples the Node's list holds now ([messages, refused]); 0 or -1. */
static int told_now(const vx_path_t *p, vx_told_t *told) {
    Py_ssize_t n = PyList_GET_SIZE(p->told);
    told->messages = n > 0 ? PySequence_Tuple(PyList_GET_ITEM(p->told, 0)) : PyTuple_New(0);
    told->refused = n > 1 ? PySequence_Tuple(PyList_GET_ITEM(p->told, 1)) : PyTuple_New(0);
    if (told->messages != NULL && told->refused != NULL) {
        Py_ssize_t i;
        told->python_messages = told->python_refused = 0;
        for (i = 0; i < PyTuple_GET_SIZE(told->messages); i++)
            told->python_messages += vx_tally_of_take(PyTuple_GET_ITEM(told->messages, i)) == NULL;
        for (i = 0; i < PyTuple_GET_SIZE(told->refused); i++)
            told->python_refused += !PyObject_TypeCheck(PyTuple_GET_ITEM(told->refused, i), &vx_RosterTallyType);
        return 0;
    }
    Py_CLEAR(told->messages);
    Py_CLEAR(told->refused);
    return -1;
}

/* Whether a listener wants what the Python delivery alone gives (each unit, every `Heard`) now: the Node's lists
 * may gain one at any time. */
static int listened(const vx_path_t *p) {
    Py_ssize_t i;
    for (i = 0; i < PyList_GET_SIZE(p->listeners); i++) {
        PyObject *kind = PyList_GET_ITEM(p->listeners, i);
        if (PyList_Check(kind) ? PyList_GET_SIZE(kind) != 0 : PyObject_IsTrue(kind) != 0) return 1;
    }
    return 0;
}

/* The Node's `delivered` listeners, told of a batch handled (Delivery.deliver tells them after the spread). */
static int tell_delivered(const vx_path_t *p, double t) {
    Py_ssize_t i;
    PyObject *when;
    if (PyList_GET_SIZE(p->delivered) == 0) return 0;
    if ((when = PyFloat_FromDouble(t)) == NULL) return -1;
    for (i = 0; i < PyList_GET_SIZE(p->delivered); i++) {
        PyObject *done = PyObject_CallOneArg(PyList_GET_ITEM(p->delivered, i), when);
        if (done == NULL) {
            Py_DECREF(when);
            return -1;
        }
        Py_DECREF(done);
    }
    Py_DECREF(when);
    return 0;
}

/* 1: the batch was delivered here; 0: it takes the Python delivery (the lock was busy, a stop is under way, or
 * a listener wants it per unit); -1: an error of our own. */
static int deliver_fast(vx_path_t *p, Py_ssize_t index, double t, const vx_batch_t *batch, const double *now) {
    PyObject *got, *ident, *wake_on, *sleep;
    vx_told_t told;
    int taking_now, status, held_back = 0, python;
    double sleep_until = 0.0, retry = 0.0;
    if (!p->fast || p->stopping || p->links[index].receiver == NULL || listened(p)) return 0;
    got = PyObject_CallOneArg(p->acquire, Py_False);
    if (got == NULL) return -1;
    status = PyObject_IsTrue(got);
    Py_DECREF(got);
    if (status <= 0) return status;
    taking_now = !p->stopping; /* a stop under way: the Python delivery knows what to hand on and count */
    if (taking_now <= 0) {
        got = PyObject_CallNoArgs(p->release);
        Py_XDECREF(got);
        return taking_now < 0 || got == NULL ? -1 : 0;
    }
    /* this batch's listeners told here; Python code of the user's may ask whether it runs on the Node's thread */
    python = told_now(p, &told) < 0 ? -1 : calls_python(p, &told);
    ident = python > 0 ? thread_ident() : NULL;
    if (python < 0 || (python && (ident == NULL || vx_slot_set(&p->reader_thread, p->state, vx_n.reader_thread, ident) < 0))) {
        Py_XDECREF(ident);
        Py_XDECREF(told.messages);
        Py_XDECREF(told.refused);
        got = PyObject_CallNoArgs(p->release);
        Py_XDECREF(got);
        return -1;
    }
    Py_XDECREF(ident);
    status = arrive_batch(p, index, t, batch, &told);
    Py_DECREF(told.messages);
    Py_DECREF(told.refused);
    if (status == 0) {
        double at = now == NULL ? monotonic() : *now;
        status = at == -1.0 && PyErr_Occurred() ? -1 : spread(p, index, at, &held_back, &retry);
    }
    if (status == 0) status = tell_delivered(p, t);
    if (status < 0) fail(p);
    if (python) {
        ident = PyLong_FromLong(0);
        if (ident != NULL) (void)vx_slot_set(&p->reader_thread, p->state, vx_n.reader_thread, ident);
        Py_XDECREF(ident);
    }
    got = PyObject_CallNoArgs(p->release);
    if (got == NULL) return -1;
    Py_DECREF(got);
    if (status < 0) return 1; /* handled: the failure reaches the loop */
    /* the loop is woken only when it must look: it has a predicate (a drain), or a window holds messages back sooner than
     * it would look by itself (read after spread set retry_at; the loop sets sleep_until before reading it) */
    wake_on = vx_slot_get(&p->wake_on_arrival, p->state, vx_n.wake_on_arrival);
    status = wake_on == NULL ? -1 : PyObject_IsTrue(wake_on);
    Py_XDECREF(wake_on);
    if (status == 0 && held_back) {
        sleep = vx_slot_get(&p->sleep_until, p->state, vx_n.sleep_until);
        if (sleep == NULL) status = -1;
        else {
            sleep_until = PyFloat_AsDouble(sleep);
            status = retry < sleep_until;
        }
        Py_XDECREF(sleep);
    }
    if (status > 0) {
        PyObject *wake = PyObject_GetAttr(p->state, vx_n.wake);
        got = wake == NULL ? NULL : PyObject_CallMethodNoArgs(wake, vx_n.set);
        Py_XDECREF(wake);
        if (got == NULL) return -1;
        Py_DECREF(got);
    }
    return status < 0 ? -1 : 1;
}

/* The Python delivery (Delivery.deliver) for units as Python objects. */
static int deliver_slow(vx_path_t *p, Py_ssize_t index, double t, PyObject *units) {
    PyObject *done = PyObject_CallFunction(p->deliver, "ndO", index, t, units);
    Py_XDECREF(done);
    return done == NULL ? -1 : 0;
}

/* ---- reading the devices ----------------------------------------------------------------- */

#ifndef _WIN32
/* Wait up to `timeout` for fd to be readable, without the GIL; 1 ready, 0 not, -1 (errno) failed; 2: the fd has
 * an error to report (POLLERR), which the transport's own read must meet: a socket tells an error only once. */
static int wait_readable(int fd, double timeout) {
    struct pollfd want;
    int ready;
    want.fd = fd;
    want.events = POLLIN;
    want.revents = 0;
    Py_BEGIN_ALLOW_THREADS
    ready = poll(&want, 1, (int)(timeout * 1000.0 + 0.5));
    Py_END_ALLOW_THREADS
    return ready > 0 && (want.revents & (POLLERR | POLLNVAL)) ? 2 : ready;
}

/* Up to READ_SIZE bytes of a serial fd into link->buf, once it has some within `timeout` (the wait and the read
 * without the GIL): 1 with *got bytes, 0 nothing yet, -1 the transport's own read must take the turn (the device
 * failed or was lost: it knows how to tell and reopen; an exception set only when out of memory). */
static int read_serial(vx_link_t *link, int fd, double timeout, ssize_t *got) {
    struct pollfd want;
    int ready;
    if (link->buf == NULL && (link->buf = PyMem_Malloc(READ_SIZE)) == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    want.fd = fd;
    want.events = POLLIN;
    want.revents = 0;
    *got = -1;
    Py_BEGIN_ALLOW_THREADS
    ready = poll(&want, 1, (int)(timeout * 1000.0 + 0.5));
    if (ready > 0 && !(want.revents & (POLLERR | POLLNVAL))) *got = read(fd, link->buf, READ_SIZE);
    Py_END_ALLOW_THREADS
    if (ready == 0 || (ready < 0 && errno == EINTR)) return 0;
    if (ready < 0 || (want.revents & (POLLERR | POLLNVAL))) return -1;
    if (*got < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR)) return 0;
    return *got <= 0 ? -1 : 1; /* readable yet nothing: the transport's read tells it as lost */
}

/* SerialTransport's read, here: its fd's bytes, counted as its read counts them. NULL result: the transport's
 * own read takes this turn (no fd now, or the device failed: it knows how to tell and reopen). */
static PyObject *pump_serial(vx_path_t *p, Py_ssize_t index, double timeout) {
    vx_link_t *link = &p->links[index];
    PyObject *fd_obj = vx_slot_get(&link->handle_fd, link->handle, vx_n.fd);
    long fd;
    ssize_t got;
    int ready;
    double t;
    vx_batch_t batch;
    if (fd_obj == NULL) return NULL;
    fd = fd_obj == Py_None ? -1 : PyLong_AsLong(fd_obj);
    Py_DECREF(fd_obj);
    if (fd < 0) return PyErr_Occurred() ? NULL : Py_NewRef(Py_None);
    if ((ready = read_serial(link, (int)fd, timeout, &got)) < 0) return PyErr_Occurred() ? NULL : Py_NewRef(Py_None);
    if (ready == 0) return PyLong_FromLong(0);
    if ((t = wall_clock()) == -1.0 && PyErr_Occurred()) return NULL;
    if (VX_HOT_T(link, RX_BYTES, got) < 0 || VX_HOT_T(link, RX, 1) < 0) return NULL;
    batch.kind = 1;
    batch.data = link->buf;
    batch.len = (size_t)got;
    ready = deliver_fast(p, index, t, &batch, NULL);
    if (ready < 0) return NULL;
    if (ready == 0) {
        PyObject *units = Py_BuildValue("[y#]", (const char *)link->buf, (Py_ssize_t)got);
        int status = units == NULL ? -1 : deliver_slow(p, index, t, units);
        Py_XDECREF(units);
        if (status < 0) return NULL;
    }
    return PyLong_FromSsize_t(got);
}

/* CLOCK_MONOTONIC in seconds: when an XBee module's byte came (compared only with itself). */
static double seconds_now(void) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)now.tv_sec + (double)now.tv_nsec * 1e-9;
}

/* The frame the link's cutting just completed: the module's own report goes to the transport (`note_report`
 * counts it), any other is the next unit of link->units. 0, or -1 with an exception. */
static int xbee_unit(vx_link_t *link, size_t *n, size_t *at) {
    const vstig_xbee_rx_t *rx = link->stream;
    const uint8_t *data = vstig_xbee_frame_data(rx);
    if (data[0] == VSTIG_XBEE_TX_STATUS || data[0] == VSTIG_XBEE_MODEM_STATUS || data[0] == VSTIG_XBEE_AT_RESPONSE) {
        PyObject *done = vx_call(link->transport, vx_n.note_report, "(y#)", (const char *)data,
                                 (Py_ssize_t)vstig_xbee_frame_len(rx));
        Py_XDECREF(done);
        return done == NULL ? -1 : 0;
    }
    memcpy(link->units + *at, vstig_xbee_wire(rx), rx->wire_len);
    link->unit_len[(*n)++] = rx->wire_len;
    *at += rx->wire_len;
    return 0;
}

/* n > 0 units a device read gave (whole frames, back to back in `data`, each unit_len[i] bytes), counted as its
 * transport's read counts them and delivered: here if it can be, else as bytes to the Python delivery. */
static int deliver_units(vx_path_t *p, Py_ssize_t index, const uint8_t *data, const uint16_t *unit_len,
                         Py_ssize_t n) {
    vx_batch_t batch;
    Py_ssize_t i, at;
    double t;
    int done;
    if (VX_HOT_T(&p->links[index], RX, n) < 0 || ((t = wall_clock()) == -1.0 && PyErr_Occurred()))
        return -1;
    batch.kind = 3;
    batch.data = data;
    batch.unit_len = unit_len;
    batch.len = (size_t)n;
    done = deliver_fast(p, index, t, &batch, NULL);
    if (done == 0) {
        PyObject *units = PyList_New(n);
        for (i = 0, at = 0; units != NULL && i < n; at += unit_len[i++]) {
            PyObject *unit = PyBytes_FromStringAndSize((const char *)data + at, unit_len[i]);
            if (unit == NULL) Py_CLEAR(units);
            else PyList_SET_ITEM(units, i, unit);
        }
        done = units == NULL ? -1 : deliver_slow(p, index, t, units);
        Py_XDECREF(units);
    }
    return done < 0 ? -1 : 0;
}

/* The units (frames) that len bytes complete, or that the line going quiet (`quiet`) gives; -1 with an exception. */
static Py_ssize_t xbee_cut(vx_link_t *link, const uint8_t *data, size_t len, int quiet) {
    vstig_xbee_rx_t *rx = link->stream;
    size_t i, n = 0, at = 0;
    for (i = 0; i <= len; i++) {
        if (i < len ? !vstig_xbee_feed(rx, data[i]) : !(quiet && vstig_xbee_flush(rx))) continue;
        do {
            if (xbee_unit(link, &n, &at) < 0) return -1;
        } while (vstig_xbee_next(rx));
    }
    return (Py_ssize_t)n;
}

#define XBEE_UNITS_ROOM (READ_SIZE + VSTIG_XBEE_WIRE_MAX) /* a read's bytes and the frame they finish */

/* XBeeTransport's read, here (its _read_device and cut): the module's bytes cut into frames by libvstig as its
 * reader cuts them (drops under its drop_<reason>), the module's reports counted by the transport, every other frame
 * a unit, counted as its read counts them; a frame still arriving `quiet` s after the last byte is cut short. NULL
 * result: the transport's own read takes this turn (no fd, the device failed, or a port just opened whose answers at
 * open left frames, or part of one, with the transport: it hands them on, then the reads are ours). */
static PyObject *pump_xbee(vx_path_t *p, Py_ssize_t index, double timeout) {
    vx_link_t *link = &p->links[index];
    PyObject *fd_obj;
    Py_ssize_t n;
    long fd;
    ssize_t got = 0;
    int ready;
    double now;
    if (link->stream == NULL) {
        link->stream = PyMem_Malloc(sizeof *link->stream);
        link->units = PyMem_Malloc(XBEE_UNITS_ROOM);
        link->unit_len = PyMem_Malloc((XBEE_UNITS_ROOM / 5u + 1u) * sizeof *link->unit_len); /* 5: the least frame */
        if (link->stream == NULL || link->units == NULL || link->unit_len == NULL) return PyErr_NoMemory();
        vstig_xbee_rx_init(link->stream, link->escaped);
    }
    if ((fd_obj = PyObject_GetAttr(link->handle, vx_n.fd)) == NULL) return NULL;
    fd = fd_obj == Py_None ? -1 : PyLong_AsLong(fd_obj);
    Py_DECREF(fd_obj);
    if (fd < 0) return PyErr_Occurred() ? NULL : Py_NewRef(Py_None);
    if (fd != link->fd) { /* a port opened since: the reads are ours once the transport holds nothing */
        PyObject *holds = PyObject_CallMethodNoArgs(link->transport, vx_n.holds);
        int held = holds == NULL ? -1 : PyObject_IsTrue(holds);
        Py_XDECREF(holds);
        if (held != 0) return held < 0 ? NULL : Py_NewRef(Py_None);
        vstig_xbee_rx_reset(link->stream);
        link->fd = (int)fd;
    }
    if ((ready = read_serial(link, (int)fd, timeout, &got)) < 0) {
        link->fd = -1; /* the transport's read takes over: what it reads is its own until it holds nothing */
        return PyErr_Occurred() ? NULL : Py_NewRef(Py_None);
    }
    now = seconds_now();
    if (ready == 0) {
        if (!vstig_xbee_holding(link->stream) || now - link->last_byte <= link->quiet) return PyLong_FromLong(0);
        n = xbee_cut(link, NULL, 0, 1);
    } else {
        link->last_byte = now;
        if (VX_HOT_T(link, RX_BYTES, got) < 0) return NULL;
        n = xbee_cut(link, link->buf, (size_t)got, 0);
    }
    if (n < 0 || vx_harvest_device_drops(&link->stream->drops, link->tcounters) < 0) return NULL;
    if (n == 0) return PyLong_FromSsize_t(got);
    if (deliver_units(p, index, link->units, link->unit_len, n) < 0) return NULL;
    return PyLong_FromSsize_t(got);
}

/* A UDP read: up to DATAGRAMS_PER_READ datagrams, each in its own DATAGRAM bytes of `room` (only the pages a
 * datagram fills are ever touched), with their sources; then the frames cut from them, back to back in `room`. */
struct vx_udp {
    struct mmsghdr header[DATAGRAMS_PER_READ];
    struct iovec io[DATAGRAMS_PER_READ];
    struct sockaddr_storage from[DATAGRAMS_PER_READ];
    uint8_t *room;
    uint16_t *unit_len; /* the frames' sizes */
    size_t lens;        /* room in unit_len */
    vstig_mavlink_rx_t cutter; /* a datagram that is not one frame: cut as the transport's reader cuts it */
};

static vx_udp_t *udp_new(void) {
    vx_udp_t *udp = PyMem_Calloc(1, sizeof *udp);
    int i;
    if (udp != NULL && (udp->room = PyMem_Malloc((size_t)DATAGRAMS_PER_READ * DATAGRAM)) == NULL) {
        PyMem_Free(udp);
        udp = NULL;
    }
    if (udp == NULL) {
        PyErr_NoMemory();
        return NULL;
    }
    for (i = 0; i < DATAGRAMS_PER_READ; i++) {
        udp->io[i].iov_base = udp->room + (size_t)i * DATAGRAM;
        udp->io[i].iov_len = DATAGRAM;
        udp->header[i].msg_hdr.msg_iov = &udp->io[i];
        udp->header[i].msg_hdr.msg_iovlen = 1;
        udp->header[i].msg_hdr.msg_name = &udp->from[i];
    }
    vstig_mavlink_rx_init(&udp->cutter);
    return udp;
}

static void udp_free(vx_udp_t *udp) {
    if (udp == NULL) return;
    PyMem_Free(udp->room);
    PyMem_Free(udp->unit_len);
    PyMem_Free(udp);
}

/* The datagrams waiting (without the GIL): how many; *refused: ICMP answers met (nobody at an address we sent to);
 * *failed: the errno of a failure the transport must hear of, else 0. */
static int udp_receive(vx_udp_t *udp, int fd, int *refused, int *failed) {
    int got = 0, r, i;
    *refused = *failed = 0;
    Py_BEGIN_ALLOW_THREADS
    while (got + *refused < DATAGRAMS_PER_READ) {
        int want = DATAGRAMS_PER_READ - got - *refused;
        for (i = got; i < got + want; i++) udp->header[i].msg_hdr.msg_namelen = sizeof udp->from[i];
        r = recvmmsg(fd, &udp->header[got], (unsigned int)want, MSG_DONTWAIT, NULL);
        if (r > 0) {
            got += r;
            if (r < want) break; /* all that had come */
        } else if (r < 0 && errno == ECONNREFUSED) {
            (*refused)++;
        } else {
            if (r < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) *failed = errno;
            break;
        }
    }
    Py_END_ALLOW_THREADS
    return got;
}

/* MavlinkUdpTransport's _one_frame: exactly one MAVLink 2 frame by its header (the framing checks its crc). */
static int one_frame(const uint8_t *data, size_t len) {
    return len > 12u && data[0] == VSTIG_MAVLINK_STX && !(data[2] & 0xFEu) &&
           len == 12u + data[1] + (data[2] ? VSTIG_MAVLINK_SIGNATURE : 0u);
}

/* A read's datagrams as units, back to back at udp->room (MavlinkUdpTransport._read_device): a datagram that is one
 * frame as it is, any other cut into its frames; each source noted in `peers` (udpin). How many, or -1. */
static Py_ssize_t udp_units(vx_link_t *link, vx_udp_t *udp, int got, PyObject *peers, double now) {
    size_t at = 0, n = 0, bytes = 0;
    int k;
    for (k = 0; k < got; k++) {
        uint8_t *data = udp->room + (size_t)k * DATAGRAM;
        size_t len = udp->header[k].msg_len, cut;
        bytes += len;
        if (peers != Py_None)
            vx_peers_heard((vx_peers_t *)peers, (const struct sockaddr *)&udp->from[k],
                           udp->header[k].msg_hdr.msg_namelen, now);
        if (n + len / 8u + 1u > udp->lens) { /* the most frames a datagram can hold: 8 bytes each (MAVLink 1) */
            size_t lens = (n + len / 8u + 1u) * 2u;
            uint16_t *grown = PyMem_Realloc(udp->unit_len, lens * sizeof *grown);
            if (grown == NULL) {
                PyErr_NoMemory();
                return -1;
            }
            udp->unit_len = grown;
            udp->lens = lens;
        }
        if (one_frame(data, len)) {
            udp->unit_len[n++] = (uint16_t)len;
        } else {
            cut = vx_mav_cut(&udp->cutter, data, len, udp->unit_len + n);
            for (len = 0; cut > 0; cut--) len += udp->unit_len[n++];
        }
        memmove(udp->room + at, data, len);
        at += len;
    }
    if (VX_HOT_T(link, RX_BYTES, (Py_ssize_t)bytes) < 0 ||
        vx_count(link->tcounters, vx_n.rx_datagrams, got) < 0 ||
        vx_mav_harvest_device(&udp->cutter, link->tcounters) < 0)
        return -1;
    return (Py_ssize_t)n;
}

/* MavlinkUdpTransport's read, here: its HEARTBEAT when the transport says one is due (`beat`, on this delivery's
 * timer), then the datagrams that came (recvmmsg), their sources into the link's peers (udpin: its CompiledHandle's
 * UdpPeers), their frames delivered and counted as its read counts them. NULL result: the transport's own read
 * takes this turn (no socket now, or it failed: the transport knows how to tell and reopen). */
static PyObject *pump_udp(vx_path_t *p, Py_ssize_t index, double timeout) {
    vx_link_t *link = &p->links[index];
    PyObject *fd_obj, *peers;
    Py_ssize_t n;
    long fd;
    int got, refused, failed, ready;
    double now;
    if (link->udp == NULL && (link->udp = udp_new()) == NULL) return NULL;
    if ((fd_obj = vx_slot_get(&link->handle_fd, link->handle, vx_n.fd)) == NULL) return NULL;
    fd = fd_obj == Py_None ? -1 : PyLong_AsLong(fd_obj);
    Py_DECREF(fd_obj);
    if (fd < 0) return PyErr_Occurred() ? NULL : Py_NewRef(Py_None);
    now = seconds_now();
    if (now >= link->next_beat) {
        PyObject *wait = PyObject_CallMethodNoArgs(link->transport, vx_n.beat);
        double seconds = wait == NULL ? -1.0 : PyFloat_AsDouble(wait);
        Py_XDECREF(wait);
        if (seconds == -1.0 && PyErr_Occurred()) return NULL;
        link->next_beat = now + seconds;
    }
    if (link->next_beat - now < timeout) timeout = link->next_beat > now ? link->next_beat - now : 0.0;
    ready = wait_readable((int)fd, timeout);
    if (ready == 0 || (ready < 0 && errno == EINTR)) return PyLong_FromLong(0);
    if (ready < 0) return Py_NewRef(Py_None);
    got = udp_receive(link->udp, (int)fd, &refused, &failed);
    if (failed == EBADF) return Py_NewRef(Py_None); /* closed under us: the transport already knows */
    if (refused && vx_count(link->tcounters, vx_n.tx_refused, refused) < 0) return NULL;
    if (failed) { /* the socket told its error to us alone: the transport must hear it */
        PyObject *done = vx_call(link->transport, vx_n.failed, "(s)", strerror(failed));
        if (done == NULL) return NULL;
        Py_DECREF(done);
    }
    if (got == 0) return PyLong_FromLong(0);
    if ((peers = vx_slot_get(&link->handle_peers, link->handle, vx_n.peers)) == NULL) return NULL;
    if (peers != Py_None && !PyObject_TypeCheck(peers, &vx_UdpPeersType)) {
        PyErr_Format(PyExc_TypeError, "link %R is read in C: its peers must be a compiled UdpPeers", link->name);
        Py_DECREF(peers);
        return NULL;
    }
    n = udp_units(link, link->udp, got, peers, seconds_now());
    Py_DECREF(peers);
    if (n < 0 || (n > 0 && deliver_units(p, index, link->udp->room, link->udp->unit_len, n) < 0)) return NULL;
    return PyLong_FromLong(got);
}

/* A SocketCAN frame as python-can's capture_message reads it (the flags, the ID's width, an FD frame's size). */
static void unpack_frame(const uint8_t *raw, size_t size, vstig_can_frame_t *frame, uint8_t *esi) {
    uint32_t id;
    memcpy(&id, raw, 4);
    frame->extended = (uint8_t)((id & 0x80000000ul) != 0);
    frame->rtr = (uint8_t)((id & 0x40000000ul) != 0);
    frame->error = (uint8_t)((id & 0x20000000ul) != 0);
    frame->id = id & (frame->extended ? 0x1FFFFFFFul : 0x7FFul);
    frame->fd = (uint8_t)(size == 72u);
    frame->brs = (uint8_t)(frame->fd && (raw[5] & 0x01u));
    *esi = (uint8_t)(frame->fd && (raw[5] & 0x02u));
    frame->len = raw[4] > (frame->fd ? 64u : 8u) ? (uint8_t)(frame->fd ? 64u : 8u) : raw[4];
    memcpy(frame->data, raw + 8, frame->len);
}

/* A frame read here as the can.Message python-can would have made of it (for the Python delivery and for the
 * transport's own look at error frames). */
static PyObject *frame_message(const vx_link_t *link, const vstig_can_frame_t *f, uint8_t esi, double t) {
    PyObject *args = PyTuple_New(0), *kwargs, *channel, *unit = NULL;
    if (args == NULL) return NULL;
    channel = PyObject_GetAttr(link->transport, vx_n.channel);
    if (channel == NULL) {
        Py_DECREF(args);
        return NULL;
    }
    kwargs = Py_BuildValue("{s:d,s:O,s:k,s:O,s:O,s:O,s:O,s:O,s:O,s:i,s:y#}", "timestamp", t, "channel", channel,
                           "arbitration_id", (unsigned long)f->id, "is_extended_id", f->extended ? Py_True : Py_False,
                           "is_remote_frame", f->rtr ? Py_True : Py_False, "is_error_frame",
                           f->error ? Py_True : Py_False, "is_fd", f->fd ? Py_True : Py_False, "bitrate_switch",
                           f->brs ? Py_True : Py_False, "error_state_indicator", esi ? Py_True : Py_False, "dlc",
                           (int)f->len, "data", (const char *)f->data, (Py_ssize_t)f->len);
    Py_DECREF(channel);
    if (kwargs != NULL) unit = PyObject_Call(CAN_MESSAGE, args, kwargs);
    Py_DECREF(args);
    Py_XDECREF(kwargs);
    return unit;
}

/* The kernel's running count of frames it dropped for this socket (SO_RXQ_OVFL), when a frame carried it. */
static int kernel_drops(const struct msghdr *header, uint32_t *count) {
    struct cmsghdr *c;
    for (c = CMSG_FIRSTHDR(header); c != NULL; c = CMSG_NXTHDR((struct msghdr *)header, c)) {
        if (c->cmsg_level == SOL_SOCKET && c->cmsg_type == 40 /* SO_RXQ_OVFL */) {
            memcpy(count, CMSG_DATA(c), sizeof *count);
            return 1;
        }
    }
    return 0;
}

/* CanTransport's read of a SocketCAN bus, here: a frame within `timeout`, then what the socket holds (at most
 * DRAIN_LIMIT more), counted as its read counts them; error frames go to the transport's own look. */
static PyObject *pump_socketcan(vx_path_t *p, Py_ssize_t index, double timeout) {
    vx_link_t *link = &p->links[index];
    vstig_can_frame_t frames[DRAIN_LIMIT + 1];
    uint8_t esi[DRAIN_LIMIT + 1];
    uint8_t raw[72], control[256];
    struct iovec io;
    struct msghdr header;
    size_t n = 0, i;
    ssize_t got;
    uint32_t drops = 0;
    int fd, ready, counted = 0, failed;
    double t, now;
    vx_batch_t batch;
    if (!p->fast) return Py_NewRef(Py_None); /* a listener wants python-can's own messages (their timestamps) */
    fd = vx_socketcan_fd(link->handle, &link->device, &link->fd, 1);
    if (fd < -1) return NULL;
    if (fd < 0) return Py_NewRef(Py_None);
    if ((now = monotonic()) == -1.0 && PyErr_Occurred()) return NULL;
    if (now - link->polled >= POLL_COUNTS_S) { /* the bus's own counts, as its recv polls them */
        PyObject *done = PyObject_CallMethodNoArgs(link->device, vx_n.poll_counts);
        if (done == NULL) return NULL;
        Py_DECREF(done);
        link->polled = now;
    }
    ready = wait_readable(fd, timeout);
    if (ready == 0 || (ready < 0 && errno == EINTR)) return PyLong_FromLong(0);
    if (ready != 1) return Py_NewRef(Py_None);
    Py_BEGIN_ALLOW_THREADS
    for (n = 0; n <= DRAIN_LIMIT; n++) {
        io.iov_base = raw;
        io.iov_len = sizeof raw;
        memset(&header, 0, sizeof header);
        header.msg_iov = &io;
        header.msg_iovlen = 1;
        header.msg_control = control;
        header.msg_controllen = sizeof control;
        got = recvmsg(fd, &header, MSG_DONTWAIT);
        if (got != 16 && got != 72) break;
        counted |= kernel_drops(&header, &drops);
        unpack_frame(raw, (size_t)got, &frames[n], &esi[n]);
    }
    failed = got < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR ? errno : 0;
    Py_END_ALLOW_THREADS
    if (failed) { /* the socket told its error (an interface gone down) to us alone: the transport must hear it */
        PyObject *done = vx_call(link->transport, vx_n.failed, "(s)", strerror(failed));
        if (done == NULL) return NULL;
        Py_DECREF(done);
    }
    if (n == 0) return PyLong_FromLong(0);
    if ((t = wall_clock()) == -1.0 && PyErr_Occurred()) return NULL;
    if (VX_HOT_T(link, RX, (Py_ssize_t)n) < 0) return NULL;
    if (counted) {
        PyObject *done = vx_call(link->device, vx_n.note_kernel_drops, "(k)", (unsigned long)drops);
        if (done == NULL) return NULL;
        Py_DECREF(done);
    }
    for (i = 0; i < n; i++) { /* error frames: counted by the transport, which may find the bus off */
        if (frames[i].error) {
            PyObject *unit = frame_message(link, &frames[i], esi[i], t), *done;
            done = unit == NULL ? NULL : PyObject_CallMethodOneArg(link->transport, vx_n.note_error_frame, unit);
            Py_XDECREF(unit);
            if (done == NULL) return NULL;
            Py_DECREF(done);
        }
    }
    batch.kind = 2;
    batch.frames = frames;
    batch.nframes = n;
    ready = deliver_fast(p, index, t, &batch, NULL);
    if (ready < 0) return NULL;
    if (ready == 0) {
        PyObject *units = PyList_New((Py_ssize_t)n);
        int status;
        for (i = 0; units != NULL && i < n; i++) {
            PyObject *unit = frame_message(link, &frames[i], esi[i], t);
            if (unit == NULL) Py_CLEAR(units);
            else PyList_SET_ITEM(units, (Py_ssize_t)i, unit);
        }
        status = units == NULL ? -1 : deliver_slow(p, index, t, units);
        Py_XDECREF(units);
        if (status < 0) return NULL;
    }
    return PyLong_FromSize_t(n);
}
#endif

/* One frame a python-can bus's recv returned, into `units`, as CanTransport._read_device takes it (an error frame
 * to the transport's own look): 1 when the bus may hold more (the frame waited longer than ALONE_S), 0 when the
 * read ends there, -1 with an exception. */
static int took_frame(vx_link_t *link, PyObject *units, PyObject *frame) {
    PyObject *flag, *stamp;
    double age;
    int error;
    if (PyList_Append(units, frame) < 0 || (flag = vx_can_field(frame, VX_CAN_ERROR)) == NULL) return -1;
    error = PyObject_IsTrue(flag);
    Py_DECREF(flag);
    if (error < 0) return -1;
    if (error) {
        PyObject *done = PyObject_CallMethodOneArg(link->transport, vx_n.note_error_frame, frame), *device;
        if (done == NULL) return -1;
        Py_DECREF(done);
        if ((device = PyObject_GetAttr(link->handle, vx_n.device)) == NULL) return -1;
        Py_DECREF(device);
        if (device == Py_None) return 0; /* the transport lost the bus (bus-off) */
    }
    if (PyList_GET_SIZE(units) > DRAIN_LIMIT) return 0;
    if ((stamp = vx_can_field(frame, VX_CAN_TIMESTAMP)) == NULL) return -1;
    age = wall_clock() - PyFloat_AsDouble(stamp);
    Py_DECREF(stamp);
    return PyErr_Occurred() ? -1 : age >= ALONE_S;
}

/* CanTransport's read of a python-can bus that is not SocketCAN (slcan, PCAN, Kvaser, Vector, virtual...), here:
 * the bus's own recv(timeout), then recv(0) while the frame read had waited (took_frame), the batch delivered with
 * no Python of ours around it. The transport's own read takes the turn (None) while it holds no bus or an outage
 * to end, every STATE_POLL_S (its look at the bus's state), and once python-can raised (after what was read before
 * is delivered): it meets the same, and handles it as its own. */
static PyObject *pump_pythoncan(vx_path_t *p, Py_ssize_t index, double timeout) {
    vx_link_t *link = &p->links[index];
    PyObject *bus, *units = NULL, *wait = NULL, *zero = NULL, *frame, *result = NULL;
    Py_ssize_t n;
    double now, t;
    vx_batch_t batch;
    int handled, failed;
    if (!p->fast) return Py_NewRef(Py_None); /* a listener wants each unit: the transport's read, Python's delivery */
    if ((now = monotonic()) == -1.0 && PyErr_Occurred()) return NULL;
    if (now - link->polled >= STATE_POLL_S) {
        link->polled = now;
        return Py_NewRef(Py_None);
    }
    if ((bus = vx_live_device(link->handle)) == NULL || bus == Py_None) return bus;
    if ((units = PyList_New(0)) == NULL || (wait = PyFloat_FromDouble(timeout)) == NULL ||
        (zero = PyFloat_FromDouble(0.0)) == NULL)
        goto done;
    frame = PyObject_CallMethodOneArg(bus, vx_n.recv, wait);
    while (frame != NULL && frame != Py_None) {
        int more = took_frame(link, units, frame);
        Py_DECREF(frame);
        if (more < 0) goto done;
        frame = more ? PyObject_CallMethodOneArg(bus, vx_n.recv, zero) : Py_NewRef(Py_None);
    }
    if ((failed = frame == NULL)) { /* the transport's read meets it next, and handles it */
        if (!PyErr_ExceptionMatches(PyExc_Exception)) goto done;
        PyErr_Clear();
    } else {
        Py_DECREF(frame);
    }
    if ((n = PyList_GET_SIZE(units)) > 0) {
        if (VX_HOT_T(link, RX, n) < 0 || ((t = wall_clock()) == -1.0 && PyErr_Occurred())) goto done;
        batch.kind = 0;
        batch.units = units;
        handled = deliver_fast(p, index, t, &batch, NULL);
        if (handled < 0 || (handled == 0 && deliver_slow(p, index, t, units) < 0)) goto done;
    }
    result = failed ? Py_NewRef(Py_None) : PyLong_FromSsize_t(n);
done:
    Py_DECREF(bus);
    Py_XDECREF(units);
    Py_XDECREF(wait);
    Py_XDECREF(zero);
    return result;
}

/* ---- the Python type ------------------------------------------------------------------------ */

/* An XBee transport's API mode and quiet time (`api`, `quiet_after`); 0, or -1 with an exception. */
static int xbee_settings(vx_link_t *link) {
    PyObject *api = PyObject_GetAttr(link->transport, vx_n.api),
             *quiet = api == NULL ? NULL : PyObject_GetAttr(link->transport, vx_n.quiet_after);
    long mode = api == NULL ? -1 : PyLong_AsLong(api);
    link->quiet = quiet == NULL ? -1.0 : PyFloat_AsDouble(quiet);
    Py_XDECREF(api);
    Py_XDECREF(quiet);
    if (PyErr_Occurred()) return -1;
    link->escaped = (uint8_t)(mode == 2);
    return 0;
}

static PyObject *Path_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"state", "lock", "deliver", "links", "receivers", "reads", "part", "guard", "outlets",
                             "listeners", "told", "heard", "delivered", "can_message", NULL};
    PyObject *state, *lock, *deliver, *links, *receivers, *reads, *part, *guard, *outlets, *listeners = NULL,
        *told = NULL, *heard = Py_None, *delivered = NULL, *can_message = Py_None;
    vx_path_t *self;
    Py_ssize_t i;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOOO!O!O!OOO!|$O!O!OO!O", kwlist, &state, &lock, &deliver,
                                     &PyList_Type, &links, &PyList_Type, &receivers, &PyList_Type, &reads, &part,
                                     &guard, &PyList_Type, &outlets, &PyList_Type, &listeners, &PyList_Type,
                                     &told, &heard, &PyList_Type, &delivered, &can_message))
        return NULL;
    if (PyList_GET_SIZE(receivers) != PyList_GET_SIZE(links) || PyList_GET_SIZE(reads) != PyList_GET_SIZE(links)) {
        PyErr_SetString(PyExc_ValueError, "one receiver and one way of reading per link");
        return NULL;
    }
    if (part != Py_None && !PyObject_TypeCheck(part, &vx_SeatType) && !PyObject_TypeCheck(part, &vx_RelayType)) {
        PyErr_SetString(PyExc_TypeError, "part must be a Seat, a Relay or None");
        return NULL;
    }
    for (i = 0; i < PyList_GET_SIZE(outlets); i++) {
        if (!PyObject_TypeCheck(PyList_GET_ITEM(outlets, i), &vx_OutletType)) {
            PyErr_SetString(PyExc_TypeError, "outlets must be Outlets");
            return NULL;
        }
    }
    if (can_message != Py_None) Py_XSETREF(CAN_MESSAGE, Py_NewRef(can_message));
    self = (vx_path_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->state = Py_NewRef(state);
    self->lock = Py_NewRef(lock);
    self->acquire = PyObject_GetAttr(lock, vx_n.acquire);
    self->release = self->acquire == NULL ? NULL : PyObject_GetAttr(lock, vx_n.release);
    if (self->release == NULL) {
        Py_DECREF(self);
        return NULL;
    }
    vx_slot_resolve(&self->reader_thread, state, vx_n.reader_thread);
    vx_slot_resolve(&self->wake_on_arrival, state, vx_n.wake_on_arrival);
    vx_slot_resolve(&self->sleep_until, state, vx_n.sleep_until);
    vx_slot_resolve(&self->retry_at, state, vx_n.retry_at);
    self->deliver = Py_NewRef(deliver);
    self->part = Py_NewRef(part);
    self->guard = Py_NewRef(guard);
    self->outlets = Py_NewRef(outlets);
    self->fast = 1; /* until the Node says a listener wants each unit or every `Heard` */
    self->listeners = listeners == NULL ? PyList_New(0) : Py_NewRef(listeners);
    self->told = told == NULL ? PyList_New(0) : Py_NewRef(told);
    self->heard = Py_NewRef(heard);
    self->delivered = delivered == NULL ? PyList_New(0) : Py_NewRef(delivered);
    if (self->listeners == NULL || self->told == NULL || self->delivered == NULL) {
        Py_DECREF(self);
        return NULL;
    }
    self->nlinks = PyList_GET_SIZE(links);
    self->links = PyMem_Calloc((size_t)(self->nlinks ? self->nlinks : 1), sizeof *self->links);
    if (self->links == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    for (i = 0; i < self->nlinks; i++) {
        vx_link_t *link = &self->links[i];
        PyObject *receiver = PyList_GET_ITEM(receivers, i);
        long reads_how = PyLong_AsLong(PyList_GET_ITEM(reads, i));
        if (receiver != Py_None && !PyObject_TypeCheck(receiver, &vx_ReceiverType)) {
            PyErr_SetString(PyExc_TypeError, "receivers must be Receivers or None");
            Py_DECREF(self);
            return NULL;
        }
        link->receiver = receiver == Py_None ? NULL : (vx_receiver_t *)Py_NewRef(receiver);
        link->reads = (uint8_t)(link->receiver == NULL ? VX_READ_PYTHON : reads_how);
        link->link = Py_NewRef(PyList_GET_ITEM(links, i));
        link->fd = -1;
        link->name = PyObject_GetAttr(link->link, vx_n.name);
        link->counters = PyObject_GetAttr(link->link, vx_n.counters);
        link->transport = PyObject_GetAttr(link->link, vx_n.transport);
        link->tcounters = link->transport == NULL ? NULL : PyObject_GetAttr(link->transport, vx_n.counters);
        /* a device this delivery reads itself: the transport's declared handle on it (its fd, its bus) */
        link->handle = link->transport == NULL || link->reads == VX_READ_PYTHON ? Py_NewRef(Py_None)
                       : PyObject_CallMethodNoArgs(link->transport, vx_n.compiled_handle);
        if (link->handle == Py_None && link->reads != VX_READ_PYTHON && !PyErr_Occurred())
            PyErr_Format(PyExc_TypeError, "link %R's transport gives no compiled handle to read it by", link->name);
        if (link->handle != NULL && link->handle != Py_None) {
            vx_slot_resolve(&link->handle_fd, link->handle, vx_n.fd);
            vx_slot_resolve(&link->handle_peers, link->handle, vx_n.peers);
        }
        if (link->counters != NULL && !PyErr_Occurred()) link->pending = vx_pending_of(link->counters);
        if (link->tcounters != NULL && !PyErr_Occurred()) link->tpending = vx_pending_of(link->tcounters);
        if (link->name == NULL || link->counters == NULL || link->tcounters == NULL || PyErr_Occurred()) {
            Py_DECREF(self);
            return NULL;
        }
        if (link->reads == VX_READ_XBEE && xbee_settings(link) < 0) {
            Py_DECREF(self);
            return NULL;
        }
    }
    return (PyObject *)self;
}

static int Path_traverse(vx_path_t *self, visitproc visit, void *arg) {
    Py_ssize_t i;
    Py_VISIT(self->state);
    Py_VISIT(self->lock);
    Py_VISIT(self->acquire);
    Py_VISIT(self->release);
    Py_VISIT(self->deliver);
    Py_VISIT(self->part);
    Py_VISIT(self->guard);
    Py_VISIT(self->outlets);
    Py_VISIT(self->listeners);
    Py_VISIT(self->told);
    Py_VISIT(self->heard);
    Py_VISIT(self->delivered);
    for (i = 0; self->links != NULL && i < self->nlinks; i++) {
        Py_VISIT(self->links[i].receiver);
        Py_VISIT(self->links[i].link);
        Py_VISIT(self->links[i].device);
        Py_VISIT(self->links[i].handle);
        Py_VISIT(self->links[i].pending);
        Py_VISIT(self->links[i].tpending);
    }
    return 0;
}

static int Path_clear(vx_path_t *self) {
    Py_ssize_t i;
    Py_CLEAR(self->state);
    Py_CLEAR(self->lock);
    Py_CLEAR(self->acquire);
    Py_CLEAR(self->release);
    Py_CLEAR(self->deliver);
    Py_CLEAR(self->part);
    Py_CLEAR(self->guard);
    Py_CLEAR(self->outlets);
    Py_CLEAR(self->listeners);
    Py_CLEAR(self->told);
    Py_CLEAR(self->heard);
    Py_CLEAR(self->delivered);
    for (i = 0; self->links != NULL && i < self->nlinks; i++) {
        vx_link_t *link = &self->links[i];
        Py_CLEAR(link->receiver);
        Py_CLEAR(link->link);
        Py_CLEAR(link->name);
        Py_CLEAR(link->counters);
        Py_CLEAR(link->transport);
        Py_CLEAR(link->tcounters);
        Py_CLEAR(link->pending);
        Py_CLEAR(link->tpending);
        Py_CLEAR(link->device);
        Py_CLEAR(link->handle);
    }
    return 0;
}

static void Path_dealloc(vx_path_t *self) {
    Py_ssize_t i;
    PyObject_GC_UnTrack(self);
    Path_clear(self);
    for (i = 0; self->links != NULL && i < self->nlinks; i++) {
        PyMem_Free(self->links[i].buf);
        PyMem_Free(self->links[i].stream);
        PyMem_Free(self->links[i].units);
        PyMem_Free(self->links[i].unit_len);
#ifndef _WIN32
        udp_free(self->links[i].udp);
#endif
    }
    PyMem_Free(self->links);
    PyMem_Free(self->msgs);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static int link_index(vx_path_t *self, Py_ssize_t index) {
    if (index >= 0 && index < self->nlinks) return 0;
    PyErr_Format(PyExc_IndexError, "no link %zd", index);
    return -1;
}

/* deliver(index, t, units, now=None) -> True when delivered here; False: the caller delivers it (Delivery.deliver).
 * `now`: the monotonic time the outlets send at (default: the clock's; the differential test gives its own). */
static PyObject *Path_deliver(vx_path_t *self, PyObject *args) {
    Py_ssize_t index;
    double t, at;
    PyObject *units, *now = Py_None;
    vx_batch_t batch;
    int done;
    if (!PyArg_ParseTuple(args, "ndO!|O:deliver", &index, &t, &PyList_Type, &units, &now) ||
        link_index(self, index) < 0)
        return NULL;
    if (now != Py_None && (at = PyFloat_AsDouble(now)) == -1.0 && PyErr_Occurred()) return NULL;
    batch.kind = 0;
    batch.units = units;
    done = deliver_fast(self, index, t, &batch, now == Py_None ? NULL : &at);
    if (done < 0) return NULL;
    return PyBool_FromLong(done);
}

static PyObject *Path_pump_at(vx_path_t *self, Py_ssize_t index, double timeout) {
    if (self->links[index].reads == VX_READ_PYTHONCAN) return pump_pythoncan(self, index, timeout); /* everywhere */
#ifndef _WIN32
    switch (self->links[index].reads) {
    case VX_READ_SERIAL:
        return pump_serial(self, index, timeout);
    case VX_READ_SOCKETCAN:
        return pump_socketcan(self, index, timeout);
    case VX_READ_XBEE:
        return pump_xbee(self, index, timeout);
    case VX_READ_UDP:
        return pump_udp(self, index, timeout);
    default:
        break;
    }
#endif
    return Py_NewRef(Py_None);
}

/* pump(index, timeout) -> how much was read (bytes or frames, maybe 0), or None: the transport's own read takes
 * this turn (it has no fd now, the device failed, or a listener wants python-can's messages) */
static PyObject *Path_pump(vx_path_t *self, PyObject *args) {
    Py_ssize_t index;
    double timeout;
    if (!PyArg_ParseTuple(args, "nd:pump", &index, &timeout) || link_index(self, index) < 0) return NULL;
    return Path_pump_at(self, index, timeout);
}

/* serve(index, timeout, turn) -> None: pump link `index` until `stopping` is set; whenever pump hands the turn
 * back (None), turn() reads through the transport (the reader thread's loop, without a Python frame per read) */
static PyObject *Path_serve(vx_path_t *self, PyObject *args) {
    PyObject *turn, *got;
    Py_ssize_t index;
    double timeout;
    if (!PyArg_ParseTuple(args, "ndO:serve", &index, &timeout, &turn) || link_index(self, index) < 0) return NULL;
    while (!self->stopping) {
        PyObject *pumped = Path_pump_at(self, index, timeout);
        if (pumped == NULL) return NULL;
        got = pumped == Py_None ? PyObject_CallNoArgs(turn) : Py_NewRef(Py_None);
        Py_DECREF(pumped);
        if (got == NULL) return NULL;
        Py_DECREF(got);
    }
    Py_RETURN_NONE;
}

/* pumps(index) -> whether pump reads this link's device itself */
static PyObject *Path_pumps(vx_path_t *self, PyObject *arg) {
    Py_ssize_t index = PyLong_AsSsize_t(arg);
    if ((index == -1 && PyErr_Occurred()) || link_index(self, index) < 0) return NULL;
    return PyBool_FromLong(self->links[index].reads != VX_READ_PYTHON);
}

static PyMethodDef Path_methods[] = {
    {"deliver", (PyCFunction)Path_deliver, METH_VARARGS, "Deliver what link `index` read, here if it can."},
    {"pump", (PyCFunction)Path_pump, METH_VARARGS, "Read link `index`'s device and deliver what came."},
    {"pumps", (PyCFunction)Path_pumps, METH_O, "Whether `pump` reads link `index`'s device itself."},
    {"serve", (PyCFunction)Path_serve, METH_VARARGS, "Pump link `index` until `stopping`; turn() when handed back."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Path_members[] = {
    {"fast", T_BOOL, offsetof(vx_path_t, fast), 0,
     "No listener wants each unit or every `Heard`: whole batches may be delivered here (the Node sets it)."},
    {"stopping", T_BOOL, offsetof(vx_path_t, stopping), 0, "The readers stop: `serve` returns (LinkReaders sets it)."},
    {NULL, 0, 0, 0, NULL},
};

PyTypeObject vx_PathType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Path",
    .tp_doc = "Path(state, lock, deliver, links, receivers, reads, part, guard, outlets, *, listeners, told, heard, "
              "delivered, can_message=None): "
              "a Node's delivery in C.",
    .tp_basicsize = sizeof(vx_path_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = Path_new,
    .tp_dealloc = (destructor)Path_dealloc,
    .tp_traverse = (traverseproc)Path_traverse,
    .tp_clear = (inquiry)Path_clear,
    .tp_methods = Path_methods,
    .tp_members = Path_members,
};
