"""The Gauss-Newton SQP: same optima as IPOPT on the reference problems, warm starts."""

from __future__ import annotations

import numpy as np
import pytest
from ocps import double_integrator_with_a_nan_derivative_at_rest

from horizon_mpc.examples import (
    build_cartpole,
    build_double_integrator,
    build_pendulum_min_time,
    double_integrator_optimum,
)
from horizon_mpc.solvers import make_solver


def solve_both(build, **gn_opts):
    """Solve fresh copies of a problem with ipopt and gnsqp from the same initial guess."""
    out = []
    for name, opts in (("ipopt", {}), ("gnsqp", {"max_iter": 300, **gn_opts})):
        prb, _ = build()
        solver = make_solver(name, prb, opts)
        assert solver.solve(), f"{name}: {solver.stats.status}"
        out.append(solver)
    return out


def test_double_integrator_is_solved_in_one_step():
    # a convex QP: the Gauss-Newton model is exact
    prb, _ = build_double_integrator(50)
    solver = make_solver("gnsqp", prb)
    assert solver.solve()
    u_star, cost = double_integrator_optimum(50)
    np.testing.assert_allclose(solver.solution["u"][0], u_star, atol=1e-6)
    assert solver.stats.cost == pytest.approx(cost, abs=1e-6)
    assert solver.stats.iterations == 1


def test_cartpole_swing_up_matches_ipopt():
    ip, gn = solve_both(lambda: build_cartpole(100))
    assert gn.stats.cost == pytest.approx(ip.stats.cost, rel=1e-4)
    assert gn.stats.constraint_violation <= 1e-6
    np.testing.assert_allclose(gn.solution["u"], ip.solution["u"], atol=1e-3)


def test_cartpole_with_input_bounds_and_cart_limit_matches_ipopt():
    ip, gn = solve_both(lambda: build_cartpole(100, u_max=12.0, cart_limit=0.5))
    assert gn.stats.cost == pytest.approx(ip.stats.cost, rel=1e-4)
    assert gn.stats.constraint_violation <= 1e-6
    assert np.max(np.abs(gn.solution["u"])) <= 12.0 + 1e-9


def test_pendulum_minimum_time_matches_ipopt():
    ip, gn = solve_both(lambda: build_pendulum_min_time(50))
    assert gn.stats.cost == pytest.approx(ip.stats.cost, rel=1e-4)
    assert gn.solution["dt"].item() == pytest.approx(ip.solution["dt"].item(), rel=1e-4)
    assert gn.stats.constraint_violation <= 1e-6


def test_cartpole_collocation_matches_ipopt():
    ip, gn = solve_both(lambda: build_cartpole(100, transcription="direct_collocation"))
    assert gn.stats.cost == pytest.approx(ip.stats.cost, rel=1e-4)
    assert gn.stats.constraint_violation <= 1e-6


@pytest.mark.parametrize("qp_solver", ["qrqp", "proxqp", "osqp"])
def test_qp_solvers_are_selectable(qp_solver):
    prb, _ = build_cartpole(30)
    solver = make_solver("gnsqp", prb, {"qp_solver": qp_solver, "max_iter": 300})
    assert solver.solve(), solver.stats.status
    assert solver.stats.extra["qp_solver"] == qp_solver
    ip = make_solver("ipopt", build_cartpole(30)[0])
    ip.solve()
    assert solver.stats.cost == pytest.approx(ip.stats.cost, rel=1e-4)


def test_history_records_every_iteration_and_stops_on_convergence():
    prb, _ = build_cartpole(50)
    solver = make_solver("gnsqp", prb, {"max_iter": 300})
    assert solver.solve()
    hist = solver.stats.history
    assert len(hist) == solver.stats.iterations + 1
    assert hist[-1]["violation"] <= 1e-8
    assert hist[-1]["stationarity"] <= 1e-6 or hist[-1]["step"] <= 1e-10
    assert solver.stats.status == "converged"


def test_max_iter_stops_with_failure():
    prb, _ = build_cartpole(50)
    solver = make_solver("gnsqp", prb, {"max_iter": 3})
    assert not solver.solve()
    assert solver.stats.status == "max_iter reached" and solver.stats.iterations == 3


@pytest.mark.parametrize("budget, status", [(60.0, "converged"), (1e-9, "time budget")])
def test_a_time_budget_never_starts_a_step_it_cannot_finish(budget, status):
    """As the ILQR's option (the GN-SQP had none: a turn ran minutes with no way to cap
    it); the first step always runs, and the stats are of the point returned."""
    prb, _ = build_cartpole()
    solver = make_solver("gnsqp", prb, {"time_budget": budget})
    assert solver.solve() is (status == "converged")
    assert solver.stats.status == status
    if budget < 1:
        assert solver.stats.iterations == 1  # one step taken, the second not started
        last = solver.stats.history[-1]
        assert (last["iteration"], solver.stats.cost) == (1, last["cost"])
    with pytest.raises(ValueError, match="time_budget"):
        make_solver("gnsqp", prb, {"time_budget": 0.0})


def test_warm_resolve_after_convergence_takes_no_step():
    prb, _ = build_cartpole(50)
    solver = make_solver("gnsqp", prb, {"max_iter": 300})
    assert solver.solve()
    assert solver.solve()  # primal and duals already optimal
    assert solver.stats.iterations <= 1


def test_receding_horizon_shift_then_warm_resolve():
    prb, v = build_cartpole(60)
    solver = make_solver("gnsqp", prb, {"max_iter": 300})
    assert solver.solve()
    cold = solver.stats.iterations
    solver.shift()
    for name in ("q", "v"):
        x0 = v[name].initial_guess[:, 0]
        v[name].set_bounds(x0, x0, nodes=0)
    assert solver.solve()
    assert solver.stats.iterations < cold
    np.testing.assert_allclose(solver.solution["q"][:, -1], [0.0, np.pi], atol=1e-6)


def test_weights_node_sets_and_bounds_change_without_rebuild():
    prb, v = build_double_integrator(20)
    solver = make_solver("gnsqp", prb)
    assert solver.solve()
    functions = (solver._linearize, solver._qp_solver())
    prb.get_term("arrive").set_nodes(10)  # arrive in half the time
    prb.get_term("effort").set_nodes(range(10))
    v["u"].set_bounds(-20.0, 20.0)  # active: the unconstrained peak is 23
    solver.reset()
    assert solver.solve()
    assert np.max(np.abs(solver.solution["u"])) == pytest.approx(20.0, abs=1e-6)
    assert solver.solution["x"][0, 10] == pytest.approx(1.0, abs=1e-8)
    assert (solver._linearize, solver._qp_solver()) == functions


def _double_integrator_with_nan_guess():
    prb, v = build_double_integrator(n_nodes=5)
    v["u"].set_initial_guess(np.nan)
    return prb


def test_a_nan_guess_is_a_failure_not_a_converged_solution():
    """NaN says nothing about feasibility: no 'converged' with a NaN solution."""
    solver = make_solver("gnsqp", _double_integrator_with_nan_guess())
    assert solver.solve() is False
    assert "not finite" in solver.stats.status and solver.stats.iterations == 0
    assert np.isnan(solver.stats.constraint_violation)


def test_the_violation_of_a_nan_point_is_nan():
    solver = make_solver("gnsqp", _double_integrator_with_nan_guess())
    tr = solver.transcription
    w = np.zeros(tr.nw)
    w[3] = np.nan
    lbx, ubx = tr.bounds_w()
    lbg, ubg = tr.bounds_g()
    assert np.isnan(tr.violation(w, np.zeros(tr.ng), lbx, ubx, lbg, ubg))
    assert tr.violation(np.zeros(tr.nw), np.zeros(tr.ng), lbx, ubx, lbg, ubg) >= 0.0


def _via_point(n_nodes: int = 10):
    """Double integrator from rest to x = 1, passing x = 0.3 at node 5; effort cost."""
    import casadi as cs

    from horizon_mpc import Problem

    prb = Problem(n_nodes)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(x[1], u))
    prb.set_dt(0.1)
    x.set_bounds([0, 0], [0, 0], nodes=0)
    via = prb.create_constraint("via", x[0] - 0.3, nodes=5)
    prb.create_cost("effort", u, weight=0.1)
    prb.create_final_constraint("goal", x - np.array([1.0, 0.0]))
    return prb, u, via


def _fresh_cost(edit) -> float:
    prb, u, via = _via_point()
    edit(u, via)
    solver = make_solver("ipopt", prb)
    assert solver.solve()
    return solver.stats.cost


@pytest.mark.parametrize("edit", [
    lambda u, via: via.set_nodes([]),                      # the active constraint dropped
    lambda u, via: via.set_bounds(-np.inf, np.inf),        # its bounds opened
    lambda u, via: u.set_bounds(-9.0, 9.0),                # an input bound relaxed
], ids=["constraint_dropped", "constraint_opened", "bound_relaxed"])
def test_a_warm_resolve_after_relaxing_the_problem_finds_the_new_optimum(edit):
    """The multipliers kept from the last solve belong to rows that no longer bind: they
    must not make the old point pass the KKT test (it did, at iteration 0)."""
    prb, u, via = _via_point()
    u.set_bounds(-8.0, 8.0)  # active in the first solve
    solver = make_solver("gnsqp", prb)
    assert solver.solve()
    first = solver.stats.cost
    edit(u, via)
    expected = _fresh_cost(lambda u_, via_: (u_.set_bounds(-8.0, 8.0), edit(u_, via_)))
    assert solver.solve(), solver.stats.status
    assert expected < first - 1e-3  # the edit matters
    assert solver.stats.cost == pytest.approx(expected, rel=1e-6)


def _around_obstacle(n_nodes: int = 50):
    """Unicycle from (0, 0, 0) to (4, 0, 0) around a disc of radius 0.7 at (2, 0): a
    curved constraint (Gauss-Newton ignores its curvature)."""
    import casadi as cs

    from horizon_mpc import Problem

    prb = Problem(n_nodes)
    p = prb.create_state_variable("p", 3)
    u = prb.create_input_variable("u", 2)
    prb.set_dynamics(cs.vertcat(u[0] * cs.cos(p[2]), u[0] * cs.sin(p[2]), u[1]))
    prb.set_dt(5.0 / n_nodes)
    p.set_bounds([0, 0, 0], [0, 0, 0], nodes=0)
    u.set_bounds([-2, -3], [2, 3])
    s = np.linspace(0, 4, n_nodes + 1)
    p.set_initial_guess(np.vstack([s, 0.8 * np.sin(np.pi * s / 4), np.zeros(n_nodes + 1)]))
    u.set_initial_guess([0.8, 0.0])
    prb.create_constraint("obstacle", (p[0] - 2) ** 2 + p[1] ** 2, bounds=(0.49, np.inf))
    prb.create_final_constraint("goal", p - np.array([4.0, 0, 0]))
    prb.create_cost("effort", u, weight=5.0 / n_nodes)
    return prb


def test_started_at_ipopts_optimum_it_converges_without_its_multipliers():
    # from the optimum with zero multipliers no step decreases the merit (the line search
    # failed at iteration 0): the QP's multipliers settle the KKT test
    ip = make_solver("ipopt", _around_obstacle())
    assert ip.solve()
    prb = _around_obstacle()
    for name in ("p", "u"):
        prb.get_variable(name).set_initial_guess(ip.solution[name])
    gn = make_solver("gnsqp", prb, {"max_iter": 300})
    assert gn.solve(), gn.stats.status
    # the Gauss-Newton fixed point lies a little off IPOPT's (curvature of the disc)
    assert gn.stats.cost == pytest.approx(ip.stats.cost, rel=1e-4)


@pytest.mark.parametrize("u_max", [1.0, 3.0])
def test_an_infeasible_problem_is_reported_as_such_early(u_max):
    """Rest to rest over 1 m in 1 s needs |u| >= 4: with |u| <= u_max the elastic QP can
    never reduce the violation; gnsqp ran to max_iter (500 iterations, 13 s on a pendulum)."""
    prb, u, via = _via_point()
    via.set_nodes([])
    u.set_bounds(-u_max, u_max)
    solver = make_solver("gnsqp", prb, {"max_iter": 100})
    assert not solver.solve()
    assert solver.stats.status.startswith("locally infeasible")
    assert solver.stats.iterations <= 10
    assert solver.stats.constraint_violation > 0.1


def test_a_feasible_problem_that_starts_infeasible_still_converges():
    prb, u, via = _via_point()
    u.set_bounds(-6.0, 6.0)  # feasible (the optimum needs 5.45 without the via point)
    via.set_nodes([])
    u.set_initial_guess(0.0)
    solver = make_solver("gnsqp", prb)
    assert solver.solve(), solver.stats.status


def test_a_derivative_undefined_at_the_guess_is_named_not_blamed_on_the_guess():
    """|v| has no derivative at v = 0, where the guess starts: the guess and parameters are
    finite, and the status says what is not."""
    solver = make_solver("gnsqp", double_integrator_with_a_nan_derivative_at_rest())
    assert solver.solve() is False
    assert solver.stats.status == ("cost gradient not finite at the initial guess (a "
                                   "derivative undefined there)")


def _unicycle_around_obstacles(n: int = 30):
    """Park a unicycle past two discs; the guess runs through them, so early
    linearisations are infeasible (an auditor's problem, shorter)."""
    import casadi as cs

    from horizon_mpc import Problem

    prb = Problem(n)
    s = prb.create_state_variable("s", 3)
    u = prb.create_input_variable("u", 2)
    prb.set_dynamics(cs.vertcat(u[0] * cs.cos(s[2]), u[0] * cs.sin(s[2]), u[1]))
    prb.set_dt(6.0 / n)
    s.set_bounds(0.0, 0.0, nodes=0)
    prb.create_final_constraint("park", s - [3.0, 0.5, np.pi / 2])
    u.set_bounds([-1.0, -1.5], [1.0, 1.5])
    for i, (ox, oy, r) in enumerate([(1.0, 0.55, 0.35), (2.0, -0.2, 0.3)]):
        prb.create_constraint(f"obs{i}", (s[0] - ox) ** 2 + (s[1] - oy) ** 2,
                              bounds=(r ** 2, np.inf))
    prb.create_cost("effort", u, weight=[1.0, 0.1])
    t = np.linspace(0.0, 1.0, n + 1)
    s.set_initial_guess(np.vstack([3 * t, 0.5 * t - 0.6 * np.sin(np.pi * t), 0 * t]))
    u.set_initial_guess([0.5, 0.0])
    return prb


def test_qrqp_gives_up_a_qp_early_and_retries_it_cold(monkeypatch):
    """Each QP of these early linearisations ran qrqp to 10000 iterations (1.5-5 s) before
    the elastic QP took over: 97 % of an 18 s solve. The plain QP now stops after one
    iteration per variable and row (at least QRQP_MIN_ITER); those QPs were feasible, the
    last step's multipliers had started qrqp on a cycle: retried cold, they take a few
    iterations, and no elastic step is left (3 before, 2.2 s of QPs against 0.4)."""
    from horizon_mpc.solvers import gnsqp

    plain = _counted_plain_qps(monkeypatch)
    prb = _unicycle_around_obstacles()
    solver = make_solver("gnsqp", prb)
    assert solver.solve(), solver.stats.status
    cap = max(gnsqp.QRQP_MIN_ITER, solver.transcription.nw + solver.transcription.ng)
    assert max(it for it, _, _ in plain) <= cap < 10000
    capped = [k for k, (it, ok, warm) in enumerate(plain) if warm and not ok]
    # warm-started, a QP stops sooner (QRQP_WARM_ITER): a collocated brachistochrone's
    # cycled through 1356 iterations (190 s) before its cold retry took 51
    assert capped and all(plain[k][0] == min(cap, gnsqp.QRQP_WARM_ITER) for k in capped)
    assert all(plain[k + 1][1] and not plain[k + 1][2] for k in capped)  # cold, solved
    assert solver.stats.extra["elastic_steps"] == 0
    assert solver.stats.constraint_violation < 1e-6
    # a local optimum (the discs can be passed on either side): IPOPT started there stays
    again = _unicycle_around_obstacles()
    for name in ("s", "u"):
        again.get_variable(name).set_initial_guess(solver.solution[name])
    reference = make_solver("ipopt", again)
    assert reference.solve()
    assert solver.stats.cost == pytest.approx(reference.stats.cost, rel=1e-5)


def test_a_qp_the_last_multipliers_start_on_a_cycle_is_solved_cold():
    """A rate-limited pendulum swing-up: qrqp, warm-started with the last step's
    multipliers, ran its feasible QPs to the iteration cap (cold: ~12 iterations); the
    elastic QP's steps then ended the solve as 'QP failed' at 3e-2 violation (QA finding)."""
    import casadi as cs

    from horizon_mpc import Problem

    def swing_up() -> Problem:
        n = 30
        prb = Problem(n)
        x = prb.create_state_variable("th", 2)
        u = prb.create_input_variable("tau", 1)
        prb.set_dynamics(cs.vertcat(x[1], -9.81 * cs.sin(x[0]) + u))
        prb.set_dt(3.0 / n)
        x.set_bounds([0, 0], [0, 0], nodes=0)
        prb.create_cost("effort", u, weight=0.1)
        prb.create_cost("rate", u - u.offset(-1), weight=1.0)
        prb.create_constraint("rate_limit", u - u.offset(-1), bounds=(-1.0, 1.0))
        prb.create_final_constraint("up", x - [np.pi, 0])
        x.set_initial_guess(np.vstack([np.linspace(0, np.pi, n + 1), np.zeros(n + 1)]))
        return prb

    ipopt = make_solver("ipopt", swing_up())
    assert ipopt.solve()
    gn = make_solver("gnsqp", swing_up())
    assert gn.solve(), gn.stats.status
    assert gn.stats.extra["elastic_steps"] == 0
    assert gn.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-6)


def test_a_warm_started_qp_stops_at_its_own_cap_and_is_solved_cold(monkeypatch):
    """The plain QP's cap grows with its size: a collocated brachistochrone's warm-started
    QP (654 variables) cycled through 1356 qrqp iterations, 190 s, where its cold retry
    took 51 (an auditor's). A warm start gets QRQP_WARM_ITER iterations (2 here)."""
    from horizon_mpc.solvers import gnsqp

    monkeypatch.setattr(gnsqp, "QRQP_WARM_ITER", 2)
    calls = _counted_plain_qps(monkeypatch)
    solver = make_solver("gnsqp", _unicycle_around_obstacles())
    assert solver.solve(), solver.stats.status
    stopped = [k for k, (it, ok, warm) in enumerate(calls) if warm and not ok]
    assert stopped and all(calls[k][0] == 2 for k in stopped)
    assert all(calls[k + 1][1] and not calls[k + 1][2] for k in stopped)  # cold, solved
    assert max(it for it, _, warm in calls if warm) <= 2


def _counted_plain_qps(monkeypatch) -> list[tuple[int, bool, bool]]:
    """(iterations, success, warm-started) of every plain QP the GN-SQP solves from now."""
    from horizon_mpc.solvers import gnsqp

    calls: list[tuple[int, bool, bool]] = []
    original = gnsqp.GnSqpSolver._qp_solver

    def counted(self, elastic=False, warm=False):
        qp = original(self, elastic, warm)
        if elastic:
            return qp

        def call(**kw):
            out = qp(**kw)
            calls.append((qp.stats()["iter_count"], qp.stats()["success"], warm))
            return out
        call.stats = qp.stats
        return call

    monkeypatch.setattr(gnsqp.GnSqpSolver, "_qp_solver", counted)
    return calls


def test_a_reach_at_an_active_joint_limit_converges():
    """An auditor's UR5 reach (torque inputs, joint limits as bounds, the elbow's active on
    three nodes): the line search's reference was the maximum of the last 3 merit values,
    and full steps of period 3 lowered the merit by 2e-7 per cycle: max_iter at 300 and at
    1000 iterations. Once the violation stalls under full steps, their weighted mean: 112
    iterations, IPOPT's optimum (the mean from the start: 58, but it failed elsewhere)."""
    import casadi as cs

    from horizon_mpc import Problem
    from horizon_mpc.model import RobotModel

    m = RobotModel.from_example("ur5")
    n, dt = 30, 0.05
    q0 = np.array([0.0, -1.2, 1.5, -0.3, 1.2, 0.0])

    def build():
        prb = Problem(n)
        q = prb.create_state_variable("q", 6)
        v = prb.create_state_variable("v", 6)
        tau = prb.create_input_variable("tau", 6)
        prb.set_dynamics(cs.vertcat(v, m.forward_dynamics([])(q, v, tau, cs.DM(0, 1))))
        prb.set_dt(dt)
        prb.transcribe("multiple_shooting", integrator="rk2")
        q.set_bounds(q0, q0, nodes=0)
        v.set_bounds(np.zeros(6), np.zeros(6), nodes=0)
        q.set_bounds(m.q_lower, m.q_upper, nodes=range(1, n + 1))
        q.set_initial_guess(np.tile(q0[:, None], (1, n + 1)))
        tau.set_initial_guess(np.tile(m.gravity()(q0).full(), (1, n)))
        prb.create_final_constraint("reach", m.fk("tool0")(q)[0] - [0.4, 0.3, 0.4])
        prb.create_final_constraint("rest", v)
        prb.create_cost("effort", tau, weight=1e-3 * dt)
        prb.create_cost("velocity", v, weight=1e-2 * dt)
        return prb, q

    ip, gn = solve_both(build)
    assert gn.stats.iterations <= 150, gn.stats.status
    assert gn.stats.cost == pytest.approx(ip.stats.cost, rel=1e-6)
    active = np.isclose(gn.solution["q"], m.q_upper[:, None], atol=1e-6) | np.isclose(
        gn.solution["q"], m.q_lower[:, None], atol=1e-6)
    assert active[:, 1:].any()  # the case: a joint limit active at the optimum


def test_the_weighted_mean_is_the_reference_only_once_the_violation_stalls():
    """Its mean as the reference from the first iteration crept where the maximum takes
    full steps: a collocated cart-pole at an active cart limit needed 292 iterations (a
    reviewer's); the maximum until a stall: 120."""
    prb, _ = build_cartpole(50, transcription="direct_collocation", degree=2, cart_limit=0.6)
    solver = make_solver("gnsqp", prb, {"max_iter": 400})
    assert solver.solve(), solver.stats.status
    assert solver.stats.iterations <= 150
    assert not solver._strict_reference
