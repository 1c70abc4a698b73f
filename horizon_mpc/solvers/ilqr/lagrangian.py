"""Augmented-Lagrangian bookkeeping of the ILQR's constraint rows.

Each row ``c`` (a constraint or a variable bound at one node) has bounds ``lb <= c <= ub``
(``-inf``/``inf`` where absent or inactive). Equalities (``lb == ub``) carry one free
multiplier; inequalities carry ``lam_lo, lam_up >= 0``. With per-row penalty ``rho``:

* equality:  ``lam (c - b) + rho/2 (c - b)^2``
* upper:     ``(max(0, lam_up + rho (c - ub))^2 - lam_up^2) / (2 rho)`` (lower alike)

The Gauss-Newton model of each active row is ``rho/2 (c - t)^2`` with a target ``t``
(``b - lam/rho``, ``ub - lam_up/rho``, ``lb + lam_lo/rho``), i.e. weight ``w = rho/2``.
Arrays have shape (n_nodes, n_rows).
"""

from __future__ import annotations

import numpy as np

__all__ = ["AugmentedLagrangian"]


class AugmentedLagrangian:
    """Multipliers and penalties of a block of constraint rows."""

    def __init__(self, lb: np.ndarray, ub: np.ndarray, rho0: float):
        self.lam = np.zeros_like(lb)
        self.lam_lo = np.zeros_like(lb)
        self.lam_up = np.zeros_like(lb)
        self.rho = np.full_like(lb, rho0)
        self.rho0 = rho0
        self.set_bounds(lb, ub)
        self._last_violation = np.full_like(lb, np.inf)

    def set_bounds(self, lb: np.ndarray, ub: np.ndarray) -> None:
        """New bounds (a row whose kind changes gets its multipliers reset)."""
        eq = np.isfinite(lb) & (lb == ub)
        if hasattr(self, "eq"):
            changed = (eq != self.eq) | (np.isfinite(lb) != np.isfinite(self.lb)) | (
                np.isfinite(ub) != np.isfinite(self.ub))
            self.lam[changed] = self.lam_lo[changed] = self.lam_up[changed] = 0.0
        self.lb, self.ub, self.eq = lb, ub, eq
        self.has_lo = np.isfinite(lb) & ~eq
        self.has_up = np.isfinite(ub) & ~eq
        # finite copies (0 where a row has no such bound) for the per-evaluation arithmetic
        self._b = np.where(eq, lb, 0.0)
        self._lo = np.where(self.has_lo, lb, 0.0)
        self._up = np.where(self.has_up, ub, 0.0)
        self._any = (bool(eq.any()), bool(self.has_up.any()), bool(self.has_lo.any()))

    def violation(self, c: np.ndarray) -> np.ndarray:
        """Per-row violation ``max(lb - c, c - ub, 0)``, shape of ``c``."""
        v = np.zeros_like(c)
        np.maximum(v, np.where(np.isfinite(self.lb), self.lb - c, 0.0), out=v)
        np.maximum(v, np.where(np.isfinite(self.ub), c - self.ub, 0.0), out=v)
        return v

    def value(self, c: np.ndarray) -> float:
        """The augmented-Lagrangian terms summed over rows."""
        rho = self.rho
        any_eq, any_up, any_lo = self._any
        total = 0.0
        if any_eq:
            e = np.where(self.eq, c - self._b, 0.0)
            total += float(np.sum(self.lam * e + 0.5 * rho * e * e))
        if any_up:
            t = np.where(self.has_up, self.lam_up + rho * (c - self._up), 0.0)
            np.maximum(t, 0.0, out=t)
            lam = np.where(self.has_up, self.lam_up, 0.0)
            total += float(np.sum((t * t - lam * lam) / (2 * rho)))
        if any_lo:
            t = np.where(self.has_lo, self.lam_lo + rho * (self._lo - c), 0.0)
            np.maximum(t, 0.0, out=t)
            lam = np.where(self.has_lo, self.lam_lo, 0.0)
            total += float(np.sum((t * t - lam * lam) / (2 * rho)))
        return total

    def weights_targets(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton weights and targets of the rows at constraint values ``c``."""
        rho = self.rho
        w = np.zeros_like(c)
        t = np.zeros_like(c)
        eq = self.eq
        w[eq] = 0.5 * rho[eq]
        t[eq] = self.lb[eq] - self.lam[eq] / rho[eq]
        up = self.has_up & (self.lam_up + rho * (c - np.where(self.has_up, self.ub, 0)) > 0)
        w[up] = 0.5 * rho[up]
        t[up] = self.ub[up] - self.lam_up[up] / rho[up]
        lo = self.has_lo & (self.lam_lo + rho * (np.where(self.has_lo, self.lb, 0) - c) > 0)
        lo &= ~up
        w[lo] = 0.5 * rho[lo]
        t[lo] = self.lb[lo] + self.lam_lo[lo] / rho[lo]
        return w, t

    def update(self, c: np.ndarray, rho_factor: float, rho_max: float,
               decrease: float = 0.25) -> None:
        """First-order multiplier update; raise ``rho`` on rows that did not improve enough."""
        rho = self.rho
        eq, up, lo = self.eq, self.has_up, self.has_lo
        self.lam[eq] += rho[eq] * (c[eq] - self.lb[eq])
        self.lam_up[up] = np.maximum(0.0, self.lam_up[up] + rho[up] * (c[up] - self.ub[up]))
        self.lam_lo[lo] = np.maximum(0.0, self.lam_lo[lo] + rho[lo] * (self.lb[lo] - c[lo]))
        viol = self.violation(c)
        slow = viol > decrease * self._last_violation
        slow &= viol > 1e-12
        self.rho[slow] = np.minimum(rho[slow] * rho_factor, rho_max)
        self._last_violation = viol

    def shift(self) -> None:
        """Receding horizon: multipliers and penalties move one node back."""
        for a in (self.lam, self.lam_lo, self.lam_up, self.rho, self._last_violation):
            if a.shape[0] > 1:
                a[:-1] = a[1:]

    def reset(self) -> None:
        """Forget multipliers and penalties."""
        self.lam[:] = self.lam_lo[:] = self.lam_up[:] = 0.0
        self.rho[:] = self.rho0
        self._last_violation[:] = np.inf
