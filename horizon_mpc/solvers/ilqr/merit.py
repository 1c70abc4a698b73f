"""The scalar measures the ILQR's line search and merit function read, in numpy.

:func:`evaluation_stats` summarises one evaluation of the problem (cost, defects, projected
equality residuals); :func:`step_stats` one step of the LQ sub-problem (directional
derivative, multiplier estimate, step size). ``riccati_c.step_stats_c`` computes the
latter in one compiled pass (to rounding: the sums run in another order; ~30 % less time at
go2's sizes), which the solver takes when the compiled library is available. (A compiled
evaluation_stats measured no faster than these few vectorised numpy calls.)
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["evaluation_stats", "step_stats"]


def evaluation_stats(gap: np.ndarray, r: np.ndarray, W: np.ndarray, c: np.ndarray,
                     b: np.ndarray, eq: np.ndarray, d0: np.ndarray, rN: np.ndarray,
                     WN: np.ndarray, cN: np.ndarray, bN: np.ndarray, eqN: np.ndarray
                     ) -> tuple[float, float, float, float, float] | None:
    """``(cost, gap_l1, gap_max, eq_l1, eq_max)`` of an evaluation, None if any value is
    not finite.

    Args:
        gap (N, ndx): defects; d0 (ndx,): the initial state's difference to its fixed value.
        r, W (N, nr): residuals and their weights; rN, WN (nrN,): the terminal ones.
        c (N, nc): constraint and bound rows, the first ``ncon = b.shape[1]`` of them
            constraints; b, eq (N, ncon): the projected equality rows' targets and mask.
        cN (ncN,), bN, eqN (ncNcon,): the terminal ones.

    ``cost`` is ``sum W r^2 + sum WN rN^2``; ``gap_*`` sum and max of ``|gap|``, ``|d0|``;
    ``eq_*`` sum and max of ``|c - b|`` over the masked rows.
    """
    total = float(gap.sum()) + float(r.sum()) + float(c.sum()) + float(d0.sum()) + float(
        rN.sum()) + float(cN.sum())
    if not math.isfinite(total):  # NaN and inf propagate through the sums
        return None
    ncon, ncNcon = b.shape[1], bN.shape[0]
    e = np.abs(np.where(eq, c[:, :ncon] - b, 0.0))
    eN = np.abs(np.where(eqN, cN[:ncNcon] - bN, 0.0))
    abs_gap, abs_d0 = np.abs(gap), np.abs(d0)
    return (float(np.vdot(W, r * r) + np.vdot(WN, rN * rN)),
            float(abs_gap.sum() + abs_d0.sum()),
            float(max(abs_gap.max(initial=0.0), abs_d0.max(initial=0.0))),
            float(e.sum() + eN.sum()),
            float(max(e.max(initial=0.0), eN.max(initial=0.0))))


def step_stats(lx: np.ndarray, lu: np.ndarray, lxN: np.ndarray, s: np.ndarray, S: np.ndarray,
               Qu: np.ndarray, Quu: np.ndarray, Qux: np.ndarray, dX: np.ndarray,
               dU: np.ndarray, pinv: np.ndarray | None) -> tuple[float, float, float, float]:
    """``(slope, lam_max, dx_max, du_max)`` of the step ``(dX (N+1, ndx), dU (N, nu))``.

    ``slope``: the cost's directional derivative ``lx.dX + lu.dU + lxN.dX_N`` (lx (N, ndx),
    lu (N, nu), lxN (ndx,)); ``lam_max``: the largest multiplier estimate, the costates
    ``|s + S dX|`` (s (N+1, ndx), S (N+1, ndx, ndx) of the backward pass) and, given the
    projection's ``pinv`` (N, nu, m), the projected rows' ``|D^+^T (Qu + Quu dU + Qux dX)|``;
    ``dx_max``, ``du_max``: the largest ``|dX|``, ``|dU|`` (0 without inputs). NaN
    propagates into the maxima.
    """
    slope = float(np.einsum("ij,ij->", lx, dX[:-1]) + np.einsum("ij,ij->", lu, dU)
                  + lxN @ dX[-1])
    lam_max = float(np.max(np.abs(s + np.einsum("kij,kj->ki", S, dX))))
    if pinv is not None and pinv.shape[2]:
        grad = Qu + np.einsum("kij,kj->ki", Quu, dU) + np.einsum("kij,kj->ki", Qux, dX[:-1])
        lam = np.einsum("kum,ku->km", pinv, grad)
        lam_max = float(np.max([lam_max, np.max(np.abs(lam))]))
    return slope, lam_max, float(np.max(np.abs(dX))), float(np.max(np.abs(dU), initial=0.0))
