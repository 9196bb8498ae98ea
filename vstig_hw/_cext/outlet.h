/* The Outlet type's object (outlet.c), for the parts (parts.c) and the delivery (path.c). */
#ifndef VSTIG_EXT_OUTLET_H
#define VSTIG_EXT_OUTLET_H

#include "ext.h"
#include "framing.h"
#include "pending.h"
#include "window.h"

#define VX_LOCAL (-1L) /* the source of this gateway's own messages (fairshare.LOCAL) */

/* How an outlet reaches its device when the writer holds nothing: */
#define VX_PORT_PYTHON 0u    /* through the link's writer (units from the encoder, or Link.units_of) */
#define VX_PORT_SERIAL 1u    /* straight to a serial transport's non-blocking fd */
#define VX_PORT_SOCKETCAN 2u /* straight to a SocketCAN bus's raw socket */
#define VX_PORT_PYTHONCAN 4u /* a python-can bus's own send(unit, 0.0): interfaces whose send cannot block */
#define VX_PORT_UDP 3u       /* straight to a MAVLink UDP socket: its router (udpout) or its peers (udpin) */

typedef struct {
    uint8_t kind;
    PyObject *transport; /* the link's transport */
    PyObject *counters;  /* its counters */
    vx_pending_t *pending; /* their hot counts (NULL: into the dict) */
    PyObject *handle;    /* a device written here: transport.compiled_handle() (CompiledHandle), else None */
    vx_slot_t fd_slot, fresh_slot, peers_slot, writing_slot; /* its `fd`, `fresh`, `peers` and `writing` slots */
    PyObject *device;    /* SocketCAN: the bus `fd` was read from */
    int fd;
} vx_port_t;

typedef struct {
    PyObject_HEAD
    PyObject *link, *counters, *writer, *queue; /* the Link, its counters, its LinkWriter, the fair share's lines */
    vx_pending_t *pending;      /* the hot counts of `counters` (NULL: into the dict) */
    vx_window_t *window;
    PyObject *encoder;          /* an Encoder, or NULL: Link.units_of */
    PyObject *not_queued;       /* the counter of a message the lines did not take */
    int keep_all;
    long hold;                  /* messages the writer may hold for a slow device (LinkWriter.hold) */
    int backlog;                /* the lines have messages: what `queue.active` said after the last call on it */
    vstig_msg_t *held;          /* one push's messages, pushed while nothing waited: sent as they came */
    size_t held_len, held_cap;
    long held_link;
    PyObject *held_sub;
    vx_port_t port;
    unsigned long long handed;  /* messages handed to the writer or the device so far (what Node.drain waits for) */
} vx_outlet_t;

extern PyTypeObject vx_OutletType;

/* Outlet.push and Outlet.flush for messages in C; 0, or -1 with an exception. flush: *retry and 1 when the
 * window holds messages back, 0 when nothing waits for the clock. */
int vx_outlet_push(vx_outlet_t *o, const vstig_msg_t *msgs, size_t n, long link, PyObject *sub);
int vx_outlet_flush(vx_outlet_t *o, double now, double *retry);

/* The fd of the SocketCAN bus a CAN transport has open now (`handle`: its CompiledHandle), cached per bus in
 * *device_seen and *fd_seen (a new bus is told it is read here if `read_here`); -1 when it has none or is in an
 * outage (the transport's own calls tell when a reopened bus works), -2 with an exception. */
int vx_socketcan_fd(PyObject *handle, PyObject **device_seen, int *fd_seen, int read_here);

/* The counter `name` on these counters, +n (shared by the parts). */
#define VX_COUNT(counters, name, n) vx_count((counters), vx_name(name), (n))

#endif /* VSTIG_EXT_OUTLET_H */
