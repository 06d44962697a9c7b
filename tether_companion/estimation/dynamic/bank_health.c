/* Which bank members are healthy, in one C call (part of _member_core).
 *
 * bank_healthy_members is FilterBank.drop_unhealthy's test over its members where _member_core
 * runs (bank.py: the Python loop is the reference and the fallback), bit for bit: each
 * member's state values (its list, else its array's, as MemberFilter.x_values reads them), the
 * squared horizontal-and-vertical distance x0 x0 + x1 x1 + x2 x2 against the limit, and the
 * finiteness of CPython 3.11's sum() of the values (one double, int 0 then each float added in
 * order: whether it is finite depends on that order only through overflow, kept here).
 *
 * It returns None, having read nothing but attributes, where the Python must run: a member
 * holding neither a list of exact floats nor a C-contiguous float64 array of 3 to MAX_N states,
 * a limit not an exact float, more than MAX_MEMBERS members, and on CPython 3.12 or later
 * (whose sum() of floats is compensated).
 */
#include "member_core.h"


/* Member kf's n state values into x (n <= MAX_N); 0 (no error set) where the Python must read
 * them, -1 with an error set. */
static int
state_values(PyObject *kf, double *x, int *n)
{
    PyObject *held = PyObject_GetAttr(kf, name_xl);
    if (held == NULL)
        return -1;
    int ok = 0;
    if (held != Py_None) {
        Py_ssize_t size = PyList_CheckExact(held) ? PyList_GET_SIZE(held) : -1;
        ok = size >= 3 && size <= MAX_N && read_exact_floats(held, size, x);
        *n = (int)size;
        Py_DECREF(held);
        return ok;
    }
    Py_DECREF(held);
    if (!(held = PyObject_GetAttr(kf, name_xa)))
        return -1;
    Py_buffer view;
    if (get(held, &view, 1, ANY, 0, 0)) {
        ok = view.shape[0] >= 3 && view.shape[0] <= MAX_N;
        if (ok) {
            *n = (int)view.shape[0];
            memcpy(x, view.buf, sizeof(double) * (size_t)*n);
        }
        PyBuffer_Release(&view);
    }
    Py_DECREF(held);
    return ok;
}

/* bank_healthy_members(filters, limit) -> list: the indices of the members of the list
 * `filters` whose state sums to a finite value and whose position is within sqrt(limit) [m]
 * of the anchor (limit [m^2]); None: not taken (see the top). */
PyObject *
bank_healthy_members(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2)
        return PyErr_Format(PyExc_TypeError, "bank_healthy_members takes 2 arguments");
#if PY_VERSION_HEX >= 0x030C0000
    Py_RETURN_NONE;
#endif
    PyObject *filters = args[0];
    if (!PyList_CheckExact(filters) || PyList_GET_SIZE(filters) > MAX_MEMBERS ||
        !PyFloat_CheckExact(args[1]))
        Py_RETURN_NONE;
    const double limit = PyFloat_AS_DOUBLE(args[1]);
    Py_ssize_t count = PyList_GET_SIZE(filters), kept = 0;
    long keep[MAX_MEMBERS];
    for (Py_ssize_t i = 0; i < count; i++) {
        double x[MAX_N];
        int n = 0, got = state_values(PyList_GET_ITEM(filters, i), x, &n);
        if (got < 0)
            return NULL;
        if (!got)
            Py_RETURN_NONE;
        const double distance_sq = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
        double sum = x[0];
        for (int k = 1; k < n; k++)
            sum += x[k];
        if (isfinite(sum) && distance_sq <= limit)
            keep[kept++] = (long)i;
    }
    PyObject *out = PyList_New(kept);
    for (Py_ssize_t i = 0; out != NULL && i < kept; i++) {
        PyObject *index = PyLong_FromLong(keep[i]);
        if (index == NULL)
            Py_CLEAR(out);
        else
            PyList_SET_ITEM(out, i, index);
    }
    return out;
}
