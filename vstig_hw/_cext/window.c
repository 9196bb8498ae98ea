/*
 * Window: vstig_hw.gateway.outlet.SendWindow in C (at most `budget` sends in any `period` seconds, evenly
 * spaced while a backlog lasts). The same float operations in the same order: the same answers.
 *
 * Reference: vstig_hw/gateway/outlet.py (held equal by tests/native; the index of the twins: vstig_hw/_vstig.pyi).
 */
#include "window.h"

#include <structmember.h>

#define PACE_BURST 4.0   /* SendWindow's PACE_BURST */
#define RESERVE_SHARE 16 /* SendWindow's RESERVE_SHARE */

static double oldest(const vx_window_t *w) { return w->sent[w->head]; }

static void pop_oldest(vx_window_t *w) {
    w->head = (w->head + 1) % w->cap;
    w->len--;
}

static void append(vx_window_t *w, double when) {
    /* a deque with maxlen: a full one drops its oldest */
    if (w->len == w->cap) pop_oldest(w);
    w->sent[(w->head + w->len) % w->cap] = when;
    w->len++;
}

long vx_window_free(vx_window_t *w, double now) {
    if (w->budget == 0) return 1L << 30;
    while (w->len && oldest(w) <= now - w->period) pop_oldest(w);
    return w->budget - w->len;
}

long vx_window_allowance(vx_window_t *w, double now) {
    long free_, paced;
    if (w->budget == 0) return 1L << 30;
    free_ = vx_window_free(w, now) - w->reserve;
    if (!w->paced) return free_;
    paced = (long)((now - w->paced_to) / w->spacing); /* int() truncates toward zero */
    if (paced > (long)PACE_BURST) paced = (long)PACE_BURST;
    return free_ < paced ? free_ : paced;
}

void vx_window_record(vx_window_t *w, double now, long count, int backlog, int sparse) {
    long i, n;
    if (w->budget == 0) return;
    n = count < w->budget ? count : w->budget;
    for (i = 0; i < n; i++) append(w, now);
    if (!backlog) {
        w->paced = 0;
    } else if (sparse) { /* from the reserve: the backlog's pace stays where it was */
        return;
    } else if (!w->paced) { /* a backlog starts: what just left was the burst */
        w->paced = 1;
        w->paced_to = now;
    } else {
        double floor_ = now - PACE_BURST * w->spacing;
        w->paced_to = (w->paced_to > floor_ ? w->paced_to : floor_) + (double)count * w->spacing;
    }
}

int vx_window_next_free(const vx_window_t *w, int sparse, double *when) {
    long over;
    int opens;
    double at = 0.0, paced;
    if (w->budget == 0) return 0;
    if (sparse) {
        *when = oldest(w) + w->period;
        return w->len >= w->budget;
    }
    over = w->len - (w->budget - w->reserve); /* the backlog has a place once over + 1 have expired */
    opens = over >= 0;
    if (opens) at = w->sent[(w->head + over) % w->cap] + w->period;
    if (!w->paced) {
        *when = at;
        return opens;
    }
    paced = w->paced_to + w->spacing;
    *when = !opens ? paced : (at > paced ? at : paced);
    return 1;
}

static PyObject *Window_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"budget", "period", NULL};
    PyObject *budget_obj;
    double period;
    long budget = 0;
    vx_window_t *self;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "Od", kwlist, &budget_obj, &period)) return NULL;
    if (budget_obj != Py_None) {
        budget = PyLong_AsLong(budget_obj);
        if (budget == -1 && PyErr_Occurred()) return NULL;
        if (budget < 1) return PyErr_Format(PyExc_ValueError, "budget must be at least 1 message per tick, got %ld",
                                            budget);
    }
    if (!(period > 0)) return PyErr_Format(PyExc_ValueError, "the tick period must be positive, got %R",
                                           PyTuple_GET_ITEM(args, 1));
    self = (vx_window_t *)type->tp_alloc(type, 0);
    if (self == NULL) return NULL;
    self->budget = budget;
    self->period = period;
    self->reserve = budget < 4 ? 0 : budget / RESERVE_SHARE > 1 ? budget / RESERVE_SHARE : 1;
    self->spacing = budget ? period / (double)(budget - self->reserve) : 0.0;
    self->cap = budget ? budget : 1;
    self->sent = PyMem_Malloc((size_t)self->cap * sizeof *self->sent);
    self->budget_obj = Py_NewRef(budget_obj);
    self->period_obj = PyFloat_FromDouble(period);
    if (self->sent == NULL || self->period_obj == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    return (PyObject *)self;
}

static void Window_dealloc(vx_window_t *self) {
    PyMem_Free(self->sent);
    Py_XDECREF(self->budget_obj);
    Py_XDECREF(self->period_obj);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *Window_free(vx_window_t *self, PyObject *now) {
    double t = PyFloat_AsDouble(now);
    if (t == -1.0 && PyErr_Occurred()) return NULL;
    return PyLong_FromLong(vx_window_free(self, t));
}

static PyObject *Window_allowance(vx_window_t *self, PyObject *now) {
    double t = PyFloat_AsDouble(now);
    if (t == -1.0 && PyErr_Occurred()) return NULL;
    return PyLong_FromLong(vx_window_allowance(self, t));
}

static PyObject *Window_record(vx_window_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"now", "count", "backlog", "sparse", NULL};
    double now;
    long count;
    int backlog = 0, sparse = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "dl|pp", kwlist, &now, &count, &backlog, &sparse)) return NULL;
    vx_window_record(self, now, count, backlog, sparse);
    Py_RETURN_NONE;
}

static PyObject *Window_next_free(vx_window_t *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"sparse", NULL};
    double when;
    int sparse = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "|p", kwlist, &sparse)) return NULL;
    if (!vx_window_next_free(self, sparse, &when)) Py_RETURN_NONE;
    return PyFloat_FromDouble(when);
}

static PyObject *Window_get_reserve(vx_window_t *self, void *closure) {
    (void)closure;
    return PyLong_FromLong(self->reserve);
}

static PyMethodDef Window_methods[] = {
    {"free", (PyCFunction)Window_free, METH_O, "How many may leave at `now` by the budget alone."},
    {"allowance", (PyCFunction)Window_allowance, METH_O, "How many of a backlog may leave at `now`."},
    {"record", (PyCFunction)(void (*)(void))Window_record, METH_VARARGS | METH_KEYWORDS,
     "`count` messages left at `now`; `backlog`: others still wait; `sparse`: they were sparse sources'."},
    {"next_free", (PyCFunction)(void (*)(void))Window_next_free, METH_VARARGS | METH_KEYWORDS,
     "When the window next lets a message of the backlog (`sparse`: a sparse source's) go, if not now."},
    {NULL, NULL, 0, NULL},
};

static PyMemberDef Window_members[] = {
    {"budget", T_OBJECT, offsetof(vx_window_t, budget_obj), READONLY, NULL},
    {"period", T_OBJECT, offsetof(vx_window_t, period_obj), READONLY, NULL},
    {NULL, 0, 0, 0, NULL},
};

static PyGetSetDef Window_getset[] = {
    {"reserve", (getter)Window_get_reserve, NULL, "Places of the window a backlog leaves to sparse sources.", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

PyTypeObject vx_WindowType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "vstig_hw._vstig.Window",
    .tp_doc = "Window(budget, period): SendWindow in C.",
    .tp_basicsize = sizeof(vx_window_t),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = Window_new,
    .tp_dealloc = (destructor)Window_dealloc,
    .tp_methods = Window_methods,
    .tp_members = Window_members,
    .tp_getset = Window_getset,
};
