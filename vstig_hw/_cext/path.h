/* The Path type (path.c): a Node's delivery of what its links read, in C. */
#ifndef VSTIG_EXT_PATH_H
#define VSTIG_EXT_PATH_H

#include "parts.h"
#include "pending.h"

#define VX_READ_PYTHON 0u    /* units come from the link's own read (transport.read), as Python objects */
#define VX_READ_SERIAL 1u    /* the serial port's fd is read here */
#define VX_READ_SOCKETCAN 2u /* the SocketCAN socket is read here */
#define VX_READ_XBEE 3u      /* an XBee module's serial fd is read and cut into frames here */
#define VX_READ_UDP 4u       /* a MAVLink UDP socket is read here (recvmmsg), a udpin link's sources noted */
#define VX_READ_PYTHONCAN 5u /* a python-can bus that is not SocketCAN: its own recv, called here */

typedef struct vx_udp vx_udp_t; /* path.c: a UDP read's datagrams, their sources, the frames cut from them */

typedef struct {
    uint8_t reads;           /* VX_READ_* */
    vx_receiver_t *receiver; /* its framing in C, or NULL: this link's units take the Python path */
    PyObject *link, *name, *counters, *transport, *tcounters;
    vx_pending_t *pending, *tpending; /* the hot counts of `counters` and of `tcounters` (NULL: into the dict) */
    PyObject *handle;        /* a device read here: transport.compiled_handle() (CompiledHandle), else None */
    vx_slot_t handle_fd;     /* its `fd` slot */
    vx_slot_t handle_peers;  /* its `peers` slot (MAVLink over UDP) */
    PyObject *device;        /* SocketCAN: the bus `fd` belongs to */
    int fd;
    double polled;           /* SocketCAN: when the bus's own drop counts were last polled; python-can: when the
                              * transport's read last had a turn (its look at the bus's state) */
    uint8_t *buf;            /* serial: a read's bytes (each link's reader thread reads into its own) */
    vstig_xbee_rx_t *stream; /* XBee: the transport's cutting of its module's bytes into frames */
    uint8_t *units;          /* XBee: the frames one read completed, as on the wire, back to back */
    uint16_t *unit_len;      /* and their sizes */
    double last_byte, quiet; /* XBee: when a byte last came; a frame still arriving after `quiet` s never will */
    uint8_t escaped;         /* XBee: API mode 2 */
    vx_udp_t *udp;           /* MAVLink over UDP: what one read takes */
    double next_beat;        /* MAVLink over UDP: when the transport's `beat` is next due (monotonic seconds) */
} vx_link_t;

typedef struct {
    PyObject_HEAD
    PyObject *state;    /* the Node's DeliveryState (vstig_hw/gateway/delivery_state.py): what it shares with us */
    PyObject *lock;     /* its lock */
    PyObject *acquire, *release; /* the lock's methods, bound once (one Python call less per batch each) */
    vx_slot_t reader_thread, wake_on_arrival, sleep_until, retry_at; /* the state's slots we touch per batch */
    PyObject *deliver;  /* its Python delivery (Delivery.deliver): the slow path */
    PyObject *part;     /* Seat, Relay, or None */
    PyObject *guard;    /* JumpGuard, a Python Guard, or None */
    PyObject *outlets;  /* list of Outlet (none: a listener) */
    Py_ssize_t nlinks;
    vx_link_t *links;
    PyObject *listeners; /* the Node's listeners that take its Python delivery, one sequence per kind (a list) */
    PyObject *told;      /* [`messages` listeners, `refused` listeners] (tuples): the delivery here tells them */
    PyObject *heard;     /* the type a refused message is told as (vstig_hw.links.link.Heard) */
    PyObject *delivered; /* the Node's listeners told of every batch handled, with its read time (a list) */
    char fast;          /* no listener wants each unit or every `Heard`: the whole batch may be C's */
    char stopping;      /* the readers stop: serve() returns */
    vstig_msg_t *msgs;  /* the messages of one unit (used under the Node's lock) */
    size_t cap;
} vx_path_t;

extern PyTypeObject vx_PathType;

#endif /* VSTIG_EXT_PATH_H */
