"""ILQR with box-constrained inputs (option ``input_bounds='box'``): the box QP, the
backward pass and rollout in numpy and C, and a receding horizon whose input bound is
active."""

import casadi as cs
import numpy as np
import pytest
from ocps import planar_double_integrator_at_rest
from scipy.optimize import minimize

from horizon_mpc import Problem, make_solver
from horizon_mpc.examples import build_cartpole, pendulum_dynamics
from horizon_mpc.solvers.ilqr import riccati, riccati_c


def _qp_reference(H, q, lo, hi):
    res = minimize(lambda z: 0.5 * z @ H @ z + q @ z, np.clip(np.zeros(len(q)), lo, hi),
                   jac=lambda z: H @ z + q, bounds=list(zip(lo, hi, strict=True)),
                   method="L-BFGS-B", options={"ftol": 1e-15, "gtol": 1e-13, "maxiter": 1000})
    return res.x


@pytest.mark.parametrize("seed", range(6))
def test_box_qp_matches_a_bounded_quasi_newton_reference(seed):
    rng = np.random.default_rng(seed)
    n = 5
    L = rng.standard_normal((n, n))
    H = L @ L.T + 0.1 * np.eye(n)
    q = 3.0 * rng.standard_normal(n)
    lo, hi = -rng.uniform(0.0, 1.0, n), rng.uniform(0.0, 1.0, n)
    lo[0], hi[1] = -np.inf, np.inf  # one-sided and unbounded inputs too
    x, free, chol = riccati.box_qp(H, q, lo, hi)
    np.testing.assert_allclose(x, _qp_reference(H, q, lo, hi), atol=1e-6)
    assert np.all(x >= lo) and np.all(x <= hi)
    g = H @ x + q
    # KKT: stationary on the free inputs, the gradient pushes the clamped ones outwards
    np.testing.assert_allclose(g[free], 0.0, atol=1e-10)
    assert np.all(((x <= lo) & (g >= 0)) | ((x >= hi) & (g <= 0)) | free)
    assert (chol is None) == (not free.any())


def test_box_qp_keeps_fixed_inputs_and_refuses_an_indefinite_free_block():
    H, q = np.eye(2), np.array([1.0, -1.0])
    x, free, _ = riccati.box_qp(H, q, np.array([0.3, -1.0]), np.array([0.3, 1.0]))
    np.testing.assert_allclose(x, [0.3, 1.0])  # input 0 fixed; input 1 at the unconstrained 1
    assert free.tolist() == [False, True]
    assert riccati.box_qp(-np.eye(2), np.zeros(2), -np.ones(2), np.ones(2)) is None


def _lq_data(seed, N=6, ndx=5, nu=3):
    rng = np.random.default_rng(seed)
    A = np.eye(ndx) + 0.1 * rng.standard_normal((N, ndx, ndx))
    B = rng.standard_normal((N, ndx, nu))
    L = rng.standard_normal((N, ndx + nu, ndx + nu))
    H = np.einsum("kij,kil->kjl", L, L) + 0.1 * np.eye(ndx + nu)
    lo, hi = np.full((N, nu), -0.3), np.full((N, nu), 0.2)
    if N > 3:
        lo[2], hi[2] = -np.inf, np.inf  # a node without box: the plain recursion
        lo[3, 1] = hi[3, 1] = 0.05  # a fixed input
    args = (A, B, rng.standard_normal((N, ndx)), 5.0 * rng.standard_normal((N, nu)),
            H[:, :ndx, :ndx].copy(), H[:, ndx:, ndx:].copy(), H[:, ndx:, :ndx].copy(),
            0.1 * rng.standard_normal((N, ndx)), rng.standard_normal(ndx), np.eye(ndx), 1e-8)
    return args, (lo, hi), rng.standard_normal(ndx)


@pytest.mark.skipif(not riccati_c.available(), reason="no C compiler")
@pytest.mark.parametrize("seed", range(3))
def test_compiled_box_backward_and_rollout_match_numpy(seed):
    args, box, dx0 = _lq_data(seed)
    bn = riccati.backward_pass(*args, box=box)
    bc = riccati_c.backward_pass_c(*args, box=box)
    for name in ("K", "k", "S", "s"):
        np.testing.assert_allclose(getattr(bc, name), getattr(bn, name), atol=1e-10)
    A, B, f = args[0], args[1], args[7]
    Xn, Un = riccati.linear_rollout(A, B, f, bn, dx0, box=box)
    Xc, Uc = riccati_c.linear_rollout_c(A, B, f, bc, dx0, box=box)
    np.testing.assert_allclose(Xc, Xn, atol=1e-10)
    np.testing.assert_allclose(Uc, Un, atol=1e-10)
    lo, hi = box
    assert np.all(Un >= lo) and np.all(Un <= hi)
    assert np.abs(Un[2]).max() > 0.3  # the node without a box is not clamped


def test_box_value_function_is_the_cost_to_go_of_the_clamped_policy():
    """One node: S, s of the box pass equal the Q-function evaluated along du = K dx + k."""
    args, box, _ = _lq_data(1, N=1)
    A, B, lx, lu, lxx, luu, lux, f, lxN, lxxN, mu = args
    bw = riccati.backward_pass(*args, box=box)
    g = lxN + lxxN @ f[0]
    Qx, Qu = lx[0] + A[0].T @ g, lu[0] + B[0].T @ g
    Qxx = lxx[0] + A[0].T @ lxxN @ A[0]
    Quu = luu[0] + B[0].T @ lxxN @ B[0] + mu * np.eye(B.shape[2])
    Qux = lux[0] + B[0].T @ lxxN @ A[0]
    K, k = bw.K[0], bw.k[0]
    S = Qxx + K.T @ Quu @ K + K.T @ Qux + Qux.T @ K
    np.testing.assert_allclose(bw.S[0], 0.5 * (S + S.T), atol=1e-10)
    np.testing.assert_allclose(bw.s[0], Qx + K.T @ (Quu @ k + Qu) + Qux.T @ k, atol=1e-10)


def _pendulum_mpc(u_max=4.0, N=30, u_min=None):
    """Pendulum tracking the angle parameter ``ref``, with ``u_min <= u <= u_max``
    (``u_min`` default ``-u_max``)."""
    prb = Problem(N)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    ref = prb.create_parameter("ref", 1)
    prb.set_dynamics(cs.vertcat(x[1], pendulum_dynamics(x[0], x[1], u)))
    prb.set_dt(0.05)
    u.set_bounds(-u_max if u_min is None else u_min, u_max)
    prb.create_cost("track", x[0] - ref, weight=5.0)
    prb.create_cost("velocity", x[1], weight=0.1)
    prb.create_cost("effort", u, weight=0.01)
    return prb, x, ref


@pytest.mark.slow
def test_receding_horizon_with_an_active_input_bound_converges_on_every_tick():
    """25 ticks of a pendulum MPC whose torque limit is active at the steps of the
    reference: with the box every solve converges to IPOPT's optimum (with the augmented
    Lagrangian, 4 of these 25 ended at max_iter)."""
    u_max = 4.0
    prb, x, ref = _pendulum_mpc(u_max)
    ilqr = make_solver("ilqr", prb, {"input_bounds": "box", "max_iter": 100})
    F = prb.discrete_dynamics()
    state, active = np.zeros(2), 0
    for t in range(25):
        r = 0.8 if t < 12 else -0.5
        x.set_bounds(state, state, nodes=0)
        ref.assign(r)
        assert ilqr.solve(), (t, ilqr.stats.status)
        assert ilqr.stats.iterations <= 15
        u = ilqr.solution["u"]
        assert np.abs(u).max() <= u_max + 1e-12
        active += int(np.isclose(np.abs(u).max(), u_max))
        cold, xc, rc = _pendulum_mpc(u_max)
        xc.set_bounds(state, state, nodes=0)
        xc.set_initial_guess(state[:, None])
        rc.assign(r)
        ipopt = make_solver("ipopt", cold)
        assert ipopt.solve()
        assert abs(ilqr.stats.cost - ipopt.stats.cost) <= 1e-6 * ipopt.stats.cost
        state = F(state, u[:, 0], [], []).full().ravel()
        ilqr.shift()
    assert active >= 5  # the bound mattered


def test_every_real_time_iterate_stays_within_the_input_bounds():
    prb, x, ref = _pendulum_mpc(2.0)
    x.set_bounds([0.5, 0.0], [0.5, 0.0], nodes=0)
    ref.assign(-0.8)
    prb.inputs[0].set_initial_guess(np.full((1, 30), 3.0))  # outside: clipped into the box
    solver = make_solver("ilqr", prb, {"input_bounds": "box", "rti": True})
    for _ in range(5):
        solver.solve()
        u = solver.solution["u"]
        assert np.abs(u).max() <= 2.0 + 1e-12
        prb.inputs[0].set_initial_guess(u)
    assert np.isclose(np.abs(u).max(), 2.0)  # the bound is active


@pytest.mark.skipif(not riccati_c.available(), reason="no C compiler")
def test_compiled_and_numpy_box_solves_agree():
    sols = []
    for codegen in (False, True):
        prb, x, ref = _pendulum_mpc(3.0)
        x.set_bounds([0.0, 0.0], [0.0, 0.0], nodes=0)
        ref.assign(1.0)
        solver = make_solver("ilqr", prb, {"input_bounds": "box", "codegen": codegen})
        assert solver.solve()
        sols.append((solver.stats.iterations, solver.solution["u"]))
    assert sols[0][0] == sols[1][0]
    np.testing.assert_allclose(sols[0][1], sols[1][1], atol=1e-8)


def test_input_bounds_option_is_checked():
    prb, _, _ = _pendulum_mpc()
    with pytest.raises(ValueError, match="input_bounds"):
        make_solver("ilqr", prb, {"input_bounds": "clip"})


def _coupled_inputs():
    """Linear dynamics, quadratic cost, linear constraints (one optimum): two input
    variables with bounds active at the optimum, an input equality (projected) on nodes
    5-11, where the bounds stay with the augmented Lagrangian."""
    prb = Problem(20)
    x = prb.create_state_variable("x", 2)
    v = prb.create_state_variable("v", 2)
    a = prb.create_input_variable("a", 1)
    b = prb.create_input_variable("b", 2)
    prb.set_dynamics(cs.vertcat(v, a[0] + b[0], b[1] - 0.5 * a[0]))
    prb.set_dt(0.05)
    x.set_bounds([0, 0], [0, 0], nodes=0)
    v.set_bounds([0, 0], [0, 0], nodes=0)
    prb.create_cost("goal", x - np.array([1.0, -0.7]), weight=10.0)
    prb.create_cost("velocity", v, weight=0.1)
    prb.create_cost("effort_a", a, weight=0.01)
    prb.create_cost("effort_b", b, weight=0.02)
    a.set_bounds(-0.4, 0.4)
    b.set_bounds(-0.5, 0.5)
    prb.create_constraint("couple", a[0] - b[1], nodes=range(5, 12))
    return prb


def test_converged_means_complementary_multipliers_too():
    """The box solve stopped here once, 'converged' 1.1e-4 above IPOPT's optimum: stationary
    and feasible, but with the bounds of the projected nodes 1.3e-3 short of active while
    their multipliers pressed them away."""
    ipopt = make_solver("ipopt", _coupled_inputs())
    assert ipopt.solve()
    ilqr = make_solver("ilqr", _coupled_inputs(), {"input_bounds": "box", "max_iter": 100})
    assert ilqr.solve(), ilqr.stats.status
    assert abs(ilqr.stats.cost - ipopt.stats.cost) <= 1e-7 * ipopt.stats.cost
    for name in ("a", "b"):
        np.testing.assert_allclose(ilqr.solution[name], ipopt.solution[name], atol=1e-5)


@pytest.mark.slow
def test_a_one_sided_bound_active_over_an_unstable_stretch_converges():
    """Pendulum driven upright with only u >= -3: the box iterates kept the bound active
    over most of the horizon, the clamped policy's costates reached ~1e5 and a merit weight
    that only grew within the call rejected every later step (max_iter at cost 550)."""
    def build():
        prb, x, ref = _pendulum_mpc(np.inf, N=60, u_min=-3.0)
        x.set_bounds([0, 0], [0, 0], nodes=0)
        ref.assign(np.pi)
        return prb

    ipopt = make_solver("ipopt", build())
    assert ipopt.solve()
    ilqr = make_solver("ilqr", build(), {"input_bounds": "box", "max_iter": 400})
    assert ilqr.solve(), ilqr.stats.status
    assert abs(ilqr.stats.cost - ipopt.stats.cost) <= 1e-6 * ipopt.stats.cost
    assert ilqr.solution["u"].min() >= -3.0


def _swing_up(u_max: float, final: str = "constraint"):
    """Pendulum from rest down to rest upright in 3 s (60 intervals), |u| <= u_max: the
    bound is active over the pumping swings (IPOPT's optimum at u_max 5: 74.35111)."""
    prb = Problem(60)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(x[1], pendulum_dynamics(x[0], x[1], u)))
    prb.set_dt(0.05)
    x.set_bounds([0, 0], [0, 0], nodes=0)
    u.set_bounds(-u_max, u_max)
    prb.create_cost("effort", u, weight=0.1)
    if final == "constraint":
        prb.create_final_constraint("upright", x - [np.pi, 0])
    else:
        prb.create_final_cost("upright", x - [np.pi, 0], weight=100.0)
    return prb


@pytest.mark.parametrize("build", [
    lambda: _swing_up(4.5), lambda: _swing_up(5.0), lambda: _swing_up(5.0, final="cost"),
    lambda: build_cartpole(100, u_max=12.0, cart_limit=0.5)[0],
], ids=["swing_up_4.5", "swing_up_5", "swing_up_5_final_cost", "cartpole"])
def test_the_default_input_bounds_converge_to_ipopts_optimum_with_active_bounds(build):
    """input_bounds='auto': the augmented Lagrangian alone ended these at max_iter 300
    (swing-ups 1-4 % above the optimum or 3e-2 violation) or, the cart-pole, at another
    local optimum (105.711 against 105.604); the box alone failed
    the cart-pole (its first clamped steps from the cold guess: violation 3). Lagrangian for
    20 iterations, then the box from there: IPOPT's optimum in 44-162 iterations."""
    ipopt = make_solver("ipopt", build())
    assert ipopt.solve()
    ilqr = make_solver("ilqr", build())
    assert ilqr.opts["input_bounds"] == "auto"
    assert ilqr.solve(), ilqr.stats.status
    assert ilqr.stats.extra["box_from"] == 20
    assert ilqr.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-6)
    assert ilqr.stats.constraint_violation <= 1e-6
    u = ilqr.solution["u"]
    assert np.all(u >= build().inputs[0].lower_bounds - 1e-12)


def test_auto_input_bounds_stay_with_the_lagrangian_in_real_time_and_with_the_barrier():
    fast = make_solver("ilqr", _swing_up(5.0), {"max_iter": 25})
    slow = [make_solver("ilqr", _swing_up(5.0), {"rti": True, "iterations_per_call": 25}),
            make_solver("ilqr", _swing_up(5.0), {"inequality": "barrier", "max_iter": 25})]
    fast.solve()
    assert fast.stats.extra["box_from"] == 20
    for solver in slow:
        solver.solve()
        assert "box_from" not in solver.stats.extra


def _waypoint_with_bounded_inputs():
    """A planar double integrator tracking (1, -0.5) through the waypoint (0.5, 0.5) at node
    10 of 30, |u| <= 2: the waypoint's rows, moved onto node 9's inputs, ask 100x the bound
    of them in one step."""
    prb, p, v, u = planar_double_integrator_at_rest(30)
    u.set_bounds([-2, -2], [2, 2])
    prb.create_cost("track", p - [1.0, -0.5], weight=10.0)
    prb.create_cost("effort", u, weight=0.01)
    prb.create_constraint("waypoint", p - [0.5, 0.5], nodes=[10])
    return prb


@pytest.mark.parametrize("input_bounds", ["auto", "box"])
def test_rows_are_not_projected_onto_bounded_inputs_in_a_converging_solve(input_bounds):
    """The projection pinned node 9's inputs to what meets the waypoint in one step and the
    bound pulled them back: max_iter in every mode, 21 % above IPOPT (a QA finding; GN-SQP
    solves this linear-quadratic problem in one iteration). Now those rows are in the
    augmented Lagrangian: 128 ('auto') and 48 ('box') iterations, IPOPT's optimum."""
    ipopt = make_solver("ipopt", _waypoint_with_bounded_inputs())
    assert ipopt.solve()
    ilqr = make_solver("ilqr", _waypoint_with_bounded_inputs(), {"input_bounds": input_bounds})
    assert ilqr.solve(), ilqr.stats.status
    assert ilqr.stats.cost == pytest.approx(ipopt.stats.cost, rel=1e-6)
    assert np.abs(ilqr.solution["u"]).max() <= 2.0 + 1e-9


def test_auto_goes_on_with_the_box_in_the_next_converging_calls():
    """A re-solve from the optimum of an 'auto' solve that switched took the 20
    augmented-Lagrangian iterations again (23 in all, the cost rising on the way)."""
    solver = make_solver("ilqr", _swing_up(5.0))
    assert solver.solve() and solver.stats.extra["box_from"] == 20
    cost = solver.stats.cost
    assert solver.solve() and solver.stats.extra["box_from"] == 0
    assert solver.stats.iterations <= 2
    assert solver.stats.cost == pytest.approx(cost, rel=1e-8)


def test_a_converging_call_from_another_guess_starts_without_the_kept_box():
    """The box an 'auto' solve went on with was kept for every later converging call: a
    cart-pole solved from its guess in 78 iterations ended at max_iter, 4x the cost and
    violation 10, when solved again from the same guess (a QA finding). The box is kept for
    the call's own warm start (solution written back, or shifted) only."""
    prb, var = build_cartpole(60, cart_limit=1.0, u_max=30.0, w_velocity=0.0,
                              w_effort=2.0)
    guess = {name: v.initial_guess for name, v in var.items()}
    solver = make_solver("ilqr", prb)
    assert solver.solve() and solver.stats.extra["box_from"] == 20, solver.stats.status
    cost = solver.stats.cost
    assert solver.solve() and solver.stats.extra["box_from"] == 0  # its own warm start
    assert solver.stats.iterations <= 2
    for name, v in var.items():  # the guess the first solve started from
        v.set_initial_guess(guess[name])
    assert solver.solve(), solver.stats.status
    assert solver.stats.extra["box_from"] == 20
    assert solver.stats.cost == pytest.approx(cost, rel=1e-6)
    solver.shift()  # the solution shifted is still the solver's own warm start
    assert solver.solve() and solver.stats.extra["box_from"] == 0
