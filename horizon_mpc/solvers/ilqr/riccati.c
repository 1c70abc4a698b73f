/*
 * Backward Riccati recursion and linear rollout of the multiple-shooting ILQR, in C.
 *
 * The same algorithm as horizon_mpc/solvers/ilqr/riccati.py (its docstrings have the maths);
 * riccati_c.py compiles this file once with plain `gcc -O3 -fPIC -shared` (no -march: the
 * library may be shared between machines; no -ffast-math: NaN and inf must propagate as they
 * do in numpy) and calls riccati_backward / riccati_rollout through ctypes.
 *
 * Conventions
 *  - Every matrix is row-major. Inputs are read through element strides, so numpy views
 *    (e.g. the transposed CasADi buffers of the solver) need no copy: each node's blocks are
 *    gathered into a small workspace, allocated once per call.
 *  - One product kernel: C = P, C + P or C - P with P = op(X) Y, op(X)(i, k) = X[i*xi + k*xk]
 *    (so X Y and X^T Y alike), Y and C row-major: a register tile of 4 rows x 2 vectors whose
 *    inner loop runs along contiguous rows.
 *  - Cholesky factors are upper triangular (H = U^T U) and built from the LOWER triangle of H,
 *    as LAPACK's potrf(lower) behind scipy's cho_factor reads it; a pivot that is not > 0
 *    (NaN included) is a failure.
 *  - With a projection, the columns of Z that are exactly zero (the range of D^T) are left
 *    out of the products: they only add decoupled unit pivots to H.
 *  - The kernels are compiled twice by including this file into itself: with 2-wide vectors
 *    for the baseline ISA (SSE2, NEON) and, on x86-64 with gcc, with 4-wide vectors for
 *    AVX2+FMA; the CPU is asked at run time which one to use.
 */
#ifndef RICCATI_KERNEL_PASS
/* ================================================================== common part */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "riccati.h"  /* the entry points and their argument orders */

#define BOX_QP_MAX_ITER 100  /* riccati.py's */
#define INPUT_ATOL 1e-13  /* equality.py's */
#define NB 4  /* rows per block of the Cholesky factorisation and solves (= the tile rows) */

/* doubles of workspace of riccati_backward */
static size_t workspace_size(int ndx, int nu)
{
    size_t m = (size_t)ndx + (size_t)nu, x = (size_t)ndx, u = (size_t)nu;
    return 2 * x * m + 3 * x + m + 5 * u * u + 5 * u * x + 10 * u;
}

/* element (i, r, c) of input k, through its strides */
#define EL(k, i, r, c) (in[k] + (ptrdiff_t)(i) * st[3 * (k)] + (ptrdiff_t)(r) * st[3 * (k) + 1] \
                        + (ptrdiff_t)(c) * st[3 * (k) + 2])

/* 1 if a node's box (lo, hi: nu values of element strides ls, hs) has a finite bound */
static int boxed(int nu, const double *lo, const double *hi, ptrdiff_t ls, ptrdiff_t hs)
{
    for (int a = 0; a < nu; a++)
        if (isfinite(lo[a * ls]) || isfinite(hi[a * hs])) return 1;
    return 0;
}

#define RICCATI_KERNEL_PASS 1
/* ---- baseline ISA: 2-wide vectors */
#define VW 2
#define ISA(name) name##_base
#include __FILE__
#undef VW
#undef ISA

#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define HAVE_AVX2 1
/* ---- AVX2 + FMA: 4-wide vectors (a*b + c contracts to fma: -ffp-contract=fast is gcc's
 * default outside ISO C mode) */
#pragma GCC push_options
#pragma GCC target("avx2,fma")
#define VW 4
#define ISA(name) name##_avx2
#include __FILE__
#undef VW
#undef ISA
#pragma GCC pop_options
#else
#define HAVE_AVX2 0
#endif

/* ================================================================== entry points */

/* 1 if this CPU can run the AVX2+FMA kernels (and they were compiled), else 0. */
int riccati_has_avx2(void)
{
#if HAVE_AVX2
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
    return 0;
#endif
}

/* variant: 0 automatic, 1 baseline ISA. */
static int use_avx2(int variant) { return variant != 1 && riccati_has_avx2(); }

/*
 * Riccati recursion of riccati.py's backward_pass.
 *  in[N_IN]: A, B, lx, lu, lxx, luu, lux, f, lxN, lxxN, P_e, P_x, Z, free (these four
 *      are only read at nodes flagged in con), lo, hi ((N, nu) bounds of du, -inf/inf for
 *      none, or both NULL: riccati.py's box, read at the other nodes); st[3 * N_IN]: element
 *      strides of each (node, row, column; the 1-D lxN uses the first of its triple, the
 *      2-D lxxN the first two).
 *  mu: added to the diagonal of every Q_uu.
 *  con: N flags (node with projected equality rows) or NULL.
 *  pat: NULL (A and B dense) or the structural nonzeros of [A | B] (ndx x (ndx + nu)), the
 *      same at every node, in compressed columns: column pointers (ndx + nu + 1 ints), then
 *      the row of each nonzero, ascending in each column. Entries outside it are not read
 *      (taken as zero). The products with A and B then cost O(nnz ndx), not O(ndx^3).
 *  out[N_OUT]: K (N, nu, ndx), k (N, nu), S (N+1, ndx, ndx), s (N+1, ndx), Qu (N, nu),
 *      Quu (N, nu, nu), Qux (N, nu, ndx), all C-contiguous.
 *  variant: 0 automatic, 1 baseline ISA.
 * Returns 0; 1: a (reduced) Q_uu is not positive definite at node *fail_node; 2: k is not
 * finite at node *fail_node; -1: out of memory.
 */
int riccati_backward(int N, int ndx, int nu, const double *const *in, const int64_t *st,
                     double mu, const uint8_t *con, const int *pat, double *const *out,
                     int variant, int *fail_node)
{
    double *w = malloc(sizeof(double) * (workspace_size(ndx, nu) + 1));
    double *vals = malloc(sizeof(double) * ((pat ? (size_t)pat[ndx + nu] : 0) + 1));
    int *cols = malloc(sizeof(int) * (2 * (size_t)nu + 1));
    int ret = -1;
    *fail_node = -1;
    if (w && vals && cols) {
#if HAVE_AVX2
        if (use_avx2(variant))
            ret = backward_avx2(N, ndx, nu, in, st, mu, con, pat, out, fail_node, w, vals,
                                cols);
        else
#endif
            ret = backward_base(N, ndx, nu, in, st, mu, con, pat, out, fail_node, w, vals,
                                cols);
    }
    free(cols);
    free(vals);
    free(w);
    return ret;
}

/*
 * Linear rollout of riccati.py's linear_rollout.
 *  in[N_RO]: A, B, f, K, k, dx0, lo, hi (the box du is clamped into, or both NULL);
 *      st[3 * N_RO]: their element strides (node, row, column).
 *  dX (N+1, ndx), dU (N, nu): C-contiguous outputs.
 * Returns 0, or -1: out of memory.
 */
int riccati_rollout(int N, int ndx, int nu, const double *const *in, const int64_t *st,
                    double *dX, double *dU, int variant)
{
    double *w = malloc(sizeof(double) * ((size_t)ndx + 1));
    if (!w) return -1;
#if HAVE_AVX2
    if (use_avx2(variant)) rollout_avx2(N, ndx, nu, in, st, dX, dU, w);
    else
#endif
        rollout_base(N, ndx, nu, in, st, dX, dU, w);
    free(w);
    return 0;
}

/*
 * Null-space parametrisation of the equality rows of every node (equality.py's batched QR).
 *  W (N m + 1, nu + ndx + 1), C-contiguous: slot j of node i is row i m + j = [D | C | e]
 *      (equality.py's _stack_rows); rows (N m): 1 where the slot holds a real row.
 *  rtol: the rows are independent when ||R||_F ||R^-1||_F < 1 / rtol (R of D_c^T = Q R).
 *  Outputs, C-contiguous, every element written: P_e (N, nu), P_x (N, nu, ndx),
 *  Z (N, nu, nu) (range columns exactly zero), free (N, nu), pinv (N, nu, m) (D^+, zero on
 *  unused slots), ok (N) (0: more rows than inputs, (nearly) dependent or non-finite rows:
 *  the caller takes the SVD there; outputs of such a node are unspecified), unmet (N).
 * Per node with c rows (in slot order): Householder QR of D_c^T (nu x c); Q formed
 * explicitly; D^+ = Q[:, :c] R^-T, P_x = -D^+ C_c, P_e = -D^+ e_c, Z = Q[:, c:].
 * Returns 0, or -1: out of memory.
 */
int riccati_project(int N, int m, int nu, int ndx, const double *W, const uint8_t *rows,
                    double rtol, double *P_e, double *P_x, double *Z, double *fr,
                    double *pinv, uint8_t *ok, uint8_t *unmet, int variant)
{
#if HAVE_AVX2
    if (use_avx2(variant))
        return project_avx2(N, m, nu, ndx, W, rows, rtol, P_e, P_x, Z, fr, pinv, ok, unmet);
#endif
    return project_base(N, m, nu, ndx, W, rows, rtol, P_e, P_x, Z, fr, pinv, ok, unmet);
}

/* max of |x| that propagates NaN as numpy's max does */
static inline void absmax(double x, double *vmax, int *nan)
{
    double a = fabs(x);
    if (a > *vmax) *vmax = a;
    else if (a != a) *nan = 1;
}

/*
 * The scalar measures of a step (solver.py's _step; merit.py's step_stats in numpy). Inputs
 * C-contiguous: lx (N, ndx), lu (N, nu), lxN (ndx); the backward pass's s (N+1, ndx),
 * S (N+1, ndx, ndx), Qu (N, nu), Quu (N, nu, nu), Qux (N, nu, ndx); the step dX (N+1, ndx),
 * dU (N, nu); pinv (N, nu, m) (the projection's D^+, or NULL).
 *  out[4]: the directional derivative of the cost lx.dX + lu.dU + lxN.dX_N; the largest
 *      multiplier estimate: |s + S dX| (costates) and, with pinv, |D^+^T (Qu + Quu dU +
 *      Qux dX)| (the projected rows'); max |dX|; max |dU| (0 without inputs). A NaN
 *      anywhere in a maximum's terms makes it NaN.
 * Returns 0, or -1: out of memory.
 */
int riccati_step_stats(int N, int ndx, int nu, int m, const double *lx, const double *lu,
                       const double *lxN, const double *s, const double *S,
                       const double *Qu, const double *Quu, const double *Qux,
                       const double *dX, const double *dU, const double *pinv, double *out)
{
    double slope = 0.0, lmax = 0.0, xmax = 0.0, umax = 0.0;
    int lnan = 0, xnan = 0, unan = 0;
    double *g = malloc(sizeof(double) * ((size_t)nu + 1));
    if (!g) return -1;
    for (int i = 0; i <= N; i++) {
        const double *x = dX + (size_t)i * ndx;
        const double *Si = S + (size_t)i * ndx * ndx, *si = s + (size_t)i * ndx;
        for (int a = 0; a < ndx; a++) {
            double v = si[a];
            for (int k = 0; k < ndx; k++) v += Si[(size_t)a * ndx + k] * x[k];
            absmax(v, &lmax, &lnan);
            absmax(x[a], &xmax, &xnan);
            slope += (i < N ? lx[(size_t)i * ndx + a] : lxN[a]) * x[a];
        }
        if (i == N) break;
        const double *u = dU + (size_t)i * nu;
        for (int a = 0; a < nu; a++) {
            slope += lu[(size_t)i * nu + a] * u[a];
            absmax(u[a], &umax, &unan);
        }
        if (!pinv || !m) continue;
        for (int a = 0; a < nu; a++) {
            const double *quu = Quu + ((size_t)i * nu + a) * nu;
            const double *qux = Qux + ((size_t)i * nu + a) * ndx;
            double v = Qu[(size_t)i * nu + a];
            for (int k = 0; k < nu; k++) v += quu[k] * u[k];
            for (int k = 0; k < ndx; k++) v += qux[k] * x[k];
            g[a] = v;
        }
        const double *P = pinv + (size_t)i * nu * m;
        for (int j = 0; j < m; j++) {
            double v = 0.0;
            for (int a = 0; a < nu; a++) v -= P[(size_t)a * m + j] * g[a];
            absmax(v, &lmax, &lnan);
        }
    }
    free(g);
    out[0] = slope;
    out[1] = lnan ? NAN : lmax;
    out[2] = xnan ? NAN : xmax;
    out[3] = unan ? NAN : umax;
    return 0;
}

/*
 * Augmented-Lagrangian / relaxed-barrier terms of n constraint rows (lagrangian.py's
 * AugmentedLagrangian.value, .violation and .weights_targets in one pass).
 *  c, lb, ub, lam, lam_lo, lam_up, rho: n doubles each, C-contiguous (lb == ub finite: an
 *      equality; an infinite bound: no such side).
 *  barrier: 1 relaxed log barrier of weight mu and relaxation delta on the inequality sides,
 *      0 the augmented Lagrangian of lam_lo, lam_up.
 *  w, t (may be NULL): Gauss-Newton weight and target of each row; viol (may be NULL):
 *      max(lb - c, c - ub, 0) of each row.
 *  sums[2]: the summed terms and the largest violation.
 */
static void barrier_side(double h, double mu, double delta, double *value, double *d1,
                         double *d2)
{
    if (h > delta) {
        *value = -mu * log(h / delta);
        *d1 = -mu / h;
        *d2 = mu / (h * h);
    } else {
        double z = (h - 2.0 * delta) / delta;
        *value = 0.5 * mu * (z * z - 1.0);
        *d1 = (mu / delta) * z;
        *d2 = mu / (delta * delta);
    }
}

void riccati_al_rows(int n, const double *c, const double *lb, const double *ub,
                     const double *lam, const double *lam_lo, const double *lam_up,
                     const double *rho, int barrier, double mu, double delta, double *w,
                     double *t, double *viol, double *sums)
{
    double total = 0.0, vmax = 0.0;
    for (int i = 0; i < n; i++) {
        double ci = c[i], lo = lb[i], up = ub[i], r = rho[i], wi = 0.0, ti = 0.0;
        double v = lo - ci;
        if (ci - up > v) v = ci - up;
        if (!(v > 0.0)) v = 0.0;
        if (v > vmax) vmax = v;
        if (viol) viol[i] = v;
        if (isfinite(lo) && lo == up) {
            double e = ci - lo;
            total += lam[i] * e + 0.5 * r * e * e;
            wi = 0.5 * r;
            ti = lo - lam[i] / r;
        } else if (barrier) {
            double g = 0.0, h = 0.0, b, d1, d2;
            int any = 0;
            if (isfinite(up)) {
                barrier_side(up - ci, mu, delta, &b, &d1, &d2);
                total += b; g -= d1; h += d2; any = 1;
            }
            if (isfinite(lo)) {
                barrier_side(ci - lo, mu, delta, &b, &d1, &d2);
                total += b; g += d1; h += d2; any = 1;
            }
            if (any) {
                wi = 0.5 * h;
                ti = ci - g / h;
            }
        } else {
            int active_up = 0;
            if (isfinite(up)) {
                double s = lam_up[i] + r * (ci - up), s0 = s > 0.0 ? s : 0.0;
                total += (s0 * s0 - lam_up[i] * lam_up[i]) / (2.0 * r);
                if (s > 0.0) {
                    active_up = 1;
                    wi = 0.5 * r;
                    ti = up - lam_up[i] / r;
                }
            }
            if (isfinite(lo)) {
                double s = lam_lo[i] + r * (lo - ci), s0 = s > 0.0 ? s : 0.0;
                total += (s0 * s0 - lam_lo[i] * lam_lo[i]) / (2.0 * r);
                if (s > 0.0 && !active_up) {
                    wi = 0.5 * r;
                    ti = lo + lam_lo[i] / r;
                }
            }
        }
        if (w) w[i] = wi;
        if (t) t[i] = ti;
    }
    sums[0] = total;
    sums[1] = vmax;
}

/*
 * The rows [D | C | e] of every node for riccati_project (equality.py's _stack_rows).
 *  Slots of node i: k "own" slots (constraint rows own_cols[s] of node i: D = cu, C = cx,
 *  e = c - b), then m - k "next" slots: the state rows nxt_cols[t] (t < j) of node i+1
 *  moved onto node i through the dynamics (J = cx of node i+1: D = J B_i, C = J A_i,
 *  e = c - b + J gap_i) or, at node N-1, the terminal rows term_cols[t] (t < jt: J = cxN,
 *  e = cN - bN + J gap); slots without a row are zero.
 *  in[N_SR]: c, b (N, nc), cx (N, nc, ndx), cu (N, nc, nu), cN, bN (ncN), cxN (ncN, ndx),
 *      A (N, ndx, ndx), B (N, ndx, nu), gap (N, ndx); st[3 * N_SR]: element strides (as
 *      riccati_backward's).
 *  own, nxt (N, nc): C-contiguous masks of the projected rows (EqualityLayout).
 *  pat: the structural nonzeros of [A | B] (riccati_backward's), or NULL (dense).
 *  W (N m + 1, nu + ndx + 1) and rows (N m): C-contiguous outputs, every element written
 *  (the last row of W is zero; rows: 1 where the slot holds a projected row).
 * Returns 0, or -1: out of memory.
 */
int riccati_stack_rows(int N, int nu, int ndx, int nc, int m, int k, int j, int jt,
                       const int *own_cols, const int *nxt_cols, const int *term_cols,
                       const double *const *in, const int64_t *st, const uint8_t *own,
                       const uint8_t *nxt, const int *pat, double *W, uint8_t *rows)
{
    const int w = nu + ndx + 1, nab = ndx + nu, jm = j > jt ? j : jt;
    /* strides in locals: the uint8 stores below may alias anything, st included */
    ptrdiff_t s[N_SR][3];
    for (int q = 0; q < N_SR; q++)
        for (int d = 0; d < 3; d++) s[q][d] = (ptrdiff_t)st[3 * q + d];
    const double *c = in[SR_C], *bnd = in[SR_BND], *cx = in[SR_CX], *cu = in[SR_CU],
                 *cN = in[SR_CN], *bN = in[SR_BNDN], *cxN = in[SR_CXN], *gap = in[SR_GAP];
    /* J^T (ndx x jm) of the moved rows and J [A | B] ((ndx + nu) x jm), slot-contiguous */
    double *Jt = malloc(sizeof(double) * ((size_t)ndx * jm + (size_t)nab * jm + 1));
    if (!Jt) return -1;
    double *acc = Jt + (size_t)ndx * jm;
    memset(W + (size_t)N * m * w, 0, sizeof(double) * w);  /* the scratch row */
    for (int i = 0; i < N; i++) {
        double *Wi = W + (size_t)i * m * w;
        for (int t = 0; t < k; t++) {
            int col = own_cols[t];
            double *row = Wi + (size_t)t * w;
            const double *u = cu + i * s[SR_CU][0] + col * s[SR_CU][1];
            const double *x = cx + i * s[SR_CX][0] + col * s[SR_CX][1];
            ptrdiff_t us = s[SR_CU][2], xs = s[SR_CX][2];
            for (int q = 0; q < nu; q++) row[q] = u[q * us];
            for (int q = 0; q < ndx; q++) row[nu + q] = x[q * xs];
            Wi[(size_t)t * w + w - 1] = c[i * s[SR_C][0] + col * s[SR_C][1]]
                                        - bnd[i * s[SR_BND][0] + col * s[SR_BND][1]];
            rows[(size_t)i * m + t] = own[(size_t)i * nc + col];
        }
        int last = i == N - 1, nn = last ? jt : j;
        /* slots without a row at this node: zero */
        memset(Wi + (size_t)(k + nn) * w, 0, sizeof(double) * (size_t)(m - k - nn) * w);
        memset(rows + (size_t)i * m + k + nn, 0, (size_t)(m - k - nn));
        if (nn == 0) continue;
        double *row0 = Wi + (size_t)k * w;
        for (int t = 0; t < nn; t++) {
            const double *J;
            ptrdiff_t js;
            if (last) {
                int col = term_cols[t];
                J = cxN + col * s[SR_CXN][0];
                js = s[SR_CXN][1];
                row0[(size_t)t * w + w - 1] = cN[col * s[SR_CN][0]] - bN[col * s[SR_BNDN][0]];
                rows[(size_t)i * m + k + t] = 1;
            } else {
                int col = nxt_cols[t];
                J = cx + (i + 1) * s[SR_CX][0] + col * s[SR_CX][1];
                js = s[SR_CX][2];
                row0[(size_t)t * w + w - 1] = c[(i + 1) * s[SR_C][0] + col * s[SR_C][1]]
                    - bnd[(i + 1) * s[SR_BND][0] + col * s[SR_BND][1]];
                rows[(size_t)i * m + k + t] = nxt[(size_t)i * nc + col];
            }
            for (int r = 0; r < ndx; r++) Jt[(size_t)r * nn + t] = J[r * js];
        }
        /* e += J gap */
        for (int r = 0; r < ndx; r++) {
            double g = gap[i * s[SR_GAP][0] + r * s[SR_GAP][1]];
            for (int t = 0; t < nn; t++) row0[(size_t)t * w + w - 1] += Jt[(size_t)r * nn + t] * g;
        }
        /* J [A | B], column by column of [A | B] (its pattern's nonzeros only, if given) */
        memset(acc, 0, sizeof(double) * (size_t)nab * nn);
        for (int q = 0; q < nab; q++) {
            int src = q < ndx ? SR_A : SR_B, cc = q < ndx ? q : q - ndx;
            const double *M = in[src] + i * s[src][0] + cc * s[src][2];
            ptrdiff_t rs = s[src][1];
            double *a = acc + (size_t)q * nn;
            int p0 = pat ? pat[q] : 0, p1 = pat ? pat[q + 1] : ndx;
            for (int p = p0; p < p1; p++) {
                int r = pat ? pat[nab + 1 + p] : p;
                double v = M[r * rs];
                const double *jr = Jt + (size_t)r * nn;
                for (int t = 0; t < nn; t++) a[t] += v * jr[t];
            }
        }
        for (int q = 0; q < nab; q++) {  /* A's columns to C (W column nu + q), B's to D */
            int dst = q < ndx ? nu + q : q - ndx;
            for (int t = 0; t < nn; t++) row0[(size_t)t * w + dst] = acc[(size_t)q * nn + t];
        }
    }
    free(Jt);
    return 0;
}

#else
/* ================================================================== kernel pass (per ISA) */
/* Everything below is compiled once per ISA, with VW doubles per vector; ISA(name) gives
 * each copy its own names, the short names are macros for readability. */
#define vec ISA(vec)
#define vload ISA(vload)
#define vstore ISA(vstore)
#define vbc ISA(vbc)
#define vsum ISA(vsum)
#define upd ISA(upd)
#define upd1 ISA(upd1)
#define gemm ISA(gemm)
#define axpy ISA(axpy)
#define scal ISA(scal)
#define copy ISA(copy)
#define dot ISA(dot)
#define matvec ISA(matvec)
#define get_mat ISA(get_mat)
#define get_vec ISA(get_vec)
#define chol_upper ISA(chol_upper)
#define chol_solve ISA(chol_solve)
#define chol_solve_vec ISA(chol_solve_vec)
#define lower_to_upper ISA(lower_to_upper)
#define backward ISA(backward)
#define box_qp ISA(box_qp)
#define policy_cost_to_go ISA(policy_cost_to_go)
#define qp_value ISA(qp_value)
#define rollout ISA(rollout)
#define project ISA(project)

typedef double vec __attribute__((vector_size(8 * VW)));

static inline vec vload(const double *p) { vec v; memcpy(&v, p, sizeof v); return v; }
static inline void vstore(double *p, vec v) { memcpy(p, &v, sizeof v); }
#if VW == 4
static inline vec vbc(double x) { return (vec){x, x, x, x}; }
static inline double vsum(vec v) { return (v[0] + v[1]) + (v[2] + v[3]); }
#else
static inline vec vbc(double x) { return (vec){x, x}; }
static inline double vsum(vec v) { return v[0] + v[1]; }
#endif
static inline vec upd(int acc, vec c, vec p) { return acc > 0 ? c + p : c - p; }
static inline double upd1(int acc, double c, double p) { return acc > 0 ? c + p : c - p; }

/* C (m x n, ldc) = P, C + P or C - P for acc = 0, 1, -1, where
 * P(i, j) = sum_k op(X)(i, k) Y(k, j), op(X)(i, k) = X[i*xi + k*xk], Y (kk x n, ldy). */
__attribute__((noinline))
static void gemm(int m, int n, int kk, const double *X, ptrdiff_t xi, ptrdiff_t xk,
                 const double *Y, ptrdiff_t ldy, double *C, ptrdiff_t ldc, int acc)
{
    int i = 0;
    for (; i + 4 <= m; i += 4) {  /* tiles of 4 rows x 2 vectors in registers */
        const double *x0 = X + i * xi, *x1 = x0 + xi, *x2 = x1 + xi, *x3 = x2 + xi;
        double *c0 = C + i * ldc, *c1 = c0 + ldc, *c2 = c1 + ldc, *c3 = c2 + ldc;
        int j = 0;
        for (; j + 2 * VW <= n; j += 2 * VW) {
            vec a0 = {0}, a1 = {0}, a2 = {0}, a3 = {0}, b0 = {0}, b1 = {0}, b2 = {0}, b3 = {0};
            const double *y = Y + j;
            for (int k = 0; k < kk; k++, y += ldy) {
                vec ya = vload(y), yb = vload(y + VW), w;
                w = vbc(x0[k * xk]); a0 += w * ya; b0 += w * yb;
                w = vbc(x1[k * xk]); a1 += w * ya; b1 += w * yb;
                w = vbc(x2[k * xk]); a2 += w * ya; b2 += w * yb;
                w = vbc(x3[k * xk]); a3 += w * ya; b3 += w * yb;
            }
            if (acc) {
                a0 = upd(acc, vload(c0 + j), a0); b0 = upd(acc, vload(c0 + j + VW), b0);
                a1 = upd(acc, vload(c1 + j), a1); b1 = upd(acc, vload(c1 + j + VW), b1);
                a2 = upd(acc, vload(c2 + j), a2); b2 = upd(acc, vload(c2 + j + VW), b2);
                a3 = upd(acc, vload(c3 + j), a3); b3 = upd(acc, vload(c3 + j + VW), b3);
            }
            vstore(c0 + j, a0); vstore(c0 + j + VW, b0); vstore(c1 + j, a1);
            vstore(c1 + j + VW, b1); vstore(c2 + j, a2); vstore(c2 + j + VW, b2);
            vstore(c3 + j, a3); vstore(c3 + j + VW, b3);
        }
        for (; j + VW <= n; j += VW) {
            vec a0 = {0}, a1 = {0}, a2 = {0}, a3 = {0};
            const double *y = Y + j;
            for (int k = 0; k < kk; k++, y += ldy) {
                vec ya = vload(y);
                a0 += vbc(x0[k * xk]) * ya; a1 += vbc(x1[k * xk]) * ya;
                a2 += vbc(x2[k * xk]) * ya; a3 += vbc(x3[k * xk]) * ya;
            }
            if (acc) {
                a0 = upd(acc, vload(c0 + j), a0); a1 = upd(acc, vload(c1 + j), a1);
                a2 = upd(acc, vload(c2 + j), a2); a3 = upd(acc, vload(c3 + j), a3);
            }
            vstore(c0 + j, a0); vstore(c1 + j, a1); vstore(c2 + j, a2); vstore(c3 + j, a3);
        }
        for (; j < n; j++) {
            double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
            const double *y = Y + j;
            for (int k = 0; k < kk; k++, y += ldy) {
                s0 += x0[k * xk] * *y; s1 += x1[k * xk] * *y;
                s2 += x2[k * xk] * *y; s3 += x3[k * xk] * *y;
            }
            if (acc) {
                s0 = upd1(acc, c0[j], s0); s1 = upd1(acc, c1[j], s1);
                s2 = upd1(acc, c2[j], s2); s3 = upd1(acc, c3[j], s3);
            }
            c0[j] = s0; c1[j] = s1; c2[j] = s2; c3[j] = s3;
        }
    }
    for (; i < m; i++) {  /* the last rows, one at a time */
        const double *x0 = X + i * xi;
        double *c0 = C + i * ldc;
        int j = 0;
        for (; j + 2 * VW <= n; j += 2 * VW) {
            vec a0 = {0}, b0 = {0};
            const double *y = Y + j;
            for (int k = 0; k < kk; k++, y += ldy) {
                vec w = vbc(x0[k * xk]);
                a0 += w * vload(y); b0 += w * vload(y + VW);
            }
            if (acc) { a0 = upd(acc, vload(c0 + j), a0); b0 = upd(acc, vload(c0 + j + VW), b0); }
            vstore(c0 + j, a0); vstore(c0 + j + VW, b0);
        }
        for (; j + VW <= n; j += VW) {
            vec a0 = {0};
            const double *y = Y + j;
            for (int k = 0; k < kk; k++, y += ldy) a0 += vbc(x0[k * xk]) * vload(y);
            if (acc) a0 = upd(acc, vload(c0 + j), a0);
            vstore(c0 + j, a0);
        }
        for (; j < n; j++) {
            double s0 = 0;
            const double *y = Y + j;
            for (int k = 0; k < kk; k++, y += ldy) s0 += x0[k * xk] * *y;
            c0[j] = acc ? upd1(acc, c0[j], s0) : s0;
        }
    }
}

/* y += a x (contiguous) */
static inline void axpy(int n, double a, const double *x, double *y)
{
    vec av = vbc(a);
    int j = 0;
    for (; j + VW <= n; j += VW) vstore(y + j, vload(y + j) + av * vload(x + j));
    for (; j < n; j++) y[j] += a * x[j];
}

/* y *= a (contiguous) */
static inline void scal(int n, double a, double *y)
{
    vec av = vbc(a);
    int j = 0;
    for (; j + VW <= n; j += VW) vstore(y + j, av * vload(y + j));
    for (; j < n; j++) y[j] *= a;
}

/* dst = src, n contiguous doubles (short rows: inline, no libc call) */
static inline void copy(int n, const double *src, double *dst)
{
    int j = 0;
    for (; j + VW <= n; j += VW) vstore(dst + j, vload(src + j));
    for (; j < n; j++) dst[j] = src[j];
}

/* sum_p a[p] b[p], contiguous */
static inline double dot(int n, const double *a, const double *b)
{
    vec acc = {0};
    int p = 0;
    for (; p + VW <= n; p += VW) acc += vload(a + p) * vload(b + p);
    double s = vsum(acc);
    for (; p < n; p++) s += a[p] * b[p];
    return s;
}

/* y (rows) = M x, M strided (rs, cs); x, y contiguous */
static inline void matvec(int rows, int cols, const double *M, ptrdiff_t rs, ptrdiff_t cs,
                          const double *x, double *y)
{
    if (cs == 1) {
        for (int r = 0; r < rows; r++) y[r] = dot(cols, M + r * rs, x);
    } else if (rs == 1) {  /* column-major: combine the columns */
        for (int r = 0; r < rows; r++) y[r] = 0.0;
        for (int c = 0; c < cols; c++) axpy(rows, x[c], M + c * cs, y);
    } else {
        for (int r = 0; r < rows; r++) {
            double s = 0;
            for (int c = 0; c < cols; c++) s += M[r * rs + c * cs] * x[c];
            y[r] = s;
        }
    }
}

/* dst (rows x cols, ld) = src strided (rs, cs) */
static inline void get_mat(int rows, int cols, const double *src, ptrdiff_t rs, ptrdiff_t cs,
                           double *dst, ptrdiff_t ld)
{
    if (cs == 1) {
        for (int r = 0; r < rows; r++) copy(cols, src + r * rs, dst + r * ld);
    } else if (rs == 1) {  /* column-major block (the solver's CasADi buffers) */
        int c = 0;
        for (; c + 4 <= cols; c += 4) {  /* 4 columns at a time: 4 reading streams */
            const double *s0 = src + c * cs, *s1 = s0 + cs, *s2 = s1 + cs, *s3 = s2 + cs;
            for (int r = 0; r < rows; r++) {
                double *d = dst + r * ld + c;
                d[0] = s0[r]; d[1] = s1[r]; d[2] = s2[r]; d[3] = s3[r];
            }
        }
        for (; c < cols; c++)
            for (int r = 0; r < rows; r++) dst[r * ld + c] = src[r + c * cs];
    } else {
        for (int r = 0; r < rows; r++)
            for (int c = 0; c < cols; c++) dst[r * ld + c] = src[r * rs + c * cs];
    }
}

/* dst (n) = src strided (s) */
static inline void get_vec(int n, const double *src, ptrdiff_t s, double *dst)
{
    if (s == 1) copy(n, src, dst);
    else for (int r = 0; r < n; r++) dst[r] = src[r * s];
}

/* U (n x n): upper triangle = the lower triangle of H (ldh) transposed, zeros below */
static inline void lower_to_upper(int n, const double *H, ptrdiff_t ldh, double *U)
{
    for (int j = 0; j < n; j++) {
        for (int p = 0; p < j; p++) U[j * n + p] = 0.0;
        for (int p = j; p < n; p++) U[j * n + p] = H[p * ldh + j];
    }
}

/* Upper Cholesky factor (U^T U = H) in place of U, whose upper triangle holds H's (see
 * lower_to_upper). Left-looking by blocks of NB rows: the bulk of the work is one gemm per
 * block. Returns 0, or -1 if a pivot is not > 0 (NaN included), as potrf. */
static int chol_upper(int n, double *U)
{
    for (int j0 = 0; j0 < n; j0 += NB) {
        int j1 = j0 + NB < n ? j0 + NB : n;
        if (j0) gemm(j1 - j0, n - j0, j0, U + j0, 1, n, U + j0, n, U + j0 * n + j0, n, -1);
        for (int j = j0; j < j1; j++) {
            double *uj = U + j * n;
            for (int p = j0; p < j; p++) axpy(n - j, -U[p * n + j], U + p * n + j, uj + j);
            double d = uj[j];
            if (!(d > 0.0)) return -1;
            d = sqrt(d);
            uj[j] = d;
            scal(n - j - 1, 1.0 / d, uj + j + 1);
        }
    }
    return 0;
}

/* X (n x m, ldx) := H^-1 X with H = U^T U: forward then back substitution by blocks of NB
 * rows (a gemm with the rows already solved, then a small triangle). */
static void chol_solve(int n, const double *U, int m, double *X, ptrdiff_t ldx)
{
    for (int i0 = 0; i0 < n; i0 += NB) {  /* U^T Y = X */
        int i1 = i0 + NB < n ? i0 + NB : n;
        if (i0) gemm(i1 - i0, m, i0, U + i0, 1, n, X, ldx, X + i0 * ldx, ldx, -1);
        for (int i = i0; i < i1; i++) {
            double *xi = X + i * ldx;
            for (int p = i0; p < i; p++) axpy(m, -U[p * n + i], X + p * ldx, xi);
            scal(m, 1.0 / U[i * n + i], xi);
        }
    }
    for (int i1 = n; i1 > 0; i1 -= NB) {  /* U X = Y, from the last rows up */
        int i0 = i1 - NB > 0 ? i1 - NB : 0;
        if (i1 < n)
            gemm(i1 - i0, m, n - i1, U + i0 * n + i1, n, 1, X + i1 * ldx, ldx, X + i0 * ldx,
                 ldx, -1);
        for (int i = i1 - 1; i >= i0; i--) {
            double *xi = X + i * ldx;
            for (int p = i + 1; p < i1; p++) axpy(m, -U[i * n + p], X + p * ldx, xi);
            scal(m, 1.0 / U[i * n + i], xi);
        }
    }
}

/* x (n) := H^-1 x with H = U^T U */
static void chol_solve_vec(int n, const double *U, double *x)
{
    for (int j = 0; j < n; j++) {
        double v = x[j];
        for (int p = 0; p < j; p++) v -= U[p * n + j] * x[p];
        x[j] = v / U[j * n + j];
    }
    for (int j = n - 1; j >= 0; j--) {
        double v = x[j] - dot(n - j - 1, U + j * n + j + 1, x + j + 1);
        x[j] = v / U[j * n + j];
    }
}

/* 0.5 x^T H x + q^T x (H: n x n, row-major) */
static double qp_value(int n, const double *H, const double *q, const double *x)
{
    double v = 0.0;
    for (int a = 0; a < n; a++) v += x[a] * (0.5 * dot(n, H + (size_t)a * n, x) + q[a]);
    return v;
}

/* riccati.py's box_qp: x (n) := argmin 0.5 x^T H x + q^T x, lo <= x <= hi, by projected
 * Newton from clip(0, lo, hi). On return free (nfree ints) lists the inputs not clamped at x
 * and U (nfree x nfree) holds the upper Cholesky factor of H on them. Workspace: Hf
 * (n x n), g, d, xt, r (n each). Returns 0, or 1: H on a free set is not positive definite. */
static int box_qp(int n, const double *H, const double *q, const double *lo,
                  const double *hi, double *x, int *free, int *nfree, double *Hf, double *U,
                  double *g, double *d, double *xt, double *r)
{
    for (int a = 0; a < n; a++) {
        double v = 0.0;
        if (v < lo[a]) v = lo[a];
        if (v > hi[a]) v = hi[a];
        x[a] = v;
    }
    for (int it = 0;; it++) {
        int nf = 0;
        for (int a = 0; a < n; a++) {
            g[a] = q[a] + dot(n, H + (size_t)a * n, x);
            int clamped = lo[a] == hi[a] || (x[a] <= lo[a] && g[a] > 0.0)
                          || (x[a] >= hi[a] && g[a] < 0.0);
            if (!clamped) free[nf++] = a;
        }
        *nfree = nf;
        if (!nf) return 0;
        for (int a = 0; a < nf; a++)
            for (int b = 0; b < nf; b++) Hf[a * nf + b] = H[(size_t)free[a] * n + free[b]];
        lower_to_upper(nf, Hf, nf, U);
        if (chol_upper(nf, U)) return 1;
        for (int a = 0; a < nf; a++) r[a] = -g[free[a]];
        chol_solve_vec(nf, U, r);
        for (int a = 0; a < n; a++) d[a] = 0.0;
        for (int a = 0; a < nf; a++) d[free[a]] = r[a];
        double slope = dot(n, g, d);
        if (it == BOX_QP_MAX_ITER || !(slope < -1e-14 * (1.0 + fabs(dot(n, q, x)))))
            return 0;
        /* Armijo search along the projected path */
        double value = qp_value(n, H, q, x), step = 1.0;
        int accepted = 0;
        while (step > 1e-10) {
            double gd = 0.0;
            for (int a = 0; a < n; a++) {
                double v = x[a] + step * d[a];
                if (v < lo[a]) v = lo[a];
                if (v > hi[a]) v = hi[a];
                xt[a] = v;
                gd += g[a] * (v - x[a]);
            }
            if (qp_value(n, H, q, xt) - value <= 0.1 * gd) {
                accepted = 1;
                break;
            }
            step *= 0.6;
        }
        if (!accepted) return 0;
        copy(n, xt, x);
    }
}

/* S_i += K^T Q_uu K + K^T Q_ux + Q_ux^T K, as the symmetric part of K^T (Q_uu K + 2 Q_ux)
 * (the symmetrisation at the end of the recursion's step takes it: one product fewer), and
 * acc = K^T (Q_uu k + Q_u) + Q_ux^T k (s_i - Q_x): the cost-to-go of du = K dx + k for a K
 * that is zero outside its nl live rows K_l (live: their inputs; Q_ll, Q_lx: Q_uu and Q_ux
 * on them). T: nl x ndx workspace. A projected or box-constrained node's policy. */
static void policy_cost_to_go(int nu, int ndx, int nl, const int *live, const double *Quu,
                              const double *Qu, const double *Qux, const double *Qll,
                              const double *Qlx, const double *Kl, const double *k,
                              double *T, double *Si, double *acc)
{
    for (int c = 0; c < ndx; c++) acc[c] = 0.0;
    if (nl) {
        for (int p = 0; p < nl * ndx; p++) T[p] = 2.0 * Qlx[p];
        gemm(nl, ndx, nl, Qll, nl, 1, Kl, ndx, T, ndx, 1);
        gemm(ndx, ndx, nl, Kl, 1, ndx, T, ndx, Si, ndx, 1);
    }
    for (int a = 0; a < nl; a++) {
        double va = dot(nu, Quu + (size_t)live[a] * nu, k) + Qu[live[a]];
        axpy(ndx, va, Kl + (size_t)a * ndx, acc);
    }
    for (int a = 0; a < nu; a++) axpy(ndx, k[a], Qux + a * ndx, acc);
}

/* The recursion (see riccati_backward); w: workspace_size doubles, cols: nu ints. */
static int backward(int N, int ndx, int nu, const double *const *in, const int64_t *st,
                    double mu, const uint8_t *con, const int *pat, double *const *out,
                    int *fail_node, double *w, double *vals, int *cols)
{
    const int m = ndx + nu;
    double *K = out[OUT_K], *kff = out[OUT_KFF], *S = out[OUT_S], *s = out[OUT_SV];
    double *Qu_all = out[OUT_QU], *Quu_all = out[OUT_QUU], *Qux_all = out[OUT_QUX];
    double *AB = w;                 /* ndx x m: [A_i | B_i] */
    double *SAB = AB + ndx * m;     /* ndx x m: S_{i+1} [A_i | B_i] (pattern: m x ndx,
                                     * [A_i | B_i]^T S_{i+1}) */
    double *fi = SAB + ndx * m;     /* ndx: f_i */
    double *g = fi + ndx;           /* ndx: s_{i+1} + S_{i+1} f_i */
    double *qx = g + ndx;           /* ndx: Q_x */
    double *acc = qx + ndx;         /* m: [A | B]^T g, then the terms of s_i - Q_x */
    double *U = acc + m;            /* nu x nu: Cholesky factor of Q_uu or of H */
    double *Zc = U + nu * nu;       /* nu x r: the nonzero columns of Z */
    double *Mz = Zc + nu * nu;      /* r x nu: Zc^T Q_uu */
    double *H = Mz + nu * nu;       /* r x r: Zc^T Q_uu Zc + diag(1 - free) */
    double *Px = H + nu * nu;       /* nu x ndx: P_x */
    double *W = Px + nu * ndx;      /* r x ndx: right-hand side, then solution, for K */
    double *T = W + nu * ndx;       /* nu x ndx: Q_uu K + Q_ux */
    double *Pe = T + nu * ndx;      /* nu: P_e */
    double *wk = Pe + nu;           /* r: right-hand side, then solution, for k */
    double *v = wk + nu;            /* nu */
    double *Quul = v + nu;          /* nl x nl: Q_uu on the live inputs */
    double *Quxl = Quul + nu * nu;  /* nl x ndx: Q_ux on the live inputs */
    double *Kl = Quxl + nu * ndx;   /* nl x ndx: K on the live inputs */
    double *gl = Kl + nu * ndx;     /* nl: Q_uu P_e + Q_u on the live inputs */
    double *blo = gl + nu;          /* nu each: the box of du, box_qp's workspace */
    double *bhi = blo + nu, *bg = bhi + nu, *bd = bg + nu, *bxt = bd + nu, *br = bxt + nu;
    int *live = cols + nu;          /* nl: the live (box: the free) inputs */

    get_mat(ndx, ndx, in[IN_LXXN], st[3 * IN_LXXN], st[3 * IN_LXXN + 1],
            S + (size_t)N * ndx * ndx, ndx);
    get_vec(ndx, in[IN_LXN], st[3 * IN_LXN], s + (size_t)N * ndx);

    for (int i = N - 1; i >= 0; i--) {
        const double *Sn = S + (size_t)(i + 1) * ndx * ndx, *sn = s + (size_t)(i + 1) * ndx;
        double *Si = S + (size_t)i * ndx * ndx, *si = s + (size_t)i * ndx;
        double *Ki = K + (size_t)i * nu * ndx, *ki = kff + (size_t)i * nu;
        double *Qu = Qu_all + (size_t)i * nu, *Quu = Quu_all + (size_t)i * nu * nu;
        double *Qux = Qux_all + (size_t)i * nu * ndx;

        /* g = s' + S' f; Q_x = l_x + A^T g, Q_u = l_u + B^T g */
        get_vec(ndx, EL(IN_F, i, 0, 0), st[3 * IN_F + 1], fi);
        for (int r = 0; r < ndx; r++) g[r] = sn[r] + dot(ndx, Sn + r * ndx, fi);
        get_vec(ndx, EL(IN_LX, i, 0, 0), st[3 * IN_LX + 1], qx);
        get_vec(nu, EL(IN_LU, i, 0, 0), st[3 * IN_LU + 1], Qu);
        /* l_xx enters S_i only, whose symmetric part is all that is kept (see the end of the
         * loop): read it as its transpose, row by row from the column-major buffer */
        get_mat(ndx, ndx, EL(IN_LXX, i, 0, 0), st[3 * IN_LXX + 2], st[3 * IN_LXX + 1], Si, ndx);
        get_mat(nu, ndx, EL(IN_LUX, i, 0, 0), st[3 * IN_LUX + 1], st[3 * IN_LUX + 2], Qux, ndx);
        get_mat(nu, nu, EL(IN_LUU, i, 0, 0), st[3 * IN_LUU + 1], st[3 * IN_LUU + 2], Quu, nu);
        if (pat) {
            /* [A B] by its structural nonzeros (CSC): Yt = [A B]^T S' row by row (an axpy of
             * a row of S' per nonzero), then [A B]^T S' [A B] (Q_xx, Q_ux and Q_uu's terms)
             * row by row from its transpose */
            const int *cp = pat, *ri = pat + m + 1;
            for (int j = 0; j < m; j++) {
                double *yt = SAB + (size_t)j * ndx, a = 0.0;
                for (int c = 0; c < ndx; c++) yt[c] = 0.0;
                for (int p = cp[j]; p < cp[j + 1]; p++) {
                    double v = j < ndx ? *EL(IN_A, i, ri[p], j) : *EL(IN_B, i, ri[p], j - ndx);
                    vals[p] = v;
                    a += v * g[ri[p]];
                    axpy(ndx, v, Sn + (size_t)ri[p] * ndx, yt);
                }
                if (j < ndx) qx[j] += a;
                else Qu[j - ndx] += a;
            }
            /* Y2 = S' [A B] (ndx x m) = Yt^T; then row k of [A B]^T Y2 is the sum, over the
             * nonzeros (r, k) of [A B], of v Y2[r]: contiguous axpys (Q_xx needs the first
             * ndx columns only) */
            double *Y2 = AB;
            get_mat(ndx, m, SAB, 1, ndx, Y2, m);  /* Yt read as the column-major Y2 */
            for (int k = 0; k < m; k++) {
                double *qa = k < ndx ? Si + (size_t)k * ndx : Qux + (size_t)(k - ndx) * ndx;
                double *qb = k < ndx ? NULL : Quu + (size_t)(k - ndx) * nu;
                for (int p = cp[k]; p < cp[k + 1]; p++) {
                    const double *y = Y2 + (size_t)ri[p] * m;
                    axpy(ndx, vals[p], y, qa);
                    if (qb) axpy(nu, vals[p], y + ndx, qb);
                }
            }
        } else {
            get_mat(ndx, ndx, EL(IN_A, i, 0, 0), st[3 * IN_A + 1], st[3 * IN_A + 2], AB, m);
            get_mat(ndx, nu, EL(IN_B, i, 0, 0), st[3 * IN_B + 1], st[3 * IN_B + 2], AB + ndx,
                    m);
            for (int c = 0; c < m; c++) acc[c] = 0.0;
            for (int r = 0; r < ndx; r++) axpy(m, g[r], AB + r * m, acc);
            for (int r = 0; r < ndx; r++) qx[r] += acc[r];
            for (int r = 0; r < nu; r++) Qu[r] += acc[ndx + r];
            /* S' [A B]; Q_xx = l_xx + A^T S' A (into S_i), Q_ux = l_ux + B^T S' A,
             * Q_uu = l_uu + B^T S' B */
            gemm(ndx, m, ndx, Sn, ndx, 1, AB, m, SAB, m, 0);
            gemm(ndx, ndx, ndx, AB, 1, m, SAB, m, Si, ndx, 1);
            gemm(nu, ndx, ndx, AB + ndx, 1, m, SAB, m, Qux, ndx, 1);
            gemm(nu, nu, ndx, AB + ndx, 1, m, SAB + ndx, m, Quu, nu, 1);
        }
        for (int r = 0; r < nu; r++) Quu[r * nu + r] += mu;

        if (con && con[i]) {
            /* du = P_e + P_x dx + Z w. Only the nonzero columns of Z take part: a zero column
             * j adds the decoupled pivot 1 - free_j to H and nothing to the solution. In
             * numpy a non-finite Q_uu spreads NaN over all of H (0 * inf), hence the check. */
            vec zv = vbc(0.0);  /* stays 0 unless an entry is NaN or inf (one branch) */
            int p = 0;
            for (; p + VW <= nu * nu; p += VW) zv += vbc(0.0) * vload(Quu + p);
            double zero = vsum(zv);
            for (; p < nu * nu; p++) zero += 0.0 * Quu[p];
            if (zero != 0.0) { *fail_node = i; return 1; }
            const double *Z = EL(IN_Z, i, 0, 0), *fr = EL(IN_FREE, i, 0, 0);
            const double *Pxi = EL(IN_PX, i, 0, 0);
            const ptrdiff_t zr = st[3 * IN_Z + 1], zc = st[3 * IN_Z + 2], fs = st[3 * IN_FREE + 1];
            const ptrdiff_t pr = st[3 * IN_PX + 1], pc = st[3 * IN_PX + 2];
            /* the nonzero columns and rows of Z by sums of |Z| (nonnegative terms: zero only
             * when all are; no early exits, so they vectorise) */
            double *colsum = v;
            int nl = 0, r = 0;
            for (int j = 0; j < nu; j++) colsum[j] = 0.0;
            for (int a = 0; a < nu; a++) {
                double rowsum = 0.0;
                for (int j = 0; j < nu; j++) {
                    double z = fabs(Z[a * zr + j * zc]);
                    colsum[j] += z;
                    rowsum += z;
                }
                live[a] = rowsum != 0.0;
            }
            for (int j = 0; j < nu; j++) {
                if (colsum[j] != 0.0) cols[r++] = j;
                else if (!(1.0 - fr[j * fs] > 0.0)) { *fail_node = i; return 1; }
            }
            /* An input whose rows of Z and P_x are zero (a swing foot's force pinned by its
             * row) is dead: its rows of K are zero and its k is P_e's. The products run on
             * the nl live inputs only (go2 trotting: 24 of 30). */
            for (int a = 0; a < nu; a++) {
                int nz = live[a];
                for (int c = 0; c < ndx && !nz; c++) nz = Pxi[a * pr + c * pc] != 0.0;
                if (nz) live[nl++] = a;  /* nl <= a: overwrites entries already read */
            }
            for (int a = 0; a < nl; a++)
                for (int q = 0; q < r; q++) Zc[a * r + q] = Z[live[a] * zr + cols[q] * zc];
            for (int a = 0; a < nl; a++)
                for (int c = 0; c < ndx; c++) Px[a * ndx + c] = Pxi[live[a] * pr + c * pc];
            get_vec(nu, EL(IN_PE, i, 0, 0), st[3 * IN_PE + 1], Pe);
            const int all = nl == nu;  /* nothing dead: Q_uu, Q_ux and K as they are */
            const double *Qll = Quu, *Qlx = Qux;
            double *Kli = all ? Ki : Kl;
            if (!all) {
                for (int a = 0; a < nl; a++) {
                    for (int b = 0; b < nl; b++) Quul[a * nl + b] = Quu[live[a] * nu + live[b]];
                    copy(ndx, Qux + (size_t)live[a] * ndx, Quxl + (size_t)a * ndx);
                }
                Qll = Quul;
                Qlx = Quxl;
            }
            /* Mz = Zc^T Q_uu; [W | wk] = Mz P_x + Zc^T Q_ux | Zc^T (Q_uu P_e + Q_u) */
            gemm(r, nl, nl, Zc, 1, r, Qll, nl, Mz, nl, 0);
            gemm(r, ndx, nl, Mz, nl, 1, Px, ndx, W, ndx, 0);
            gemm(r, ndx, nl, Zc, 1, r, Qlx, ndx, W, ndx, 1);
            for (int a = 0; a < nl; a++)
                gl[a] = dot(nu, Quu + (size_t)live[a] * nu, Pe) + Qu[live[a]];
            for (int q = 0; q < r; q++) wk[q] = 0.0;
            for (int a = 0; a < nl; a++) axpy(r, gl[a], Zc + a * r, wk);
            /* H = Mz Zc + diag(1 - free), factored; [W | wk] := H^-1 [W | wk] */
            gemm(r, r, nl, Mz, nl, 1, Zc, r, H, r, 0);
            for (int q = 0; q < r; q++) H[q * r + q] += 1.0 - fr[cols[q] * fs];
            lower_to_upper(r, H, r, U);
            if (chol_upper(r, U)) { *fail_node = i; return 1; }
            chol_solve(r, U, ndx, W, ndx);
            chol_solve_vec(r, U, wk);
            /* K = P_x - Zc W (zero rows for dead inputs), k = P_e - Zc wk */
            gemm(nl, ndx, r, Zc, r, 1, W, ndx, Kli, ndx, 0);
            for (int p = 0; p < nl * ndx; p++) Kli[p] = Px[p] - Kli[p];
            if (!all) {
                for (int p = 0; p < nu * ndx; p++) Ki[p] = 0.0;
                for (int a = 0; a < nl; a++)
                    copy(ndx, Kl + (size_t)a * ndx, Ki + (size_t)live[a] * ndx);
            }
            copy(nu, Pe, ki);
            for (int a = 0; a < nl; a++) ki[live[a]] -= dot(r, Zc + a * r, wk);
            policy_cost_to_go(nu, ndx, nl, live, Quu, Qu, Qux, Qll, Qlx, Kli, ki, T, Si, acc);
        } else if (in[IN_BLO] && boxed(nu, EL(IN_BLO, i, 0, 0), EL(IN_BHI, i, 0, 0),
                                       st[3 * IN_BLO + 1], st[3 * IN_BHI + 1])) {
            /* the box of du: k from box_qp, K = -Q_ff^-1 Q_fx on its free inputs (zero rows
             * for the clamped ones); S_i, s_i the cost-to-go of that policy, as with a
             * projection */
            get_vec(nu, EL(IN_BLO, i, 0, 0), st[3 * IN_BLO + 1], blo);
            get_vec(nu, EL(IN_BHI, i, 0, 0), st[3 * IN_BHI + 1], bhi);
            int nl = 0;
            if (box_qp(nu, Quu, Qu, blo, bhi, ki, live, &nl, Quul, U, bg, bd, bxt, br)) {
                *fail_node = i;
                return 1;
            }
            for (int p = 0; p < nu * ndx; p++) Ki[p] = 0.0;
            for (int a = 0; a < nl; a++) {
                for (int c = 0; c < ndx; c++) Kl[a * ndx + c] = -Qux[(size_t)live[a] * ndx + c];
                for (int b = 0; b < nl; b++) Quul[a * nl + b] = Quu[live[a] * nu + live[b]];
                copy(ndx, Qux + (size_t)live[a] * ndx, Quxl + (size_t)a * ndx);
            }
            if (nl) chol_solve(nl, U, ndx, Kl, ndx);
            for (int a = 0; a < nl; a++) copy(ndx, Kl + (size_t)a * ndx, Ki + (size_t)live[a] * ndx);
            policy_cost_to_go(nu, ndx, nl, live, Quu, Qu, Qux, Quul, Quxl, Kl, ki, T, Si, acc);
        } else {
            /* K = -Q_uu^-1 Q_ux, k = -Q_uu^-1 Q_u; S_i = Q_xx + Q_ux^T K, s_i = Q_x + Q_ux^T k */
            lower_to_upper(nu, Quu, nu, U);
            if (chol_upper(nu, U)) { *fail_node = i; return 1; }
            for (int p = 0; p < nu * ndx; p++) Ki[p] = -Qux[p];
            for (int a = 0; a < nu; a++) ki[a] = -Qu[a];
            chol_solve(nu, U, ndx, Ki, ndx);
            chol_solve_vec(nu, U, ki);
            gemm(ndx, ndx, nu, Qux, 1, ndx, Ki, ndx, Si, ndx, 1);
            for (int c = 0; c < ndx; c++) acc[c] = 0.0;
            for (int a = 0; a < nu; a++) axpy(ndx, ki[a], Qux + a * ndx, acc);
        }
        for (int a = 0; a < nu; a++)
            if (!isfinite(ki[a])) { *fail_node = i; return 2; }
        for (int r = 0; r < ndx; r++) si[r] = qx[r] + acc[r];
        for (int r = 0; r < ndx; r++)  /* S_i = (S_i + S_i^T) / 2 */
            for (int c = r + 1; c < ndx; c++) {
                double a = 0.5 * (Si[r * ndx + c] + Si[c * ndx + r]);
                Si[r * ndx + c] = a;
                Si[c * ndx + r] = a;
            }
    }
    return 0;
}

/* The rollout (see riccati_rollout); w: ndx doubles. */
static void rollout(int N, int ndx, int nu, const double *const *in, const int64_t *st,
                    double *dX, double *dU, double *w)
{
    get_vec(ndx, in[RO_DX0], st[3 * RO_DX0], dX);
    for (int i = 0; i < N; i++) {
        const double *x = dX + (size_t)i * ndx;
        double *u = dU + (size_t)i * nu, *xn = dX + (size_t)(i + 1) * ndx;
        /* du = k + K dx;  dx' = A dx + B du + f */
        matvec(nu, ndx, EL(RO_K, i, 0, 0), st[3 * RO_K + 1], st[3 * RO_K + 2], x, u);
        const double *k = EL(RO_KFF, i, 0, 0);
        for (int a = 0; a < nu; a++) u[a] += k[a * st[3 * RO_KFF + 1]];
        if (in[RO_LO]) {  /* clamped into the box (NaN stays NaN) */
            const double *lo = EL(RO_LO, i, 0, 0), *hi = EL(RO_HI, i, 0, 0);
            const ptrdiff_t ls = st[3 * RO_LO + 1], hs = st[3 * RO_HI + 1];
            for (int a = 0; a < nu; a++) {
                if (u[a] < lo[a * ls]) u[a] = lo[a * ls];
                if (u[a] > hi[a * hs]) u[a] = hi[a * hs];
            }
        }
        matvec(ndx, ndx, EL(RO_A, i, 0, 0), st[3 * RO_A + 1], st[3 * RO_A + 2], x, xn);
        matvec(ndx, nu, EL(RO_B, i, 0, 0), st[3 * RO_B + 1], st[3 * RO_B + 2], u, w);
        const double *f = EL(RO_F, i, 0, 0);
        for (int r = 0; r < ndx; r++) xn[r] = (xn[r] + w[r]) + f[r * st[3 * RO_F + 1]];
    }
}

/* The projection (see riccati_project), per ISA: plain loops the compiler vectorises. */
static int project(int N, int m, int nu, int ndx, const double *W, const uint8_t *rows,
                   double rtol, double *P_e, double *P_x, double *Z, double *fr,
                   double *pinv, uint8_t *ok, uint8_t *unmet)
{
    const int ld = nu + ndx + 1;
    const size_t mm = m > 0 ? (size_t)m : 1, uu = nu > 0 ? (size_t)nu : 1;
    const size_t lg = (size_t)ndx + 1;
    double *a = malloc(sizeof(double) * mm * uu);   /* g x nf: row q of D_g (free columns),
                                                     * reflected in place */
    double *R = malloc(sizeof(double) * mm * mm);   /* g x g, upper */
    double *Ri = malloc(sizeof(double) * mm * mm);  /* R^-1, upper */
    double *Q = malloc(sizeof(double) * uu * uu);   /* nf x nf */
    double *pv = malloc(sizeof(double) * uu * mm);  /* nf x g: D_g^+ */
    double *wq = malloc(sizeof(double) * uu);       /* nf: v^T Q */
    double *G = malloc(sizeof(double) * mm * lg);   /* g x (ndx + 1): [C | e] of the general
                                                     * rows, the pinned inputs eliminated */
    double *E = malloc(sizeof(double) * mm * mm);   /* g x p: D[row q][pcol[k]] / d_k */
    int *slot = malloc(sizeof(int) * mm);
    int *pin = malloc(sizeof(int) * mm), *pcol = malloc(sizeof(int) * mm);
    int *gen = malloc(sizeof(int) * mm), *fcol = malloc(sizeof(int) * uu);
    uint8_t *taken = malloc(uu);
    int ret = -1;
    if (!a || !R || !Ri || !Q || !pv || !wq || !G || !E || !slot || !pin || !pcol || !gen
        || !fcol || !taken)
        goto done;
    for (int i = 0; i < N; i++) {
        double *pe = P_e + (size_t)i * nu, *px = P_x + (size_t)i * nu * ndx;
        double *z = Z + (size_t)i * nu * nu, *f = fr + (size_t)i * nu;
        double *pi = pinv + (size_t)i * nu * m;
        int c = 0;
        for (int j = 0; j < m; j++)
            if (rows[(size_t)i * m + j]) slot[c++] = j;
        memset(pe, 0, sizeof(double) * nu);
        memset(px, 0, sizeof(double) * nu * ndx);
        memset(pi, 0, sizeof(double) * nu * m);
        memset(z, 0, sizeof(double) * nu * nu);
        unmet[i] = 0;
        ok[i] = c <= nu;
        if (!ok[i]) continue;
        for (int p = 0; p < nu; p++) f[p] = p >= c;
        if (c == 0) {
            for (int p = 0; p < nu; p++) z[p * nu + p] = 1.0;
            continue;
        }
#define WROW(j) (W + ((size_t)i * m + slot[j]) * ld)
        /* a row whose input Jacobian is round-off next to its state Jacobian (equality.py's
         * INPUT_ATOL) leaves the node to the SVD, which drops it */
        for (int j = 0; j < c && ok[i]; j++) {  /* 2-norms: sums the compiler vectorises */
            const double *wj = WROW(j);
            double dd = 0.0, cc = 0.0;
            for (int p = 0; p < nu; p++) dd += wj[p] * wj[p];
            for (int r = 0; r < ndx; r++) cc += wj[nu + r] * wj[nu + r];
            if (!(dd > INPUT_ATOL * INPUT_ATOL * fmax(1.0, cc))) ok[i] = 0;  /* NaN: not ok */
        }
        if (!ok[i]) continue;
        /* pinned rows: one nonzero in D, in a column no earlier pinned row has (a zero
         * force, d_k f_p = ...): they fix du_p = -(C dx + e) / d_k, and the other rows see
         * them eliminated. The minimum-norm solution, hence D^+, P_e, P_x and the null
         * space, are those of the whole D; the QR only takes the general rows on the free
         * columns (go2 trotting: 12 rows on 24 inputs instead of 18 on 30). */
        int np_ = 0, ng = 0, nf = 0;
        memset(taken, 0, uu);
        for (int j = 0; j < c; j++) {
            const double *wj = WROW(j);
            int nz = 0, col = -1;
            for (int p = 0; p < nu && nz < 2; p++)
                if (wj[p] != 0.0) { nz++; col = p; }
            if (nz == 1 && !taken[col]) { taken[col] = 1; pin[np_] = j; pcol[np_++] = col; }
            else gen[ng++] = j;
        }
        for (int p = 0; p < nu; p++)
            if (!taken[p]) fcol[nf++] = p;
        for (int q = 0; q < ng; q++) {
            const double *wg = WROW(gen[q]);
            double *gq = G + (size_t)q * lg;
            memcpy(gq, wg + nu, sizeof(double) * lg);
            for (int t = 0; t < nf; t++) a[(size_t)q * nf + t] = wg[fcol[t]];
            for (int k = 0; k < np_; k++) {
                const double *wk = WROW(pin[k]);
                double e = wg[pcol[k]] / wk[pcol[k]];
                E[(size_t)q * np_ + k] = e;
                if (e != 0.0)
                    for (int r = 0; r < (int)lg; r++) gq[r] -= e * wk[nu + r];
            }
        }
        /* Householder on the general rows: H_j = I - 2 v v^T / (v^T v), v in a[j][j:] */
        int singular = 0;
        for (int j = 0; j < ng; j++) {
            double *aj = a + (size_t)j * nf, nrm = 0.0;
            for (int r = j; r < nf; r++) nrm += aj[r] * aj[r];
            nrm = sqrt(nrm);
            if (!(nrm > 0.0)) { singular = 1; break; }  /* zero or NaN */
            double alpha = aj[j] > 0.0 ? -nrm : nrm;
            for (int q = 0; q < j; q++) R[q * ng + j] = aj[q];
            R[j * ng + j] = alpha;
            for (int q = j + 1; q < ng; q++) R[q * ng + j] = 0.0;
            aj[j] -= alpha;
            double vv = 0.0;
            for (int r = j; r < nf; r++) vv += aj[r] * aj[r];
            if (!(vv > 0.0)) { singular = 1; break; }
            for (int q = j + 1; q < ng; q++) {
                double *aq = a + (size_t)q * nf, d = 0.0;
                for (int r = j; r < nf; r++) d += aj[r] * aq[r];
                d *= 2.0 / vv;
                for (int r = j; r < nf; r++) aq[r] -= d * aj[r];
            }
        }
        if (singular) { ok[i] = 0; continue; }
        /* R^-1 by back substitution, column by column */
        for (int p = 0; p < ng * ng; p++) Ri[p] = 0.0;
        for (int col = 0; col < ng; col++) {
            Ri[col * ng + col] = 1.0 / R[col * ng + col];
            for (int r = col - 1; r >= 0; r--) {
                double sum = 0.0;
                for (int q = r + 1; q <= col; q++) sum += R[r * ng + q] * Ri[q * ng + col];
                Ri[r * ng + col] = -sum / R[r * ng + r];
            }
        }
        /* Q = H_0 H_1 ... H_{g-1}: the reflectors applied to I from the last one */
        for (int p = 0; p < nf * nf; p++) Q[p] = 0.0;
        for (int p = 0; p < nf; p++) Q[p * nf + p] = 1.0;
        for (int j = ng - 1; j >= 0; j--) {  /* Q[j:, j:] -= (2 / v^T v) v (v^T Q[j:, j:]) */
            const double *v = a + (size_t)j * nf;
            double vv = 0.0;
            for (int r = j; r < nf; r++) vv += v[r] * v[r];
            for (int col = j; col < nf; col++) wq[col] = 0.0;
            for (int r = j; r < nf; r++) {  /* rows: contiguous inner loops */
                const double *qr = Q + r * nf, vr = v[r];
                for (int col = j; col < nf; col++) wq[col] += vr * qr[col];
            }
            for (int r = j; r < nf; r++) {
                double *qr = Q + r * nf, g = 2.0 * v[r] / vv;
                for (int col = j; col < nf; col++) qr[col] -= g * wq[col];
            }
        }
        /* D_g^+ = Q[:, :g] R^-T: pv[t][q] = sum_{l >= q} Q[t][l] Ri[q][l] */
        for (int t = 0; t < nf; t++)
            for (int q = 0; q < ng; q++) {
                double sum = 0.0;
                for (int l = q; l < ng; l++) sum += Q[t * nf + l] * Ri[q * ng + l];
                pv[t * ng + q] = sum;
            }
        /* D^+: the free inputs take D_g^+ of the eliminated right-hand side, a pinned input
         * its own row */
        for (int t = 0; t < nf; t++) {
            double *pr = pi + (size_t)fcol[t] * m;
            for (int q = 0; q < ng; q++) pr[slot[gen[q]]] = pv[t * ng + q];
            for (int k = 0; k < np_; k++) {
                double sum = 0.0;
                for (int q = 0; q < ng; q++) sum += pv[t * ng + q] * E[(size_t)q * np_ + k];
                pr[slot[pin[k]]] = -sum;
            }
        }
        for (int k = 0; k < np_; k++) {
            const double *wk = WROW(pin[k]);
            double g = -1.0 / wk[pcol[k]];
            pi[(size_t)pcol[k] * m + slot[pin[k]]] = -g;
            double *row = px + (size_t)pcol[k] * ndx;
            for (int r = 0; r < ndx; r++) row[r] = g * wk[nu + r];
            pe[pcol[k]] = g * wk[nu + ndx];
        }
        /* ||D||_F^2 ||D^+||_F^2 bounds the condition number of D (as in the whole QR) */
        double nD = 0.0, nP = 0.0;
        for (int j = 0; j < c; j++) {
            const double *wj = WROW(j);
            for (int p = 0; p < nu; p++) nD += wj[p] * wj[p];
        }
        for (int p = 0; p < nu; p++)
            for (int j = 0; j < c; j++) {
                double v = pi[(size_t)p * m + slot[j]];
                nP += v * v;
            }
        double cond2 = nD * nP;
        if (!(cond2 < 1.0 / (rtol * rtol))) { ok[i] = 0; continue; }  /* NaN: not ok */
        /* P_x = -D^+ C, P_e = -D^+ e on the free inputs (the eliminated [C | e]) */
        for (int q = 0; q < ng; q++) {
            const double *gq = G + (size_t)q * lg;
            for (int t = 0; t < nf; t++) {
                double g = -pv[t * ng + q];
                double *row = px + (size_t)fcol[t] * ndx;
                for (int r = 0; r < ndx; r++) row[r] += g * gq[r];
                pe[fcol[t]] += g * gq[ndx];
            }
        }
        /* null-space basis: the columns g.. of Q on the free inputs, as columns c.. */
        for (int t = 0; t < nf; t++)
            for (int col = ng; col < nf; col++)
                z[fcol[t] * nu + np_ + col] = Q[t * nf + col];
        /* well conditioned (||D||_F ||D^+||_F <= 3e4): the rows are met far within the
         * 1e-8 test below; otherwise check it */
        if (cond2 > 1e9) {
            double emax = 0.0, res = 0.0;
            for (int j = 0; j < c; j++) {
                const double *wj = WROW(j);
                double r = wj[nu + ndx];
                for (int p = 0; p < nu; p++) r += wj[p] * pe[p];
                if (fabs(wj[nu + ndx]) > emax) emax = fabs(wj[nu + ndx]);
                if (fabs(r) > res) res = fabs(r);
            }
            unmet[i] = res > 1e-8 * (1.0 + emax);
        }
#undef WROW
    }
    ret = 0;
done:
    free(a); free(R); free(Ri); free(Q); free(pv); free(wq); free(G); free(E); free(slot);
    free(pin); free(pcol); free(gen); free(fcol); free(taken);
    return ret;
}

#undef project
#undef vec
#undef vload
#undef vstore
#undef vbc
#undef vsum
#undef upd
#undef upd1
#undef gemm
#undef axpy
#undef scal
#undef copy
#undef dot
#undef matvec
#undef get_mat
#undef get_vec
#undef chol_upper
#undef chol_solve
#undef chol_solve_vec
#undef lower_to_upper
#undef backward
#undef box_qp
#undef policy_cost_to_go
#undef qp_value
#undef rollout
#endif
