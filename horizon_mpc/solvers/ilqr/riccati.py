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

from horizon_mpc.solvers.ilqr.equality import Projection

__all__ = ["BackwardResult", "backward_pass", "linear_rollout"]


@dataclass
class BackwardResult:
    """Feedback gains K (N, nu, ndx), feed-forward k (N, nu), value-function Hessians
    S (N+1, ndx, ndx) and gradients s (N+1, ndx), and the Q-function blocks."""

    K: np.ndarray
    k: np.ndarray
    S: np.ndarray
    s: np.ndarray
    Qu: np.ndarray | None = None  # (N, nu) of the recursion (for multiplier estimates)
    Quu: np.ndarray | None = None  # (N, nu, nu)
    Qux: np.ndarray | None = None  # (N, nu, ndx)


def backward_pass(A, B, lx, lu, lxx, luu, lux, f, lxN, lxxN, mu: float,
                  proj: Projection | None = None) -> BackwardResult | None:
    """Riccati recursion with Levenberg-Marquardt regularisation ``mu`` on Q_uu.

    With ``proj`` (see :mod:`.equality`), the input of a constrained node is restricted to
    ``du = P_e + P_x dx + Z w`` and the recursion minimises over ``w``; the value function
    is the cost-to-go under that policy. Returns None when a (reduced) Q_uu is not positive
    definite (the caller raises ``mu``).
    """
    N, ndx, nu = B.shape
    K = np.empty((N, nu, ndx))
    k = np.empty((N, nu))
    S = np.empty((N + 1, ndx, ndx))
    s = np.empty((N + 1, ndx))
    Qu_all = np.empty((N, nu))
    Quu_all = np.empty((N, nu, nu))
    Qux_all = np.empty((N, nu, ndx))
    S[N] = lxxN
    s[N] = lxN
    eye = mu * np.eye(nu)
    constrained = proj.constrained if proj is not None else np.zeros(N, bool)
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
        Qu_all[i], Quu_all[i], Qux_all[i] = Qu, Quu, Qux
        if constrained[i]:
            Z, Pe, Px = proj.Z[i], proj.P_e[i], proj.P_x[i]
            H = Z.T @ Quu @ Z + np.diag(1.0 - proj.free[i])
            try:
                chol = cho_factor(H, lower=True, check_finite=False)
            except LinAlgError:
                return None
            rhs = Z.T @ np.column_stack((Qux + Quu @ Px, Qu + Quu @ Pe))
            sol = Z @ cho_solve(chol, rhs, check_finite=False)
            Ki, ki = Px - sol[:, :ndx], Pe - sol[:, ndx]
            QuuK = Quu @ Ki
            Si = Qxx + Ki.T @ (QuuK + Qux) + Qux.T @ Ki
            si = Qx + Ki.T @ (Quu @ ki + Qu) + Qux.T @ ki
        else:
            try:
                chol = cho_factor(Quu, lower=True, check_finite=False)
            except LinAlgError:
                return None
            sol = cho_solve(chol, np.column_stack((Qux, Qu)), check_finite=False)
            Ki, ki = -sol[:, :ndx], -sol[:, ndx]
            Si = Qxx + Qux.T @ Ki
            si = Qx + Qux.T @ ki
        if not np.all(np.isfinite(ki)):
            return None
        K[i], k[i] = Ki, ki
        S[i] = 0.5 * (Si + Si.T)
        s[i] = si
    return BackwardResult(K, k, S, s, Qu_all, Quu_all, Qux_all)


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
