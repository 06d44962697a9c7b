/* The members' per-tick matrix arithmetic in C (the optional extension _member_core).
 *
 * One member's arrays (C-contiguous float64, 2-D covariances), read and written through the
 * buffer protocol (no numpy C API); the outputs are arrays the caller made. The numpy code in
 * imu_batch.py and bank.py is the reference and the fallback: every function returns None
 * (and the caller runs the numpy code) where the arguments are not the arrays it was written
 * for (not float64, not C-contiguous, wrong shapes, more than MAX_N states) or an input is
 * not finite (the products below skip the transition's zero entries; numpy's 0 * inf gives
 * nan where they would not).
 *
 * Not bit for bit numpy: numpy's 17x17 products are OpenBLAS's dgemm / dgemv, whose summation
 * order and fused multiply-adds are the library's (and the CPU's). These loops sum in index
 * order, skip zero entries of the transition and fuse nothing (-ffp-contract=off): each entry
 * differs from numpy's by rounding only, and tests/test_member_core.py holds them to 1e-12
 * relative (issue 12, the lead's decision of 2026-11-27). The positive-definiteness test is a
 * Cholesky factorisation as LAPACK's dpotrf (a pivot not > 0 fails), in the same arithmetic.
 *
 * force_balance is the exception: scalar arithmetic written as member.solve_force_balance
 * writes it, bit for bit (tests/test_force_balance_core.py), the Python function called
 * wherever C could differ.
 *
 * bank_fusion.c (same extension, shared helpers in member_core.h) is the bank's whole
 * force-balance fusion over its members, bit for bit the bank's Python on these functions.
 */
#include "member_core.h"

/* out = phi x + (d[0..5], 0...) for the n x n phi and the n-state x (imu_batch's
 * BatchStep.step_state; step() and bank_predict.c): index-order sums over phi's nonzeros. */
void
member_step(const double *phi, const double *x, const double *d, int n, double *out)
{
    for (int i = 0; i < n; i++) {
        double value = 0.0;
        for (int k = 0; k < n; k++)
            if (phi[i * n + k] != 0.0)
                value += phi[i * n + k] * x[k];
        out[i] = i < 6 ? value + d[i] : value;
    }
}

/* step(phi, x, d_p, d_v, x_out) -> True: x_out = phi x + (d_p, d_v, 0...) (one state of
 * imu_batch.BatchStep.step_state; d_p, d_v lists of 3 floats); None: not taken. */
static PyObject *
step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5)
        return PyErr_Format(PyExc_TypeError, "step takes 5 arguments");
    double d[6];
    Views v = {.count = 0};
    Py_buffer *vx, *vphi, *vout;
    if (!read_numbers(args[2], d, 3) || !read_numbers(args[3], d + 3, 3) || !all_finite(d, 6) ||
        !(vx = take(&v, args[1], 1, ANY, 0, 0)) || vx->shape[0] < 6 || vx->shape[0] > MAX_N)
        goto not_taken;
    int n = (int)vx->shape[0];
    if (!(vphi = take(&v, args[0], 2, n, n, 0)) || !(vout = take(&v, args[4], 1, n, 0, 1)))
        goto not_taken;
    const double *x = vx->buf, *phi = vphi->buf;
    if (!all_finite(x, n) || !all_finite(phi, (Py_ssize_t)n * n))
        goto not_taken;
    member_step(phi, x, d, n, vout->buf);
    release(&v);
    Py_RETURN_TRUE;
not_taken:
    release(&v);
    Py_RETURN_NONE;
}

/* out = phi p phi^T + q t on the upper triangle, mirrored, for the n x n phi, p and q (p and q
 * symmetric, finite; out not p's memory): step_covariance()'s arithmetic (below) and
 * bank_predict.c's. */
void
member_step_covariance(const double *phi, const double *p, const double *q, double t, int n,
                       double *out)
{
    int count[MAX_N], col[MAX_N][MAX_N], unit[MAX_N];
    for (int i = 0; i < n; i++) {
        count[i] = 0;
        for (int k = 0; k < n; k++)
            if (phi[i * n + k] != 0.0)
                col[i][count[i]++] = k;
        unit[i] = count[i] == 1 && col[i][0] == i && phi[i * n + i] == 1.0;
    }
    double a[MAX_N * MAX_N];
    const double *a_row[MAX_N]; /* row i of A = phi p: p's own row for a unit row of phi */
    for (int i = 0; i < n; i++) {
        if (unit[i]) {
            a_row[i] = p + i * n;
            continue;
        }
        double *restrict row = a + i * n; /* sum_c phi_ic p_cj, c in index order, along j */
        for (int j = 0; j < n; j++)
            row[j] = 0.0;
        for (int c = 0; c < count[i]; c++) {
            const double f = phi[i * n + col[i][c]];
            const double *restrict p_row = p + col[i][c] * n;
            for (int j = 0; j < n; j++)
                row[j] += f * p_row[j];
        }
        a_row[i] = row;
    }
    for (int i = 0; i < n; i++) /* (A phi^T)_ij for j >= i, mirrored */
        for (int j = i; j < n; j++) {
            double value;
            if (unit[j])
                value = a_row[i][j];
            else {
                value = 0.0;
                for (int c = 0; c < count[j]; c++)
                    value += a_row[i][col[j][c]] * phi[j * n + col[j][c]];
            }
            out[i * n + j] = out[j * n + i] = value + q[i * n + j] * t;
        }
}

/* step_covariance(phi, p, q, t, out) -> bool: out = phi p phi^T + q t (one covariance of
 * imu_batch.BatchStep.step_covariance; p and q symmetric), whether out is finite; None: not
 * taken (also for a q not exactly symmetric, or out sharing p's memory: p's rows are read
 * while out is written).
 *
 * The product is computed once per entry of the upper triangle and mirrored, so out is exactly
 * symmetric without numpy's (A + A^T) / 2, and with phi's known sparsity: the zeros of phi are
 * skipped, and a unit row of phi (e_i: 1 on the diagonal, nothing else; the dynamic filter's
 * rows from 6 on) takes p's own row (phi p) or entry (A phi^T) without arithmetic. Only the
 * entries where both rows carry the batch's terms (the 6 x 6 position/velocity block) are sums
 * of sums; they differ from the symmetrised full product by rounding (tests/test_member_core.py
 * holds them to 1e-12 of the entry's scale). */
static PyObject *
step_covariance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 5)
        return PyErr_Format(PyExc_TypeError, "step_covariance takes 5 arguments");
    if (!PyFloat_Check(args[3]))
        Py_RETURN_NONE;
    double t = PyFloat_AS_DOUBLE(args[3]);
    Views v = {.count = 0};
    Py_buffer *vp, *vphi, *vq, *vout;
    if (!(vp = take(&v, args[1], 2, ANY, ANY, 0)) || vp->shape[0] != vp->shape[1] ||
        vp->shape[0] > MAX_N)
        goto not_taken;
    int n = (int)vp->shape[0];
    if (!(vphi = take(&v, args[0], 2, n, n, 0)) || !(vq = take(&v, args[2], 2, n, n, 0)) ||
        !(vout = take(&v, args[4], 2, n, n, 1)))
        goto not_taken;
    const double *p = vp->buf, *phi = vphi->buf, *q = vq->buf;
    double *out = vout->buf;
    if (!all_finite(p, (Py_ssize_t)n * n) || !all_finite(phi, (Py_ssize_t)n * n) || !isfinite(t) ||
        (const double *)out == p)
        goto not_taken;
    if (!exactly_symmetric(q, n))
        goto not_taken;
    member_step_covariance(phi, p, q, t, n, out);
    int ok = all_finite(out, (Py_ssize_t)n * n);
    release(&v);
    return PyBool_FromLong(ok);
not_taken:
    release(&v);
    Py_RETURN_NONE;
}

/* P H^T (n x m) into pht and H P H^T (m x m, row-major) into s for the m x n h (p finite):
 * index-order sums over h's nonzero entries (project() and bank_fusion.c). Skipping a zero of h
 * changes no bit: p's term is then +-0, and a sum begun at +0 is never -0, so adding it gives
 * the sum back. */
void
member_project(const double *p, const double *h, int n, int m, double *pht, double *s)
{
    int count[MAX_M], col[MAX_M][MAX_N];
    for (int r = 0; r < m; r++) {
        count[r] = 0;
        for (int k = 0; k < n; k++)
            if (h[r * n + k] != 0.0)
                col[r][count[r]++] = k;
    }
    for (int i = 0; i < n; i++)
        for (int r = 0; r < m; r++) {
            double value = 0.0;
            for (int c = 0; c < count[r]; c++)
                value += p[i * n + col[r][c]] * h[r * n + col[r][c]];
            pht[i * m + r] = value;
        }
    for (int r = 0; r < m; r++)
        for (int c = 0; c < m; c++) {
            double value = 0.0;
            for (int k = 0; k < count[r]; k++)
                value += h[r * n + col[r][k]] * pht[col[r][k] * m + c];
            s[r * m + c] = value;
        }
}

/* The update with the gain K = pht S^-1 into xo, po (update()'s arithmetic, and bank_fusion.c's):
 * xo = x + pht w, po = p - K pht^T (p symmetric) computed on the upper triangle and mirrored
 * (exactly symmetric; numpy's (B + B^T) / 2 of the full B differs by rounding), the consider
 * states hold_start .. hold_stop - 1 given back their prior mean and own block; whether xo and
 * po are finite and po positive definite. */
int
member_gain_update(const double *x, const double *p, const double *pht, const double *s_inv,
                   const double *w, int n, int m, Py_ssize_t hold_start, Py_ssize_t hold_stop,
                   double *xo, double *po)
{
    double k[MAX_N * MAX_M];
    for (int i = 0; i < n; i++) {
        double value = 0.0;
        for (int r = 0; r < m; r++)
            value += pht[i * m + r] * w[r];
        xo[i] = x[i] + value;
        for (int c = 0; c < m; c++) { /* K = pht S^-1 */
            double kv = 0.0;
            for (int r = 0; r < m; r++)
                kv += pht[i * m + r] * s_inv[r * m + c];
            k[i * m + c] = kv;
        }
    }
    for (int i = 0; i < n; i++)
        for (int j = i; j < n; j++) {
            double value = 0.0;
            for (int r = 0; r < m; r++)
                value += k[i * m + r] * pht[j * m + r];
            po[i * n + j] = po[j * n + i] = p[i * n + j] - value;
        }
    for (Py_ssize_t i = hold_start; i < hold_stop; i++) {
        xo[i] = x[i];
        for (Py_ssize_t j = hold_start; j < hold_stop; j++)
            po[i * n + j] = p[i * n + j];
    }
    return all_finite(xo, n) && all_finite(po, (Py_ssize_t)n * n) && cholesky_ok(po, n);
}

/* project(p, h, pht) -> S: pht = p h^T (n x m) and the m x m S = h p h^T (a tuple of m*m floats,
 * row-major) for the m x n h (a list or tuple of m*n floats or ints, or a float64 array);
 * None: not taken. */
static PyObject *
project(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 3)
        return PyErr_Format(PyExc_TypeError, "project takes 3 arguments");
    Views v = {.count = 0};
    Py_buffer *vp, *vpht, *vh;
    if (!(vp = take(&v, args[0], 2, ANY, ANY, 0)) || vp->shape[0] != vp->shape[1] ||
        vp->shape[0] > MAX_N || !(vpht = take(&v, args[2], 2, vp->shape[0], ANY, 1)) ||
        vpht->shape[1] < 1 || vpht->shape[1] > MAX_M)
        goto not_taken;
    int n = (int)vp->shape[0], m = (int)vpht->shape[1];
    double h[MAX_M * MAX_N];
    if (PyList_CheckExact(args[1]) || PyTuple_CheckExact(args[1])) {
        if (!read_numbers(args[1], h, (Py_ssize_t)m * n))
            goto not_taken;
    }
    else {
        if (!(vh = take(&v, args[1], 2, m, n, 0)))
            goto not_taken;
        memcpy(h, vh->buf, sizeof(double) * m * n);
    }
    const double *p = vp->buf;
    double *pht = vpht->buf;
    if (!all_finite(p, (Py_ssize_t)n * n) || !all_finite(h, (Py_ssize_t)m * n))
        goto not_taken;
    double hph[MAX_M * MAX_M];
    member_project(p, h, n, m, pht, hph);
    release(&v);
    PyObject *s = PyTuple_New(m * m);
    if (s == NULL)
        return NULL;
    for (int i = 0; i < m * m; i++) {
        PyObject *item = PyFloat_FromDouble(hph[i]);
        if (item == NULL) {
            Py_DECREF(s);
            return NULL;
        }
        PyTuple_SET_ITEM(s, i, item);
    }
    return s;
not_taken:
    release(&v);
    Py_RETURN_NONE;
}

/* update(x, p, pht, s_inv, w, hold_start, hold_stop, x_out, p_out) -> bool: the update with the
 * gain K = pht S^-1 (pht n x m, s_inv the m x m S^-1 and w = S^-1 y as lists or tuples of
 * floats): x_out = x + pht w, p_out = (B + B^T) / 2 with B = p - K pht^T, the consider states
 * hold_start..hold_stop - 1 (none when equal) given back their prior mean and own covariance
 * block (member.hold_consider); whether x_out and p_out are finite and p_out positive definite
 * (bank._finite_and_definite); None: not taken. */
static PyObject *
update(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 9)
        return PyErr_Format(PyExc_TypeError, "update takes 9 arguments");
    Views v = {.count = 0};
    Py_buffer *vx, *vp, *vpht, *vxo, *vpo;
    double s_inv[MAX_M * MAX_M], w[MAX_M];
    if (!(vp = take(&v, args[1], 2, ANY, ANY, 0)) || vp->shape[0] != vp->shape[1] ||
        vp->shape[0] > MAX_N)
        goto not_taken;
    int n = (int)vp->shape[0];
    if (!(vpht = take(&v, args[2], 2, n, ANY, 0)) || vpht->shape[1] < 1 || vpht->shape[1] > MAX_M)
        goto not_taken;
    int m = (int)vpht->shape[1];
    if (!(vx = take(&v, args[0], 1, n, 0, 0)) || !(vxo = take(&v, args[7], 1, n, 0, 1)) ||
        !(vpo = take(&v, args[8], 2, n, n, 1)) || !read_numbers(args[3], s_inv, (Py_ssize_t)m * m) ||
        !read_numbers(args[4], w, m))
        goto not_taken;
    Py_ssize_t hold_start = PyLong_AsSsize_t(args[5]), hold_stop = PyLong_AsSsize_t(args[6]);
    if ((hold_start == -1 || hold_stop == -1) && PyErr_Occurred()) {
        release(&v);
        return NULL;
    }
    if (hold_start < 0 || hold_stop > n || hold_start > hold_stop)
        goto not_taken;
    const double *x = vx->buf, *p = vp->buf, *pht = vpht->buf;
    double *xo = vxo->buf, *po = vpo->buf;
    if (!all_finite(x, n) || !all_finite(p, (Py_ssize_t)n * n) || !all_finite(pht, (Py_ssize_t)n * m) ||
        !all_finite(s_inv, m * m) || !all_finite(w, m))
        goto not_taken;
    int ok = member_gain_update(x, p, pht, s_inv, w, n, m, hold_start, hold_stop, xo, po);
    release(&v);
    return PyBool_FromLong(ok);
not_taken:
    release(&v);
    Py_RETURN_NONE;
}

/* member.solve_force_balance's scalars (force_balance() and bank_fusion.c): 1 with log det S
 * and out = (nis, S^-1 row-major (9), S^-1 y (3)); 0 when S is not positive definite, out[0]
 * the sum of its upper entries; -1 where C could differ (a non-finite input, sum or result:
 * the Python's). */
int
member_solve_force_balance(const double *s, const double *y, double r, double *log_det_out,
                           double *out)
{
    double s00 = s[0], s01 = s[1], s02 = s[2], s11 = s[4], s12 = s[5], s22 = s[8];
    if (!isfinite(s00 + s01 + s02 + s11 + s12 + s22 + r + y[0] + y[1] + y[2]) ||
        !isfinite(s[3] + s[6] + s[7]))
        return -1;
    s00 += r;
    s11 += r;
    s22 += r;
    double m01 = s00 * s11 - s01 * s01;
    double c0 = s11 * s22 - s12 * s12, c1 = s02 * s12 - s01 * s22, c2 = s01 * s12 - s02 * s11;
    double det = s00 * c0 + s01 * c1 + s02 * c2;
    if (!(s00 > 0.0 && m01 > 0.0 && det > 0.0)) {
        double s_sum = s00 + s11 + s22 + s01 + s02 + s12;
        out[0] = s_sum;
        return isfinite(s_sum) ? 0 : -1;
    }
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
        return -1;
    const double values[13] = {nis, i00, i01, i02, i01, i11, i12, i02, i12, i22, w0, w1, w2};
    memcpy(out, values, sizeof(values));
    *log_det_out = log_det;
    return 1;
}

/* force_balance(fallback, s_values, innovation, r_variance): member.solve_force_balance's
 * scalars, bit for bit: the same IEEE operations in the same order (no contraction), log()
 * as math.log. The fallback (the Python function) runs where C could differ: an argument
 * not exact floats of the right count, or any non-finite input or result (a NaN's sign and
 * payload depend on which operand the compiler puts first). */
static PyObject *
force_balance(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    if (nargs != 4)
        return PyErr_Format(PyExc_TypeError, "force_balance takes the fallback and 3 arguments");
    double s[9], y[3];
    if (!read_exact_floats(args[1], 9, s) || !read_exact_floats(args[2], 3, y) ||
        !PyFloat_CheckExact(args[3]))
        return PyObject_Vectorcall(args[0], args + 1, 3, NULL);
    double log_det, out[13];
    switch (member_solve_force_balance(s, y, PyFloat_AS_DOUBLE(args[3]), &log_det, out)) {
    case 1:
        return Py_BuildValue("(d(ddddddddddddd))", log_det, out[0], out[1], out[2], out[3],
                             out[4], out[5], out[6], out[7], out[8], out[9], out[10], out[11],
                             out[12]);
    case 0:
        return Py_BuildValue("(dd)", (double)NAN, out[0]);
    default:
        return PyObject_Vectorcall(args[0], args + 1, 3, NULL);
    }
}

static PyMethodDef methods[] = {
    {"step", (PyCFunction)(void (*)(void))step, METH_FASTCALL,
     "step(phi, x, d_p, d_v, x_out): x_out = phi x + (d_p, d_v, 0...); None: not taken."},
    {"step_covariance", (PyCFunction)(void (*)(void))step_covariance, METH_FASTCALL,
     "step_covariance(phi, p, q, t, out): out = sym(phi p phi^T) + q t; whether finite."},
    {"project", (PyCFunction)(void (*)(void))project, METH_FASTCALL,
     "project(p, h, pht): pht = p h^T; returns S = h p h^T (m*m floats)."},
    {"update", (PyCFunction)(void (*)(void))update, METH_FASTCALL,
     "update(x, p, pht, s_inv, w, hold_start, hold_stop, x_out, p_out): the gain's update; "
     "whether finite and positive definite."},
    {"mixture", (PyCFunction)(void (*)(void))member_mixture_moments, METH_FASTCALL,
     "mixture(w, xs, ps, mean_out, cov_out): the weighted mixture's moments."},
    {"force_balance", (PyCFunction)(void (*)(void))force_balance, METH_FASTCALL,
     "force_balance(fallback, s_values, innovation, r_variance): member.solve_force_balance "
     "bit for bit (the fallback where C could differ)."},
    {"fuse_force_balance", (PyCFunction)(void (*)(void))bank_fuse_force_balance, METH_FASTCALL,
     "fuse_force_balance(filters, sensor, z, measure, r_variance, hold_start, hold_stop, empty, "
     "result_type, fused, gated, log_weight, tempering): bank.FilterBank.update_force_balance "
     "over every member, bit for bit (bank_fusion.c); None: not taken, nothing changed."},
    {"fuse_scalar", (PyCFunction)(void (*)(void))bank_fuse_scalar, METH_FASTCALL,
     "fuse_scalar(filters, sensor, z, measure, r_variance, hold_start, hold_stop, empty, "
     "result_type, fused, gated, log_weight, tempering): bank.FilterBank.update_scalar (no "
     "pseudo) over every member, bit for bit (bank_fusion.c); None: not taken, nothing changed."},
    {"bank_healthy_members", (PyCFunction)(void (*)(void))bank_healthy_members, METH_FASTCALL,
     "bank_healthy_members(filters, limit): the indices bank.FilterBank.drop_unhealthy keeps, "
     "bit for bit (bank_health.c); None: not taken."},
    {"bank_mixture", (PyCFunction)(void (*)(void))bank_mixture, METH_FASTCALL,
     "bank_mixture(filters, log_weight, cache, empty): bank.FilterBank.mixture's cache test and "
     "moments over two or more members, bit for bit (bank_mixture.c): the cache kept (the same "
     "object, or a new one); None: not taken."},
    {"predict_batch", (PyCFunction)(void (*)(void))bank_predict_batch, METH_FASTCALL,
     "predict_batch(filters, phi, d_p, d_v, q, t, empty): bank.FilterBank.predict_batch's "
     "member-by-member step over every member, bit for bit (bank_predict.c); None: not taken, "
     "nothing changed."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "_member_core",
    "One bank member's matrix arithmetic in C (bank.py's and imu_batch.py's numpy to 1e-12).", -1,
    methods,
};

PyObject *name_xa, *name_pa, *name_xl, *name_pl, *name_x, *name_p;

PyMODINIT_FUNC
PyInit__member_core(void)
{
    if (!(name_xa = PyUnicode_InternFromString("_xa")) ||
        !(name_pa = PyUnicode_InternFromString("_pa")) ||
        !(name_xl = PyUnicode_InternFromString("_xl")) ||
        !(name_pl = PyUnicode_InternFromString("_pl")) ||
        !(name_x = PyUnicode_InternFromString("x")) || !(name_p = PyUnicode_InternFromString("P")))
        return NULL;
    return PyModule_Create(&module_def);
}
