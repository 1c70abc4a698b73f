"""Exact treatment of equality constraints in the ILQR backward pass (null-space projection).

An equality row that depends on the input at node k (``c(x_k, u_k) = b``: under-actuation,
zero swing force) is linearised as ``C_k dx_k + D_k du_k + e_k = 0``. A state-only equality
row at node k+1 (``c(x_{k+1}) = b``: stance foot velocity, a final state) is moved onto the
input of node k through the linearised dynamics ``dx_{k+1} = A_k dx_k + B_k du_k + f_k``
(Giftthaler & Buchli 2017). Per node, with the pseudo-inverse ``D^+`` and a basis ``Z`` of
the null space of ``D`` (batched SVD over nodes):

    du = P_e + P_x dx + Z w,    P_e = -D^+ e,  P_x = -D^+ C

and the backward pass minimises over ``w`` only, so every step of the solver satisfies the
linearised equalities exactly (with ``alpha = 1``). Rows that do not fit in the inputs of
their node (more rows than inputs, e.g. a full final state on a one-input system) stay with
the augmented Lagrangian, which drives them to feasibility over the iterations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["EqualityLayout", "Projection", "project"]


@dataclass
class EqualityLayout:
    """Which constraint rows are projected at which node.

    ``own`` (N, nc_con): input-dependent equality rows handled at their own node.
    ``next`` (N, nc_con): state-only equality rows of node k+1 handled at node k (k < N-1).
    ``term`` (ncN_con,): state-only equality rows of the final node handled at node N-1.
    ``b``, ``bN``: their targets (the equal bounds), zero elsewhere.
    """

    own: np.ndarray
    next: np.ndarray
    term: np.ndarray
    b: np.ndarray
    bN: np.ndarray

    @property
    def any(self) -> bool:
        """True if at least one row is projected."""
        return bool(self.own.any() or self.next.any() or self.term.any())

    @classmethod
    def empty(cls, n: int, nc_con: int, ncN_con: int) -> EqualityLayout:
        """No projected row."""
        return cls(np.zeros((n, nc_con), bool), np.zeros((n, nc_con), bool),
                   np.zeros(ncN_con, bool), np.zeros((n, nc_con)), np.zeros(ncN_con))

    @classmethod
    def from_bounds(cls, lb: np.ndarray, ub: np.ndarray, uses_input: np.ndarray,
                    lbN: np.ndarray, ubN: np.ndarray, nu: int,
                    reach: np.ndarray | None = None,
                    reachN: np.ndarray | None = None) -> EqualityLayout:
        """Choose the projected rows from the bounds of the constraint rows.

        Args:
            lb, ub: (N, nc_con) stage bounds (``-inf``/``inf`` where inactive).
            uses_input: (nc_con,) True for rows that depend on the input.
            lbN, ubN: (ncN_con,) terminal bounds.
            nu: inputs per node (at most that many rows are projected at a node).
            reach, reachN: (nc_con,), (ncN_con,) rows an input can move in one step (the
                others, e.g. a position under a double integrator, stay with the
                augmented Lagrangian); None: all.
        """
        n = lb.shape[0]
        eq = np.isfinite(lb) & (lb == ub)
        eqN = np.isfinite(lbN) & (lbN == ubN)
        if reach is not None:
            eq &= reach[None, :]
        if reachN is not None:
            eqN &= reachN
        own = eq & uses_input[None, :]
        state = eq & ~uses_input[None, :]
        nxt = np.zeros_like(own)
        nxt[:-1] = state[1:]
        term = eqN.copy()
        n_own = own.sum(axis=1)
        fits = n_own + nxt.sum(axis=1) <= nu
        nxt[~fits] = False
        if n and n_own[-1] + term.sum() > nu:
            term[:] = False
        return cls(own, nxt, term, np.where(eq, lb, 0.0), np.where(eqN, lbN, 0.0))

    def stage_rows(self) -> np.ndarray:
        """(N, nc_con) rows of the stage layout handled by projection (own or from k-1)."""
        rows = self.own.copy()
        rows[1:] |= self.next[:-1]
        return rows


@dataclass
class Projection:
    """Per-node affine parametrisation ``du = P_e + P_x dx + Z w`` of the equality set.

    Shapes: P_e (N, nu), P_x (N, nu, ndx), Z (N, nu, nu) (columns of the range of D^T are
    zero), free (N, nu) (1 for null-space columns), pinv (N, nu, m) and ``rows`` (N, m) the
    mask of real rows; ``constrained`` (N,) marks nodes with at least one row;
    ``rank_deficient`` counts nodes whose rows could not all be met (least squares).
    """

    P_e: np.ndarray
    P_x: np.ndarray
    Z: np.ndarray
    free: np.ndarray
    pinv: np.ndarray
    rows: np.ndarray
    constrained: np.ndarray
    rank_deficient: int


def project(layout: EqualityLayout, c: np.ndarray, cx: np.ndarray, cu: np.ndarray,
            cN: np.ndarray, cxN: np.ndarray, A: np.ndarray, B: np.ndarray,
            gap: np.ndarray, rtol: float = 1e-9) -> Projection:
    """Linearised equality rows of every node and their null-space parametrisation.

    Args:
        layout: the projected rows.
        c, cx, cu: stage constraint values (N, nc_con) and Jacobians (N, nc_con, ndx|nu).
        cN, cxN: terminal constraint values (ncN_con,) and Jacobian (ncN_con, ndx).
        A, B, gap: linearised dynamics (N, ndx, ndx), (N, ndx, nu), defects (N, ndx).
    """
    n, ndx, nu = B.shape
    own_cols = np.flatnonzero(layout.own.any(axis=0))
    nxt_cols = np.flatnonzero(layout.next.any(axis=0))
    term_cols = np.flatnonzero(layout.term)
    m_next = max(len(nxt_cols), len(term_cols))
    m = len(own_cols) + m_next
    if m == 0 or nu == 0:
        return Projection(np.zeros((n, nu)), np.zeros((n, nu, ndx)),
                          np.broadcast_to(np.eye(nu), (n, nu, nu)).copy(), np.ones((n, nu)),
                          np.zeros((n, nu, 0)), np.zeros((n, 0), bool), np.zeros(n, bool), 0)
    D = np.zeros((n, m, nu))
    C = np.zeros((n, m, ndx))
    e = np.zeros((n, m))
    rows = np.zeros((n, m), bool)
    k = len(own_cols)
    if k:
        mask = layout.own[:, own_cols]
        D[:, :k] = cu[:, own_cols] * mask[..., None]
        C[:, :k] = cx[:, own_cols] * mask[..., None]
        e[:, :k] = (c[:, own_cols] - layout.b[:, own_cols]) * mask
        rows[:, :k] = mask
    if len(nxt_cols) and n > 1:
        j = len(nxt_cols)
        mask = layout.next[:-1, nxt_cols]
        Jn = cx[1:, nxt_cols] * mask[..., None]  # rows of node k+1, (N-1, j, ndx)
        D[:-1, k:k + j] = Jn @ B[:-1]
        C[:-1, k:k + j] = Jn @ A[:-1]
        e[:-1, k:k + j] = ((c[1:, nxt_cols] - layout.b[1:, nxt_cols]) * mask
                           + np.einsum("kij,kj->ki", Jn, gap[:-1]))
        rows[:-1, k:k + j] = mask
    if len(term_cols):
        j = len(term_cols)
        Jn = cxN[term_cols]
        D[-1, k:k + j] = Jn @ B[-1]
        C[-1, k:k + j] = Jn @ A[-1]
        e[-1, k:k + j] = cN[term_cols] - layout.bN[term_cols] + Jn @ gap[-1]
        rows[-1, k:k + j] = True
    constrained = rows.any(axis=1)
    # batched SVD: D = U diag(s) V^T; range of D^T = V[:, :r], null space = the rest
    U, s, Vt = np.linalg.svd(D, full_matrices=True)
    V = np.swapaxes(Vt, 1, 2)
    smax = s[:, :1] if s.shape[1] else np.zeros((n, 1))
    keep = s > rtol * np.maximum(smax, 1e-300)  # (n, min(m, nu))
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    r = keep.shape[1]
    pinv = (V[:, :, :r] * inv_s[:, None, :]) @ np.swapaxes(U[:, :, :r], 1, 2)  # (n, nu, m)
    free = np.ones((n, nu))
    free[:, :r] = ~keep
    Z = V * free[:, None, :]
    P_e = -np.einsum("kum,km->ku", pinv, e)
    P_x = -pinv @ C
    residual = np.einsum("kmu,ku->km", D, P_e) - (-e)
    rank_deficient = int(np.sum(np.max(np.abs(residual), axis=1, initial=0.0)
                                > 1e-8 * (1.0 + np.max(np.abs(e), axis=1, initial=0.0))))
    return Projection(P_e, P_x, Z, free, pinv, rows, constrained, rank_deficient)
