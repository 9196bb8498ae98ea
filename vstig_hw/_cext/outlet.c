/*
 * Outlet: vstig_hw.gateway.outlet.Outlet in C, one link's way out (its window, its share of sources, its writer).
 *
 * Reference: vstig_hw/gateway/outlet.py vstig_hw/transports/serial.py vstig_hw/transports/can.py
 *   vstig_hw/transports/mavlink.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 *
 * What Outlet does, done the same way: a push while nothing waits is held as it came and goes out at the next
 * flush if the window and the writer take it all; otherwise it waits in the fair share's lines, which stay the
 * Python ones (`queue`: FairQueue or FairFifo, the one implementation of the share) and are only touched while
 * a backlog lasts. The window is a Window (window.c); the writer stays the link's LinkWriter.
 *
 * What is new is how a batch reaches the device while the writer holds nothing (`writer.idle`): a serial port's
 * non-blocking fd, a SocketCAN socket or a MAVLink UDP socket (unpaced; a signed one under its write lock) is
 * written here, in C, with the transport's own counters, exactly as its write_nowait would; whatever the device
 * does not take at once (a full buffer, an error) goes to the writer, whose write_nowait meets the same condition
 * and handles it as it always does (the rest waits; a lost device is counted and reopened by the transport).
 */
#include "outlet.h"
#include "peers.h"

#include <errno.h>
#include <string.h>
#include <structmember.h>
#ifndef _WIN32
#include <sys/socket.h>
#include <unistd.h>
#endif

/* ---- reaching the device --------------------------------------------------------------- */

/* bool(obj.name): 1 or 0, or -1 with an exception */
static int attribute_true(PyObject *obj, PyObject *name) {
    PyObject *value = PyObject_GetAttr(obj, name);
    int result;
    if (value == NULL) return -1;
    result = PyObject_IsTrue(value);
    Py_DECREF(value);
    return result;
}

/* The writer holds nothing and writes nothing now (LinkWriter.idle): a batch may go straight to the device. */
static int writer_idle(vx_outlet_t *o) { return attribute_true(o->writer, vx_n.idle); }

/* writer.submit(units, messages) with the exception Outlet._hand counts as drop_write_error. */
static int writer_submit(vx_outlet_t *o, PyObject *units, Py_ssize_t messages) {
    PyObject *count = PyLong_FromSsize_t(messages), *done;
    if (count == NULL) return -1;
    done = PyObject_CallMethodObjArgs(o->writer, vx_n.submit, units, count, NULL);
    Py_DECREF(count);
    if (done != NULL) {
        Py_DECREF(done);
        return 0;
    }
    if (!PyErr_ExceptionMatches(PyExc_Exception)) return -1;
    PyErr_Clear(); /* a transport that broke its promise not to raise: count, keep the loop alive */
    return vx_count(o->counters, vx_n.drop_write_error, messages);
}

static PyObject *message_list(const vstig_msg_t *msgs, size_t n) {
    PyObject *list = PyList_New((Py_ssize_t)n);
    size_t i;
    for (i = 0; list != NULL && i < n; i++) {
        PyObject *m = vx_message(&msgs[i]);
        if (m == NULL) Py_CLEAR(list);
        else PyList_SET_ITEM(list, (Py_ssize_t)i, m);
    }
    return list;
}

/* The writer gets `n` messages as units: the encoder's, or Link.units_of's. */
static int submit_through_writer(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n) {
    PyObject *units;
    int status;
    if (o->encoder != NULL) {
        PyObject *list = message_list(msgs, n);
        units = list == NULL ? NULL : PyObject_CallMethodOneArg(o->encoder, vx_n.encode_batch, list);
        Py_XDECREF(list);
    } else {
        PyObject *list = message_list(msgs, n);
        units = list == NULL ? NULL : PyObject_CallMethodObjArgs(o->link, vx_n.units_of, list, NULL);
        Py_XDECREF(list);
    }
    if (units == NULL) {
        if (!PyErr_ExceptionMatches(PyExc_Exception)) return -1;
        PyErr_Clear();
        return vx_count(o->counters, vx_n.drop_write_error, (Py_ssize_t)n);
    }
    status = writer_submit(o, units, (Py_ssize_t)n);
    Py_DECREF(units);
    return status;
}

/* `sent` of a batch's `count` CAN frames went to the bus (carrying `sent_messages` of its `n`): counted as the
 * transport's write_nowait counts them; the frames after them, as can.Messages, go to the writer, whose
 * write_nowait meets what the bus did not take here (busy, gone) and handles it as it always does. 0, or -1. */
static int sent_and_rest(vx_outlet_t *o, const vx_tx_t *tx, const vstig_can_frame_t *frames, size_t sent,
                         size_t count, size_t n, size_t sent_messages) {
    PyObject *rest;
    size_t k;
    int status;
    if (sent && (VX_HOT(&o->port, TX, (Py_ssize_t)sent) < 0 ||
                 VX_HOT(o, OUT, (Py_ssize_t)sent_messages) < 0))
        return -1;
    if (sent == count) return 0;
    rest = PyList_New((Py_ssize_t)(count - sent));
    for (k = sent; rest != NULL && k < count; k++) {
        PyObject *unit = vx_frame_unit(tx, &frames[k]);
        if (unit == NULL) Py_CLEAR(rest);
        else PyList_SET_ITEM(rest, (Py_ssize_t)(k - sent), unit);
    }
    status = rest == NULL ? -1 : writer_submit(o, rest, (Py_ssize_t)(n - sent_messages));
    Py_XDECREF(rest);
    return status;
}

/* The batch's frames to a python-can bus by its own send(unit, 0.0), as CanTransport.write_nowait sends them (an
 * interface whose send cannot block: `_send`, then `_sent`'s count); from the first frame the bus does not take,
 * the rest goes to the writer. 1 done (or handed to the writer), 0 not tried (no bus now, or an outage to end),
 * -1 error. */
static int write_pythoncan(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n) {
    vx_tx_t *tx = &((vx_encoder_t *)o->encoder)->tx;
    vstig_can_frame_t stack[64], *frames = stack;
    size_t count, i = 0, base, extra, sent_messages = 0;
    Py_ssize_t made;
    PyObject *bus = vx_live_device(o->port.handle), *zero = NULL;
    int status = 1;
    if (bus == NULL || bus == Py_None) {
        Py_XDECREF(bus);
        return bus == NULL ? -1 : 0;
    }
    if ((n > 64 && (frames = PyMem_Malloc(n * sizeof *frames)) == NULL) || (zero = PyFloat_FromDouble(0.0)) == NULL) {
        if (frames == NULL) PyErr_NoMemory();
        goto error;
    }
    if ((made = vx_tx_wire(tx, msgs, n, NULL, frames)) <= 0) { /* none: all held back (no tag), as no units */
        if (made < 0) goto error;
        goto done;
    }
    count = (size_t)made;
    base = n / count;
    extra = n % count; /* LinkWriter.submit's spread: unit i carries base + (i < extra) */
    for (; i < count; i++) {
        PyObject *unit = vx_frame_unit(tx, &frames[i]), *done, *call[3] = {bus, unit, zero};
        if (unit == NULL) goto error;
        done = PyObject_VectorcallMethod(vx_n.send, call, 3, NULL);
        Py_DECREF(unit);
        if (done == NULL) {
            if (!PyErr_ExceptionMatches(PyExc_Exception)) goto error;
            PyErr_Clear(); /* busy, or gone: the writer's write_nowait meets it again */
            break;
        }
        Py_DECREF(done);
        sent_messages += base + (i < extra);
    }
    if (sent_and_rest(o, tx, frames, i, count, n, sent_messages) < 0) goto error;
    goto done;
error:
    status = -1;
done:
    Py_DECREF(bus);
    Py_XDECREF(zero);
    if (frames != stack && frames != NULL) PyMem_Free(frames);
    return status;
}

#ifndef _WIN32
/* A serial transport's open fd (its CompiledHandle's), or -1 when it has none now (lost, or no fd at all). */
static int serial_fd(vx_port_t *p) {
    PyObject *fd = vx_slot_get(&p->fd_slot, p->handle, vx_n.fd);
    long value;
    if (fd == NULL) return -2;
    value = fd == Py_None ? -1 : PyLong_AsLong(fd);
    Py_DECREF(fd);
    if (value == -1 && PyErr_Occurred()) return -2;
    return (int)value;
}

#define PREAMBLE_MAX 16u /* a serial transport's preamble: the wire bytes are made after room for it */

/* The batch's wire bytes straight to the serial fd; 1 done (or handed to the writer), 0 not tried, -1 error. */
static int write_serial(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n) {
    vx_port_t *p = &o->port;
    vx_tx_t *tx = &((vx_encoder_t *)o->encoder)->tx;
    PyObject *fresh, *rest;
    uint8_t stack[64 * VX_SERIAL_MAX_BYTES + PREAMBLE_MAX], *buf = stack, *start;
    size_t len, at = 0, room = vx_tx_room(tx, n) + PREAMBLE_MAX;
    Py_ssize_t made;
    ssize_t written;
    int fd = serial_fd(p), status = 1;
    if (fd < -1) return -1;
    if (fd < 0) return 0; /* the transport reopens it: its write_nowait knows how */
    if (room > sizeof stack && (buf = PyMem_Malloc(room)) == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    if ((made = vx_tx_wire(tx, msgs, n, buf + PREAMBLE_MAX, NULL)) <= 0) { /* none: all held back, as no units */
        if (made < 0) goto error;
        goto done;
    }
    fresh = vx_slot_get(&p->fresh_slot, p->handle, vx_n.fresh);
    if (fresh == NULL) goto error;
    if (PyObject_IsTrue(fresh) == 1) { /* the first write since the port opened: the preamble goes first */
        PyObject *preamble = PyObject_GetAttr(p->handle, vx_n.preamble);
        if (preamble == NULL || !PyBytes_Check(preamble) || PyBytes_GET_SIZE(preamble) > PREAMBLE_MAX) {
            Py_XDECREF(preamble);
            Py_DECREF(fresh);
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_TypeError, "a serial preamble is at most 16 bytes");
            goto error;
        }
        at = (size_t)PyBytes_GET_SIZE(preamble);
        memcpy(buf + PREAMBLE_MAX - at, PyBytes_AS_STRING(preamble), at);
        Py_DECREF(preamble);
        if (vx_slot_set(&p->fresh_slot, p->handle, vx_n.fresh, Py_False) < 0) {
            Py_DECREF(fresh);
            goto error;
        }
    }
    Py_DECREF(fresh);
    start = buf + PREAMBLE_MAX - at;
    len = at + (size_t)made;
    written = write(fd, start, len);
    if (written == (ssize_t)len) { /* SerialTransport._write_fd's success, then LinkWriter.submit's */
        if (VX_HOT(p, TX, 1) < 0 || VX_HOT(p, TX_BYTES, (Py_ssize_t)len) < 0 ||
            VX_HOT(o, OUT, (Py_ssize_t)n) < 0)
            goto error;
        goto done;
    }
    if (written > 0 && VX_HOT(p, TX_BYTES, written) < 0) goto error;
    if (written < 0) written = 0; /* full, or an error its write_nowait will meet and handle */
    rest = Py_BuildValue("[y#]", (const char *)start + written, (Py_ssize_t)(len - (size_t)written));
    if (rest == NULL || writer_submit(o, rest, (Py_ssize_t)n) < 0) {
        Py_XDECREF(rest);
        goto error;
    }
    Py_DECREF(rest);
    goto done;
error:
    status = -1;
done:
    if (buf != stack) PyMem_Free(buf);
    return status;
}

int vx_socketcan_fd(PyObject *handle, PyObject **device_seen, int *fd_seen, int read_here) {
    PyObject *device = PyObject_GetAttr(handle, vx_n.device), *outage, *fd, *done;
    int in_outage;
    long value;
    if (device == NULL) return -2;
    if (device == Py_None) {
        Py_DECREF(device);
        return -1;
    }
    outage = PyObject_GetAttr(handle, vx_n.outage); /* a reopened bus is back only once a call on it worked */
    in_outage = outage == NULL ? -1 : PyObject_IsTrue(outage);
    Py_XDECREF(outage);
    if (in_outage != 0) {
        Py_DECREF(device);
        return in_outage < 0 ? -2 : -1;
    }
    if (device == *device_seen) {
        Py_DECREF(device);
        return *fd_seen;
    }
    fd = PyObject_CallMethodNoArgs(device, vx_n.fileno);
    value = fd == NULL ? -1 : PyLong_AsLong(fd);
    Py_XDECREF(fd);
    /* a reader of the socket tells the bus so: what is left unread at its close is then counted */
    done = PyErr_Occurred() ? NULL : read_here ? PyObject_CallMethodNoArgs(device, vx_n.read_elsewhere)
                                                : Py_NewRef(device);
    if (done == NULL) {
        Py_DECREF(device);
        return -2;
    }
    Py_DECREF(done);
    Py_XSETREF(*device_seen, device);
    *fd_seen = (int)value;
    return *fd_seen;
}

/* A libvstig frame as python-can's build_can_frame packs it for SocketCAN; its size. */
static size_t pack_frame(const vstig_can_frame_t *f, uint8_t out[72]) {
    uint32_t id = f->id | (f->extended ? 0x80000000ul : 0u);
    size_t size = f->fd ? 72u : 16u;
    memset(out, 0, size);
    memcpy(out, &id, 4); /* native byte order, as struct "=I" */
    out[4] = f->len;
    out[5] = (uint8_t)((f->fd ? 0x04u : 0u) | (f->brs ? 0x01u : 0u)); /* CANFD_FDF, CANFD_BRS */
    out[7] = f->len;                                                   /* len8_dlc: python-can writes the dlc */
    memcpy(out + 8, f->data, f->len);
    return size;
}

/* The batch's frames straight to the socket; 1 done (or handed to the writer), 0 not tried, -1 error. */
static int write_socketcan(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n) {
    vx_port_t *p = &o->port;
    vx_tx_t *tx = &((vx_encoder_t *)o->encoder)->tx;
    vstig_can_frame_t stack[64], *frames = stack;
    size_t count, i, base, extra, sent_messages = 0;
    Py_ssize_t made;
    uint8_t raw[72];
    int fd = vx_socketcan_fd(p->handle, &p->device, &p->fd, 0), status = 1;
    if (fd < -1) return -1;
    if (fd < 0) return 0;
    if (n > 64 && (frames = PyMem_Malloc(n * sizeof *frames)) == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    if ((made = vx_tx_wire(tx, msgs, n, NULL, frames)) <= 0) { /* none: all held back (no tag), as no units */
        if (made < 0) goto error;
        goto done;
    }
    count = (size_t)made;
    base = n / count;
    extra = n % count; /* LinkWriter.submit's spread: unit i carries base + (i < extra) */
    for (i = 0; i < count; i++) {
        size_t size = pack_frame(&frames[i], raw);
        if (send(fd, raw, size, MSG_DONTWAIT) != (ssize_t)size) break;
        sent_messages += base + (i < extra);
    }
    /* the rest (busy, or an error) through the writer, whose write_nowait handles either */
    if (sent_and_rest(o, tx, frames, i, count, n, sent_messages) < 0) goto error;
    goto done;
error:
    status = -1;
done:
    if (frames != stack) PyMem_Free(frames);
    return status;
}
/* A signed link's write lock (CompiledHandle.writing) taken without waiting, into *lock (None: the link has none):
 * 1 taken or none to take, 0 another write holds it (the writer's write_nowait waits for it), -1 error. */
static int take_writing(vx_port_t *p, PyObject **lock) {
    PyObject *got;
    int taken;
    if ((*lock = vx_slot_get(&p->writing_slot, p->handle, vx_n.writing)) == NULL) return -1;
    if (*lock == Py_None) return 1;
    got = PyObject_CallMethodOneArg(*lock, vx_n.acquire, Py_False);
    taken = got == NULL ? -1 : PyObject_IsTrue(got);
    Py_XDECREF(got);
    if (taken <= 0) Py_CLEAR(*lock);
    return taken;
}

/* The lock take_writing took, given back (and its reference); 0, or -1 with an exception. */
static int give_writing(PyObject *lock) {
    PyObject *done = lock == Py_None ? Py_NewRef(Py_None) : PyObject_CallMethodNoArgs(lock, vx_n.release);
    Py_DECREF(lock);
    Py_XDECREF(done);
    return done == NULL ? -1 : 0;
}

/* The TUNNELs of a batch straight to a MAVLink UDP socket, one datagram (MavlinkUdpTransport.write_nowait: `_send`,
 * to the router of a connected udpout socket or to each live peer of a udpin one); 1 done (or handed to the
 * writer), 0 not tried, -1 error. A send that fails at once goes to the writer, whose write_nowait meets the same
 * and handles it; one that fails after others went is counted as `_send` counts it (tx_busy, or the socket lost).
 * A signed link's frames are made and sent under its write lock, the newest timestamp written then the Encoder's
 * `written` (MavlinkFraming.in_order signs again any older frame written after them); while another write holds
 * the lock, the batch goes to the writer. */
static int write_udp(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n) {
    vx_port_t *p = &o->port;
    vx_tx_t *tx = &((vx_encoder_t *)o->encoder)->tx;
    uint8_t stack[VX_MAV_TX_ROOM(64)], *buf = stack;
    size_t len, room = vx_tx_room(tx, n);
    PyObject *peers, *rest, *lock;
    Py_ssize_t targets, i, sent = 0, refused = 0;
    int fd = serial_fd(p), status = 1, failed = 0, taken;
    if (fd < -1) return -1;
    if (fd < 0) return 0; /* the transport reopens it: its write_nowait knows how */
    if ((peers = vx_slot_get(&p->peers_slot, p->handle, vx_n.peers)) == NULL) return -1;
    if (peers != Py_None && !PyObject_TypeCheck(peers, &vx_UdpPeersType)) {
        Py_DECREF(peers); /* peers the C cannot read: the transport's own write sends */
        return 0;
    }
    targets = peers == Py_None ? 1 : vx_peers_live((vx_peers_t *)peers, vx_monotonic());
    if (targets == 0) { /* udpin: nobody has spoken to us lately */
        Py_DECREF(peers);
        return vx_count(p->counters, vx_n.tx_no_peer, 1) < 0 || VX_HOT(o, OUT, (Py_ssize_t)n) < 0
               ? -1 : 1;
    }
    if ((taken = take_writing(p, &lock)) <= 0) {
        Py_DECREF(peers);
        return taken;
    }
    if (room > sizeof stack && (buf = PyMem_Malloc(room)) == NULL) {
        Py_DECREF(peers);
        (void)give_writing(lock);
        PyErr_NoMemory();
        return -1;
    }
    len = vx_tx_bytes(tx, msgs, n, buf);
    for (i = 0; i < targets; i++) {
        const vx_peer_t *peer = peers == Py_None ? NULL : &((vx_peers_t *)peers)->peer[i];
        ssize_t r = peer == NULL ? send(fd, buf, len, MSG_DONTWAIT)
                                 : sendto(fd, buf, len, MSG_DONTWAIT, (const struct sockaddr *)&peer->addr, peer->len);
        if (r >= 0) sent++;
        else if (errno == ECONNREFUSED) refused++; /* nobody there (an ICMP answer): the others still get it */
        else {
            failed = errno;
            break;
        }
    }
    Py_DECREF(peers);
    if (lock != Py_None && (sent || refused)) tx->mav.written = vx_mav_tx_timestamp(&tx->mav);
    if (give_writing(lock) < 0) goto error;
    if (failed && sent == 0 && refused == 0) { /* the first send failed: the writer's write_nowait handles it */
        rest = Py_BuildValue("[y#]", (const char *)buf, (Py_ssize_t)len);
        status = rest == NULL || writer_submit(o, rest, (Py_ssize_t)n) < 0 ? -1 : 1;
        Py_XDECREF(rest);
        goto done;
    }
    if ((refused && vx_count(p->counters, vx_n.tx_refused, refused) < 0) ||
        (sent && (VX_HOT(p, TX, 1) < 0 ||
                  VX_HOT(p, TX_BYTES, sent * (Py_ssize_t)len) < 0)) ||
        VX_HOT(o, OUT, (Py_ssize_t)n) < 0)
        goto error;
    if (failed == EAGAIN || failed == EWOULDBLOCK || failed == ENOBUFS) {
        if (vx_count(p->counters, vx_n.tx_busy, 1) < 0) goto error;
    } else if (failed) { /* the socket failed: as DeviceTransport.write, the transport loses it */
        PyObject *done = vx_call(p->transport, vx_n.failed, "(s)", strerror(failed));
        if (done == NULL || vx_count(p->counters, vx_n.tx_dropped, 1) < 0) {
            Py_XDECREF(done);
            goto error;
        }
        Py_DECREF(done);
    }
    goto done;
error:
    status = -1;
done:
    if (buf != stack) PyMem_Free(buf);
    return status;
}
#endif

/* Outlet._hand: `n` messages handed to the writer, or straight to the device when the writer was idle as the
 * flush found it (`idle`: no Python ran since, so nothing could have given it work). */
static int hand(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n, int idle) {
    int done = 0;
    if (n == 0) return 0;
    o->handed += n;
    if (o->port.kind == VX_PORT_PYTHONCAN) { /* python-can's own send: on every platform */
        if (idle && (done = write_pythoncan(o, msgs, n)) < 0) return -1;
        return done ? 0 : submit_through_writer(o, msgs, n);
    }
#ifndef _WIN32
    if (o->port.kind != VX_PORT_PYTHON && idle) {
        done = o->port.kind == VX_PORT_SERIAL ? write_serial(o, msgs, n)
               : o->port.kind == VX_PORT_UDP  ? write_udp(o, msgs, n)
                                              : write_socketcan(o, msgs, n);
        if (done < 0) return -1;
    }
#else
    (void)idle;
#endif
    return done ? 0 : submit_through_writer(o, msgs, n);
}

/* ---- the share and the window: Outlet's push and flush ------------------------------------- */

static int note_backlog(vx_outlet_t *o) {
    o->backlog = attribute_true(o->queue, vx_n.active);
    return o->backlog < 0 ? -1 : 0;
}

/* len(queue.sparse): the sparse sources waiting, each first in the lines with one message; -1 with an exception */
static Py_ssize_t sparse_waiting(vx_outlet_t *o) {
    PyObject *sparse = PyObject_GetAttr(o->queue, vx_n.sparse);
    Py_ssize_t count;
    if (sparse == NULL) return -1;
    count = PyObject_Length(sparse);
    Py_DECREF(sparse);
    return count;
}

/* Outlet._enqueue: into the source's line; what the lines do not take is counted. */
static int enqueue(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n, long link, PyObject *sub) {
    PyObject *list = message_list(msgs, n), *refused;
    Py_ssize_t count;
    if (list == NULL) return -1;
    refused = vx_call(o->queue, vx_n.push, "(OlO)", list, link, sub);
    Py_DECREF(list);
    if (refused == NULL) return -1;
    count = PyLong_AsSsize_t(refused);
    Py_DECREF(refused);
    if (count == -1 && PyErr_Occurred()) return -1;
    if (vx_count(o->counters, o->not_queued, count) < 0) return -1;
    return note_backlog(o);
}

static int enqueue_held(vx_outlet_t *o) {
    size_t n = o->held_len;
    PyObject *sub = o->held_sub;
    int status;
    if (n == 0) return 0;
    o->held_len = 0;
    o->held_sub = NULL;
    status = enqueue(o, o->held, n, o->held_link, sub);
    Py_XDECREF(sub);
    return status;
}

static int hold(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n) {
    if (o->held_len + n > o->held_cap) {
        size_t cap = (o->held_len + n) * 2;
        vstig_msg_t *grown = PyMem_Realloc(o->held, cap * sizeof *grown);
        if (grown == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        o->held = grown;
        o->held_cap = cap;
    }
    memcpy(o->held + o->held_len, msgs, n * sizeof *msgs);
    o->held_len += n;
    return 0;
}

int vx_outlet_push(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n, long link, PyObject *sub) {
    int same;
    if (n == 0) return 0;
    if (o->held_len == 0) {
        if (!o->backlog) { /* nothing waits: held as it came */
            if (hold(o, msgs, n) < 0) return -1;
            o->held_link = link;
            o->held_sub = Py_NewRef(sub);
            return 0;
        }
    } else if (o->keep_all && link == o->held_link) { /* a raw batch's next unit, from the same source */
        same = sub == o->held_sub ? 1 : PyObject_RichCompareBool(sub, o->held_sub, Py_EQ);
        if (same < 0) return -1;
        if (same) return hold(o, msgs, n);
    }
    if (enqueue_held(o) < 0) return -1;
    return enqueue(o, msgs, n, link, sub);
}

/* writer.room(): the writer's hold while it is idle (what room() answers then, without a call; *idle says so),
 * else its answer */
static long room(vx_outlet_t *o, int *idle) {
    PyObject *answer;
    long value;
    *idle = writer_idle(o);
    if (*idle < 0) return -1;
    if (*idle) return o->hold;
    answer = PyObject_CallMethodNoArgs(o->writer, vx_n.room);
    if (answer == NULL) return -1;
    value = PyLong_AsLong(answer);
    Py_DECREF(answer);
    if (value == -1 && PyErr_Occurred()) return -1;
    return value < 0 ? 0 : value;
}

/* queue.drain(allowed) as C messages; the caller frees *out. */
static int drain_lines(vx_outlet_t *o, long allowed, vstig_msg_t **out, size_t *n) {
    PyObject *batch = vx_call(o->queue, vx_n.drain, "(l)", allowed);
    Py_ssize_t i, len;
    *out = NULL;
    *n = 0;
    if (batch == NULL) return -1;
    if (!PyList_Check(batch)) {
        Py_DECREF(batch);
        PyErr_SetString(PyExc_TypeError, "the fair share's drain must return a list of Messages");
        return -1;
    }
    len = PyList_GET_SIZE(batch);
    *out = PyMem_Malloc((size_t)(len ? len : 1) * sizeof **out);
    if (*out == NULL) {
        Py_DECREF(batch);
        PyErr_NoMemory();
        return -1;
    }
    for (i = 0; i < len; i++) {
        if (vx_msg_of(PyList_GET_ITEM(batch, i), &(*out)[i]) < 0) {
            Py_DECREF(batch);
            PyMem_Free(*out);
            *out = NULL;
            return -1;
        }
    }
    *n = (size_t)len;
    Py_DECREF(batch);
    return 0;
}

int vx_outlet_flush(vx_outlet_t *o, double now, double *retry) {
    vx_window_t *window = o->window;
    int idle;
    if (o->held_len) { /* nothing else waits: all of it now, as it came, if the window and the writer take it all */
        long r = room(o, &idle);
        if (r < 0) return -1;
        if ((long)o->held_len <= r && (window->budget == 0 || (long)o->held_len <= vx_window_free(window, now))) {
            size_t n = o->held_len;
            o->held_len = 0;
            Py_CLEAR(o->held_sub);
            vx_window_record(window, now, (long)n, 0, 0);
            return hand(o, o->held, n, idle);
        }
        if (enqueue_held(o) < 0) return -1;
    }
    while (o->backlog) {
        vstig_msg_t *batch;
        size_t n;
        int status;
        Py_ssize_t sparse = 0;
        long allowed = room(o, &idle);
        if (allowed < 0) return -1;
        if (allowed == 0) return 0; /* the writer calls on_room when it has room again */
        if (window->budget != 0) {
            long free_;
            if ((sparse = sparse_waiting(o)) < 0) return -1;
            if (sparse) { /* sparse sources' messages, first in the lines: at once, the budget allowing */
                if (sparse < allowed) allowed = (long)sparse;
                free_ = vx_window_free(window, now);
            } else {
                free_ = vx_window_allowance(window, now);
            }
            if (free_ < allowed) allowed = free_;
            if (allowed <= 0) return vx_window_next_free(window, sparse != 0, retry);
        }
        if (drain_lines(o, allowed, &batch, &n) < 0 || note_backlog(o) < 0) {
            PyMem_Free(batch);
            return -1;
        }
        vx_window_record(window, now, (long)n, o->backlog, sparse != 0);
        status = hand(o, batch, n, idle);
        PyMem_Free(batch);
        if (status < 0) return -1;
    }
    return 0;
}

/* ---- the Python type -------------------------------------------------------------------- */

static PyObject *Outlet_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"link", "writer", "window", "queue", "keep_all", "encoder", "port", NULL};
    PyObject *link, *writer, *window, *queue, *encoder = Py_None, *hold_obj;
    int keep_all = 0;
    const char *port = "python";
    vx_outlet_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OOO!O|$pOs", kwlist, &link, &writer, &vx_WindowType, &window,
                                     &queue, &keep_all, &encoder, &port))
        return NULL;
    if (encoder != Py_None && !PyObject_TypeCheck(encoder, &vx_EncoderType)) {
        PyErr_SetString(PyExc_TypeError, "encoder must be an Encoder or None");
        return NULL;
    }
    self = (vx_outlet_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->link = Py_NewRef(link);
    self->writer = Py_NewRef(writer);
    self->window = (vx_window_t *)Py_NewRef(window);
    self->queue = Py_NewRef(queue);
    self->encoder = encoder == Py_None ? NULL : Py_NewRef(encoder);
    self->keep_all = keep_all;
    self->not_queued = Py_NewRef(keep_all ? vx_n.drop_overflow : vx_n.superseded);
    self->counters = PyObject_GetAttr(link, vx_n.counters);
    self->port.transport = PyObject_GetAttr(link, vx_n.transport);
    self->port.counters = self->port.transport == NULL ? NULL : PyObject_GetAttr(self->port.transport,
                                                                                 vx_n.counters);
    hold_obj = PyObject_GetAttr(writer, vx_n.hold);
    self->hold = hold_obj == NULL ? -1 : PyLong_AsLong(hold_obj);
    Py_XDECREF(hold_obj);
    if (self->counters == NULL || self->port.counters == NULL || PyErr_Occurred() || note_backlog(self) < 0)
        goto fail;
    self->pending = vx_pending_of(self->counters);
    self->port.pending = PyErr_Occurred() ? NULL : vx_pending_of(self->port.counters);
    if (PyErr_Occurred()) goto fail;
    if (strcmp(port, "serial") == 0) self->port.kind = VX_PORT_SERIAL;
    else if (strcmp(port, "socketcan") == 0) self->port.kind = VX_PORT_SOCKETCAN;
    else if (strcmp(port, "pythoncan") == 0) self->port.kind = VX_PORT_PYTHONCAN;
    else if (strcmp(port, "udp") == 0) self->port.kind = VX_PORT_UDP;
    else if (strcmp(port, "python") != 0) {
        PyErr_Format(PyExc_ValueError, "port must be serial, socketcan, udp or python, got %s", port);
        goto fail;
    }
    if (self->port.kind != VX_PORT_PYTHON && self->encoder == NULL) {
        PyErr_SetString(PyExc_ValueError, "writing straight to a device needs the link's Encoder");
        goto fail;
    }
    /* a device written here: the transport's declared handle on it (its fd, its bus) */
    self->port.handle = self->port.kind == VX_PORT_PYTHON
                            ? Py_NewRef(Py_None)
                            : PyObject_CallMethodNoArgs(self->port.transport, vx_n.compiled_handle);
    if (self->port.handle == NULL) goto fail;
    if (self->port.handle == Py_None && self->port.kind != VX_PORT_PYTHON) {
        PyErr_SetString(PyExc_TypeError, "writing straight to a device needs its transport's compiled handle");
        goto fail;
    }
    vx_slot_resolve(&self->port.fd_slot, self->port.handle, vx_n.fd);
    vx_slot_resolve(&self->port.fresh_slot, self->port.handle, vx_n.fresh);
    vx_slot_resolve(&self->port.peers_slot, self->port.handle, vx_n.peers);
    vx_slot_resolve(&self->port.writing_slot, self->port.handle, vx_n.writing);
    return (PyObject *)self;
fail:
    Py_DECREF(self);
    return NULL;
}

static int Outlet_traverse(vx_outlet_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->link);
    Py_VISIT(self->counters);
    Py_VISIT(self->writer);
    Py_VISIT(self->queue);
    Py_VISIT(self->window);
    Py_VISIT(self->encoder);
    Py_VISIT(self->held_sub);
    Py_VISIT(self->port.transport);
    Py_VISIT(self->port.counters);
    Py_VISIT(self->pending);
    Py_VISIT(self->port.pending);
    Py_VISIT(self->port.device);
    Py_VISIT(self->port.handle);
    return 0;
}

static int Outlet_clear(vx_outlet_t *self) {
    Py_CLEAR(self->link);
    Py_CLEAR(self->counters);
    Py_CLEAR(self->writer);
    Py_CLEAR(self->queue);
    Py_CLEAR(self->window);
    Py_CLEAR(self->encoder);
    Py_CLEAR(self->not_queued);
    Py_CLEAR(self->held_sub);
    Py_CLEAR(self->port.transport);
    Py_CLEAR(self->port.counters);
    Py_CLEAR(self->pending);
    Py_CLEAR(self->port.pending);
    Py_CLEAR(self->port.device);
    Py_CLEAR(self->port.handle);
    return 0;
}

static void Outlet_dealloc(vx_outlet_t *self) {
    PyObject_GC_UnTrack(self);
    Outlet_clear(self);
    PyMem_Free(self->held);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

extern vstig_msg_t *vx_msgs_of(PyObject *messages, size_t *n);

static PyObject *Outlet_push(vx_outlet_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"messages", "link", "sub", NULL};
    PyObject *messages, *sub = Py_None;
    long link = VX_LOCAL;
    size_t n;
    vstig_msg_t *msgs;
    int status;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|lO", kwlist, &messages, &link, &sub)) return NULL;
    if ((msgs = vx_msgs_of(messages, &n)) == NULL) return NULL;
    status = vx_outlet_push(self, msgs, n, link, sub);
    PyMem_Free(msgs);
    if (status < 0) return NULL;
    Py_RETURN_NONE;
}

static PyObject *Outlet_flush(vx_outlet_t *self, PyObject *now_obj) {
    double now = PyFloat_AsDouble(now_obj), retry;
    int status;
    if (now == -1.0 && PyErr_Occurred()) return NULL;
    status = vx_outlet_flush(self, now, &retry);
    if (status < 0) return NULL;
    if (status == 0) Py_RETURN_NONE;
    return PyFloat_FromDouble(retry);
}

static Py_ssize_t Outlet_len(vx_outlet_t *self) {
    Py_ssize_t queued = PyObject_Length(self->queue);
    return queued < 0 ? -1 : queued + (Py_ssize_t)self->held_len;
}

static PyObject *Outlet_close(vx_outlet_t *self, PyObject *unused) {
    /* Outlet.close: the device takes what is queued (briefly), then the writer stops */
    (void)unused;
    return PyObject_CallMethodNoArgs(self->writer, vx_n.close);
}

static PyObject *Outlet_get_keep_all(vx_outlet_t *self, void *closure) {
    (void)closure;
    return PyBool_FromLong(self->keep_all);
}

static PyMethodDef Outlet_methods[] = {
    {"push", (PyCFunction)(void (*)(void))Outlet_push, METH_VARARGS | METH_KEYWORDS,
     "Queue messages from source (link, sub)."},
    {"flush", (PyCFunction)Outlet_flush, METH_O, "Send what the window and the writer's room allow."},
    {"close", (PyCFunction)Outlet_close, METH_NOARGS, "Let the device take what is queued (briefly), then stop."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Outlet_members[] = {
    {"link", T_OBJECT, offsetof(vx_outlet_t, link), READONLY, NULL},
    {"counters", T_OBJECT, offsetof(vx_outlet_t, counters), READONLY, NULL},
    {"writer", T_OBJECT, offsetof(vx_outlet_t, writer), READONLY, NULL},
    {"window", T_OBJECT, offsetof(vx_outlet_t, window), READONLY, NULL},
    {"queue", T_OBJECT, offsetof(vx_outlet_t, queue), READONLY, NULL},
    {"handed", T_ULONGLONG, offsetof(vx_outlet_t, handed), 0,
     "Messages handed to the writer or the device so far (what Node.drain waits for)."},
    {NULL, 0, 0, 0, NULL},
};

static PyGetSetDef Outlet_getset[] = {
    {"keep_all", (getter)Outlet_get_keep_all, NULL, "Raw mode: every frame kept, in order per source.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PySequenceMethods Outlet_as_sequence = {.sq_length = (lenfunc)Outlet_len};

PyTypeObject vx_OutletType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Outlet",
    .tp_doc = "Outlet(link, writer, window, queue, *, keep_all=False, encoder=None, port='python'): "
              "one link's way out, Outlet in C.",
    .tp_basicsize = sizeof(vx_outlet_t),
    /* a base type: the gateway adds the Python-side calls a stop and a confirmed write make (compiled.py) */
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC,
    .tp_new = Outlet_new,
    .tp_dealloc = (destructor)Outlet_dealloc,
    .tp_traverse = (traverseproc)Outlet_traverse,
    .tp_clear = (inquiry)Outlet_clear,
    .tp_methods = Outlet_methods,
    .tp_members = Outlet_members,
    .tp_getset = Outlet_getset,
    .tp_as_sequence = &Outlet_as_sequence,
};
