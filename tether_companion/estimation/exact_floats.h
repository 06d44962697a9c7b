/* Reading a Python list or tuple of exact floats into doubles, for the optional C extensions
 * whose Python reference runs wherever the arguments are anything else (tension_core.c,
 * dynamic/member_core.c): a subclass of float, an int or a wrong count is the fallback's,
 * never converted here.
 */
#ifndef TETHER_EXACT_FLOATS_H
#define TETHER_EXACT_FLOATS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>

/* Read `count` exact floats from a list or tuple into `out`; 0 when it is anything else. */
static inline int
read_exact_floats(PyObject *seq, Py_ssize_t count, double *out)
{
    PyObject **items;
    if (PyList_CheckExact(seq)) {
        if (PyList_GET_SIZE(seq) != count)
            return 0;
        items = ((PyListObject *)seq)->ob_item;
    }
    else if (PyTuple_CheckExact(seq)) {
        if (PyTuple_GET_SIZE(seq) != count)
            return 0;
        items = ((PyTupleObject *)seq)->ob_item;
    }
    else
        return 0;
    for (Py_ssize_t i = 0; i < count; i++) {
        if (!PyFloat_CheckExact(items[i]))
            return 0;
        out[i] = PyFloat_AS_DOUBLE(items[i]);
    }
    return 1;
}

#endif
