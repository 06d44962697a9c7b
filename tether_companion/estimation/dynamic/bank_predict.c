/* The bank's batch prediction over its members in one C call (part of _member_core).
 *
 * bank_predict_batch is FilterBank.predict_batch's member-by-member path where _member_core
 * runs (bank.py: that loop is the reference and the fallback), bit for bit: for every member
 * the state's step (member_core.c's step, BatchStep.step_state), the covariance's step (its
 * step_covariance, BatchStep.step_member_covariance) into new arrays, and the keeping of both
 * (MemberFilter.set_predicted with healthy true: _keep). One call instead of, per member, four
 * Python calls, two numpy allocations from Python and a numpy reduction.
 *
 * All members are computed first and nothing is written until every one is known to take the
 * common path; otherwise the call returns None with no member touched and the caller runs the
 * Python loop, which then does what it always did. The common path: every member's state and
 * covariance float64 arrays (a member holding lists is converted by its x / P properties, as
 * the loop's kf.x and kf.P convert it), finite, with the transition, the batch's sums and the
 * process noise as step() and step_covariance() take them; and every result healthy beyond
 * doubt: the stepped covariance finite and every stepped state entry finite and at most
 * DBL_MAX / n in magnitude, so that the loop's test, isfinite of numpy's sum of the state (in
 * numpy's order), is true whatever that order (a partial sum of n such terms cannot overflow).
 * Where it could be false the loop runs and decides (and repairs) as it always did.
 */
#include <float.h>

#include "member_core.h"

typedef struct {
    PyObject *x, *p, *x_new, *p_new; /* new references */
} Predicted;

static void
drop_all(Predicted *members, Py_ssize_t count)
{
    for (Py_ssize_t i = 0; i < count; i++) {
        Py_CLEAR(members[i].x);
        Py_CLEAR(members[i].p);
        Py_CLEAR(members[i].x_new);
        Py_CLEAR(members[i].p_new);
    }
}

/* One member stepped into new arrays made by `empty`: 1 when healthy beyond doubt (see the
 * top), 0 (no error set) when the loop must run, -1 with an error set. */
static int
predict_member(Predicted *mb, PyObject *kf, const double *phi, const double *d, const double *q,
               double t, int n, PyObject *empty, PyObject *shape_x, PyObject *shape_p)
{
    if (!(mb->x = held_array(kf, name_xa, name_x)) || !(mb->p = held_array(kf, name_pa, name_p)))
        return 0;
    Views v = {.count = 0};
    Py_buffer *vx, *vp, *vxo, *vpo;
    if (!(vx = take(&v, mb->x, 1, n, 0, 0)) || !(vp = take(&v, mb->p, 2, n, n, 0)) ||
        !all_finite(vx->buf, n) || !all_finite(vp->buf, (Py_ssize_t)n * n)) {
        release(&v);
        return 0;
    }
    if (!(mb->x_new = PyObject_CallOneArg(empty, shape_x)) ||
        !(mb->p_new = PyObject_CallOneArg(empty, shape_p))) {
        release(&v);
        return -1;
    }
    if (!(vxo = take(&v, mb->x_new, 1, n, 0, 1)) || !(vpo = take(&v, mb->p_new, 2, n, n, 1))) {
        release(&v);
        return 0;
    }
    double *xo = vxo->buf, *po = vpo->buf;
    member_step(phi, vx->buf, d, n, xo);
    member_step_covariance(phi, vp->buf, q, t, n, po);
    int healthy = all_finite(po, (Py_ssize_t)n * n);
    const double bound = DBL_MAX / n;
    for (int i = 0; i < n && healthy; i++)
        healthy = fabs(xo[i]) <= bound; /* false for nan */
    release(&v);
    return healthy;
}

/* predict_batch(filters, phi, d_p, d_v, q, t, empty) -> True: every member of the list
 * `filters` stepped over the batch (phi its (n, n) transition, d_p and d_v lists of 3 floats,
 * q the (n, n) process noise spectral density, t the batch's duration [s], empty numpy.empty)
 * and kept; None: not taken, nothing changed. */
PyObject *
bank_predict_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 7)
        return PyErr_Format(PyExc_TypeError, "predict_batch takes 7 arguments");
    PyObject *filters = args[0], *empty = args[6];
    if (!PyList_CheckExact(filters) || !PyFloat_Check(args[5]))
        Py_RETURN_NONE;
    Py_ssize_t count = PyList_GET_SIZE(filters);
    double t = PyFloat_AS_DOUBLE(args[5]), d[6];
    if (count < 1 || count > MAX_MEMBERS || !isfinite(t) || !read_numbers(args[2], d, 3) ||
        !read_numbers(args[3], d + 3, 3) || !all_finite(d, 6))
        Py_RETURN_NONE;
    Views v = {.count = 0};
    Py_buffer *vphi, *vq;
    if (!(vphi = take(&v, args[1], 2, ANY, ANY, 0)) || vphi->shape[0] != vphi->shape[1] ||
        vphi->shape[0] < 6 || vphi->shape[0] > MAX_N) {
        release(&v);
        Py_RETURN_NONE;
    }
    int n = (int)vphi->shape[0];
    const double *phi = vphi->buf;
    if (!(vq = take(&v, args[4], 2, n, n, 0)) || !all_finite(phi, (Py_ssize_t)n * n) ||
        !exactly_symmetric(vq->buf, n)) {
        release(&v);
        Py_RETURN_NONE;
    }
    PyObject *shape_x = Py_BuildValue("(n)", (Py_ssize_t)n);
    PyObject *shape_p = Py_BuildValue("(nn)", (Py_ssize_t)n, (Py_ssize_t)n);
    Predicted members[MAX_MEMBERS] = {{NULL}};
    int outcome = shape_x != NULL && shape_p != NULL ? 1 : -1;
    Py_ssize_t done = 0;
    for (; done < count && outcome == 1; done++)
        outcome = predict_member(&members[done], PyList_GET_ITEM(filters, done), phi, d, vq->buf,
                                 t, n, empty, shape_x, shape_p);
    release(&v);
    Py_XDECREF(shape_x);
    Py_XDECREF(shape_p);
    for (Py_ssize_t i = 0; i < count && outcome == 1; i++) { /* every member's _keep */
        PyObject *kf = PyList_GET_ITEM(filters, i);
        if (PyObject_SetAttr(kf, name_xa, members[i].x_new) < 0 ||
            PyObject_SetAttr(kf, name_xl, Py_None) < 0 ||
            PyObject_SetAttr(kf, name_pa, members[i].p_new) < 0 ||
            PyObject_SetAttr(kf, name_pl, Py_None) < 0)
            outcome = -1;
    }
    drop_all(members, done);
    if (outcome < 0)
        return NULL;
    if (outcome == 0)
        Py_RETURN_NONE;
    Py_RETURN_TRUE;
}
