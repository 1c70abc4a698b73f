"""A sparse Gauss-Newton SQP for problems whose cost is a sum of squared residuals.

With ``f(w) = ||R(w)||^2`` (see :mod:`horizon_mpc.problem.transcription`), every iteration
solves the QP

    min_d  1/2 d' (2 J_R' J_R + reg I) d + (2 J_R' R)' d
    s.t.   lbg - g(w) <= J_g(w) d <= ubg - g(w),     lbx - w <= d <= ubx - w

through CasADi's ``conic`` interface (sparsity fixed, QP solver built once; variables and
constraints sorted stage-wise so the KKT matrix is banded), warm-started with the last
multipliers and, if that fails, once more cold. When the linearised constraints
are inconsistent, an *elastic* QP (l1-penalised slacks on every row, penalty
``elastic_penalty``) gives the step instead. The step ``w += alpha d`` is chosen by
backtracking (Armijo, non-monotone: against the maximum of the last ``nonmonotone`` merit
values, which lets the full Gauss-Newton step through where a monotone test would halve it
forever; once the violation stalls, :data:`STALL_WINDOW`, against their mean with weights
halving into the past, which ends the cycles of full steps the maximum lets through) on the
l1 merit ``phi(w) = f(w) + mu ||viol(g(w))||_1``; ``mu`` never decreases and stays above
the largest QP multiplier. Multipliers follow ``lam += alpha (lam_QP - lam)``.

Convergence: the constraint violation (dynamics, constraints, bounds; inf-norm) is below
``tol_constr`` and either the KKT stationarity ``||grad f + J_g' lam_g + lam_x||_inf`` and
complementarity (``|lam| *`` distance to the bound it acts on), both divided by IPOPT's
multiplier scale ``max(1, mean |lam| / 100)``, are below ``tol``, or the last step
``||alpha d||_inf`` is below ``tol_step`` with the stationarity below ``sqrt(tol)`` (a
step can be tiny far from a solution: under a huge regularisation). A solve starts from
the last solve's multipliers, with the signs the current bounds allow (a row opened since
then frees its multiplier). When no step decreases the merit, the QP's multipliers are
taken once without a step and the KKT test decides (a start at a solution); a second
failure ends the solve ("line search failed"). Five elastic steps in a row that predict no less
violation than the current one end it as "locally infeasible".

Gauss-Newton ignores the curvature of the constraints (``lam' d2g``): convergence is
linear, fast when residuals dominate (tracking MPC), slower when the multipliers are large
(swing-ups). It also needs a sensible initial guess: from a poor one the linearisations
can turn inconsistent; IPOPT is the robust choice for cold, highly nonlinear problems.

Options (``make_solver('gnsqp', prb, opts)``):

=================== ========== ========================================================
``max_iter``        300        SQP iteration limit
``tol``             1e-6       scaled stationarity tolerance
``tol_constr``      1e-8       constraint-violation tolerance
``tol_step``        1e-10      step tolerance (inf-norm)
``qp_solver``       'qrqp'     'qrqp' (default: most reliable here), 'proxqp', 'osqp',
                               'qpoases' (dense: slow beyond a few hundred variables)
``qp_options``      {}         options handed to the QP plugin (merged over ours)
``regularization``  1e-8       ``reg`` added to the Gauss-Newton Hessian's diagonal
``armijo``          1e-4       sufficient-decrease constant of the line search
``nonmonotone``     3          merit values the Armijo test compares against (their
                               maximum; their weighted mean once the violation stalls;
                               1: monotone)
``min_step``        1e-8       smallest step length tried before giving up
``elastic_penalty`` 1e4        l1 penalty of the elastic QP's slacks (at least ``mu``)
``sym``             'SX'       graph type of the transcription ('SX' or 'MX')
``constraint_rows`` 'valid'    'valid' or 'active' (see ``Transcription``)
``time_budget``     None       s per call: an iteration is not started when the last
                               one's duration would take the call past it (the first
                               always runs; status ``'time budget'``), as the ILQR's
=================== ========== ========================================================
"""

from __future__ import annotations

import logging
import math
import time
from typing import Any

import casadi as cs
import numpy as np

from horizon_mpc.problem import Problem
from horizon_mpc.problem.terms import GeneralCost
from horizon_mpc.solvers.nlp_solver import NlpSolver

__all__ = ["GnSqpSolver"]

log = logging.getLogger(__name__)

# elastic steps in a row that cannot reduce the violation before "locally infeasible"
INFEASIBLE_STEPS = 5

# The line search compares with the maximum of the last `nonmonotone` merit values until
# the violation falls less than STALL_FACTOR times over STALL_WINDOW iterations, then with
# their weighted mean (GnSqpSolver._stalled). Measured (doc/problem.md): the mean from the
# start cycled or stalled where the maximum converged (collocated cart-poles, a unicycle
# with four discs); the maximum throughout cycled at active bounds (UR5 reaches, an Euler
# unicycle); the switch converged 71 of 94 auditor's problems, the maximum 64
STALL_WINDOW = 30
STALL_FACTOR = 0.3
STALL_FULL_STEPS = 1 / 3  # share of full steps in the window (the cycles' pattern: 1, 1, 1/4)

# qrqp's iteration cap of the plain QP: min(10000, max(QRQP_MIN_ITER, variables + rows))
QRQP_MIN_ITER = 200
# qrqp's cap when warm-started from the last step's multipliers: beyond it the warm start
# is taken to cycle and the QP is solved cold (the cap above scales with the QP's size,
# and so did a cycling warm start's cost: 1356 iterations, 190 s, on a 654-variable QP)
QRQP_WARM_ITER = 200

# Accurate, quiet settings per QP plugin (the SQP needs precise multipliers).
QP_DEFAULTS: dict[str, dict[str, Any]] = {
    "qrqp": {"print_iter": False, "print_header": False, "print_info": False,
             "max_iter": 10000, "error_on_fail": False},
    "osqp": {"osqp": {"verbose": False, "eps_abs": 1e-6, "eps_rel": 1e-6, "polish": True,
                      "max_iter": 100000}, "warm_start_primal": True, "warm_start_dual": True,
             "error_on_fail": False},
    "qpoases": {"printLevel": "none", "sparse": True, "error_on_fail": False},
    "proxqp": {"proxqp": {"eps_abs": 1e-10, "max_iter": 10000}, "error_on_fail": False},
}


def _merit_weight(mu: float, lam_g: np.ndarray) -> float:
    """The l1 merit's constraint weight after a step: at least its value so far, and above
    the step's largest multiplier (an exact penalty)."""
    return max(mu, 1.1 * float(np.max(np.abs(lam_g), initial=0.0)))


class GnSqpSolver(NlpSolver):
    """Gauss-Newton SQP with an l1-merit line search (see the module docstring).

    Attributes:
        transcription: the :class:`Transcription`.
        lam_x, lam_g: multipliers of the last solve (None before), kept for warm starts.
    """

    name = "gnsqp"
    DEFAULTS: dict[str, Any] = {
        "max_iter": 300, "tol": 1e-6, "tol_constr": 1e-8, "tol_step": 1e-10,
        "qp_solver": "qrqp", "qp_options": {}, "regularization": 1e-8, "armijo": 1e-4,
        "min_step": 1e-8, "sym": "SX", "constraint_rows": "valid", "nonmonotone": 3,
        "elastic_penalty": 1e4, "time_budget": None,
    }
    RANGES = {"max_iter": ">=1", "tol": ">=0", "tol_constr": ">=0", "tol_step": ">=0",
              "regularization": ">=0", "armijo": "(0,1)", "min_step": ">0",
              "nonmonotone": ">=1", "elastic_penalty": ">0", "time_budget": ">0"}

    def __init__(self, prb: Problem, opts: dict[str, Any] | None = None):
        super().__init__(prb, opts)
        tr = self.transcription
        # The SQP works on w and g sorted stage-wise (see Transcription.node_order): the
        # KKT matrices are then banded and the QP factorisations stay sparse.
        self._pw, self._pg = tr.node_order()
        T = type(tr.nlp["x"])
        w, P = T.sym("w", tr.nw), tr.nlp["p"]
        w_orig = w[np.argsort(self._pw)]
        R, g = cs.Function("nlp", [tr.nlp["x"], P], [tr.residual, tr.nlp["g"]])(w_orig, P)
        g = g[self._pg]
        reg, lam_g, lam_x = T.sym("reg"), T.sym("lam_g", tr.ng), T.sym("lam_x", tr.nw)
        J_R, J_g = cs.jacobian(R, w), cs.jacobian(g, w)
        H = 2 * cs.mtimes(J_R.T, J_R) + reg * T.eye(tr.nw)
        grad = 2 * cs.mtimes(J_R.T, R)
        f = cs.sumsqr(R)
        stationarity = cs.norm_inf(grad + cs.mtimes(J_g.T, lam_g) + lam_x)
        # one call per iteration (each Python -> CasADi call costs tens of microseconds)
        self._linearize = cs.Function(
            "gn_linearize", [w, P, reg, lam_g, lam_x], [H, grad, f, g, J_g, stationarity],
            ["w", "p", "reg", "lam_g", "lam_x"], ["H", "grad", "f", "g", "J_g", "stat"])
        self._evaluate = cs.Function("gn_evaluate", [w, P], [f, g], ["w", "p"], ["f", "g"])
        self._H_sp, self._A_sp = H.sparsity(), J_g.sparsity()
        self._qp: dict[bool | str, cs.Function] = {}  # plain, elastic (True), "warm"
        self._build_qp()

    def _check_problem(self, prb: Problem) -> None:
        general = [n for n, c in prb.costs.items() if isinstance(c, GeneralCost)]
        if general:
            raise ValueError(f"gnsqp minimises sums of squared residuals; the general cost(s) "
                             f"{general} need a full Hessian: use the 'ipopt' solver, or write "
                             "them as residuals with create_cost()")

    def _check_together(self, opts: dict[str, Any]) -> None:
        _check_qp_solver(opts["qp_solver"])

    def set_option(self, key: str, value: Any) -> None:
        """Change one option; the QP solver is rebuilt (and its options checked) at once."""
        previous = self.opts.get(key)
        super().set_option(key, value)
        if key in ("qp_solver", "qp_options", "regularization"):
            try:
                self._build_qp()
            except ValueError:
                self.opts[key] = previous
                raise

    def _build_qp(self) -> None:
        """(Re)build the QP solver now: options its plugin refuses raise ValueError here,
        not at the next solve."""
        self._qp.clear()
        try:
            self._qp_solver()
        except RuntimeError as exc:  # CasADi's refusal of a QP option
            self._qp.clear()
            raise ValueError(f"gnsqp: the QP solver {self.opts['qp_solver']!r} refuses its "
                             f"options {self.opts['qp_options']!r}: {_first_line(exc)}") from None

    def _qp_solver(self, elastic: bool = False, warm: bool = False) -> cs.Function:
        """The QP of a step: plain, or ``elastic`` (l1-relaxed); ``warm``: the plain QP
        started from the last multipliers, whose qrqp cap is :data:`QRQP_WARM_ITER`."""
        key = "warm" if warm and not elastic else elastic
        if key not in self._qp:
            name = self.opts["qp_solver"]
            qp_opts = {**QP_DEFAULTS.get(name, {}), **self.opts["qp_options"]}
            H_sp, A_sp = self._H_sp, self._A_sp
            if name == "qrqp" and not elastic and "max_iter" not in self.opts["qp_options"]:
                # an infeasible linearisation ran qrqp to its 10000 iterations (seconds)
                # before the elastic QP took over; a feasible one needs about one
                # iteration per active-set change, and one beyond the cap only costs
                # the elastic QP's step (exact penalty: the same step when feasible)
                qp_opts["max_iter"] = min(qp_opts["max_iter"],
                                          max(QRQP_MIN_ITER, H_sp.size1() + A_sp.size1()))
                if warm:  # a warm start that needs more is cycling: the cold QP takes over
                    qp_opts["max_iter"] = min(qp_opts["max_iter"], QRQP_WARM_ITER)
            if elastic:  # slacks s+ and s- on every constraint row
                ng = A_sp.size1()
                H_sp = cs.diagcat(H_sp, cs.Sparsity.diag(2 * ng))
                A_sp = cs.horzcat(A_sp, cs.Sparsity.diag(ng), cs.Sparsity.diag(ng))
            self._qp[key] = cs.conic(f"gn_qp{'_elastic' if elastic else ''}"
                                     f"{'_warm' if key == 'warm' else ''}", name,
                                     {"h": H_sp, "a": A_sp}, qp_opts)
        return self._qp[key]

    def _step(self, H, grad, J, g, w, lbx, ubx, lbg, ubg, lam_g, lam_x, mu):
        """Solve the QP for a step; fall back to the elastic (l1-relaxed) QP when the
        linearised constraints are infeasible. Returns (d, lam_g, lam_x, slack_sum, mu) or
        None when both fail."""
        nw, ng = w.size, g.size
        data = dict(h=H, g=grad, a=J, lba=lbg - g, uba=ubg - g, lbx=lbx - w, ubx=ubx - w,
                    x0=np.zeros(nw))
        warm = bool(lam_g.any() or lam_x.any())
        qp = self._qp_solver(warm=warm)
        sol = qp(**data, lam_a0=lam_g, lam_x0=lam_x)
        if not qp.stats().get("success", True) and warm:
            # the last step's multipliers can start an active-set QP solver on a cycle: a
            # rate-limited swing-up's feasible QPs ran qrqp to its cap warm, ~12 iterations
            # cold, and the elastic QP's steps then ended the solve as a failure; a
            # collocated brachistochrone's ran 1356 iterations warm (190 s), 51 cold
            qp = self._qp_solver()
            sol = qp(**data)
        if qp.stats().get("success", True):
            d, lg, lx = (sol[k].full().ravel() for k in ("x", "lam_a", "lam_x"))
            return d, lg, lx, 0.0, _merit_weight(mu, lg)
        self._elastic_steps += 1
        rho = max(self.opts["elastic_penalty"], mu)
        qp = self._qp_solver(elastic=True)
        eye = cs.DM.eye(ng)
        # rows without a finite bound cannot be violated: their slacks are fixed at 0
        free = np.isinf(lbg) & np.isinf(ubg)
        zeros, infs = np.zeros(2 * ng), np.where(np.tile(free, 2), 0.0, np.inf)
        sol = qp(h=cs.diagcat(H, self.opts["regularization"] * cs.DM.eye(2 * ng)),
                 g=np.concatenate([grad, np.full(2 * ng, rho)]), a=cs.horzcat(J, eye, -eye),
                 lba=lbg - g, uba=ubg - g, lbx=np.concatenate([lbx - w, zeros]),
                 ubx=np.concatenate([ubx - w, infs]), lam_a0=lam_g)
        if not qp.stats().get("success", True):
            return None
        z, lg, lx = (sol[k].full().ravel() for k in ("x", "lam_a", "lam_x"))
        slack = float(np.sum(z[nw:]))
        if slack <= 1e-12 * max(1.0, float(np.max(np.abs(g), initial=0.0))):
            # a feasible QP that only ran past the plain QP's cap: its step, and the
            # merit's weight as the plain QP's would be (not the elastic penalty's)
            return z[:nw], lg, lx[:nw], 0.0, _merit_weight(mu, lg)
        return z[:nw], lg, lx[:nw], slack, max(mu, rho)

    # ------------------------------------------------------------------ solve
    def _solve(self) -> bool:
        o, tr = self.opts, self.transcription
        pw, pg = self._pw, self._pg  # everything below is in stage-wise order
        lbx, ubx = (b[pw] for b in tr.bounds_w())
        lbg, ubg = (b[pg] for b in tr.bounds_g())
        p = tr.parameters()
        w = np.clip(self._initial_w()[pw], lbx, ubx)
        # warm-start multipliers, of the sign the current bounds allow (a bound removed
        # since the last solve frees its multiplier)
        lam_g = _signed(self.lam_g[pg], lbg, ubg) if self.lam_g is not None else np.zeros(tr.ng)
        lam_x = _signed(self.lam_x[pw], lbx, ubx) if self.lam_x is not None else np.zeros(tr.nw)
        history: list[dict[str, float]] = []
        self._merit_history: list[float] = []
        self._violation_history: list[float] = []
        self._full_steps: list[bool] = []  # whether each line search took the full step
        self._strict_reference = False  # the line search's, once the violation stalled
        self._elastic_steps = 0
        mu, status, alpha, step, success = 0.0, "max_iter reached", 1.0, np.inf, False
        multipliers_only = False  # the last iteration only took the QP's multipliers
        infeasible_steps = 0  # consecutive elastic steps that predict no less violation
        timing = {"linearize": 0.0, "qp": 0.0, "line_search": 0.0}
        t0 = time.perf_counter()
        it = 0
        t_iter = t0
        for it in range(o["max_iter"] + 1):
            tic = time.perf_counter()
            H, grad, f, g, J, stat = self._linearize(w, p, o["regularization"], lam_g, lam_x)
            timing["linearize"] += time.perf_counter() - tic
            grad, g, f = grad.full().ravel(), g.full().ravel(), float(f)
            # dual scaling as IPOPT's: large multipliers relax the stationarity test
            scale = max(100.0, (np.abs(lam_g).sum() + np.abs(lam_x).sum())
                        / max(1, tr.ng + tr.nw)) / 100.0
            stat = float(stat) / scale
            viol = tr.violation(w, g, lbx, ubx, lbg, ubg)
            # a multiplier on a bound the point does not touch (one relaxed since a warm
            # start) makes a stationary-looking but wrong KKT point
            comp = max(_complementarity(lam_g, g, lbg, ubg),
                       _complementarity(lam_x, w, lbx, ubx)) / scale
            history.append({"iteration": it, "cost": f, "violation": viol,
                            "stationarity": stat, "complementarity": comp, "step": step,
                            "alpha": alpha, "mu": mu})
            if o["verbose"]:  # alpha is None after a multipliers-only iteration
                self._progress(f"{it:3d} cost {f:.6e} viol {viol:.2e} stationarity "
                               f"{stat:.2e} alpha {alpha or 0.0:.3f}")
            if not (math.isfinite(f) and math.isfinite(viol) and np.isfinite(grad).all()):
                status = (_not_finite_at_guess(w, p, f, viol) if it == 0
                          else "not finite after a step")
                break
            # a tiny step alone is no convergence: a huge regularisation makes every step
            # tiny (1e9: 'converged' at cost 16 against the optimum's 12, stationarity 0.4)
            if viol <= o["tol_constr"] and ((stat <= o["tol"] and comp <= o["tol"]) or (
                    step <= o["tol_step"] and stat <= math.sqrt(o["tol"]))):
                status, success = "converged", True
                break
            if it == o["max_iter"]:
                break
            # never start a step that would not end within the budget (its cost estimated
            # by the last one's; a GN-SQP turn took minutes with no way to cap it)
            tic = time.perf_counter()
            if it > 0 and o["time_budget"] is not None and (
                    2 * tic - t_iter - t0 > o["time_budget"]):
                status = "time budget"
                break
            t_iter = tic
            res = self._step(H, grad, J, g, w, lbx, ubx, lbg, ubg, lam_g, lam_x, mu)
            timing["qp"] += time.perf_counter() - tic
            if res is None:
                status = (f"QP failed ({self._qp_solver(True).stats().get('return_status')})")
                break
            d, lg_qp, lx_qp, slack, mu = res
            # the elastic QP predicts no less violation than now, again and again: a
            # stationary point of the violation (the linearisations stay inconsistent)
            stuck = slack > 0.0 and slack >= (1.0 - 1e-6) * _l1_violation(g, lbg, ubg) - 1e-12
            infeasible_steps = infeasible_steps + 1 if stuck else 0
            if infeasible_steps >= INFEASIBLE_STEPS:
                status = "locally infeasible (the violation cannot be reduced further)"
                break
            tic = time.perf_counter()
            alpha = self._line_search(w, d, p, f, g, grad, mu, slack, lbg, ubg)
            timing["line_search"] += time.perf_counter() - tic
            if alpha is None and not multipliers_only:
                # no descent from here: at a solution (a warm start from one, whose
                # multipliers were not kept) the KKT test with the QP's multipliers decides
                multipliers_only, lam_g, lam_x, step = True, lg_qp, lx_qp, np.inf
                continue
            if alpha is None:
                status, alpha = "line search failed", 0.0
                break
            multipliers_only = False
            w = np.clip(w + alpha * d, lbx, ubx)
            lam_g = lam_g + alpha * (lg_qp - lam_g)
            lam_x = lam_x + alpha * (lx_qp - lam_x)
            step = alpha * float(np.max(np.abs(d), initial=0.0))
        elapsed = time.perf_counter() - t0
        self.w, self.lam_g, self.lam_x = (np.empty_like(v) for v in (w, lam_g, lam_x))
        self.w[pw], self.lam_g[pg], self.lam_x[pw] = w, lam_g, lam_x
        self._split_solution(*tr.unpack(self.w))
        s = self.stats
        last = history[-1]
        s.success, s.status, s.iterations, s.time = success, status, it, elapsed
        s.cost, s.constraint_violation = last["cost"], last["violation"]
        s.history = history
        s.extra = {"stationarity": last["stationarity"], "qp_solver": o["qp_solver"],
                   "elastic_steps": self._elastic_steps,
                   **{f"t_{k}": v for k, v in timing.items()}}
        log.debug("gnsqp: %s in %d iterations, %.4f s, cost %.6g, violation %.2e", status, it,
                  elapsed, s.cost, s.constraint_violation)
        return success

    def _stalled(self) -> bool:
        """Whether the violation (l1) stalled under full steps: the smallest of the last
        :data:`STALL_WINDOW` iterations' above ``tol_constr`` and above :data:`STALL_FACTOR`
        times the smallest of the window before (so no answer before 2 windows of this
        solve), and :data:`STALL_FULL_STEPS` of the last window's steps full. Full steps the
        maximum of the recent merits lets through then cycle (a UR5 reach at an
        active joint limit: steps of period 3, the merit 2e-7 lower per cycle, 'max_iter'
        at 300 and 1000 iterations)."""
        v, full = self._violation_history, self._full_steps
        if len(v) < 2 * STALL_WINDOW:
            return False
        before, now = min(v[-2 * STALL_WINDOW:-STALL_WINDOW]), min(v[-STALL_WINDOW:])
        # ... through full steps: a stall under short steps (a collocated cart-pole at an
        # active bound, alpha 1/16-1/32 for 200 iterations) is the maximum's to end (it
        # did, in 286 iterations; the mean took 397)
        return (now > self.opts["tol_constr"] and now > STALL_FACTOR * before
                and sum(full[-STALL_WINDOW:]) >= STALL_FULL_STEPS * STALL_WINDOW)

    def _line_search(self, w, d, p, f, g, grad, mu, slack, lbg, ubg) -> float | None:
        """Backtracking (non-monotone Armijo) on the l1 merit; the step length or None."""
        violation = _l1_violation(g, lbg, ubg)
        phi0 = f + mu * violation
        self._merit_history.append(phi0)
        self._violation_history.append(violation)
        recent = self._merit_history[-self.opts["nonmonotone"]:]
        if not self._strict_reference and self._stalled():
            self._strict_reference = True
            log.debug("gnsqp: the violation stalled; the line search's reference is now the "
                      "weighted mean of the recent merit values")
        ref = max(phi0, _recent_mean(recent)) if self._strict_reference else max(recent)
        slack_tol = 1e-12 * max(1.0, abs(ref))  # rounding of the merit near convergence
        # directional derivative of the merit along d (the linearisation leaves `slack`)
        slope = min(0.0, float(grad @ d) + mu * (slack - violation))
        alpha = 1.0
        while alpha >= self.opts["min_step"]:
            f1, g1 = self._evaluate(w + alpha * d, p)
            phi1 = float(f1) + mu * _l1_violation(g1.full().ravel(), lbg, ubg)
            if phi1 <= ref + self.opts["armijo"] * alpha * slope + slack_tol:
                self._full_steps.append(alpha == 1.0)
                return alpha
            alpha *= 0.5
        self._full_steps.append(False)
        return None


def _recent_mean(recent: list[float]) -> float:
    """The mean of ``recent`` (oldest first), weights halving into the past (the newest 1,
    the one before 1/2, ...): the line search's reference once the violation stalled."""
    weights = [0.5 ** k for k in range(len(recent) - 1, -1, -1)]
    return sum(w * v for w, v in zip(weights, recent, strict=True)) / sum(weights)


def _not_finite_at_guess(w: np.ndarray, p: np.ndarray, f: float, viol: float) -> str:
    """Why the first linearisation is not finite, as far as the data say."""
    if not (np.isfinite(w).all() and np.isfinite(p).all()):
        return "not finite at the initial guess (NaN/inf in the guess or the parameters)"
    if not (math.isfinite(f) and math.isfinite(viol)):
        return "cost or constraints not finite at the initial guess"
    return "cost gradient not finite at the initial guess (a derivative undefined there)"


def _signed(lam: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """``lam`` with the signs the bounds allow (CasADi: > 0 upper bound, < 0 lower bound)."""
    lam = np.where(np.isinf(ub), np.minimum(lam, 0.0), lam)
    return np.where(np.isinf(lb), np.maximum(lam, 0.0), lam)


def _complementarity(lam: np.ndarray, val: np.ndarray, lb: np.ndarray,
                     ub: np.ndarray) -> float:
    """Largest ``|lam| * distance to the bound lam acts on`` (0 where lam is 0)."""
    dist = np.where(lam > 0, ub - val, np.where(lam < 0, val - lb, 0.0))
    prod = np.abs(lam) * np.where(np.isfinite(dist), np.abs(dist), 0.0)
    # an infinite distance with a nonzero multiplier is impossible after _signed
    return float(np.max(prod, initial=0.0))


def _first_line(exc: Exception) -> str:
    """The informative line of a CasADi error (its first lines name C++ files)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return next((ln for ln in reversed(lines) if "casadi" not in ln.lower()[:40]), lines[-1]
                if lines else type(exc).__name__)


def _check_qp_solver(name: str) -> None:
    if not cs.has_conic(name):
        raise ValueError(f"gnsqp: QP solver {name!r} is not available in this CasADi; try "
                         f"one of {sorted(n for n in QP_DEFAULTS if cs.has_conic(n))}")


def _l1_violation(g: np.ndarray, lbg: np.ndarray, ubg: np.ndarray) -> float:
    return float(np.sum(np.maximum(0.0, np.maximum(lbg - g, g - ubg))))
