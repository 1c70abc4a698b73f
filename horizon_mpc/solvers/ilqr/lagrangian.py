"""Augmented-Lagrangian and relaxed-barrier bookkeeping of the ILQR's constraint rows.

Each row ``c`` (a constraint or a variable bound at one node) has bounds ``lb <= c <= ub``
(``-inf``/``inf`` where absent or inactive). Equalities (``lb == ub``) carry one free
multiplier and penalty ``rho``: ``lam (c - b) + rho/2 (c - b)^2``. Inequalities are
treated one of two ways (``inequality``):

* ``'lagrangian'``: multipliers ``lam_lo, lam_up >= 0`` and the term
  ``(max(0, lam_up + rho (c - ub))^2 - lam_up^2) / (2 rho)`` (lower alike): exact at
  convergence, but the Gauss-Newton weight of a row jumps between 0 and ``rho/2`` as it
  enters or leaves the active set, so one iteration per tick can chatter;
* ``'barrier'``: the relaxed logarithmic barrier of the slack ``h`` (``ub - c``,
  ``c - lb``), ``-mu ln(h / delta)`` for ``h > delta`` and its quadratic extension below
  (continuous up to the second derivative, finite for any violation): a smooth, convex
  term whose model is right to second order on both sides of the boundary. Not exact: a
  row pressed hard by the cost settles slightly inside or, past ``delta``, slightly
  outside its bound; ``violation`` reports it as it is.

The Gauss-Newton model of each row is ``w (c - t)^2`` with a weight ``w`` and a target
``t`` (``rho/2`` and ``b - lam/rho`` for an equality; half the barrier's curvature and
the Newton target ``c - B'/B''`` for a barrier row). Arrays have shape (n_nodes, n_rows).
"""

from __future__ import annotations

import numpy as np

__all__ = ["AugmentedLagrangian", "relaxed_barrier"]


INEQUALITY_MODES = ("lagrangian", "barrier")


def _kernel(lb, ub, lam, lam_lo, lam_up, rho):
    """The compiled rows (``riccati_c.AlRowsKernel``), or None without the library."""
    from horizon_mpc.solvers.ilqr import riccati_c  # imports this package's equality module

    return riccati_c.AlRowsKernel(lb, ub, lam, lam_lo, lam_up, rho) if riccati_c.available(
    ) else None


def relaxed_barrier(h: np.ndarray, mu: float, delta: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value, first and second derivative of the relaxed log barrier at slacks ``h``.

    ``-mu ln(h / delta)`` for ``h > delta``, else
    ``mu/2 (((h - 2 delta) / delta)^2 - 1)``; zero at ``h = delta``.
    """
    h = np.asarray(h, dtype=float)
    z = (h - 2.0 * delta) / delta
    value = 0.5 * mu * (z * z - 1.0)
    d1 = (mu / delta) * z
    d2 = np.full_like(h, mu / (delta * delta))
    inside = h > delta
    if inside.any():
        hi = h[inside]
        value[inside] = -mu * np.log(hi / delta)
        d1[inside] = -mu / hi
        d2[inside] = mu / (hi * hi)
    return value, d1, d2


class AugmentedLagrangian:
    """Multipliers, penalties and barrier terms of a block of constraint rows.

    Args:
        lb, ub: (n_nodes, n_rows) bounds.
        rho0: initial penalty of the augmented Lagrangian.
        inequality: ``'lagrangian'`` or ``'barrier'`` (see the module docstring).
        barrier_mu, barrier_delta: weight and relaxation slack of the barrier (in the
            units of the rows).
        compiled: evaluate the rows in one compiled pass (``riccati_c.AlRowsKernel``) when
            the compiled library is available; numpy otherwise (the same values to
            rounding).
    """

    def __init__(self, lb: np.ndarray, ub: np.ndarray, rho0: float,
                 inequality: str = "lagrangian", barrier_mu: float = 1.0,
                 barrier_delta: float = 1.0, compiled: bool = True):
        if inequality not in INEQUALITY_MODES:
            raise ValueError(f"inequality must be one of {INEQUALITY_MODES}, got {inequality!r}")
        if not (barrier_mu > 0 and barrier_delta > 0):
            raise ValueError(f"barrier_mu and barrier_delta must be > 0, got {barrier_mu}, "
                             f"{barrier_delta}")
        self.barrier = inequality == "barrier"
        self.mu, self.delta = float(barrier_mu), float(barrier_delta)
        shape = np.shape(lb)
        self.lam = np.zeros(shape)
        self.lam_lo = np.zeros(shape)
        self.lam_up = np.zeros(shape)
        self.rho = np.full(shape, float(rho0))
        self.rho0 = rho0
        self._kernel = None
        self._last_violation = np.full(shape, np.inf)
        self.set_bounds(lb, ub)
        if compiled:  # bound once: it reads bounds, multipliers and penalties in place
            self._kernel = _kernel(self.lb, self.ub, self.lam, self.lam_lo, self.lam_up,
                                   self.rho)

    def set_bounds(self, lb: np.ndarray, ub: np.ndarray) -> None:
        """New bounds (a row whose kind changes gets its multipliers reset)."""
        lb = np.ascontiguousarray(lb, dtype=float)
        ub = np.ascontiguousarray(ub, dtype=float)
        if lb.shape != self.lam.shape or ub.shape != self.lam.shape:
            raise ValueError(f"bounds of shape {lb.shape}, {ub.shape}; the rows have shape "
                             f"{self.lam.shape}")
        finite_lb, finite_ub = np.isfinite(lb), np.isfinite(ub)
        eq = finite_lb & (lb == ub)
        has_lo, has_up = finite_lb & ~eq, finite_ub & ~eq
        # a row's kind (equality, lower side, upper side) in one code: these three masks
        # follow from (finite lb, finite ub, eq)
        kind = finite_lb.view(np.uint8) + 2 * finite_ub.view(np.uint8) + 4 * eq.view(np.uint8)
        if hasattr(self, "eq"):
            changed = kind != self._kind
            if changed.any():  # rarely: bounds usually keep their kind between solves
                self.lam[changed] = self.lam_lo[changed] = self.lam_up[changed] = 0.0
                self._last_violation[changed] = np.inf  # no progress history of a new row
        self._kind = kind
        if hasattr(self, "lb"):  # the same arrays throughout: compiled readers keep pointers
            np.copyto(self.lb, lb)
            np.copyto(self.ub, ub)
        else:
            self.lb, self.ub = lb.copy(), ub.copy()
        self.eq = eq
        self._any_eq = bool(eq.any())
        self.has_lo, self.has_up = has_lo, has_up
        self._barrier_memo = None
        if self._kernel is not None:
            return  # bound to self.lb and self.ub, updated in place
        # finite copies (0 where a row has no such bound) for the per-evaluation arithmetic
        self._b = np.where(eq, lb, 0.0)
        self._lo = np.where(self.has_lo, lb, 0.0)
        self._up = np.where(self.has_up, ub, 0.0)
        self._any = (self._any_eq, bool(self.has_up.any()), bool(self.has_lo.any()))
        # barrier rows, flat: upper sides then lower sides (a row may have both)
        self._iu, self._il = np.flatnonzero(self.has_up), np.flatnonzero(self.has_lo)
        self._bu, self._bl = self.ub.ravel()[self._iu], self.lb.ravel()[self._il]
        self._isides = np.concatenate((self._iu, self._il))
        self._irows = np.flatnonzero(self.has_up | self.has_lo)

    def violation(self, c: np.ndarray) -> np.ndarray:
        """Per-row violation ``max(lb - c, c - ub, 0)``, shape of ``c``."""
        # infinite bounds give -inf here (c is finite wherever this is asked)
        v = np.maximum(self.lb - c, c - self.ub)
        np.maximum(v, 0.0, out=v)
        return v

    def complementarity(self, c: np.ndarray) -> float:
        """The largest ``|min(lam_up, ub - c)|`` (and its lower-side mirror) over the
        inequality rows: zero at a KKT point of the rows, where a row pressed by its
        multiplier sits on its bound; the primal violation where a row is past it (0 for
        barrier rows: they carry no multiplier). The augmented Lagrangian's stationary
        points with multipliers that press rows away from their bounds fail it (measured
        against ``lam / rho`` instead, a penalty at ``rho_max`` hid a multiplier of 1.9
        pressing a bound 1.3e-4 away)."""
        if self.barrier:
            return 0.0
        worst = 0.0
        for mask, lam, slack in ((self.has_up, self.lam_up, self.ub - c),
                                 (self.has_lo, self.lam_lo, c - self.lb)):
            if mask.any():
                worst = max(worst, float(np.max(np.abs(np.minimum(lam[mask], slack[mask])))))
        return worst

    def _barrier_terms(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Barrier value, dB/dc and d2B/dc2 of the barrier sides, flat (upper sides, then
        lower sides: index ``self._iu``, ``self._il`` into ``c.ravel()``)."""
        # one evaluation's rows are asked for their value, then their Gauss-Newton model
        # (and again after a multiplier update): the last result is reused for equal input
        memo = self._barrier_memo
        if (memo is not None and memo[1] == (self.mu, self.delta) and memo[0].shape == c.shape
                and np.array_equal(memo[0], c)):
            return memo[2]
        cf = c.ravel()
        slack = np.concatenate((self._bu - cf[self._iu], cf[self._il] - self._bl))
        value, d1, d2 = relaxed_barrier(slack, self.mu, self.delta)
        d1[:self._iu.size] *= -1.0  # slack ub - c: dB/dc = -B'
        for a in (value, d1, d2):
            a.setflags(write=False)
        self._barrier_memo = (c.copy(), (self.mu, self.delta), (value, d1, d2))
        return value, d1, d2

    @property
    def compiled(self) -> bool:
        """Whether the rows are evaluated by the compiled kernel (else numpy)."""
        return self._kernel is not None

    def value(self, c: np.ndarray) -> float:
        """The augmented-Lagrangian (and barrier) terms summed over rows."""
        if self._kernel is not None:
            return self._kernel(c, self.barrier, self.mu, self.delta)[0]
        return self._value_numpy(c)

    def value_and_violation(self, c: np.ndarray) -> tuple[float, float]:
        """``(value(c), violation(c).max(initial=0))`` (one pass when compiled)."""
        if self._kernel is not None:
            return self._kernel(c, self.barrier, self.mu, self.delta)[:2]
        return self._value_numpy(c), float(self.violation(c).max(initial=0.0))

    def _value_numpy(self, c: np.ndarray) -> float:
        rho = self.rho
        any_eq, any_up, any_lo = self._any
        total = 0.0
        if any_eq:
            e = np.where(self.eq, c - self._b, 0.0)
            total += float(np.sum(self.lam * e + 0.5 * rho * e * e))
        if self.barrier:
            if any_up or any_lo:
                total += float(np.sum(self._barrier_terms(c)[0]))
            return total
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
        if self._kernel is not None:
            _, _, w, t = self._kernel(c, self.barrier, self.mu, self.delta, weights=True)
            return w, t
        rho = self.rho
        w = np.zeros_like(c)
        t = np.zeros_like(c)
        eq = self.eq
        w[eq] = 0.5 * rho[eq]
        t[eq] = self.lb[eq] - self.lam[eq] / rho[eq]
        if self.barrier:
            if self._any[1] or self._any[2]:
                _, d1, d2 = self._barrier_terms(c)
                # a row with both bounds sums its two sides
                g = np.bincount(self._isides, weights=d1, minlength=c.size)
                h = np.bincount(self._isides, weights=d2, minlength=c.size)
                rows = self._irows
                wf, tf = w.reshape(-1), t.reshape(-1)
                wf[rows] = 0.5 * h[rows]
                tf[rows] = c.ravel()[rows] - g[rows] / h[rows]  # h > 0 on every barrier row
            return w, t
        up = self.has_up & (self.lam_up + rho * (c - np.where(self.has_up, self.ub, 0)) > 0)
        w[up] = 0.5 * rho[up]
        t[up] = self.ub[up] - self.lam_up[up] / rho[up]
        lo = self.has_lo & (self.lam_lo + rho * (np.where(self.has_lo, self.lb, 0) - c) > 0)
        lo &= ~up
        w[lo] = 0.5 * rho[lo]
        t[lo] = self.lb[lo] + self.lam_lo[lo] / rho[lo]
        return w, t

    def update(self, c: np.ndarray, rho_factor: float, rho_max: float,
               decrease: float = 0.25) -> bool:
        """First-order multiplier update; raise ``rho`` on rows that did not improve enough
        (barrier rows have neither). Returns False when there was nothing to update (the
        terms' value at ``c`` is unchanged)."""
        if self.barrier and not self._any_eq:
            # barrier rows carry no multiplier nor penalty; the violation history only
            # serves equality rows (set_bounds restarts it for a row that becomes one)
            return False
        rho = self.rho
        eq, up, lo = self.eq, self.has_up, self.has_lo
        self.lam[eq] += rho[eq] * (c[eq] - self.lb[eq])
        viol = self.violation(c)
        slow = viol > decrease * self._last_violation
        slow &= viol > 1e-12
        if self.barrier:
            slow &= eq
        else:
            self.lam_up[up] = np.maximum(0.0, self.lam_up[up] + rho[up] * (c[up] - self.ub[up]))
            self.lam_lo[lo] = np.maximum(0.0, self.lam_lo[lo] + rho[lo] * (self.lb[lo] - c[lo]))
        self.rho[slow] = np.minimum(rho[slow] * rho_factor, rho_max)
        self._last_violation = viol
        return True

    def shift(self) -> None:
        """Receding horizon: multipliers and penalties move one node back."""
        for a in (self.lam, self.lam_lo, self.lam_up, self.rho, self._last_violation):
            if a.shape[0] > 1:
                a[:-1] = a[1:]

    def relax_idle_penalties(self, c: np.ndarray) -> bool:
        """Fresh multipliers and penalties (0, ``rho0``) for the inequality rows that are
        inactive at ``c``: ``lam + rho (c - ub) <= 0`` on each bounded side (``'lagrangian'``
        mode; returns whether any changed). The term of such a row is a constant there, so
        the merit moves by that constant only, but a penalty a past solve raised to
        ``rho_max`` puts a kink of that curvature a hair from ``c``, which the Gauss-Newton
        model (weight 0 while inactive) does not see: every step toward the bound was
        rejected, the regularisation grew, and a re-solve of a converged problem ended at
        ``max_iter``."""
        if self.barrier:
            return False
        with np.errstate(invalid="ignore"):  # inf bounds: the side's test is False
            up = self.has_up & (self.lam_up + self.rho * (c - self.ub) > 0.0)
            lo = self.has_lo & (self.lam_lo + self.rho * (self.lb - c) > 0.0)
        inactive = (self.has_up | self.has_lo) & ~up & ~lo
        inactive &= (self.rho != self.rho0) | (self.lam_up != 0.0) | (self.lam_lo != 0.0)
        if not inactive.any():
            return False
        self.lam_up[inactive] = self.lam_lo[inactive] = 0.0
        self.rho[inactive] = self.rho0
        self._last_violation[inactive] = np.inf
        return True

    def reset_penalties(self) -> None:
        """Penalties back to ``rho0`` (multipliers kept)."""
        self.rho[:] = self.rho0
        self._last_violation[:] = np.inf

    def reset(self) -> None:
        """Forget multipliers and penalties."""
        self.lam[:] = self.lam_lo[:] = self.lam_up[:] = 0.0
        self.rho[:] = self.rho0
        self._last_violation[:] = np.inf
