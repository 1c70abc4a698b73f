/*
 * The entry points of riccati.c that the library's other sources (evaluation.c, lq_step.c)
 * call, and the order of their array arguments. Shapes and conventions: riccati.c.
 */
#ifndef HORIZON_MPC_RICCATI_H
#define HORIZON_MPC_RICCATI_H

#include <stdint.h>

/* inputs of riccati_backward, in this order */
enum { IN_A, IN_B, IN_LX, IN_LU, IN_LXX, IN_LUU, IN_LUX, IN_F, IN_LXN, IN_LXXN,
       IN_PE, IN_PX, IN_Z, IN_FREE, IN_BLO, IN_BHI, N_IN };
/* outputs of riccati_backward */
enum { OUT_K, OUT_KFF, OUT_S, OUT_SV, OUT_QU, OUT_QUU, OUT_QUX, N_OUT };
/* inputs of riccati_rollout */
enum { RO_A, RO_B, RO_F, RO_K, RO_KFF, RO_DX0, RO_LO, RO_HI, N_RO };
/* inputs of riccati_stack_rows */
enum { SR_C, SR_BND, SR_CX, SR_CU, SR_CN, SR_BNDN, SR_CXN, SR_A, SR_B, SR_GAP, N_SR };

int riccati_backward(int N, int ndx, int nu, const double *const *in, const int64_t *st,
                     double mu, const uint8_t *con, const int *pat, double *const *out,
                     int variant, int *fail_node);
int riccati_rollout(int N, int ndx, int nu, const double *const *in, const int64_t *st,
                    double *dX, double *dU, int variant);
int riccati_project(int N, int m, int nu, int ndx, const double *W, const uint8_t *rows,
                    double rtol, double *P_e, double *P_x, double *Z, double *fr,
                    double *pinv, uint8_t *ok, uint8_t *unmet, int variant);
int riccati_step_stats(int N, int ndx, int nu, int m, const double *lx, const double *lu,
                       const double *lxN, const double *s, const double *S,
                       const double *Qu, const double *Quu, const double *Qux,
                       const double *dX, const double *dU, const double *pinv, double *out);
int riccati_stack_rows(int N, int nu, int ndx, int nc, int m, int k, int j, int jt,
                       const int *own_cols, const int *nxt_cols, const int *term_cols,
                       const double *const *in, const int64_t *st, const uint8_t *own,
                       const uint8_t *nxt, const int *pat, double *W, uint8_t *rows);
void riccati_al_rows(int n, const double *c, const double *lb, const double *ub,
                     const double *lam, const double *lam_lo, const double *lam_up,
                     const double *rho, int barrier, double mu, double delta, double *w,
                     double *t, double *viol, double *sums);

#endif
