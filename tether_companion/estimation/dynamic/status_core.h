/* What status_core.c (the published covariance's added terms) and status_decide.c (the
 * status decision) share: reading exact floats, and the decision's entry points. The C twins of
 * the status read's Python functions; build with -ffp-contract=off and -fno-builtin-pow.
 */
#ifndef TETHER_STATUS_CORE_H
#define TETHER_STATUS_CORE_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

static inline int
float_of(PyObject *value, double *out)
{
    if (!PyFloat_CheckExact(value))
        return 0;
    *out = PyFloat_AS_DOUBLE(value);
    return 1;
}

/* The first `count` items of a list or tuple of at least `least` items (exactly `least` when
 * `exact`), all exact floats; 0 otherwise. */
static inline int
floats_of(PyObject *seq, Py_ssize_t least, int exact, Py_ssize_t count, double *out)
{
    PyObject **items;
    Py_ssize_t size;
    if (PyList_CheckExact(seq)) {
        size = PyList_GET_SIZE(seq);
        items = ((PyListObject *)seq)->ob_item;
    }
    else if (PyTuple_CheckExact(seq)) {
        size = PyTuple_GET_SIZE(seq);
        items = ((PyTupleObject *)seq)->ob_item;
    }
    else
        return 0;
    if (size < least || (exact && size != least))
        return 0;
    for (Py_ssize_t i = 0; i < count; i++) {
        if (!float_of(items[i], &out[i]))
            return 0;
    }
    return 1;
}

/* decide(fallback, **keywords): observability.decide in C (status_decide.c) */
PyObject *status_decide(PyObject *self, PyObject *const *args, Py_ssize_t nargs,
                        PyObject *kwnames);
/* Its keywords interned, at the module's import: 0 on an error (raised). */
int status_decide_init(void);

#endif
