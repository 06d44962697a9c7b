/* published_terms.added_position_terms in C, float for float (and the module _status_core,
 * with observability.decide from status_decide.c): the published position
 * covariance's added terms, read at every IMU tick's status (and at every exact value), with
 * the terms it calls written out in their order:
 *
 *   offset_term.offset_rows (the catenary's plane rows with a fused winch length, their
 *   span_per_horizontal_tension the Python model's; the straight cable's otherwise,
 *   observability.unmodelled_position_rows in straight_rows.h, shared with bound_core.c),
 *   position_information.reduce_added_rows, position_information.height_excess,
 *   published_terms._along_range, published_terms._ring (observability.horizontal_pull_n,
 *   observability.min_horizontal_pull_n, bearing_ambiguity.bearing_ambiguity).
 *
 * The same IEEE double operations in the same order (Python's left-to-right sums and
 * products, its conditional expressions as comparisons), built with -ffp-contract=off (no
 * fused multiply-add) and -fno-builtin-pow (libm's pow, as CPython's `**`), math.hypot as
 * CPython 3.11's vector_norm (hypot2 below), math.sqrt and math.exp as libm's.
 *
 * Where C could differ it calls the Python function given as its first argument and returns
 * what it returns (or raises what it raises):
 *   - any argument that is not what the statements read as exact floats (a subclass, an int),
 *     winch_fused not exactly True or False, the information neither None nor a tuple of 13
 *     exact floats, a state of fewer than 13 items, a setting that is not an exact float;
 *   - `(drag / pull) ** 2` or `(radial * force_std) ** 2` overflowing (Python raises
 *     OverflowError), the model raising or giving no exact float;
 *   - any non-finite result (a NaN's bits, a ZeroDivisionError's place: Python's).
 * Python's float +, -, *, /, abs, comparisons, math.sqrt of a sum of squares and math.exp
 * raise nothing else here. tests/test_status_core.py compares.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <float.h>
#include <math.h>
#include <string.h>

#include "status_core.h"
#include "straight_rows.h"

/* state.TENSION, state.WIND.start, state.N_STATES (checked the same way) */
#define TENSION 6
#define WIND 11
#define LEAST_STATES 13
#define INFORMATION_TERMS 13

/* ------------------------------------------------------------------ math.hypot of two */

typedef struct {
    double hi;
    double lo;
} DoubleLength;

static DoubleLength
dl_fast_sum(double a, double b)
{
    double x = a + b;
    double y = (a - x) + b;
    return (DoubleLength){x, y};
}

static DoubleLength
dl_split(double x)
{
    double t = x * 134217729.0; /* Veltkamp: 2 ** 27 + 1 */
    double hi = t - (t - x);
    double lo = x - hi;
    return (DoubleLength){hi, lo};
}

static DoubleLength
dl_mul(double x, double y)
{
    DoubleLength xx = dl_split(x);
    DoubleLength yy = dl_split(y);
    double p = xx.hi * yy.hi;
    double q = xx.hi * yy.lo + xx.lo * yy.hi;
    double z = p + q;
    double zz = p - z + q + xx.lo * yy.lo;
    return (DoubleLength){z, zz};
}

/* CPython 3.11's vector_norm (Modules/mathmodule.c) of n <= 2 non-negative values. */
static double
vector_norm(int n, double *vec, double max, int found_nan)
{
    double x, h, scale, csum = 1.0, frac1 = 0.0, frac2 = 0.0;
    DoubleLength pr, sm;
    int max_e;
    if (isinf(max))
        return max;
    if (found_nan)
        return NAN;
    if (max == 0.0 || n <= 1)
        return max;
    frexp(max, &max_e);
    if (max_e < -1023) { /* subnormal: scaled up to normals first */
        for (int i = 0; i < n; i++)
            vec[i] /= DBL_MIN;
        return DBL_MIN * vector_norm(n, vec, max / DBL_MIN, found_nan);
    }
    scale = ldexp(1.0, -max_e);
    for (int i = 0; i < n; i++) {
        x = vec[i];
        x *= scale;
        pr = dl_mul(x, x);
        sm = dl_fast_sum(csum, pr.hi);
        csum = sm.hi;
        frac1 += pr.lo;
        frac2 += sm.lo;
    }
    h = sqrt(csum - 1.0 + (frac1 + frac2));
    pr = dl_mul(-h, h);
    sm = dl_fast_sum(csum, pr.hi);
    csum = sm.hi;
    frac1 += pr.lo;
    frac2 += sm.lo;
    x = csum - 1.0 + (frac1 + frac2);
    h += x / (2.0 * h);
    return h / scale;
}

/* math.hypot(a, b) as CPython 3.11 computes it. */
static double
hypot2(double a, double b)
{
    double vec[2] = {fabs(a), fabs(b)};
    double max = 0.0;
    int found_nan = 0;
    for (int i = 0; i < 2; i++) {
        found_nan |= isnan(vec[i]);
        if (vec[i] > max)
            max = vec[i];
    }
    return vector_norm(2, vec, max, found_nan);
}

/* ------------------------------------------------------------------ reading the arguments */

/* settings.<name> as an exact float; 0 when it is not one (an error is cleared: the
 * fallback reads it again and raises its own). */
static int
setting_of(PyObject *settings, PyObject *name, double *out)
{
    PyObject *value = PyObject_GetAttr(settings, name);
    if (value == NULL) {
        PyErr_Clear();
        return 0;
    }
    int ok = float_of(value, out);
    Py_DECREF(value);
    return ok;
}

static PyObject *WINCH_LENGTH_NOISE, *PULL_PER_WIND, *WIND_STD, *DRAG_PER_WIND;

/* ------------------------------------------------------------------ the terms */

/* observability.horizontal_pull_n of a state's values */
static double
pull_of(const double *x)
{
    double distance = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    return distance == 0.0 ? 0.0 : x[TENSION] * hypot2(x[0], x[1]) / distance;
}

/* observability.min_horizontal_pull_n */
static double
least_pull(double pull_per_wind, double wind_std, double wind_n, double wind_e)
{
    double speed = hypot2(wind_n, wind_e);
    return pull_per_wind * (speed > wind_std ? speed : wind_std);
}

/* published_terms._ring with bearing_ambiguity.bearing_ambiguity: (nn, ne, ee) into r;
 * 0: the fallback's ((drag / pull) ** 2 overflows, or a setting is not a float). */
static int
ring(const double *x, PyObject *settings, double *r)
{
    double drag_per_wind, pull_per_wind, wind_std;
    r[0] = r[1] = r[2] = 0.0;
    if (!setting_of(settings, DRAG_PER_WIND, &drag_per_wind))
        return 0;
    if (!(drag_per_wind > 0.0))
        return 1;
    if (!setting_of(settings, PULL_PER_WIND, &pull_per_wind)
        || !setting_of(settings, WIND_STD, &wind_std))
        return 0;
    double pull = pull_of(x);
    double wind_n = x[WIND], wind_e = x[WIND + 1];
    double min_pull = least_pull(pull_per_wind, wind_std, wind_n, wind_e);
    if (!(pull < min_pull))
        return 1;
    double drag = least_pull(drag_per_wind, wind_std, wind_n, wind_e);
    double n = x[0], e = x[1];
    double rho_sq = n * n + e * e;
    if (!(rho_sq > 0.0 && drag > 0.0 && isfinite(rho_sq + drag)))
        return 1;
    double s_sq = INFINITY;
    if (pull > 0.0) {
        double ratio = drag / pull;
        s_sq = pow(ratio, 2.0);
        if (isfinite(ratio) && isinf(s_sq))
            return 0; /* OverflowError in Python */
    }
    double across = rho_sq * 0.5 * (1.0 - exp(-2.0 * s_sq));
    double along = rho_sq * (1.5 - 2.0 * exp(-0.5 * s_sq) + 0.5 * exp(-2.0 * s_sq));
    double un = n * n / rho_sq, ue = e * e / rho_sq;
    double cross = n * e / rho_sq;
    r[0] = along * un + across * ue;
    r[1] = (along - across) * cross;
    r[2] = along * ue + across * un;
    return 1;
}

/* sag_range.span_per_horizontal_tension (the generated catenary model's Jacobian: Python's,
 * imported at the first call) into *out; 0 when it raises or gives no exact float (the
 * fallback then calls it again and does what it does). */
static PyObject *SPAN_PER_HORIZONTAL_TENSION;

static int
span_per_horizontal_tension(double span, double height, double horizontal, double weight,
                            double *out)
{
    if (SPAN_PER_HORIZONTAL_TENSION == NULL) {
        PyObject *module = PyImport_ImportModule("tether_companion.estimation.dynamic.sag_range");
        if (module == NULL) {
            PyErr_Clear();
            return 0;
        }
        SPAN_PER_HORIZONTAL_TENSION = PyObject_GetAttrString(module,
                                                             "span_per_horizontal_tension");
        Py_DECREF(module);
        if (SPAN_PER_HORIZONTAL_TENSION == NULL) {
            PyErr_Clear();
            return 0;
        }
    }
    PyObject *result = PyObject_CallFunction(SPAN_PER_HORIZONTAL_TENSION, "dddd", span, height,
                                             horizontal, weight);
    if (result == NULL) {
        PyErr_Clear();
        return 0;
    }
    int ok = float_of(result, out);
    Py_DECREF(result);
    return ok;
}

/* offset_term._plane_rows's upper triangle (nn, ne, nd, ee, ed, dd); 0 when
 * `(radial * force_std) ** 2` overflows (OverflowError in Python). */
static int
plane_rows(double n, double e, double d, double span, double distance, double tension,
           double radial_m_per_n, double force_std_n, double length_std_m, double *u)
{
    double h0 = n / span, h1 = e / span;
    double u0 = n / distance, u1 = e / distance, u2 = d / distance;
    double across = distance * force_std_n / tension;
    double g_t = across * across;
    double radial_force = radial_m_per_n * force_std_n;
    double g_r = pow(radial_force, 2.0);
    if (isfinite(radial_force) && isinf(g_r))
        return 0;
    double w = length_std_m * length_std_m;
    u[0] = g_t * h1 * h1 + g_r * h0 * h0 + w * u0 * u0;
    u[1] = -g_t * h0 * h1 + g_r * h0 * h1 + w * u0 * u1;
    u[2] = w * u0 * u2;
    u[3] = g_t * h0 * h0 + g_r * h1 * h1 + w * u1 * u1;
    u[4] = w * u1 * u2;
    u[5] = w * u2 * u2;
    return 1;
}

/* position_information.reduce_added_rows on the upper triangle u, in place */
static void
reduce_rows(const double *info, double *u)
{
    double kept = info[6], fresh = 1.0 - kept;
    double r01 = kept * info[1] + fresh * u[1] + info[8];
    double r02 = kept * info[2] + fresh * u[2] + info[9];
    double r12 = kept * info[4] + fresh * u[4] + info[11];
    u[0] = kept * info[0] + fresh * u[0] + info[7];
    u[1] = r01;
    u[2] = r02;
    u[3] = kept * info[3] + fresh * u[3] + info[10];
    u[4] = r12;
    u[5] = kept * info[5] + fresh * u[5] + info[12];
}

/* position_information.height_excess (nn, ne, nd, ee, ed, dd) */
static void
height_rows(double n, double e, double d, double v, int range_held, double *h)
{
    for (int i = 0; i < 6; i++)
        h[i] = 0.0;
    if (!(v > 0.0))
        return;
    double distance = sqrt(n * n + e * e + d * d);
    if (range_held || !isfinite(distance) || distance == 0.0) {
        h[5] = v;
        return;
    }
    double floor = 0.1 * distance;
    if (fabs(d) < floor)
        d = copysign(floor, d);
    double un = n / d, ue = e / d;
    h[0] = v * un * un;
    h[1] = v * un * ue;
    h[2] = v * un;
    h[3] = v * ue * ue;
    h[4] = v * ue;
    h[5] = v;
}

/* added_position_terms(fallback, x, weight_n_per_m, settings, force_std_n, information,
 * height_excess_m2, winch_fused, sag_m2, terrain_m2) -> (nn, ne, nd, ee, ed, dd) */
static PyObject *
added_position_terms(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 10) {
        PyErr_SetString(PyExc_TypeError,
                        "added_position_terms takes the fallback and 9 arguments");
        return NULL;
    }
    PyObject *fallback = args[0], *settings = args[3], *information = args[5];
    double x[LEAST_STATES], info[INFORMATION_TERMS], weight, force_std, height_excess_m2;
    double sag_m2, terrain_m2, length_std = 0.0;
    int winch_fused = args[7] == Py_True;
    if (!floats_of(args[1], LEAST_STATES, 0, LEAST_STATES, x) || !float_of(args[2], &weight)
        || !float_of(args[4], &force_std) || !float_of(args[6], &height_excess_m2)
        || !(winch_fused || args[7] == Py_False) || !float_of(args[8], &sag_m2)
        || !float_of(args[9], &terrain_m2)
        || (information != Py_None
            && !(PyTuple_CheckExact(information)
                 && floats_of(information, INFORMATION_TERMS, 1, INFORMATION_TERMS, info)))
        || (winch_fused && !setting_of(settings, WINCH_LENGTH_NOISE, &length_std)))
        goto python;
    double n = x[0], e = x[1], d = x[2];
    /* offset_term.offset_rows */
    double tension = x[TENSION];
    tension = MIN_TENSION_N > tension ? MIN_TENSION_N : tension;
    double span = hypot2(n, e);
    double height = -d;
    double u[6], h[6], s[3] = {0.0, 0.0, 0.0}, r[3];
    int plane = 0;
    if (winch_fused && weight > 0.0 && span > 0.0 && height > 0.0) {
        double distance = hypot2(span, height);
        double radial;
        if (!span_per_horizontal_tension(span, height, tension * span / distance, weight,
                                         &radial))
            goto python;
        if (isfinite(radial)) {
            if (!plane_rows(n, e, d, span, distance, tension, radial, force_std, length_std, u))
                goto python;
            plane = 1;
        }
    }
    if (!plane) {
        double rows[9];
        straight_rows(n, e, d, tension, force_std, length_std, rows);
        double upper[6] = {rows[0], rows[1], rows[2], rows[4], rows[5], rows[8]};
        memcpy(u, upper, sizeof(u));
    }
    if (information != Py_None)
        reduce_rows(info, u);
    height_rows(n, e, d, height_excess_m2 + terrain_m2, winch_fused, h);
    if (sag_m2 != 0.0) { /* _along_range (a NaN is true in Python too) */
        double along_span = hypot2(n, e);
        if (along_span != 0.0) {
            double h0 = n / along_span, h1 = e / along_span;
            s[0] = sag_m2 * h0 * h0;
            s[1] = sag_m2 * h0 * h1;
            s[2] = sag_m2 * h1 * h1;
        }
    }
    if (!ring(x, settings, r))
        goto python;
    double out[6] = {
        u[0] + h[0] + s[0] + r[0], u[1] + h[1] + s[1] + r[1], u[2] + h[2],
        u[3] + h[3] + s[2] + r[2], u[4] + h[4],               u[5] + h[5],
    };
    for (int i = 0; i < 6; i++) {
        if (!isfinite(out[i]))
            goto python;
    }
    return Py_BuildValue("(dddddd)", out[0], out[1], out[2], out[3], out[4], out[5]);
python:
    return PyObject_Vectorcall(fallback, args + 1, 9, NULL);
}

/* ------------------------------------------------------------------ the horizontal pulls */

/* horizontal_pull(fallback, x) -> observability.horizontal_pull_n(x): a state of at least 13
 * exact floats (else Python's), a non-finite result Python's. */
static PyObject *
horizontal_pull(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "horizontal_pull takes the fallback and x");
        return NULL;
    }
    double x[LEAST_STATES];
    if (!floats_of(args[1], LEAST_STATES, 0, LEAST_STATES, x))
        return PyObject_Vectorcall(args[0], args + 1, 1, NULL);
    double pull = pull_of(x);
    if (!isfinite(pull)) /* a NaN's bits: Python's */
        return PyObject_Vectorcall(args[0], args + 1, 1, NULL);
    return PyFloat_FromDouble(pull);
}

/* min_horizontal_pull(fallback, pull_per_wind_n_s_per_m, wind_std_mps, wind_n_mps,
 * wind_e_mps) -> observability.min_horizontal_pull_n(...): exact floats (else Python's), a
 * non-finite result Python's. */
static PyObject *
min_horizontal_pull(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "min_horizontal_pull takes the fallback and 4 floats");
        return NULL;
    }
    double per_wind, wind_std, wind_n, wind_e;
    if (!float_of(args[1], &per_wind) || !float_of(args[2], &wind_std)
        || !float_of(args[3], &wind_n) || !float_of(args[4], &wind_e))
        return PyObject_Vectorcall(args[0], args + 1, 4, NULL);
    double pull = least_pull(per_wind, wind_std, wind_n, wind_e);
    if (!isfinite(pull))
        return PyObject_Vectorcall(args[0], args + 1, 4, NULL);
    return PyFloat_FromDouble(pull);
}

static PyMethodDef methods[] = {
    {"added_position_terms", (PyCFunction)(void (*)(void))added_position_terms,
     METH_FASTCALL,
     "added_position_terms(fallback, *args): published_terms.added_position_terms(*args) in C."},
    {"decide", (PyCFunction)(void (*)(void))status_decide, METH_FASTCALL | METH_KEYWORDS,
     "decide(fallback, **keywords): observability.decide(**keywords) in C."},
    {"horizontal_pull", (PyCFunction)(void (*)(void))horizontal_pull, METH_FASTCALL,
     "horizontal_pull(fallback, x): observability.horizontal_pull_n(x) in C."},
    {"min_horizontal_pull", (PyCFunction)(void (*)(void))min_horizontal_pull, METH_FASTCALL,
     "min_horizontal_pull(fallback, *args): observability.min_horizontal_pull_n(*args) in C."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_status_core",
    "published_terms.added_position_terms, observability.decide and the horizontal pulls in C"
    " (the Python functions' twins).",
    -1, methods,
};

PyMODINIT_FUNC
PyInit__status_core(void)
{
    WINCH_LENGTH_NOISE = PyUnicode_InternFromString("winch_length_noise_std_m");
    PULL_PER_WIND = PyUnicode_InternFromString("pull_per_wind_n_s_per_m");
    WIND_STD = PyUnicode_InternFromString("wind_std_mps");
    DRAG_PER_WIND = PyUnicode_InternFromString("drag_per_wind_n_s_per_m");
    if (WINCH_LENGTH_NOISE == NULL || PULL_PER_WIND == NULL || WIND_STD == NULL
        || DRAG_PER_WIND == NULL)
        return NULL;
    if (!status_decide_init())
        return NULL;
    return PyModule_Create(&module_def);
}
