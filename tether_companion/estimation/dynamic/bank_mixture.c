/* The members' mixture (part of _member_core): its moments (the extension's `mixture`, called
 * by bank.py with the members' arrays) and the bank's whole mixture in one C call.
 *
 * bank_mixture is FilterBank.mixture's path over two or more members where _member_core runs
 * (bank.py: the Python is the reference and the fallback), bit for bit: the cache's test (the
 * same log weights, by list equality, and every member holding the same two arrays, by
 * identity), else the members' arrays in order (kf.x, kf.P: a member holding lists is
 * converted by its properties, as the Python's are), the normalised weights as
 * FilterBank._weight_list computes them (max, libm's exp as math.exp, CPython 3.11's float
 * sum: one double added in order, then each divided by it) and the moments (as `mixture`) into
 * new arrays made by `empty`; the new cache (arrays, log weights copied, (mean,
 * cov)).
 *
 * It returns None, having changed nothing but the conversions the Python makes too, where the
 * Python must run: fewer than two members, a log weight not an exact finite float, a state or
 * covariance not a finite C-contiguous float64 array of the first state's size, more than
 * MAX_MEMBERS members, and on CPython 3.12 or later (whose sum() of floats is compensated).
 */
#include "member_core.h"

/* The weighted mixture's mean sum w_i x_i into mean and covariance sum w_i P_i + sum w_i s_i
 * s_i^T (s_i = x_i - mean; the P_i symmetric) on the upper triangle, mirrored, into cov, for
 * `members` states xs[i] (n) and covariances ps[i] (n x n): member_mixture_moments()'s
 * arithmetic (below) and bank_mixture()'s. */
static void
member_mixture(const double *w, const double *const *xs, const double *const *ps,
               Py_ssize_t members, int n, double *mean, double *cov)
{
    for (int j = 0; j < n; j++) {
        double value = 0.0;
        for (Py_ssize_t i = 0; i < members; i++)
            value += w[i] * xs[i][j];
        mean[j] = value;
    }
    for (int j = 0; j < n; j++)
        for (int k = j; k < n; k++) {
            double within = 0.0, between = 0.0;
            for (Py_ssize_t i = 0; i < members; i++) {
                const double *x = xs[i];
                within += w[i] * ps[i][j * n + k];
                between += (x[j] - mean[j]) * w[i] * (x[k] - mean[k]);
            }
            cov[j * n + k] = cov[k * n + j] = within + between;
        }
}

/* mixture(w, xs, ps, mean_out, cov_out) -> True: the weighted mixture's mean sum w_i x_i and
 * covariance sum w_i P_i + sum w_i s_i s_i^T (s_i = x_i - mean; the P_i symmetric) on the upper
 * triangle, mirrored: exactly symmetric (bank.FilterBank.mixture, whose (C + C^T) / 2 of the
 * full C differs by rounding; w a list of floats, xs and ps lists of the members' (n,) and
 * (n, n) arrays); None: not taken. */
PyObject *
member_mixture_moments(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5)
        return PyErr_Format(PyExc_TypeError, "mixture takes 5 arguments");
    PyObject *wl = args[0], *xl = args[1], *pl = args[2];
    if (!PyList_CheckExact(wl) || !PyList_CheckExact(xl) || !PyList_CheckExact(pl))
        Py_RETURN_NONE;
    Py_ssize_t members = PyList_GET_SIZE(wl);
    if (members < 1 || members > MAX_MEMBERS || PyList_GET_SIZE(xl) != members ||
        PyList_GET_SIZE(pl) != members)
        Py_RETURN_NONE;
    double w[MAX_MEMBERS];
    if (!read_numbers(wl, w, members) || !all_finite(w, members))
        Py_RETURN_NONE;
    Py_buffer vx[MAX_MEMBERS], vp[MAX_MEMBERS], vmean, vcov;
    Py_ssize_t got = 0;
    int n = 0, ok = 0;
    for (; got < members; got++) {
        if (!get(PyList_GET_ITEM(xl, got), &vx[got], 1, got ? n : ANY, 0, 0))
            break;
        if (got == 0)
            n = (int)vx[0].shape[0];
        if (n > MAX_N || !get(PyList_GET_ITEM(pl, got), &vp[got], 2, n, n, 0)) {
            PyBuffer_Release(&vx[got]);
            break;
        }
        if (!all_finite(vx[got].buf, n) || !all_finite(vp[got].buf, (Py_ssize_t)n * n)) {
            PyBuffer_Release(&vx[got]);
            PyBuffer_Release(&vp[got]);
            break;
        }
    }
    if (got == members && get(args[3], &vmean, 1, n, 0, 1)) {
        if (get(args[4], &vcov, 2, n, n, 1)) {
            const double *xs[MAX_MEMBERS], *ps[MAX_MEMBERS];
            for (Py_ssize_t i = 0; i < members; i++) {
                xs[i] = vx[i].buf;
                ps[i] = vp[i].buf;
            }
            member_mixture(w, xs, ps, members, n, vmean.buf, vcov.buf);
            ok = 1;
            PyBuffer_Release(&vcov);
        }
        PyBuffer_Release(&vmean);
    }
    for (Py_ssize_t i = 0; i < got; i++) {
        PyBuffer_Release(&vx[i]);
        PyBuffer_Release(&vp[i]);
    }
    if (ok)
        Py_RETURN_TRUE;
    Py_RETURN_NONE;
}

/* 1 when cache = (arrays, log weights, moments) holds `filters`' arrays and `log_weight`, 0 when
 * not, -1 with an error set (as the Python's comparisons and attribute reads raise). */
static int
cache_holds(PyObject *filters, PyObject *log_weight, PyObject *cache)
{
    if (!PyTuple_CheckExact(cache) || PyTuple_GET_SIZE(cache) != 3) {
        PyErr_SetString(PyExc_TypeError, "the mixture's cache is not a 3-tuple");
        return -1;
    }
    PyObject *arrays = PyTuple_GET_ITEM(cache, 0);
    int same = PyObject_RichCompareBool(PyTuple_GET_ITEM(cache, 1), log_weight, Py_EQ);
    if (same <= 0)
        return same;
    Py_ssize_t count = PyList_GET_SIZE(filters);
    if (!PyList_CheckExact(arrays) || PyList_GET_SIZE(arrays) != 2 * count)
        return 0;
    for (int which = 0; which < 2; which++) /* every _xa, then every _pa, as the Python reads */
        for (Py_ssize_t i = 0; i < count; i++) {
            PyObject *held = PyObject_GetAttr(PyList_GET_ITEM(filters, i), which ? name_pa : name_xa);
            if (held == NULL)
                return -1;
            Py_DECREF(held); /* the member holds it: only its identity is compared */
            if (held != PyList_GET_ITEM(arrays, 2 * i + which))
                return 0;
        }
    return 1;
}

/* FilterBank._weight_list of the finite log weights ll (count >= 1) into w. */
static void
weights(const double *ll, Py_ssize_t count, double *w)
{
    double top = ll[0];
    for (Py_ssize_t i = 1; i < count; i++) /* max(): the first of the largest */
        if (ll[i] > top)
            top = ll[i];
    double total = 0.0; /* sum(): int 0 + the first float is that float, then in order */
    for (Py_ssize_t i = 0; i < count; i++) {
        w[i] = exp(ll[i] - top);
        total = i ? total + w[i] : w[i];
    }
    for (Py_ssize_t i = 0; i < count; i++)
        w[i] = w[i] / total;
}

/* The members' arrays (x, P, x, P, ...) as the Python's list comprehension reads them; NULL
 * with no error set where one is missing. */
static PyObject *
member_arrays(PyObject *filters)
{
    Py_ssize_t count = PyList_GET_SIZE(filters);
    PyObject *arrays = PyList_New(2 * count);
    if (arrays == NULL) {
        PyErr_Clear();
        return NULL;
    }
    for (Py_ssize_t i = 0; i < 2 * count; i++) {
        PyObject *kf = PyList_GET_ITEM(filters, i / 2);
        PyObject *array = i % 2 ? held_array(kf, name_pa, name_p) : held_array(kf, name_xa, name_x);
        if (array == NULL) {
            Py_DECREF(arrays);
            return NULL;
        }
        PyList_SET_ITEM(arrays, i, array);
    }
    return arrays;
}

/* The moments of `arrays` with the weights w into new arrays; the (mean, cov) tuple, None (a
 * new reference) where not taken, NULL with an error set. */
static PyObject *
moments(PyObject *arrays, const double *w, Py_ssize_t count, PyObject *empty)
{
    Py_buffer vx[MAX_MEMBERS], vp[MAX_MEMBERS], vmean, vcov;
    const double *xs[MAX_MEMBERS], *ps[MAX_MEMBERS];
    PyObject *mean = NULL, *cov = NULL, *out = NULL;
    Py_ssize_t got = 0;
    int n = 0, ok = 1;
    for (; got < count && ok; got++) {
        ok = get(PyList_GET_ITEM(arrays, 2 * got), &vx[got], 1, got ? n : ANY, 0, 0);
        if (!ok)
            break;
        if (got == 0)
            n = (int)vx[0].shape[0];
        ok = n <= MAX_N && get(PyList_GET_ITEM(arrays, 2 * got + 1), &vp[got], 2, n, n, 0);
        if (!ok) {
            PyBuffer_Release(&vx[got]);
            break;
        }
        xs[got] = vx[got].buf;
        ps[got] = vp[got].buf;
        ok = all_finite(xs[got], n) && all_finite(ps[got], (Py_ssize_t)n * n);
    }
    if (!ok) {
        out = Py_NewRef(Py_None);
        goto done;
    }
    PyObject *shape_x = Py_BuildValue("(n)", (Py_ssize_t)n);
    PyObject *shape_p = Py_BuildValue("(nn)", (Py_ssize_t)n, (Py_ssize_t)n);
    if (shape_x && shape_p && (mean = PyObject_CallOneArg(empty, shape_x)) &&
        (cov = PyObject_CallOneArg(empty, shape_p))) {
        if (get(mean, &vmean, 1, n, 0, 1)) {
            if (get(cov, &vcov, 2, n, n, 1)) {
                member_mixture(w, xs, ps, count, n, vmean.buf, vcov.buf);
                out = PyTuple_Pack(2, mean, cov);
                PyBuffer_Release(&vcov);
            }
            PyBuffer_Release(&vmean);
        }
        if (out == NULL && !PyErr_Occurred())
            out = Py_NewRef(Py_None);
    }
    Py_XDECREF(shape_x);
    Py_XDECREF(shape_p);
    Py_XDECREF(mean);
    Py_XDECREF(cov);
done:
    for (Py_ssize_t i = 0; i < got; i++) {
        PyBuffer_Release(&vx[i]);
        PyBuffer_Release(&vp[i]);
    }
    return out;
}

/* bank_mixture(filters, log_weight, cache, empty) -> cache: FilterBank.mixture over the list
 * `filters` (two or more members) with the list `log_weight` and the bank's cache (arrays, log
 * weights, (mean, cov)): the same cache object when it holds them, else a new one; None: not
 * taken (see the top). */
PyObject *
bank_mixture(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4)
        return PyErr_Format(PyExc_TypeError, "bank_mixture takes 4 arguments");
#if PY_VERSION_HEX >= 0x030C0000
    Py_RETURN_NONE;
#endif
    PyObject *filters = args[0], *log_weight = args[1], *cache = args[2];
    if (!PyList_CheckExact(filters) || !PyList_CheckExact(log_weight))
        Py_RETURN_NONE;
    Py_ssize_t count = PyList_GET_SIZE(filters);
    if (count < 2 || count > MAX_MEMBERS || PyList_GET_SIZE(log_weight) != count)
        Py_RETURN_NONE;
    int holds = cache_holds(filters, log_weight, cache);
    if (holds < 0)
        return NULL;
    if (holds)
        return Py_NewRef(cache);
    double ll[MAX_MEMBERS], w[MAX_MEMBERS];
    if (!read_exact_floats(log_weight, count, ll) || !all_finite(ll, count))
        Py_RETURN_NONE;
    PyObject *arrays = member_arrays(filters);
    if (arrays == NULL)
        Py_RETURN_NONE;
    weights(ll, count, w);
    PyObject *result = NULL, *mixture = moments(arrays, w, count, args[3]);
    if (mixture != NULL && mixture != Py_None) {
        PyObject *ll_copy = PyList_GetSlice(log_weight, 0, count);
        if (ll_copy != NULL)
            result = PyTuple_Pack(3, arrays, ll_copy, mixture);
        Py_XDECREF(ll_copy);
    }
    else if (mixture == Py_None)
        result = Py_NewRef(Py_None);
    Py_XDECREF(mixture);
    Py_DECREF(arrays);
    return result;
}
