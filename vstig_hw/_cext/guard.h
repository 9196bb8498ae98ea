/* The JumpGuard type's object, for the data path (path.c). */
#ifndef VSTIG_EXT_GUARD_H
#define VSTIG_EXT_GUARD_H

#include "ext.h"

#define VX_GUARD_UNITS 1024u /* the guard's time units a second: k/1024 s is exact in a float */
#define VX_GUARD_MAX_LEARN 2097151.0 /* seconds (2^31 units): libvstig compares times less than that apart */

typedef struct {
    PyObject_HEAD
    vstig_guard_t guard;
    PyObject *max_jump, *learn; /* as given: Guard's attributes */
    PyObject *warnings;         /* always empty (no flap policy): Guard's list for the caller to print */
    PyObject *policies;         /* always empty: Guard's per-link policies */
    PyObject *jump;             /* "drop_jump" (borrowed from the module's names) */
} vx_guard_t;

/* Seconds as the guard's time (units modulo 2^32); whether msg passes at that time. */
uint32_t vx_guard_units(double now);
uint8_t vx_guard_passes(vx_guard_t *self, const vstig_msg_t *msg, uint32_t now);

#endif /* VSTIG_EXT_GUARD_H */
