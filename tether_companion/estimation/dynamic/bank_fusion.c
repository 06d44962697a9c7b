/* The bank's force-balance fusion over its members in one C call (part of _member_core).
 *
 * bank_fuse_force_balance is FilterBank.update_force_balance's path where _member_core runs
 * (bank.py: the Python is the reference and the fallback), bit for bit: for every member the
 * measurement model on its state list, the innovation z - h(x), P H^T and H P H^T (as
 * member_core.c's project), S's test and inverse (as its force_balance), the gate and its
 * counting (MemberFilter.test_force_balance, ExtendedKalmanFilter._gate, gate_rejects), the
 * gain's update (as its update) and its keeping (MemberFilter.accept_update, _keep), with the
 * same IEEE operations in the same order (-ffp-contract=off).
 *
 * All members are computed first and nothing is written until every one is known to take the
 * common path; otherwise the call returns None with no member, status or count touched and
 * the caller runs the Python, which then does what it always did. The uncommon path: any
 * member holding its values as lists, a state, covariance, model value, Jacobian or result
 * not finite, a sensor seen for the first time, a gate threshold not yet cached, S not
 * positive definite, an updated covariance failing the Cholesky test, arguments of other
 * types (not exact floats, a model returning something other than a 2-tuple).
 *
 * The model (`measure`) is called from here on each member's state as a new list; it is
 * pure, so calling it again in the Python after a None changes nothing.
 */
#include "member_core.h"

#define FB_M 3 /* the force balance's axes */

typedef struct {
    PyObject *kf, *xa, *pa, *status, *jac; /* new references (status borrowed from a dict) */
    Py_buffer vx, vp;
    int have_x, have_p;
    long consecutive;
    double y[FB_M], log_det, nis;
    int gated, forced;
    PyObject *x_new, *p_new; /* new references when not gated */
} Member;

static PyObject *s_xa, *s_pa, *s_xl, *s_pl, *s_sensors, *s_thresholds, *s_limit, *s_log_det,
    *s_consecutive, *s_last_nis, *s_innovation, *s_gated, *s_forced, *s_fused, *s_three;

static int
intern_names(void)
{
    if (s_three != NULL)
        return 1;
    s_xa = PyUnicode_InternFromString("_xa");
    s_pa = PyUnicode_InternFromString("_pa");
    s_xl = PyUnicode_InternFromString("_xl");
    s_pl = PyUnicode_InternFromString("_pl");
    s_sensors = PyUnicode_InternFromString("sensors");
    s_thresholds = PyUnicode_InternFromString("_thresholds");
    s_limit = PyUnicode_InternFromString("max_consecutive_rejections");
    s_log_det = PyUnicode_InternFromString("last_log_det_s");
    s_consecutive = PyUnicode_InternFromString("consecutive_rejections");
    s_last_nis = PyUnicode_InternFromString("last_nis");
    s_innovation = PyUnicode_InternFromString("innovation");
    s_gated = PyUnicode_InternFromString("gated");
    s_forced = PyUnicode_InternFromString("forced");
    s_fused = PyUnicode_InternFromString("fused");
    s_three = PyLong_FromLong(FB_M);
    return s_xa && s_pa && s_xl && s_pl && s_sensors && s_thresholds && s_limit && s_log_det &&
           s_consecutive && s_last_nis && s_innovation && s_gated && s_forced && s_fused &&
           s_three;
}

static void
drop_member(Member *mb)
{
    if (mb->have_x)
        PyBuffer_Release(&mb->vx);
    if (mb->have_p)
        PyBuffer_Release(&mb->vp);
    mb->have_x = mb->have_p = 0;
    Py_CLEAR(mb->kf);
    Py_CLEAR(mb->xa);
    Py_CLEAR(mb->pa);
    Py_CLEAR(mb->jac);
    Py_CLEAR(mb->x_new);
    Py_CLEAR(mb->p_new);
    mb->status = NULL;
}

/* An attribute that is an exact int into *out; 0 (no error set) when it is not one. */
static int
attr_long(PyObject *obj, PyObject *name, long *out)
{
    PyObject *value = PyObject_GetAttr(obj, name);
    if (value == NULL) {
        PyErr_Clear();
        return 0;
    }
    int ok = PyLong_CheckExact(value);
    if (ok) {
        *out = PyLong_AsLong(value);
        if (*out == -1 && PyErr_Occurred()) {
            PyErr_Clear();
            ok = 0;
        }
    }
    Py_DECREF(value);
    return ok;
}

/* Set obj.name = the new reference value (stolen); -1 with an error set on failure. */
static int
set_new(PyObject *obj, PyObject *name, PyObject *value)
{
    if (value == NULL)
        return -1;
    int rc = PyObject_SetAttr(obj, name, value);
    Py_DECREF(value);
    return rc;
}

/* obj.name += 1 for an exact int attribute; -1 with an error set on failure. */
static int
increment(PyObject *obj, PyObject *name)
{
    long value;
    if (!attr_long(obj, name, &value) || value == LONG_MAX) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "a status counter is not an int");
        return -1;
    }
    return set_new(obj, name, PyLong_FromLong(value + 1));
}

/* Everything about one member up to the write: 1 when it takes the common path, 0 (no error
 * set) when the Python must run, -1 with an error set (the model raised). */
static int
compute_member(Member *mb, PyObject *kf, PyObject *sensor, const double *z, PyObject *measure,
               double r, Py_ssize_t hold_start, Py_ssize_t hold_stop, PyObject *empty, int *n_all)
{
    Py_INCREF(kf);
    mb->kf = kf;
    if (!(mb->xa = PyObject_GetAttr(kf, s_xa)) || !(mb->pa = PyObject_GetAttr(kf, s_pa))) {
        PyErr_Clear();
        return 0;
    }
    if (mb->xa == Py_None || mb->pa == Py_None)
        return 0;
    if (!(mb->have_x = get(mb->xa, &mb->vx, 1, *n_all ? *n_all : ANY, 0, 0)))
        return 0;
    int n = (int)mb->vx.shape[0];
    if (n > MAX_N || n < 1 || hold_stop > n)
        return 0;
    *n_all = n;
    if (!(mb->have_p = get(mb->pa, &mb->vp, 2, n, n, 0)))
        return 0;
    const double *x = mb->vx.buf, *p = mb->vp.buf;
    if (!all_finite(x, n) || !all_finite(p, (Py_ssize_t)n * n))
        return 0;
    /* the status and the gate: MemberFilter.test_force_balance's sensors.get, _gate's cache */
    PyObject *sensors = PyObject_GetAttr(kf, s_sensors);
    if (sensors == NULL) {
        PyErr_Clear();
        return 0;
    }
    mb->status = PyDict_CheckExact(sensors) ? PyDict_GetItemWithError(sensors, sensor) : NULL;
    Py_DECREF(sensors); /* the member keeps the dict and the dict the status */
    if (mb->status == NULL) {
        PyErr_Clear();
        return 0;
    }
    PyObject *thresholds = PyObject_GetAttr(kf, s_thresholds);
    if (thresholds == NULL) {
        PyErr_Clear();
        return 0;
    }
    PyObject *cached = PyDict_CheckExact(thresholds) ? PyDict_GetItemWithError(thresholds, s_three)
                                                     : NULL;
    double threshold = (cached != NULL && PyFloat_CheckExact(cached)) ? PyFloat_AS_DOUBLE(cached)
                                                                      : NAN;
    Py_DECREF(thresholds);
    PyErr_Clear();
    long limit;
    if (threshold != threshold || !attr_long(kf, s_limit, &limit) ||
        !attr_long(mb->status, s_consecutive, &mb->consecutive))
        return 0;
    double in_force = (0 < limit && limit <= mb->consecutive) ? INFINITY : threshold;
    /* the model on the state as a list (x_values) */
    PyObject *xs = PyList_New(n);
    if (xs == NULL)
        return -1;
    for (int i = 0; i < n; i++) {
        PyObject *item = PyFloat_FromDouble(x[i]);
        if (item == NULL) {
            Py_DECREF(xs);
            return -1;
        }
        PyList_SET_ITEM(xs, i, item);
    }
    PyObject *out = PyObject_CallOneArg(measure, xs);
    Py_DECREF(xs);
    if (out == NULL)
        return -1;
    double value[FB_M], h[FB_M * MAX_N];
    int ok = PyTuple_CheckExact(out) && PyTuple_GET_SIZE(out) == 2 &&
             read_exact_floats(PyTuple_GET_ITEM(out, 0), FB_M, value);
    if (ok) {
        mb->jac = PyTuple_GET_ITEM(out, 1);
        Py_INCREF(mb->jac);
        ok = (PyList_CheckExact(mb->jac) || PyTuple_CheckExact(mb->jac)) &&
             read_numbers(mb->jac, h, (Py_ssize_t)FB_M * n);
    }
    Py_DECREF(out);
    if (!ok || !all_finite(h, (Py_ssize_t)FB_M * n))
        return 0;
    for (int k = 0; k < FB_M; k++)
        mb->y[k] = z[k] - value[k];
    /* P H^T and H P H^T: member_core.c's project */
    double pht[MAX_N * FB_M], s[FB_M * FB_M];
    for (int i = 0; i < n; i++)
        for (int c = 0; c < FB_M; c++) {
            double v = 0.0;
            for (int k = 0; k < n; k++)
                v += p[i * n + k] * h[c * n + k];
            pht[i * FB_M + c] = v;
        }
    for (int rr = 0; rr < FB_M; rr++)
        for (int c = 0; c < FB_M; c++) {
            double v = 0.0;
            for (int k = 0; k < n; k++)
                v += h[rr * n + k] * pht[k * FB_M + c];
            s[rr * FB_M + c] = v;
        }
    /* S = H P H^T + r I tested and inverted: member.solve_force_balance */
    double s00 = s[0], s01 = s[1], s02 = s[2], s11 = s[4], s12 = s[5], s22 = s[8];
    const double *y = mb->y;
    if (!isfinite(s00 + s01 + s02 + s11 + s12 + s22 + r + y[0] + y[1] + y[2]) ||
        !isfinite(s[3] + s[6] + s[7]))
        return 0;
    s00 += r;
    s11 += r;
    s22 += r;
    double m01 = s00 * s11 - s01 * s01;
    double c0 = s11 * s22 - s12 * s12, c1 = s02 * s12 - s01 * s22, c2 = s01 * s12 - s02 * s11;
    double det = s00 * c0 + s01 * c1 + s02 * c2;
    if (!(s00 > 0.0 && m01 > 0.0 && det > 0.0))
        return 0;
    double log_det = log(det);
    double inv = 1.0 / det;
    double i00 = c0 * inv, i01 = c1 * inv, i02 = c2 * inv;
    double i11 = (s00 * s22 - s02 * s02) * inv;
    double i12 = (s01 * s02 - s00 * s12) * inv;
    double i22 = m01 * inv;
    double w0 = i00 * y[0] + i01 * y[1] + i02 * y[2];
    double w1 = i01 * y[0] + i11 * y[1] + i12 * y[2];
    double w2 = i02 * y[0] + i12 * y[1] + i22 * y[2];
    double nis = y[0] * w0 + y[1] * w1 + y[2] * w2;
    if (!isfinite(log_det + nis + i00 + i01 + i02 + i11 + i12 + i22 + w0 + w1 + w2))
        return 0;
    mb->log_det = log_det;
    mb->nis = nis;
    /* the gate (gate_rejects): a NaN cannot reach here */
    mb->gated = nis > in_force;
    mb->forced = !mb->gated && nis > threshold;
    if (mb->gated)
        return 1;
    /* the gain's update into new arrays: member_core.c's update */
    const double s_inv[FB_M * FB_M] = {i00, i01, i02, i01, i11, i12, i02, i12, i22};
    const double w[FB_M] = {w0, w1, w2};
    PyObject *shape_x = Py_BuildValue("(i)", n), *shape_p = Py_BuildValue("(ii)", n, n);
    if (shape_x == NULL || shape_p == NULL) {
        Py_XDECREF(shape_x);
        Py_XDECREF(shape_p);
        return -1;
    }
    mb->x_new = PyObject_CallOneArg(empty, shape_x);
    mb->p_new = mb->x_new ? PyObject_CallOneArg(empty, shape_p) : NULL;
    Py_DECREF(shape_x);
    Py_DECREF(shape_p);
    if (mb->p_new == NULL)
        return -1;
    Views v = {.count = 0};
    Py_buffer *vxo, *vpo;
    if (!(vxo = take(&v, mb->x_new, 1, n, 0, 1)) || !(vpo = take(&v, mb->p_new, 2, n, n, 1))) {
        release(&v);
        return 0;
    }
    double *xo = vxo->buf, *po = vpo->buf, k[MAX_N * FB_M], b[MAX_N * MAX_N];
    for (int i = 0; i < n; i++) {
        double value_i = 0.0;
        for (int rr = 0; rr < FB_M; rr++)
            value_i += pht[i * FB_M + rr] * w[rr];
        xo[i] = x[i] + value_i;
        for (int c = 0; c < FB_M; c++) { /* K = pht S^-1 */
            double kv = 0.0;
            for (int rr = 0; rr < FB_M; rr++)
                kv += pht[i * FB_M + rr] * s_inv[rr * FB_M + c];
            k[i * FB_M + c] = kv;
        }
    }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double value_ij = 0.0;
            for (int rr = 0; rr < FB_M; rr++)
                value_ij += k[i * FB_M + rr] * pht[j * FB_M + rr];
            b[i * n + j] = p[i * n + j] - value_ij;
        }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++)
            po[i * n + j] = (b[i * n + j] + b[j * n + i]) * 0.5;
    for (Py_ssize_t i = hold_start; i < hold_stop; i++) {
        xo[i] = x[i];
        for (Py_ssize_t j = hold_start; j < hold_stop; j++)
            po[i * n + j] = p[i * n + j];
    }
    int checked = all_finite(xo, n) && all_finite(po, (Py_ssize_t)n * n) && cholesky_ok(po, n);
    release(&v);
    return checked;
}

/* Write one computed member (its status, counters, arrays) and return its UpdateResult; NULL
 * with an error set on failure. */
static PyObject *
commit_member(Member *mb, PyObject *result_type, PyObject *fused, PyObject *gated)
{
    PyObject *status = mb->status;
    if (set_new(mb->kf, s_log_det, PyFloat_FromDouble(mb->log_det)) < 0 ||
        set_new(status, s_last_nis, PyFloat_FromDouble(mb->nis)) < 0 ||
        set_new(status, s_innovation, Py_BuildValue("(ddd)", mb->y[0], mb->y[1], mb->y[2])) < 0)
        return NULL;
    if (mb->gated) {
        if (set_new(status, s_consecutive, PyLong_FromLong(mb->consecutive + 1)) < 0 ||
            increment(status, s_gated) < 0)
            return NULL;
    }
    else {
        if ((mb->forced && increment(status, s_forced) < 0) ||
            PyObject_SetAttr(mb->kf, s_xa, mb->x_new) < 0 ||
            PyObject_SetAttr(mb->kf, s_xl, Py_None) < 0 ||
            PyObject_SetAttr(mb->kf, s_pa, mb->p_new) < 0 ||
            PyObject_SetAttr(mb->kf, s_pl, Py_None) < 0 || increment(status, s_fused) < 0 ||
            set_new(status, s_consecutive, PyLong_FromLong(0)) < 0)
            return NULL;
    }
    PyObject *nis = PyFloat_FromDouble(mb->nis);
    if (nis == NULL)
        return NULL;
    PyObject *args[2] = {mb->gated ? gated : fused, nis};
    PyObject *result = PyObject_Vectorcall(result_type, args, 2, NULL);
    Py_DECREF(nis);
    return result;
}

/* bank_fuse_force_balance(filters, sensor, z, measure, r_variance, hold_start, hold_stop, empty,
 * result_type, fused, gated) -> (results, jacobians, priors) as FilterBank.update_force_balance
 * returns them, every member's fusion done; None: not taken, nothing changed. */
PyObject *
bank_fuse_force_balance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 11)
        return PyErr_Format(PyExc_TypeError, "fuse_force_balance takes 11 arguments");
    if (!intern_names())
        return NULL;
    PyObject *filters = args[0], *sensor = args[1], *measure = args[3], *empty = args[7];
    double z[FB_M];
    if (!PyList_CheckExact(filters) || PyList_GET_SIZE(filters) < 1 ||
        PyList_GET_SIZE(filters) > MAX_MEMBERS || !read_exact_floats(args[2], FB_M, z) ||
        !PyFloat_CheckExact(args[4]) || !PyLong_CheckExact(args[5]) || !PyLong_CheckExact(args[6]))
        Py_RETURN_NONE;
    double r = PyFloat_AS_DOUBLE(args[4]);
    Py_ssize_t hold_start = PyLong_AsSsize_t(args[5]), hold_stop = PyLong_AsSsize_t(args[6]);
    if (hold_start < 0 || hold_stop < hold_start) {
        PyErr_Clear();
        Py_RETURN_NONE;
    }
    Py_ssize_t members = PyList_GET_SIZE(filters);
    Member mbs[MAX_MEMBERS];
    memset(mbs, 0, sizeof(Member) * (size_t)members);
    int n = 0, state = 1;
    for (Py_ssize_t i = 0; i < members && state == 1; i++)
        state = compute_member(&mbs[i], PyList_GET_ITEM(filters, i), sensor, z, measure, r,
                               hold_start, hold_stop, empty, &n);
    PyObject *out = NULL;
    if (state == 1) {
        PyObject *results = PyList_New(members), *jacobians = PyList_New(members),
                 *priors = PyList_New(members);
        int failed = results == NULL || jacobians == NULL || priors == NULL;
        for (Py_ssize_t i = 0; i < members && !failed; i++) {
            PyObject *result = commit_member(&mbs[i], args[8], args[9], args[10]);
            if (result == NULL) {
                failed = 1;
                break;
            }
            PyList_SET_ITEM(results, i, result);
            Py_INCREF(mbs[i].jac);
            PyList_SET_ITEM(jacobians, i, mbs[i].jac);
            Py_INCREF(mbs[i].pa);
            PyList_SET_ITEM(priors, i, mbs[i].pa);
        }
        if (!failed)
            out = PyTuple_Pack(3, results, jacobians, priors);
        Py_XDECREF(results);
        Py_XDECREF(jacobians);
        Py_XDECREF(priors);
    }
    for (Py_ssize_t i = 0; i < members; i++)
        drop_member(&mbs[i]);
    if (state == 0) {
        Py_RETURN_NONE;
    }
    return out; /* NULL with the error set (the model raised, or a write failed) */
}
