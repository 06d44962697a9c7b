/* published_bound.stepped_terms and approximation_tail, and
 * observability.unmodelled_position_rows in C, float for float (all run at every IMU tick's
 * status read), and mixture.sd_bounds (once a mixture).
 *
 * The published estimate's approximation steps the mixture's state over the batch and bounds
 * its position block (published_bound.py): every statement of stepped_terms and
 * approximation_tail here, the same IEEE double operations in the same order (Python's
 * left-to-right sums, `max` written out as comparisons that keep the first value unless a
 * later one is greater, NaN included), built with -ffp-contract=off (no fused multiply-add)
 * and -fno-builtin-pow (libm's pow, as CPython's `**`), so the results are the same floats.
 *
 * Where C could differ it calls the Python function given as its first argument and returns
 * what it returns (or raises what it raises): any argument that is not an exact float, or a
 * list/tuple of the length and exact floats the statements read, and any non-finite result
 * (NaN bits), and a `** 2` that overflows (OverflowError in Python). Python's float +, -, *,
 * abs and comparisons never raise, so there is no other case. tests/test_bound_core.py
 * compares.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "straight_rows.h"

/* The items of a list or tuple and its length (NULL: neither). */
static PyObject **
items_of(PyObject *seq, Py_ssize_t *size)
{
    if (PyList_CheckExact(seq)) {
        *size = PyList_GET_SIZE(seq);
        return ((PyListObject *)seq)->ob_item;
    }
    if (PyTuple_CheckExact(seq)) {
        *size = PyTuple_GET_SIZE(seq);
        return ((PyTupleObject *)seq)->ob_item;
    }
    return NULL;
}

/* Items first..first+count-1 of a list/tuple of at least `least` (exactly, with `exact`)
 * items, all exact floats, into out; 0 otherwise. */
static int
floats_at(PyObject *seq, Py_ssize_t least, int exact, Py_ssize_t first, Py_ssize_t count,
          double *out)
{
    Py_ssize_t size;
    PyObject **items = items_of(seq, &size);
    if (items == NULL || size < least || (exact && size != least))
        return 0;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *item = items[first + i];
        if (!PyFloat_CheckExact(item))
            return 0;
        out[i] = PyFloat_AS_DOUBLE(item);
    }
    return 1;
}

static int
float_of(PyObject *value, double *out)
{
    if (!PyFloat_CheckExact(value))
        return 0;
    *out = PyFloat_AS_DOUBLE(value);
    return 1;
}

/* stepped_terms(fallback, x, t, d_p, d_v, b, b_v, sd, position_sd, velocity_sd, q, linear,
 * quadratic, block) -> (x, north, north_east, east, down, spread, moved, row_sum, offset) */
static PyObject *
stepped_terms(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 14) {
        PyErr_SetString(PyExc_TypeError, "stepped_terms takes the fallback and 13 arguments");
        return NULL;
    }
    double xs[11], t, d_p[3], d_v[3], b[9], b_v[9], sd[3], position_sd, velocity_sd, q[3];
    double linear[4], quadratic[4], block[4];
    Py_ssize_t n_x;
    PyObject **x_items = items_of(args[1], &n_x);
    if (x_items == NULL || !floats_at(args[1], 11, 0, 0, 11, xs) || !float_of(args[2], &t)
        || !floats_at(args[3], 3, 1, 0, 3, d_p) || !floats_at(args[4], 3, 1, 0, 3, d_v)
        || !floats_at(args[5], 9, 1, 0, 9, b) || !floats_at(args[6], 9, 1, 0, 9, b_v)
        || !floats_at(args[7], 11, 0, 8, 3, sd) || !float_of(args[8], &position_sd)
        || !float_of(args[9], &velocity_sd) || !floats_at(args[10], 3, 0, 0, 3, q)
        || !floats_at(args[11], 4, 1, 0, 4, linear) || !floats_at(args[12], 4, 1, 0, 4, quadratic)
        || !floats_at(args[13], 4, 1, 0, 4, block))
        return PyObject_Vectorcall(args[0], args + 1, 13, NULL);

    double b0 = xs[8], b1 = xs[9], b2 = xs[10];
    double v0 = xs[3], v1 = xs[4], v2 = xs[5];
    double nx[6];
    nx[0] = xs[0] + t * v0 + d_p[0] + (b[0] * b0 + b[1] * b1 + b[2] * b2);
    nx[1] = xs[1] + t * v1 + d_p[1] + (b[3] * b0 + b[4] * b1 + b[5] * b2);
    nx[2] = xs[2] + t * v2 + d_p[2] + (b[6] * b0 + b[7] * b1 + b[8] * b2);
    nx[3] = v0 + d_v[0] + (b_v[0] * b0 + b_v[1] * b1 + b_v[2] * b2);
    nx[4] = v1 + d_v[1] + (b_v[3] * b0 + b_v[4] * b1 + b_v[5] * b2);
    nx[5] = v2 + d_v[2] + (b_v[6] * b0 + b_v[7] * b1 + b_v[8] * b2);
    double a[9], av[9], o[6];
    for (int i = 0; i < 9; i++) {
        a[i] = fabs(b[i]);
        av[i] = fabs(b_v[i]);
    }
    double s8 = sd[0], s9 = sd[1], s10 = sd[2];
    double f0 = a[0] * s8 + a[1] * s9 + a[2] * s10;
    double f1 = a[3] * s8 + a[4] * s9 + a[5] * s10;
    double f2 = a[6] * s8 + a[7] * s9 + a[8] * s10;
    double spread = f1 > f0 ? f1 : f0;
    double f = f2 > spread ? f2 : spread;
    double moved = f * (2.0 * (position_sd + t * velocity_sd) + f);
    double row_sum = 1.0 + t + (a[0] + a[1] + a[2] + a[3] + a[4] + a[5] + a[6] + a[7] + a[8]);
    row_sum += av[0] + av[1] + av[2] + av[3] + av[4] + av[5] + av[6] + av[7] + av[8];
    for (int i = 0; i < 3; i++) {
        o[i] = fabs(d_p[i]);
        o[3 + i] = fabs(d_v[i]);
    }
    double offset = o[1] > o[0] ? o[1] : o[0];
    for (int i = 2; i < 6; i++)
        offset = o[i] > offset ? o[i] : offset;
    double north = block[0] + (t * (linear[0] + t * quadratic[0]) + t * q[0]);
    double north_east = block[1] + t * (linear[1] + t * quadratic[1]);
    double east = block[2] + (t * (linear[2] + t * quadratic[2]) + t * q[1]);
    double down = block[3] + (t * (linear[3] + t * quadratic[3]) + t * q[2]);
    /* A NaN's sign and payload are the operand order's, which the compiler may swap in a
     * commutative product: a non-finite result is left to Python (finite results come from
     * finite operands only, and IEEE fixes those bits). */
    if (!isfinite(nx[0] + nx[1] + nx[2] + nx[3] + nx[4] + nx[5] + north + north_east + east
                  + down + spread + moved + row_sum + offset))
        return PyObject_Vectorcall(args[0], args + 1, 13, NULL);

    PyObject *x = PyList_New(n_x); /* list(x) with its first six replaced */
    if (x == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < n_x; i++) {
        PyObject *item;
        if (i < 6) {
            item = PyFloat_FromDouble(nx[i]);
            if (item == NULL) {
                Py_DECREF(x);
                return NULL;
            }
        }
        else {
            item = x_items[i];
            Py_INCREF(item);
        }
        PyList_SET_ITEM(x, i, item);
    }
    return Py_BuildValue("(Ndddddddd)", x, north, north_east, east, down, spread, moved,
                         row_sum, offset);
}

/* unmodelled_rows(fallback, n, e, d, tension_n, force_std_n, length_std_m) -> 3 lists of 3
 * floats: observability.unmodelled_position_rows's statements, in its order
 * (straight_rows.h). */
static PyObject *
unmodelled_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "unmodelled_rows takes the fallback and 6 arguments");
        return NULL;
    }
    double n, e, d, tension_n, force_std_n, length_std_m;
    if (!float_of(args[1], &n) || !float_of(args[2], &e) || !float_of(args[3], &d)
        || !float_of(args[4], &tension_n) || !float_of(args[5], &force_std_n)
        || !float_of(args[6], &length_std_m))
        return PyObject_Vectorcall(args[0], args + 1, 6, NULL);
    double r[9];
    straight_rows(n, e, d, tension_n, force_std_n, length_std_m, r);
    /* a NaN's bits are the operand order's (see stepped_terms): left to Python */
    if (!isfinite(r[0] + r[1] + r[2] + r[3] + r[4] + r[5] + r[6] + r[7] + r[8]))
        return PyObject_Vectorcall(args[0], args + 1, 6, NULL);
    return Py_BuildValue("[[ddd][ddd][ddd]]", r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7],
                         r[8]);
}

#define MAX_STATES 64

/* sd_bounds(fallback, diagonal, x_values) -> (sd, largest_sd, position_sd, velocity_sd,
 * largest_value): mixture.sd_bounds, statement for statement (builtin max/min: the first
 * value kept unless a later one is greater/smaller), for a finite state and a finite,
 * non-negative diagonal (anything else, NaN's place in max() included, is Python's). */
static PyObject *
sd_bounds(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "sd_bounds takes the fallback and 2 arguments");
        return NULL;
    }
    double diagonal[MAX_STATES], x[MAX_STATES];
    Py_ssize_t n, m;
    int usable = items_of(args[1], &n) != NULL && items_of(args[2], &m) != NULL && n >= 6
                 && n <= MAX_STATES && m >= 1 && m <= MAX_STATES
                 && floats_at(args[1], n, 1, 0, n, diagonal) && floats_at(args[2], m, 1, 0, m, x);
    for (Py_ssize_t i = 0; usable && i < n; i++)
        usable = diagonal[i] >= 0.0 && isfinite(diagonal[i]);
    for (Py_ssize_t i = 0; usable && i < m; i++)
        usable = isfinite(x[i]);
    if (!usable)
        return PyObject_Vectorcall(args[0], args + 1, 2, NULL);
    PyObject *sd = PyList_New(n);
    if (sd == NULL)
        return NULL;
    double largest = 0.0, position = 0.0, velocity = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) {
        double v = sqrt(diagonal[i]);
        PyObject *item = PyFloat_FromDouble(v);
        if (item == NULL) {
            Py_DECREF(sd);
            return NULL;
        }
        PyList_SET_ITEM(sd, i, item);
        largest = (i == 0 || v > largest) ? v : largest;
        if (i < 3)
            position = (i == 0 || v > position) ? v : position;
        else if (i < 6)
            velocity = (i == 3 || v > velocity) ? v : velocity;
    }
    double most = x[0], least = x[0];
    for (Py_ssize_t i = 1; i < m; i++) {
        most = x[i] > most ? x[i] : most;
        least = x[i] < least ? x[i] : least;
    }
    double negated = -least;
    double largest_value = negated > most ? negated : most;
    return Py_BuildValue("(Ndddd)", sd, largest, position, velocity, largest_value);
}

#define TAIL_ARGS 16
#define EXACT_INT 4294967296LL /* 2 ** 32: a sum of such ints is exact in a double */

/* sum(map(abs, jac))'s next step: `*sum += abs(item)` for an exact float or an exact int of
 * magnitude below EXACT_INT (the model's Jacobian has int zeros); 0 for anything else.
 * CPython 3.11's sum adds ints exactly and floats left to right in a double, starting from
 * int 0: for ints this small, the same as adding each as a double from 0.0. */
static int
add_abs(PyObject *item, double *sum)
{
    if (PyFloat_CheckExact(item)) {
        *sum += fabs(PyFloat_AS_DOUBLE(item));
        return 1;
    }
    if (!PyLong_CheckExact(item))
        return 0;
    int overflow;
    long long value = PyLong_AsLongLongAndOverflow(item, &overflow);
    if (overflow || value <= -EXACT_INT || value >= EXACT_INT)
        return 0;
    *sum += (double)(value < 0 ? -value : value);
    return 1;
}

/* approximation_tail(fallback, Approximation, rounding, finite_bound, x, t, north, north_east,
 * east, down, spread, moved, row_sum, offset, largest_sd, largest_value, noise_largest,
 * tension, jac, added_terms) -> (Approximation(...), spread, largest):
 * published_bound.approximation_tail's statements in its order, with its module's
 * Approximation, ROUNDING and FINITE_BOUND bound in front. x, t and tension are passed on as
 * the same objects. Python's: any float argument that is not an exact float, jac neither None
 * nor a list/tuple of exact floats and small exact ints (add_abs), added_terms not a
 * list/tuple of 6 exact floats, the `** 2` overflowing (OverflowError), any non-finite float
 * of the result (a NaN's bits). */
static PyObject *
approximation_tail(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4 + TAIL_ARGS) {
        PyErr_SetString(PyExc_TypeError,
                        "approximation_tail takes the fallback, Approximation, rounding, "
                        "finite_bound and 16 arguments");
        return NULL;
    }
    PyObject *const *a = args + 4;
    double rounding, finite_bound, t, north, north_east, east, down, spread, moved, row_sum;
    double offset, largest_sd, largest_value, noise_largest, tension, added[6];
    double jac_sum = 0.0;
    int with_jac = a[14] != Py_None;
    Py_ssize_t n_jac = 0;
    PyObject **jac = with_jac ? items_of(a[14], &n_jac) : NULL;
    int usable = float_of(args[2], &rounding) && float_of(args[3], &finite_bound)
                 && float_of(a[1], &t) && float_of(a[2], &north) && float_of(a[3], &north_east)
                 && float_of(a[4], &east) && float_of(a[5], &down) && float_of(a[6], &spread)
                 && float_of(a[7], &moved) && float_of(a[8], &row_sum)
                 && float_of(a[9], &offset) && float_of(a[10], &largest_sd)
                 && float_of(a[11], &largest_value) && float_of(a[12], &noise_largest)
                 && float_of(a[13], &tension) && (!with_jac || jac != NULL)
                 && floats_at(a[15], 6, 1, 0, 6, added);
    for (Py_ssize_t i = 0; usable && i < n_jac; i++)
        usable = add_abs(jac[i], &jac_sum);
    if (!usable)
        return PyObject_Vectorcall(args[0], a, TAIL_ARGS, NULL);

    double largest = largest_sd * row_sum;
    double position_scale = largest_value * row_sum + offset;
    north += added[0];
    north_east += added[1];
    east += added[3];
    down += added[5];
    double scale = largest * largest + t * noise_largest;
    scale += added[0] + added[3] + added[5];
    double tension_bound;
    if (!with_jac)
        tension_bound = largest * largest + t * noise_largest;
    else {
        double base = jac_sum * largest;
        double square = pow(base, 2.0);
        if (isinf(square) && isfinite(base)) /* OverflowError in Python */
            return PyObject_Vectorcall(args[0], a, TAIL_ARGS, NULL);
        tension_bound = square + t * noise_largest * jac_sum * jac_sum;
    }
    int finite = scale < finite_bound && tension_bound < finite_bound
                 && position_scale < finite_bound && fabs(tension) < finite_bound;
    double position_tol = rounding * position_scale;
    double covariance_tol = finite ? rounding * scale + (1.0 + rounding) * moved : INFINITY;
    /* a NaN's bits are the operand order's (see stepped_terms): left to Python */
    if (!isfinite(north + north_east + east + down + position_tol + largest)
        || (finite && !isfinite(covariance_tol)))
        return PyObject_Vectorcall(args[0], a, TAIL_ARGS, NULL);

    PyObject *horizontal = Py_BuildValue("(ddd)", north, north_east, east);
    if (horizontal == NULL)
        return NULL;
    PyObject *made[8] = {a[0], a[1], horizontal, NULL, a[13], finite ? Py_True : Py_False,
                         NULL, NULL};
    made[3] = PyFloat_FromDouble(down);
    made[6] = PyFloat_FromDouble(position_tol);
    made[7] = PyFloat_FromDouble(covariance_tol);
    PyObject *approx = NULL;
    if (made[3] != NULL && made[6] != NULL && made[7] != NULL)
        approx = PyObject_Vectorcall(args[1], made, 8, NULL);
    Py_DECREF(horizontal);
    Py_XDECREF(made[3]);
    Py_XDECREF(made[6]);
    Py_XDECREF(made[7]);
    if (approx == NULL)
        return NULL;
    return Py_BuildValue("(Ndd)", approx, spread, largest);
}

static PyMethodDef methods[] = {
    {"stepped_terms", (PyCFunction)(void (*)(void))stepped_terms, METH_FASTCALL,
     "stepped_terms(fallback, *args): published_bound.stepped_terms(*args) in C."},
    {"unmodelled_rows", (PyCFunction)(void (*)(void))unmodelled_rows, METH_FASTCALL,
     "unmodelled_rows(fallback, *args): observability.unmodelled_position_rows(*args) in C."},
    {"sd_bounds", (PyCFunction)(void (*)(void))sd_bounds, METH_FASTCALL,
     "sd_bounds(fallback, diagonal, x_values): mixture.sd_bounds(diagonal, x_values) in C."},
    {"approximation_tail", (PyCFunction)(void (*)(void))approximation_tail, METH_FASTCALL,
     "approximation_tail(fallback, Approximation, rounding, finite_bound, *args):"
     " published_bound.approximation_tail(*args) in C."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_bound_core",
    "published_bound.stepped_terms and observability.unmodelled_position_rows in C (the Python"
    " functions' twins).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__bound_core(void)
{
    return PyModule_Create(&module_def);
}
