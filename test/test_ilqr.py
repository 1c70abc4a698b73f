"""ILQR: exactness on LQ problems, agreement with IPOPT, gap closing, honest refusals."""

import casadi as cs
import numpy as np
import pytest
from ocps import double_integrator_with_a_nan_derivative_at_rest, pendulum_swing_up

from horizon_mpc import Problem, make_solver
from horizon_mpc.examples import pendulum_dynamics
from horizon_mpc.examples.cartpole import build_cartpole
from horizon_mpc.model.liegroup import quat_multiply

OPTS = {"codegen": False, "max_iter": 400}


def _lq_problem(n=20):
    prb = Problem(n)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(x[1], u))
    prb.set_dt(0.1)
    prb.transcribe("multiple_shooting", integrator="euler")
    x.set_bounds([1.0, 0.0], [1.0, 0.0], nodes=0)
    prb.create_cost("effort", u, weight=0.1)
    prb.create_cost("state", x, weight=1.0)
    return prb, x, u


def _riccati_reference(n=20, dt=0.1):
    """The LQ optimum by a dense KKT solve (independent of the solver's recursion)."""
    A = np.array([[1.0, dt], [0.0, 1.0]])
    B = np.array([[0.0], [dt]])
    nx, nu = 2, 1
    nz = nx * (n + 1) + nu * n
    H = np.zeros((nz, nz))
    for k in range(n + 1):
        H[nx * k:nx * k + nx, nx * k:nx * k + nx] = 2 * np.eye(nx)
    off = nx * (n + 1)
    for k in range(n):
        H[off + k, off + k] = 0.2
    rows = []
    rhs = []
    e0 = np.zeros((nx, nz))
    e0[:, :nx] = np.eye(nx)
    rows.append(e0)
    rhs.append([1.0, 0.0])
    for k in range(n):
        r = np.zeros((nx, nz))
        r[:, nx * k:nx * k + nx] = A
        r[:, off + k:off + k + 1] = B
        r[:, nx * (k + 1):nx * (k + 2)] = -np.eye(nx)
        rows.append(r)
        rhs.append([0.0, 0.0])
    C = np.vstack(rows)
    d = np.concatenate(rhs)
    kkt = np.block([[H, C.T], [C, np.zeros((C.shape[0], C.shape[0]))]])
    sol = np.linalg.solve(kkt, np.concatenate([np.zeros(nz), d]))
    return sol[:off].reshape(n + 1, nx).T, sol[off:nz].reshape(n, nu).T


def test_lq_problem_is_solved_exactly_by_the_first_iteration():
    prb, x, u = _lq_problem()
    solver = make_solver("ilqr", prb, {**OPTS, "mu_init": 0.0, "mu_min": 0.0})
    assert solver.solve()
    X_ref, U_ref = _riccati_reference()
    first = solver.stats.history[0]
    assert first["alpha"] == 1.0
    # the second iteration only confirms stationarity: nothing moved
    assert solver.stats.iterations <= 2
    np.testing.assert_allclose(solver.solution["x"], X_ref, atol=1e-9)
    np.testing.assert_allclose(solver.solution["u"], U_ref, atol=1e-9)


def _solve(prb, name, opts=None):
    solver = make_solver(name, prb, opts or {})
    ok = solver.solve()
    return ok, solver


@pytest.mark.parametrize("u_max", [None, 25.0])
def test_cartpole_swing_up_matches_ipopt(u_max):
    prb_i, _ = build_cartpole(n_nodes=60, u_max=u_max)
    ok_i, ipopt = _solve(prb_i, "ipopt")
    prb_l, _ = build_cartpole(n_nodes=60, u_max=u_max)
    ok_l, ilqr = _solve(prb_l, "ilqr", OPTS)
    assert ok_i and ok_l, ilqr.stats.status
    assert abs(ilqr.stats.cost - ipopt.stats.cost) <= 1e-3 * abs(ipopt.stats.cost)
    assert ilqr.stats.constraint_violation <= 1e-6
    if u_max is not None:
        assert np.max(np.abs(ilqr.solution["u"])) <= u_max + 1e-6


# 5.5: the bound is active over long stretches (the pendulum must pump); it stalled at 0.1
# violation while the multipliers were updated after every iteration
@pytest.mark.parametrize("u_max", [6.0, 5.5])
def test_pendulum_with_input_bounds_and_final_equality_matches_ipopt(u_max):
    ok_i, ipopt = _solve(pendulum_swing_up(u_max), "ipopt")
    ok_l, ilqr = _solve(pendulum_swing_up(u_max), "ilqr", OPTS)
    assert ok_i and ok_l
    assert abs(ilqr.stats.cost - ipopt.stats.cost) <= 1e-3 * ipopt.stats.cost
    assert ilqr.stats.constraint_violation <= 1e-6
    assert np.max(np.abs(ilqr.solution["u"])) <= u_max + 1e-6


def test_large_gaps_in_the_warm_start_are_closed():
    prb, _ = build_cartpole(n_nodes=60)
    rng = np.random.default_rng(3)
    q = prb.get_variable("q")
    q.set_initial_guess(q.initial_guess + rng.normal(0, 0.5, q.initial_guess.shape))
    solver = make_solver("ilqr", prb, OPTS)
    X0 = np.vstack([prb.get_variable("q").initial_guess, prb.get_variable("v").initial_guess])
    F = prb.discrete_dynamics()
    gaps0 = max(np.max(np.abs(np.asarray(F(X0[:, k], 0.0, [], [])).ravel() - X0[:, k + 1]))
                for k in range(60))
    assert gaps0 > 0.3
    assert solver.solve()
    X = solver.solution["x"]
    U = solver.solution["u"]
    gaps = max(np.max(np.abs(np.asarray(F(X[:, k], U[:, k], [], [])).ravel() - X[:, k + 1]))
               for k in range(60))
    assert gaps <= 1e-6


def test_free_single_variable_is_refused_not_ignored():
    prb = Problem(10)
    prb.create_state_variable("x", 1)
    u = prb.create_input_variable("u", 1)
    T = prb.create_single_variable("T", 1)
    T.set_bounds(0.1, 2.0)
    prb.set_dynamics(u)
    prb.set_dt(T / 10)
    prb.create_cost("u", u)
    with pytest.raises(ValueError, match="single variable 'T'"):
        make_solver("ilqr", prb, OPTS)


@pytest.mark.parametrize("codegen", [False, True], ids=["vm", "compiled"])
@pytest.mark.parametrize("where", ["dynamics", "cost"])
def test_a_fixed_single_variable_is_the_same_at_every_node(codegen, where):
    """A single variable fixed by equal bounds is one value for all nodes (the stage
    functions take it once, not once per node): ILQR finds IPOPT's optimum."""
    def build():
        prb = Problem(10)
        x = prb.create_state_variable("x", 1)
        u = prb.create_input_variable("u", 1)
        k = prb.create_single_variable("k", 1)
        k.set_bounds(2.0, 2.0)
        prb.set_dynamics(k * u if where == "dynamics" else 2 * u)
        prb.set_dt(0.1)
        x.set_bounds(0.0, 0.0, nodes=0)
        prb.create_final_constraint("goal", x - 1.0)
        prb.create_cost("effort", u if where == "dynamics" else u * k / 2)
        return prb

    ilqr = make_solver("ilqr", build(), {**OPTS, "codegen": codegen})
    ipopt = make_solver("ipopt", build())
    assert ilqr.solve() and ipopt.solve()
    assert ilqr.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-8)  # 2.5
    np.testing.assert_allclose(ilqr.solution["u"], ipopt.solution["u"], atol=1e-8)
    assert ilqr.solution["x"][0, -1] == pytest.approx(1.0, abs=1e-9)


def _single_integrator(n: int):
    """``x' = u`` (one state, one input), ``dt`` 0.1: (problem, x, u)."""
    prb = Problem(n)
    x = prb.create_state_variable("x", 1)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(u)
    prb.set_dt(0.1)
    return prb, x, u


def test_general_cost_is_refused():
    prb, x, _ = _single_integrator(10)
    prb.create_general_cost("quartic", x**4)
    with pytest.raises(ValueError, match="general cost"):
        make_solver("ilqr", prb, OPTS)


def test_rti_mode_runs_exactly_the_requested_iterations_and_exposes_gains():
    prb, _ = build_cartpole(n_nodes=40)
    solver = make_solver("ilqr", prb, {**OPTS, "rti": True, "iterations_per_call": 2})
    solver.solve()
    assert solver.stats.iterations == 2
    assert solver.feedback_gains.shape == (40, 1, 4)
    assert np.all(np.isfinite(solver.feedback_gains))


@pytest.mark.parametrize("rti, max_inner, expected", [(True, 10, 1), (False, 1, 3),
                                                     (False, 10, 0)])
def test_multipliers_are_updated_once_per_real_time_call(rti, max_inner, expected):
    """Real-time iterations take one dual step per call (after the last iteration); a
    converging solve takes one when the inner problem is nearly solved or every
    ``al_max_inner`` iterations (the swing-up's first 3 are far from stationary)."""
    prb, _ = build_cartpole(n_nodes=20)
    solver = make_solver("ilqr", prb, {**OPTS, "rti": rti, "iterations_per_call": 3,
                                       "max_iter": 3, "tol": 0.0, "al_max_inner": max_inner})
    calls = []
    update = solver._al.update
    solver._al.update = lambda c, *a, **k: (calls.append(c.copy()), update(c, *a, **k))[1]
    solver.solve()
    assert solver.stats.iterations == 3
    assert len(calls) == expected


@pytest.mark.parametrize("budget, iterations, status", [
    (None, 4, "rti"), (60.0, 4, "rti"), (1e-9, 1, "time budget")])
def test_a_time_budget_never_starts_an_iteration_it_cannot_finish(budget, iterations, status):
    prb, _ = build_cartpole(n_nodes=20)
    solver = make_solver("ilqr", prb, {**OPTS, "rti": True, "iterations_per_call": 4,
                                       "time_budget": budget})
    solver.solve()
    assert solver.stats.iterations == iterations  # the first iteration always runs
    assert solver.stats.status == status
    assert np.all(np.isfinite(solver.solution["x"]))


def test_nan_in_the_problem_is_reported_and_never_returned():
    prb = Problem(10)
    x = prb.create_state_variable("x", 1)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.sqrt(x) + u)  # NaN for x < 0
    prb.set_dt(0.1)
    x.set_bounds(-1.0, -1.0, nodes=0)
    prb.create_cost("u", u)
    solver = make_solver("ilqr", prb, OPTS)
    ok = solver.solve()
    assert not ok
    assert "not finite" in solver.stats.status
    assert all(np.all(np.isfinite(v)) for v in solver.solution.values())


def test_warm_resolve_needs_far_fewer_iterations_than_cold():
    prb, _ = build_cartpole(n_nodes=60)
    solver = make_solver("ilqr", prb, OPTS)
    assert solver.solve()
    cold = solver.stats.iterations
    assert solver.solve()  # the solution was written back as the initial guess
    assert solver.stats.iterations <= max(3, cold // 10)


def _lq_with_equalities(n=20):
    """LQ problem plus linear equalities on (x, u) and on x alone (velocity: relative
    degree one, so the input of the node before can meet it)."""
    prb, x, u = _lq_problem(n)
    prb.create_constraint("mixed", u + 0.5 * x[1] - 0.2, nodes=range(2, 5))
    prb.create_constraint("velocity", x[1] + 0.1, nodes=[6, n])
    return prb


def test_a_relative_degree_two_row_stays_with_the_augmented_lagrangian():
    """A position row cannot be met by one input: it is not projected, yet it converges."""
    prb, x, u = _lq_problem(20)
    prb.create_constraint("position", x[0] - 0.3, nodes=[12, 20])
    ok, solver = _solve(prb, "ilqr", OPTS)
    assert ok, solver.stats.status
    assert not solver._layout.any
    assert abs(solver.solution["x"][0, 12] - 0.3) <= 1e-6


@pytest.mark.parametrize("n", [20, 7])
def test_linear_equalities_are_met_by_the_first_projected_step(n):
    """Exact projection: one iteration lands on the equality-constrained LQ optimum."""
    prb = _lq_with_equalities(n)
    solver = make_solver("ilqr", prb, {**OPTS, "mu_init": 0.0, "mu_min": 0.0,
                                       "rti": True, "iterations_per_call": 1})
    solver.solve()
    assert solver.stats.history[0]["alpha"] == 1.0
    assert solver.stats.constraint_violation <= 1e-9
    ref = make_solver("ipopt", _lq_with_equalities(n), {"ipopt.tol": 1e-12})
    assert ref.solve()
    np.testing.assert_allclose(solver.solution["u"], ref.solution["u"], atol=1e-6)
    np.testing.assert_allclose(solver.solution["x"], ref.solution["x"], atol=1e-6)


def test_projection_and_lagrangian_reach_the_same_optimum():
    """The two equality treatments agree on a nonlinear problem (cart-pole, mid-swing equality)."""
    sols = {}
    for mode in ("projection", "lagrangian"):
        prb, var = build_cartpole(n_nodes=60)
        q = var["q"]
        prb.create_constraint("pole_level", q[1] - np.pi / 2, nodes=[30])
        ok, solver = _solve(prb, "ilqr", {**OPTS, "equality": mode})
        assert ok, solver.stats.status
        sols[mode] = solver
    a, b = sols["projection"], sols["lagrangian"]
    assert abs(a.stats.cost - b.stats.cost) <= 1e-4 * abs(b.stats.cost)
    assert a.stats.constraint_violation <= 1e-6
    assert a.stats.iterations <= b.stats.iterations


def test_unknown_equality_mode_is_refused():
    prb, _, _ = _lq_problem()
    with pytest.raises(ValueError, match="equality"):
        make_solver("ilqr", prb, {**OPTS, "equality": "barrier"})


def _cartpole_with_input_equality(n_nodes: int = 30):
    """Cart-pole whose force follows a state-dependent law on the first third of the
    horizon: an input-dependent equality (the projection's kind of row)."""
    prb, var = build_cartpole(n_nodes=n_nodes)
    law = prb.create_constraint("force_law", var["u"] - 2.0 * var["v"][0],
                                nodes=range(n_nodes // 3))
    return prb, law


def test_the_lean_quadratisation_leaves_out_only_zero_weight_terms():
    prb, _ = _cartpole_with_input_equality()
    solver = make_solver("ilqr", prb, OPTS)
    m = solver.model
    assert not m.al_rows[:m.nc_con].all() and m.al_rows[m.nc_con:].all()
    full = m.quadratise_full()
    rng = np.random.default_rng(3)
    N = m.n_nodes
    args = [rng.standard_normal((m.nx, N)), rng.standard_normal((m.nu, N)),
            np.zeros((prb.ns, 1)), np.zeros((prb.np_, N)), rng.random((m.nr, N)),
            rng.random((m.nc, N)) * m.al_rows[:, None], rng.standard_normal((m.nc, N))]
    for lean_out, full_out in zip(m.quadratise(*args), full(*args), strict=True):
        np.testing.assert_allclose(np.asarray(lean_out), np.asarray(full_out), rtol=1e-12,
                                   atol=1e-12)


def test_a_left_out_equality_made_an_inequality_gets_its_terms_back():
    prb, law = _cartpole_with_input_equality()
    solver = make_solver("ilqr", prb, OPTS)
    solver.solve()
    assert solver._quadratise_fn is solver._quadratise_lean
    law.set_bounds(-50.0, 50.0)  # no longer an equality: the augmented Lagrangian's now
    assert solver.solve()
    assert solver._quadratise_fn is solver._quadratise_all
    sol = solver.solution
    residual = sol["u"][0, :10] - 2.0 * sol["v"][0, :10]
    assert np.all(np.abs(residual) <= 50.0 + 1e-6)
    # the same optimum as with every row in the augmented Lagrangian from the start
    ref_prb, ref_law = _cartpole_with_input_equality()
    ref_law.set_bounds(-50.0, 50.0)
    ref = make_solver("ilqr", ref_prb, {**OPTS, "equality": "lagrangian"})
    assert ref.solve()
    assert solver.stats.cost == pytest.approx(ref.stats.cost, rel=1e-6)


def test_a_nan_parameter_is_named_as_such_not_as_a_bad_guess():
    prb = Problem(5)
    x = prb.create_state_variable("x", 1)
    u = prb.create_input_variable("u", 1)
    k = prb.create_parameter("k", 1)
    prb.set_dynamics(u)
    prb.set_dt(0.1)
    x.set_bounds(0.0, 0.0, nodes=0)
    prb.create_cost("effort", k * u)
    solver = make_solver("ilqr", prb, OPTS)
    k.assign(np.nan)
    assert solver.solve() is False and solver.stats.status == "parameters not finite"
    k.assign(1.0)
    u.set_initial_guess(np.nan)
    assert solver.solve() is False and solver.stats.status == "initial guess not finite"
    u.set_initial_guess(0.0)
    assert solver.solve() is True


def _start_at(fixed: bool, start_row: tuple | None):
    """Double integrator to x = 1 in 1.5 s; node 0 fixed at rest or not, and a row on node 0."""
    prb = Problem(15)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(x[1], u))
    prb.set_dt(0.1)
    prb.create_cost("effort", u, weight=0.1)
    prb.create_final_constraint("goal", x - np.array([1.0, 0.0]))
    if fixed:
        x.set_bounds([0, 0], [0, 0], nodes=0)
    if start_row is not None:
        expr, bounds = start_row
        prb.create_constraint("start", expr(x), nodes=0, bounds=bounds)
    return prb


@pytest.mark.parametrize("start_row, violation", [
    ((lambda x: x[0] - 0.5, None), 0.5),       # an equality the fixed state breaks
    ((lambda x: x[1], (0.2, 1.0)), 0.2),       # an inequality it breaks
])
def test_a_fixed_initial_state_that_breaks_a_node0_row_is_reported_infeasible(
        start_row, violation):
    # the rows are left out of the steps (nothing can change them) but not out of the
    # violation: they were, and ILQR reported 'converged' with violation 7e-7
    solver = make_solver("ilqr", _start_at(True, start_row))
    assert not solver.solve()
    assert solver.stats.status.startswith("infeasible")
    assert solver.stats.constraint_violation == pytest.approx(violation)
    assert solver.stats.iterations < 30  # stopped once the rest was solved, not at max_iter


def test_a_node0_row_met_by_the_fixed_state_changes_nothing():
    plain = make_solver("ilqr", _start_at(True, None))
    assert plain.solve()
    met = make_solver("ilqr", _start_at(True, (lambda x: x[0], None)))
    assert met.solve(), met.stats.status
    assert met.stats.cost == pytest.approx(plain.stats.cost, rel=1e-9)


def test_a_warm_receding_solve_never_claims_convergence_above_the_optimum():
    """Pendulum MPC with an active input bound, shifted between solves: the steps were
    rejected until the regularisation reached 1e6, and the tiny regularised decrease passed
    for stationarity ('converged' 3 % above IPOPT's optimum). Every success must now be the
    optimum."""
    def build():
        prb = Problem(30)
        x = prb.create_state_variable("x", 2)
        u = prb.create_input_variable("u", 1)
        ref = prb.create_parameter("ref", 1)
        prb.set_dynamics(cs.vertcat(x[1], pendulum_dynamics(x[0], x[1], u)))
        prb.set_dt(0.05)
        u.set_bounds(-4, 4)
        prb.create_cost("track", x[0] - ref, weight=5.0)
        prb.create_cost("velocity", x[1], weight=0.1)
        prb.create_cost("effort", u, weight=0.01)
        ref.assign(0.8)
        return prb, x

    prb, x = build()
    solver = make_solver("ilqr", prb)
    step = prb.discrete_dynamics()
    state, successes = np.zeros(2), 0
    for _ in range(4):
        x.set_bounds(state, state, nodes=0)
        if solver.solve():
            successes += 1
            ref_prb, ref_x = build()
            ref_x.set_bounds(state, state, nodes=0)
            ipopt = make_solver("ipopt", ref_prb)
            assert ipopt.solve()
            assert solver.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-4)
        state = step(state, solver.solution["u"][:, 0], [], []).full().ravel()
        solver.shift()
    assert successes >= 1


def test_a_start_that_fails_returns_the_guesses_it_failed_at():
    # the solution was {} (KeyError on solution['x']) or a previous solve's
    prb = pendulum_swing_up(5.5, n_nodes=10)
    solver = make_solver("ilqr", prb)
    assert solver.solve() is not None
    prb.get_variable("u").set_initial_guess(np.nan, nodes=3)
    assert not solver.solve()
    assert solver.solution["x"].shape == (2, 11) and solver.solution["u"].shape == (1, 10)
    assert np.isnan(solver.solution["u"][0, 3])


def test_a_single_variable_freed_after_the_build_is_refused_not_read_at_its_bound():
    # each solve took the lower bound as its value: 'converged' at k = 0.5 (IPOPT: 4.98)
    prb = Problem(10)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    k = prb.create_single_variable("k", 1)
    prb.set_dynamics(cs.vertcat(x[1], -k * x[0] + u))
    prb.set_dt(0.05)
    x.set_bounds([1, 0], [1, 0], nodes=0)
    k.set_bounds(2.0, 2.0)
    prb.create_cost("track", x[0])
    prb.create_cost("effort", u, weight=0.1)
    solver = make_solver("ilqr", prb)
    assert solver.solve()
    k.set_bounds(0.5, 8.0)
    with pytest.raises(ValueError, match=r"single variable\(s\) \['k'\]"):
        solver.solve()
    k.set_bounds(3.0, 3.0)  # fixed again: fine
    assert solver.solve() and solver.solution["k"].item() == 3.0


def test_a_failed_prepare_does_not_keep_the_last_solves_success():
    prb = _start_at(True, None)
    solver = make_solver("ilqr", prb)
    assert solver.solve()
    prb.get_variable("u").set_initial_guess(np.nan, nodes=2)
    assert not solver.prepare()
    assert solver.stats.success is False and solver.stats.status.startswith("prepare:")


def _quat_manifold():
    q, q1, d = cs.SX.sym("q", 4), cs.SX.sym("q1", 4), cs.SX.sym("d", 3)
    n2 = cs.dot(d, d)
    n = cs.sqrt(cs.fmax(n2, 1e-12))
    half = cs.if_else(n2 < 1e-12, 0.5 - n2 / 48, cs.sin(n / 2) / n)
    exp = cs.vertcat(half * d, cs.if_else(n2 < 1e-12, 1 - n2 / 8, cs.cos(n / 2)))
    r = quat_multiply(cs.vertcat(-q[:3], q[3]), q1)
    s = cs.if_else(r[3] < 0, -1, 1)
    v, w = s * r[:3], s * r[3]
    m2 = cs.dot(v, v)
    m = cs.sqrt(cs.fmax(m2, 1e-12))
    log = cs.if_else(m2 < 1e-12, 2 / w, 2 * cs.atan2(m, w) / m) * v
    return (cs.Function("integrate", [q, d], [quat_multiply(q, exp)]),
            cs.Function("difference", [q, q1], [log]))


@pytest.mark.parametrize("codegen", [False, True])
def test_unit_quaternion_rows_under_a_norm_preserving_integrator_converge(codegen):
    """A state-only unit-norm row on a quaternion integrated on its manifold: its input
    Jacobian through the dynamics is round-off (1e-20), and projecting it gave P_x ~ 1e3:
    max_iter with mu 1e10. Now dropped from the projection: IPOPT's optimum."""
    integrate, difference = _quat_manifold()
    target = np.array([0.5, 0.5, 0.5, 0.5])

    def build():
        prb = Problem(40)
        tau = prb.create_input_variable("tau", 3)
        w = prb.create_state_variable("w", 3)
        q = prb.create_state_variable("q", 4)
        q.set_manifold(integrate, difference, 3)
        prb.set_dynamics(cs.vertcat(tau, w))
        prb.set_dt(0.05)
        q.set_bounds([0, 0, 0, 1], [0, 0, 0, 1], nodes=0)
        w.set_bounds(0, 0, nodes=0)
        q.set_initial_guess([0, 0, 0, 1.0])
        prb.create_cost("effort", tau, weight=0.01)
        prb.create_constraint("unit", cs.dot(q, q) - 1, nodes=range(1, 41))
        prb.create_final_constraint("goal", difference(cs.DM(target), q))
        prb.create_final_constraint("rest", w)
        return prb

    ok_i, ipopt = _solve(build(), "ipopt")
    ok_l, ilqr = _solve(build(), "ilqr", {**OPTS, "codegen": codegen, "max_iter": 100})
    assert ok_i and ok_l, ilqr.stats.status
    assert abs(ilqr.stats.cost - ipopt.stats.cost) <= 1e-6 * ipopt.stats.cost


@pytest.mark.parametrize("input_bounds", ["lagrangian", "box", "auto"])
def test_an_active_input_bound_is_never_called_converged_short_of_it(input_bounds):
    """x' = u, |u| <= 0.5 active on 19 of 20 nodes (a convex problem): the augmented
    Lagrangian stopped 'converged' 7.7e-5 above IPOPT's optimum with u 1.3e-4 inside the
    bound its multiplier (1.9) pressed it onto: complementarity was measured against
    lambda / rho, and rho had reached 1e9."""
    def build():
        prb, x, u = _single_integrator(20)
        x.set_bounds(0, 0, nodes=0)
        prb.create_cost("track", x - 1, weight=1.0)
        prb.create_cost("effort", u, weight=0.01)
        u.set_bounds(-0.5, 0.5)
        return prb

    ok_i, ipopt = _solve(build(), "ipopt")
    ok_l, ilqr = _solve(build(), "ilqr", {"input_bounds": input_bounds})
    assert ok_i
    u = np.abs(ilqr.solution["u"])
    if input_bounds != "lagrangian":  # the box keeps the bound exactly: the optimum
        assert ok_l, ilqr.stats.status
        assert ilqr.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-7)
    elif ok_l:  # within the complementarity tolerance of the bound (measured: 148
        # iterations, 4e-6 inside, cost 2.5e-6 above IPOPT's), never 1e-4 short of it
        assert np.max(0.5 - u[u > 0.45]) <= ilqr.opts["tol_complementarity"]
        assert ilqr.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-5)
    else:
        assert ilqr.stats.status == "max_iter reached"


def _two_inputs_alike(coefficient: float, integrator: str = "rk4"):
    """x'' = u0 + c u1 from rest to rest at 1 in 2 s: both final rows move through the one
    combination u0 + c u1 at node N-1, so they are dependent in the inputs there."""
    prb = Problem(40)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 2)
    prb.set_dynamics(cs.vertcat(x[1], u[0] + coefficient * u[1]))
    prb.set_dt(0.05)
    prb.transcribe("multiple_shooting", integrator=integrator)
    x.set_bounds([0, 0], [0, 0], nodes=0)
    prb.create_cost("effort", u, weight=0.01)
    prb.create_final_constraint("goal", x - [1.0, 0.0])
    return prb


@pytest.mark.parametrize("coefficient, codegen", [(1.0, False), (1.0, True), (0.5, True)])
def test_projected_rows_dependent_in_the_inputs_go_to_the_augmented_lagrangian(coefficient,
                                                                               codegen):
    """The final position and velocity were both projected onto node N-1's two inputs, whose
    Jacobian there has rank 1: the projection met them in the least-squares sense only, the
    augmented Lagrangian did not see them, and the solve stalled at max_iter with the goal
    97.5 % unmet (IPOPT and equality='lagrangian': 6 iterations). Now those rows go back to
    the augmented Lagrangian: 6 iterations, IPOPT's optimum."""
    ok_i, ipopt = _solve(_two_inputs_alike(coefficient), "ipopt")
    ok_l, ilqr = _solve(_two_inputs_alike(coefficient), "ilqr", {"codegen": codegen})
    assert ok_i and ok_l, ilqr.stats.status
    assert ilqr.stats.iterations <= 20
    assert ilqr.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-6)
    np.testing.assert_allclose(ilqr.solution["x"][:, -1], [1.0, 0.0], atol=1e-6)
    # the next call of the same solver starts from the projected layout again
    assert ilqr.solve() and ilqr.stats.iterations <= 3


def _unicycle_around_an_obstacle(N: int = 40, T: float = 4.0):
    """To (3, 0) in 4 s around a disc of radius 0.5 at (1.5, 0.05), |v| <= 1, |w| <= 1.5,
    from a guess that curves below it."""
    prb = Problem(N)
    p = prb.create_state_variable("p", 3)
    u = prb.create_input_variable("u", 2)
    prb.set_dynamics(cs.vertcat(u[0] * cs.cos(p[2]), u[0] * cs.sin(p[2]), u[1]))
    prb.set_dt(T / N)
    p.set_bounds([0, 0, 0], [0, 0, 0], nodes=0)
    u.set_bounds([-1.0, -1.5], [1.0, 1.5])
    prb.create_final_constraint("goal", p[:2] - [3.0, 0.0])
    prb.create_constraint("obstacle", (p[0] - 1.5) ** 2 + (p[1] - 0.05) ** 2,
                          nodes=range(1, N + 1), bounds=(0.25, np.inf))
    prb.create_cost("effort", u, weight=T / N)
    s = np.linspace(0, 1, N + 1)
    xs, ys = 3 * s, -0.8 * np.sin(np.pi * s)
    p.set_initial_guess(np.vstack([xs, ys, np.arctan2(np.gradient(ys), np.gradient(xs))]))
    u.set_initial_guess(np.vstack([np.full(N, 0.9), np.zeros(N)]))
    return prb, p


def test_a_receding_horizon_around_an_obstacle_converges_on_every_tick():
    """Shifted converging solves kept the penalties their predecessors raised: 4 of 12
    ticks ended at max_iter (a fresh solver from the same guess: 14-19 iterations). They now
    start from the initial penalties: 12 of 12 (15-136 iterations)."""
    prb, p = _unicycle_around_an_obstacle()
    solver = make_solver("ilqr", prb)
    assert solver.solve()
    rng = np.random.default_rng(0)
    for tick in range(12):
        x1 = solver.solution["p"][:, 1] + 0.01 * rng.standard_normal(3)
        solver.shift()
        p.set_bounds(x1, x1, nodes=0)
        assert solver.solve(), (tick, solver.stats.status)
        assert solver.stats.iterations <= 200


def _random_small_mpc(x0: np.ndarray):
    """An auditor's randomly generated MPC (seed 0 of their generator): a linear system of
    two positions, velocity bounds on a few nodes, input bounds fixed and one-sided, a final
    and a mid-horizon equality, a mixed inequality; infeasible from its first state."""
    inf = np.inf
    prb = Problem(7)
    q = prb.create_state_variable("q", 2)
    v = prb.create_state_variable("v", 2)
    a = prb.create_input_variable("a", 2)
    ref = prb.create_parameter("ref", 2)
    acc = cs.vertcat(
        -0.267835 * q[0] + 0.180798 * q[1] - 0.140747 * v[0] - 0.253084 * v[1]
        - 0.325031 * a[0] - 0.218792 * a[1],
        0.652 * q[0] + 0.47354 * q[1] - 0.124655 * v[0] - 0.0082652 * v[1]
        - 1.24591 * a[0] + 1.26773 * a[1]) + 0.1 * ref
    prb.set_dynamics(cs.vertcat(v, acc))
    prb.set_dt(0.05)
    q.set_bounds(x0[:2], x0[:2], nodes=0)
    v.set_bounds(x0[2:], x0[2:], nodes=0)
    a.set_bounds([[-3, -2, -3, -inf, -2, -3, 0.3], [-2, -2, -inf, -2, -2, -3, -inf]],
                 [[3, inf, 3, inf, inf, 3, 0.3], [inf, inf, inf, inf, inf, 3, 2]])
    v.set_bounds(-1.5, 1.5, nodes=[3, 5, 7])
    prb.create_cost("effort", a, weight=1.1859)
    prb.create_cost("track", q - ref, weight=2.0206)
    prb.create_final_constraint("goal", q[0] + 0.156961)
    prb.create_constraint("mid", v[0], nodes=[5])
    prb.create_constraint("ineq", q[0] + q[1] + 0.3 * a[0], nodes=[2, 3, 4, 5],
                          bounds=(-inf, 0.246854))
    ref.assign([[-0.644181, 0.197561, 0.214932, 0.348021, -0.592059, -0.330851, -0.218218,
                 -0.584901],
                [0.869684, -0.247955, 0.164485, -0.129286, 0.791736, 0.660180, 0.316676,
                 -1.101755]])
    return prb, q, v, ref


@pytest.mark.parametrize("opts", [{}, {"input_bounds": "lagrangian"}, {"input_bounds": "box"}])
def test_the_tick_after_an_infeasible_one_starts_without_its_multipliers(opts):
    """The multipliers an infeasible tick left below rho_max were kept as the next, feasible
    tick's warm start: it stopped at max_iter (cost 5440, violation 0.88) where a fresh
    solver from the same shifted guess converged in 28 iterations to IPOPT's 2806."""
    prb, q, v, ref = _random_small_mpc(np.array([-0.272129, -0.158150, 0.205815, 0.521257]))
    solver = make_solver("ilqr", prb, opts)
    assert not solver.solve()  # infeasible
    x1 = np.vstack([solver.solution["q"], solver.solution["v"]])[:, 1] + 0.02 * \
        np.random.default_rng(0).normal(size=4)
    solver.shift()
    q.set_bounds(x1[:2], x1[:2], nodes=0)
    v.set_bounds(x1[2:], x1[2:], nodes=0)
    values = ref.values.copy()
    values[:, -1] += 0.3
    ref.assign(values)
    guess = {n: prb.get_variable(n).initial_guess.copy() for n in ("q", "v", "a")}
    assert solver.solve(), solver.stats.status
    fresh, *_, fresh_ref = _random_small_mpc(x1)
    fresh_ref.assign(values)
    for name, value in guess.items():
        fresh.get_variable(name).set_initial_guess(value)
    ipopt = make_solver("ipopt", fresh)
    assert ipopt.solve()
    assert solver.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-5)


@pytest.mark.parametrize("opts", [{}, {"codegen": False}, {"equality": "lagrangian"},
                                  {"input_bounds": "box"}, {"line_search": False}])
def test_a_point_where_no_step_can_be_computed_is_never_called_converged(opts):
    """The guess is feasible and the linearisation NaN there: no step, so nothing is known
    about stationarity (it was 'converged' at iteration 1, unmoved, 12.5 above nothing)."""
    solver = make_solver("ilqr", double_integrator_with_a_nan_derivative_at_rest(), opts)
    assert solver.solve() is False
    assert solver.stats.status == "linearisation not finite (NaN/Inf) at every regularisation"
    rti = make_solver("ilqr", double_integrator_with_a_nan_derivative_at_rest(),
                      {**opts, "rti": True})
    assert rti.solve() is False and rti.stats.success is False


def test_a_resolve_after_an_infeasible_solve_starts_without_its_diverged_multipliers():
    """A state box that makes the final upright state unreachable: the solve fails, its
    final equality's multiplier blows up (1.7e11); with the box relaxed the same solver must
    reach the optimum as a fresh one does (it stopped at max_iter, cost 147.5, before)."""
    prb = pendulum_swing_up(5.0)
    x = prb.get_variable("x")
    solver = make_solver("ilqr", prb)
    x.set_bounds([-0.5, -np.inf], [0.5, np.inf], nodes=range(1, 60))
    assert not solver.solve()
    assert np.abs(solver._alN.lam).max() == 0.0  # forgotten: they were past rho_max
    x.set_bounds(-np.inf, np.inf, nodes=range(1, 60))
    assert solver.solve(), solver.stats.status
    fresh = make_solver("ilqr", pendulum_swing_up(5.0))
    assert fresh.solve()
    assert solver.stats.cost == pytest.approx(fresh.stats.cost, rel=1e-6)


def test_a_re_solve_after_moving_a_state_bound_parameter_converges_at_once():
    """A converged re-solve of an unchanged problem ended at max_iter (an extender's audit):
    a penalty raised to rho_max by the solve before sat on rows inactive at the warm start,
    a kink the Gauss-Newton model does not see, and every step was rejected. Rows inactive
    at the start of a plain re-solve get fresh multipliers and penalties."""
    N = 20
    prb = Problem(N)
    p = prb.create_state_variable("p", 1)
    v = prb.create_state_variable("v", 1)
    u = prb.create_input_variable("u", 1)
    wall = prb.create_parameter("wall", 1)
    prb.set_dynamics(cs.vertcat(v, u))
    prb.set_dt(0.05)
    prb.create_cost("track", p - 1.0, weight=10.0)
    prb.create_cost("effort", u, weight=0.01)
    prb.create_constraint("wall", p - wall, bounds=(-np.inf, 0.0))
    wall.assign(0.5)
    p.set_bounds(0, 0, nodes=0)
    v.set_bounds(0, 0, nodes=0)
    solver = make_solver("ilqr", prb)
    for change in (None, lambda: wall.assign(0.4), None,
                   lambda: wall.assign(0.45, nodes=range(10, N + 1)), None):
        if change is not None:
            change()
        solver.solve()
        assert solver.stats.success, solver.stats.status
    assert solver.stats.iterations <= 2  # the last: nothing changed since the solve before
    cost = solver.stats.cost
    reference = make_solver("ipopt", prb)
    reference.solve()
    assert cost == pytest.approx(reference.stats.cost, rel=1e-5)
