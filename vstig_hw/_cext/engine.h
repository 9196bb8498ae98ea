/* The Engine type's object, for the data path (path.c) that drives it without Python calls. */
#ifndef VSTIG_EXT_ENGINE_H
#define VSTIG_EXT_ENGINE_H

#include "ext.h"
#include "tags.h"

struct vx_engine {
    PyObject_HEAD
    vstig_engine_t engine;
    uint16_t *order;         /* keys in the order first stored (entries() iterates so, as a dict does) */
    PyObject *onconflict;    /* the rule as given (a ready-made one runs as its C twin) */
    PyObject *onconflictlost; /* or None */
    PyObject *error_type, *error_value, *error_tb; /* what a callback raised, raised after libvstig returns */
    uint8_t lost_raised;     /* onconflictlost raised: the outcome was not counted, as in Python */
    vx_tags_t *tags;         /* given the swarm key: SignedEngine's twin (tags.c); else NULL */
};

/* Receive one message as Engine.receive does; then vx_engine_raise (0, or -1 with the exception a
 * Python callback raised, as the Python engine raises it). */
vstig_outcome_t vx_engine_receive(vx_engine_t *self, const vstig_msg_t *msg);
int vx_engine_raise(vx_engine_t *self, vstig_outcome_t outcome);
/* Whether a conflict may call Python (a rule of the user's, or onconflictlost). */
int vx_engine_calls_python(const vx_engine_t *self);

/* A list of Messages; OutQueue.drain's budget argument. */
PyObject *vx_drain_list(const vstig_msg_t *out, size_t n);
int vx_budget(PyObject *args, PyObject *kwds, size_t pending, size_t *budget);

#endif /* VSTIG_EXT_ENGINE_H */
