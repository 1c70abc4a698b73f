/*
 * One evaluation of the ILQR's problem in one call: the CasADi-generated value functions
 * called through their C entry points, then the scalar terms the line search reads.
 *
 * What IlqrSolver._evaluate does with numpy (values, values_term, state difference,
 * merit.evaluation_stats, AugmentedLagrangian.value_and_violation), without its ~40 numpy
 * and CasADi calls per evaluation from Python. evaluation.py binds it with ctypes;
 * riccati_c.py compiles this file with riccati.c into one library (riccati_al_rows, the
 * augmented-Lagrangian rows, comes from there).
 *
 * Generated functions use CasADi's C interface (the one its code generator documents):
 * f(arg, res, iw, w, mem) with caller-owned argument, result and work arrays sized by
 * f_work(). A null argument reads as zeros; a null result is not computed.
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>

#include "riccati.h"  /* riccati_al_rows */

typedef long long casadi_int_t; /* casadi_int of the generated code (the binder checks it) */
typedef int (*generated_entry)(const double **arg, double **res, casadi_int_t *iw, double *w,
                               int mem);

/* a generated function with its arrays (arg and res have f_work()'s sizes, >= n_in, n_out) */
typedef struct {
    generated_entry f;
    const double **arg;
    double **res;
    casadi_int_t *iw;
    double *w;
} generated_fn;

/* the augmented-Lagrangian rows of one block: n doubles each */
typedef struct {
    int n;
    const double *lb, *ub, *lam, *lam_lo, *lam_up, *rho;
} al_block;

/*
 * What an evaluation reads besides the trajectory. Row-major arrays:
 *  S (N, ns) the fixed single variables, repeated per stage node (the mapped functions
 *  take one column per node; the terminal one reads the first); P (N+1, npar) the
 *  parameters node by node;
 *  x_init (nx) node 0's fixed state or NULL (free); W (N, nr), WN (nrN) residual weights;
 *  b, eq (N, ncon) the projected rows' targets and mask (eq: 0/1), bN, eqN (ncNcon).
 */
typedef struct {
    int N, nx, ndx, nr, nc, ncon, nrN, ncN, ncNcon, npar;
    int barrier;
    double mu, delta;
    generated_fn values;      /* (x, u, s, p, x_next) -> (gap, r, c), mapped over N nodes */
    generated_fn values_term; /* (x, s, p) -> (r, c) of node N */
    generated_fn difference;  /* (x0, x1) -> dx */
    const double *S, *P, *x_init, *W, *WN, *b, *bN;
    const uint8_t *eq, *eqN;
    al_block al, alN;
} evaluation_data;

/* evaluation outputs, row-major: gap (N, ndx), r (N, nr), c (N, nc), rN (nrN), cN (ncN), d0 */
typedef struct {
    double *gap, *r, *c, *rN, *cN, *d0;
} evaluation_out;

enum { EV_COST, EV_GAP_L1, EV_GAP_MAX, EV_EQ_L1, EV_EQ_MAX, EV_AL, EV_AL_VIOL, N_EV };


/* g(args) -> res: the first n_args arguments and n_res results set, the rest left as they
 * are (f_work's sizes leave room for them) */
static int call(const generated_fn *g, const double *const *args, int n_args,
                double *const *res, int n_res)
{
    for (int i = 0; i < n_args; i++) g->arg[i] = args[i];
    for (int i = 0; i < n_res; i++) g->res[i] = res[i];
    return g->f(g->arg, g->res, g->iw, g->w, 0);
}

/* no NaN nor inf in x: x * 0 is 0 for a finite x, NaN otherwise, and NaN propagates through
 * a sum (eight sums: independent chains run in parallel without -ffast-math; 40 us for
 * go2's 1.9 MB of quadratisation where one chain, or an integer test of the exponent bits
 * on the baseline ISA, takes 180) */
static int all_finite(const double *x, size_t n)
{
    double s[8] = {0.0};
    size_t i = 0;
    for (; i + 8 <= n; i += 8)
        for (int j = 0; j < 8; j++) s[j] += x[i + j] * 0.0;
    for (; i < n; i++) s[0] += x[i] * 0.0;
    double total = 0.0;
    for (int j = 0; j < 8; j++) total += s[j];
    return total == 0.0;
}

static void abs_sum_max(const double *x, size_t n, double *sum, double *max)
{
    for (size_t i = 0; i < n; i++) {
        double a = fabs(x[i]);
        *sum += a;
        if (a > *max) *max = a;
    }
}

/*
 * Evaluate the problem at X (N+1, nx), U (N, nu) (row-major). Writes `o`'s arrays and
 * stats[N_EV]: cost (sum W r^2 + sum WN rN^2), gap_l1 / gap_max (|gap| and |d0|),
 * eq_l1 / eq_max (|c - b| over the projected rows), al (the augmented-Lagrangian terms of
 * both blocks), al_viol (their largest bound violation).
 * Returns 0; 1 when a value is not finite (stats not written); 2 when a generated
 * function reports a failure.
 */
int ilqr_evaluate(const evaluation_data *d, const double *X, const double *U,
                  const evaluation_out *o, double *stats)
{
    const int N = d->N, nx = d->nx, ndx = d->ndx;
    const double *stage[5] = {X, U, d->S, d->P, X + nx};
    double *stage_out[3] = {o->gap, o->r, o->c};
    if (call(&d->values, stage, 5, stage_out, 3)) return 2;
    const double *term[3] = {X + (size_t)N * nx, d->S, d->P + (size_t)N * d->npar};
    double *term_out[2] = {o->rN, o->cN};
    if (call(&d->values_term, term, 3, term_out, 2)) return 2;
    if (d->x_init) {
        const double *pair[2] = {X, d->x_init};
        if (call(&d->difference, pair, 2, &o->d0, 1)) return 2;
    } else {
        for (int i = 0; i < ndx; i++) o->d0[i] = 0.0;
    }
    if (!all_finite(o->gap, (size_t)N * ndx) || !all_finite(o->r, (size_t)N * d->nr)
        || !all_finite(o->c, (size_t)N * d->nc) || !all_finite(o->rN, d->nrN)
        || !all_finite(o->cN, d->ncN) || !all_finite(o->d0, ndx))
        return 1;

    double cost = 0.0;
    for (size_t i = 0; i < (size_t)N * d->nr; i++) cost += d->W[i] * o->r[i] * o->r[i];
    for (int i = 0; i < d->nrN; i++) cost += d->WN[i] * o->rN[i] * o->rN[i];

    double gap_l1 = 0.0, gap_max = 0.0, eq_l1 = 0.0, eq_max = 0.0;
    abs_sum_max(o->gap, (size_t)N * ndx, &gap_l1, &gap_max);
    abs_sum_max(o->d0, ndx, &gap_l1, &gap_max);
    for (int k = 0; k < N; k++) {
        const double *ck = o->c + (size_t)k * d->nc, *bk = d->b + (size_t)k * d->ncon;
        const uint8_t *ek = d->eq + (size_t)k * d->ncon;
        for (int i = 0; i < d->ncon; i++) {
            if (!ek[i]) continue;
            double e = fabs(ck[i] - bk[i]);
            eq_l1 += e;
            if (e > eq_max) eq_max = e;
        }
    }
    for (int i = 0; i < d->ncNcon; i++) {
        if (!d->eqN[i]) continue;
        double e = fabs(o->cN[i] - d->bN[i]);
        eq_l1 += e;
        if (e > eq_max) eq_max = e;
    }

    double sums[2], sumsN[2];
    const al_block *a = &d->al, *aN = &d->alN;
    riccati_al_rows(a->n, o->c, a->lb, a->ub, a->lam, a->lam_lo, a->lam_up, a->rho, d->barrier,
                    d->mu, d->delta, NULL, NULL, NULL, sums);
    riccati_al_rows(aN->n, o->cN, aN->lb, aN->ub, aN->lam, aN->lam_lo, aN->lam_up, aN->rho,
                    d->barrier, d->mu, d->delta, NULL, NULL, NULL, sumsN);

    stats[EV_COST] = cost;
    stats[EV_GAP_L1] = gap_l1;
    stats[EV_GAP_MAX] = gap_max;
    stats[EV_EQ_L1] = eq_l1;
    stats[EV_EQ_MAX] = eq_max;
    stats[EV_AL] = sums[0] + sumsN[0];
    stats[EV_AL_VIOL] = sums[1] > sumsN[1] ? sums[1] : sumsN[1];
    return 0;
}

/*
 * The quadratisation's generated functions and arrays: the stage function
 * (x, u, s, p, w_r, w_c, t_c) -> 9 outputs mapped over N nodes, the terminal one
 * (x, s, p, w_r, w_c, t_c) -> 3 outputs; their outputs point into `buffer` (n_buffer
 * doubles: one finiteness test covers them); w, t (N, nc) and wN, tN (ncN) receive the
 * augmented-Lagrangian rows' Gauss-Newton weights and targets they take.
 */
typedef struct {
    generated_fn stage, term;
    double *w, *t, *wN, *tN;
    double *out[9];
    double *out_term[3];
    const double *buffer;
    size_t n_buffer;
} quadratise_data;

/*
 * Quadratise at X (N+1, nx), U (N, nu) whose evaluation gave the constraint rows c (N, nc),
 * cN (ncN): what IlqrSolver._quadratise does (AugmentedLagrangian.weights_targets of both
 * blocks, the two generated functions, the finiteness test of their outputs).
 * Returns 0; 1 when an output is not finite; 2 when a generated function reports a failure.
 */
int ilqr_quadratise(const evaluation_data *d, const quadratise_data *q, const double *X,
                    const double *U, const double *c, const double *cN)
{
    double sums[2];
    const al_block *a = &d->al, *aN = &d->alN;
    riccati_al_rows(a->n, c, a->lb, a->ub, a->lam, a->lam_lo, a->lam_up, a->rho, d->barrier,
                    d->mu, d->delta, q->w, q->t, NULL, sums);
    riccati_al_rows(aN->n, cN, aN->lb, aN->ub, aN->lam, aN->lam_lo, aN->lam_up, aN->rho,
                    d->barrier, d->mu, d->delta, q->wN, q->tN, NULL, sums);

    const double *stage[7] = {X, U, d->S, d->P, d->W, q->w, q->t};
    if (call(&q->stage, stage, 7, q->out, 9)) return 2;
    const double *term[6] = {X + (size_t)d->N * d->nx, d->S, d->P + (size_t)d->N * d->npar,
                             d->WN, q->wN, q->tN};
    if (call(&q->term, term, 6, q->out_term, 3)) return 2;
    return all_finite(q->buffer, q->n_buffer) ? 0 : 1;
}
