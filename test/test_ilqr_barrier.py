"""ILQR inequality rows through the relaxed log barrier (``inequality='barrier'``)."""

import numpy as np
import pytest
from ocps import pendulum_swing_up

from horizon_mpc import make_solver
from horizon_mpc.solvers.ilqr.lagrangian import AugmentedLagrangian, relaxed_barrier


@pytest.mark.parametrize("mu, delta", [(1.0, 1.0), (0.1, 5.0), (1e-3, 1e-2)])
def test_relaxed_barrier_is_twice_continuous_with_exact_derivatives(mu, delta):
    h = np.linspace(-3 * delta, 6 * delta, 2001)
    b, d1, d2 = relaxed_barrier(h, mu, delta)
    assert np.all(np.isfinite(b)) and np.all(d2 > 0)
    eps = 1e-6 * delta
    bp, d1p, _ = relaxed_barrier(h + eps, mu, delta)
    bm, d1m, _ = relaxed_barrier(h - eps, mu, delta)
    np.testing.assert_allclose((bp - bm) / (2 * eps), d1, rtol=1e-5, atol=1e-6 * mu / delta)
    np.testing.assert_allclose((d1p - d1m) / (2 * eps), d2, rtol=1e-4,
                               atol=1e-6 * mu / delta ** 2)
    # the two pieces meet with equal value, slope and curvature at h = delta
    inside = relaxed_barrier(np.array([delta * (1 + 1e-12)]), mu, delta)
    outside = relaxed_barrier(np.array([delta]), mu, delta)
    for a, c in zip(inside, outside, strict=True):
        np.testing.assert_allclose(a, c, rtol=1e-9, atol=1e-9 * mu / delta ** 2)
    assert outside[0][0] == 0.0
    # a log barrier inside, growing without bound towards (and past) the bound
    np.testing.assert_allclose(relaxed_barrier(np.array([3 * delta]), mu, delta)[0],
                               -mu * np.log(3.0))
    assert b[0] > b[len(h) // 2] > b[-1]


def test_barrier_rows_get_the_newton_model_of_their_barrier():
    rng = np.random.default_rng(3)
    lb = np.array([[-1.0, -np.inf, 0.5, 2.0, -np.inf]] * 4)
    ub = np.array([[np.inf, 1.0, 3.0, 2.0, np.inf]] * 4)
    al = AugmentedLagrangian(lb, ub, 100.0, inequality="barrier", barrier_mu=0.5,
                             barrier_delta=0.3)
    c = rng.uniform(-2.0, 4.0, size=lb.shape)
    w, t = al.weights_targets(c)

    def total(cc):
        return al.value(cc)

    eps = 1e-4
    for k in range(c.shape[0]):
        for j in (0, 1, 2):  # lower, upper, both: gradient and curvature of the model
            e = np.zeros_like(c)
            e[k, j] = eps
            g = (total(c + e) - total(c - e)) / (2 * eps)
            hess = (total(c + e) - 2 * total(c) + total(c - e)) / eps ** 2
            np.testing.assert_allclose(2 * w[k, j] * (c[k, j] - t[k, j]), g, rtol=1e-5,
                                       atol=1e-7)
            np.testing.assert_allclose(2 * w[k, j], hess, rtol=1e-3, atol=1e-5)
    # the equality row keeps the augmented Lagrangian; a free row has no term at all
    np.testing.assert_array_equal(w[:, 3], 50.0)
    np.testing.assert_array_equal(w[:, 4], 0.0)
    # barrier rows carry no multipliers and no penalty growth
    al.update(c, 10.0, 1e9)
    assert not al.lam_lo.any() and not al.lam_up.any()
    assert np.all(al.rho[:, :3] == 100.0)


def test_the_reused_barrier_terms_follow_the_rows_values_bounds_and_parameters():
    """The last barrier evaluation is reused for equal input only: a row changed in place,
    new bounds or a new barrier weight give fresh terms."""
    lb = np.array([[-1.0, 0.0, -np.inf]] * 3)
    ub = np.array([[1.0, np.inf, 0.5]] * 3)
    al = AugmentedLagrangian(lb, ub, 10.0, inequality="barrier")

    def fresh(c, lb=lb, ub=ub, mu=1.0):
        return AugmentedLagrangian(lb, ub, 10.0, inequality="barrier", barrier_mu=mu).value(c)

    c = np.full((3, 3), 0.2)
    assert al.value(c) == fresh(c)
    c[1, 1] = -0.7  # in place
    assert al.value(c) == fresh(c)
    w, t = al.weights_targets(c)
    w2, t2 = AugmentedLagrangian(lb, ub, 10.0, inequality="barrier").weights_targets(c)
    np.testing.assert_array_equal(w, w2)
    np.testing.assert_array_equal(t, t2)
    lb2 = lb.copy()
    lb2[:, 0] = -0.5
    al.set_bounds(lb2, ub)
    assert al.value(c) == fresh(c, lb=lb2)
    al.mu = 0.1
    assert al.value(c) == fresh(c, lb=lb2, mu=0.1)


def test_the_multiplier_update_of_barrier_rows_has_nothing_to_do_but_for_equalities():
    """Barrier rows carry no multiplier nor penalty: with no equality row the update says
    so (the caller keeps the terms' value); an equality row gets its multiplier, and a row
    that becomes an equality starts without a progress history (no penalty raise yet)."""
    lb = np.array([[-1.0, 0.0]] * 2)
    ub = np.array([[1.0, np.inf]] * 2)
    al = AugmentedLagrangian(lb, ub, 10.0, inequality="barrier")
    c = np.array([[2.0, -1.0]] * 2)  # both rows violated
    before = al.value(c)
    assert al.update(c, 10.0, 1e6) is False
    assert al.value(c) == before and not al.lam.any() and np.all(al.rho == 10.0)
    lb2, ub2 = lb.copy(), ub.copy()
    lb2[:, 1] = ub2[:, 1] = 0.5  # row 1 becomes an equality
    al.set_bounds(lb2, ub2)
    assert al.update(c, 10.0, 1e6) is True
    np.testing.assert_allclose(al.lam[:, 1], 10.0 * (-1.0 - 0.5))
    assert np.all(al.rho == 10.0)  # its first update: no history to compare with
    assert al.update(c, 10.0, 1e6) is True  # no progress since: the penalty rises
    np.testing.assert_allclose(al.rho[:, 1], 100.0)
    np.testing.assert_allclose(al.rho[:, 0], 10.0)  # the barrier row keeps its own


def test_unknown_inequality_mode_and_bad_barrier_parameters_are_refused():
    lb, ub = np.zeros((2, 1)), np.ones((2, 1))
    with pytest.raises(ValueError, match="inequality"):
        AugmentedLagrangian(lb, ub, 1.0, inequality="penalty")
    with pytest.raises(ValueError, match="barrier_mu"):
        AugmentedLagrangian(lb, ub, 1.0, inequality="barrier", barrier_delta=0.0)


def test_a_small_barrier_approaches_the_augmented_lagrangian_optimum():
    u_max = 6.0
    al = make_solver("ilqr", pendulum_swing_up(u_max), {"codegen": False, "max_iter": 400})
    assert al.solve()
    bar = make_solver("ilqr", pendulum_swing_up(u_max), {
        "codegen": False, "max_iter": 400, "inequality": "barrier", "barrier_mu": 1e-3,
        "barrier_delta": 1e-2})
    assert bar.solve(), bar.stats.status
    # the final equality is still exact; the bound is met within the relaxation slack and
    # the barrier's interior solution costs a little more than the exact optimum
    assert bar.stats.constraint_violation <= 1e-6
    u = bar.solution["u"]
    assert np.max(np.abs(u)) <= u_max
    assert np.max(np.abs(u)) > u_max - 0.5  # the bound is pressed: the barrier is at work
    assert al.stats.cost <= bar.stats.cost <= 1.02 * al.stats.cost


def test_a_large_barrier_keeps_the_solution_away_from_the_bound():
    u_max = 6.0
    weak = make_solver("ilqr", pendulum_swing_up(u_max), {
        "codegen": False, "max_iter": 400, "inequality": "barrier", "barrier_mu": 1e-3,
        "barrier_delta": 1e-2})
    strong = make_solver("ilqr", pendulum_swing_up(u_max), {
        "codegen": False, "max_iter": 400, "inequality": "barrier", "barrier_mu": 1.0,
        "barrier_delta": 1.0})
    assert weak.solve() and strong.solve()
    assert np.max(np.abs(strong.solution["u"])) < np.max(np.abs(weak.solution["u"]))


@pytest.mark.parametrize("mode", ["barrier", "lagrangian"])
def test_the_compiled_rows_match_numpy_in_both_modes(mode):
    """AugmentedLagrangian in one compiled pass (riccati_c.AlRowsKernel) against its numpy
    path: equalities, one- and two-sided rows, rows without bounds, active and inactive
    multipliers, values inside and past the barrier's relaxation."""
    from horizon_mpc.solvers.ilqr import riccati_c

    if not riccati_c.available():
        pytest.skip("no compiled library (no C compiler or HORIZON_MPC_NO_CODEGEN)")
    rng = np.random.default_rng(11)
    lb = rng.normal(size=(9, 13))
    ub = lb + rng.uniform(0.1, 2.0, size=lb.shape)
    ub[0] = lb[0]  # equalities
    lb[1, :6] = -np.inf  # upper sides only
    ub[2, :5] = np.inf  # lower sides only
    lb[3], ub[3] = -np.inf, np.inf  # no bound
    c = 2.0 * rng.normal(size=lb.shape)
    kw = dict(inequality=mode, barrier_mu=0.3, barrier_delta=0.2)
    fast = AugmentedLagrangian(lb, ub, 10.0, **kw)
    ref = AugmentedLagrangian(lb, ub, 10.0, compiled=False, **kw)
    assert fast.compiled and not ref.compiled
    for al in (fast, ref):  # multipliers and penalties of every kind of row
        al.update(c + 0.3, 10.0, 1e6)
        al.update(c, 10.0, 1e6)
    np.testing.assert_array_equal(fast.rho, ref.rho)
    value, viol = fast.value_and_violation(c)
    np.testing.assert_allclose(value, ref.value(c), rtol=1e-13)
    assert fast.value(c) == value
    assert viol == ref.violation(c).max() > 0.0
    for a, b in zip(fast.weights_targets(c), ref.weights_targets(c), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-15)
    # the kernel reads the multipliers in place: a shift shows at once
    fast.shift()
    ref.shift()
    np.testing.assert_allclose(fast.value(c), ref.value(c), rtol=1e-13)
    with pytest.raises(ValueError, match="the rows have shape"):
        fast.set_bounds(lb[:3], ub[:3])


def test_a_solved_barrier_problem_stops_instead_of_running_to_max_iter():
    # the barrier's optimum leaves bound rows past their bounds (its relaxation): the
    # solve ran all of max_iter (1000) with an expected decrease of 1e-13
    from ocps import pendulum_swing_up

    from horizon_mpc import make_solver

    solver = make_solver("ilqr", pendulum_swing_up(4.0), {
        "inequality": "barrier", "barrier_mu": 1e-2, "barrier_delta": 1e-2, "max_iter": 500})
    solver.solve()
    st = solver.stats
    if st.constraint_violation > solver.opts["tol_constraint"]:
        assert st.status.startswith("stationary: the barrier's optimum") and not st.success
    else:
        assert st.success
    assert st.iterations < 500


def test_an_infeasible_fixed_initial_state_is_said_so_with_the_barrier_too():
    """The barrier's 'stationary: ... rows past their bounds' was reported for a node 0 no
    relaxation makes feasible (the augmented Lagrangian said infeasible; session 28)."""
    import casadi as cs

    from horizon_mpc.problem import Problem

    statuses = {}
    for mode in ("lagrangian", "barrier"):
        prb = Problem(30)
        x = prb.create_state_variable("x", 2)
        u = prb.create_input_variable("u", 1)
        prb.set_dynamics(cs.vertcat(x[1], u))
        prb.set_dt(0.05)
        x.set_bounds([0.0, 1.0], [0.0, 1.0], nodes=0)  # v0 = 1 beyond |v| <= 0.5
        prb.create_constraint("speed", x[1], bounds=(-0.5, 0.5))
        prb.create_cost("effort", u, weight=0.1)
        prb.create_final_cost("goal", x - [1.0, 0.0], weight=10.0)
        solver = make_solver("ilqr", prb, {"inequality": mode})
        assert not solver.solve()
        statuses[mode] = solver.stats.status
    assert statuses == dict.fromkeys(
        statuses, "infeasible: the fixed initial state violates constraints at node 0")
