"""Multiple-shooting, constrained iterative LQR (``make_solver('ilqr', prb, opts)``).

One iteration (the real-time iteration of the MPC):

1. quadratise all nodes in one compiled mapped call (dynamics Jacobians in the tangent
   space, Gauss-Newton model of the residual costs and of the augmented-Lagrangian rows);
2. backward Riccati recursion with the defects (gaps) of the warm start as affine terms,
   Levenberg-Marquardt regularisation raised on failure;
3. linear rollout of the full Gauss-Newton step, which closes the linearised gaps;
4. backtracking line search on the merit ``cost + AL terms + nu * ||gaps||_1``;
5. multiplier and penalty update of the augmented Lagrangian (when the inner problem is
   nearly solved, or every few iterations; once per call in real-time mode).

Equality constraints are projected exactly or go through the augmented Lagrangian;
inequality rows and bounds go through the augmented Lagrangian (driven to feasibility over
the iterations) or, with ``inequality='barrier'``, through a relaxed log barrier (smooth:
the choice for one iteration per MPC tick). Nothing the problem declares is dropped.
"""

from __future__ import annotations

import functools
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from horizon_mpc.codegen import BufferedFunction, codegen_enabled, compile_function
from horizon_mpc.problem import Problem
from horizon_mpc.problem.terms import (
    revisions,
    stacked_active,
    stacked_bounds,
    stacked_weights,
)
from horizon_mpc.solvers.base import Solver
from horizon_mpc.solvers.ilqr import merit, riccati, riccati_c
from horizon_mpc.solvers.ilqr.equality import EqualityLayout, project
from horizon_mpc.solvers.ilqr.evaluation import CompiledEvaluation
from horizon_mpc.solvers.ilqr.lagrangian import INEQUALITY_MODES, AugmentedLagrangian
from horizon_mpc.solvers.ilqr.lq_step import CompiledLqStep
from horizon_mpc.solvers.ilqr.stages import build_stage_model, check_supported

__all__ = ["IlqrSolver"]

log = logging.getLogger(__name__)

# the compiled backward pass reads A and B by their pattern below this density of nonzeros
SPARSE_DYNAMICS = 0.25


def _blocks(out: np.ndarray, n: int, rows: int, cols: int) -> np.ndarray:
    """(rows, cols*n) column-major output of a mapped Function -> (n, rows, cols), a view."""
    if not cols or not rows:
        return np.zeros((n, rows, cols))
    return out.T.reshape(n, cols, rows).transpose(0, 2, 1)


class IlqrSolver(Solver):
    """Constrained multiple-shooting ILQR; see the module docstring.

    Options (``make_solver('ilqr', prb, opts)``; ``*``: read when the solver is built,
    ``set_option`` refuses a change):

    ========================= ============== ==============================================
    ``max_iter``              300            iteration limit of a converging solve
    ``rti``                   False          True: exactly ``iterations_per_call``
                                             iterations per ``solve()``, no convergence
                                             test (real-time iterations)
    ``iterations_per_call``   1              iterations of a real-time call
    ``tol``                   1e-8           stationarity: expected decrease / (1 + cost)
    ``tol_constraint``        1e-6           defects, constraints, bounds (inf-norm)
    ``tol_complementarity``   1e-4           inequality rows: largest
                                             ``|min(multiplier, slack)|`` (IPOPT's
                                             ``compl_inf_tol`` default)
    ``mu_init``               1e-8           regularisation of the backward pass: its
    ``mu_min``                1e-10          start and bounds
    ``mu_max``                1e10
    ``rho_init*``             100            augmented-Lagrangian penalty; grows by
    ``rho_factor``            10             ``rho_factor`` up to ``rho_max`` (fixed in
    ``rho_max``               1e9            ``rti`` mode: the problem moves between calls)
    ``line_search``           True           False: every full step (the classic
                                             real-time iteration); a step whose
                                             evaluation is not finite is still rejected
    ``line_search_steps``     10             step lengths tried: 1, 1/2, ...,
                                             2^-(n-1)
    ``time_budget``           None           s per call: an iteration is not started when
                                             the last one's duration would take the call
                                             past it (the first always runs; status
                                             ``'time budget'``)
    ``codegen*``              True           compile the node functions (cached on disk)
    ``callback``              None           called with the history dict of each
                                             iteration
    ``equality*``             'projection'   equality rows exact in the backward pass
                                             (:mod:`.equality`; rows that do not fit a
                                             node's inputs use the augmented Lagrangian),
                                             or 'lagrangian' (all rows through it)
    ``al_inner_tol``          1e-3           a converging solve updates multipliers and
    ``al_max_inner``          10             penalties when the expected decrease is below
                                             ``al_inner_tol`` x cost, after a rejected
                                             step, or every ``al_max_inner`` iterations
    ``rti_multiplier_update`` True           False leaves a real-time call's multipliers
                                             alone (:meth:`prepare`/:meth:`feedback`
                                             update them after the feedback)
    ``inequality*``           'lagrangian'   inequality rows and bounds through the
                                             augmented Lagrangian (exact at convergence),
                                             or 'barrier': a relaxed log barrier of weight
                                             ``barrier_mu*`` (1) and slack
                                             ``barrier_delta*`` (1), in the rows' units:
                                             smooth, so one iteration per MPC tick does not
                                             chatter on the active set, approximately
                                             feasible (:mod:`.lagrangian`)
    ``input_bounds``          'auto'         'box': the inputs' bounds kept by the backward
                                             pass (box QP per node, clamped rollouts;
                                             through the Lagrangian at nodes with projected
                                             rows); 'lagrangian': as the other bounds;
                                             'auto': 'lagrangian', then 'box' from the
                                             current iterate after ``box_after`` (20)
                                             iterations without convergence (real-time
                                             calls and the barrier keep 'lagrangian')
    ``box_after``             20             (see ``input_bounds``)
    ``barrier_mu*``           1.0            (see ``inequality``)
    ``barrier_delta*``        1.0            (see ``inequality``)
    ========================= ============== ==============================================
    """

    name = "ilqr"
    DEFAULTS: dict[str, Any] = {
        "max_iter": 300,
        "rti": False,
        "iterations_per_call": 1,
        "tol": 1e-8,
        "tol_constraint": 1e-6,
        "tol_complementarity": 1e-4,
        "mu_init": 1e-8,
        "mu_min": 1e-10,
        "mu_max": 1e10,
        "rho_init": 1e2,
        "rho_factor": 10.0,
        "rho_max": 1e9,
        "line_search_steps": 10,
        "time_budget": None,
        "codegen": True,
        "callback": None,
        "equality": "projection",
        "line_search": True,
        "al_inner_tol": 1e-3,
        "al_max_inner": 10,
        "rti_multiplier_update": True,
        "inequality": "lagrangian",
        "input_bounds": "auto",
        "box_after": 20,
        "barrier_mu": 1.0,
        "barrier_delta": 1.0,
    }

    CHOICES = {"equality": ("projection", "lagrangian"),
               "input_bounds": ("auto", "box", "lagrangian"),
               "inequality": INEQUALITY_MODES}
    # built into the stage model and the multipliers' rows at construction
    BUILD_ONLY = ("codegen", "equality", "inequality", "barrier_mu", "barrier_delta",
                  "rho_init")
    RANGES = {
        "max_iter": ">=1", "iterations_per_call": ">=1", "tol": ">=0", "tol_constraint": ">=0",
        "tol_complementarity": ">=0", "mu_init": ">=0", "mu_min": ">=0", "mu_max": ">0",
        "rho_init": ">0", "rho_factor": ">=1", "rho_max": ">0", "line_search_steps": ">=1",
        "time_budget": ">0", "al_inner_tol": ">=0", "al_max_inner": ">=1", "box_after": ">=1",
        "barrier_mu": ">0", "barrier_delta": ">0",
    }

    def _check_together(self, opts: dict[str, Any]) -> None:
        for lo, hi in (("mu_min", "mu_max"), ("rho_init", "rho_max")):
            if opts[lo] > opts[hi]:
                raise ValueError(f"ilqr options: {lo} {opts[lo]!r} is above {hi} {opts[hi]!r}")
        if opts["callback"] is not None and not callable(opts["callback"]):
            raise TypeError(f"ilqr option 'callback' must be callable (called with a dict per "
                            f"iteration) or None, got {opts['callback']!r}")

    def _check_problem(self, prb: Problem) -> None:
        check_supported(prb)

    def __init__(self, prb: Problem, opts: dict[str, Any] | None = None):
        super().__init__(prb, opts)
        self._auto_box = False  # 'auto': this call went on with the box (_switch_to_box)
        # 'auto': where the last converging call ended with the box, (X, U) as stacked guesses
        # (or that point shifted): the next converging call from there starts with it
        self._box_start: tuple[np.ndarray, np.ndarray] | None = None
        self._shifted = False  # shift() since the last call (see _begin_call)
        # nodes whose projected rows went back to the augmented Lagrangian (_demote_dependent;
        # for the solver's life: a warm re-solve keeps their multipliers)
        self._demoted = np.zeros(prb.n_nodes, bool)
        self._box_from: int | None = None
        self.model = build_stage_model(prb, codegen=bool(self.opts["codegen"]),
                                       projected_equalities=self.opts["equality"] == "projection")
        m = self.model
        N = m.n_nodes
        o = self.opts
        rows = dict(inequality=o["inequality"], barrier_mu=o["barrier_mu"],
                    barrier_delta=o["barrier_delta"])
        self._al = AugmentedLagrangian(np.full((N, m.nc), -np.inf), np.full((N, m.nc), np.inf),
                                       o["rho_init"], **rows)
        self._alN = AugmentedLagrangian(np.full((1, m.ncN), -np.inf),
                                        np.full((1, m.ncN), np.inf), o["rho_init"], **rows)
        self._layout = EqualityLayout.empty(N, m.nc_con, m.ncN_con)
        self._eq_rows = self._layout.stage_rows()
        self._uses_input = np.concatenate(
            [np.full(c.dim, bool(c.uses_input)) for c in m.stage_cons] or [np.zeros(0, bool)])
        self.mu = self._mu_init()
        difference = prb.state_difference()
        if self.opts["codegen"] and codegen_enabled():
            difference = compile_function(difference)
        self._difference = BufferedFunction(difference)
        # numpy in/out through preallocated buffers (no DM conversion); outputs are views
        # overwritten by the next call of the same function
        self._values = BufferedFunction(m.values)
        self._values_term = BufferedFunction(m.values_term)
        self._quadratise_fn = self._quadratise_lean = BufferedFunction(m.quadratise)
        self._quadratise_all: BufferedFunction | None = None  # every row's AL terms, on demand
        self._quadratise_term = BufferedFunction(m.quadratise_term)
        self._integrate = BufferedFunction(m.integrate)
        # the Riccati recursion in compiled C when available (numpy loop otherwise); sparse
        # dynamics Jacobians (go2 walking: 5 % of [A | B]) by their pattern
        self._ab_pattern: riccati_c.AbPattern | None = None  # also read by the projection
        self._step_stats = merit.step_stats
        # the evaluation and the quadratisation in one compiled call each (when the
        # functions are compiled: their C entry points are called from evaluation.c)
        self._compiled_eval: CompiledEvaluation | None = None
        if self.opts["codegen"] and riccati_c.available():
            self._compiled_eval = CompiledEvaluation.create(
                m.values, m.values_term, difference, m.quadratise, m.quadratise_term,
                {"N": N, "nx": m.nx, "ndx": m.ndx, "nu": m.nu, "nr": m.nr, "nc": m.nc,
                 "ncon": m.nc_con, "nrN": m.nrN, "ncN": m.ncN, "ncNcon": m.ncN_con,
                 "npar": prb.np_, "ns": prb.ns}, self._al, self._alN)
            self._backward, self._rollout = riccati_c.backward_pass_c, riccati_c.linear_rollout_c
            self._step_stats = riccati_c.step_stats_c
            pattern = None if m.ab_pattern is None else riccati_c.AbPattern.from_mask(
                m.ab_pattern)
            if pattern is not None and pattern.density <= SPARSE_DYNAMICS:
                self._ab_pattern = pattern
                self._backward = functools.partial(riccati_c.backward_pass_c, pattern=pattern)
        # the quadratisation's blocks: views of the compiled evaluation's persistent buffer
        # (built once), which the compiled LQ step reads in place
        self._q_views: dict[str, np.ndarray] | None = None
        self._lq: CompiledLqStep | None = None
        if self._compiled_eval is not None:
            ce = self._compiled_eval
            self._q_views = self._quadratisation_views(ce.quadratisation,
                                                       ce.quadratisation_term)
            self._lq = CompiledLqStep.create(
                self._q_views, {"N": N, "ndx": m.ndx, "nu": m.nu, "nc": m.nc_con,
                                "ncN": m.ncN_con, "ldc": m.nc}, self._ab_pattern)
        else:
            self._backward, self._rollout = riccati.backward_pass, riccati.linear_rollout
        self._gains = np.zeros((N, m.nu, m.ndx))
        self._memos: dict[str, tuple[tuple, Any]] = {}  # see _memo
        self.Wr: np.ndarray | None = None  # (N, nr) residual weights (_gather)
        self.WrN: np.ndarray | None = None  # (1, nrN)
        self.timings: dict[str, float] = {}
        self._prepared: tuple | None = None  # (evaluation, LQ step, info) of prepare()
        self._box: tuple[np.ndarray, np.ndarray] | None = None  # see _set_box
        # the box of the step (see _box_step): the compiled LQ step's bound arrays
        self._box_du = ((self._lq.box_lo, self._lq.box_hi) if self._lq is not None else
                        (np.zeros((N, m.nu)), np.zeros((N, m.nu))))

    # ------------------------------------------------------------------ problem data
    def _gather(self) -> None:
        """Read guesses, parameters, bounds and weights from the problem (once per solve).

        The stacked bounds of the constraints and the residual weights are read again only
        when a term's revision changed (a receding horizon moves node sets, rarely bounds
        or weights)."""
        prb, m = self.prb, self.model
        N = m.n_nodes
        self.X = prb.stacked("state", copy=False).T.copy()  # (N+1, nx)
        self.U = prb.stacked("input", copy=False).T.copy()  # (N, nu)
        self.S = prb.stacked("single", "lower_bounds")  # fixed singles, (ns, 1)
        if self.S.size and not np.array_equal(self.S, prb.stacked("single", "upper_bounds",
                                                                   copy=False)):
            # freed since the build: solving on with its lower bound would be a wrong answer
            free = [v.name for v in prb.singles
                    if not np.array_equal(v.lower_bounds, v.upper_bounds)]
            raise ValueError(f"ilqr cannot optimise single variable(s) {free} (their bounds "
                             "differ since the solver was built): fix them with equal bounds "
                             "or use ipopt/gnsqp")
        self.P = prb.stacked("parameter")  # (np, N+1)
        xlb = prb.stacked("state", "lower_bounds", copy=False)  # read-only views
        xub = prb.stacked("state", "upper_bounds", copy=False)
        ulb = prb.stacked("input", "lower_bounds", copy=False)
        uub = prb.stacked("input", "upper_bounds", copy=False)
        self.x_init = None
        self._fixed_rows = None  # (rows, lb, ub) of the state-only rows skipped at node 0
        if np.all(np.isfinite(xlb[:, 0])) and np.array_equal(xlb[:, 0], xub[:, 0]):
            self.x_init = xlb[:, 0].copy()
        # stage rows: constraints, then x bounds, then u bounds
        nc, ncN = m.nc_con, m.ncN_con
        lb, ub = np.empty((N, m.nc)), np.empty((N, m.nc))
        if nc:
            clb, cub = self._memo("stage bounds", revisions(m.stage_cons, "bounds_revision"),
                                  lambda: stacked_bounds(m.stage_cons)[:2])
            act = stacked_active(m.stage_cons)[:, :N]
            if self.x_init is not None:
                # a fixed initial state cannot be changed: nothing to enforce at node 0,
                # but what those rows violate there still counts (an infeasible problem)
                rows = np.flatnonzero(act[:, 0] & ~self._uses_input)
                self._fixed_rows = (rows, clb[rows, 0], cub[rows, 0]) if rows.size else None
                act[~self._uses_input, 0] = False
            lb[:, :nc] = np.where(act, clb[:, :N], -np.inf).T
            ub[:, :nc] = np.where(act, cub[:, :N], np.inf).T
        lb[:, nc:nc + m.nx], ub[:, nc:nc + m.nx] = xlb[:, :N].T, xub[:, :N].T
        if self.x_init is not None:  # the fixed state is not a bound of the step
            lb[0, nc:nc + m.nx], ub[0, nc:nc + m.nx] = -np.inf, np.inf
        lb[:, nc + m.nx:], ub[:, nc + m.nx:] = ulb.T, uub.T
        lbN, ubN = np.empty((1, m.ncN)), np.empty((1, m.ncN))
        if ncN:
            tlb, tub = self._memo("terminal bounds", revisions(m.term_cons, "bounds_revision"),
                                  lambda: stacked_bounds(m.term_cons)[:2])
            tact = stacked_active(m.term_cons)
            lbN[0, :ncN] = np.where(tact[:, N], tlb[:, N], -np.inf)
            ubN[0, :ncN] = np.where(tact[:, N], tub[:, N], np.inf)
        lbN[0, ncN:], ubN[0, ncN:] = xlb[:, N], xub[:, N]
        if self.opts["equality"] == "projection":
            self._layout = EqualityLayout.from_bounds(
                lb[:, :nc], ub[:, :nc], self._uses_input, lbN[0, :ncN], ubN[0, :ncN], m.nu,
                m.con_reach, m.conN_reach)
            if not self.opts["rti"]:
                # a converging solve projects no row onto an input with a bound: the
                # projection pins the input to what meets the rows in one step (a waypoint
                # of a double integrator: 100x its bound), the bound pulls it back, and
                # the solve stalled (max_iter in every mode, 21 % above IPOPT); rows found
                # dependent there go back too (_demote_dependent)
                bounded = (np.isfinite(ulb) | np.isfinite(uub)).any(axis=0)
                self._layout = self._layout.without_nodes(bounded | self._demoted)
            self._eq_rows = self._layout.stage_rows()
            # projected rows leave the augmented Lagrangian
            lb[:, :nc][self._eq_rows], ub[:, :nc][self._eq_rows] = -np.inf, np.inf
            lbN[0, :ncN][self._layout.term], ubN[0, :ncN][self._layout.term] = -np.inf, np.inf
        self._set_box(lb, ub, ulb, uub)
        self._al.set_bounds(lb, ub)
        self._alN.set_bounds(lbN, ubN)
        self._choose_quadratisation(lb[:, :m.nc_con], ub[:, :m.nc_con])
        weights = self.Wr, self.WrN
        self.Wr, self.WrN = self._memo("weights", (revisions(m.stage_costs),
                                                   revisions(m.term_costs)), self._weights)
        if self._compiled_eval is not None:
            lay = self._layout
            self._compiled_eval.set_problem(
                self.S, self.P, lay.b, self._eq_rows, lay.bN, lay.term,
                None if weights[0] is self.Wr and weights[1] is self.WrN
                else (self.Wr, self.WrN[0]))

    def _set_box(self, lb: np.ndarray, ub: np.ndarray, ulb: np.ndarray,
                 uub: np.ndarray) -> None:
        """The input bounds the backward pass keeps (option ``input_bounds='box'``): those
        of the nodes without projected rows, taken out of the augmented-Lagrangian bounds
        ``lb``, ``ub`` (N, nc) in place; ``self._box`` = their (lower, upper) (N, nu),
        infinite elsewhere, or None. The guess's inputs are clipped into them (the steps
        then stay inside). ``ulb``, ``uub``: (nu, N) input bounds."""
        self._box = None
        m = self.model
        if not m.nu or not (self.opts["input_bounds"] == "box" or self._auto_box):
            return
        finite = np.isfinite(ulb) | np.isfinite(uub)
        if not finite.any():
            return
        nodes = finite.any(axis=0) & ~self._layout.nodes()
        if not nodes.any():
            return
        box_lb = np.where(nodes[:, None], ulb.T, -np.inf)
        box_ub = np.where(nodes[:, None], uub.T, np.inf)
        lb[nodes, -m.nu:], ub[nodes, -m.nu:] = -np.inf, np.inf
        self._box = (box_lb, box_ub)
        np.clip(self.U, box_lb, box_ub, out=self.U)

    def _demote_dependent(self, proj) -> bool:
        """The projected rows of nodes where they are dependent in the input (e.g. a final
        position and velocity under two inputs that act alike: the projection keeps one
        direction, meets the other row only if it already is, and leaves out its multiplier,
        so a solve stalled unmet, or at a solution rejected every step) go back to the
        augmented Lagrangian, from then on (later converging calls too): the problem is read
        again without them in the layout. Converging solves only (real-time calls keep the
        layout of the bounds: the rows of a receding horizon move between calls). Returns
        whether rows were demoted (the caller evaluates and quadratises again)."""
        if proj is None or self.opts["rti"]:
            return False
        new = proj.dependent() & ~self._demoted
        if not new.any():
            return False
        self._demoted |= new
        self._regather()
        log.debug("ilqr: projected rows at nodes %s go to the augmented Lagrangian (their "
                  "input Jacobians are dependent, the rows not met)", np.flatnonzero(new))
        return True

    def _auto_applies(self) -> bool:
        """Whether ``input_bounds='auto'`` may hand the input bounds to the box (not with the
        barrier, which relaxes them on purpose)."""
        return self.opts["input_bounds"] == "auto" and self.opts["inequality"] == "lagrangian"

    def _switch_to_box(self, ev: dict[str, Any]) -> dict[str, Any] | None:
        """``input_bounds='auto'``: go on from the current iterate with the input bounds kept
        by the backward pass (the problem read again, those rows out of the augmented
        Lagrangian, the inputs clipped into them, the regularisation reset). Returns the
        evaluation to go on with: ``ev`` itself when there is no input bound (and the call
        stays as it was)."""
        prb = self.prb
        if not (np.isfinite(prb.stacked("input", "lower_bounds", copy=False)).any()
                or np.isfinite(prb.stacked("input", "upper_bounds", copy=False)).any()):
            return ev
        # a converging solve projects no row onto a bounded input (_gather): every bounded
        # node gets its box
        self._auto_box = True
        self._regather()
        self.mu = self._mu_init()
        return self._evaluate(self.X, self.U)

    def _regather(self) -> None:
        """Read the problem again (bounds, layout, box) in the middle of a call, going on
        from the current iterate (its inputs clipped into the box)."""
        X, U = self.X, self.U
        self._gather()
        self.X, self.U = X, U
        if self._box is not None:
            np.clip(self.U, self._box[0], self._box[1], out=self.U)

    def _box_step(self) -> bool:
        """The box of the step ``du`` at the current inputs into ``self._box_du`` (the
        compiled LQ step reads the same arrays); whether there is one."""
        if self._box is None:
            return False
        np.subtract(self._box[0], self.U, out=self._box_du[0])
        np.subtract(self._box[1], self.U, out=self._box_du[1])
        return True

    def _weights(self) -> tuple[np.ndarray, np.ndarray]:
        """The residual weights per node, Wr (N, nr) and WrN (1, nrN) (0 where inactive)."""
        m, N = self.model, self.model.n_nodes
        out = []
        for name, costs, nodes, empty in (("stage", m.stage_costs, slice(0, N), (N, 0)),
                                          ("terminal", m.term_costs, slice(N, N + 1), (1, 0))):
            if not costs:
                out.append(np.zeros(empty))
                continue
            # the rows' weights change more rarely than the costs' nodes
            w = self._memo(f"{name} weight rows", revisions(costs, "weight_revision"),
                           lambda costs=costs: np.concatenate([c.weight for c in costs]))
            out.append(stacked_weights(costs, w)[:, nodes].T)
        return out[0], out[1]

    def _memo(self, name: str, key: tuple, compute: Callable[[], Any]) -> Any:
        """``compute()``, or its value of the last call with the same ``key`` (the value is
        shared: never written in place)."""
        hit = self._memos.get(name)
        if hit is not None and hit[0] == key:
            return hit[1]
        value = compute()
        self._memos[name] = (key, value)
        return value

    def _choose_quadratisation(self, lb: np.ndarray, ub: np.ndarray) -> None:
        """The lean quadratisation (no AL terms for the projected equalities) unless a row it
        leaves out is in the augmented Lagrangian now (lb, ub: (N, nc_con) AL bounds)."""
        left_out = ~self.model.al_rows[:lb.shape[1]]
        needed = (np.isfinite(lb[:, left_out]) | np.isfinite(ub[:, left_out])).any()
        if not needed:
            self._quadratise_fn = self._quadratise_lean
            if self._compiled_eval is not None:
                self._compiled_eval.set_stage_quadratisation(self._quadratise_lean.fn)
            return
        if self._quadratise_all is None:
            log.info("ilqr: a constraint row left out of the lean quadratisation (an equality "
                     "the projection was to handle) is in the augmented Lagrangian now: "
                     "building the quadratisation with every row")
            self._quadratise_all = BufferedFunction(self.model.quadratise_full())
        self._quadratise_fn = self._quadratise_all
        if self._compiled_eval is not None:
            self._compiled_eval.set_stage_quadratisation(self._quadratise_all.fn)

    # ------------------------------------------------------------------ evaluation
    def _evaluate(self, X: np.ndarray, U: np.ndarray) -> dict[str, Any] | None:
        """Defects, residuals and constraints at (X, U); None if anything is not finite."""
        m, N = self.model, self.model.n_nodes
        ce = self._compiled_eval
        if ce is not None:
            ce.set_initial_state(self.x_init)
            stats = ce(np.ascontiguousarray(X, dtype=float), np.ascontiguousarray(U, dtype=float))
            if stats is None:
                return None
            cost, gap_l1, gap_max, eq_l1, eq_max, al, al_viol = stats
            c = ce.c.copy()
            return {"gap": ce.gap.copy(), "r": ce.r.copy(), "c": c,
                    "rN": ce.rN.reshape(1, m.nrN).copy(), "cN": ce.cN.reshape(1, m.ncN).copy(),
                    "d0": ce.d0.copy(), "eq_l1": eq_l1, "cost": cost, "al": al,
                    "gap_l1": gap_l1, **self._violations(c, gap_max, eq_max, al_viol)}
        gap, r, c = self._values(X[:N].T, U.T, self._singles_per_node(), self.P[:, :N], X[1:].T)
        rN, cN = self._values_term(X[N], self.S, self.P[:, N])
        gap, r, c = gap.T.copy(), r.T.copy(), c.T.copy()  # (N, ndx), (N, nr), (N, nc)
        rN, cN = rN.reshape(1, m.nrN).copy(), cN.reshape(1, m.ncN).copy()
        if self.x_init is not None:
            d0 = self._difference(X[0], self.x_init)[0].reshape(m.ndx).copy()
        else:
            d0 = np.zeros(m.ndx)
        lay = self._layout
        stats = merit.evaluation_stats(gap, r, self.Wr, c, lay.b, self._eq_rows, d0, rN[0],
                                       self.WrN[0], cN[0], lay.bN, lay.term)
        if stats is None:  # a value is not finite
            return None
        cost, gap_l1, gap_max, eq_l1, eq_max = stats
        al, al_viol = self._al.value_and_violation(c)
        alN, alN_viol = self._alN.value_and_violation(cN)
        return {
            "gap": gap, "r": r, "c": c, "rN": rN, "cN": cN, "d0": d0,
            "eq_l1": eq_l1, "cost": cost, "al": al + alN, "gap_l1": gap_l1,
            **self._violations(c, gap_max, eq_max, max(al_viol, alN_viol)),
        }

    def _violations(self, c: np.ndarray, gap_max: float, eq_max: float,
                    al_viol: float) -> dict[str, float]:
        """The evaluation's violations (inf-norms): ``viol_eq`` of the dynamics and the
        projected equalities, ``viol_free`` with the augmented-Lagrangian rows too,
        ``viol_fixed`` of the state-only rows at a fixed node 0 (left out of the steps),
        ``viol`` of everything."""
        fixed = 0.0
        if self._fixed_rows is not None:
            rows, lb, ub = self._fixed_rows
            c0 = c[0, rows]
            fixed = float(np.max(np.maximum(lb - c0, c0 - ub), initial=0.0))
        eq = max(gap_max, eq_max)
        free = max(eq, al_viol)
        if self._box is not None:  # the input bounds the backward pass keeps
            u = c[:, -self.model.nu:]
            free = max(free, float(np.max(np.maximum(self._box[0] - u, u - self._box[1]),
                                          initial=0.0)))
        return {"viol_eq": eq, "viol_free": free, "viol_fixed": fixed, "viol": max(free, fixed)}

    def _complementarity(self, ev: dict[str, Any]) -> float:
        """How far the inequality rows are from complementarity with their multipliers
        (:meth:`.AugmentedLagrangian.complementarity`; the fixed node 0's rows left out, as
        from the steps): a stationary, feasible point whose multipliers still press rows
        away from their bounds is no solution (a reviewer's convex problem was called
        converged 1.1e-4 above IPOPT's optimum with bounds 1.3e-3 short of active)."""
        return max(self._al.complementarity(ev["c"]), self._alN.complementarity(ev["cN"]))

    def _merit(self, ev: dict[str, Any], nu: float) -> float:
        return ev["cost"] + ev["al"] + nu * (ev["gap_l1"] + ev["eq_l1"])

    def _quadratise(self, X, U, ev):
        N = self.model.n_nodes
        ce = self._compiled_eval
        if ce is not None:
            if not ce.quadratise(np.ascontiguousarray(X, dtype=float),
                                 np.ascontiguousarray(U, dtype=float), ev["c"], ev["cN"][0]):
                return None
            return self._q_views
        wc, tc = self._al.weights_targets(ev["c"])
        wcN, tcN = self._alN.weights_targets(ev["cN"])
        out = self._quadratise_fn(X[:N].T, U.T, self._singles_per_node(), self.P[:, :N], self.Wr.T,
                                  wc.T, tc.T)
        out_term = self._quadratise_term(X[N], self.S, self.P[:, N], self.WrN.T, wcN.T,
                                         tcN.T)
        # one finiteness test on the outputs (NaN and inf propagate through sums)
        if not math.isfinite(float(self._quadratise_fn.output_buffer.sum())
                             + float(self._quadratise_term.output_buffer.sum())):
            return None
        return self._quadratisation_views(out, out_term)

    def _quadratisation_views(self, out, out_term) -> dict[str, np.ndarray]:
        """The quadratisation's blocks node by node, views of the functions' outputs: A, B,
        lx, lu, lxx, luu, lux (N, ...), lxN, lxxN, and the constraint Jacobians cx, cu
        (N, nc_con, ...), cxN (ncN_con, ndx)."""
        m, N = self.model, self.model.n_nodes
        A, B, lx, lu, lxx, luu, lux, cx, cu = out
        lxN, lxxN, cxN = out_term
        ndx, nu = m.ndx, m.nu
        return {
            "A": _blocks(A, N, ndx, ndx), "B": _blocks(B, N, ndx, nu),
            "lx": lx.T, "lu": lu.T,
            "lxx": _blocks(lxx, N, ndx, ndx), "luu": _blocks(luu, N, nu, nu),
            "lux": _blocks(lux, N, nu, ndx),
            "lxN": lxN.reshape(ndx), "lxxN": lxxN.reshape(ndx, ndx),
            "cx": _blocks(cx, N, m.nc_con, ndx), "cu": _blocks(cu, N, m.nc_con, nu),
            "cxN": np.asarray(cxN).reshape(m.ncN_con, ndx),
        }

    def _retract(self, X, dX, alpha):
        return self._integrate(X.T, alpha * dX.T)[0].T.copy()

    # ------------------------------------------------------------------ iterations
    def _lq_step(self, ev: dict[str, Any], info: dict[str, float]):
        """Quadratise at (self.X, self.U), project the equality rows and run the backward
        pass, raising the regularisation until every Q_uu is positive definite.

        Returns ``(q, proj, bw)``, or None (``info`` says why: ``status_nan``,
        ``linearisation_failed``, ``backward_failed``)."""
        m, o = self.model, self.opts
        t0 = time.perf_counter()
        q = self._quadratise(self.X, self.U, ev)
        t1 = time.perf_counter()
        self._time("quadratise", t1 - t0)
        if q is None:
            if self.mu >= o["mu_max"]:
                info["linearisation_failed"] = 1.0
            self.mu = min(max(self.mu * 100, 1e-6), o["mu_max"])
            info["status_nan"] = 1.0
            return None
        proj, lq = None, self._lq
        box = self._box_step()
        if self._layout.any:
            if lq is not None:
                proj = lq.project(self._layout, ev["c"], ev["cN"][0], ev["gap"])
            else:
                proj = project(self._layout, ev["c"][:, :m.nc_con], q["cx"], q["cu"],
                               ev["cN"][0, :m.ncN_con], q["cxN"], q["A"], q["B"], ev["gap"],
                               pattern=self._ab_pattern)
            info["rank_deficient_nodes"] = float(proj.rank_deficient)
        while True:
            if lq is not None:
                bw = lq.backward(ev["gap"], self.mu, proj, box)
            else:
                bw = self._backward(q["A"], q["B"], q["lx"], q["lu"], q["lxx"], q["luu"],
                                    q["lux"], ev["gap"], q["lxN"], q["lxxN"], self.mu, proj,
                                    box=self._box_du if box else None)
            if bw is not None:
                self._time("backward", time.perf_counter() - t1)
                return q, proj, bw
            if self.mu >= o["mu_max"]:
                info["backward_failed"] = 1.0
                return None
            self.mu = min(max(self.mu * 10, 1e-6), o["mu_max"])

    def _iterate(self, ev: dict[str, Any]) -> tuple[dict[str, Any], dict[str, float]]:
        """One ILQR iteration from (self.X, self.U) with its evaluation ``ev``."""
        m = self.model
        info = self._new_info()
        lq = self._lq_step(ev, info)
        if lq is not None and self._demote_dependent(lq[1]):
            ev = self._evaluate(self.X, self.U)
            if ev is None:  # the same point: the augmented Lagrangian's terms are finite
                raise RuntimeError("ilqr: evaluation not finite after demoting rows")
            info = self._new_info()
            lq = self._lq_step(ev, info)
        if lq is None:
            return ev, info
        q, proj, bw = lq
        if self.x_init is not None:
            dx0 = ev["d0"]
        else:
            S0 = bw.S[0] + 1e-9 * np.eye(m.ndx)
            dx0 = -np.linalg.solve(S0, bw.s[0])
        return self._step(ev, q, proj, bw, dx0, info)

    def _step(self, ev: dict[str, Any], q: dict[str, np.ndarray], proj, bw, dx0: np.ndarray,
              info: dict[str, float]) -> tuple[dict[str, Any], dict[str, float]]:
        """The rest of an iteration after its backward pass: linear rollout from ``dx0``,
        merit weight, line search, regularisation update."""
        o = self.opts
        t2 = time.perf_counter()
        # the step, the model cost's directional derivative along it (the gaps shrink
        # linearly) and the largest multiplier estimate (costates and, with a projection, the
        # projected rows' multipliers), which the l1 merit weight stays above
        if self._lq is not None:
            dX, dU, (slope, lam_max, dx_max, du_max) = self._lq.rollout(
                ev["gap"], bw, dx0, proj, self._box is not None)
        else:
            dX, dU = self._rollout(q["A"], q["B"], ev["gap"], bw, dx0,
                                   box=None if self._box is None else self._box_du)
            slope, lam_max, dx_max, du_max = self._step_stats(
                q["lx"], q["lu"], q["lxN"], bw.s, bw.S, bw.Qu, bw.Quu, bw.Qux, dX, dU,
                None if proj is None else proj.pinv)
        self._gains = bw.K
        # the merit weight only grows within a call, except with the box: its clamped
        # policy's costates swing with the active set (a pendulum with u >= -3 over an
        # unstable stretch: |S| ~ 5e7 at one iteration, a weight of 1e6 kept after it and
        # every later step rejected; following the estimate it converges, 217 iterations)
        self._nu = max(1.5 * lam_max, 1.0) if self._box is not None else max(
            self._nu, 1.5 * lam_max, 1.0)
        nu = self._nu
        merit0 = self._merit(ev, nu)
        deriv = slope - nu * (ev["gap_l1"] + ev["eq_l1"])
        t3 = time.perf_counter()
        alpha, best = 1.0, None
        for _ in range(max(1, o["line_search_steps"])):
            Xt = self._retract(self.X, dX, alpha)
            Ut = self.U + alpha * dU
            evt = self._evaluate(Xt, Ut)
            if evt is not None and not o["line_search"]:
                best = (Xt, Ut, evt)
                break
            if evt is not None:
                mt = self._merit(evt, nu)
                if mt <= merit0 + 1e-4 * alpha * min(deriv, 0.0) or (
                        deriv >= 0 and mt < merit0):
                    best = (Xt, Ut, evt)
                    break
            alpha *= 0.5
        t4 = time.perf_counter()
        if best is None:
            self.mu = min(max(self.mu * 10, 1e-6), o["mu_max"])
            info.update(expected=deriv)
        else:
            self.X, self.U, ev = best
            self.mu = max(self.mu / 10, o["mu_min"])
            info.update(alpha=alpha, accepted=1.0, expected=deriv)
        info["step_norm"] = alpha * (dx_max + du_max)
        self._time("rollout", t3 - t2)
        self._time("line_search", t4 - t3)
        return ev, info

    def _update_multipliers(self, ev: dict[str, Any], rho_factor: float) -> None:
        changed = self._al.update(ev["c"], rho_factor, self.opts["rho_max"])
        changed |= self._alN.update(ev["cN"], rho_factor, self.opts["rho_max"])
        if changed:
            self._refresh_al(ev)

    def _refresh_al(self, ev: dict[str, Any]) -> None:
        """``ev['al']`` again after the rows' multipliers or penalties changed."""
        ev["al"] = self._al.value(ev["c"]) + self._alN.value(ev["cN"])

    def _begin_call(self) -> dict[str, Any] | None:
        """What :meth:`solve` and :meth:`prepare` start with: fresh timings and merit
        weight, no pending preparation, the problem read, the warm start evaluated (None
        if not finite)."""
        self.timings = {}
        self._nu = 0.0
        self._prepared = None
        # 'auto': a converging call after one that went on with the box starts with it (a
        # re-solve from that call's optimum took the 20 augmented-Lagrangian iterations again,
        # moving away and back: 23 iterations against 1), if it starts where that call
        # ended: from a cold guess the box diverges (a cart-pole solved in 78 iterations
        # from its guess ended at max_iter, 4x the cost, re-solved from the same guess)
        self._auto_box = (not self.opts["rti"] and self._auto_applies()
                          and self._starts_where_the_box_ended())
        self._box_from = 0 if self._auto_box else None
        if self._shifted and not self.opts["rti"]:
            # a converging solve of a shifted (receding) problem starts from the initial
            # penalties: those its predecessor raised made a unicycle-around-an-obstacle MPC
            # end 4 of 12 ticks at max_iter (a fresh solver from the same guess: 14-19
            # iterations); now 0 of 12, 15-136. A plain re-solve keeps them (after a bound
            # change, a cart-pole with them reset ended at 1.1e-6 violation, max_iter)
            self._al.reset_penalties()
            self._alN.reset_penalties()
        relax = not self._shifted and not self.opts["rti"]
        self._shifted = False
        self._gather()
        ev = self._evaluate(self.X, self.U)
        if relax and ev is not None:
            # a plain re-solve keeps the penalties of the rows it needs (above), not those of
            # rows idle at the warm start (AugmentedLagrangian.relax_idle_penalties)
            if (self._al.relax_idle_penalties(ev["c"])
                    | self._alN.relax_idle_penalties(ev["cN"])):
                self._refresh_al(ev)
        return ev

    def _singles_per_node(self) -> np.ndarray:
        """The single variables once per stage node, (ns, N): the mapped stage functions
        take one column per node (a view, no copy)."""
        return np.broadcast_to(self.S, (self.S.shape[0], self.model.n_nodes))

    def _not_finite_status(self) -> str:
        """Why the evaluation at the warm start is not finite, as far as the data say."""
        if not (np.isfinite(self.X).all() and np.isfinite(self.U).all()):
            return "initial guess not finite"
        if not (np.isfinite(self.P).all() and np.isfinite(self.S).all()):
            return "parameters not finite"
        return "not finite at the initial guess (a function of the problem gave NaN/inf)"

    def _time(self, phase: str, seconds: float) -> None:
        self.timings[phase] = self.timings.get(phase, 0.0) + seconds

    def _new_info(self) -> dict[str, float]:
        """An iteration's info before its step (no step taken yet)."""
        return {"mu": self.mu, "alpha": 0.0, "accepted": 0.0}

    @staticmethod
    def _record(it: int, ev: dict[str, Any], info: dict[str, float]) -> dict[str, float]:
        """The history entry (and callback argument) of iteration ``it``."""
        return {"iteration": it, "cost": ev["cost"], "merit": ev["cost"] + ev["al"],
                "violation": ev["viol"], **info}

    def _rti_success(self, ev: dict[str, Any]) -> bool:
        """The real-time criterion: finite cost, violation within max(tol_constraint, 1e-3)."""
        return bool(ev["viol"] <= max(self.opts["tol_constraint"], 1e-3)
                    and np.isfinite(ev["cost"]))

    def _solve(self) -> bool:
        o = self.opts
        t_start = time.perf_counter()
        ev = self._begin_call()
        if ev is None:
            self._failed_call(self._not_finite_status(), t_start)
            self._publish(ev)
            return False
        rti = bool(o["rti"])
        n_iter = int(o["iterations_per_call"]) if rti else int(o["max_iter"])
        history, status, converged = [], "max_iter reached", False
        it = 0
        t_iter = time.perf_counter()  # start of the current iteration
        inner = 0  # iterations since the last multiplier update
        stepped = False  # whether the last iteration computed a step
        for it in range(1, n_iter + 1):
            ev, info = self._iterate(ev)
            # a step of the regularised model understates the gradient by ~mu where mu
            # dominates the Hessian: both measures are scaled back (a pendulum whose steps
            # were rejected until mu reached 1e6 was called converged 3 % above the optimum)
            damping = max(1.0, self.mu)
            # no step computed (the linearisation not finite, no positive-definite Q_uu): the
            # point is not known to be stationary (a NaN derivative at a feasible guess was
            # called converged there, unmoved)
            stepped = "expected" in info
            stationary = stepped and (abs(info["expected"]) * damping
                                      <= o["tol"] * (1.0 + ev["cost"])
                                      or info.get("step_norm", 1.0) * damping < 1e-10)
            # multipliers and penalties: a converging solve updates them when the inner
            # (fixed-multiplier) problem is nearly stationary or every `al_max_inner`
            # iterations (updating after every iteration made the penalty ratchet to rho_max
            # and the active set cycle: a pendulum with an active input bound stalled at 0.1
            # violation; the go2 trot took 32 iterations against 14 now). Real-time
            # iterations update them once per call, after the last one: several dual steps on
            # one linearisation of a moving problem overshoot (go2 fell with 2 iterations per
            # tick that way), and keep the penalty fixed: the problem moves between calls, so
            # "not decreasing fast enough" says nothing and the penalty would ratchet up
            # without bound through the shifts, ruining the conditioning of the steps
            inner += 1
            inner_done = inner >= o["al_max_inner"] or stepped and (
                abs(info["expected"]) <= o["al_inner_tol"] * (1.0 + ev["cost"])
                or not info.get("accepted"))
            if (rti and it == n_iter) or (not rti and inner_done):
                inner = 0
                if not rti or o["rti_multiplier_update"]:
                    self._update_multipliers(ev, 1.0 if rti else o["rho_factor"])
            rec = self._record(it, ev, info)
            history.append(rec)
            if o["callback"] is not None:
                o["callback"](rec)
            if o["verbose"]:
                self._progress(f"{it:3d} cost {ev['cost']:.6e} viol {ev['viol']:.2e} alpha "
                               f"{info['alpha']:.3f} mu {self.mu:.1e}")
            reason = self._stop_reason(ev, info, stationary and not rti)
            if reason is not None:
                status, converged = reason, reason == "converged"
                break
            if (not rti and not self._auto_box and it == o["box_after"]
                    and self._auto_applies() and it < n_iter):
                ev = self._switch_to_box(ev)
                self._box_from = it if self._auto_box else None
                if ev is None:
                    status = "not finite after the switch to the box"
                    break
                inner = 0
            # never start an iteration that would not end within the budget (its cost
            # estimated by the last one's)
            now = time.perf_counter()
            if o["time_budget"] is not None and it < n_iter and (
                    2 * now - t_iter - t_start > o["time_budget"]):
                status = "time budget"
                break
            t_iter = now
        if rti:
            # the iterations ran (a failure to compute a step says so, and is no success)
            status = "rti" if status == "max_iter reached" else status
            converged = stepped and self._rti_success(ev)
        elif not converged:
            self._after_failed_solve()
        if not rti:
            self._box_start = (self.X.T.copy(), self.U.T.copy()) if self._auto_box else None
        self.stats.iterations = it
        self.stats.status = status
        self.stats.success = bool(converged)
        self.stats.history = history
        self.stats.time = time.perf_counter() - t_start
        self._publish(ev)
        return bool(converged)

    def _stop_reason(self, ev: dict[str, Any], info: dict[str, Any],
                     stationary: bool) -> str | None:
        """Why the solve stops after this iteration: 'converged', a stationary point that
        is no solution, or a failure to compute a step; None to go on. ``stationary``: the
        iteration's step says so (never in real-time calls, which stop on failures only)."""
        o = self.opts
        if stationary and ev["viol"] <= o["tol_constraint"] and (
                self._complementarity(ev) <= o["tol_complementarity"]):
            return "converged"
        # an infeasible node 0 before the barrier's relaxation: no step moves it (the
        # barrier's status was reported for it, its rows elsewhere relaxed past the bounds)
        if stationary and ev["viol_fixed"] > o["tol_constraint"] and (
                self._al.barrier or ev["viol_free"] <= o["tol_constraint"]):
            return "infeasible: the fixed initial state violates constraints at node 0"
        if stationary and self._al.barrier and ev["viol_eq"] <= o["tol_constraint"]:
            # the barrier problem is solved; what its rows are still past their bounds is
            # its relaxation, which more iterations do not change
            return "stationary: the barrier's optimum, inequality rows past their bounds"
        if info.get("backward_failed"):
            return "regularisation limit reached"
        if info.get("linearisation_failed"):
            return "linearisation not finite (NaN/Inf) at every regularisation"
        return None

    def _after_failed_solve(self) -> None:
        """What a converging solve that failed leaves for the next one: the initial
        penalties (those it ratcheted to rho_max, carried on by shift(), left every later
        solve of a receding horizon ill-conditioned) and no multipliers: a failed solve's
        are no estimate to start from (an infeasible problem's, e.g. 1.7e11 on a final
        equality a state box made unreachable, held the next solve at max_iter after the
        box was relaxed; those below rho_max, kept until session 30, held a random MPC's
        next, feasible tick at max_iter where a fresh solver converged in 28 iterations)."""
        self._al.reset()
        self._alN.reset()

    def _failed_call(self, status: str, t_start: float) -> None:
        """Stats of a call that ran no iteration: none of the previous call's iterations,
        history or time (a failed tick was logged with the last one's)."""
        st = self.stats
        st.success, st.status = False, status
        st.iterations, st.history = 0, []
        st.time = time.perf_counter() - t_start

    def _publish(self, ev) -> None:
        self.stats.cost = ev["cost"] if ev else math.nan
        self.stats.constraint_violation = ev["viol"] if ev else math.nan
        self.stats.extra = {"mu": self.mu, "timings": dict(self.timings)}
        if self._box_from is not None:  # 'auto': the iteration after which the box took over
            self.stats.extra["box_from"] = self._box_from
        # a failed start returns the point it failed at (the guesses), as the NLP solvers
        # do: never an empty or a previous solve's solution
        self._split_solution(self.X.T.copy(), self.U.T.copy(), self.S)

    # ------------------------------------------------------------------ split iteration
    def prepare(self) -> bool:
        """Preparation phase of a real-time iteration split in two (MPC latency).

        Everything of one iteration that does not need the measured initial state: read the
        problem (as :meth:`solve` does; node 0's fixed state is the predicted one), evaluate
        and quadratise at the warm start, project the equality rows, backward pass.
        :meth:`feedback` then ends the iteration from the measured state: rollout of the
        feedback law, line search, multiplier update. Returns False when no step could be
        prepared (warm start or linearisation not finite, regularisation limit);
        ``stats.status`` says why. The setup is a real-time call's whatever the ``rti``
        option (with ``rti`` False it was a converging solve's: its 'auto' box and no
        equality rows projected onto bounded inputs, another plan than the real-time
        iteration the split stands for).
        """
        self.check_problem_unchanged()
        self.prb.check_dt_values()
        t_start = time.perf_counter()
        rti, self.opts["rti"] = self.opts["rti"], True
        try:
            ev = self._begin_call()
            if ev is None:
                self._failed_call(f"prepare: {self._not_finite_status()}", t_start)
                self.stats.cost = self.stats.constraint_violation = math.nan
                return False
            info = self._new_info()
            lq = self._lq_step(ev, info)
        finally:
            self.opts["rti"] = rti
        self._time("prepare", time.perf_counter() - t_start)
        if lq is None:
            self._failed_call("prepare: regularisation limit reached"
                              if info.get("backward_failed") else
                              "prepare: linearisation not finite", t_start)
            self.stats.cost, self.stats.constraint_violation = ev["cost"], ev["viol"]
            return False
        self._prepared = (ev, *lq, info)
        return True

    @property
    def feedback_gains(self) -> np.ndarray:
        """The gains K (N, nu, ndx) of the last step taken (``du = K dx + k``), a copy."""
        return self._gains.copy()

    @property
    def prepared(self) -> bool:
        """Whether a :meth:`prepare` awaits its :meth:`feedback`."""
        return self._prepared is not None

    def feedback(self, x0: np.ndarray) -> bool:
        """Feedback phase: end the prepared iteration from the measured initial state.

        ``x0`` (nx,): the measured state. The rollout of the prepared feedback law from
        ``x0 (-) x0_predicted``, the line search of an iteration and the multiplier update
        of a real-time call: the result is exactly the one-iteration real-time
        :meth:`solve` from the same warm start with node 0 fixed at ``x0``. The solution,
        statistics and the problem's guesses are updated like :meth:`solve` does (node 0's
        bounds in the problem stay what the caller set). Returns whether the result is
        finite with a constraint violation within ``max(tol_constraint, 1e-3)`` (the
        real-time criterion).

        Raises:
            RuntimeError: no :meth:`prepare` awaits its feedback.
            ValueError: ``x0`` is not of shape (nx,) (the preparation stays).
        """
        if self._prepared is None:
            raise RuntimeError("ilqr feedback() needs a successful prepare() first")
        m = self.model
        x0 = np.asarray(x0, dtype=float)
        if x0.size != m.nx:
            raise ValueError(f"ilqr feedback(): x0 of shape {x0.shape}; the state has nx = "
                             f"{m.nx} entries")
        x0 = x0.reshape(m.nx)
        t_start = time.perf_counter()
        ev, q, proj, bw, info = self._prepared
        self._prepared = None
        st = self.stats
        if not np.all(np.isfinite(x0)):
            self._failed_call("feedback: initial state not finite", t_start)
            st.cost = st.constraint_violation = math.nan
            return False
        dx0 = self._difference(self.X[0], x0)[0].reshape(m.ndx).copy()
        # the prepared evaluation, with node 0 now fixed at x0
        self.x_init = x0.copy()
        ev = dict(ev, d0=dx0, gap_l1=ev["gap_l1"] - float(np.sum(np.abs(ev["d0"])))
                  + float(np.sum(np.abs(dx0))),
                  viol=max(ev["viol"], float(np.max(np.abs(dx0)))))
        ev, info = self._step(ev, q, proj, bw, dx0, info)
        self._update_multipliers(ev, 1.0)
        st.iterations, st.history, st.status = 1, [self._record(1, ev, info)], "feedback"
        st.success = self._rti_success(ev)
        self._publish(ev)
        if self.opts["warm_start"]:
            self._write_back()
        self._time("feedback", time.perf_counter() - t_start)
        st.time = self.timings["feedback"]
        st.extra["timings"] = dict(self.timings)
        return st.success

    # ------------------------------------------------------------------ receding horizon
    def _starts_where_the_box_ended(self) -> bool:
        """Whether the problem's guesses are the point the last converging call ended at
        with the box (its solution written back), or that point shifted."""
        if self._box_start is None:
            return False
        X, U = self._box_start
        prb = self.prb
        return (np.array_equal(prb.stacked("state", copy=False), X)
                and np.array_equal(prb.stacked("input", copy=False), U))

    def shift(self) -> None:
        """Shift the problem's guesses/parameters and the AL multipliers one node back."""
        follows = self._starts_where_the_box_ended()
        super().shift()
        if follows:  # the shifted warm start still starts where the box ended
            self._box_start = (self.prb.stacked("state"), self.prb.stacked("input"))
        self._al.shift()
        self._prepared = None
        self._shifted = True

    def reset(self) -> None:
        """A cold start for the next solve, as a fresh solver's: the multipliers
        (:meth:`reset_multipliers`), and what the last solves learned of the problem (the
        'auto' box mode they kept, rows they moved to the augmented Lagrangian)."""
        self.reset_multipliers()
        self._auto_box = False
        self._box_start = None
        self._box_from = None
        self._demoted[:] = False

    def set_option(self, key: str, value: Any) -> None:
        """Change one option between solves (``mu_init`` also restarts the regularisation
        at it: it was taken at the build and at resets only)."""
        super().set_option(key, value)
        if key == "mu_init":
            self.mu = self._mu_init()

    def _mu_init(self) -> float:
        """``mu_init`` within [``mu_min``, ``mu_max``]: a regularisation started outside its
        range ran there (1e3 above mu_max 1: 101 iterations for 86; 1e-12 below mu_min 1e-6
        was taken as is). Clipped, not refused: raising only ``mu_min`` is a choice of the
        range, the default start follows it."""
        o = self.opts
        return min(max(o["mu_init"], o["mu_min"]), o["mu_max"])

    def reset_multipliers(self) -> None:
        """Forget the augmented-Lagrangian state (e.g. after a solver failure)."""
        self._al.reset()
        self._alN.reset()
        self.mu = self._mu_init()
