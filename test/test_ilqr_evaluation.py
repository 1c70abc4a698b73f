"""The compiled evaluation and quadratisation (evaluation.c: the generated functions called
from C, the merit terms and the augmented-Lagrangian rows in one call each) return what
the numpy evaluation and quadratisation of the ILQR do."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pytest
from ocps import pendulum_swing_up, trotting_go2_mpc

from horizon_mpc import make_solver
from horizon_mpc.codegen import codegen_enabled
from horizon_mpc.solvers.ilqr import riccati_c
from horizon_mpc.solvers.ilqr.evaluation import GeneratedFunction

pytestmark = pytest.mark.skipif(not (codegen_enabled() and riccati_c.available()),
                                reason="needs code generation and the compiled library")


def _both(solver, X, U):
    """(compiled, numpy) evaluations of ``solver`` at (X, U)."""
    compiled = solver._compiled_eval
    assert compiled is not None
    a = solver._evaluate(X, U)
    solver._compiled_eval = None
    try:
        b = solver._evaluate(X, U)
    finally:
        solver._compiled_eval = compiled
    return a, b


def _both_quadratised(solver, X, U):
    """(compiled, numpy) quadratisations of ``solver`` at (X, U), copied."""
    compiled = solver._compiled_eval
    ev = solver._evaluate(X, U)
    out = []
    for use in (compiled, None):
        solver._compiled_eval = use
        try:
            q = solver._quadratise(X, U, ev)
        finally:
            solver._compiled_eval = compiled
        out.append(None if q is None else {k: np.array(v) for k, v in q.items()})
    return out


def _assert_same(a, b):
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_allclose(a[key], b[key], rtol=1e-12, atol=1e-12, err_msg=key)


def _perturbed(solver, seed=0):
    rng = np.random.default_rng(seed)
    solver._begin_call()
    return (solver.X + 0.05 * rng.standard_normal(solver.X.shape),
            solver.U + 0.5 * rng.standard_normal(solver.U.shape))


@pytest.mark.parametrize("mode", ["lagrangian", "barrier"])
def test_the_compiled_evaluation_matches_numpy_on_a_bounded_ocp(mode):
    prb = pendulum_swing_up(u_max=3.0, n_nodes=20)
    solver = make_solver("ilqr", prb, {"inequality": mode, "max_iter": 4})
    solver.solve()  # multipliers and penalties away from their initial values
    X, U = _perturbed(solver)
    a, b = _both(solver, X, U)
    _assert_same(a, b)
    assert a["al"] != 0.0 and a["viol"] > 0.0  # the bound and final rows are in play
    qa, qb = _both_quadratised(solver, X, U)
    _assert_same(qa, qb)
    assert np.any(qa["luu"] != 0.0)


def test_the_compiled_evaluation_matches_numpy_with_a_free_initial_state():
    prb = pendulum_swing_up(u_max=3.0, n_nodes=10)
    prb.get_variable("x").set_bounds([-1.0, -1.0], [1.0, 1.0], nodes=0)
    solver = make_solver("ilqr", prb, {"max_iter": 2})
    solver.solve()
    X, U = _perturbed(solver, seed=1)
    a, b = _both(solver, X, U)
    assert solver.x_init is None
    _assert_same(a, b)
    assert not a["d0"].any()


def test_the_compiled_evaluation_matches_numpy_on_the_walking_problem():
    solver = trotting_go2_mpc(15).solver
    X, U = _perturbed(solver, seed=2)
    a, b = _both(solver, X, U)
    assert solver._layout.any
    _assert_same(a, b)
    assert a["eq_l1"] > 0.0
    qa, qb = _both_quadratised(solver, X, U)
    assert {"cx", "cu", "cxN"} <= qa.keys()
    _assert_same(qa, qb)
    # a projected row's bounds made an inequality: the full quadratisation takes over
    row = int(np.flatnonzero(solver._eq_rows.any(axis=0))[0])
    lb = np.full(solver.model.nc_con, -np.inf)
    lb[row] = -1.0
    solver._choose_quadratisation(np.tile(lb, (solver.model.n_nodes, 1)),
                                  np.full((solver.model.n_nodes, solver.model.nc_con), np.inf))
    assert solver._quadratise_fn is solver._quadratise_all
    qa, qb = _both_quadratised(solver, X, U)
    _assert_same(qa, qb)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_value_that_is_not_finite_fails_the_compiled_evaluation(bad):
    prb = pendulum_swing_up(u_max=3.0, n_nodes=10)
    solver = make_solver("ilqr", prb, {"max_iter": 1})
    solver.solve()
    X, U = _perturbed(solver)
    U[4, 0] = bad
    a, b = _both(solver, X, U)
    assert a is None and b is None


def test_a_quadratisation_that_is_not_finite_is_refused_by_both():
    # sqrt(x) has an infinite derivative at 0: finite values, an infinite Jacobian
    prb = pendulum_swing_up(u_max=3.0, n_nodes=8)
    x = prb.get_variable("x")
    prb.create_cost("root", cs.sqrt(x[0]), weight=1.0)
    solver = make_solver("ilqr", prb, {"max_iter": 1})
    solver._begin_call()
    X, U = solver.X.copy(), solver.U.copy()
    X[:, 0] = 1.0
    X[3, 0] = 0.0
    qa, qb = _both_quadratised(solver, X, U)
    assert qa is None and qb is None


def test_only_functions_of_the_code_generator_bind():
    x = cs.SX.sym("x")
    with pytest.raises(RuntimeError, match="not a compiled function"):
        GeneratedFunction.bind(cs.Function("f", [x], [2 * x]))
