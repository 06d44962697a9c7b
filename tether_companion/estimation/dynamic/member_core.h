/* The helpers shared by _member_core's sources (member_core.c: one member's arrays;
 * bank_fusion.c: the bank's fusion over its members): buffers of C-contiguous float64 arrays,
 * the finite test, numbers from lists, the Cholesky test.
 */
#ifndef TETHER_MEMBER_CORE_H
#define TETHER_MEMBER_CORE_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#include "../exact_floats.h"

#define MAX_N 32 /* the largest state handled here (the dynamic filter has 17) */
#define MAX_M 3  /* the largest measurement (the force balance: 3 axes) */
#define MAX_MEMBERS 64 /* the most bank members mixture() takes */
#define ANY (-1)

/* The members' attribute names the bank's sources read (bank_fusion.c, bank_health.c,
 * bank_mixture.c, bank_predict.c), interned once when the module loads (member_core.c). */
extern PyObject *name_xa, *name_pa, *name_xl, *name_pl, *name_x, *name_p;

/* A C-contiguous float64 buffer of `obj` with `ndim` dimensions of sizes d0, d1 (ANY: any);
 * 0 without an error set when it is not one. */
static inline int
get(PyObject *obj, Py_buffer *view, int ndim, Py_ssize_t d0, Py_ssize_t d1, int writable)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) != 0) {
        PyErr_Clear();
        return 0;
    }
    if (view->ndim != ndim || view->itemsize != 8 || view->format == NULL ||
        strcmp(view->format, "d") != 0 || (d0 != ANY && view->shape[0] != d0) ||
        (ndim == 2 && d1 != ANY && view->shape[1] != d1)) {
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

/* The buffers of one call, released together. */
typedef struct {
    Py_buffer views[8];
    int count;
} Views;

static inline Py_buffer *
take(Views *v, PyObject *obj, int ndim, Py_ssize_t d0, Py_ssize_t d1, int writable)
{
    Py_buffer *view = &v->views[v->count];
    if (!get(obj, view, ndim, d0, d1, writable))
        return NULL;
    v->count++;
    return view;
}

static inline void
release(Views *v)
{
    for (int i = 0; i < v->count; i++)
        PyBuffer_Release(&v->views[i]);
    v->count = 0;
}

/* Whether every one of the count doubles at a is finite: a[i] * 0 is nan for a nan or an
 * infinity and +-0 otherwise, so the sum of these products is nan exactly when one is, in any
 * order (four sums: the loop vectorises). */
static inline int
all_finite(const double *a, Py_ssize_t count)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    Py_ssize_t i = 0;
    for (; i + 4 <= count; i += 4) {
        s0 += a[i] * 0.0;
        s1 += a[i + 1] * 0.0;
        s2 += a[i + 2] * 0.0;
        s3 += a[i + 3] * 0.0;
    }
    for (; i < count; i++)
        s0 += a[i] * 0.0;
    return (s0 + s1) + (s2 + s3) == 0.0;
}

/* Whether the n x n q is exactly symmetric (q_ij == q_ji bit for bit, nan never). */
static inline int
exactly_symmetric(const double *q, int n)
{
    for (int i = 0; i < n; i++)
        for (int j = i + 1; j < n; j++)
            if (q[i * n + j] != q[j * n + i])
                return 0;
    return 1;
}

/* A member's held array (attribute `held`, "_xa" / "_pa"), or where it holds a list (None there)
 * its property `name` ("x" / "P"), which converts it as Python's kf.x / kf.P do; NULL with no
 * error set where neither gives one. */
static inline PyObject *
held_array(PyObject *kf, PyObject *held, PyObject *name)
{
    PyObject *value = PyObject_GetAttr(kf, held);
    if (value == Py_None) {
        Py_DECREF(value);
        value = PyObject_GetAttr(kf, name);
    }
    if (value == NULL)
        PyErr_Clear();
    return value;
}

/* The floats of a list or tuple of exactly n floats or ints into out; 0 (no error set) otherwise. */
static inline int
read_numbers(PyObject *obj, double *out, Py_ssize_t n)
{
    if (!(PyList_CheckExact(obj) || PyTuple_CheckExact(obj)) || PySequence_Fast_GET_SIZE(obj) != n)
        return 0;
    PyObject **items = PySequence_Fast_ITEMS(obj);
    for (Py_ssize_t i = 0; i < n; i++) {
        if (PyFloat_Check(items[i]))
            out[i] = PyFloat_AS_DOUBLE(items[i]);
        else if (PyLong_CheckExact(items[i])) {
            out[i] = PyLong_AsDouble(items[i]);
            if (out[i] == -1.0 && PyErr_Occurred()) {
                PyErr_Clear();
                return 0;
            }
        }
        else
            return 0;
    }
    return 1;
}

/* Whether the symmetric n x n matrix a (its upper triangle read) is positive definite: every
 * pivot of its Cholesky factorisation > 0 (dpotrf's test; a nan fails it). Right-looking on the
 * rows of U = L^T: each entry takes the same subtractions in the same order as the
 * left-looking dot products (l_ik l_jk = u_ki u_kj), so the same pivots bit for bit, but the
 * inner loop runs along contiguous rows (vectorised). */
static inline int
cholesky_ok(const double *a, int n)
{
    double u[MAX_N * MAX_N];
    for (int j = 0; j < n; j++)
        memcpy(u + j * n + j, a + j * n + j, sizeof(double) * (size_t)(n - j));
    for (int j = 0; j < n; j++) {
        double *restrict row_j = u + j * n;
        double d = row_j[j];
        if (!(d > 0.0))
            return 0;
        d = sqrt(d);
        for (int c = j + 1; c < n; c++)
            row_j[c] /= d;
        for (int i = j + 1; i < n; i++) {
            double *restrict row_i = u + i * n;
            const double f = row_j[i];
            for (int c = i; c < n; c++)
                row_i[c] -= f * row_j[c];
        }
    }
    return 1;
}


/* member_core.c's arithmetic, shared with bank_fusion.c and bank_predict.c */
void member_step(const double *phi, const double *x, const double *d, int n, double *out);
void member_step_covariance(const double *phi, const double *p, const double *q, double t, int n,
                            double *out);
void member_project(const double *p, const double *h, int n, int m, double *pht, double *s);
int member_gain_update(const double *x, const double *p, const double *pht, const double *s_inv,
                       const double *w, int n, int m, Py_ssize_t hold_start, Py_ssize_t hold_stop,
                       double *xo, double *po);
int member_solve_force_balance(const double *s, const double *y, double r, double *log_det_out,
                               double *out);

/* bank_fusion.c */
PyObject *bank_fuse_force_balance(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *bank_fuse_scalar(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

/* bank_predict.c */
PyObject *bank_predict_batch(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

/* bank_health.c */
PyObject *bank_healthy_members(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

/* bank_mixture.c */
PyObject *member_mixture_moments(PyObject *self, PyObject *const *args, Py_ssize_t nargs);
PyObject *bank_mixture(PyObject *self, PyObject *const *args, Py_ssize_t nargs);

#endif
