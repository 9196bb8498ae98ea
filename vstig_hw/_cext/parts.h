/* The Seat and Relay types' objects (parts.c), for the delivery (path.c). */
#ifndef VSTIG_EXT_PARTS_H
#define VSTIG_EXT_PARTS_H

#include "engine.h"
#include "guard.h"
#include "outlet.h"

typedef struct {
    PyObject_HEAD
    PyObject *outlets;    /* list of Outlet (outlets[i] belongs to links[i]) */
    PyObject *guard;      /* or None */
    PyObject *names;      /* the links' names */
    int guard_is_python;  /* a Guard (read_only asked of it), not a JumpGuard (which has no read-only links) */
} vx_relay_t;

typedef struct {
    PyObject_HEAD
    vx_engine_t *engine;
    PyObject *links, *outlets, *guard, *on_change; /* on_change: the Node's listeners (a sequence) */
    PyObject *intake_obj;                           /* None, or the intake per source and period */
    Py_ssize_t nlinks;
    /* the intake: a token bucket per source (Seat._allowed), refilled by the batches' read times */
    double rate, burst, latest;
    double *left, *since; /* per link as one source: messages it may still give, as of when */
    char *known;          /* per link: it gave since it was last forgotten */
    PyObject *allowed;    /* (link, sub) -> (left, since), for a link's peers (a dict) */
    PyObject *one_domain; /* per link: True when every robot there hears every frame (Link.one_domain) */
    long source_link;     /* the source (link, sub) that caused the messages in the engine's outbox */
    PyObject *source_sub;
    /* key -> (the PUT just stored, index of the one-domain link it came from), until the next queue_out */
    int16_t *note_link;
    vstig_msg_t *note_msg;
    uint16_t *noted;
    size_t nnoted;
} vx_seat_t;

extern PyTypeObject vx_SeatType;
extern PyTypeObject vx_RelayType;

/* Seat.admit over C messages: how many of the first n the engine takes (the rest are counted drop_intake). */
int vx_seat_admit(vx_seat_t *s, Py_ssize_t index, PyObject *sub, size_t n, double t, size_t *admitted);
/* Seat.take and Relay.take over C messages; 0 or -1. A Seat tells its change listeners (`on_change`) of every
 * entry that changed, with `sender` (what the unit's link says sent it, or None). */
int vx_seat_take(vx_seat_t *s, Py_ssize_t index, const vstig_msg_t *msgs, size_t n, PyObject *sender, PyObject *sub);
/* Whether the Seat's change listeners want to hear (1), not (0), or -1 on error. */
int vx_seat_listening(vx_seat_t *s);
int vx_seat_queue_out(vx_seat_t *s);
int vx_relay_take(vx_relay_t *r, Py_ssize_t index, const vstig_msg_t *msgs, size_t n, PyObject *sub);

#endif /* VSTIG_EXT_PARTS_H */
