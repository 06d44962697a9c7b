/* The ingest's time line in C: the flight controller's clock gate, the reorder buffer and the
 * per-kind order check as ONE object (part of the _frame_core extension).
 *
 * Python stays the reference and the fallback: fc_time.FcTimeGate (the clock),
 * reorder.ReorderBuffer (the buffer) and Ingest's receive_input / _believed / _ordered /
 * _in_order (the counts and the order). An IngestCore is all of their state in one struct and
 * serves both classes' interfaces, so the message path (SYSTEM_TIME, the ground readings, the
 * messages the frame path leaves to the parser) and the frame path share it:
 *
 *   clock:    check(fc_s, local_s), on_system_time(fc_s, local_s), reset(), latest_fc_s
 *   buffer:   push(kind, time_s, sample), clear(), len(), window_s, reordered, widened,
 *             narrowed, largest_lateness_s, max_window_s
 *   ingest:   receive_input(kind, sample, local_s), believed(verdict), ordered(released)
 *   frames:   samples(frame, local_s): Reader.read(frame), its drop counted, receive_input
 *
 * IngestCore(ingest, counters, latest_by_kind, max_window_s, gate) takes the Ingest (whose
 * `_local_s` and `rebooted` it sets as receive_input does), its IngestCounters (counted by
 * name, as the Python counts them), its per-kind newest stamps dict (shared with the Python
 * methods), the buffer's largest window [s] and the gate's parameters (backstep_s,
 * future_tolerance_s, max_rate, confirm_span_s, fallback_s, confirmations, fallback_samples).
 *
 * Every comparison and sum is the reference's, in its order (-ffp-contract=off): the values
 * are doubles (a stamp or local time given as an int below 2^53 converts exactly, as Python
 * compares them). The reference's lists become what it reads of them: the confirmations'
 * count, min and max of the local times (and whether one was None), the run of stamps ahead's
 * first stamp, count, min and max. The heap orders (stamp, arrival number) as heapq orders
 * the reference's tuples (stamps are finite: the inputs' integer time fields scaled).
 * tests/test_ingest_core.py runs random streams through both, every counter after every input.
 */
#include "frame_wire.h"
#include <math.h>
#include <stddef.h>

#define MAX_HELD 4096 /* reorder.MAX_HELD */
#define MARGIN 1.25   /* reorder.MARGIN */
#define PERIOD_S 5.0  /* reorder.PERIOD_S */

typedef struct {
    double t;
    long long seq;
    PyObject *kind, *sample;
} Held;

typedef struct {
    PyObject_HEAD
    /* the clock gate's parameters and state (fc_time.FcTimeGate) */
    double backstep_s, future_tolerance_s, max_rate, confirm_span_s, fallback_s;
    long long confirmations, fallback_samples;
    double latest_fc_s;
    int has_latest_local;
    double latest_local_s;
    int has_claim, claim_has_local;
    double claim_fc_s, claim_local_s;
    long long n_confirm;
    int confirm_none, confirm_timed; /* a None among them; a local time among them */
    double confirm_min, confirm_max;
    long long backsteps;
    int has_first_backstep_local;
    double first_backstep_local_s;
    long long n_ahead;
    double ahead_fc_s, ahead_local_s, ahead_min, ahead_max;
    /* the reorder buffer's (reorder.ReorderBuffer) */
    double max_window_s, window_s, largest_lateness_s, newest_s, period_end_s, lateness_s,
        previous_lateness_s;
    long long reordered, widened, narrowed, next_seq;
    Held *heap;
    Py_ssize_t held, capacity;
    PyObject *newest_by_kind;
    /* the ingest's (Ingest): its per-kind newest stamps, counters, itself, the frame reader */
    PyObject *latest_by_kind, *counters, *ingest, *reader;
} Core;

static PyObject *one;
static PyObject *v_accept, *v_implausible, *v_backstep, *v_reboot;
static PyObject *n_messages, *n_implausible, *n_out_of_order, *n_reboots, *n_duplicate,
    *n_reordered, *n_window, *n_widened, *n_accepted, *n_local_s, *n_rebooted, *n_time_s;

/* ------------------------------------------------------------------ the clock gate */

static int
implausible(Core *c, double fc_s, int has_local, double local_s)
{
    if (!has_local || !c->has_latest_local)
        return 0;
    double elapsed = local_s - c->latest_local_s;
    if (!(elapsed > 0.0))
        elapsed = 0.0;
    return fc_s > c->latest_fc_s + c->max_rate * elapsed + c->future_tolerance_s;
}

static void
gate_reset(Core *c)
{
    c->latest_fc_s = -INFINITY;
    c->has_latest_local = 0;
    c->has_claim = 0;
    c->n_confirm = 0;
    c->confirm_none = c->confirm_timed = 0;
    c->backsteps = 0;
    c->has_first_backstep_local = 0;
    c->n_ahead = 0;
}

/* max(local times) - min(local times) >= confirm_span_s, or True if one was None. */
static int
spans(Core *c, int none, double lo, double hi)
{
    return none || hi - lo >= c->confirm_span_s;
}

static int
jump_confirmed(Core *c, double fc_s, double local_s)
{
    if (c->n_ahead) {
        double elapsed = local_s - c->ahead_local_s;
        int agrees = c->ahead_fc_s - c->backstep_s <= fc_s
                     && fc_s <= c->ahead_fc_s + c->max_rate * elapsed + c->future_tolerance_s;
        if (!agrees)
            c->n_ahead = 0;
    }
    if (c->n_ahead == 0) {
        c->ahead_fc_s = fc_s;
        c->ahead_local_s = c->ahead_min = c->ahead_max = local_s;
    }
    else {
        /* min/max as Python's: the first of equals kept; NaN never here (local times) */
        if (local_s < c->ahead_min)
            c->ahead_min = local_s;
        if (local_s > c->ahead_max)
            c->ahead_max = local_s;
    }
    c->n_ahead++;
    return c->n_ahead >= c->confirmations && spans(c, 0, c->ahead_min, c->ahead_max);
}

static PyObject *
rebooted(Core *c, double fc_s, int has_local, double local_s)
{
    gate_reset(c);
    c->latest_fc_s = fc_s;
    c->has_latest_local = has_local;
    c->latest_local_s = local_s;
    return v_reboot;
}

static int
agrees_with_claim(Core *c, double fc_s, int has_local, double local_s)
{
    if (fc_s < c->claim_fc_s - c->backstep_s)
        return 0;
    if (!has_local || !c->claim_has_local)
        return 1;
    return fc_s <= c->claim_fc_s + (local_s - c->claim_local_s) + c->future_tolerance_s;
}

static int
fallback_due(Core *c, int has_local, double local_s)
{
    if (!has_local || !c->has_first_backstep_local)
        return c->backsteps >= c->fallback_samples;
    return local_s - c->first_backstep_local_s >= c->fallback_s;
}

static PyObject *
backstep(Core *c, double fc_s, int has_local, double local_s)
{
    if (c->backsteps == 0) {
        c->has_first_backstep_local = has_local;
        c->first_backstep_local_s = local_s;
    }
    c->backsteps++;
    if (c->has_claim && agrees_with_claim(c, fc_s, has_local, local_s)) {
        if (!has_local)
            c->confirm_none = 1;
        else if (!c->confirm_timed) {
            c->confirm_timed = 1;
            c->confirm_min = c->confirm_max = local_s;
        }
        else {
            if (local_s < c->confirm_min)
                c->confirm_min = local_s;
            if (local_s > c->confirm_max)
                c->confirm_max = local_s;
        }
        c->n_confirm++;
        if (c->n_confirm >= c->confirmations
            && spans(c, c->confirm_none, c->confirm_min, c->confirm_max))
            return rebooted(c, fc_s, has_local, local_s);
    }
    else if (fallback_due(c, has_local, local_s))
        return rebooted(c, fc_s, has_local, local_s);
    return v_backstep;
}

/* FcTimeGate.check: the verdict (a borrowed interned string). */
static PyObject *
gate_check(Core *c, double fc_s, int has_local, double local_s)
{
    if (implausible(c, fc_s, has_local, local_s) && !jump_confirmed(c, fc_s, local_s))
        return v_implausible;
    c->n_ahead = 0;
    if (fc_s < c->latest_fc_s - c->backstep_s)
        return backstep(c, fc_s, has_local, local_s);
    c->has_claim = 0;
    c->backsteps = 0;
    c->has_first_backstep_local = 0;
    if (fc_s >= c->latest_fc_s) {
        c->latest_fc_s = fc_s;
        c->has_latest_local = has_local;
        c->latest_local_s = local_s;
    }
    return v_accept;
}

/* ------------------------------------------------------------------ the reorder buffer */

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

/* ReorderBuffer.push: a new list of (kind, sample) due, oldest first. */
static PyObject *
buffer_push(Core *c, PyObject *kind, double time_s, PyObject *sample)
{
    if (c->max_window_s == 0.0) {
        PyObject *one = pair(kind, sample);
        if (one == NULL)
            return NULL;
        PyObject *out = PyList_New(1);
        if (out == NULL) {
            Py_DECREF(one);
            return NULL;
        }
        PyList_SET_ITEM(out, 0, one);
        return out;
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
        PyObject *one = pair(kind, sample);
        if (one == NULL)
            return NULL;
        PyObject *out = PyList_New(1);
        if (out == NULL) {
            Py_DECREF(one);
            return NULL;
        }
        PyList_SET_ITEM(out, 0, one);
        return out;
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

static int
buffer_clear(Core *c)
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

/* ------------------------------------------------------------------ the ingest's counts */

/* counters.<name> += 1; 0 with an error set. */
static int
count(PyObject *counters, PyObject *name)
{
    PyObject *value = PyObject_GetAttr(counters, name);
    if (value == NULL)
        return 0;
    PyObject *more = PyNumber_Add(value, one);
    Py_DECREF(value);
    if (more == NULL)
        return 0;
    int failed = PyObject_SetAttr(counters, name, more);
    Py_DECREF(more);
    return !failed;
}

static int
set_long(PyObject *o, PyObject *name, long long v)
{
    PyObject *x = PyLong_FromLongLong(v);
    if (x == NULL)
        return 0;
    int failed = PyObject_SetAttr(o, name, x);
    Py_DECREF(x);
    return !failed;
}

/* Ingest._believed: 1 (goes on), 0 (dropped), -1 (error). */
static int
believed(Core *c, PyObject *verdict)
{
    if (verdict == v_implausible)
        return count(c->counters, n_implausible) ? 0 : -1;
    if (verdict == v_backstep)
        return count(c->counters, n_out_of_order) ? 0 : -1;
    if (verdict == v_reboot) {
        if (!count(c->counters, n_reboots)
            || PyObject_SetAttr(c->ingest, n_rebooted, Py_True) < 0)
            return -1;
        PyDict_Clear(c->latest_by_kind);
        buffer_clear(c);
    }
    return 1;
}

/* Ingest._in_order: 1, 0, or -1 (error). */
static int
in_order(Core *c, PyObject *kind, PyObject *sample)
{
    PyObject *time = PyObject_GetAttr(sample, n_time_s);
    if (time == NULL)
        return -1;
    double t = PyFloat_AsDouble(time);
    Py_DECREF(time);
    if (t == -1.0 && PyErr_Occurred())
        return -1;
    PyObject *counters = c->counters;
    PyObject *window = PyFloat_FromDouble(c->window_s);
    if (window == NULL)
        return -1;
    int failed = !set_long(counters, n_reordered, c->reordered)
                 || PyObject_SetAttr(counters, n_window, window) < 0
                 || !set_long(counters, n_widened, c->widened);
    Py_DECREF(window);
    if (failed)
        return -1;
    PyObject *previous = PyDict_GetItemWithError(c->latest_by_kind, kind);
    if (previous == NULL && PyErr_Occurred())
        return -1;
    double previous_s = previous == NULL ? -INFINITY : PyFloat_AsDouble(previous);
    if (t == previous_s)
        return count(counters, n_duplicate) ? 0 : -1;
    if (t < previous_s)
        return count(counters, n_out_of_order) ? 0 : -1;
    PyObject *ts = PyFloat_FromDouble(t);
    if (ts == NULL || PyDict_SetItem(c->latest_by_kind, kind, ts) < 0) {
        Py_XDECREF(ts);
        return -1;
    }
    Py_DECREF(ts);
    PyObject *accepted = PyObject_GetAttr(counters, n_accepted);
    if (accepted == NULL)
        return -1;
    PyObject *n = PyObject_GetItem(accepted, kind);
    PyObject *more = n == NULL ? NULL : PyNumber_Add(n, one);
    Py_XDECREF(n);
    failed = more == NULL || PyObject_SetItem(accepted, kind, more) < 0;
    Py_XDECREF(more);
    Py_DECREF(accepted);
    return failed ? -1 : 1;
}

/* Ingest._ordered: the released (kind, sample) pairs' samples that pass in_order (a new list;
 * `released` is consumed). */
static PyObject *
ordered(Core *c, PyObject *released)
{
    if (released == NULL)
        return NULL;
    PyObject *out = PyList_New(0);
    if (out == NULL) {
        Py_DECREF(released);
        return NULL;
    }
    Py_ssize_t n = PyList_GET_SIZE(released);
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *item = PyList_GET_ITEM(released, i);
        if (!PyTuple_Check(item) || PyTuple_GET_SIZE(item) != 2) {
            PyErr_SetString(PyExc_TypeError, "released items are (kind, sample) pairs");
            goto fail;
        }
        PyObject *sample = PyTuple_GET_ITEM(item, 1);
        int ok = in_order(c, PyTuple_GET_ITEM(item, 0), sample);
        if (ok < 0 || (ok && PyList_Append(out, sample) < 0))
            goto fail;
    }
    Py_DECREF(released);
    return out;
fail:
    Py_DECREF(released);
    Py_DECREF(out);
    return NULL;
}

/* A local time argument: None (has = 0) or a number; 0 with an error set. */
static int
local_time(PyObject *o, int *has, double *local_s)
{
    *has = o != Py_None;
    *local_s = 0.0;
    if (*has) {
        *local_s = PyFloat_AsDouble(o);
        if (*local_s == -1.0 && PyErr_Occurred())
            return 0;
    }
    return 1;
}

/* Ingest.receive_input for (kind, sample or None, local time object). */
static PyObject *
receive(Core *c, PyObject *kind, PyObject *sample, PyObject *local)
{
    int has_local;
    double local_s;
    if (!local_time(local, &has_local, &local_s))
        return NULL;
    if (PyObject_SetAttr(c->ingest, n_local_s, local) < 0
        || PyObject_SetAttr(c->ingest, n_rebooted, Py_False) < 0
        || !count(c->counters, n_messages))
        return NULL;
    if (sample == Py_None)
        return PyList_New(0);
    PyObject *time = PyObject_GetAttr(sample, n_time_s);
    if (time == NULL)
        return NULL;
    double time_s = PyFloat_AsDouble(time);
    Py_DECREF(time);
    if (time_s == -1.0 && PyErr_Occurred())
        return NULL;
    PyObject *verdict = gate_check(c, time_s, has_local, local_s);
    if (verdict != v_accept) {
        int goes_on = believed(c, verdict);
        if (goes_on < 0)
            return NULL;
        if (!goes_on)
            return PyList_New(0);
    }
    return ordered(c, buffer_push(c, kind, time_s, sample));
}

/* ------------------------------------------------------------------ Python methods */

static int
two_times(PyObject *const *args, Py_ssize_t nargs, double *fc_s, int *has, double *local_s)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "expected (fc_s, local_s)");
        return 0;
    }
    *fc_s = PyFloat_AsDouble(args[0]);
    if (*fc_s == -1.0 && PyErr_Occurred())
        return 0;
    return local_time(args[1], has, local_s);
}

static PyObject *
core_check(Core *c, PyObject *const *args, Py_ssize_t nargs)
{
    double fc_s, local_s;
    int has;
    if (!two_times(args, nargs, &fc_s, &has, &local_s))
        return NULL;
    return Py_NewRef(gate_check(c, fc_s, has, local_s));
}

static PyObject *
core_on_system_time(Core *c, PyObject *const *args, Py_ssize_t nargs)
{
    double fc_s, local_s;
    int has;
    if (!two_times(args, nargs, &fc_s, &has, &local_s))
        return NULL;
    if (!isfinite(c->latest_fc_s))
        return Py_NewRef(v_accept);
    if (implausible(c, fc_s, has, local_s))
        return Py_NewRef(v_implausible);
    if (fc_s < c->latest_fc_s - c->backstep_s) {
        c->has_claim = 1;
        c->claim_fc_s = fc_s;
        c->claim_has_local = has;
        c->claim_local_s = local_s;
        c->n_confirm = 0;
        c->confirm_none = c->confirm_timed = 0;
        return Py_NewRef(v_backstep);
    }
    c->has_claim = 0;
    return Py_NewRef(v_accept);
}

static PyObject *
core_reset(Core *c, PyObject *unused)
{
    gate_reset(c);
    Py_RETURN_NONE;
}

static PyObject *
core_push(Core *c, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "expected (kind, time_s, sample)");
        return NULL;
    }
    double time_s = PyFloat_AsDouble(args[1]);
    if (time_s == -1.0 && PyErr_Occurred())
        return NULL;
    return buffer_push(c, args[0], time_s, args[2]);
}

static PyObject *
core_clear(Core *c, PyObject *unused)
{
    buffer_clear(c);
    Py_RETURN_NONE;
}

static PyObject *
core_believed(Core *c, PyObject *verdict)
{
    /* the verdicts are interned; an equal string from elsewhere is the same verdict */
    PyObject *known[] = {v_accept, v_implausible, v_backstep, v_reboot};
    for (int i = 0; i < 4; i++)
        if (verdict != known[i] && PyUnicode_Check(verdict)
            && PyUnicode_Compare(verdict, known[i]) == 0)
            verdict = known[i];
    int goes_on = believed(c, verdict);
    if (goes_on < 0)
        return NULL;
    return PyBool_FromLong(goes_on);
}

static PyObject *
core_ordered(Core *c, PyObject *released)
{
    if (!PyList_Check(released)) {
        PyErr_SetString(PyExc_TypeError, "released must be a list");
        return NULL;
    }
    return ordered(c, Py_NewRef(released));
}

static PyObject *
core_receive_input(Core *c, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "expected (kind, sample, local_s)");
        return NULL;
    }
    return receive(c, args[0], args[1], args[2]);
}

/* FrameIngest.samples for an admitted frame: Reader.read, the drop counted, receive_input. */
static PyObject *
core_samples(Core *c, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "expected (frame, local_s)");
        return NULL;
    }
    if (c->reader == NULL) {
        PyErr_SetString(PyExc_ValueError, "no Reader set");
        return NULL;
    }
    PyObject *read = tether_reader_read(c->reader, args[0]);
    if (read == NULL)
        return NULL;
    if (!PyTuple_Check(read) || PyTuple_GET_SIZE(read) != 3) {
        Py_DECREF(read);
        PyErr_SetString(PyExc_TypeError, "not a frame the link's take accepted");
        return NULL;
    }
    PyObject *dropped = PyTuple_GET_ITEM(read, 2);
    PyObject *out = NULL;
    if (dropped == Py_None || count(c->counters, dropped))
        out = receive(c, PyTuple_GET_ITEM(read, 0), PyTuple_GET_ITEM(read, 1), args[1]);
    Py_DECREF(read);
    return out;
}

static PyObject *
core_set_reader(Core *c, PyObject *reader)
{
    if (!tether_is_reader(reader)) {
        PyErr_SetString(PyExc_TypeError, "a _frame_core.Reader");
        return NULL;
    }
    Py_XSETREF(c->reader, Py_NewRef(reader));
    Py_RETURN_NONE;
}

static Py_ssize_t
core_len(Core *c)
{
    return c->held;
}

static int
core_init(Core *c, PyObject *args, PyObject *kwds)
{
    PyObject *ingest, *counters, *latest_by_kind, *gate;
    double max_window_s;
    if (!PyArg_ParseTuple(args, "OOO!dO!", &ingest, &counters, &PyDict_Type, &latest_by_kind,
                          &max_window_s, &PyTuple_Type, &gate)
        || !PyArg_ParseTuple(gate, "dddddLL", &c->backstep_s, &c->future_tolerance_s,
                             &c->max_rate, &c->confirm_span_s, &c->fallback_s,
                             &c->confirmations, &c->fallback_samples))
        return -1;
    if (!(0.0 <= max_window_s && max_window_s < INFINITY)) {
        PyErr_Format(PyExc_ValueError, "reorder window must be >= 0 s and finite, got %R",
                     PyTuple_GET_ITEM(args, 3));
        return -1;
    }
    PyObject *by_kind = PyDict_New();
    if (by_kind == NULL)
        return -1;
    Py_XSETREF(c->newest_by_kind, by_kind);
    buffer_clear(c);
    Py_XSETREF(c->ingest, Py_NewRef(ingest));
    Py_XSETREF(c->counters, Py_NewRef(counters));
    Py_XSETREF(c->latest_by_kind, Py_NewRef(latest_by_kind));
    Py_CLEAR(c->reader);
    gate_reset(c);
    c->max_window_s = max_window_s;
    c->window_s = c->largest_lateness_s = c->lateness_s = c->previous_lateness_s = 0.0;
    c->reordered = c->widened = c->narrowed = 0;
    c->newest_s = c->period_end_s = -INFINITY;
    return 0;
}

static int
core_traverse(Core *c, visitproc visit, void *arg)
{
    for (Py_ssize_t i = 0; i < c->held; i++) {
        Py_VISIT(c->heap[i].kind);
        Py_VISIT(c->heap[i].sample);
    }
    Py_VISIT(c->newest_by_kind);
    Py_VISIT(c->latest_by_kind);
    Py_VISIT(c->counters);
    Py_VISIT(c->ingest);
    Py_VISIT(c->reader);
    return 0;
}

static int
core_clear_refs(Core *c)
{
    while (c->held) {
        Held h = c->heap[--c->held];
        Py_DECREF(h.kind);
        Py_DECREF(h.sample);
    }
    Py_CLEAR(c->newest_by_kind);
    Py_CLEAR(c->latest_by_kind);
    Py_CLEAR(c->counters);
    Py_CLEAR(c->ingest);
    Py_CLEAR(c->reader);
    return 0;
}

static void
core_dealloc(Core *c)
{
    PyObject_GC_UnTrack(c);
    core_clear_refs(c);
    PyMem_Free(c->heap);
    Py_TYPE(c)->tp_free((PyObject *)c);
}

/* a getter of a double or long long member at `closure`'s offset */
static PyObject *
get_double(Core *c, void *offset)
{
    return PyFloat_FromDouble(*(double *)((char *)c + (Py_ssize_t)offset));
}

static PyObject *
get_long(Core *c, void *offset)
{
    return PyLong_FromLongLong(*(long long *)((char *)c + (Py_ssize_t)offset));
}

#define DOUBLE(name, doc) {#name, (getter)get_double, NULL, doc, (void *)offsetof(Core, name)}
#define LONG(name, doc) {#name, (getter)get_long, NULL, doc, (void *)offsetof(Core, name)}

static PyGetSetDef core_getset[] = {
    DOUBLE(latest_fc_s, "Newest believed flight-controller stamp [s] (FcTimeGate's)."),
    DOUBLE(backstep_s, "FcTimeGate's backstep threshold [s]."),
    DOUBLE(future_tolerance_s, "FcTimeGate's implausible-stamp threshold [s]."),
    DOUBLE(max_rate, "FcTimeGate's largest clock rate over local time."),
    DOUBLE(confirm_span_s, "FcTimeGate's confirmations' local-time span [s]."),
    DOUBLE(fallback_s, "FcTimeGate's fallback [s of local time]."),
    LONG(confirmations, "FcTimeGate's confirmations."),
    LONG(fallback_samples, "FcTimeGate's fallback without local times [samples]."),
    DOUBLE(max_window_s, "ReorderBuffer's largest window [s]."),
    DOUBLE(window_s, "ReorderBuffer's current window [s]."),
    DOUBLE(largest_lateness_s, "ReorderBuffer's largest lateness seen [s]."),
    LONG(reordered, "ReorderBuffer's samples that arrived older than their stream's newest."),
    LONG(widened, "ReorderBuffer's widenings."),
    LONG(narrowed, "ReorderBuffer's narrowings."),
    {NULL},
};

static PyMethodDef core_methods[] = {
    {"check", (PyCFunction)(void (*)(void))core_check, METH_FASTCALL,
     "FcTimeGate.check(fc_s, local_s) -> verdict"},
    {"on_system_time", (PyCFunction)(void (*)(void))core_on_system_time, METH_FASTCALL,
     "FcTimeGate.on_system_time(fc_s, local_s) -> verdict"},
    {"reset", (PyCFunction)core_reset, METH_NOARGS, "FcTimeGate.reset()"},
    {"push", (PyCFunction)(void (*)(void))core_push, METH_FASTCALL,
     "ReorderBuffer.push(kind, time_s, sample) -> [(kind, sample), ...]"},
    {"clear", (PyCFunction)core_clear, METH_NOARGS, "ReorderBuffer.clear()"},
    {"believed", (PyCFunction)core_believed, METH_O, "Ingest._believed(verdict) -> bool"},
    {"ordered", (PyCFunction)core_ordered, METH_O, "Ingest._ordered(released) -> [sample]"},
    {"receive_input", (PyCFunction)(void (*)(void))core_receive_input, METH_FASTCALL,
     "Ingest.receive_input(kind, sample, local_s) -> [sample]"},
    {"samples", (PyCFunction)(void (*)(void))core_samples, METH_FASTCALL,
     "FrameIngest.samples(frame, local_s) -> [sample] through the Reader set"},
    {"set_reader", (PyCFunction)core_set_reader, METH_O, "The Reader samples() reads with."},
    {NULL, NULL, 0, NULL},
};

static PySequenceMethods core_sequence = {.sq_length = (lenfunc)core_len};

static PyTypeObject CoreType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "tether_companion.service._frame_core.IngestCore",
    .tp_basicsize = sizeof(Core),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "The ingest's clock gate, reorder buffer and order check (see ingest_core.c).",
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)core_init,
    .tp_traverse = (traverseproc)core_traverse,
    .tp_clear = (inquiry)core_clear_refs,
    .tp_dealloc = (destructor)core_dealloc,
    .tp_methods = core_methods,
    .tp_getset = core_getset,
    .tp_as_sequence = &core_sequence,
};

static int
interned(PyObject **where, const char *text)
{
    *where = PyUnicode_InternFromString(text);
    return *where != NULL;
}

int
tether_ingest_core_add(PyObject *m)
{
    one = PyLong_FromLong(1);
    if (one == NULL)
        return 0;
    if (!(interned(&v_accept, "accept") && interned(&v_implausible, "implausible")
          && interned(&v_backstep, "backstep") && interned(&v_reboot, "reboot")
          && interned(&n_messages, "messages") && interned(&n_implausible, "implausible")
          && interned(&n_out_of_order, "out_of_order") && interned(&n_reboots, "reboots")
          && interned(&n_duplicate, "duplicate") && interned(&n_reordered, "reordered")
          && interned(&n_window, "reorder_window_s") && interned(&n_widened, "reorder_widened")
          && interned(&n_accepted, "accepted") && interned(&n_local_s, "_local_s")
          && interned(&n_rebooted, "rebooted") && interned(&n_time_s, "time_s")))
        return 0;
    if (PyType_Ready(&CoreType) < 0)
        return 0;
    return PyModule_AddObjectRef(m, "IngestCore", (PyObject *)&CoreType) == 0;
}
