"""The ILQR's view of a Problem: stacked stage and terminal functions, mapped over nodes.

Every quantity the ILQR needs at a node is produced by ONE compiled call mapped over all
nodes (Python -> CasADi calls cost ~40 us each, so never one call per node):

* ``values``  (x, u, s, p, x_next) -> (gap, r, c): the dynamics defect
  ``F(x, u) (-) x_next`` in the tangent space, the stacked cost residuals and constraints;
* ``quadratise`` (x, u, s, p, w_r, w_c, t_c) -> (A, B, lx, lu, lxx, luu, lux, cx, cu):
  the dynamics Jacobians in the tangent space, the Gauss-Newton model of
  ``sum_i w_r,i r_i^2 + sum_j w_c,j (c_j - t_c,j)^2`` (the augmented-Lagrangian rows of
  the constraints enter through ``w_c``/``t_c``, chosen numerically by the solver) and the
  Jacobians of the problem's constraint rows (for the exact equality projection).

Jacobians are taken with respect to ``dx`` in ``x (+) dx`` at ``dx = 0``, so states on a
manifold (quaternions) are handled in their tangent space.

Constraint rows: the problem's constraints valid on the stage (or terminal) node, then
the state bounds (nx rows, on stage and terminal nodes) and the input bounds (nu rows, stage).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import casadi as cs
import numpy as np

from horizon_mpc.problem import Problem
from horizon_mpc.problem.terms import Constraint, Cost, GeneralCost

__all__ = ["StageModel", "build_stage_model"]

log = logging.getLogger(__name__)


@dataclass
class StageModel:
    """Mapped functions and row layouts of a problem for the ILQR.

    Row layouts (``*_rows``) list ``(term name, start, stop)`` in the stacked vectors.
    """

    nx: int
    ndx: int
    nu: int
    n_nodes: int
    stage_costs: list[Cost]
    term_costs: list[Cost]
    stage_cons: list[Constraint]
    term_cons: list[Constraint]
    nr: int
    nrN: int
    nc: int
    ncN: int
    values: cs.Function  # mapped over N stage nodes
    quadratise: cs.Function  # mapped over N stage nodes (AL terms of rows al_rows only)
    nc_con: int  # rows of the problem's constraints in the stage layout (before the bounds)
    ncN_con: int  # rows of the problem's constraints in the terminal layout
    con_reach: np.ndarray  # (nc_con,) rows the input of their node (or of the node before) moves
    conN_reach: np.ndarray  # (ncN_con,) terminal rows the input of node N-1 moves
    values_term: cs.Function
    quadratise_term: cs.Function
    integrate: cs.Function  # (x, dx) -> x, mapped over N+1 nodes
    difference: cs.Function  # (x0, x1) -> dx, mapped over N+1 nodes
    # (ndx, ndx + nu) structural nonzeros of [A | B] (the same at every node): the rest of
    # the dense outputs A and B is exactly zero
    ab_pattern: np.ndarray | None = None
    # (nc,) stage rows whose augmented-Lagrangian Gauss-Newton terms ``quadratise`` forms;
    # the others (equalities the projection handles) are left out: a third fewer operations
    # on the go2 walking problem. ``quadratise_full()`` builds the one with every row.
    al_rows: np.ndarray | None = None
    quadratise_full: Callable[[], cs.Function] | None = None


def check_supported(prb: Problem) -> None:
    """ValueError naming what of ``prb`` the ILQR cannot honour (general costs, offset
    terms, free single variables, collocation)."""
    for term in [*prb.constraints.values(), *prb.costs.values()]:
        if isinstance(term, GeneralCost):
            raise ValueError(f"ilqr needs residual costs (Gauss-Newton); {term.name!r} is a "
                             "general cost: write it as create_cost(name, residual) or use "
                             "the ipopt solver")
        if term.offsets:
            raise ValueError(f"ilqr does not support terms with offset variables "
                             f"({term.kind} {term.name!r} uses offsets {term.offsets}); use "
                             "ipopt or gnsqp, or add the previous value to the state")
    for v in prb.singles:
        if not np.array_equal(v.lower_bounds, v.upper_bounds):
            raise ValueError(f"ilqr cannot optimise single variable {v.name!r} (e.g. a free "
                             "duration): fix it with equal bounds or use ipopt/gnsqp")
    if prb.transcription != "multiple_shooting":
        raise ValueError(f"ilqr is a shooting method; the problem is transcribed with "
                         f"{prb.transcription!r}: call prb.transcribe('multiple_shooting')")


def _jac(expr: cs.SX, sym: cs.SX) -> cs.SX:
    return cs.jacobian(expr, sym) if sym.numel() else cs.SX(expr.numel(), 0)


def _gn(res, jx, ju, w, t):
    """Gauss-Newton terms of sum w (res - t)^2 (gradient and Hessian blocks)."""
    e = w * (res - t)
    wjx = cs.mtimes(cs.diag(w), jx) if res.numel() else jx
    lx = 2 * cs.mtimes(jx.T, e)
    lxx = 2 * cs.mtimes(jx.T, wjx)
    if ju is None:
        return lx, lxx
    wju = cs.mtimes(cs.diag(w), ju) if res.numel() else ju
    return lx, 2 * cs.mtimes(ju.T, e), lxx, 2 * cs.mtimes(ju.T, wju), 2 * cs.mtimes(ju.T, wjx)


def _structure(expr: cs.SX) -> np.ndarray:
    """Boolean (rows, cols) mask of the structural nonzeros of a matrix expression."""
    mask = np.zeros(expr.shape, bool)
    rows, cols = expr.sparsity().get_triplet()
    mask[np.asarray(rows, int), np.asarray(cols, int)] = True
    return mask


def _input_reach(cons, x, u, s, p, x_next, terminal: bool = False) -> np.ndarray:
    """Rows an input can move in one step (structurally): a row on (x, u) through u, a
    state-only row through the dynamics ``x_next = F(x, u)`` (relative degree one)."""
    rows = []
    for con in cons:
        if con.uses_input and not terminal:
            expr = con.function(x, u, s, p)
        else:
            expr = con.function(x_next, u, s, p)
        rows.append(_structure(_jac(expr, u)).any(axis=1))
    return np.concatenate(rows) if rows else np.zeros(0, bool)


def _compile(fn: cs.Function, enabled: bool) -> cs.Function:
    if not enabled:
        return fn
    try:
        from horizon_mpc.codegen import compile_function
    except ImportError:  # pragma: no cover - codegen module absent
        log.warning("horizon_mpc.codegen not available: running %s in the CasADi VM", fn.name())
        return fn
    return compile_function(fn)


def build_stage_model(prb: Problem, codegen: bool = True,
                      projected_equalities: bool = False) -> StageModel:
    """Build the mapped value and quadratisation functions of ``prb`` (finalized).

    ``projected_equalities``: the solver projects equality rows out (its ``equality``
    option ``'projection'``): the rows of constraints that are equalities now and that an
    input moves in one step get no augmented-Lagrangian terms in ``quadratise`` (see
    ``StageModel.al_rows``; the solver switches to ``quadratise_full()`` if one of them
    ever needs them, e.g. after its bounds become an inequality).

    Raises:
        ValueError: the problem uses something the ILQR cannot honour (general costs,
            offset terms, free single variables, collocation).
    """
    check_supported(prb)
    prb.finalize()
    N = prb.n_nodes
    nx, ndx, nu, ns, npar = prb.nx, prb.ndx, prb.nu, prb.ns, prb.np_
    x, u = cs.SX.sym("x", nx), cs.SX.sym("u", nu)
    s, p = cs.SX.sym("s", ns), cs.SX.sym("p", npar)
    dx = cs.SX.sym("dx", ndx)
    xt = prb.integrate_expr(x, dx)
    stage_costs = [c for c in prb.costs.values() if c.valid_nodes.min() < N]
    term_costs = [c for c in prb.costs.values() if not c.uses_input and c.valid_nodes.max() == N]
    stage_cons = [c for c in prb.constraints.values() if c.valid_nodes.min() < N]
    term_cons = [c for c in prb.constraints.values()
                 if not c.uses_input and c.valid_nodes.max() == N]

    def stack(terms, xx, uu):
        parts = [t.function(xx, uu, s, p) for t in terms]
        return cs.vertcat(*parts) if parts else cs.SX(0, 1)

    def at0(e):
        return cs.substitute(e, dx, cs.DM.zeros(ndx))

    # ---- stage: dynamics, residuals, constraints (+ state and input bounds)
    F = prb.discrete_dynamics()
    x_next_nom = F(x, u, s, p)
    x_next = F(xt, u, s, p)
    # Jacobians in the tangent space at F(x, u): differentiate with the reference held fixed
    x_ref = cs.SX.sym("x_ref", nx)
    f_dx = prb.difference_expr(x_ref, x_next)
    A = cs.substitute(at0(_jac(f_dx, dx)), x_ref, x_next_nom)
    B = cs.substitute(at0(_jac(f_dx, u)), x_ref, x_next_nom)
    ab_pattern = np.hstack((_structure(A), _structure(B)))
    r = stack(stage_costs, xt, u)
    c = cs.vertcat(stack(stage_cons, xt, u), xt, u)
    rx, ru = at0(_jac(r, dx)), at0(_jac(r, u))
    cx, cu = at0(_jac(c, dx)), at0(_jac(c, u))
    nc_con = c.numel() - nx - nu
    con_reach = _input_reach(stage_cons, x, u, s, p, x_next_nom)
    r0, c0 = at0(r), at0(c)
    nr, nc = r.numel(), c.numel()
    w_r, w_c, t_c = cs.SX.sym("w_r", nr), cs.SX.sym("w_c", nc), cs.SX.sym("t_c", nc)
    lx1, lu1, lxx1, luu1, lux1 = _gn(r0, rx, ru, w_r, cs.DM.zeros(nr))
    al_rows = np.ones(nc, bool)
    if projected_equalities:
        eq = np.concatenate([np.full(con.dim, con.is_equality) for con in stage_cons]
                            or [np.zeros(0, bool)])
        al_rows[:nc_con] = ~(eq & con_reach)
    d = cs.densify
    x_nxt = cs.SX.sym("x_next", nx)
    gap = prb.difference_expr(x_nxt, x_next_nom)  # F(x, u) (-) x_next
    values = cs.Function("ilqr_values", [x, u, s, p, x_nxt], [d(gap), d(r0), d(c0)],
                         ["x", "u", "s", "p", "x_next"], ["gap", "r", "c"])
    def quadratisation(rows: np.ndarray) -> cs.Function:
        """The stage quadratisation with the AL terms of ``rows`` (same signature always)."""
        k = [int(i) for i in np.flatnonzero(rows)]
        lx2, lu2, lxx2, luu2, lux2 = _gn(c0[k], cx[k, :], cu[k, :], w_c[k], t_c[k])
        return cs.Function(
            "ilqr_quadratise", [x, u, s, p, w_r, w_c, t_c],
            [d(A), d(B), d(lx1 + lx2), d(lu1 + lu2), d(lxx1 + lxx2), d(luu1 + luu2),
             d(lux1 + lux2), d(cx[:nc_con, :]), d(cu[:nc_con, :])],
            ["x", "u", "s", "p", "w_r", "w_c", "t_c"],
            ["A", "B", "lx", "lu", "lxx", "luu", "lux", "cx", "cu"])

    def quadratise_full() -> cs.Function:
        return _compile(quadratisation(np.ones(nc, bool)).map(N, "serial"), codegen)

    # ---- terminal: residuals and constraints on x only (+ state bounds)
    uN = cs.SX(0, 1)
    rN = stack(term_costs, xt, cs.DM.zeros(nu) if nu else uN)
    cN = cs.vertcat(stack(term_cons, xt, cs.DM.zeros(nu) if nu else uN), xt)
    rNx, cNx = at0(_jac(rN, dx)), at0(_jac(cN, dx))
    rN0, cN0 = at0(rN), at0(cN)
    nrN, ncN = rN.numel(), cN.numel()
    ncN_con = ncN - nx
    conN_reach = _input_reach(term_cons, x, u, s, p, x_next_nom, terminal=True)
    w_rN, w_cN, t_cN = cs.SX.sym("w_r", nrN), cs.SX.sym("w_c", ncN), cs.SX.sym("t_c", ncN)
    lxN1, lxxN1 = _gn(rN0, rNx, None, w_rN, cs.DM.zeros(nrN))
    lxN2, lxxN2 = _gn(cN0, cNx, None, w_cN, t_cN)
    values_term = cs.Function("ilqr_values_term", [x, s, p], [d(rN0), d(cN0)],
                              ["x", "s", "p"], ["r", "c"])
    quad_term = cs.Function("ilqr_quadratise_term", [x, s, p, w_rN, w_cN, t_cN],
                            [d(lxN1 + lxN2), d(lxxN1 + lxxN2), d(cNx[:ncN_con, :])],
                            ["x", "s", "p", "w_r", "w_c", "t_c"], ["lx", "lxx", "cx"])

    integ, diff = prb.state_integrate(), prb.state_difference()
    log.info("ilqr stage model: nx=%d ndx=%d nu=%d N=%d, %d residual rows, %d constraint rows "
             "(terminal %d/%d)", nx, ndx, nu, N, nr, nc, nrN, ncN)
    return StageModel(
        nx=nx, ndx=ndx, nu=nu, n_nodes=N,
        stage_costs=stage_costs, term_costs=term_costs,
        stage_cons=stage_cons, term_cons=term_cons,
        nr=nr, nrN=nrN, nc=nc, ncN=ncN, nc_con=nc_con, ncN_con=ncN_con,
        con_reach=con_reach, conN_reach=conN_reach,
        values=_compile(values.map(N, "serial"), codegen),
        quadratise=_compile(quadratisation(al_rows).map(N, "serial"), codegen),
        values_term=_compile(values_term, codegen),
        quadratise_term=_compile(quad_term, codegen),
        integrate=_compile(integ.map(N + 1, "serial"), codegen),  # each line-search step
        difference=diff.map(N + 1, "serial"),
        al_rows=al_rows,
        quadratise_full=quadratise_full,
        ab_pattern=ab_pattern,
    )
