/* The tension filter's predict and update (tension_filter.py) in C, float for float; and, the
 * same way, the per-sample input arithmetic both filters read: the static thrust curve's sum
 * over the motors (thrust_input.static_thrust_n, per PWM sample) and the motor lag's step
 * (thrust_input.lagged_thrust_n, per PWM sample; libm's exp as math.exp), the attitude's
 * rotation rows (frames.rotation_ned_to_body_rows, per ATTITUDE sample) and the tension filter's
 * observation (tension_kf.observe_tension_ned_values, per IMU tick).
 *
 * tension_filter.py generates, per filter, straight-line Python for
 *   predict:  x <- A x,  P <- A P A^T + Q   (lower triangle, mirrored)
 *   update:   v = y - x_c, s = P_cc + R, g = P e_c / s, x <- x + g v^T,
 *             P <- (I - g e_c^T) P (I - g e_c^T)^T + R g g^T   (lower triangle, mirrored)
 * with A, Q and R written in as literals and the products with A's zeros left out (its
 * ``times``/``sum_of``: a zero coefficient drops the term, 1 keeps the bare value, -1 negates
 * it, an empty sum is 0.0). These functions take A, Q (and n, R) as arguments and apply the
 * same rules at run time, so they do the generated function's IEEE double operations in the
 * same order: with -ffp-contract=off (no fused multiply-add) the results are the same floats.
 *
 * Where C could differ they call the generated Python function given as their first argument
 * and return what it returns (or raise what it raises): any input that is not a list/tuple of
 * the right length of exact Python floats, a zero innovation variance s (Python's float
 * division raises ZeroDivisionError there) and any non-finite result (NaN bits). tests/test_tension_core.py compares the two.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "exact_floats.h"

#define MAX_TAPS 8

/* A new list of the `count` values (NULL on a memory error). */
static PyObject *
list_of(const double *values, Py_ssize_t count)
{
    PyObject *list = PyList_New(count);
    if (list == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *f = PyFloat_FromDouble(values[i]);
        if (f == NULL) {
            Py_DECREF(list);
            return NULL;
        }
        PyList_SET_ITEM(list, i, f);
    }
    return list;
}

/* A new list of the n*n entries of the symmetric matrix whose lower triangle is low[i*n + j]
 * (j <= i), each entry above the diagonal the same object as its mirror (as the generated
 * list names the same variable twice). */
static PyObject *
mirrored(const double *low, int n)
{
    PyObject *list = PyList_New((Py_ssize_t)n * n);
    if (list == NULL)
        return NULL;
    for (int i = 0; i < n; i++) {
        for (int j = 0; j <= i; j++) {
            PyObject *f = PyFloat_FromDouble(low[i * n + j]);
            if (f == NULL) {
                Py_DECREF(list);
                return NULL;
            }
            PyList_SET_ITEM(list, i * n + j, f);
            if (j != i) {
                Py_INCREF(f);
                PyList_SET_ITEM(list, j * n + i, f);
            }
        }
    }
    return list;
}

/* sum_of(times(...)) as it accumulates: the term coefficient * value added to the running
 * sum (`*started` 0: the term is the sum). */
static inline void
add_term(double *sum, int *started, double coefficient, double value)
{
    double term;
    if (coefficient == 0.0)
        return;
    if (coefficient == 1.0)
        term = value;
    else if (coefficient == -1.0)
        term = -value;
    else
        term = coefficient * value;
    if (*started)
        *sum = *sum + term;
    else {
        *sum = term;
        *started = 1;
    }
}

/* Whether the state's `count` values and the covariance's lower triangle are finite. A NaN's
 * sign and payload are the operand order's, which the compiler may swap in a commutative
 * product: a non-finite result is left to Python (finite results come from finite operands
 * only, and IEEE fixes those bits). */
static int
all_finite(const double *x, int count, const double *low, int n)
{
    for (int i = 0; i < count; i++)
        if (!isfinite(x[i]))
            return 0;
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++)
            if (!isfinite(low[i * n + j]))
                return 0;
    return 1;
}

static PyObject *
call_fallback(PyObject *fallback, PyObject *const *args, Py_ssize_t nargs)
{
    return PyObject_Vectorcall(fallback, args, (size_t)nargs, NULL);
}

/* predict(fallback, a, q, x, p) -> [x'], [P'] ; a and q the n*n row-major A and Q. */
static PyObject *
predict(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "predict(fallback, a, q, x, p)");
        return NULL;
    }
    PyObject *fallback = args[0];
    double a[MAX_TAPS * MAX_TAPS], q[MAX_TAPS * MAX_TAPS], p[MAX_TAPS * MAX_TAPS];
    double x[MAX_TAPS * 3], m[MAX_TAPS * MAX_TAPS], new_x[MAX_TAPS * 3];
    double low[MAX_TAPS * MAX_TAPS];
    Py_ssize_t nn = PyTuple_CheckExact(args[1]) ? PyTuple_GET_SIZE(args[1]) : -1;
    int n = 0;
    while (n <= MAX_TAPS && (Py_ssize_t)n * n < nn)
        n++;
    if (n < 1 || n > MAX_TAPS || (Py_ssize_t)n * n != nn || !read_exact_floats(args[1], nn, a)
        || !read_exact_floats(args[2], nn, q) || !read_exact_floats(args[3], 3 * n, x)
        || !read_exact_floats(args[4], nn, p))
        return call_fallback(fallback, args + 3, 2);
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) {
            double sum = 0.0;
            int started = 0;
            for (int j = 0; j < n; j++)
                add_term(&sum, &started, a[i * n + j], x[j * 3 + k]);
            new_x[i * 3 + k] = sum;
        }
    }
    for (int i = 0; i < n; i++) { /* M = A P */
        for (int j = 0; j < n; j++) {
            double sum = 0.0;
            int started = 0;
            for (int k = 0; k < n; k++)
                add_term(&sum, &started, a[i * n + k], p[k * n + j]);
            m[i * n + j] = sum;
        }
    }
    for (int i = 0; i < n; i++) { /* M A^T + Q, lower triangle */
        for (int j = 0; j <= i; j++) {
            double sum = 0.0;
            int started = 0;
            for (int k = 0; k < n; k++)
                add_term(&sum, &started, a[j * n + k], m[i * n + k]);
            if (q[i * n + j] != 0.0) {
                sum = started ? sum + q[i * n + j] : q[i * n + j];
            }
            low[i * n + j] = sum;
        }
    }
    if (!all_finite(new_x, 3 * n, low, n))
        return call_fallback(fallback, args + 3, 2);
    PyObject *xs = list_of(new_x, 3 * n);
    if (xs == NULL)
        return NULL;
    PyObject *ps = mirrored(low, n);
    if (ps == NULL) {
        Py_DECREF(xs);
        return NULL;
    }
    PyObject *result = PyTuple_Pack(2, xs, ps);
    Py_DECREF(xs);
    Py_DECREF(ps);
    return result;
}

/* update(fallback, r, x, p, y0, y1, y2) -> [x'], [P'], [v0, v1, v2] ; n from len(p). */
static PyObject *
update(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "update(fallback, r, x, p, y0, y1, y2)");
        return NULL;
    }
    PyObject *fallback = args[0];
    double x[MAX_TAPS * 3], p[MAX_TAPS * MAX_TAPS], b[MAX_TAPS * MAX_TAPS];
    double low[MAX_TAPS * MAX_TAPS], g[MAX_TAPS], new_x[MAX_TAPS * 3], v[3], y[3];
    Py_ssize_t nn = PyList_CheckExact(args[3]) ? PyList_GET_SIZE(args[3])
                    : PyTuple_CheckExact(args[3]) ? PyTuple_GET_SIZE(args[3]) : -1;
    int n = 0;
    while (n <= MAX_TAPS && (Py_ssize_t)n * n < nn)
        n++;
    if (n < 1 || n > MAX_TAPS || (Py_ssize_t)n * n != nn || !PyFloat_CheckExact(args[1])
        || !read_exact_floats(args[2], 3 * n, x) || !read_exact_floats(args[3], nn, p)
        || !PyFloat_CheckExact(args[4]) || !PyFloat_CheckExact(args[5])
        || !PyFloat_CheckExact(args[6]))
        return call_fallback(fallback, args + 2, 5);
    double r = PyFloat_AS_DOUBLE(args[1]);
    int c = n - 1;
    for (int k = 0; k < 3; k++) {
        y[k] = PyFloat_AS_DOUBLE(args[4 + k]);
        v[k] = y[k] - x[c * 3 + k];
    }
    double s = p[c * n + c] + r;
    if (s == 0.0) /* Python raises ZeroDivisionError: let it */
        return call_fallback(fallback, args + 2, 5);
    for (int i = 0; i < n; i++)
        g[i] = p[i * n + c] / s;
    for (int i = 0; i < n; i++)
        for (int k = 0; k < 3; k++)
            new_x[i * 3 + k] = x[i * 3 + k] + g[i] * v[k];
    for (int i = 0; i < n; i++) /* B = (I - g e_c^T) P */
        for (int j = 0; j < n; j++)
            b[i * n + j] = p[i * n + j] - g[i] * p[c * n + j];
    for (int i = 0; i < n; i++) /* B (I - g e_c^T)^T + R g g^T, lower triangle */
        for (int j = 0; j <= i; j++)
            low[i * n + j] = b[i * n + j] - b[i * n + c] * g[j] + r * g[i] * g[j];
    if (!all_finite(new_x, 3 * n, low, n) || !isfinite(v[0] + v[1] + v[2]))
        return call_fallback(fallback, args + 2, 5);
    PyObject *xs = list_of(new_x, 3 * n);
    PyObject *ps = xs == NULL ? NULL : mirrored(low, n);
    PyObject *vs = ps == NULL ? NULL : list_of(v, 3);
    PyObject *result = vs == NULL ? NULL : PyTuple_Pack(3, xs, ps, vs);
    Py_XDECREF(xs);
    Py_XDECREF(ps);
    Py_XDECREF(vs);
    return result;
}

#define MAX_MOTORS 16

/* static_thrust(fallback, pwm, pwm_min_us, per_us, scale, total, c1, c2): thrust_input's
 * static_thrust_n, the curve's sum over the motors, statement for statement. */
static PyObject *
static_thrust(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 8) {
        PyErr_SetString(PyExc_TypeError, "static_thrust takes the fallback and 7 arguments");
        return NULL;
    }
    double pwm[MAX_MOTORS], k[6];
    PyObject *seq = args[1];
    Py_ssize_t count = PyList_CheckExact(seq)    ? PyList_GET_SIZE(seq)
                       : PyTuple_CheckExact(seq) ? PyTuple_GET_SIZE(seq)
                                                 : -1;
    int exact = count >= 0 && count <= MAX_MOTORS && read_exact_floats(seq, count, pwm);
    for (int i = 0; exact && i < 6; i++) {
        exact = PyFloat_CheckExact(args[2 + i]);
        if (exact)
            k[i] = PyFloat_AS_DOUBLE(args[2 + i]);
    }
    if (!exact)
        return PyObject_Vectorcall(args[0], args + 1, 7, NULL);
    double pwm_min_us = k[0], per_us = k[1], scale = k[2], total = k[3], c1 = k[4], c2 = k[5];
    for (Py_ssize_t i = 0; i < count; i++) {
        double u = (pwm[i] - pwm_min_us) * per_us;
        double cmd = (u < 0.0 ? 0.0 : u > 1.0 ? 1.0 : u) * scale;
        total += cmd * (c1 + c2 * cmd);
    }
    if (!isfinite(total)) /* a NaN's bits are the operand order's: left to Python */
        return PyObject_Vectorcall(args[0], args + 1, 7, NULL);
    return PyFloat_FromDouble(total);
}

#define RESTART_GAP_S 1.0 /* thrust_input.RESTART_GAP_S */
#define HOLD_FRACTION 0.5 /* thrust_input.HOLD_FRACTION */

/* lagged_thrust(fallback, command_n, dt_s, thrust_n, last_command_n, interval_s,
 * time_constant_s) -> (thrust_n, interval_s, expected_n): thrust_input.lagged_thrust_n,
 * statement for statement (libm's exp, as math.exp). Python's: an argument that is not an
 * exact float, a zero time constant (ZeroDivisionError), a non-finite result (a NaN's bits). */
static PyObject *
lagged_thrust(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "lagged_thrust takes the fallback and 6 arguments");
        return NULL;
    }
    double k[6];
    for (int i = 0; i < 6; i++) {
        if (!PyFloat_CheckExact(args[1 + i]))
            return PyObject_Vectorcall(args[0], args + 1, 6, NULL);
        k[i] = PyFloat_AS_DOUBLE(args[1 + i]);
    }
    double command_n = k[0], dt_s = k[1], thrust_n = k[2], last_command_n = k[3];
    double interval_s = k[4], time_constant_s = k[5];
    if (time_constant_s == 0.0) /* Python's float division raises ZeroDivisionError */
        return PyObject_Vectorcall(args[0], args + 1, 6, NULL);
    if (!(0.0 < dt_s && dt_s <= RESTART_GAP_S))
        thrust_n = command_n;
    else {
        double decay = exp(-dt_s / time_constant_s);
        thrust_n = last_command_n + (thrust_n - last_command_n) * decay;
        interval_s = dt_s;
    }
    double ahead = exp(-(HOLD_FRACTION * interval_s) / time_constant_s);
    double expected_n = command_n + (thrust_n - command_n) * ahead;
    if (!isfinite(thrust_n + interval_s + expected_n)) /* a NaN's bits: Python's */
        return PyObject_Vectorcall(args[0], args + 1, 6, NULL);
    return Py_BuildValue("(ddd)", thrust_n, interval_s, expected_n);
}

/* Three exact floats of a list or tuple (0: anything else). */
static int
row_of(PyObject *seq, double *out)
{
    return read_exact_floats(seq, 3, out);
}

/* observe_tension(fallback, specific_force, rotation_rows, thrust_n, mass_kg) -> (n, e, d):
 * tension_kf.observe_tension_ned_values, statement for statement. */
static PyObject *
observe_tension(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "observe_tension takes the fallback and 4 arguments");
        return NULL;
    }
    double f[3], r[9], thrust_n, mass_kg;
    PyObject *rows = args[2];
    PyObject **items = PyList_CheckExact(rows) && PyList_GET_SIZE(rows) == 3
                           ? ((PyListObject *)rows)->ob_item
                       : PyTuple_CheckExact(rows) && PyTuple_GET_SIZE(rows) == 3
                           ? ((PyTupleObject *)rows)->ob_item
                           : NULL;
    if (items == NULL || !row_of(args[1], f) || !row_of(items[0], r) || !row_of(items[1], r + 3)
        || !row_of(items[2], r + 6) || !PyFloat_CheckExact(args[3])
        || !PyFloat_CheckExact(args[4]))
        return PyObject_Vectorcall(args[0], args + 1, 4, NULL);
    thrust_n = PyFloat_AS_DOUBLE(args[3]);
    mass_kg = PyFloat_AS_DOUBLE(args[4]);
    double c0 = mass_kg * f[0], c1 = mass_kg * f[1], c2 = mass_kg * f[2] + thrust_n;
    double n = r[0] * c0 + r[3] * c1 + r[6] * c2;
    double e = r[1] * c0 + r[4] * c1 + r[7] * c2;
    double d = r[2] * c0 + r[5] * c1 + r[8] * c2;
    if (!isfinite(n + e + d)) /* a NaN's bits are the operand order's: left to Python */
        return PyObject_Vectorcall(args[0], args + 1, 4, NULL);
    return Py_BuildValue("(ddd)", n, e, d);
}

/* libm's sin and cos called one by one, as math.sin and math.cos call them (through volatile
 * pointers: the compiler may not merge a sin and a cos of the same angle into one sincos). */
static double (*volatile libm_sin)(double) = sin;
static double (*volatile libm_cos)(double) = cos;

/* rotation_rows(fallback, roll, pitch, yaw) -> 3 lists of 3 floats:
 * frames.rotation_ned_to_body_rows, statement for statement. */
static PyObject *
rotation_rows(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "rotation_rows takes the fallback and 3 arguments");
        return NULL;
    }
    double a[3];
    for (int i = 0; i < 3; i++) {
        /* math.sin/cos raise on an infinity: any angle not finite is Python's */
        if (!PyFloat_CheckExact(args[1 + i]) || !isfinite(a[i] = PyFloat_AS_DOUBLE(args[1 + i])))
            return PyObject_Vectorcall(args[0], args + 1, 3, NULL);
    }
    double cr = libm_cos(a[0]), sr = libm_sin(a[0]);
    double cp = libm_cos(a[1]), sp = libm_sin(a[1]);
    double cy = libm_cos(a[2]), sy = libm_sin(a[2]);
    return Py_BuildValue("[[ddd][ddd][ddd]]", cp * cy, cp * sy, -sp, sr * sp * cy - cr * sy,
                         sr * sp * sy + cr * cy, sr * cp, cr * sp * cy + sr * sy,
                         cr * sp * sy - sr * cy, cr * cp);
}

static PyMethodDef methods[] = {
    {"predict", (PyCFunction)(void (*)(void))predict, METH_FASTCALL,
     "predict(fallback, a, q, x, p): the generated predict(x, p) of A = a, Q = q (n*n "
     "row-major tuples of floats)."},
    {"update", (PyCFunction)(void (*)(void))update, METH_FASTCALL,
     "update(fallback, r, x, p, y0, y1, y2): the generated update(x, p, y0, y1, y2) of R = r."},
    {"static_thrust", (PyCFunction)(void (*)(void))static_thrust, METH_FASTCALL,
     "static_thrust(fallback, pwm, pwm_min_us, per_us, scale, total, c1, c2): "
     "thrust_input.static_thrust_n in C."},
    {"lagged_thrust", (PyCFunction)(void (*)(void))lagged_thrust, METH_FASTCALL,
     "lagged_thrust(fallback, command_n, dt_s, thrust_n, last_command_n, interval_s, "
     "time_constant_s): thrust_input.lagged_thrust_n in C."},
    {"observe_tension", (PyCFunction)(void (*)(void))observe_tension, METH_FASTCALL,
     "observe_tension(fallback, specific_force, rotation_rows, thrust_n, mass_kg): "
     "tension_kf.observe_tension_ned_values in C."},
    {"rotation_rows", (PyCFunction)(void (*)(void))rotation_rows, METH_FASTCALL,
     "rotation_rows(fallback, roll, pitch, yaw): frames.rotation_ned_to_body_rows in C."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_tension_core",
    "The tension filter's generated predict and update, its observation, the static thrust "
    "curve's sum, the motor lag's step and the attitude's rotation rows in C (the Python "
    "functions' twins).",
    -1,
    methods,
};

PyMODINIT_FUNC
PyInit__tension_core(void)
{
    return PyModule_Create(&module_def);
}
