"""The NLP built from a Problem: layout, bounds, weights, node masks, offsets, collocation."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pytest

from horizon_mpc.examples import build_double_integrator, double_integrator_optimum
from horizon_mpc.problem import Problem
from horizon_mpc.problem.transcription import Transcription, collocation_coefficients

N = 6


def small_problem(method: str = "multiple_shooting") -> tuple[Problem, dict]:
    """Two states, one input, one parameter, a rate cost and a box constraint."""
    prb = Problem(N)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    r = prb.create_parameter("r", 1)
    prb.set_dynamics(cs.vertcat(x[1], u - x[0]))
    prb.set_dt(0.1)
    if method == "direct_collocation":
        prb.transcribe(method, degree=2)
    else:
        prb.transcribe(method, integrator="rk4")
    prb.create_cost("track", x[0] - r, weight=4.0)
    prb.create_cost("rate", u - u.offset(-1), nodes=range(2, N), weight=9.0)
    prb.create_constraint("box", x[1] + u, nodes=[1, 3], bounds=(-1.0, 2.0))
    return prb, {"x": x, "u": u, "r": r}


def test_decision_vector_layout_is_states_then_inputs_then_singles():
    prb, _ = small_problem()
    tr = Transcription(prb)
    assert tr.nw == 2 * (N + 1) + 1 * N
    w = np.arange(tr.nw, dtype=float)
    X, U, S = tr.unpack(w)
    assert X.shape == (2, N + 1) and U.shape == (1, N) and S.shape == (0, 1)
    np.testing.assert_array_equal(X[:, 1], [2.0, 3.0])  # column-major, one column per node
    np.testing.assert_array_equal(U[0, :2], [14.0, 15.0])


def test_cost_is_weighted_sum_of_squares_with_shifted_offsets():
    prb, v = small_problem()
    v["r"].assign(0.5)
    tr = Transcription(prb)
    rng = np.random.default_rng(0)
    w = rng.normal(size=tr.nw)
    X, U, _ = tr.unpack(w)
    f = float(cs.Function("f", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["f"]])(w, tr.parameters()))
    expected = 4.0 * np.sum((X[0] - 0.5) ** 2) + 9.0 * np.sum((U[0, 2:] - U[0, 1:-1]) ** 2)
    assert f == pytest.approx(expected, rel=1e-12)


def test_residual_squared_is_the_cost():
    prb, _ = small_problem()
    tr = Transcription(prb)
    w = np.random.default_rng(1).normal(size=tr.nw)
    F = cs.Function("F", [tr.nlp["x"], tr.nlp["p"]], [tr.nlp["f"], cs.sumsqr(tr.residual)])
    f, rr = F(w, tr.parameters())
    assert float(f) == pytest.approx(float(rr), rel=1e-12)


def test_inactive_constraint_nodes_are_unbounded_and_active_ones_bounded():
    prb, _ = small_problem()
    tr = Transcription(prb)
    lbg, ubg = tr.bounds_g()
    block = tr.g_blocks[1]  # 'box' on its valid nodes 0..N-1 (it uses an input)
    assert block.name == "box" and block.cols == N
    lb, ub = lbg[block.start:block.stop], ubg[block.start:block.stop]
    np.testing.assert_array_equal(np.flatnonzero(np.isfinite(lb)), [1, 3])
    assert lb[1] == -1.0 and ub[3] == 2.0
    dyn = tr.g_blocks[0]
    assert np.all(lbg[dyn.start:dyn.stop] == 0) and np.all(ubg[dyn.start:dyn.stop] == 0)


def test_weights_and_node_masks_are_numeric_parameters():
    prb, _ = small_problem()
    tr = Transcription(prb)
    p0 = tr.parameters()
    prb.get_term("track").set_weight(16.0)
    prb.get_term("track").set_nodes([0, N])
    p1 = tr.parameters()
    block = tr.p_blocks[1]
    np.testing.assert_array_equal(p0[block.start:block.stop], np.full(N + 1, 2.0))
    np.testing.assert_array_equal(p1[block.start:block.stop], [4.0, 0, 0, 0, 0, 0, 4.0])


def test_variable_bounds_and_initial_guess_follow_the_variables():
    prb, v = small_problem()
    v["x"].set_bounds([0.0, -1.0], [0.0, 1.0], nodes=0)
    v["u"].set_initial_guess(3.0)
    tr = Transcription(prb)
    lbx, ubx = tr.bounds_w()
    assert lbx[:2].tolist() == [0.0, -1.0] and ubx[:2].tolist() == [0.0, 1.0]
    assert np.all(np.isinf(lbx[2:]))
    _, U, _ = tr.unpack(tr.initial_w())
    assert np.all(U == 3.0)


def test_shift_vector_moves_node_blocks_back_and_keeps_singles():
    prb = Problem(3)
    x = prb.create_state_variable("x", 1)
    prb.create_input_variable("u", 1)
    prb.create_single_variable("T", 1)
    prb.set_dynamics(x)
    prb.set_dt(0.1)
    tr = Transcription(prb)
    w = np.arange(tr.nw, dtype=float)  # X = 0..3, U = 4..6, S = 7
    np.testing.assert_array_equal(tr.shift_vector(w, tr.w_blocks), [1, 2, 3, 3, 5, 6, 6, 7])


def test_node_order_is_a_stagewise_permutation():
    prb, _ = small_problem("direct_collocation")
    tr = Transcription(prb)
    pw, pg = tr.node_order()
    assert sorted(pw) == list(range(tr.nw)) and sorted(pg) == list(range(tr.ng))
    nx, d = 2, 2
    # x_0, then u_0 (index nx*(N+1)), then the collocation states of interval 0
    assert pw[:nx].tolist() == [0, 1] and pw[nx] == nx * (N + 1)
    assert pw[nx + 1] == tr.w_blocks[3].start and pw[nx + 1 + nx * d] == 2


def test_collocation_coefficients_differentiate_and_extrapolate_polynomials():
    for degree in (1, 2, 3, 5):
        tau, C, D = collocation_coefficients(degree)
        p = np.poly1d(np.arange(1.0, degree + 2))  # a polynomial of degree `degree`
        np.testing.assert_allclose(p(tau) @ C, np.polyder(p)(tau), atol=1e-9)
        assert p(tau) @ D == pytest.approx(p(1.0), abs=1e-10)


@pytest.mark.parametrize("method", ["multiple_shooting", "direct_collocation"])
def test_double_integrator_nlp_optimum_is_the_exact_discrete_optimum(method):
    # The NLP is a convex QP here: one Newton step of IPOPT's KKT, solved with qpsol
    prb, _ = build_double_integrator(20, transcription=method)
    tr = Transcription(prb)
    lbx, ubx = tr.bounds_w()
    lbg, ubg = tr.bounds_g()
    qp = cs.qpsol("qp", "qrqp", {k: tr.nlp[k] for k in ("x", "p", "f", "g")},
                  {"print_iter": False, "print_header": False, "print_info": False})
    sol = qp(p=tr.parameters(), lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    _, U, _ = tr.unpack(sol["x"].full())
    u_star, cost = double_integrator_optimum(20)
    np.testing.assert_allclose(U[0], u_star, atol=1e-9)
    assert float(sol["f"]) == pytest.approx(cost, rel=1e-10)


def test_general_cost_counts_only_its_active_nodes():
    prb, v = small_problem()
    prb.create_general_cost("quartic", v["x"][0] ** 4, nodes=[2, 5])
    tr = Transcription(prb)
    w = np.random.default_rng(2).normal(size=tr.nw)
    X, _, _ = tr.unpack(w)
    general = cs.Function("l", [tr.nlp["x"], tr.nlp["p"]], [tr.general])(w, tr.parameters())
    assert float(general) == pytest.approx(X[0, 2] ** 4 + X[0, 5] ** 4, rel=1e-12)


@pytest.mark.parametrize("name", ["ipopt", "gnsqp"])
def test_a_collocation_solve_starts_from_the_collocation_states_it_carries(name):
    """The solved collocation states were dropped and interpolated again from the nodes: a
    solved problem solved again broke its collocation equations by 0.24 and GN-SQP took 64
    iterations (IPOPT 3) to re-solve its own optimum (session 28 audit). Now 0 iterations,
    as with multiple shooting; after a shift every interval but the last starts from the
    shifted solution; reset() starts cold."""
    from horizon_mpc.examples import build_cartpole
    from horizon_mpc.solvers import make_solver

    prb, _ = build_cartpole(30, transcription="direct_collocation")
    solver = make_solver(name, prb)
    assert solver.solve()
    tr = solver.transcription
    assert np.array_equal(tr.initial_w(solver.w), solver.w)  # unchanged guesses: the solution
    assert solver.solve() and solver.stats.iterations == 0
    solver.shift()
    w0, b = tr.initial_w(solver.w), tr.w_blocks[3]
    Xc = w0[b.start:b.stop].reshape(b.rows, b.cols, order="F")
    Xc_solved = solver.w[b.start:b.stop].reshape(b.rows, b.cols, order="F")
    assert np.array_equal(Xc[:, :-1], Xc_solved[:, :-1])
    # the last interval (both its nodes the old last state) interpolated: that state
    assert np.allclose(Xc[:, -1], np.tile(prb.stacked("state")[:, -1], tr.degree))
    solver.reset()
    assert solver.w is None
    assert np.array_equal(tr.initial_w(solver.w), tr.initial_w())
