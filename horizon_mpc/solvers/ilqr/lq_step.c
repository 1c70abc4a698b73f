/*
 * The LQ step of one ILQR iteration on arrays bound once: the projected equality rows
 * stacked and factorised, the backward pass, the rollout and the step's scalar measures.
 *
 * The same calls as riccati_c.py's wrappers (stack_rows_c, project_rows_c, backward_pass_c,
 * linear_rollout_c, step_stats_c) make, without their per-call marshalling (pointer and
 * stride tables of ~30 arrays, fresh outputs): lq_step.py fills an lq_step once with the
 * quadratisation's blocks (read through their element strides, as riccati.c reads them)
 * and persistent outputs, and each call passes only what changes between iterations: the
 * evaluation's arrays, the layout of the projected rows, the regularisation, the output
 * gains. riccati_c.py compiles this file with riccati.c into one library.
 */
#include <stddef.h>
#include <stdint.h>

#include "riccati.h"

/*
 * Everything but the per-call arrays. Strides are in elements (node, row, column), set by
 * the binder for the per-call arrays too: those must be C-contiguous with the shapes of
 * the comments below.
 */
typedef struct {
    int N, ndx, nu, nc, ncN, variant;
    double rtol;
    const int *pat;                      /* [A | B]'s pattern (riccati_backward's) or NULL */
    const double *sr_in[N_SR];           /* riccati_stack_rows' inputs */
    int64_t sr_st[3 * N_SR];
    const double *bw_in[N_IN];           /* riccati_backward's */
    int64_t bw_st[3 * N_IN];
    double *bw_out[N_OUT];               /* K is set per call */
    const double *ro_in[N_RO];           /* riccati_rollout's */
    int64_t ro_st[3 * N_RO];
    /* projection outputs: W (N m + 1, nu + ndx + 1), rows (N m), pinv (N, nu, m) for the
     * m of the last lq_project; P_e (N, nu), P_x (N, nu, ndx), Z (N, nu, nu), fr (N, nu),
     * ok, unmet, con (N) */
    double *W, *P_e, *P_x, *Z, *fr, *pinv;
    uint8_t *rows, *ok, *unmet, *con;
    double *dX, *dU;                     /* (N+1, ndx), (N, nu) */
    const double *lx, *lu, *lxN;         /* C-contiguous (N, ndx), (N, nu), (ndx) */
} lq_step;

/*
 * Stack and factorise the projected rows (riccati_stack_rows, then riccati_project).
 *  c (N, ldc: its first nc columns are the constraint rows), b (N, nc), cN (ncN), bN (ncN),
 *  gap (N, ndx); own, nxt (N, nc) the layout's masks; m slots per node: k own columns,
 *  then j of the next node's rows or, at node N-1, jt terminal ones (riccati_stack_rows).
 * Writes the projection outputs and con (1 where a node has a projected row).
 * Returns the number of nodes that are not ok (the caller takes the SVD there), or -1: out
 * of memory.
 */
int lq_project(lq_step *s, const double *c, const double *b, const double *cN,
               const double *bN, const double *gap, const uint8_t *own, const uint8_t *nxt,
               int m, int k, int j, int jt, const int *own_cols, const int *nxt_cols,
               const int *term_cols)
{
    s->sr_in[SR_C] = c;
    s->sr_in[SR_BND] = b;
    s->sr_in[SR_CN] = cN;
    s->sr_in[SR_BNDN] = bN;
    s->sr_in[SR_GAP] = gap;
    if (riccati_stack_rows(s->N, s->nu, s->ndx, s->nc, m, k, j, jt, own_cols, nxt_cols,
                           term_cols, s->sr_in, s->sr_st, own, nxt, s->pat, s->W, s->rows))
        return -1;
    if (riccati_project(s->N, m, s->nu, s->ndx, s->W, s->rows, s->rtol, s->P_e, s->P_x, s->Z,
                        s->fr, s->pinv, s->ok, s->unmet, s->variant))
        return -1;
    int bad = 0;
    for (int i = 0; i < s->N; i++) {
        uint8_t any = 0;
        for (int q = 0; q < m; q++) any |= s->rows[(size_t)i * m + q];
        s->con[i] = any != 0;
        bad += !s->ok[i];
    }
    return bad;
}

/*
 * riccati_backward with regularisation mu, the defects gap (N, ndx), the last projection
 * when `projected` (else none), the gains written to K (N, nu, ndx). Returns its value.
 */
int lq_backward(lq_step *s, const double *gap, double mu, int projected, double *K,
                int *fail_node)
{
    s->bw_in[IN_F] = gap;
    s->bw_out[OUT_K] = K;
    return riccati_backward(s->N, s->ndx, s->nu, s->bw_in, s->bw_st, mu,
                            projected ? s->con : NULL, s->pat, s->bw_out, s->variant,
                            fail_node);
}

/*
 * The rollout of the gains K (N, nu, ndx) and the last backward pass's k from dx0 (ndx)
 * with the defects gap (N, ndx) into dX, dU, then riccati_step_stats into stats[4] (with
 * the projection's D^+ when m > 0). Returns 0, or -1: out of memory.
 */
int lq_rollout(lq_step *s, const double *gap, const double *K, const double *dx0, int m,
               double *stats)
{
    s->ro_in[RO_F] = gap;
    s->ro_in[RO_K] = K;
    s->ro_in[RO_DX0] = dx0;
    if (riccati_rollout(s->N, s->ndx, s->nu, s->ro_in, s->ro_st, s->dX, s->dU, s->variant))
        return -1;
    return riccati_step_stats(s->N, s->ndx, s->nu, m, s->lx, s->lu, s->lxN, s->bw_out[OUT_SV],
                              s->bw_out[OUT_S], s->bw_out[OUT_QU], s->bw_out[OUT_QUU],
                              s->bw_out[OUT_QUX], s->dX, s->dU, m ? s->pinv : NULL, stats);
}
