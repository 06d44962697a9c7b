/* The ingest's time line in C: the flight controller's clock gate, the reorder buffer and the
 * per-kind order check as ONE object (part of the _frame_core extension). This file is the
 * object, the ingest's counts and order and its Python type; the gate's steps are
 * ingest_clock.c's, the buffer's ingest_reorder.c's (ingest_core.h: the state they share).
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
 * name, as the Python counts them; the buffer's reordered / reorder_window_s /
 * reorder_widened, which the reference writes at every order check, only when they differ
 * from what it last wrote: nothing else writes them), its per-kind newest stamps dict (shared
 * with the Python methods), the buffer's largest window [s] and the gate's parameters (backstep_s,
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
#include "ingest_core.h"

static PyObject *one;
PyObject *v_accept, *v_implausible, *v_backstep, *v_reboot;
static PyObject *n_messages, *n_implausible, *n_out_of_order, *n_reboots, *n_duplicate,
    *n_reordered, *n_window, *n_widened, *n_accepted, *n_local_s, *n_rebooted, *n_time_s;

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
        ingest_buffer_clear(c);
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
    int failed;
    /* the buffer's counts into the counters, as the reference writes them every time: only
     * when they differ from what was last written (the same values; only this writes them) */
    if (!c->mirrored || c->mirror_reordered != c->reordered || c->mirror_widened != c->widened
        || memcmp(&c->mirror_window_s, &c->window_s, sizeof(double)) != 0) {
        PyObject *window = PyFloat_FromDouble(c->window_s);
        if (window == NULL)
            return -1;
        failed = !set_long(counters, n_reordered, c->reordered)
                 || PyObject_SetAttr(counters, n_window, window) < 0
                 || !set_long(counters, n_widened, c->widened);
        Py_DECREF(window);
        if (failed)
            return -1;
        c->mirrored = 1;
        c->mirror_reordered = c->reordered;
        c->mirror_widened = c->widened;
        c->mirror_window_s = c->window_s;
    }
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
    PyObject *verdict = ingest_gate_check(c, time_s, has_local, local_s);
    if (verdict != v_accept) {
        int goes_on = believed(c, verdict);
        if (goes_on < 0)
            return NULL;
        if (!goes_on)
            return PyList_New(0);
    }
    return ordered(c, ingest_buffer_push(c, kind, time_s, sample));
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
    return Py_NewRef(ingest_gate_check(c, fc_s, has, local_s));
}

static PyObject *
core_on_system_time(Core *c, PyObject *const *args, Py_ssize_t nargs)
{
    double fc_s, local_s;
    int has;
    if (!two_times(args, nargs, &fc_s, &has, &local_s))
        return NULL;
    return Py_NewRef(ingest_gate_on_system_time(c, fc_s, has, local_s));
}

static PyObject *
core_reset(Core *c, PyObject *unused)
{
    ingest_gate_reset(c);
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
    return ingest_buffer_push(c, args[0], time_s, args[2]);
}

static PyObject *
core_clear(Core *c, PyObject *unused)
{
    ingest_buffer_clear(c);
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
    ingest_buffer_clear(c);
    Py_XSETREF(c->ingest, Py_NewRef(ingest));
    Py_XSETREF(c->counters, Py_NewRef(counters));
    c->mirrored = 0;
    Py_XSETREF(c->latest_by_kind, Py_NewRef(latest_by_kind));
    Py_CLEAR(c->reader);
    ingest_gate_reset(c);
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
