"""ILQR real-time iteration split in a preparation and a feedback phase (MPC latency)."""

import numpy as np
import pytest
from ocps import pendulum_swing_up

from horizon_mpc import make_solver
from horizon_mpc.examples.cartpole import build_cartpole

RTI = {"rti": True, "iterations_per_call": 1}


def _warm_cartpole(u_max=25.0):
    """A cart-pole part-way through its swing-up (a few iterations from rest), so the
    warm start has gaps, active bounds and nonzero multipliers."""
    prb, _ = build_cartpole(n_nodes=30, u_max=u_max)
    solver = make_solver("ilqr", prb, {"codegen": False, "max_iter": 4})
    solver.solve()
    return prb, solver


def _set_initial_state(prb, x0):
    prb.get_variable("q").set_bounds(x0[:2], x0[:2], nodes=0)
    prb.get_variable("v").set_bounds(x0[2:], x0[2:], nodes=0)


@pytest.mark.parametrize("line_search", [True, False])
@pytest.mark.parametrize("disturbance", [0.0, 0.05, 0.5])
def test_prepare_then_feedback_is_the_one_piece_real_time_iteration(disturbance, line_search):
    # the split iteration from a measured x0 must equal the one-piece iteration whose
    # node-0 bound is x0 while the warm start's node 0 is still the predicted state; two
    # identical solvers, one per way, then one more (one-piece) iteration each: equal
    # again only if the multipliers were updated alike
    split, whole = [_warm_cartpole() for _ in range(2)]
    x_pred = split[0].stacked("state")[:, 0].copy()
    x_meas = x_pred + disturbance * np.array([1.0, -0.5, 2.0, 1.0])
    for _, solver in (split, whole):
        solver.set_option("line_search", line_search)
        for key, value in RTI.items():
            solver.set_option(key, value)

    prb, solver = split
    _set_initial_state(prb, x_pred)
    assert solver.prepare()
    assert solver.prepared
    ok = solver.feedback(x_meas)
    assert not solver.prepared
    assert ok == solver.stats.success
    for prb, _ in (split, whole):  # the node-0 bounds are the caller's to set
        _set_initial_state(prb, x_meas)
    whole[1].solve()
    for _ in range(2):
        a, b = split[1], whole[1]
        np.testing.assert_allclose(a.solution["x"], b.solution["x"], rtol=1e-9, atol=1e-10)
        np.testing.assert_allclose(a.solution["u"], b.solution["u"], rtol=1e-9, atol=1e-10)
        for key in ("alpha", "cost", "violation"):
            assert a.stats.history[-1][key] == pytest.approx(b.stats.history[-1][key],
                                                             rel=1e-9, abs=1e-12)
        assert a.stats.cost == pytest.approx(b.stats.cost, rel=1e-9)
        a.solve()
        b.solve()
    if split[1].stats.history[0]["alpha"] == 1.0:
        np.testing.assert_allclose(split[1].solution["x"][:, 0], x_meas, atol=1e-12)


def test_feedback_writes_the_warm_start_and_the_statistics():
    prb, solver = _warm_cartpole()
    x0 = prb.stacked("state")[:, 0].copy()
    assert solver.prepare()
    ok = solver.feedback(x0)
    np.testing.assert_array_equal(prb.stacked("state"), solver.solution["x"])
    st = solver.stats
    assert st.status == "feedback" and st.iterations == 1
    assert np.isfinite(st.cost) and np.isfinite(st.constraint_violation)
    assert ok == st.success == (st.constraint_violation <= 1e-3)
    assert {"prepare", "feedback", "quadratise", "backward"} <= set(st.extra["timings"])


def test_feedback_needs_a_prepare_and_a_shift_or_solve_discards_it():
    prb, solver = _warm_cartpole()
    with pytest.raises(RuntimeError, match="prepare"):
        solver.feedback(np.zeros(4))
    assert solver.prepare()
    solver.shift()
    assert not solver.prepared
    assert solver.prepare()
    solver.solve()
    assert not solver.prepared


def test_a_feedback_step_that_is_not_finite_leaves_the_guesses_alone():
    prb, solver = _warm_cartpole()
    before = prb.stacked("state").copy()
    assert solver.prepare()
    assert not solver.feedback(np.array([0.0, np.nan, 0.0, 0.0]))
    assert solver.stats.status == "feedback: initial state not finite"
    assert not solver.stats.success
    np.testing.assert_array_equal(prb.stacked("state"), before)


def _swing_up(u_max: float):
    """The pendulum swing-up with an active input bound, solved and shifted."""
    prb = pendulum_swing_up(u_max)
    solver = make_solver("ilqr", prb)
    assert solver.solve()
    solver.shift()
    return prb, solver


def test_the_split_is_the_real_time_iteration_whatever_the_rti_option():
    """With rti False (the default) prepare() set up a converging solve (its 'auto' box, no
    equality rows projected onto bounded inputs): another plan than the real-time solve
    (cost 78.24 against 82.65, inputs 0.52 apart; session 28 audit)."""
    split, whole = _swing_up(5.0), _swing_up(5.0)
    x_meas = split[0].stacked("state")[:, 0] + np.array([0.05, -0.1])
    for prb, _ in (split, whole):
        prb.get_variable("x").set_bounds(x_meas, x_meas, nodes=0)
    assert not split[1].opts["rti"]
    split[1].prepare()
    split[1].feedback(x_meas)
    assert not split[1].opts["rti"]  # the option is left as it was
    whole[1].set_option("rti", True)
    whole[1].solve()
    np.testing.assert_allclose(split[1].solution["u"], whole[1].solution["u"], rtol=1e-9,
                               atol=1e-10)
    assert split[1].stats.cost == pytest.approx(whole[1].stats.cost, rel=1e-9)


def test_a_failed_call_reports_no_iteration_of_the_call_before():
    """A failed solve, prepare or feedback kept the previous call's iterations, history and
    time (an MPC logging its stats reported a failed tick with the last one's)."""
    prb, solver = _warm_cartpole()
    assert solver.stats.iterations == 4
    q = prb.get_variable("q")
    guess = q.initial_guess.copy()
    guess[0, 5] = np.nan
    q.set_initial_guess(guess)
    assert not solver.solve()
    st = solver.stats
    assert (st.iterations, st.history, st.status) == (0, [], "initial guess not finite")
    assert st.time < 1.0
    guess[0, 5] = 0.0
    q.set_initial_guess(guess)
    assert solver.prepare() and not solver.feedback(np.full(4, np.nan))
    assert (st.iterations, st.history) == (0, []) and np.isnan(st.cost)
