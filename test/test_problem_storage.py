"""How a Problem stores what changes between solves: each kind of variable stacked in one
array (the variables' arrays are views of its rows), and terms that say when they changed
(revisions) so that solvers read again only what did."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pytest

from horizon_mpc.problem import Problem
from horizon_mpc.problem.terms import revisions, stacked_weights
from horizon_mpc.solvers import make_solver


@pytest.fixture
def prb() -> Problem:
    p = Problem(4)
    x = p.create_state_variable("x", 2)
    y = p.create_state_variable("y", 1)
    u = p.create_input_variable("u", 2)
    p.create_parameter("r", 1)
    p.set_dynamics(cs.vertcat(x[1], u[0], u[1] - y))
    p.set_dt(0.1)
    return p


def test_variables_write_into_their_kinds_stacked_arrays(prb):
    x, y = prb.get_variable("x"), prb.get_variable("y")
    x.set_initial_guess([1.0, 2.0])
    y.set_initial_guess(np.arange(5.0)[None, :])
    x.set_bounds(-1.0, 1.0, nodes=0)
    X = prb.stacked("state")
    assert X.shape == (3, 5)
    np.testing.assert_array_equal(X[:2], [[1.0] * 5, [2.0] * 5])
    np.testing.assert_array_equal(X[2], np.arange(5.0))
    lb = prb.stacked("state", "lower_bounds")
    np.testing.assert_array_equal(lb[:2, 0], [-1.0, -1.0])
    assert np.all(np.isneginf(lb[:2, 1:])) and np.all(np.isneginf(lb[2]))
    prb.get_variable("r").assign(np.linspace(0, 1, 5)[None, :])
    np.testing.assert_allclose(prb.parameter_values(), [np.linspace(0, 1, 5)])


def test_stacked_copies_unless_asked_for_the_read_only_view(prb):
    X = prb.stacked("state")
    X[:] = 7.0  # a copy: the problem keeps its values
    assert not np.any(prb.stacked("state") == 7.0)
    view = prb.stacked("state", copy=False)
    with pytest.raises(ValueError, match="read-only"):
        view[0, 0] = 1.0
    prb.get_variable("y").set_initial_guess(3.0)
    np.testing.assert_array_equal(view[2], 3.0)  # the problem's own array


def test_stacked_initial_guess_writes_every_variable_of_a_kind(prb):
    prb.set_stacked_initial_guess("state", np.arange(15.0).reshape(3, 5))
    np.testing.assert_array_equal(prb.get_variable("y").initial_guess, [np.arange(10.0, 15.0)])
    with pytest.raises(ValueError, match=r"shape \(3, 4\); expected \(3, 5\)"):
        prb.set_stacked_initial_guess("state", np.zeros((3, 4)))
    with pytest.raises(KeyError, match="unknown variable kind 'states'"):
        prb.stacked("states")
    with pytest.raises(KeyError, match="unknown stacked array 'guess'"):
        prb.stacked("state", "guess")


def test_shift_moves_every_kind_one_node_back(prb):
    prb.set_stacked_initial_guess("state", np.tile(np.arange(5.0), (3, 1)))
    prb.get_variable("u").set_initial_guess(np.tile(np.arange(4.0), (2, 1)))
    prb.get_variable("r").assign(np.arange(5.0)[None, :])
    prb.shift()
    np.testing.assert_array_equal(prb.get_variable("x").initial_guess[0], [1, 2, 3, 4, 4])
    np.testing.assert_array_equal(prb.get_variable("u").initial_guess[1], [1, 2, 3, 3])
    np.testing.assert_array_equal(prb.get_variable("r").values[0], [1, 2, 3, 4, 4])


def test_one_variable_shifts_alone_in_its_kinds_array(prb):
    prb.set_stacked_initial_guess("state", np.tile(np.arange(5.0), (3, 1)))
    prb.get_variable("y").shift()
    np.testing.assert_array_equal(prb.stacked("state")[2], [1, 2, 3, 4, 4])
    np.testing.assert_array_equal(prb.stacked("state")[:2], np.tile(np.arange(5.0), (2, 1)))


def test_variables_keep_their_values_when_more_are_created():
    p = Problem(3)
    x = p.create_state_variable("x", 1)
    x.set_initial_guess(5.0)
    x.set_bounds(-2.0, 2.0)
    p.create_state_variable("z", 2)  # the stacked arrays grow: x's rows move
    np.testing.assert_array_equal(x.initial_guess, 5.0)
    np.testing.assert_array_equal(p.stacked("state", "upper_bounds")[0], 2.0)
    x.set_initial_guess(1.0)  # and still write into the group
    np.testing.assert_array_equal(p.stacked("state")[0], 1.0)


def test_a_term_revision_changes_with_its_nodes_bounds_and_weight(prb):
    x, u = prb.get_variable("x"), prb.get_variable("u")
    con = prb.create_constraint("c", x[0], nodes=[1, 2])
    cost = prb.create_cost("w", u)
    before = revisions([con, cost])
    assert revisions([con, cost]) == before
    con.set_nodes([2, 3])
    assert con.revision != before[0] and con.bounds_revision == before[0]
    bounds = con.bounds_revision
    con.set_bounds(-1.0, 1.0)
    assert con.bounds_revision != bounds
    weight = cost.weight_revision
    cost.set_nodes([0, 1])
    assert cost.weight_revision == weight and cost.revision != before[1]
    cost.set_weight(2.0)
    assert cost.weight_revision != weight
    np.testing.assert_array_equal(stacked_weights([cost])[:, :3], [[2, 2, 0], [2, 2, 0]])
    with pytest.raises(IndexError, match="cannot be evaluated on nodes \\[4\\]"):
        cost.set_nodes(np.ones(5, bool))  # an input term: not on node N


def test_ilqr_reads_changed_weights_and_bounds_between_solves():
    """The solver keeps what it read from terms that did not change; a changed weight, node
    set or bound is read again (the same result as a solver built after the change)."""
    def build(weight: float, bound: float, home: range) -> tuple[Problem, object]:
        p = Problem(20)
        x = p.create_state_variable("x", 2)
        u = p.create_input_variable("u", 1)
        p.set_dynamics(cs.vertcat(x[1], u))
        p.set_dt(0.1)
        x.set_bounds([1.0, 0.0], [1.0, 0.0], nodes=0)
        p.create_cost("effort", u, weight=1e-2)
        p.create_cost("home", x[0], weight=weight, nodes=home)
        c = p.create_constraint("u_max", u, bounds=(-bound, bound))
        c.set_nodes(range(0, 20))
        return p, make_solver("ilqr", p, {"max_iter": 100})

    p, solver = build(weight=1.0, bound=10.0, home=range(10, 21))
    assert solver.solve()
    assert np.max(np.abs(solver.solution["u"])) > 2.5  # the bound to come is not met
    p.costs["home"].set_weight(5.0)
    p.costs["home"].set_nodes(range(8, 21))
    p.constraints["u_max"].set_bounds(-2.0, 2.0)
    p.set_stacked_initial_guess("state", np.tile([[1.0], [0.0]], (1, 21)))
    p.set_stacked_initial_guess("input", np.zeros((1, 20)))
    solver.solve()
    _, fresh = build(weight=5.0, bound=2.0, home=range(8, 21))
    # converged or not (the augmented Lagrangian reaches the active bound's complementarity
    # slowly: the fresh solve ends at max_iter within 1e-7 of IPOPT's cost), both are
    # feasible and agree
    fresh.solve()
    assert max(solver.stats.constraint_violation, fresh.stats.constraint_violation) <= 1e-6
    assert solver.stats.cost == pytest.approx(fresh.stats.cost, rel=1e-4)
    # what the solver read is what a fresh one reads; the solutions agree to the solves'
    # tolerances (the first solver's multipliers start from its first solve)
    np.testing.assert_array_equal(solver.Wr, fresh.Wr)
    np.testing.assert_array_equal(solver.WrN, fresh.WrN)
    np.testing.assert_array_equal(solver._al.lb, fresh._al.lb)
    np.testing.assert_array_equal(solver._al.ub, fresh._al.ub)
    np.testing.assert_allclose(solver.solution["u"], fresh.solution["u"], atol=0.05)
    assert np.max(np.abs(solver.solution["u"])) <= 2.0 + 1e-4
