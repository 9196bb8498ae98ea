/* The RosterTally type (roster.c): the roster's per-message work, for the Path (path.c) to feed in C. */
#ifndef VSTIG_EXT_ROSTER_H
#define VSTIG_EXT_ROSTER_H

#include "ext.h"

#define VX_ROSTER_LINKS 64       /* links one gateway takes (links/assemble.py MAX_LINKS): a bit each */
#define VX_ROSTER_BEHIND_KEYS 64 /* keys one robot may lag on that the roster remembers (MAX_BEHIND_KEYS) */

typedef struct vx_tally vx_tally_t;

extern PyTypeObject vx_RosterTallyType;

/* What one unit carried past the guard (Roster.take): `named`: the medium named `sender`; else each PUT is its
 * writer's. 0, or -1 with an exception (a link past VX_ROSTER_LINKS). */
int vx_tally_take(vx_tally_t *tally, PyObject *link, double t, int named, unsigned long long sender,
                  const vstig_msg_t *msgs, size_t n);
/* One message the guard refused (Roster.refuse). */
void vx_tally_refuse(vx_tally_t *tally, double t, int named, unsigned long long sender, const vstig_msg_t *msg);
/* Whether `listener` is a tally's `take` (a `messages` listener the Path feeds in C); the tally, or NULL. */
vx_tally_t *vx_tally_of_take(PyObject *listener);

#endif /* VSTIG_EXT_ROSTER_H */
