"""The IPOPT solver on the reference problems: optima, warm starts, receding updates."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pytest

from horizon_mpc.examples import (
    build_cartpole,
    build_double_integrator,
    build_pendulum_min_time,
    double_integrator_optimum,
)
from horizon_mpc.problem import Problem
from horizon_mpc.solvers import make_solver


@pytest.mark.parametrize("method", ["multiple_shooting", "direct_collocation"])
def test_double_integrator_matches_the_exact_discrete_optimum(method):
    # RK4 and collocation are exact for x'' = u with piecewise-constant u, so the discrete
    # optimum has a closed form (see double_integrator_optimum)
    prb, v = build_double_integrator(50, transcription=method)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    u_star, cost = double_integrator_optimum(50)
    np.testing.assert_allclose(solver.solution["u"][0], u_star, atol=1e-6)
    assert solver.stats.cost == pytest.approx(cost, abs=1e-6)


def test_double_integrator_approaches_the_continuous_optimum_at_second_order():
    # continuous optimum: u(t) = 6 - 12 t, cost 12; the discrete cost is 12 / (1 - h^2)
    n = 200
    prb, _ = build_double_integrator(n)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    h = 1.0 / n
    assert abs(solver.stats.cost - 12.0) <= 12.0 * h**2 / (1 - h**2) + 1e-6
    t_mid = (np.arange(n) + 0.5) * h
    np.testing.assert_allclose(solver.solution["u"][0], 6 - 12 * t_mid, atol=12 * h**2 + 1e-6)


def test_solution_shapes_and_stats_are_filled():
    prb, _ = build_double_integrator(10)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    assert solver.solution["x"].shape == (1, 11) and solver.solution["u"].shape == (1, 10)
    s = solver.stats
    assert s.success and s.status == "Solve_Succeeded"
    assert s.iterations >= 1 and s.time > 0 and s.constraint_violation < 1e-9


def test_cartpole_swing_up_reaches_the_upright_goal():
    prb, v = build_cartpole(100)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    q = solver.solution["q"]
    np.testing.assert_allclose(q[:, -1], [0.0, np.pi], atol=1e-8)
    np.testing.assert_allclose(q[:, 0], [0.0, 0.0], atol=1e-8)
    assert solver.stats.constraint_violation <= 1e-8


def test_cartpole_input_bounds_and_cart_limit_are_respected():
    prb, _ = build_cartpole(100, u_max=12.0, cart_limit=0.5)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    u, p = solver.solution["u"], solver.solution["q"][0]
    assert np.max(np.abs(u)) <= 12.0 + 1e-7 and np.max(np.abs(p)) <= 0.5 + 1e-7
    assert np.max(np.abs(u)) > 11.9  # the bound is active (free optimum peaks at ~15 N)


def test_multiple_shooting_and_collocation_agree_within_discretisation_error():
    sols = {}
    for method in ("multiple_shooting", "direct_collocation"):
        prb, _ = build_cartpole(100, transcription=method)
        solver = make_solver("ipopt", prb)
        assert solver.solve()
        sols[method] = (solver.stats.cost, solver.solution["u"][0])
    (c_ms, u_ms), (c_dc, u_dc) = sols.values()
    # RK4 (order 4) vs Legendre collocation of degree 3 (order 6 at the nodes), dt = 0.02
    assert c_dc == pytest.approx(c_ms, rel=1e-4)
    assert np.max(np.abs(u_ms - u_dc)) < 1e-2 * np.max(np.abs(u_ms))


def test_pendulum_minimum_time_with_dt_as_single_variable():
    prb, v = build_pendulum_min_time(50)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    T = 50 * solver.solution["dt"].item()
    assert 2.3 < T < 2.6  # the torque limit (5 < m g l = 9.81 N m) forces a pumping swing
    assert np.max(np.abs(solver.solution["tau"])) == pytest.approx(5.0, abs=1e-6)
    assert solver.stats.constraint_violation <= 1e-8


def test_dt_as_parameter_changes_the_horizon_without_rebuild():
    n = 20
    prb = Problem(n)
    x = prb.create_state_variable("x", 1)
    v = prb.create_state_variable("v", 1)
    u = prb.create_input_variable("u", 1)
    dt = prb.create_parameter("dt", 1)
    prb.set_dynamics(cs.vertcat(v, u))
    prb.set_dt(dt)
    x.set_bounds(0, 0, nodes=0)
    v.set_bounds(0, 0, nodes=0)
    prb.create_final_constraint("arrive", cs.vertcat(x - 1, v))
    prb.create_cost("effort", u * cs.sqrt(dt))  # sum dt u^2
    solver = make_solver("ipopt", prb)
    for T in (1.0, 2.0):
        dt.assign(T / n)
        assert solver.solve()
        _, cost = double_integrator_optimum(n, duration=T)
        assert solver.stats.cost == pytest.approx(cost, rel=1e-8)


def test_general_cost_is_accepted():
    prb, v = build_double_integrator(20)
    prb.create_general_cost("quartic", 1e-3 * v["u"][0] ** 4)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    _, quadratic_only = double_integrator_optimum(20)
    assert solver.stats.cost > quadratic_only


def shift_and_fix_initial_state(solver, v) -> None:
    """Receding horizon: shift, then pin node 0 to the shifted guess (the 'measured' state)."""
    solver.shift()
    for name in ("q", "v"):
        x0 = v[name].initial_guess[:, 0]
        v[name].set_bounds(x0, x0, nodes=0)


def test_warm_resolve_after_shift_needs_far_fewer_iterations():
    prb, v = build_cartpole(100)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    cold = solver.stats.iterations
    shift_and_fix_initial_state(solver, v)
    assert solver.solve()
    assert solver.stats.extra["warm"]
    assert solver.stats.iterations <= cold // 2, (solver.stats.iterations, cold)


def test_shift_moves_the_multipliers_one_node_back():
    prb, v = build_cartpole(20)
    solver = make_solver("ipopt", prb)
    solver.solve()
    lam_g = solver.lam_g.copy()
    solver.shift()
    dyn = solver.transcription.g_blocks[0]
    before = lam_g[dyn.start:dyn.stop].reshape(dyn.rows, dyn.cols, order="F")
    after = solver.lam_g[dyn.start:dyn.stop].reshape(dyn.rows, dyn.cols, order="F")
    np.testing.assert_array_equal(after[:, :-1], before[:, 1:])


def test_node_sets_weights_and_bounds_change_without_rebuild():
    prb, v = build_double_integrator(20)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    nlp, instance = solver.transcription.nlp, solver._solvers[False]
    _, base_cost = double_integrator_optimum(20)
    # weight x4 -> cost x4, same input
    prb.get_term("effort").set_weight(4 * 0.05)
    solver.reset()
    assert solver.solve()
    assert solver.stats.cost == pytest.approx(4 * base_cost, rel=1e-8)
    # arrive earlier: move the constraint to node 10 (half the time: cost x8)
    prb.get_term("arrive").set_nodes(10)
    prb.get_term("effort").set_weight(0.05)
    prb.get_term("effort").set_nodes(range(10))
    solver.reset()
    assert solver.solve()
    _, half = double_integrator_optimum(10, duration=0.5)
    assert solver.stats.cost == pytest.approx(half, rel=1e-8)
    # an input bound becomes active
    v["u"].set_bounds(-20.0, 20.0)  # unconstrained peak: 23; bang-bang reach: 1.25 > 1
    solver.reset()
    assert solver.solve()
    assert np.max(np.abs(solver.solution["u"])) == pytest.approx(20.0, abs=1e-6)
    assert solver.transcription.nlp is nlp and solver._solvers[False] is instance


def test_options_pass_through_and_friendly_aliases():
    prb, _ = build_cartpole(50)
    solver = make_solver("ipopt", prb, {"max_iter": 2, "ipopt.mu_strategy": "monotone"})
    assert not solver.solve()
    assert solver.stats.status == "Maximum_Iterations_Exceeded"
    assert solver.stats.iterations == 2
    solver.set_option("max_iter", 200)
    solver.reset()
    assert solver.solve()


def test_sx_and_mx_graphs_give_the_same_solution():
    costs = []
    for sym in ("SX", "MX"):
        prb, _ = build_cartpole(40)
        solver = make_solver("ipopt", prb, {"sym": sym})
        assert solver.solve()
        costs.append(solver.stats.cost)
    assert costs[0] == pytest.approx(costs[1], rel=1e-9)


def test_active_constraint_rows_give_a_smaller_nlp_with_the_same_optimum():
    full = make_solver("ipopt", build_cartpole(50)[0])
    prb, _ = build_cartpole(50)
    trimmed = make_solver("ipopt", prb, {"constraint_rows": "active"})
    assert trimmed.transcription.ng == full.transcription.ng - 4 * 50  # goal rows on node N
    assert full.solve() and trimmed.solve()
    assert trimmed.stats.cost == pytest.approx(full.stats.cost, rel=1e-9)
    prb.get_term("goal_q").set_nodes(40)
    with pytest.raises(ValueError, match=r"'goal_q' is active on nodes \[40\] that have no rows"):
        trimmed.solve()


def test_a_nan_parameter_reports_nan_cost_and_violation_not_zero():
    prb = Problem(5)
    x = prb.create_state_variable("x", 1)
    u = prb.create_input_variable("u", 1)
    k = prb.create_parameter("k", 1)
    k.assign(np.nan)
    prb.set_dynamics(u)
    prb.set_dt(0.1)
    x.set_bounds(0.0, 0.0, nodes=0)
    prb.create_cost("effort", k * u)
    solver = make_solver("ipopt", prb)
    assert solver.solve() is False
    assert solver.stats.status == "Invalid_Number_Detected"
    assert np.isnan(solver.stats.cost) and np.isnan(solver.stats.constraint_violation)
