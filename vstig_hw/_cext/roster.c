/*
 * RosterTally: the per-message half of vstig_hw.gateway.roster.Roster in C (`take` and `refuse`: who was heard,
 * when, on which link, what it wrote and asked, the keys it showed older than the newest), so that a compiled
 * Path keeps the roster with no Python per message; and the sweep's per-tick half (`due`: the rates, and whether a
 * robot's state would change), so that a tick with nothing to tell (`tick`, a Node's tick listener) runs no Python.
 * The Roster folds the tally in (`fold`) on a sweep with something to tell and on every read; states (it `mark`s
 * each change here), their changes and every view stay the Roster's. The same rules and float operations in the same
 * order as Roster.take and Roster._judge: the same tallies, rates and states.
 *
 * Reference: vstig_hw/gateway/roster.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 */
#include "roster.h"

#include <math.h>
#include <string.h>
#include <time.h>

#define GAP_WEIGHT 0.25 /* Roster's _GAP_WEIGHT: how fast a robot's usual gap follows its latest one */
#define QUIET_PERIODS 3 /* Roster's QUIET_PERIODS: quiet once silent for this many of its own usual gaps too */
#define RATE_WINDOW 1.0 /* Roster's RATE_WINDOW: seconds, the time constant of the recent message rate */
#define FREE_SLOT (-1)

enum { ALIVE, QUIET, GONE }; /* a robot's state, as the Roster's STATE_ORDER numbers them */

typedef struct {
    unsigned long long who;
    double first, last, gap;
    double revived;         /* when first heard since the last fold (NaN: not heard since) */
    uint64_t revived_links; /* its links then (what Roster.take tells a return with) */
    double rate;            /* messages per second, recent (Roster._judge's) */
    long long messages, writes, gets, refused;
    long long counted;      /* `messages` at the last advance of the rates */
    uint64_t links;         /* a bit per link name (the tally's `names`) */
    uint8_t named, gone, used, fresh;
    uint8_t state;          /* the Roster's state of it (`mark`): ALIVE until it says otherwise */
    uint8_t nbehind;
    uint16_t behind_key[VX_ROSTER_BEHIND_KEYS];
    double behind_since[VX_ROSTER_BEHIND_KEYS];
} robot_t;

struct vx_tally {
    PyObject_HEAD
    Py_ssize_t max_robots;
    robot_t *robots;         /* max_robots places */
    int32_t *table;          /* who -> place, open addressing (linear probing), `mask + 1` slots */
    size_t mask;
    int32_t *spare;          /* places free, a stack */
    int32_t *live;           /* the places in use, in the order added (the Roster's dict order): what a tick walks */
    Py_ssize_t nspare, count, ngone;
    double quiet_after, gone_after; /* the Roster's thresholds */
    double swept;            /* when the rates were last advanced (NaN: never) */
    PyObject *on_due;        /* the Roster's sweep(now): what a tick calls when a state would change */
    uint8_t *dirty;          /* per place: listed in `touched` since the last fold */
    int32_t *touched;
    Py_ssize_t ntouched;
    unsigned long long *evicted; /* robots forgotten since the last fold (at most max_robots: only gone ones are) */
    Py_ssize_t nevicted;
    long long untracked, behind_untracked, unattributed;
    int counted;             /* one of those three moved since the last fold */
    PyObject *names;         /* list of link names, a bit each */
    uint16_t newest[VSTIG_KEYS]; /* key -> newest timestamp heard (0: none) */
};

static size_t slot_of(const vx_tally_t *t, unsigned long long who) {
    unsigned long long h = who * 0x9E3779B97F4A7C15ull;
    return (size_t)(h >> 32) & t->mask;
}

static robot_t *find(const vx_tally_t *t, unsigned long long who) {
    size_t i = slot_of(t, who);
    while (t->table[i] != FREE_SLOT) {
        robot_t *r = &t->robots[t->table[i]];
        if (r->who == who) return r;
        i = (i + 1) & t->mask;
    }
    return NULL;
}

static void touch(vx_tally_t *t, const robot_t *r) {
    int32_t place = (int32_t)(r - t->robots);
    if (!t->dirty[place]) {
        t->dirty[place] = 1;
        t->touched[t->ntouched++] = place;
    }
}

static void unlink_who(vx_tally_t *t, unsigned long long who) {
    /* backward-shift deletion: every later member of the run stays findable */
    size_t i = slot_of(t, who), j, home;
    while (t->robots[t->table[i]].who != who) i = (i + 1) & t->mask;
    j = i;
    for (;;) {
        j = (j + 1) & t->mask;
        if (t->table[j] == FREE_SLOT) break;
        home = slot_of(t, t->robots[t->table[j]].who);
        if (((j - home) & t->mask) >= ((j - i) & t->mask)) {
            t->table[i] = t->table[j];
            i = j;
        }
    }
    t->table[i] = FREE_SLOT;
}

/* Roster._evict_gone: forget the gone robot heard longest ago (the first added of equals); 0 if none is gone. */
static int evict_gone(vx_tally_t *t) {
    robot_t *oldest = NULL;
    Py_ssize_t i;
    Py_ssize_t at = 0;
    if (!t->ngone) return 0;
    for (i = 0; i < t->count; i++) { /* in the order added: the first added of equals is kept */
        robot_t *r = &t->robots[t->live[i]];
        if (r->gone && (oldest == NULL || r->last < oldest->last)) {
            oldest = r;
            at = i;
        }
    }
    memmove(&t->live[at], &t->live[at + 1], (size_t)(t->count - at - 1) * sizeof *t->live);
    unlink_who(t, oldest->who);
    oldest->used = 0;
    t->spare[t->nspare++] = (int32_t)(oldest - t->robots);
    t->evicted[t->nevicted++] = oldest->who;
    t->count--;
    t->ngone--;
    return 1;
}

/* Roster._new: NULL when the roster is full of robots not gone (counted in `untracked`). */
static robot_t *add(vx_tally_t *t, unsigned long long who, int named, double when) {
    robot_t *r;
    int32_t place;
    size_t i;
    if (t->count >= t->max_robots && !evict_gone(t)) {
        t->untracked++;
        t->counted = 1;
        return NULL;
    }
    place = t->spare[--t->nspare];
    r = &t->robots[place];
    memset(r, 0, sizeof *r);
    r->who = who;
    r->named = (uint8_t)named;
    r->used = r->fresh = 1;
    r->first = r->last = when;
    r->revived = NAN;
    for (i = slot_of(t, who); t->table[i] != FREE_SLOT; i = (i + 1) & t->mask) {}
    t->table[i] = place;
    t->live[t->count++] = place;
    touch(t, r);
    return r;
}

/* The bit of link name `link`, learning it; -1 with ValueError past VX_ROSTER_LINKS. */
static int link_bit(vx_tally_t *t, PyObject *link) {
    Py_ssize_t i, n = PyList_GET_SIZE(t->names);
    for (i = 0; i < n; i++) {
        if (PyList_GET_ITEM(t->names, i) == link) return (int)i;
    }
    for (i = 0; i < n; i++) {
        int same = PyObject_RichCompareBool(PyList_GET_ITEM(t->names, i), link, Py_EQ);
        if (same) return same < 0 ? -1 : (int)i;
    }
    if (n >= VX_ROSTER_LINKS) {
        PyErr_Format(PyExc_ValueError, "a roster tracks at most %d links; %R is one more", VX_ROSTER_LINKS, link);
        return -1;
    }
    return PyList_Append(t->names, link) < 0 ? -1 : (int)n;
}

static void heard_at(robot_t *r, double when) {
    double gap = when - r->last;
    if (gap > 0) r->gap = r->gap != 0.0 ? r->gap + (gap - r->gap) * GAP_WEIGHT : gap;
    r->last = when;
}

/* Heard: on a link, alive again if it was gone (Roster._change to alive, which the fold tells). */
static void heard(vx_tally_t *t, robot_t *r, uint64_t bit, double when) {
    if (when != r->last) heard_at(r, when);
    r->links |= bit;
    if (r->gone) {
        r->gone = 0;
        t->ngone--;
    }
    if (isnan(r->revived)) {
        r->revived = when;
        r->revived_links = r->links;
    }
    touch(t, r);
}

static int behind_at(const robot_t *r, uint16_t key) {
    int i;
    for (i = 0; i < r->nbehind; i++) {
        if (r->behind_key[i] == key) return i;
    }
    return -1;
}

static void caught_up(robot_t *r, uint16_t key) {
    int i = r->nbehind ? behind_at(r, key) : -1;
    if (i < 0) return;
    r->nbehind--;
    r->behind_key[i] = r->behind_key[r->nbehind];
    r->behind_since[i] = r->behind_since[r->nbehind];
}

/* Roster._lags: `r` showed an entry for `key` older than the newest heard (bounded per robot). */
static void lags(vx_tally_t *t, robot_t *r, uint16_t key, double when) {
    if (behind_at(r, key) >= 0) return;
    if (r->nbehind < VX_ROSTER_BEHIND_KEYS) {
        r->behind_key[r->nbehind] = key;
        r->behind_since[r->nbehind++] = when;
    } else {
        t->behind_untracked++;
        t->counted = 1;
    }
}

static int is_newer(uint16_t a, uint16_t b) { /* vstig_hw.timestamps.is_newer */
    uint16_t distance = (uint16_t)(a - b);
    if (b == 0) return a != 0;
    if (a == 0) return 0;
    return (distance > 0 && distance < 0x8000u) || (distance == 0x8000u && a > b);
}

/* One message's timestamp against the newest of its key (Roster.take's loop body). */
static void shown(vx_tally_t *t, robot_t *r, const vstig_msg_t *m, double when) {
    uint16_t key = m->key, held = t->newest[key], ts = m->timestamp;
    if (ts == held) {
        caught_up(r, key);
    } else if (is_newer(ts, held)) {
        t->newest[key] = ts;
        caught_up(r, key);
    } else {
        lags(t, r, key, when);
    }
}

int vx_tally_take(vx_tally_t *t, PyObject *link, double when, int named, unsigned long long sender,
                  const vstig_msg_t *msgs, size_t n) {
    int bit = link_bit(t, link);
    size_t i, gets = 0;
    robot_t *r;
    if (bit < 0) return -1;
    if (named) {
        if ((r = find(t, sender)) == NULL && (r = add(t, sender, 1, when)) == NULL) return 0;
        heard(t, r, (uint64_t)1 << bit, when);
        r->messages += (long long)n;
        for (i = 0; i < n; i++) {
            gets += msgs[i].op == VSTIG_GET;
            shown(t, r, &msgs[i], when);
        }
        r->gets += (long long)gets;
        r->writes += (long long)(n - gets);
        return 0;
    }
    for (i = 0; i < n; i++) { /* a medium that names no sender: each PUT is its writer's, a GET nobody's */
        if (msgs[i].op == VSTIG_GET) {
            t->unattributed++;
            t->counted = 1;
            continue;
        }
        if ((r = find(t, msgs[i].robot)) == NULL && (r = add(t, msgs[i].robot, 0, when)) == NULL) continue;
        heard(t, r, (uint64_t)1 << bit, when);
        r->messages++;
        r->writes++;
        shown(t, r, &msgs[i], when);
    }
    return 0;
}

void vx_tally_refuse(vx_tally_t *t, double when, int named, unsigned long long sender, const vstig_msg_t *msg) {
    unsigned long long who = named ? sender : msg->robot;
    robot_t *r;
    if (!named && msg->op == VSTIG_GET) {
        t->unattributed++;
        t->counted = 1;
        return;
    }
    if ((r = find(t, who)) == NULL && (r = add(t, who, named, when)) == NULL) return;
    r->refused++;
    touch(t, r);
}

/* Roster._judge's state for `r` at `now`. */
static int judged(const vx_tally_t *t, const robot_t *r, double now) {
    double silent = now - r->last;
    if (silent > t->gone_after) return GONE;
    if (silent > t->quiet_after && silent > QUIET_PERIODS * r->gap) return QUIET;
    return ALIVE;
}

/* The rates as of `now` (Roster._judge's, for every robot: a fold carries the ones that moved); 1 if a sweep at
 * `now` has something to tell (a robot whose state would change, or one heard again since the Roster last saw it
 * quiet or gone), else 0. A second call at the same `now` moves no rate. */
static int advance(vx_tally_t *t, double now) {
    double dt = now - t->swept, smoothing = dt > 0 ? 1.0 - exp(-dt / RATE_WINDOW) : 0.0;
    int due = 0;
    Py_ssize_t i;
    for (i = 0; i < t->count; i++) {
        robot_t *r = &t->robots[t->live[i]];
        if (smoothing != 0.0) {
            double rate = r->rate + ((double)(r->messages - r->counted) / dt - r->rate) * smoothing;
            r->counted = r->messages;
            if (rate != r->rate) {
                r->rate = rate;
                touch(t, r);
            }
        }
        if (!due) due = (r->state != ALIVE && !isnan(r->revived)) || judged(t, r, now) != r->state;
    }
    if (!(dt <= 0)) t->swept = now;
    return due;
}

/* ---- the Python interface ---------------------------------------------------------------- */

static PyObject *Tally_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"max_robots", "quiet_after", "gone_after", "on_due", NULL};
    Py_ssize_t max_robots, i;
    size_t slots = 2;
    double quiet_after, gone_after;
    PyObject *on_due;
    vx_tally_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "nddO", kwlist, &max_robots, &quiet_after, &gone_after, &on_due))
        return NULL;
    if (max_robots < 1 || max_robots > (1 << 24))
        return PyErr_Format(PyExc_ValueError, "max_robots must be in 1..%d, got %zd", 1 << 24, max_robots);
    if (!(quiet_after > 0 && gone_after > quiet_after && isfinite(gone_after))) {
        char text[128];
        PyOS_snprintf(text, sizeof text, "quiet_after (%g s) must be positive and below gone_after (%g s), finite",
                      quiet_after, gone_after);
        PyErr_SetString(PyExc_ValueError, text);
        return NULL;
    }
    if (!PyCallable_Check(on_due)) return PyErr_Format(PyExc_TypeError, "on_due must be callable, got %R", on_due);
    while (slots < 2 * (size_t)max_robots) slots *= 2;
    self = (vx_tally_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->max_robots = max_robots;
    self->mask = slots - 1;
    self->robots = PyMem_Calloc((size_t)max_robots, sizeof *self->robots);
    self->table = PyMem_Malloc(slots * sizeof *self->table);
    self->spare = PyMem_Malloc((size_t)max_robots * sizeof *self->spare);
    self->live = PyMem_Malloc((size_t)max_robots * sizeof *self->live);
    self->quiet_after = quiet_after;
    self->gone_after = gone_after;
    self->swept = NAN;
    self->on_due = Py_NewRef(on_due);
    self->dirty = PyMem_Calloc((size_t)max_robots, 1);
    self->touched = PyMem_Malloc((size_t)max_robots * sizeof *self->touched);
    self->evicted = PyMem_Malloc((size_t)max_robots * sizeof *self->evicted);
    self->names = PyList_New(0);
    if (self->robots == NULL || self->table == NULL || self->spare == NULL || self->live == NULL ||
        self->dirty == NULL || self->touched == NULL || self->evicted == NULL || self->names == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    for (i = 0; i < (Py_ssize_t)slots; i++) self->table[i] = FREE_SLOT;
    for (i = 0; i < max_robots; i++) self->spare[i] = (int32_t)(max_robots - 1 - i);
    self->nspare = max_robots;
    return (PyObject *)self;
}

/* The tally holds the Roster's sweep, the Roster the tally: a cycle the collector breaks. */
static int Tally_traverse(vx_tally_t *self, visitproc visit, void *arg) {
    Py_VISIT(self->on_due);
    return 0;
}

static int Tally_clear(vx_tally_t *self) {
    Py_CLEAR(self->on_due);
    return 0;
}

static void Tally_dealloc(vx_tally_t *self) {
    PyObject_GC_UnTrack(self);
    Tally_clear(self);
    PyMem_Free(self->robots);
    PyMem_Free(self->table);
    PyMem_Free(self->spare);
    PyMem_Free(self->live);
    PyMem_Free(self->dirty);
    PyMem_Free(self->touched);
    PyMem_Free(self->evicted);
    Py_XDECREF(self->names);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

/* sender: None (unnamed) or an int; 0/1 into *named, -1 on error */
static int sender_of(PyObject *obj, int *named, unsigned long long *sender) {
    *named = obj != Py_None;
    if (!*named) return 0;
    *sender = PyLong_AsUnsignedLongLong(obj);
    return *sender == (unsigned long long)-1 && PyErr_Occurred() ? -1 : 0;
}

static PyObject *Tally_take(vx_tally_t *self, PyObject *const *args, Py_ssize_t nargs) {
    PyObject *seq;
    vstig_msg_t *msgs;
    unsigned long long sender = 0;
    double when;
    int named, status = 0;
    Py_ssize_t i, n;
    if (nargs != 4) return PyErr_Format(PyExc_TypeError, "take(link, t, sender, messages), got %zd arguments", nargs);
    when = PyFloat_AsDouble(args[1]);
    if ((when == -1.0 && PyErr_Occurred()) || sender_of(args[2], &named, &sender) < 0) return NULL;
    if ((seq = PySequence_Fast(args[3], "messages must be a sequence of Message")) == NULL) return NULL;
    n = PySequence_Fast_GET_SIZE(seq);
    msgs = PyMem_Malloc((size_t)(n ? n : 1) * sizeof *msgs);
    if (msgs == NULL) status = -1;
    for (i = 0; status == 0 && i < n; i++) status = vx_msg_of(PySequence_Fast_GET_ITEM(seq, i), &msgs[i]);
    if (status == 0) status = vx_tally_take(self, args[0], when, named, sender, msgs, (size_t)n);
    PyMem_Free(msgs);
    Py_DECREF(seq);
    if (status < 0) return PyErr_Occurred() ? NULL : PyErr_NoMemory();
    Py_RETURN_NONE;
}

/* The `refused` listener: tally(heard, reason), a Heard's message, time and sender. */
static PyObject *Tally_call(vx_tally_t *self, PyObject *args, PyObject *kwds) {
    PyObject *heard_obj, *reason, *message = NULL, *when_obj = NULL, *sender_obj = NULL;
    vstig_msg_t msg;
    unsigned long long sender = 0;
    double when = -1.0;
    int named = 0, ok;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "OO", (char *[]){"heard", "reason", NULL}, &heard_obj, &reason))
        return NULL;
    ok = (message = PyObject_GetAttr(heard_obj, vx_n.message)) != NULL &&
         (when_obj = PyObject_GetAttr(heard_obj, vx_n.t)) != NULL &&
         (sender_obj = PyObject_GetAttr(heard_obj, vx_n.sender)) != NULL && vx_msg_of(message, &msg) == 0 &&
         !((when = PyFloat_AsDouble(when_obj)) == -1.0 && PyErr_Occurred()) &&
         sender_of(sender_obj, &named, &sender) == 0;
    Py_XDECREF(message);
    Py_XDECREF(when_obj);
    Py_XDECREF(sender_obj);
    if (!ok) return NULL;
    vx_tally_refuse(self, when, named, sender, &msg);
    Py_RETURN_NONE;
}

static PyObject *Tally_mark(vx_tally_t *self, PyObject *args) {
    unsigned long long who;
    int state, gone;
    robot_t *r;
    if (!PyArg_ParseTuple(args, "Ki", &who, &state)) return NULL;
    if (state < ALIVE || state > GONE) return PyErr_Format(PyExc_ValueError, "state must be 0..2, got %d", state);
    if ((r = find(self, who)) == NULL) Py_RETURN_NONE;
    r->state = (uint8_t)state;
    gone = state == GONE;
    if (r->gone != gone) { /* only gone robots make room */
        r->gone = (uint8_t)gone;
        self->ngone += gone ? 1 : -1;
    }
    Py_RETURN_NONE;
}

static double now_of(PyObject *obj) {
    double now = PyFloat_AsDouble(obj);
    if (now == -1.0 && PyErr_Occurred()) return NAN;
    if (isnan(now)) PyErr_Format(PyExc_ValueError, "now must be a time in seconds, got %R", obj);
    return now;
}

static PyObject *Tally_due(vx_tally_t *self, PyObject *now_obj) {
    double now = now_of(now_obj);
    if (isnan(now)) return NULL;
    return PyBool_FromLong(advance(self, now));
}

/* A Node's tick listener: the wall clock (time.time's, as the readers stamp what they read), the rates, and the
 * Roster's sweep only when it has something to tell. */
static PyObject *Tally_tick(vx_tally_t *self, PyObject *node) {
    struct timespec ts;
    double now;
    (void)node;
    clock_gettime(CLOCK_REALTIME, &ts);
    now = (double)((long long)ts.tv_sec * 1000000000LL + ts.tv_nsec) / 1e9;
    if (!advance(self, now) || self->on_due == NULL) Py_RETURN_NONE; /* (NULL: cleared by the collector) */
    return PyObject_CallFunction(self->on_due, "d", now);
}

/* The names of the links of bit set `links`, a list. */
static PyObject *links_of(const vx_tally_t *t, uint64_t links) {
    PyObject *names = PyList_New(0);
    int i;
    for (i = 0; names != NULL && i < VX_ROSTER_LINKS; i++) {
        if ((links >> i & 1u) && PyList_Append(names, PyList_GET_ITEM(t->names, i)) < 0) Py_CLEAR(names);
    }
    return names;
}

static PyObject *record_of(const vx_tally_t *t, robot_t *r) {
    PyObject *links = links_of(t, r->links), *behind = PyTuple_New(r->nbehind), *record = NULL;
    int i;
    for (i = 0; behind != NULL && i < r->nbehind; i++) {
        PyObject *pair = Py_BuildValue("(Hd)", r->behind_key[i], r->behind_since[i]);
        if (pair == NULL) Py_CLEAR(behind);
        else PyTuple_SET_ITEM(behind, i, pair);
    }
    if (links != NULL && behind != NULL) {
        PyObject *revived = isnan(r->revived) ? Py_NewRef(Py_None)
                                              : Py_BuildValue("(dN)", r->revived, links_of(t, r->revived_links));
        if (revived != NULL)
            record = Py_BuildValue("(KNNddddLLLLNNN)", r->who, PyBool_FromLong(r->named), PyBool_FromLong(r->fresh),
                                   r->first, r->last, r->gap, r->rate, r->messages, r->writes, r->gets, r->refused,
                                   links, revived, behind);
        links = behind = NULL; /* stolen (N), or revived failed: freed below */
    }
    Py_XDECREF(links);
    Py_XDECREF(behind);
    return record;
}

/* What changed since the last fold: (records, evicted, untracked, behind_untracked, unattributed); None if
 * nothing did (a tick of a quiet swarm costs no lists). */
static PyObject *Tally_fold(vx_tally_t *self, PyObject *unused) {
    PyObject *records, *evicted, *record;
    Py_ssize_t i;
    (void)unused;
    if (!self->ntouched && !self->nevicted && !self->counted) Py_RETURN_NONE;
    records = PyList_New(0);
    evicted = PyList_New(self->nevicted);
    for (i = 0; evicted != NULL && i < self->nevicted; i++) {
        PyObject *who = PyLong_FromUnsignedLongLong(self->evicted[i]);
        if (who == NULL) Py_CLEAR(evicted);
        else PyList_SET_ITEM(evicted, i, who);
    }
    for (i = 0; records != NULL && evicted != NULL && i < self->ntouched; i++) {
        robot_t *r = &self->robots[self->touched[i]];
        if (!r->used) continue; /* forgotten since: in `evicted` */
        record = record_of(self, r);
        if (record == NULL || PyList_Append(records, record) < 0) Py_CLEAR(records);
        Py_XDECREF(record);
    }
    if (records == NULL || evicted == NULL) {
        Py_XDECREF(records);
        Py_XDECREF(evicted);
        return NULL;
    }
    for (i = 0; i < self->ntouched; i++) {
        robot_t *r = &self->robots[self->touched[i]];
        self->dirty[self->touched[i]] = 0;
        r->fresh = 0;
        r->revived = NAN;
    }
    self->ntouched = self->nevicted = 0;
    self->counted = 0;
    return Py_BuildValue("(NNLLL)", records, evicted, self->untracked, self->behind_untracked, self->unattributed);
}

static PyMethodDef Tally_methods[] = {
    {"take", (PyCFunction)(void (*)(void))Tally_take, METH_FASTCALL,
     "take(link, t, sender, messages): what one unit carried past the guard (Roster.take; a `messages` listener)."},
    {"mark", (PyCFunction)Tally_mark, METH_VARARGS,
     "mark(robot, state): the Roster's state of `robot` is now `state` (its STATE_ORDER: 0 alive, 1 quiet, 2 gone)."},
    {"due", (PyCFunction)Tally_due, METH_O,
     "due(now) -> bool: the rates advanced to `now`; whether a sweep at `now` has a state change to tell."},
    {"tick", (PyCFunction)Tally_tick, METH_O,
     "tick(node): a Node's tick listener: `due` at the wall clock, and the Roster's sweep only if it is."},
    {"fold", (PyCFunction)Tally_fold, METH_NOARGS,
     "(records, evicted, untracked, behind_untracked, unattributed): every robot changed since the last fold, as "
     "(robot, named, fresh, first, last, gap, rate, messages, writes, gets, refused, links, revived, behind), "
     "revived: None or (when first heard since the last fold, its links then); None if nothing changed."},
    {NULL, NULL, 0, NULL},
};

vx_tally_t *vx_tally_of_take(PyObject *listener) {
    if (!PyCFunction_Check(listener) || PyCFunction_GET_FUNCTION(listener) != (PyCFunction)(void (*)(void))Tally_take)
        return NULL;
    return (vx_tally_t *)PyCFunction_GET_SELF(listener);
}

PyTypeObject vx_RosterTallyType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.RosterTally",
    .tp_doc = "RosterTally(max_robots, quiet_after, gone_after, on_due): Roster.take, Roster.refuse and the rates "
              "and state judging of Roster.sweep in C; `take` is a `messages` listener, the tally itself a `refused` "
              "one, `tick` a `tick` one that calls on_due(now) (the Roster's sweep) only when a state would change.",
    .tp_basicsize = sizeof(vx_tally_t),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_traverse = (traverseproc)Tally_traverse,
    .tp_clear = (inquiry)Tally_clear,
    .tp_new = Tally_new,
    .tp_dealloc = (destructor)Tally_dealloc,
    .tp_call = (ternaryfunc)Tally_call,
    .tp_methods = Tally_methods,
};
