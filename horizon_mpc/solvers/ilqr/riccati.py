"""Backward Riccati recursion and linear rollout of the multiple-shooting ILQR.

Linear-quadratic sub-problem at the current iterate, in tangent coordinates:

    dx_{k+1} = A_k dx_k + B_k du_k + f_k          (f_k: defect F(x_k, u_k) (-) x_{k+1})
    cost     = sum_k l_k(dx_k, du_k) + l_N(dx_N)   (Gauss-Newton quadratic models)

Arrays are stacked over nodes on the first axis: A (N, ndx, ndx), B (N, ndx, nu),
lx (N, ndx), lu (N, nu), lxx (N, ndx, ndx), luu (N, nu, nu), lux (N, nu, ndx),
f (N, ndx). This is the per-iteration hot path: a tight loop of BLAS calls per node.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve

__all__ = ["BackwardResult", "backward_pass", "linear_rollout"]


@dataclass
class BackwardResult:
    """Feedback gains K (N, nu, ndx), feed-forward k (N, nu), value-function Hessians
    S (N+1, ndx, ndx) and gradients s (N+1, ndx)."""

    K: np.ndarray
    k: np.ndarray
    S: np.ndarray
    s: np.ndarray


def backward_pass(A, B, lx, lu, lxx, luu, lux, f, lxN, lxxN, mu: float) -> BackwardResult | None:
    """Riccati recursion with Levenberg-Marquardt regularisation ``mu`` on Q_uu.

    Returns None when a Q_uu is not positive definite (the caller raises ``mu``).
    """
    N, ndx, nu = B.shape
    K = np.empty((N, nu, ndx))
    k = np.empty((N, nu))
    S = np.empty((N + 1, ndx, ndx))
    s = np.empty((N + 1, ndx))
    S[N] = lxxN
    s[N] = lxN
    eye = mu * np.eye(nu)
    for i in range(N - 1, -1, -1):
        Sn, sn = S[i + 1], s[i + 1]
        At, Bt = A[i].T, B[i].T
        g = sn + Sn @ f[i]
        SA = Sn @ A[i]
        SB = Sn @ B[i]
        Qx = lx[i] + At @ g
        Qu = lu[i] + Bt @ g
        Qxx = lxx[i] + At @ SA
        Quu = luu[i] + Bt @ SB + eye
        Qux = lux[i] + Bt @ SA
        try:
            chol = cho_factor(Quu, lower=True, check_finite=False)
        except LinAlgError:
            return None
        sol = cho_solve(chol, np.column_stack((Qux, Qu)), check_finite=False)
        Ki, ki = -sol[:, :ndx], -sol[:, ndx]
        if not np.all(np.isfinite(ki)):
            return None
        K[i], k[i] = Ki, ki
        Si = Qxx + Qux.T @ Ki
        S[i] = 0.5 * (Si + Si.T)
        s[i] = Qx + Qux.T @ ki
    return BackwardResult(K, k, S, s)


def linear_rollout(A, B, f, bw: BackwardResult, dx0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The full step (dX (N+1, ndx), dU (N, nu)) of the linear-quadratic sub-problem."""
    N, ndx, nu = B.shape
    dX = np.empty((N + 1, ndx))
    dU = np.empty((N, nu))
    dX[0] = dx0
    for i in range(N):
        dU[i] = bw.k[i] + bw.K[i] @ dX[i]
        dX[i + 1] = A[i] @ dX[i] + B[i] @ dU[i] + f[i]
    return dX, dU
