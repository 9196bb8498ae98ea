/* The Window type's object (window.c), for the outlets (outlet.c). */
#ifndef VSTIG_EXT_WINDOW_H
#define VSTIG_EXT_WINDOW_H

#include "ext.h"

typedef struct {
    PyObject_HEAD
    long budget;            /* 0: no budget */
    long reserve;           /* places of the window a backlog leaves to sparse sources (SendWindow.reserve) */
    double period, spacing; /* spacing: period / (budget - reserve), the pace while a backlog lasts */
    double *sent;           /* a ring of send times, at most `cap` (SendWindow's deque with maxlen) */
    long cap, head, len;
    int paced;              /* a backlog is being paced: paced_to holds */
    double paced_to;
    PyObject *budget_obj, *period_obj; /* as given: SendWindow's attributes */
} vx_window_t;

extern PyTypeObject vx_WindowType;

/* how many may leave at `now` by the budget alone (SendWindow.free); a backlog's share of them (allowance) */
long vx_window_free(vx_window_t *w, double now);
long vx_window_allowance(vx_window_t *w, double now);
void vx_window_record(vx_window_t *w, double now, long count, int backlog, int sparse);
/* 1 and *when the window next lets a message of the backlog (`sparse`: a sparse source's) go, or 0 (it does now,
 * or there is no budget) */
int vx_window_next_free(const vx_window_t *w, int sparse, double *when);

#endif /* VSTIG_EXT_WINDOW_H */
