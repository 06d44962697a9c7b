/* IngestCore's reorder buffer: reorder.ReorderBuffer's push and clear in C, bit for bit (see
 * ingest_core.c for the object and its tests). */
#include "ingest_core.h"

#define MAX_HELD 4096 /* reorder.MAX_HELD */
#define MARGIN 1.25   /* reorder.MARGIN */
#define PERIOD_S 5.0  /* reorder.PERIOD_S */

static int
held_before(const Held *a, const Held *b)
{
    return a->t < b->t || (a->t == b->t && a->seq < b->seq);
}

static int
heap_push(Core *c, double t, PyObject *kind, PyObject *sample)
{
    if (c->held == c->capacity) {
        Py_ssize_t capacity = c->capacity ? 2 * c->capacity : 64;
        Held *heap = PyMem_Realloc(c->heap, capacity * sizeof(Held));
        if (heap == NULL) {
            PyErr_NoMemory();
            return 0;
        }
        c->heap = heap;
        c->capacity = capacity;
    }
    Held item = {t, c->next_seq++, Py_NewRef(kind), Py_NewRef(sample)};
    Py_ssize_t i = c->held++;
    while (i > 0) {
        Py_ssize_t parent = (i - 1) / 2;
        if (!held_before(&item, &c->heap[parent]))
            break;
        c->heap[i] = c->heap[parent];
        i = parent;
    }
    c->heap[i] = item;
    return 1;
}

/* The oldest held item (its references handed to the caller). */
static Held
heap_pop(Core *c)
{
    Held top = c->heap[0];
    Held last = c->heap[--c->held];
    Py_ssize_t i = 0, n = c->held;
    for (;;) {
        Py_ssize_t child = 2 * i + 1;
        if (child >= n)
            break;
        if (child + 1 < n && held_before(&c->heap[child + 1], &c->heap[child]))
            child++;
        if (!held_before(&c->heap[child], &last))
            break;
        c->heap[i] = c->heap[child];
        i = child;
    }
    if (n > 0)
        c->heap[i] = last;
    return top;
}

static PyObject *
pair(PyObject *kind, PyObject *sample)
{
    return PyTuple_Pack(2, kind, sample);
}

static void
reordering_seen(Core *c, double lateness_s)
{
    c->reordered++;
    if (lateness_s > c->largest_lateness_s) /* max(largest, lateness) */
        c->largest_lateness_s = lateness_s;
    if (lateness_s > c->lateness_s) {
        c->lateness_s = lateness_s;
        double margin = MARGIN * lateness_s;
        double wanted = margin < c->max_window_s ? margin : c->max_window_s;
        if (wanted > c->window_s) {
            c->window_s = wanted;
            c->widened++;
        }
    }
}

static void
end_period(Core *c, double time_s)
{
    c->previous_lateness_s = c->lateness_s;
    c->lateness_s = 0.0;
    c->period_end_s = time_s + PERIOD_S;
    double margin = MARGIN * c->previous_lateness_s;
    double wanted = margin < c->max_window_s ? margin : c->max_window_s;
    if (wanted < c->window_s) {
        c->window_s = wanted;
        c->narrowed++;
    }
}

/* [(kind, sample)]: the input due at once, nothing held (a new list, or NULL with an error set). */
static PyObject *
due_alone(PyObject *kind, PyObject *sample)
{
    PyObject *item = pair(kind, sample);
    if (item == NULL)
        return NULL;
    PyObject *out = PyList_New(1);
    if (out == NULL) {
        Py_DECREF(item);
        return NULL;
    }
    PyList_SET_ITEM(out, 0, item);
    return out;
}

/* ReorderBuffer.push: a new list of (kind, sample) due, oldest first. */
PyObject *
ingest_buffer_push(Core *c, PyObject *kind, double time_s, PyObject *sample)
{
    if (c->max_window_s == 0.0) {
        return due_alone(kind, sample);
    }
    double newest = c->newest_s;
    if (time_s >= newest) {
        c->newest_s = newest = time_s;
        if (time_s >= c->period_end_s)
            end_period(c, time_s);
    }
    PyObject *seen = PyDict_GetItemWithError(c->newest_by_kind, kind);
    if (seen == NULL && PyErr_Occurred())
        return NULL;
    double seen_s = seen == NULL ? -INFINITY : PyFloat_AsDouble(seen);
    if (time_s < seen_s)
        reordering_seen(c, newest - time_s);
    else {
        PyObject *t = PyFloat_FromDouble(time_s);
        if (t == NULL || PyDict_SetItem(c->newest_by_kind, kind, t) < 0) {
            Py_XDECREF(t);
            return NULL;
        }
        Py_DECREF(t);
    }
    if (c->held == 0 && c->window_s == 0.0) {
        return due_alone(kind, sample);
    }
    if (!heap_push(c, time_s, kind, sample))
        return NULL;
    double horizon = newest - c->window_s;
    PyObject *out = PyList_New(0);
    if (out == NULL)
        return NULL;
    while (c->held && (c->heap[0].t <= horizon || c->held > MAX_HELD)) {
        Held top = heap_pop(c);
        PyObject *item = PyTuple_New(2);
        if (item == NULL) {
            Py_DECREF(top.kind);
            Py_DECREF(top.sample);
            Py_DECREF(out);
            return NULL;
        }
        PyTuple_SET_ITEM(item, 0, top.kind);
        PyTuple_SET_ITEM(item, 1, top.sample);
        int failed = PyList_Append(out, item);
        Py_DECREF(item);
        if (failed) {
            Py_DECREF(out);
            return NULL;
        }
    }
    return out;
}

int
ingest_buffer_clear(Core *c)
{
    while (c->held) {
        Held h = c->heap[--c->held];
        Py_DECREF(h.kind);
        Py_DECREF(h.sample);
    }
    c->newest_s = -INFINITY;
    PyDict_Clear(c->newest_by_kind);
    c->period_end_s = -INFINITY;
    return 1;
}

