/* observability.decide in C, statement for statement (the approximate status read calls it at
 * every IMU tick, by keyword): the same status object, or None, or the same exception.
 *
 * Where C could differ it calls the Python function given as its first argument with the
 * same keywords: a positional argument, a keyword missing, unknown or given twice (Python's
 * TypeError), any value not an exact bool / str / float / tuple of three exact floats where
 * the statements read one, and `(a - c) ** 2` overflowing (Python's OverflowError). `explained`
 * is called exactly where Python calls it. tests/test_status_core.py compares.
 */
#include <math.h>

#include "status_core.h"

/* The statuses (output.OK, ...), read from the Python module at the first call. */
enum { S_OK, S_INITIALISING, S_WEAK_PULL, S_LEARNING, S_SLACK, S_ON_GROUND, S_STALE, S_RESET,
       N_STATUSES };
static const char *STATUS_NAMES[N_STATUSES] = {
    "OK", "INITIALISING", "WEAK_PULL", "LEARNING", "SLACK", "ON_GROUND", "STALE_INPUTS", "RESET",
};
static PyObject *STATUSES[N_STATUSES];

static int
load_statuses(void)
{
    if (STATUSES[0] != NULL)
        return 1;
    PyObject *output = PyImport_ImportModule("tether_companion.estimation.dynamic.output");
    if (output == NULL)
        return 0;
    for (int i = 0; i < N_STATUSES; i++) {
        PyObject *status = PyObject_GetAttrString(output, STATUS_NAMES[i]);
        if (status == NULL) {
            Py_DECREF(output);
            for (int j = 0; j < i; j++)
                Py_CLEAR(STATUSES[j]);
            return 0;
        }
        STATUSES[i] = status;
    }
    Py_DECREF(output);
    return 1;
}

static PyObject *
status(int which)
{
    Py_INCREF(STATUSES[which]);
    return STATUSES[which];
}

/* decide's keyword-only parameters, in its order (all given, or the three with defaults) */
enum { K_INITIALISED, K_RESET, K_ON_GROUND, K_STALE, K_TENSION, K_SLACK, K_HORIZONTAL, K_MAX_STD,
       K_PULL, K_MIN_PULL, K_EXPLAINED, K_MARGIN, K_VARIANCE_TOL, K_RANGE_UNKNOWN, N_KEYWORDS };
static const char *KEYWORD_NAMES[N_KEYWORDS] = {
    "initialised", "reset", "on_ground", "inputs_stale", "tension_n", "slack_tension_n",
    "horizontal_m2", "max_horizontal_std_m", "horizontal_pull_n", "min_horizontal_pull_n",
    "explained", "margin", "variance_tol", "range_unknown",
};
static PyObject *KEYWORDS[N_KEYWORDS];

/* observability._less: 1 (a < b), 0 (not), -1 (None: within the margin, or not a number) */
static int
less(double a, double b, double margin)
{
    if (margin > 0.0 && !(fabs(a - b) > margin * (fabs(a) + fabs(b))))
        return -1;
    return a < b;
}

/* decide(fallback, **keywords) -> the status or None: observability.decide's statements;
 * the fallback's for anything but its keywords with exact bools, a str, exact floats and a
 * tuple of three (or a `** 2` that overflows: OverflowError in Python). */
PyObject *
status_decide(PyObject *self, PyObject *const *args, Py_ssize_t nargs, PyObject *kwnames)
{
    if (nargs != 1) {
        PyErr_SetString(PyExc_TypeError, "decide takes the fallback and keywords only");
        return NULL;
    }
    PyObject *given[N_KEYWORDS] = {NULL};
    Py_ssize_t count = kwnames == NULL ? 0 : PyTuple_GET_SIZE(kwnames);
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *name = PyTuple_GET_ITEM(kwnames, i);
        int k = 0;
        while (k < N_KEYWORDS && KEYWORDS[k] != name)
            k++;
        if (k == N_KEYWORDS) { /* not interned as ours: compared by value */
            for (k = 0; k < N_KEYWORDS; k++) {
                if (PyUnicode_Compare(name, KEYWORDS[k]) == 0)
                    break;
            }
            if (PyErr_Occurred())
                return NULL;
        }
        if (k == N_KEYWORDS || given[k] != NULL)
            goto python;
        given[k] = args[1 + i];
    }
    double margin = 0.0, variance_tol = 0.0, tension, slack, max_std, pull, min_pull, h[3];
    int range_unknown = 0;
    for (int k = 0; k < K_MARGIN; k++) {
        if (given[k] == NULL)
            goto python;
    }
    PyObject *explained = given[K_EXPLAINED], *on_ground = given[K_ON_GROUND];
    if (!PyBool_Check(given[K_INITIALISED]) || !PyBool_Check(given[K_RESET])
        || !PyBool_Check(given[K_STALE]) || !PyUnicode_CheckExact(on_ground)
        || !float_of(given[K_TENSION], &tension) || !float_of(given[K_SLACK], &slack)
        || !float_of(given[K_MAX_STD], &max_std) || !float_of(given[K_PULL], &pull)
        || !float_of(given[K_MIN_PULL], &min_pull)
        || !(PyTuple_CheckExact(given[K_HORIZONTAL])
             && floats_of(given[K_HORIZONTAL], 3, 1, 3, h))
        || (given[K_MARGIN] != NULL && !float_of(given[K_MARGIN], &margin))
        || (given[K_VARIANCE_TOL] != NULL && !float_of(given[K_VARIANCE_TOL], &variance_tol))
        || (given[K_RANGE_UNKNOWN] != NULL && !PyBool_Check(given[K_RANGE_UNKNOWN])))
        goto python;
    if (!load_statuses())
        return NULL;
    range_unknown = given[K_RANGE_UNKNOWN] == Py_True;
    if (given[K_RESET] == Py_True)
        return status(S_RESET);
    if (given[K_INITIALISED] != Py_True)
        return status(S_INITIALISING);
    if (PyUnicode_GET_LENGTH(on_ground) > 0)
        return status(S_ON_GROUND);
    if (given[K_STALE] == Py_True)
        return status(S_STALE);
    int slack_now = less(tension, slack, margin);
    if (slack_now != 0) {
        if (slack_now < 0)
            Py_RETURN_NONE;
        return status(S_SLACK);
    }
    if (range_unknown)
        return status(S_WEAK_PULL);
    int weak = less(pull, min_pull, margin);
    if (weak != 0) {
        if (weak < 0)
            Py_RETURN_NONE;
        return status(S_WEAK_PULL);
    }
    /* _largest_std_values(a, b, c) */
    double a_c = h[0] - h[2];
    double square = pow(a_c, 2.0);
    if (isfinite(a_c) && isinf(square))
        goto python; /* OverflowError in Python */
    double largest = 0.5 * (h[0] + h[2]) + sqrt(0.25 * square + h[1] * h[1]);
    double std = sqrt(0.0 > largest ? 0.0 : largest);
    if (margin > 0.0 || variance_tol > 0.0) {
        double bound_sq = max_std * max_std;
        if (!(fabs(std * std - bound_sq) > 4.0 * variance_tol + margin * (std * std + bound_sq)))
            Py_RETURN_NONE;
    }
    if (std <= max_std)
        return status(S_OK);
    if (explained == Py_None)
        return status(S_WEAK_PULL);
    PyObject *learning = PyObject_CallNoArgs(explained);
    if (learning == NULL)
        return NULL;
    if (learning == Py_None) {
        Py_DECREF(learning);
        Py_RETURN_NONE;
    }
    int truth = PyObject_IsTrue(learning);
    Py_DECREF(learning);
    if (truth < 0)
        return NULL;
    return status(truth ? S_LEARNING : S_WEAK_PULL);
python:
    return PyObject_Vectorcall(args[0], args + 1, 0, kwnames);
}

int
status_decide_init(void)
{
    for (int k = 0; k < N_KEYWORDS; k++) {
        KEYWORDS[k] = PyUnicode_InternFromString(KEYWORD_NAMES[k]);
        if (KEYWORDS[k] == NULL)
            return 0;
    }
    return 1;
}
