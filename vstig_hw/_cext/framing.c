/*
 * Receiver and Encoder: a link's framing in C, libvstig's receivers and encoders with the Python
 * framings' interface (feed, tick, reset; encode_batch), for cobs8, epuck4, kilobot, CAN, XBee (API frames
 * in mode 1 or 2, whole frames a unit as the XBee transport cuts them) and MAVLink (TUNNELs, signed or not: mavlink.c).
 *
 * Reference: vstig_hw/framing/cobs8.py vstig_hw/framing/epuck4.py vstig_hw/framing/kilobot.py
 *   vstig_hw/framing/can.py vstig_hw/framing/xbee.py vstig_hw/framing/mavlink.py (held equal by tests/native; the index of the twins:
 *   vstig_hw/_vstig.pyi).
 *
 * A Receiver counts its drops in the Python framing's own `drops` Counters (given when built), so
 * a link's stats read the same whichever side decoded.
 */
#include "framing.h"
#include "engine.h"

#include <string.h>
#include <structmember.h>

static const char *const FRAMINGS[VX_FRAMINGS] = {"cobs8", "epuck4", "kilobot", "can", "xbee", "mavlink"};

static int framing_kind(PyObject *name) {
    int kind;
    const char *text = PyUnicode_Check(name) ? PyUnicode_AsUTF8(name) : NULL;
    for (kind = 0; text != NULL && kind < (int)VX_FRAMINGS; kind++) {
        if (strcmp(text, FRAMINGS[kind]) == 0) return kind;
    }
    if (!PyErr_Occurred()) PyErr_Format(PyExc_ValueError, "no compiled framing %R (cobs8, epuck4, kilobot, can, xbee, mavlink)", name);
    return -1;
}

/* The CAN scheme's fields; 0, or -1 with ValueError naming what libvstig refused. */
static int can_scheme(vstig_can_t *can, int extended, PyObject *base, int stigmergy, int sender, int fd, int brs) {
    unsigned long base_value = VSTIG_CAN_DEFAULT_BASE;
    if (base != Py_None) {
        base_value = PyLong_AsUnsignedLong(base);
        if (PyErr_Occurred()) return -1;
    }
    if (stigmergy < 0 || stigmergy > 255 || sender < 0 || sender > 0xFFFF ||
        vstig_can_init(can, (uint8_t)(extended != 0), (uint32_t)base_value, (uint8_t)stigmergy, (uint16_t)sender,
                       (uint8_t)(fd != 0), (uint8_t)(brs != 0)) != 0) {
        PyErr_Format(PyExc_ValueError, "no such CAN scheme: extended=%d base=%R stigmergy=%d sender=%d", extended,
                     base, stigmergy, sender);
        return -1;
    }
    return 0;
}

/* ---- receiving ------------------------------------------------------------------------- */

/* cobs8: a frame's payload is a message, or a record (SPEC.md 10.5), kept where the link checks tags */
static size_t cobs8_bytes(vx_rx_t *rx, const uint8_t *data, size_t len, size_t *used, vstig_msg_t *out, size_t max) {
    vstig_deframer_t *d = &rx->serial.deframer;
    size_t i = 0, n = 0;
    while (i < len && n < max) { /* a frame at a time (feed_run), not a call per byte */
        uint8_t size;
        i += vstig_deframer_feed_run(d, data + i, len - i, VSTIG_MESSAGE_SIZE, VSTIG_RECORD_SIZE, &size);
        if (size == 0) continue;
        vstig_msg_decode(d->buf, &out[n]);
        if (size == VSTIG_RECORD_SIZE && rx->policy != VSTIG_AUTH_OFF)
            vx_records_add(&rx->records, &out[n], d->buf + VSTIG_MESSAGE_SIZE, rx->emitted + n);
        n++;
    }
    *used = i;
    rx->emitted += n;
    return n;
}

size_t vx_rx_bytes(vx_rx_t *rx, const uint8_t *data, size_t len, size_t *used, vstig_msg_t *out, size_t max) {
    if (rx->kind == VX_COBS8) return cobs8_bytes(rx, data, len, used, out, max);
    return vstig_serial_receive(&rx->serial, data, len, used, out, max);
}

void vx_rx_unit_done(vx_rx_t *rx) {
    rx->records.n = 0;
    rx->emitted = 0;
}

/* One whole frame the XBee receiver cut: its messages at out[n..], the sender noted. */
/* A Receive Packet or Transmit Request whose RF data is a tagged batch (SPEC.md 10.5: VX_BATCH_MARKER and N >= 1
 * records; never 8*N bytes): its messages at out, their records kept where the link checks tags; 0 for any other
 * frame (vstig_xbee_messages' then, a batch of another length dropped there as bad_length). */
static uint8_t xbee_batch(vx_rx_t *rx, const uint8_t *data, uint16_t len, vstig_msg_t *out, uint8_t source[8],
                          uint8_t *has_source) {
    uint16_t header = data[0] == VSTIG_XBEE_RECEIVE_PACKET ? VSTIG_XBEE_RX_HEADER : VSTIG_XBEE_TX_HEADER, rf, at;
    uint8_t n = 0, i;
    if ((data[0] != VSTIG_XBEE_RECEIVE_PACKET && data[0] != VSTIG_XBEE_TRANSMIT_REQUEST) || len < header)
        return 0;
    rf = (uint16_t)(len - header);
    if (rf < 1u + VSTIG_RECORD_SIZE || data[header] != VX_BATCH_MARKER || (rf - 1u) % VSTIG_RECORD_SIZE != 0)
        return 0;
    for (at = (uint16_t)(header + 1u); at < len; at = (uint16_t)(at + VSTIG_RECORD_SIZE), n++) {
        vstig_msg_decode(data + at, &out[n]);
        if (rx->policy != VSTIG_AUTH_OFF) vx_records_add(&rx->records, &out[n], data + at + 8, rx->emitted + n);
    }
    *has_source = data[0] == VSTIG_XBEE_RECEIVE_PACKET;
    for (i = 0; *has_source && i < 8u; i++) source[i] = data[1 + i];
    return n;
}

static size_t xbee_frame(vx_rx_t *rx, vstig_msg_t *out) {
    const uint8_t *data = vstig_xbee_frame_data(&rx->xbee);
    uint16_t len = vstig_xbee_frame_len(&rx->xbee);
    uint8_t source[8], has_source = 0, n = xbee_batch(rx, data, len, out, source, &has_source), i;
    if (n == 0 && vstig_xbee_messages(data, len, out, &n, source, &has_source, &rx->xbee.drops) == VSTIG_XBEE_REPORT)
        vstig_drops_count(&rx->xbee.drops, VSTIG_DROP_UNKNOWN_TYPE); /* the transport keeps the module's reports */
    rx->emitted += n;
    if (n && has_source && !rx->has_sender) {
        rx->has_sender = 1;
        rx->sender = 0;
        for (i = 0; i < 8u; i++) rx->sender = rx->sender << 8 | source[i];
    }
    return n;
}

size_t vx_rx_xbee(vx_rx_t *rx, const uint8_t *data, size_t len, vstig_msg_t *out) {
    /* XBeeFraming.feed: a unit is whole, so what it did not complete never will (fed, then flushed) */
    size_t i, n = 0;
    rx->has_sender = 0;
    for (i = 0; i <= len; i++) {
        if (i < len ? !vstig_xbee_feed(&rx->xbee, data[i]) : !vstig_xbee_flush(&rx->xbee)) continue;
        do n += xbee_frame(rx, out + n);
        while (vstig_xbee_next(&rx->xbee));
    }
    return n;
}

size_t vx_rx_whole(vx_rx_t *rx, const uint8_t *data, size_t len, vstig_msg_t *out) {
    if (rx->kind == VX_MAVLINK) return vx_mav_feed(&rx->mav, data, len, out, &rx->has_sender, &rx->sender);
    return vx_rx_xbee(rx, data, len, out);
}

size_t vx_rx_frame(vx_rx_t *rx, const vstig_can_frame_t *frame, vstig_msg_t out[8], uint16_t *sender) {
    vstig_can_frame_t message;
    size_t n;
    if (!frame->fd || frame->len != VSTIG_RECORD_SIZE) {
        n = vstig_can_receive(&rx->can, frame, out, sender);
        rx->emitted += n;
        return n;
    }
    message = *frame; /* a record: its message as the 8-byte frame it starts with (IDs and op checked alike) */
    message.len = VSTIG_MESSAGE_SIZE;
    n = vstig_can_receive(&rx->can, &message, out, sender);
    if (n == 1 && rx->policy != VSTIG_AUTH_OFF) vx_records_add(&rx->records, &out[0], frame->data + 8, rx->emitted);
    rx->emitted += n;
    return n;
}

int vx_rx_harvest(vx_rx_t *rx) {
    if (rx->records.lost) { /* a record without room: the unit cannot be judged as it came */
        rx->records.lost = 0;
        PyErr_SetString(PyExc_MemoryError, "no memory for a unit's records");
        return -1;
    }
    if (rx->kind == VX_CAN) return vx_harvest_drops(&rx->can.drops, rx->drops);
    if (rx->kind == VX_XBEE) return vx_harvest_drops(&rx->xbee.drops, rx->drops);
    if (rx->kind == VX_MAVLINK) return vx_mav_harvest(&rx->mav, rx->drops);
    if (vx_harvest_drops(&rx->serial.deframer.drops, rx->drops) < 0) return -1;
    return rx->kind == VX_EPUCK4 ? vx_harvest_drops(&rx->epuck4.drops, rx->drops) : 0;
}

PyObject *vx_can_field(PyObject *unit, vx_can_field_t field) {
    /* read at the offsets of the first class met that declares them as slots (python-can's Message, which every bus
     * makes): ~20 instructions a read where a lookup by name is ~160; a frame of any other class is read by name */
    static vx_slot_t slots[VX_CAN_FIELDS];
    static const PyTypeObject *tried; /* the last class resolution was tried on (compared only) */
    PyObject *const names[VX_CAN_FIELDS] = {vx_n.arbitration_id, vx_n.is_extended_id, vx_n.is_fd,
                                            vx_n.is_remote_frame, vx_n.is_error_frame, vx_n.data, vx_n.timestamp};
    vx_slots_resolve_once(slots, names, VX_CAN_FIELDS, unit, &tried);
    return vx_slot_get(&slots[field], unit, names[field]);
}

int vx_frame_of(PyObject *unit, vstig_can_frame_t *frame) {
    PyObject *value[6] = {NULL, NULL, NULL, NULL, NULL, NULL};
    Py_buffer data;
    int i, status = -1;
    unsigned long id;
    for (i = 0; i < 6; i++) { /* the fields in vx_can_field_t's order, up to the data */
        if ((value[i] = vx_can_field(unit, (vx_can_field_t)i)) == NULL) goto done;
    }
    id = PyLong_AsUnsignedLong(value[0]);
    if (PyErr_Occurred()) goto done;
    frame->id = (uint32_t)id;
    frame->extended = (uint8_t)PyObject_IsTrue(value[1]);
    frame->fd = (uint8_t)PyObject_IsTrue(value[2]);
    frame->rtr = (uint8_t)PyObject_IsTrue(value[3]);
    frame->error = (uint8_t)PyObject_IsTrue(value[4]);
    frame->brs = 0;
    if (PyObject_GetBuffer(value[5], &data, PyBUF_SIMPLE) < 0) goto done;
    /* a frame longer than any CAN frame is kept too long, so that it is dropped as bad_dlc */
    frame->len = (uint8_t)(data.len > 255 ? 255 : data.len);
    memcpy(frame->data, data.buf, (size_t)(data.len > VSTIG_CAN_FD_MAX ? VSTIG_CAN_FD_MAX : data.len));
    PyBuffer_Release(&data);
    status = 0;
done:
    for (i = 0; i < 6; i++) Py_XDECREF(value[i]);
    return status;
}

static PyObject *Receiver_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"framing", "drops", "expiry_ticks", "kilobot_type", "extended", "base", "stigmergy",
                             "escaped", "on_tick", "sysid", "compid", "key", NULL};
    PyObject *name, *drops, *base = Py_None, *on_tick = Py_None, *key = Py_None;
    int expiry_ticks = 3, kilobot_type = VSTIG_KILOBOT_TYPE, extended = 0, stigmergy = 0, escaped = 0, kind;
    int sysid = 1, compid = VSTIG_MAVLINK_COMP_ID;
    vx_receiver_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OO!|$iipOipOiiO", kwlist, &name, &PyDict_Type, &drops,
                                     &expiry_ticks, &kilobot_type, &extended, &base, &stigmergy, &escaped, &on_tick,
                                     &sysid, &compid, &key))
        return NULL;
    if (on_tick != Py_None && !PyCallable_Check(on_tick)) {
        PyErr_SetString(PyExc_TypeError, "on_tick must be callable or None");
        return NULL;
    }
    if ((kind = framing_kind(name)) < 0) return NULL;
    if (expiry_ticks < 1 || expiry_ticks > 254) {
        PyErr_Format(PyExc_ValueError, "the compiled epuck4 receiver expires after 1..254 ticks, got %d", expiry_ticks);
        return NULL;
    }
    self = (vx_receiver_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->rx.kind = (uint8_t)kind;
    self->rx.drops = Py_NewRef(drops);
    self->rx.on_tick = Py_NewRef(on_tick);
    self->rx.policy = VSTIG_AUTH_OFF;
    self->rx.refuse = Py_NewRef(Py_None);
    vstig_epuck4_init(&self->rx.epuck4, (uint8_t)expiry_ticks);
    vstig_xbee_rx_init(&self->rx.xbee, (uint8_t)escaped);
    if (kind == VX_XBEE) {
        /* nothing more: the XBee receiver needs only its API mode */
    } else if (kind == VX_MAVLINK) {
        if (vx_mav_rx_init(&self->rx.mav, sysid, compid, key) < 0) goto fail;
    } else if (kind == VX_CAN) {
        if (can_scheme(&self->rx.can, extended, base, stigmergy, 0, 0, 0) < 0) goto fail;
    } else if (kilobot_type < 0 || kilobot_type >= 0x80 ||
               vstig_serial_rx_init(&self->rx.serial, (uint8_t)kind, (uint8_t)kilobot_type, &self->rx.epuck4) != 0) {
        PyErr_Format(PyExc_ValueError, "Kilobot message type must be a user type in 0..127, got %d", kilobot_type);
        goto fail;
    }
    return (PyObject *)self;
fail:
    Py_DECREF(self);
    return NULL;
}

static int Receiver_traverse(vx_receiver_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->rx.drops);
    Py_VISIT(self->rx.on_tick);
    Py_VISIT(self->rx.refuse);
    return 0;
}

static int Receiver_clear(vx_receiver_t *self) {
    Py_CLEAR(self->rx.drops);
    Py_CLEAR(self->rx.on_tick);
    Py_CLEAR(self->rx.refuse);
    return 0;
}

static void Receiver_dealloc(vx_receiver_t *self) {
    PyObject_GC_UnTrack(self);
    Receiver_clear(self);
    vx_mav_rx_free(&self->rx.mav);
    PyMem_Free(self->rx.records.at);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

#define FEED_BATCH 64u

/* feed(unit) -> the messages it completes (bytes for a serial framing, a can.Message for CAN) */
static PyObject *Receiver_feed(vx_receiver_t *self, PyObject *unit) {
    vstig_msg_t out[FEED_BATCH];
    PyObject *list = PyList_New(0);
    size_t n, i;
    if (list == NULL) return NULL;
    vx_rx_unit_done(&self->rx);
    if (self->rx.kind == VX_CAN) {
        vstig_can_frame_t frame;
        uint16_t sender;
        if (vx_frame_of(unit, &frame) < 0) goto fail;
        n = vx_rx_frame(&self->rx, &frame, out, &sender);
        for (i = 0; i < n; i++) {
            PyObject *m = vx_message(&out[i]);
            if (m == NULL || PyList_Append(list, m) < 0) {
                Py_XDECREF(m);
                goto fail;
            }
            Py_DECREF(m);
        }
    } else if (self->rx.kind == VX_XBEE || self->rx.kind == VX_MAVLINK) {
        Py_buffer data;
        vstig_msg_t *got;
        if (PyObject_GetBuffer(unit, &data, PyBUF_SIMPLE) < 0) goto fail;
        got = PyMem_Malloc(((size_t)data.len / VSTIG_MESSAGE_SIZE + 1u) * sizeof *got);
        if (got == NULL) {
            PyBuffer_Release(&data);
            PyErr_NoMemory();
            goto fail;
        }
        n = vx_rx_whole(&self->rx, (const uint8_t *)data.buf, (size_t)data.len, got);
        PyBuffer_Release(&data);
        for (i = 0; i < n; i++) {
            PyObject *m = vx_message(&got[i]);
            if (m == NULL || PyList_Append(list, m) < 0) {
                Py_XDECREF(m);
                PyMem_Free(got);
                goto fail;
            }
            Py_DECREF(m);
        }
        PyMem_Free(got);
    } else {
        Py_buffer data;
        size_t at = 0, used;
        if (PyObject_GetBuffer(unit, &data, PyBUF_SIMPLE) < 0) goto fail;
        while (at < (size_t)data.len) {
            n = vx_rx_bytes(&self->rx, (const uint8_t *)data.buf + at, (size_t)data.len - at, &used, out, FEED_BATCH);
            at += used;
            for (i = 0; i < n; i++) {
                PyObject *m = vx_message(&out[i]);
                if (m == NULL || PyList_Append(list, m) < 0) {
                    Py_XDECREF(m);
                    PyBuffer_Release(&data);
                    goto fail;
                }
                Py_DECREF(m);
            }
        }
        PyBuffer_Release(&data);
    }
    if (vx_rx_harvest(&self->rx) < 0) goto fail;
    return list;
fail:
    Py_DECREF(list);
    return NULL;
}

/* check_tags(auth, refuse): the link checks tags by policy `auth` (0 require, 1 prefer, 2 off: AuthPolicy's order),
 * refusing through `refuse` (its Signing.refuse): records are kept from now on (SPEC.md 10.5, 10.6) */
static PyObject *Receiver_check_tags(vx_receiver_t *self, PyObject *args) {
    int auth;
    PyObject *refuse;
    if (!PyArg_ParseTuple(args, "iO:check_tags", &auth, &refuse)) return NULL;
    if (auth < VSTIG_AUTH_REQUIRE || auth > VSTIG_AUTH_OFF || !PyCallable_Check(refuse)) {
        PyErr_Format(PyExc_ValueError, "check_tags takes auth 0 (require), 1 (prefer) or 2 (off) and a callable, "
                                       "got %d and %R", auth, refuse);
        return NULL;
    }
    self->rx.policy = (vstig_auth_policy_t)auth;
    Py_INCREF(refuse);
    Py_SETREF(self->rx.refuse, refuse);
    vx_rx_unit_done(&self->rx);
    Py_RETURN_NONE;
}

/* feed_tagged(unit) -> [(message, (epoch, tag) or None)]: feed's messages, each with its record's epoch and tag
 * where the link checks tags and it came as one (the Python delivery's Signing.decoder) */
static PyObject *Receiver_feed_tagged(vx_receiver_t *self, PyObject *unit) {
    PyObject *messages = Receiver_feed(self, unit), *pairs;
    Py_ssize_t i;
    size_t r = 0;
    if (messages == NULL) return NULL;
    pairs = PyList_New(PyList_GET_SIZE(messages));
    for (i = 0; pairs != NULL && i < PyList_GET_SIZE(messages); i++) {
        const vx_record_t *record = r < self->rx.records.n && self->rx.records.at[r].place == (size_t)i
                                        ? &self->rx.records.at[r++] : NULL;
        PyObject *pair = record == NULL
            ? Py_BuildValue("(OO)", PyList_GET_ITEM(messages, i), Py_None)
            : Py_BuildValue("(O(ky#))", PyList_GET_ITEM(messages, i), (unsigned long)record->epoch,
                            (const char *)record->tag, (Py_ssize_t)VSTIG_TAG_SIZE);
        if (pair == NULL) Py_CLEAR(pairs);
        else PyList_SET_ITEM(pairs, i, pair);
    }
    vx_rx_unit_done(&self->rx);
    Py_DECREF(messages);
    return pairs;
}

static PyObject *Receiver_tick(vx_receiver_t *self, PyObject *unused) {
    (void)unused;
    if (self->rx.kind == VX_EPUCK4) {
        vstig_epuck4_tick(&self->rx.epuck4);
        if (vx_rx_harvest(&self->rx) < 0) return NULL;
    }
    if (self->rx.on_tick != Py_None) {
        PyObject *done = PyObject_CallNoArgs(self->rx.on_tick);
        if (done == NULL) return NULL;
        Py_DECREF(done);
    }
    Py_RETURN_NONE;
}

static PyObject *Receiver_reset(vx_receiver_t *self, PyObject *unused) {
    /* forget a partial frame (the port was reopened), as CobsFrameReader.reset does */
    (void)unused;
    self->rx.serial.deframer.len = 0;
    self->rx.serial.deframer.discarding = 0;
    vstig_xbee_rx_reset(&self->rx.xbee);
    Py_RETURN_NONE;
}

/* XBee: the 64-bit source of the last unit's messages (what Node._arrive's sender_of says); MAVLink: its sysid << 8
 * | compid; or None. */
static PyObject *Receiver_get_sender(vx_receiver_t *self, void *closure) {
    (void)closure;
    if (!self->rx.has_sender) Py_RETURN_NONE;
    return PyLong_FromUnsignedLongLong(self->rx.sender);
}

static PyGetSetDef Receiver_getset[] = {
    {"sender", (getter)Receiver_get_sender, NULL, "XBee, MAVLink: the sender of the last unit fed, or None.",
     NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyMethodDef Receiver_methods[] = {
    {"feed", (PyCFunction)Receiver_feed, METH_O, "The messages this unit completes; drops counted in `drops`."},
    {"feed_tagged", (PyCFunction)Receiver_feed_tagged, METH_O, "feed's messages, each with its (epoch, tag) or None."},
    {"check_tags", (PyCFunction)Receiver_check_tags, METH_VARARGS, "The link checks tags: by this policy, refusing so."},
    {"tick", (PyCFunction)Receiver_tick, METH_NOARGS, "One control period passed (expires epuck4 fragments)."},
    {"reset", (PyCFunction)Receiver_reset, METH_NOARGS, "Forget any partial frame."},
    {NULL, NULL, 0, NULL},
};

PyTypeObject vx_ReceiverType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Receiver",
    .tp_doc = "Receiver(framing, drops, *, expiry_ticks=3, kilobot_type=0x56, extended=False, base=None, "
              "stigmergy=0, escaped=False, on_tick=None, sysid=1, compid=191, key=None): a link's receiving framing in C.",
    .tp_basicsize = sizeof(vx_receiver_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = Receiver_new,
    .tp_dealloc = (destructor)Receiver_dealloc,
    .tp_traverse = (traverseproc)Receiver_traverse,
    .tp_clear = (inquiry)Receiver_clear,
    .tp_methods = Receiver_methods,
    .tp_getset = Receiver_getset,
};

/* ---- encoding -------------------------------------------------------------------------- */

size_t vx_tx_room(const vx_tx_t *tx, size_t n) {
    if (tx->kind == VX_MAVLINK) return VX_MAV_TX_ROOM(n);
    if (tx->kind != VX_XBEE) return n * VX_SERIAL_MAX_BYTES; /* a cobs8 record's frame too (24 bytes) */
    /* with tags: as if each message were a tagged batch of its own, beside the untagged ones' frames */
    return VSTIG_XBEE_TX_BYTES(n) + (tx->tag_engine ? n * VSTIG_XBEE_TRANSMIT_BYTES(1u + VSTIG_RECORD_SIZE) : 0u);
}

/* MAVLink: the TUNNELs of n messages back to back, 16 to a TUNNEL (MavlinkFraming.encode_batch, joined as
 * Link.units_of joins a byte stream's units). */
static size_t mavlink_tunnels(vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out) {
    size_t at = 0, w = 0;
    while (at < n) {
        uint8_t count = (uint8_t)(n - at < VSTIG_MAVLINK_MAX_MESSAGES ? n - at : VSTIG_MAVLINK_MAX_MESSAGES);
        uint16_t len;
        vx_mav_tx_clock(&tx->mav);
        len = vstig_mavlink_encode(&tx->mav.tx, msgs + at, count, out + w);
        w += len;
        at += count;
    }
    return w;
}

size_t vx_tx_bytes(vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out) {
    size_t i, w = 0;
    uint32_t words[3];
    uint8_t k;
    if (tx->kind == VX_XBEE) return vstig_xbee_encode(&tx->xbee, msgs, n, out);
    if (tx->kind == VX_MAVLINK) return mavlink_tunnels(tx, msgs, n, out);
    for (i = 0; i < n; i++) {
        switch (tx->kind) {
        case VX_COBS8:
            w += vstig_cobs8_encode(&msgs[i], out + w);
            break;
        case VX_EPUCK4:
            vstig_epuck4_encode(&msgs[i], words);
            for (k = 0; k < 3; k++) w += vstig_epuck4_word_frame(words[k], out + w);
            break;
        default:
            w += vstig_kilobot_frame(&msgs[i], tx->kilobot_type, out + w);
            break;
        }
    }
    return w;
}

size_t vx_tx_frames(const vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, vstig_can_frame_t *frames) {
    return vstig_can_encode(&tx->can, msgs, n, frames);
}

/* CAN units are copies of one can.Message that frame_type's own constructor made when the Encoder was built (the
 * template), with a frame's fields written into the slots python-can declares (can.Message.__slots__): python-can's
 * __init__ is Python, ~8k instructions a frame; a copy is ~1k. Only a class of slots alone (no __dict__, no base but
 * object, object's __new__) whose template holds nothing mutable is copied; any other frame_type is called per
 * frame. tests/native holds every slot of a unit equal to the one CanFraming makes. */
static const char *const UNIT_FIELDS[6] = {"arbitration_id", "is_extended_id", "data", "dlc", "is_fd",
                                           "bitrate_switch"};

static int immutable(PyObject *value) {
    return value == NULL || value == Py_None || PyBool_Check(value) || PyLong_CheckExact(value) ||
           PyFloat_CheckExact(value) || PyUnicode_CheckExact(value) || PyBytes_CheckExact(value);
}

static int unit_template(vx_tx_t *tx) {
    PyTypeObject *type;
    PyMemberDef *member;
    PyObject *made;
    int i, found = 0;
    if (!PyType_Check(tx->frame_type)) return 0;
    type = (PyTypeObject *)tx->frame_type;
    if (!(type->tp_flags & Py_TPFLAGS_HEAPTYPE) || type->tp_base != &PyBaseObject_Type || type->tp_dictoffset != 0 ||
        type->tp_new != PyBaseObject_Type.tp_new || type->tp_members == NULL)
        return 0;
    if ((made = PyObject_CallNoArgs(tx->frame_type)) == NULL) return -1;
    for (member = type->tp_members; member->name != NULL && Py_TYPE(made) == type; member++) {
        PyObject *value = *(PyObject **)((char *)made + member->offset);
        if (member->type != T_OBJECT_EX) continue;
        for (i = 0; i < 6; i++) {
            if (strcmp(member->name, UNIT_FIELDS[i]) == 0) {
                tx->unit_slots[i] = member->offset;
                found |= 1 << i;
            }
        }
        if (strcmp(member->name, "data") != 0 && !immutable(value)) found = -1;
    }
    if (found == 0x3F && Py_TYPE(made) == type)
        tx->unit_template = made;
    else
        Py_DECREF(made);
    return 0;
}

static PyObject *copied_unit(const vx_tx_t *tx, const vstig_can_frame_t *frame) {
    PyObject *template = tx->unit_template, *unit = NULL, *fields[6];
    PyTypeObject *type = Py_TYPE(template);
    PyMemberDef *member;
    int i;
    fields[0] = PyLong_FromUnsignedLong(frame->id);
    fields[1] = Py_NewRef(frame->extended ? Py_True : Py_False);
    fields[2] = PyByteArray_FromStringAndSize((const char *)frame->data, (Py_ssize_t)frame->len);
    fields[3] = PyLong_FromLong((long)frame->len);
    fields[4] = Py_NewRef(frame->fd ? Py_True : Py_False);
    fields[5] = Py_NewRef(frame->brs ? Py_True : Py_False);
    if (fields[0] != NULL && fields[2] != NULL && fields[3] != NULL) unit = type->tp_alloc(type, 0);
    if (unit != NULL) {
        for (member = type->tp_members; member->name != NULL; member++) {
            if (member->type == T_OBJECT_EX)
                *(PyObject **)((char *)unit + member->offset) =
                    Py_XNewRef(*(PyObject **)((char *)template + member->offset));
        }
        for (i = 0; i < 6; i++) {
            Py_XSETREF(*(PyObject **)((char *)unit + tx->unit_slots[i]), fields[i]);
            fields[i] = NULL;
        }
    }
    for (i = 0; i < 6; i++) Py_XDECREF(fields[i]);
    return unit;
}

PyObject *vx_frame_unit(const vx_tx_t *tx, const vstig_can_frame_t *frame) {
    /* can.Message(arbitration_id=, is_extended_id=, data=, is_fd=, bitrate_switch=), as CanFraming builds it */
    PyObject *args, *kwargs, *unit = NULL;
    if (tx->unit_template != NULL) return copied_unit(tx, frame);
    if ((args = PyTuple_New(0)) == NULL) return NULL;
    kwargs = Py_BuildValue("{s:k,s:O,s:y#,s:O,s:O}", "arbitration_id", (unsigned long)frame->id, "is_extended_id",
                           frame->extended ? Py_True : Py_False, "data", (const char *)frame->data,
                           (Py_ssize_t)frame->len, "is_fd", frame->fd ? Py_True : Py_False, "bitrate_switch",
                           frame->brs ? Py_True : Py_False);
    if (kwargs != NULL) unit = PyObject_Call(tx->frame_type, args, kwargs);
    Py_DECREF(args);
    Py_XDECREF(kwargs);
    return unit;
}

static PyObject *Encoder_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"framing", "kilobot_type", "extended", "base", "stigmergy", "sender", "fd", "brs",
                             "frame_type", "escaped", "dest", "sysid", "compid", "target", "key", "link_id", NULL};
    PyObject *name, *base = Py_None, *frame_type = Py_None, *key = Py_None;
    int sysid = 1, compid = VSTIG_MAVLINK_COMP_ID, target = 0, link_id = 0;
    int kilobot_type = VSTIG_KILOBOT_TYPE, extended = 0, stigmergy = 0, sender = 0, fd = 0, brs = 1, escaped = 0, kind;
    unsigned long long dest = 0xFFFFull;
    uint8_t dest_bytes[8];
    int i;
    vx_encoder_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O|$ipOiippOpKiiiOi", kwlist, &name, &kilobot_type, &extended,
                                     &base, &stigmergy, &sender, &fd, &brs, &frame_type, &escaped, &dest, &sysid,
                                     &compid, &target, &key, &link_id))
        return NULL;
    if ((kind = framing_kind(name)) < 0) return NULL;
    if (kind == VX_CAN && !PyCallable_Check(frame_type)) {
        PyErr_SetString(PyExc_TypeError, "a CAN encoder needs frame_type (can.Message) for the frames it hands out");
        return NULL;
    }
    if (kilobot_type < 0 || kilobot_type >= 0x80) {
        PyErr_Format(PyExc_ValueError, "Kilobot message type must be a user type in 0..127, got %d", kilobot_type);
        return NULL;
    }
    self = (vx_encoder_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->tx.kind = (uint8_t)kind;
    self->tx.records_per_frame = (uint8_t)((VSTIG_XBEE_DEFAULT_MAX_PAYLOAD - 1u) / VSTIG_RECORD_SIZE);
    self->tx.kilobot_type = (uint8_t)kilobot_type;
    self->tx.frame_type = Py_NewRef(frame_type);
    if (kind == VX_CAN && unit_template(&self->tx) < 0) {
        Py_DECREF(self);
        return NULL;
    }
    for (i = 0; i < 8; i++) dest_bytes[i] = (uint8_t)(dest >> (56 - 8 * i));
    vstig_xbee_tx_init(&self->tx.xbee, (uint8_t)escaped, dest_bytes);
    if ((kind == VX_CAN && can_scheme(&self->tx.can, extended, base, stigmergy, sender, fd, brs) < 0) ||
        (kind == VX_MAVLINK && vx_mav_tx_init(&self->tx.mav, sysid, compid, target, key, link_id) < 0)) {
        Py_DECREF(self);
        return NULL;
    }
    return (PyObject *)self;
}

static int Encoder_traverse(vx_encoder_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->tx.frame_type);
    Py_VISIT(self->tx.unit_template);
    Py_VISIT(self->tx.tag_engine);
    Py_VISIT(self->tx.tag_counters);
    return 0;
}

static int Encoder_clear(vx_encoder_t *self) {
    Py_CLEAR(self->tx.frame_type);
    Py_CLEAR(self->tx.unit_template);
    Py_CLEAR(self->tx.tag_engine);
    Py_CLEAR(self->tx.tag_counters);
    return 0;
}

static void Encoder_dealloc(vx_encoder_t *self) {
    PyObject_GC_UnTrack(self);
    Encoder_clear(self);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* Messages from a Python sequence into a C array (PyMem); NULL with an exception. */
vstig_msg_t *vx_msgs_of(PyObject *messages, size_t *n) {
    PyObject *seq = PySequence_Fast(messages, "messages must be a sequence of Messages");
    vstig_msg_t *msgs;
    Py_ssize_t i;
    if (seq == NULL) return NULL;
    *n = (size_t)PySequence_Fast_GET_SIZE(seq);
    msgs = PyMem_Malloc((*n ? *n : 1u) * sizeof *msgs);
    if (msgs == NULL) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return NULL;
    }
    for (i = 0; i < (Py_ssize_t)*n; i++) {
        if (vx_msg_of(PySequence_Fast_GET_ITEM(seq, i), &msgs[i]) < 0) {
            PyMem_Free(msgs);
            Py_DECREF(seq);
            return NULL;
        }
    }
    Py_DECREF(seq);
    return msgs;
}

/* MAVLink: the HEARTBEAT that announces the component, on the same sequence and timestamps as the TUNNELs. */
static PyObject *Encoder_heartbeat(vx_encoder_t *self, PyObject *unused) {
    uint8_t out[VSTIG_MAVLINK_FRAME_MAX];
    (void)unused;
    if (self->tx.kind != VX_MAVLINK) {
        PyErr_SetString(PyExc_TypeError, "only a mavlink Encoder sends HEARTBEATs");
        return NULL;
    }
    vx_mav_tx_clock(&self->tx.mav);
    return PyBytes_FromStringAndSize((const char *)out, vstig_mavlink_heartbeat(&self->tx.mav.tx, out));
}

/* A record's 20 bytes (SPEC.md 10.3): its message, epoch and tag. */
static void record_bytes(const vx_record_t *record, uint8_t out[VSTIG_RECORD_SIZE]) {
    vstig_msg_encode(&record->msg, out);
    out[8] = (uint8_t)(record->epoch >> 24);
    out[9] = (uint8_t)(record->epoch >> 16);
    out[10] = (uint8_t)(record->epoch >> 8);
    out[11] = (uint8_t)record->epoch;
    memcpy(out + 12, record->tag, VSTIG_TAG_SIZE);
}

/* Link._tagged_units in wire form: each message with its entry's record first (a cobs8 frame, one CAN FD frame
 * under its message's op: CanFraming.encode_tagged, or XBee Transmit Requests of tagged batches, records_per_frame
 * in each: XBeeFraming.encode_tagged), then those without a proof untagged, packed as usual; on a link that requires
 * tags these are held back (counted held_unverified). */
static Py_ssize_t tagged_wire(vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out,
                              vstig_can_frame_t *frames) {
    const vstig_tagged_t *tagged = &((vx_engine_t *)tx->tag_engine)->tags->tagged;
    vstig_msg_t stack[64], *plain = n <= 64 ? stack : PyMem_Malloc(n * sizeof *plain);
    vx_record_t record;
    uint8_t payload[VSTIG_RECORD_SIZE], batch[1u + VX_XBEE_MAX_RECORDS * VSTIG_RECORD_SIZE];
    size_t i, count = 0, kept = 0, held = 0, batched = 0;
    if (plain == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    for (i = 0; i < n; i++) {
        if (!vstig_tagged_record(tagged, &msgs[i], &record.epoch, record.tag)) {
            if (tx->tag_require) held++;
            else plain[kept++] = msgs[i];
            continue;
        }
        record.msg = msgs[i];
        record_bytes(&record, payload);
        if (tx->kind == VX_CAN) {
            (void)vstig_can_encode(&tx->can, &record.msg, 1, &frames[count]);
            memcpy(frames[count].data, payload, VSTIG_RECORD_SIZE);
            frames[count++].len = VSTIG_RECORD_SIZE;
        } else if (tx->kind == VX_XBEE) { /* the batch's marker, then its records; sent when full */
            batch[0] = VX_BATCH_MARKER;
            memcpy(batch + 1 + batched++ * VSTIG_RECORD_SIZE, payload, VSTIG_RECORD_SIZE);
            if (batched == tx->records_per_frame) {
                count += vstig_xbee_transmit(&tx->xbee, batch, (uint16_t)(1u + batched * VSTIG_RECORD_SIZE),
                                             out + count);
                batched = 0;
            }
        } else {
            count += vstig_frame_encode(payload, VSTIG_RECORD_SIZE, out + count);
        }
    }
    if (batched)
        count += vstig_xbee_transmit(&tx->xbee, batch, (uint16_t)(1u + batched * VSTIG_RECORD_SIZE), out + count);
    count += tx->kind == VX_CAN ? vx_tx_frames(tx, plain, kept, frames + count)
                                : vx_tx_bytes(tx, plain, kept, out + count);
    if (plain != stack) PyMem_Free(plain);
    if (held && vx_count(tx->tag_counters, vx_name("held_unverified"), (Py_ssize_t)held) < 0) return -1;
    return (Py_ssize_t)count;
}

Py_ssize_t vx_tx_wire(vx_tx_t *tx, const vstig_msg_t *msgs, size_t n, uint8_t *out, vstig_can_frame_t *frames) {
    if (tx->tag_engine != NULL) return tagged_wire(tx, msgs, n, out, frames);
    return (Py_ssize_t)(tx->kind == VX_CAN ? vx_tx_frames(tx, msgs, n, frames) : vx_tx_bytes(tx, msgs, n, out));
}

/* send_tags(engine, require, counters): from now on each message goes with its entry's record from `engine` (an
 * Engine given the swarm key), as Link.units_of sends them where Link.record_of is set; cobs8 and CAN FD only */
static PyObject *Encoder_send_tags(vx_encoder_t *self, PyObject *args) {
    PyObject *engine, *counters;
    int require;
    if (!PyArg_ParseTuple(args, "O!pO!:send_tags", &vx_EngineType, &engine, &require, &PyDict_Type, &counters))
        return NULL;
    if (((vx_engine_t *)engine)->tags == NULL ||
        !(self->tx.kind == VX_COBS8 || self->tx.kind == VX_XBEE || (self->tx.kind == VX_CAN && self->tx.can.fd))) {
        PyErr_SetString(PyExc_ValueError, "send_tags needs an Engine given swarm_key, and a cobs8, CAN FD or XBee "
                                          "encoder");
        return NULL;
    }
    Py_INCREF(engine);
    Py_XSETREF(self->tx.tag_engine, engine);
    Py_INCREF(counters);
    Py_XSETREF(self->tx.tag_counters, counters);
    self->tx.tag_require = (uint8_t)require;
    Py_RETURN_NONE;
}

/* encode_batch(messages) -> units: one bytes object for a byte stream (as Link.units_of joins them), or the
 * CAN frames as can.Message */
static PyObject *Encoder_encode_batch(vx_encoder_t *self, PyObject *messages) {
    size_t n;
    Py_ssize_t count = -1, i;
    vstig_msg_t *msgs = vx_msgs_of(messages, &n);
    uint8_t *bytes = NULL;
    vstig_can_frame_t *frames = NULL;
    PyObject *units = NULL;
    if (msgs == NULL) return NULL;
    if (self->tx.kind == VX_CAN) frames = PyMem_Malloc((n ? n : 1u) * sizeof *frames);
    else bytes = PyMem_Malloc(vx_tx_room(&self->tx, n) + 1u);
    if (frames == NULL && bytes == NULL) {
        PyErr_NoMemory();
    } else if ((count = vx_tx_wire(&self->tx, msgs, n, bytes, frames)) >= 0 && bytes != NULL) {
        units = count == 0 ? PyList_New(0) : Py_BuildValue("[y#]", (const char *)bytes, count);
    } else if (count >= 0) {
        units = PyList_New(count);
        for (i = 0; units != NULL && i < count; i++) {
            PyObject *unit = vx_frame_unit(&self->tx, &frames[i]);
            if (unit == NULL) Py_CLEAR(units);
            else PyList_SET_ITEM(units, i, unit);
        }
    }
    PyMem_Free(msgs);
    PyMem_Free(bytes);
    PyMem_Free(frames);
    return units;
}

static PyMethodDef Encoder_methods[] = {
    {"encode_batch", (PyCFunction)Encoder_encode_batch, METH_O, "The units that carry these messages."},
    {"send_tags", (PyCFunction)Encoder_send_tags, METH_VARARGS, "Each message with its entry's record from now on."},
    {"heartbeat", (PyCFunction)Encoder_heartbeat, METH_NOARGS, "MAVLink: the HEARTBEAT frame that comes next."},
    {NULL, NULL, 0, NULL},
};

/* XBee: what the link's XBeeFraming reads and sets as its own (frame ids, reports, NP), so both send alike. */
static PyMemberDef Encoder_members[] = {
    {"frame_id", T_UBYTE, offsetof(vx_encoder_t, tx.xbee.frame_id), 0, "XBee: the last frame id given (1..255)."},
    {"report", T_UBYTE, offsetof(vx_encoder_t, tx.xbee.report), 0,
     "XBee: the next frame asks for a Transmit Status (1)."},
    {"seq", T_UBYTE, offsetof(vx_encoder_t, tx.mav.tx.seq), 0, "MAVLink: the next frame's sequence number."},
    {"written", T_LONGLONG, offsetof(vx_encoder_t, tx.mav.written), 0,
     "MAVLink: the newest signing timestamp the link wrote (the framing's in_order and the outlet's sends)."},
    {NULL, 0, 0, 0, NULL},
};

static PyObject *Encoder_get_per_frame(vx_encoder_t *self, void *closure) {
    (void)closure;
    return PyLong_FromLong(self->tx.xbee.per_frame);
}

static int Encoder_set_per_frame(vx_encoder_t *self, PyObject *value, void *closure) {
    long per_frame = value == NULL ? -1 : PyLong_AsLong(value);
    (void)closure;
    if (per_frame == -1 && PyErr_Occurred()) return -1;
    if (per_frame < 1 || per_frame > (long)VSTIG_XBEE_MAX_MESSAGES) {
        PyErr_Format(PyExc_ValueError, "an XBee frame carries 1..%d messages, got %R", (int)VSTIG_XBEE_MAX_MESSAGES,
                     value == NULL ? Py_None : value);
        return -1;
    }
    self->tx.xbee.per_frame = (uint8_t)per_frame;
    return 0;
}

static PyObject *Encoder_get_records_per_frame(vx_encoder_t *self, void *closure) {
    (void)closure;
    return PyLong_FromLong(self->tx.records_per_frame);
}

static int Encoder_set_records_per_frame(vx_encoder_t *self, PyObject *value, void *closure) {
    long records = value == NULL ? -1 : PyLong_AsLong(value);
    (void)closure;
    if (records == -1 && PyErr_Occurred()) return -1;
    if (records < 1 || records > (long)VX_XBEE_MAX_RECORDS) {
        PyErr_Format(PyExc_ValueError, "an XBee tagged batch carries 1..%d records, got %R",
                     (int)VX_XBEE_MAX_RECORDS, value == NULL ? Py_None : value);
        return -1;
    }
    self->tx.records_per_frame = (uint8_t)records;
    return 0;
}

/* MAVLink: the last signing timestamp sent (10 us units since 2015); the next is max(this + 1, the clock). */
static PyObject *Encoder_get_timestamp(vx_encoder_t *self, void *closure) {
    unsigned long long stamp = 0;
    int i;
    (void)closure;
    for (i = 6; i-- > 0;) stamp = stamp << 8 | self->tx.mav.tx.timestamp[i];
    return PyLong_FromUnsignedLongLong(stamp);
}

static int Encoder_set_timestamp(vx_encoder_t *self, PyObject *value, void *closure) {
    unsigned long long stamp = value == NULL ? (unsigned long long)-1 : PyLong_AsUnsignedLongLong(value);
    int i;
    (void)closure;
    if (PyErr_Occurred()) return -1;
    if (stamp >> 48) {
        PyErr_Format(PyExc_ValueError, "a MAVLink signing timestamp is 48 bits, got %R", value == NULL ? Py_None : value);
        return -1;
    }
    for (i = 0; i < 6; i++) self->tx.mav.tx.timestamp[i] = (uint8_t)(stamp >> (8 * i));
    return 0;
}

static PyGetSetDef Encoder_getset[] = {
    {"timestamp", (getter)Encoder_get_timestamp, (setter)Encoder_set_timestamp,
     "MAVLink: the last signing timestamp sent.", NULL},
    {"per_frame", (getter)Encoder_get_per_frame, (setter)Encoder_set_per_frame,
     "XBee: messages a frame carries (the module's NP / 8).", NULL},
    {"records_per_frame", (getter)Encoder_get_records_per_frame, (setter)Encoder_set_records_per_frame,
     "XBee: records a tagged batch carries ((the module's NP - 1) / 20).", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject vx_EncoderType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Encoder",
    .tp_doc = "Encoder(framing, *, kilobot_type=0x56, extended=False, base=None, stigmergy=0, sender=0, fd=False, "
              "brs=True, frame_type=None, escaped=False, dest=0xFFFF, sysid=1, compid=191, target=0, key=None, "
              "link_id=0): a link's sending framing in C.",
    .tp_basicsize = sizeof(vx_encoder_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_new = Encoder_new,
    .tp_dealloc = (destructor)Encoder_dealloc,
    .tp_traverse = (traverseproc)Encoder_traverse,
    .tp_clear = (inquiry)Encoder_clear,
    .tp_methods = Encoder_methods,
    .tp_members = Encoder_members,
    .tp_getset = Encoder_getset,
};
