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
    PyObject *kf, *xa, *pa, *status, *jac; /* new references */
    Py_buffer vx, vp;
    int have_x, have_p;
    long consecutive;
    double y[FB_M], log_det, nis;
    int gated, forced;
    PyObject *x_new, *p_new; /* new references when not gated */
} Member;

static PyObject *s_sensors, *s_thresholds, *s_limit, *s_log_det,
    *s_consecutive, *s_last_nis, *s_innovation, *s_gated, *s_forced, *s_fused, *s_three, *s_one;

static int
intern_names(void)
{
    if (s_three != NULL)
        return 1;
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
    s_one = PyLong_FromLong(1);
    return s_sensors && s_thresholds && s_limit && s_log_det &&
           s_consecutive && s_last_nis && s_innovation && s_gated && s_forced && s_fused &&
           s_three && s_one;
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
    Py_CLEAR(mb->status);
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

/* A member's held arrays, its sensor's status and its gate (test_force_balance / test_scalar's
 * sensors.get, _gate's cached threshold for `m` axes): 1 when they take the common path, 0 (no
 * error set) when the Python must run. */
static int
member_setup(Member *mb, PyObject *kf, PyObject *sensor, int m, Py_ssize_t hold_stop, int *n_all,
             double *threshold, double *in_force)
{
    Py_INCREF(kf);
    mb->kf = kf;
    if (!(mb->xa = PyObject_GetAttr(kf, name_xa)) || !(mb->pa = PyObject_GetAttr(kf, name_pa))) {
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
    if (!all_finite(mb->vx.buf, n) || !all_finite(mb->vp.buf, (Py_ssize_t)n * n))
        return 0;
    PyObject *sensors = PyObject_GetAttr(kf, s_sensors);
    if (sensors == NULL) {
        PyErr_Clear();
        return 0;
    }
    mb->status = PyDict_CheckExact(sensors) ? PyDict_GetItemWithError(sensors, sensor) : NULL;
    Py_XINCREF(mb->status); /* held: the model (Python) runs before it is written */
    Py_DECREF(sensors);
    if (mb->status == NULL) {
        PyErr_Clear();
        return 0;
    }
    PyObject *thresholds = PyObject_GetAttr(kf, s_thresholds);
    if (thresholds == NULL) {
        PyErr_Clear();
        return 0;
    }
    PyObject *key = m == FB_M ? s_three : s_one;
    PyObject *cached = PyDict_CheckExact(thresholds) ? PyDict_GetItemWithError(thresholds, key)
                                                     : NULL;
    *threshold = (cached != NULL && PyFloat_CheckExact(cached)) ? PyFloat_AS_DOUBLE(cached) : NAN;
    Py_DECREF(thresholds);
    PyErr_Clear();
    long limit;
    if (*threshold != *threshold || !attr_long(kf, s_limit, &limit) ||
        !attr_long(mb->status, s_consecutive, &mb->consecutive))
        return 0;
    *in_force = (0 < limit && limit <= mb->consecutive) ? INFINITY : *threshold;
    return 1;
}

/* The gain's update into new arrays (member_core.c's update) for a member the gate let
 * through: 1 when finite and positive definite (kept then), 0 (no error set) when not (the
 * Python must run), -1 with an error set. */
static int
update_member(Member *mb, int n, int m, const double *pht, const double *s_inv, const double *w,
              Py_ssize_t hold_start, Py_ssize_t hold_stop, PyObject *empty)
{
    const double *x = mb->vx.buf, *p = mb->vp.buf;
    /* the shapes (n,) and (n, n), kept for the last n (every member of a bank has the same) */
    static PyObject *shape_x, *shape_p;
    static int shape_n;
    if (shape_x == NULL || shape_n != n) {
        Py_CLEAR(shape_x);
        Py_CLEAR(shape_p);
        shape_x = Py_BuildValue("(i)", n);
        shape_p = Py_BuildValue("(ii)", n, n);
        if (shape_x == NULL || shape_p == NULL) {
            Py_CLEAR(shape_x);
            Py_CLEAR(shape_p);
            return -1;
        }
        shape_n = n;
    }
    mb->x_new = PyObject_CallOneArg(empty, shape_x);
    mb->p_new = mb->x_new ? PyObject_CallOneArg(empty, shape_p) : NULL;
    if (mb->p_new == NULL)
        return -1;
    Views v = {.count = 0};
    Py_buffer *vxo, *vpo;
    if (!(vxo = take(&v, mb->x_new, 1, n, 0, 1)) || !(vpo = take(&v, mb->p_new, 2, n, n, 1))) {
        release(&v);
        return 0;
    }
    int checked = member_gain_update(x, p, pht, s_inv, w, n, m, hold_start, hold_stop, vxo->buf,
                                     vpo->buf);
    release(&v);
    return checked;
}

/* The state as a new list of floats (x_values). */
static PyObject *
state_list(const double *x, int n)
{
    PyObject *xs = PyList_New(n);
    if (xs == NULL)
        return NULL;
    for (int i = 0; i < n; i++) {
        PyObject *item = PyFloat_FromDouble(x[i]);
        if (item == NULL) {
            Py_DECREF(xs);
            return NULL;
        }
        PyList_SET_ITEM(xs, i, item);
    }
    return xs;
}

/* Everything about one member of a force-balance fusion up to the write: 1 when it takes the
 * common path, 0 (no error set) when the Python must run, -1 with an error set (the model
 * raised). */
static int
compute_force_balance(Member *mb, PyObject *kf, PyObject *sensor, const double *z,
                      PyObject *measure, double r, Py_ssize_t hold_start, Py_ssize_t hold_stop,
                      PyObject *empty, int *n_all)
{
    double threshold, in_force;
    if (!member_setup(mb, kf, sensor, FB_M, hold_stop, n_all, &threshold, &in_force))
        return 0;
    int n = *n_all;
    const double *x = mb->vx.buf;
    /* the model on the state as a list (x_values) */
    PyObject *xs = state_list(x, n);
    if (xs == NULL)
        return -1;
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
    double pht[MAX_N * FB_M], s[FB_M * FB_M];
    member_project(mb->vp.buf, h, n, FB_M, pht, s);
    /* S = H P H^T + r I tested and inverted: member.solve_force_balance */
    double solved[13];
    if (member_solve_force_balance(s, mb->y, r, &mb->log_det, solved) != 1)
        return 0;
    double nis = mb->nis = solved[0];
    /* the gate (gate_rejects): a NaN cannot reach here */
    mb->gated = nis > in_force;
    mb->forced = !mb->gated && nis > threshold;
    if (mb->gated)
        return 1;
    return update_member(mb, n, FB_M, pht, solved + 1, solved + 10, hold_start, hold_stop, empty);
}

/* The first float of a model's value: an exact float list/tuple or a float64 array, 1-D. */
static int
first_value(PyObject *value, double *out)
{
    if (PyList_CheckExact(value) || PyTuple_CheckExact(value)) {
        if (PySequence_Fast_GET_SIZE(value) < 1)
            return 0;
        PyObject *item = PySequence_Fast_ITEMS(value)[0];
        if (!PyFloat_CheckExact(item))
            return 0;
        *out = PyFloat_AS_DOUBLE(item);
        return 1;
    }
    Py_buffer view;
    if (!get(value, &view, 1, ANY, 0, 0))
        return 0;
    int ok = view.shape[0] >= 1;
    if (ok)
        *out = ((const double *)view.buf)[0];
    PyBuffer_Release(&view);
    return ok;
}

/* Everything about one member of a scalar fusion up to the write (FilterBank.update_scalar
 * without `pseudo`, MemberFilter.test_scalar): as compute_force_balance. */
static int
compute_scalar(Member *mb, PyObject *kf, PyObject *sensor, double z, PyObject *measure, double r,
               Py_ssize_t hold_start, Py_ssize_t hold_stop, PyObject *empty, int *n_all)
{
    double threshold, in_force;
    if (!member_setup(mb, kf, sensor, 1, hold_stop, n_all, &threshold, &in_force))
        return 0;
    int n = *n_all;
    PyObject *out = PyObject_CallOneArg(measure, mb->xa); /* measure(kf.x) */
    if (out == NULL)
        return -1;
    double value, h[MAX_N];
    int ok = PyTuple_CheckExact(out) && PyTuple_GET_SIZE(out) == 2 &&
             first_value(PyTuple_GET_ITEM(out, 0), &value);
    if (ok) {
        mb->jac = PyTuple_GET_ITEM(out, 1);
        Py_INCREF(mb->jac);
        if (PyList_CheckExact(mb->jac) || PyTuple_CheckExact(mb->jac))
            ok = read_numbers(mb->jac, h, n);
        else {
            Py_buffer view;
            ok = get(mb->jac, &view, 2, 1, n, 0);
            if (ok) {
                for (int k = 0; k < n; k++)
                    h[k] = ((const double *)view.buf)[k];
                PyBuffer_Release(&view);
            }
        }
    }
    Py_DECREF(out);
    if (!ok || !all_finite(h, n))
        return 0;
    double y = z - value;
    double pht[MAX_N], hph;
    member_project(mb->vp.buf, h, n, 1, pht, &hph);
    double s = hph + r;
    if (!(s > 0.0) || !isfinite(s) || !isfinite(y))
        return 0;
    double log_det = log(s), nis = y * y / s, s_inv = 1.0 / s, w = y / s;
    if (!isfinite(log_det + nis + s_inv + w))
        return 0;
    mb->y[0] = y;
    mb->log_det = log_det;
    mb->nis = nis;
    mb->gated = nis > in_force;
    mb->forced = !mb->gated && nis > threshold;
    if (mb->gated)
        return 1;
    return update_member(mb, n, 1, pht, &s_inv, &w, hold_start, hold_stop, empty);
}

/* Write one computed member (its status, counters, arrays) and return its UpdateResult; NULL
 * with an error set on failure. */
static PyObject *
commit_member(Member *mb, int m, PyObject *result_type, PyObject *fused, PyObject *gated)
{
    PyObject *status = mb->status;
    PyObject *innovation = m == FB_M ? Py_BuildValue("(ddd)", mb->y[0], mb->y[1], mb->y[2])
                                     : Py_BuildValue("(d)", mb->y[0]);
    if (set_new(mb->kf, s_log_det, PyFloat_FromDouble(mb->log_det)) < 0 ||
        set_new(status, s_last_nis, PyFloat_FromDouble(mb->nis)) < 0 ||
        set_new(status, s_innovation, innovation) < 0)
        return NULL;
    if (mb->gated) {
        if (set_new(status, s_consecutive, PyLong_FromLong(mb->consecutive + 1)) < 0 ||
            increment(status, s_gated) < 0)
            return NULL;
    }
    else {
        if ((mb->forced && increment(status, s_forced) < 0) ||
            PyObject_SetAttr(mb->kf, name_xa, mb->x_new) < 0 ||
            PyObject_SetAttr(mb->kf, name_xl, Py_None) < 0 ||
            PyObject_SetAttr(mb->kf, name_pa, mb->p_new) < 0 ||
            PyObject_SetAttr(mb->kf, name_pl, Py_None) < 0 || increment(status, s_fused) < 0 ||
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

/* The members' fusion (m = FB_M: the force balance, z 3 floats; m = 1: a scalar, z a float):
 * (results, jacobians, priors) with every member's fusion done; None: not taken, nothing
 * changed. */
static PyObject *
fuse_members(PyObject *const *args, Py_ssize_t nargs, int m)
{
    if (nargs != 13)
        return PyErr_Format(PyExc_TypeError, "the bank's fusion takes 13 arguments");
    if (!intern_names())
        return NULL;
    PyObject *filters = args[0], *sensor = args[1], *measure = args[3], *empty = args[7];
    double z[FB_M];
    int z_ok = m == FB_M ? read_exact_floats(args[2], FB_M, z) : PyFloat_CheckExact(args[2]);
    if (!PyList_CheckExact(filters) || PyList_GET_SIZE(filters) < 1 ||
        PyList_GET_SIZE(filters) > MAX_MEMBERS || !z_ok || !PyFloat_CheckExact(args[4]) ||
        !PyLong_CheckExact(args[5]) || !PyLong_CheckExact(args[6]))
        Py_RETURN_NONE;
    if (m == 1)
        z[0] = PyFloat_AS_DOUBLE(args[2]);
    double r = PyFloat_AS_DOUBLE(args[4]);
    Py_ssize_t hold_start = PyLong_AsSsize_t(args[5]), hold_stop = PyLong_AsSsize_t(args[6]);
    if (hold_start < 0 || hold_stop < hold_start) {
        PyErr_Clear();
        Py_RETURN_NONE;
    }
    Py_ssize_t members = PyList_GET_SIZE(filters);
    /* the members' evidence (FilterBank.add_evidence over the outcomes): a bank of several
     * members given its log weights (exact floats) and a tempering (an exact float) */
    PyObject *log_weight = args[11];
    double weights[MAX_MEMBERS], tempering = 0.0;
    int evidence = log_weight != Py_None && members > 1;
    if (evidence) {
        if (!PyList_CheckExact(log_weight) || !read_exact_floats(log_weight, members, weights) ||
            !PyFloat_CheckExact(args[12]))
            Py_RETURN_NONE;
        tempering = PyFloat_AS_DOUBLE(args[12]);
    }
    Member mbs[MAX_MEMBERS];
    memset(mbs, 0, sizeof(Member) * (size_t)members);
    int n = 0, state = 1;
    for (Py_ssize_t i = 0; i < members && state == 1; i++) {
        PyObject *kf = PyList_GET_ITEM(filters, i);
        state = m == FB_M ? compute_force_balance(&mbs[i], kf, sensor, z, measure, r, hold_start,
                                                  hold_stop, empty, &n)
                          : compute_scalar(&mbs[i], kf, sensor, z[0], measure, r, hold_start,
                                           hold_stop, empty, &n);
    }
    PyObject *out = NULL;
    if (state == 1) {
        PyObject *results = PyList_New(members), *jacobians = PyList_New(members),
                 *priors = PyList_New(members);
        int failed = results == NULL || jacobians == NULL || priors == NULL;
        for (Py_ssize_t i = 0; i < members && !failed; i++) {
            PyObject *result = commit_member(&mbs[i], m, args[8], args[9], args[10]);
            if (result == NULL) {
                failed = 1;
                break;
            }
            PyList_SET_ITEM(results, i, result);
            if (evidence) { /* nis and log det S are finite here */
                double value = mbs[i].nis + mbs[i].log_det;
                PyObject *weight = PyFloat_FromDouble(weights[i] - 0.5 * value / tempering);
                if (weight == NULL || PyList_SetItem(log_weight, i, weight) < 0) {
                    failed = 1;
                    break;
                }
            }
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

/* bank_fuse_force_balance(filters, sensor, z, measure, r_variance, hold_start, hold_stop, empty,
 * result_type, fused, gated, log_weight, tempering) -> (results, jacobians, priors) as
 * FilterBank.update_force_balance returns them, every member's fusion done and, with log_weight
 * (the bank's list) and several members, each one's evidence added to it; None: not taken,
 * nothing changed. */
PyObject *
bank_fuse_force_balance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return fuse_members(args, nargs, FB_M);
}

/* bank_fuse_scalar(filters, sensor, z, measure, r_variance, hold_start, hold_stop, empty,
 * result_type, fused, gated, log_weight, tempering): FilterBank.update_scalar without `pseudo`,
 * as
 * bank_fuse_force_balance (z a float, measure(x) on the state array). */
PyObject *
bank_fuse_scalar(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    return fuse_members(args, nargs, 1);
}
