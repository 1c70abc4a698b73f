"""Exact treatment of equality constraints in the ILQR backward pass (null-space projection).

An equality row that depends on the input at node k (``c(x_k, u_k) = b``: under-actuation,
zero swing force) is linearised as ``C_k dx_k + D_k du_k + e_k = 0``. A state-only equality
row at node k+1 (``c(x_{k+1}) = b``: stance foot velocity, a final state) is moved onto the
input of node k through the linearised dynamics ``dx_{k+1} = A_k dx_k + B_k du_k + f_k``
(Giftthaler & Buchli 2017). Per node, with the pseudo-inverse ``D^+`` and an orthonormal
basis ``Z`` of the null space of ``D``:

    du = P_e + P_x dx + Z w,    P_e = -D^+ e,  P_x = -D^+ C

and the backward pass minimises over ``w`` only, so every step of the solver satisfies the
linearised equalities exactly (with ``alpha = 1``). Rows that do not fit in the inputs of
their node (more rows than inputs, e.g. a full final state on a one-input system) stay with
the augmented Lagrangian, which drives them to feasibility over the iterations.

``D^+`` and ``Z`` come from a QR of each node's rows: compiled C (``riccati.c``, go2
walking, 40 nodes of 18 rows and 30 inputs: ~0.8 ms), or batched numpy (~1.2 ms) where a
batched SVD takes ~2.4 ms; the nodes whose rows are (nearly) dependent, or more than the
inputs, take the SVD, which also serves as the reference (``project(..., method='svd')``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg.lapack import dtrtri as _trtri

if TYPE_CHECKING:  # riccati_c imports this module
    from horizon_mpc.solvers.ilqr.riccati_c import AbPattern

__all__ = ["INPUT_ATOL", "EqualityLayout", "Projection", "fill_by_svd", "project"]

#: A row whose input Jacobian D is within this of zero (2-norm), relative to max(1, |C|)
#: (its state Jacobian), is round-off, not a row the input moves: e.g. a unit-quaternion row under a
#: norm-preserving integrator (D ~ 1e-20, C ~ 1e-16), whose projection would be
#: P_x = C / D ~ 1e3. Such directions are dropped, as dependent ones are (the row is then met
#: only if it already is; ``Projection.rank_deficient`` counts the nodes where it is not).
INPUT_ATOL = 1e-13


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

    def nodes(self) -> np.ndarray:
        """(N,) nodes whose input takes projected rows (own, of node k+1 or, at N-1, the
        terminal ones): ``Projection.constrained`` before any row is stacked."""
        nodes = self.own.any(axis=1) | self.next.any(axis=1)
        if nodes.size:
            nodes[-1] |= bool(self.term.any())
        return nodes

    def without_nodes(self, nodes: np.ndarray) -> EqualityLayout:
        """This layout without the rows projected at ``nodes`` ((N,) bool): their own rows,
        those of node k+1 and, at N-1, the terminal ones (they go back to the augmented
        Lagrangian)."""
        own, nxt, term = self.own.copy(), self.next.copy(), self.term.copy()
        own[nodes], nxt[nodes] = False, False
        if nodes.size and nodes[-1]:
            term[:] = False
        return EqualityLayout(own, nxt, term, self.b, self.bN)

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

    def dependent(self) -> np.ndarray:
        """(N,) nodes whose rows are (nearly) dependent in the input (rank below the number
        of rows: the projection keeps fewer directions than rows)."""
        rank = self.free.shape[1] - np.count_nonzero(self.free, axis=1)
        return np.count_nonzero(self.rows, axis=1) > rank


_METHODS = ("qr", "qr-numpy", "svd")


def project(layout: EqualityLayout, c: np.ndarray, cx: np.ndarray, cu: np.ndarray,
            cN: np.ndarray, cxN: np.ndarray, A: np.ndarray, B: np.ndarray,
            gap: np.ndarray, rtol: float = 1e-9, method: str = "qr",
            pattern: AbPattern | None = None) -> Projection:
    """Linearised equality rows of every node and their null-space parametrisation.

    Args:
        layout: the projected rows.
        c, cx, cu: stage constraint values (N, nc_con) and Jacobians (N, nc_con, ndx|nu).
        cN, cxN: terminal constraint values (ncN_con,) and Jacobian (ncN_con, ndx).
        A, B, gap: linearised dynamics (N, ndx, ndx), (N, ndx, nu), defects (N, ndx).
        rtol: singular values of a node's D below ``rtol`` times its largest are dropped
            (its rows are then met in the least-squares sense only).
        method: ``'qr'``: a QR of each node's rows, with the SVD only at the nodes whose
            rows are (nearly) dependent or more than ``nu``; compiled C (``riccati.c``)
            when :func:`.riccati_c.available`, else ``'qr-numpy'``, the same in batched
            numpy (~4x slower at go2 sizes); ``'svd'``: a batched SVD
            at every node (the reference; 2.3x slower in the go2 walking MPC, 3x on warm
            caches). Both give the same P_e, P_x, pinv, free and rank_deficient, to
            rounding, and orthonormal bases Z of the same null spaces.
        pattern: the structural nonzeros of [A | B] (the backward pass's), read by the
            compiled row stacking of ``'qr'`` (its other entries of A and B are not read);
            None: dense.

    Returns:
        The :class:`Projection` (``pinv`` may be a transposed view).
    """
    if method not in _METHODS:
        raise ValueError(f"project: unknown method {method!r}; expected one of {_METHODS}")
    n, ndx, nu = B.shape
    compiled = method == "qr" and _compiled()
    if compiled:
        from horizon_mpc.solvers.ilqr import riccati_c

        W_flat, rows = riccati_c.stack_rows_c(layout, c, cx, cu, cN, cxN, A, B, gap, pattern)
    else:
        W_flat, rows = _stack_rows(layout, c, cx, cu, cN, cxN, A, B, gap)
    m = rows.shape[1]
    if m == 0 or nu == 0:
        return Projection(np.zeros((n, nu)), np.zeros((n, nu, ndx)),
                          np.broadcast_to(np.eye(nu), (n, nu, nu)).copy(), np.ones((n, nu)),
                          np.zeros((n, nu, 0)), np.zeros((n, 0), bool), np.zeros(n, bool), 0)
    if method == "svd":
        sol = _svd_solve(W_flat[:-1].reshape(n, m, -1) * rows[..., None], nu, rtol)
    else:
        sol = _qr_solve(W_flat, rows, nu, rtol, compiled=compiled)
    return Projection(sol.P_e, sol.P_x, sol.Z, sol.free, sol.pinv, rows, rows.any(axis=1),
                      int(np.count_nonzero(sol.unmet)))


def _compiled() -> bool:
    from horizon_mpc.solvers.ilqr import riccati_c  # riccati_c imports this module

    return riccati_c.available()


def _slots(layout: EqualityLayout) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The slot layout of :func:`_stack_rows`: the constraint columns of the own rows, of
    the rows of node k+1 and of the terminal rows, and the slots per node ``m``."""
    own_cols = np.flatnonzero(layout.own.any(axis=0))
    nxt_cols = np.flatnonzero(layout.next.any(axis=0))
    term_cols = np.flatnonzero(layout.term)
    return own_cols, nxt_cols, term_cols, len(own_cols) + max(len(nxt_cols), len(term_cols))


def _stack_rows(layout: EqualityLayout, c: np.ndarray, cx: np.ndarray, cu: np.ndarray,
                cN: np.ndarray, cxN: np.ndarray, A: np.ndarray, B: np.ndarray,
                gap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows ``[D | C | e]`` of every node and their mask ``rows`` (N, m).

    Returns ``W_flat`` (N m + 1, nu + ndx + 1): slot j of node k is row ``k m + j``, and
    the last row is zero (gathers point their unused slots at it). Slots: the columns of
    ``layout.own`` first, then those of ``layout.next`` (state rows of node k+1 through the
    dynamics) or, at node N-1, of ``layout.term``. Slots where ``rows`` is False hold what
    the unused rows evaluate to, not zeros: mask them before use.
    """
    n, ndx, nu = B.shape
    own_cols, nxt_cols, term_cols, m = _slots(layout)
    k, j, jt = len(own_cols), len(nxt_cols), len(term_cols)
    rows = np.zeros((n, m), bool)
    if m == 0 or nu == 0:
        return np.zeros((n * m + 1, nu + ndx + 1)), rows
    W_flat = np.empty((n * m + 1, nu + ndx + 1))  # every slot is written below
    W_flat[-1] = 0.0
    W = W_flat[:-1].reshape(n, m, -1)
    used = np.concatenate((own_cols, nxt_cols))
    cx_used = cx[:, used]  # one pass over cx (the largest input) for both kinds of rows
    c_used = c[:, used] - layout.b[:, used]
    if k:
        W[:, :k, :nu] = cu[:, own_cols]
        W[:, :k, nu:-1] = cx_used[:, :k]
        W[:, :k, -1] = c_used[:, :k]
        rows[:, :k] = layout.own[:, own_cols]
    if m > k:  # state rows c(x_{k+1}) = b: J (A dx + B du + gap) + c - b = 0
        J = np.zeros((n, m - k, ndx))
        r = np.zeros((n, m - k))
        if j and n > 1:
            J[:-1, :j] = cx_used[1:, k:]
            r[:-1, :j] = c_used[1:, k:]
            rows[:-1, k:k + j] = layout.next[:-1, nxt_cols]
        if jt:
            J[-1, :jt] = cxN[term_cols]
            r[-1, :jt] = cN[term_cols] - layout.bN[term_cols]
            rows[-1, k:k + jt] = True
        np.matmul(J, B, out=W[:, k:, :nu])
        np.matmul(J, A, out=W[:, k:, nu:-1])
        W[:, k:, -1] = r + np.einsum("kij,kj->ki", J, gap)
    return W_flat, rows


@dataclass
class _Solution:
    """P_x (b, nu, ndx), P_e (b, nu), Z (b, nu, nu), free (b, nu), pinv (b, nu, m) and
    ``unmet`` (b,): nodes whose rows ``D P_e + e = 0`` are not met (least squares)."""

    P_x: np.ndarray
    P_e: np.ndarray
    Z: np.ndarray
    free: np.ndarray
    pinv: np.ndarray
    unmet: np.ndarray


def _unmet(D: np.ndarray, e: np.ndarray, P_e: np.ndarray) -> np.ndarray:
    """(b,) True where the residual of the rows ``D P_e + e`` (D (b, r, nu), e (b, r)) is
    not zero to rounding (1e-8 relative to the largest |e|)."""
    residual = (D @ P_e[..., None])[..., 0] + e
    return (np.max(np.abs(residual), axis=1, initial=0.0)
            > 1e-8 * (1.0 + np.max(np.abs(e), axis=1, initial=0.0)))


def _svd_solve(W: np.ndarray, nu: int, rtol: float) -> _Solution:
    """The projection of the masked rows W (b, m, nu + ndx + 1) by a batched SVD.

    ``D = U diag(s) V^T``: the range of D^T is ``V[:, :r]`` and the null space the rest,
    with ``r`` the singular values above ``rtol`` times the largest; dependent rows are met
    in the least-squares sense.
    """
    b = W.shape[0]
    D, e = W[..., :nu], W[..., -1]
    U, s, Vt = np.linalg.svd(D, full_matrices=True)
    V = np.swapaxes(Vt, 1, 2)
    smax = s[:, :1] if s.shape[1] else np.zeros((b, 1))
    # round-off input Jacobians too (INPUT_ATOL against the node's largest state Jacobian)
    floor = INPUT_ATOL * np.maximum(1.0, np.linalg.norm(W[..., nu:-1], axis=2).max(
        axis=1, initial=0.0))
    keep = (s > rtol * np.maximum(smax, 1e-300)) & (s > floor[:, None])  # (b, min(m, nu))
    inv_s = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    r = keep.shape[1]
    pinv = (V[:, :, :r] * inv_s[:, None, :]) @ np.swapaxes(U[:, :, :r], 1, 2)  # (b, nu, m)
    free = np.ones((b, nu))
    free[:, :r] = ~keep
    P_e = -np.einsum("kum,km->ku", pinv, e)
    P_x = -pinv @ W[..., nu:-1]
    return _Solution(P_x, P_e, V * free[:, None, :], free, pinv, _unmet(D, e, P_e))


def _qr_solve(W_flat: np.ndarray, rows: np.ndarray, nu: int, rtol: float,
              compiled: bool = False) -> _Solution:
    """What :func:`_svd_solve` returns, from a QR of each node's rows.

    Nodes with 1..nu rows go through :func:`_qr_nodes` (or the compiled kernel), and those
    found (nearly) dependent, with more rows than inputs or non-finite through
    :func:`_svd_solve`. Nodes without rows are skipped: ``du`` is free there (Z = I,
    P_e = 0, P_x = 0).

    W_flat, rows: as :func:`_stack_rows` returns them.
    """
    n, m = rows.shape
    if compiled:
        from horizon_mpc.solvers.ilqr import riccati_c

        P_e, P_x, Z, free, pinv, ok, unmet = riccati_c.project_rows_c(W_flat, rows, nu, rtol)
        sol = _Solution(P_x, P_e, Z, free, pinv, unmet)
        fb = np.flatnonzero(~ok)
    else:
        sol, fb = _qr_solve_numpy(W_flat, rows, nu, rtol)
    if fb.size:
        fill_by_svd({name: getattr(sol, name) for name in _Solution.__dataclass_fields__},
                    W_flat, rows, fb, nu, rtol)
    return sol


def fill_by_svd(out: dict[str, np.ndarray], W_flat: np.ndarray, rows: np.ndarray,
                fb: np.ndarray, nu: int, rtol: float) -> None:
    """Overwrite nodes ``fb`` of a projection's arrays (``out``: P_x, P_e, Z, free, pinv,
    unmet, shaped as :class:`Projection`'s) with :func:`_svd_solve`'s solution: the nodes
    the QR could not take. W_flat, rows: as :func:`_stack_rows` returns them."""
    n, m = rows.shape
    W = W_flat[:-1].reshape(n, m, -1)
    part = _svd_solve(W[fb] * rows[fb][..., None], nu, rtol)
    for name, a in out.items():
        a[fb] = getattr(part, name)


def _qr_solve_numpy(W_flat: np.ndarray, rows: np.ndarray, nu: int,
                    rtol: float) -> tuple[_Solution, np.ndarray]:
    """:func:`_qr_solve` in batched numpy; also returns the nodes left to the SVD."""
    n, m = rows.shape
    count = np.count_nonzero(rows, axis=1)
    sel = np.flatnonzero((count > 0) & (count <= nu))
    ok = np.ones(0, bool)
    if sel.size:
        part, ok, idx = _qr_nodes(W_flat, rows, count, sel, nu, rtol)
    if sel.size and sel.size == n:  # the usual case: every node has rows
        sol = part
    else:
        ndx = W_flat.shape[1] - nu - 1
        sol = _Solution(np.zeros((n, nu, ndx)), np.zeros((n, nu)),
                        np.broadcast_to(np.eye(nu), (n, nu, nu)).copy(), np.ones((n, nu)),
                        None, np.zeros(n, bool))
        if sel.size:
            for name in ("P_x", "P_e", "Z", "free", "unmet"):
                getattr(sol, name)[sel] = getattr(part, name)
    pinv_t = np.zeros((n * m + 1, nu))  # D^+ transposed: a row per slot, the last scratch
    if sel.size:
        pinv_t[idx] = np.swapaxes(part.pinv, 1, 2)
    sol.pinv = pinv_t[:-1].reshape(n, m, nu).swapaxes(1, 2)
    fb = np.flatnonzero(count > nu)
    if not ok.all():
        fb = np.union1d(fb, sel[~ok])
    return sol, fb


def _qr_nodes(W_flat: np.ndarray, rows: np.ndarray, count: np.ndarray, sel: np.ndarray,
              nu: int, rtol: float) -> tuple[_Solution, np.ndarray, np.ndarray]:
    """The projection of nodes ``sel`` (each with 1..nu rows) by a batched QR.

    A node's ``c`` rows are gathered to its first slots (in order), the other slots are
    zero, and ``D_c^T = Q R`` (complete QR): with independent rows ``Q[:, :c]`` spans the
    range of D^T, ``Q[:, c:]`` is an orthonormal basis of the null space and
    ``D^+ = Q[:, :c] R_c^-T``. The rows count as independent only when R_c is invertible
    and ``||R_c||_F ||R_c^-1||_F < 1 / rtol``: that bounds the condition number of D, so
    the SVD would keep every singular value.

    Returns the :class:`_Solution` of the nodes with ``pinv`` compacted (b, nu, w) (column
    j: the j-th row of the node), ``ok`` (b,) (False: rows too close to dependent, the
    solution there is meaningless) and ``idx`` (b, w) the row of ``W_flat`` of each
    compacted slot (the zero row for unused slots).
    """
    n, m = rows.shape
    cnt = count[sel]
    w = int(cnt.max())
    padded = bool(cnt.min() < w)  # some node leaves slots unused
    idx = np.argsort(~rows[sel], axis=1, kind="stable")[:, :w]  # real rows first, in order
    idx += (m * sel)[:, None]
    if padded:
        slot = np.arange(w) < cnt[:, None]  # (b, w): slots holding a row
        idx[~slot] = n * m
    Wc = W_flat[idx]  # (b, w, nu + ndx + 1)
    Q, R = np.linalg.qr(np.swapaxes(Wc[..., :nu], 1, 2), mode="complete")
    R = R[:, :w]  # (b, w, w); the rows and columns of unused slots are zero
    if padded:
        R[:, range(w), range(w)] += ~slot  # R = diag(R_c, I)
    Rinv, ok = _inv_upper(R)
    if padded:
        Rinv *= slot[:, None, :]  # diag(R_c^-1, 0)
    cond2 = (np.einsum("kij,kij->k", R, R) - (w - cnt)) * np.einsum("kij,kij->k", Rinv, Rinv)
    ok &= cond2 < rtol ** -2  # NaN: not ok
    # a row whose input Jacobian is round-off (INPUT_ATOL): to the SVD, which drops it
    slot_rows = np.arange(w) < cnt[:, None]
    dnorm = np.linalg.norm(Wc[..., :nu], axis=2)
    cnorm = np.maximum(1.0, np.linalg.norm(Wc[..., nu:-1], axis=2))
    ok &= np.all((dnorm > INPUT_ATOL * cnorm) | ~slot_rows, axis=1)
    # D^+ (b, nu, w), zero on unused slots (Q_1 copied: a strided operand is slower)
    pinv = np.ascontiguousarray(Q[:, :, :w]) @ np.swapaxes(Rinv, 1, 2)
    P_x = pinv @ Wc[..., nu:-1]
    np.negative(P_x, out=P_x)
    P_e = -(pinv @ Wc[..., -1:])[..., 0]
    # with ||D||_F ||D^+||_F <= 3e4 the Householder solution meets the rows to ~1e-10 of
    # max |e| at worst, far within _unmet's 1e-8: the residual need not be computed
    unmet = (_unmet(Wc[..., :nu], Wc[..., -1], P_e)
             if np.max(cond2, where=ok, initial=0.0) > 1e9 else np.zeros(len(sel), bool))
    fr = np.arange(nu) >= cnt[:, None]
    if padded:  # the range columns are exactly zero
        Q *= fr[:, None, :]
    else:
        Q[:, :, :w] = 0.0
    return _Solution(P_x, P_e, Q, fr.astype(float), pinv, unmet), ok, idx


def _inv_upper(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverses of the upper triangular matrices R (b, w, w), and (b,) False where R is
    singular (a zero pivot; the inverse there is meaningless)."""
    # numpy has no triangular inverse (np.linalg.inv: LU, ~4x slower at go2 sizes) and
    # scipy's batched inv adds a condition estimate and warnings: one LAPACK call per node,
    # in place on the transposed (so Fortran-ordered) copy
    Rinv = R.copy()
    out = [_trtri(Rt, 1, 0, 1) for Rt in np.swapaxes(Rinv, 1, 2)]
    if out and not np.shares_memory(out[0][0], Rinv):  # not in place after all: copy back
        Rinv = np.swapaxes(np.stack([o[0] for o in out]), 1, 2)
    return Rinv, np.equal([o[1] for o in out], 0)
