"""Backward Riccati recursion and linear rollout of the multiple-shooting ILQR.

Linear-quadratic sub-problem at the current iterate, in tangent coordinates:

    dx_{k+1} = A_k dx_k + B_k du_k + f_k          (f_k: defect F(x_k, u_k) (-) x_{k+1})
    cost     = sum_k l_k(dx_k, du_k) + l_N(dx_N)   (Gauss-Newton quadratic models)

Arrays are stacked over nodes on the first axis: A (N, ndx, ndx), B (N, ndx, nu),
lx (N, ndx), lu (N, nu), lxx (N, ndx, ndx), luu (N, nu, nu), lux (N, nu, ndx),
f (N, ndx). This is the per-iteration hot path: a tight loop of BLAS calls per node.

Input bounds (control-limited DDP, Tassa, Mansard & Todorov 2014): with ``box = (lo, hi)``
(N, nu) bounds on ``du`` (``lb - u``, ``ub - u``; infinite for none), the feed-forward term
of a node without projected rows is the solution of the box-constrained QP
``min 0.5 du^T Q_uu du + Q_u^T du, lo <= du <= hi`` (:func:`box_qp`), the gains of its
clamped inputs are zero and the value function is the cost-to-go of that policy; the
rollout clamps ``du`` into the box, so every step stays within the bounds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import LinAlgError, cho_factor, cho_solve

from horizon_mpc.solvers.ilqr.equality import Projection

__all__ = ["BackwardResult", "backward_pass", "box_qp", "linear_rollout"]


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


BOX_QP_MAX_ITER = 100  # projected-Newton iterations of box_qp (a few in practice)


def box_qp(H: np.ndarray, q: np.ndarray, lo: np.ndarray,
           hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple | None] | None:
    """``argmin 0.5 x^T H x + q^T x`` subject to ``lo <= x <= hi`` by projected Newton
    (Bertsekas 1982, as Tassa et al. 2014 use it): Newton steps on the free inputs, an
    Armijo search along the projected path, from ``x = clip(0, lo, hi)``.

    Args:
        H (n, n): symmetric; positive definite on every free set met.
        q (n,); lo, hi (n,): bounds, ``-inf``/``inf`` for none, ``lo <= hi``.

    Returns:
        ``(x, free, chol)``: the solution, the mask of the inputs not clamped at it (an
        input with ``lo == hi`` is always clamped) and scipy's Cholesky factor of ``H`` on
        them (None when all are clamped); None when that block of ``H`` is not positive
        definite.
    """
    n = q.shape[0]
    x = np.minimum(np.maximum(0.0, lo), hi)
    fixed = lo == hi
    for it in range(BOX_QP_MAX_ITER + 1):
        g = q + H @ x
        free = ~(fixed | ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
        if not free.any():
            return x, free, None
        try:
            chol = cho_factor(H[np.ix_(free, free)], lower=True, check_finite=False)
        except LinAlgError:
            return None
        d = np.zeros(n)
        d[free] = -cho_solve(chol, g[free], check_finite=False)
        slope = float(g @ d)
        if it == BOX_QP_MAX_ITER or not slope < -1e-14 * (1.0 + abs(float(q @ x))):
            break
        value = 0.5 * float(x @ H @ x) + float(q @ x)
        step, accepted = 1.0, None
        while step > 1e-10:
            xt = np.minimum(np.maximum(x + step * d, lo), hi)
            if 0.5 * float(xt @ H @ xt) + float(q @ xt) - value <= 0.1 * float(g @ (xt - x)):
                accepted = xt
                break
            step *= 0.6
        if accepted is None:
            break
        x = accepted
    return x, free, chol


def _cost_to_go(Qx, Qu, Qxx, Quu, Qux, K, k) -> tuple[np.ndarray, np.ndarray]:
    """``(S, s)`` of the policy ``du = K dx + k`` in the Q-function (any K, k: a projected
    or box-constrained node's; the unconstrained optimum simplifies it)."""
    S = Qxx + K.T @ (Quu @ K + Qux) + Qux.T @ K
    s = Qx + K.T @ (Quu @ k + Qu) + Qux.T @ k
    return S, s


def _boxed(box: tuple[np.ndarray, np.ndarray] | None, i: int) -> bool:
    """Whether node ``i`` has a finite input bound in ``box``."""
    return box is not None and bool(np.isfinite(box[0][i]).any()
                                    or np.isfinite(box[1][i]).any())


def backward_pass(A: np.ndarray, B: np.ndarray, lx: np.ndarray, lu: np.ndarray, lxx: np.ndarray,
                  luu: np.ndarray, lux: np.ndarray, f: np.ndarray, lxN: np.ndarray,
                  lxxN: np.ndarray, mu: float, proj: Projection | None = None,
                  box: tuple[np.ndarray, np.ndarray] | None = None) -> BackwardResult | None:
    """Riccati recursion with Levenberg-Marquardt regularisation ``mu`` on Q_uu.

    With ``proj`` (see :mod:`.equality`), the input of a constrained node is restricted to
    ``du = P_e + P_x dx + Z w`` and the recursion minimises over ``w``; the value function
    is the cost-to-go under that policy. With ``box = (lo, hi)`` (N, nu) bounds on ``du``,
    the other nodes' inputs stay within them (see the module docstring; a node with
    projected rows ignores its box). Returns None when a (reduced) Q_uu is not positive
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
            Si, si = _cost_to_go(Qx, Qu, Qxx, Quu, Qux, Ki, ki)
        elif _boxed(box, i):
            qp = box_qp(Quu, Qu, box[0][i], box[1][i])
            if qp is None:
                return None
            ki, free, chol = qp
            Ki = np.zeros((nu, ndx))
            if chol is not None:
                Ki[free] = -cho_solve(chol, Qux[free], check_finite=False)
            Si, si = _cost_to_go(Qx, Qu, Qxx, Quu, Qux, Ki, ki)
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


def linear_rollout(A: np.ndarray, B: np.ndarray, f: np.ndarray, bw: BackwardResult, dx0: np.ndarray,
                   box: tuple[np.ndarray, np.ndarray] | None = None,
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The full step (dX (N+1, ndx), dU (N, nu)) of the linear-quadratic sub-problem;
    ``box = (lo, hi)`` (N, nu): each ``du`` clamped into them (NaN stays NaN)."""
    N, ndx, nu = B.shape
    dX = np.empty((N + 1, ndx))
    dU = np.empty((N, nu))
    dX[0] = dx0
    for i in range(N):
        dU[i] = bw.k[i] + bw.K[i] @ dX[i]
        if box is not None:
            du = dU[i]
            np.copyto(du, box[0][i], where=du < box[0][i])
            np.copyto(du, box[1][i], where=du > box[1][i])
        dX[i + 1] = A[i] @ dX[i] + B[i] @ dU[i] + f[i]
    return dX, dU
