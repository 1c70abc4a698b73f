"""Bad input to the Problem API and the solver factory: each a clear exception naming what
is wrong."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pytest

from horizon_mpc.problem import Problem
from horizon_mpc.solvers import make_solver


@pytest.fixture
def prb() -> Problem:
    p = Problem(10)
    x = p.create_state_variable("x", 2)
    u = p.create_input_variable("u", 1)
    p.set_dynamics(cs.vertcat(x[1], u))
    p.set_dt(0.1)
    return p


def test_bounds_of_wrong_dimension_name_the_variable(prb):
    with pytest.raises(ValueError, match=r"lower bound of 'x'.*shape \(3,\)"):
        prb.get_variable("x").set_bounds([0, 0, 0], [1, 1, 1])


def test_bounds_and_guesses_that_are_not_numbers_name_the_variable(prb):
    """numpy's own message named neither the variable nor the bound ('could not convert
    string to float', 'inhomogeneous shape'; an auditor)."""
    x = prb.get_variable("x")
    with pytest.raises(ValueError, match=r"lower bound of 'x': 'a' is not a number"):
        x.set_bounds("a", 1)
    with pytest.raises(ValueError, match=r"upper bound of 'x': \[\[1, 2\], \[3\]\] is not"):
        x.set_bounds(0, [[1, 2], [3]])
    with pytest.raises(ValueError, match=r"initial guess of 'u': 'zz' is not a number"):
        prb.get_variable("u").set_initial_guess("zz")
    with pytest.raises(ValueError, match=r"weight of cost 'effort': 'a' is not a number"):
        prb.create_cost("effort", prb.get_variable("u"), weight="a")


def test_initial_guess_of_wrong_node_count_is_refused(prb):
    with pytest.raises(ValueError, match="initial guess of 'u'"):
        prb.get_variable("u").set_initial_guess(np.zeros((1, 11)))  # inputs live on 10 nodes


def test_dynamics_of_wrong_dimension_state_the_expected_shape():
    p = Problem(5)
    x = p.create_state_variable("x", 2)
    with pytest.raises(ValueError, match=r"expected an expression of shape \(2, 1\)"):
        p.set_dynamics(x[0])


def test_unknown_variable_name_lists_the_known_ones(prb):
    with pytest.raises(KeyError, match="unknown variable 'y'; variables are: x, u"):
        prb.get_variable("y")


def test_unknown_term_name_is_reported(prb):
    prb.create_cost("effort", prb.get_variable("u"))
    with pytest.raises(KeyError, match="unknown constraint or cost 'efort'"):
        prb.get_term("efort")


def test_variable_nodes_out_of_range_give_the_valid_range(prb):
    with pytest.raises(IndexError, match=r"nodes \[11\] out of range.*0\.\.10"):
        prb.get_variable("x").set_bounds(0, 1, nodes=11)


def test_input_bounds_on_the_final_node_are_out_of_range(prb):
    with pytest.raises(IndexError, match=r"nodes \[10\] out of range.*0\.\.9"):
        prb.get_variable("u").set_bounds(-1, 1, nodes=10)


def test_constraint_with_input_on_final_node_names_the_valid_nodes(prb):
    with pytest.raises(IndexError, match=r"on nodes \[10\].*valid nodes: 0\.\.9"):
        prb.create_constraint("c", prb.get_variable("u"), nodes=[5, 10])


def test_offset_term_excludes_the_first_node(prb):
    u = prb.get_variable("u")
    with pytest.raises(IndexError, match=r"nodes \[0\]"):
        prb.create_cost("rate", u - u.offset(-1), nodes=0)


def test_state_created_after_the_dynamics_is_refused(prb):
    with pytest.raises(RuntimeError, match="after set_dynamics"):
        prb.create_state_variable("z", 1)


def test_input_created_after_the_dynamics_is_refused(prb):
    with pytest.raises(RuntimeError, match="after set_dynamics"):
        prb.create_input_variable("w", 1)


def test_duplicate_names_are_refused(prb):
    with pytest.raises(ValueError, match="'x' already exists"):
        prb.create_parameter("x", 1)
    prb.create_cost("c", prb.get_variable("u"))
    with pytest.raises(ValueError, match="'c' already exists"):
        prb.create_constraint("c", prb.get_variable("x"))


def test_foreign_symbols_in_a_term_are_refused(prb):
    with pytest.raises(ValueError, match="not variables of this problem"):
        prb.create_cost("c", cs.SX.sym("alien"))


def test_another_problems_variable_of_the_same_name_is_refused(prb):
    """Symbols were matched by name: another problem's ``x`` passed here and make_solver
    then failed inside CasADi ("variables [x_0, x_1] are free"), naming no term."""
    other = Problem(prb.n_nodes)
    x_other = other.create_state_variable("x", prb.get_variable("x").dim)
    with pytest.raises(ValueError, match=r"not variables of this problem.*\['x_0'"):
        prb.create_final_constraint("goal", x_other - 1.0)
    with pytest.raises(ValueError, match="not variables of this problem"):
        prb.create_cost("c", x_other[0] + prb.get_variable("x")[0])
    prb.create_cost("ok", prb.get_variable("x"))  # its own x still is


def test_unknown_transcription_and_integrator_list_the_choices(prb):
    with pytest.raises(ValueError, match="unknown transcription 'shooting'"):
        prb.transcribe("shooting")
    with pytest.raises(ValueError, match="unknown integrator 'rk5'"):
        prb.transcribe("multiple_shooting", integrator="rk5")


def test_the_argument_a_transcription_does_not_use_is_warned_about(prb, recwarn):
    """An auditor asked for an Euler collocation and got Legendre's without a word."""
    with pytest.warns(UserWarning, match=r"direct_collocation: integrator 'euler' is not used "
                      r"\(the collocation polynomial integrates the dynamics\)"):
        prb.transcribe("direct_collocation", integrator="euler", degree=2)
    assert (prb.transcription, prb.collocation_degree) == ("direct_collocation", 2)
    with pytest.warns(UserWarning, match=r"multiple_shooting: degree 5 is not used"):
        prb.transcribe("multiple_shooting", degree=5)
    assert prb.integrator_name == "rk4"
    recwarn.clear()
    prb.transcribe("direct_collocation", degree=4)  # the defaults and the arguments used:
    prb.transcribe("direct_collocation")             # no word
    prb.transcribe("multiple_shooting", integrator="euler")
    assert not [w for w in recwarn if issubclass(w.category, UserWarning)]
    assert (prb.integrator_name, prb.collocation_degree) == ("euler", 3)


def test_solving_without_dt_says_so():
    p = Problem(3)
    x = p.create_state_variable("x", 1)
    p.set_dynamics(-x)
    with pytest.raises(RuntimeError, match="dt is not set"):
        make_solver("ipopt", p)


def test_unknown_solver_and_option_are_reported(prb):
    with pytest.raises(ValueError, match="unknown solver 'snopt'"):
        make_solver("snopt", prb)
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['maxiter'\]"):
        make_solver("ipopt", prb, {"maxiter": 3})


def test_gnsqp_refuses_a_general_cost_and_names_it(prb):
    prb.create_general_cost("energy", prb.get_variable("u")[0] ** 4)
    with pytest.raises(ValueError, match=r"general cost\(s\) \['energy'\].*'ipopt'"):
        make_solver("gnsqp", prb)


@pytest.mark.parametrize("name", ["ilqr", "gnsqp"])
def test_a_problem_a_solver_refuses_can_still_be_changed(prb, name):
    """The ILQR finalized (froze) the problem before refusing its general cost: the fix its
    message names (create_cost with the residual) then raised 'already built into a
    solver'. Both refuse before freezing it."""
    u = prb.get_variable("u")
    prb.create_general_cost("energy", u[0] ** 4)
    with pytest.raises(ValueError, match="general cost"):
        make_solver(name, prb)
    prb.remove("energy")
    prb.create_cost("energy", u[0] ** 2)
    assert make_solver(name, prb).solve()


@pytest.mark.parametrize("name, key, value, match", [
    ("ilqr", "equality", "lagrangian", "'equality' of solver 'ilqr' is read when the solver "
     "is built"),
    ("ilqr", "inequality", "barrier", "'inequality' .* is read when the solver is built"),
    ("ilqr", "rho_init", 10.0, "'rho_init' .* is read when the solver is built"),
    ("ipopt", "sym", "MX", "'sym' of solver 'ipopt' is read when the solver is built"),
    ("gnsqp", "constraint_rows", "active", "'constraint_rows' .* is read when"),
    ("ilqr", "input_bounds", "bogus", r"'input_bounds' .* must be one of \['auto', 'box', "
     r"'lagrangian'\], got 'bogus'"),
])
def test_set_option_refuses_build_options_and_values_outside_the_choices(prb, name, key,
                                                                        value, match):
    """The ILQR accepted set_option('equality' / 'inequality' / 'rho_init' / ...), read only
    at construction, and had no effect (inequality: its 'auto' box mode then disagreed
    with the rows it was built with); input_bounds 'bogus' acted as 'lagrangian'."""
    solver = make_solver(name, prb)
    with pytest.raises(ValueError, match=match):
        solver.set_option(key, value)
    solver.set_option(key, solver.opts[key])  # the value it has: a no-op, allowed


@pytest.mark.parametrize("name, opts", [("ilqr", {"equality": "bogus"}),
                                        ("ilqr", {"inequality": "Barrier"}),
                                        ("ipopt", {"sym": "sx"}),
                                        ("gnsqp", {"constraint_rows": "all"})])
def test_choice_options_outside_their_choices_are_refused_at_the_build(prb, name, opts):
    with pytest.raises(ValueError, match=f"'{next(iter(opts))}' .* must be one of"):
        make_solver(name, prb, opts)


def test_terms_cannot_be_added_once_built_into_a_solver(prb):
    make_solver("ipopt", prb)
    with pytest.raises(RuntimeError, match="already built into a solver"):
        prb.create_cost("late", prb.get_variable("u"))


def test_node_selections_accept_masks_and_integer_arrays():
    from horizon_mpc.problem.nodes import select_nodes

    mask = np.zeros(6, bool)
    mask[[1, 4]] = True
    np.testing.assert_array_equal(select_nodes(mask, 6), [1, 4])
    np.testing.assert_array_equal(select_nodes(np.array([4, 1, 4]), 6), [1, 4])
    np.testing.assert_array_equal(select_nodes(np.array([0, 2, 5]), 6), [0, 2, 5])
    with pytest.raises(IndexError, match="boolean node mask of shape"):
        select_nodes(mask[:4], 6, "cost 'c'")
    with pytest.raises(IndexError, match="out of range"):
        select_nodes(np.array([1, 6]), 6, "cost 'c'")


def test_per_node_values_go_to_the_nodes_in_the_order_they_are_listed(prb):
    """Column j of a (dim, n) value goes to the j-th node listed: nodes=[8, 3] with the
    values (-1, 2) put -1 on node 8 (they were sorted first: IPOPT then met swapped
    waypoints and called it a success)."""
    u = prb.get_variable("u")
    par = prb.create_parameter("ref", 1)
    con = prb.create_constraint("waypoint", prb.get_variable("x")[0], nodes=[3, 8])
    for nodes in ([8, 3], range(8, 2, -5), np.array([8, 3]), slice(8, 2, -5)):
        u.set_bounds([[-1.0, 2.0]], [[3.0, 6.0]], nodes=nodes)
        u.set_initial_guess([[-1.0, 2.0]], nodes=nodes)
        par.assign([[-1.0, 2.0]], nodes=nodes)
        con.set_bounds([[-1.0, 2.0]], [[-1.0, 2.0]], nodes=nodes)
        for values in (u.lower_bounds, u.upper_bounds - 4.0, u.initial_guess, par.values,
                       con.lower_bounds, con.upper_bounds):
            np.testing.assert_array_equal(values[0, [8, 3]], [-1.0, 2.0])
    # a node named twice: the set of nodes; a scalar fills them, per-node values must fit it
    u.set_initial_guess(0.5, nodes=[2, 1, 2])
    np.testing.assert_array_equal(u.initial_guess[0, [1, 2]], [0.5, 0.5])
    with pytest.raises(ValueError, match=r"shape \(1, 3\) does not fit dimension 1 on 2"):
        u.set_initial_guess([[1.0, 2.0, 3.0]], nodes=[1, 1, 2])
    con.set_nodes([3, 3, 8])
    assert con.nodes.tolist() == [3, 8]


def test_a_list_of_bools_is_a_mask_and_bools_or_fractions_are_not_nodes():
    """Read as ints, [False, False, True] would select nodes 0 and 1 and True node 1."""
    from horizon_mpc.problem.nodes import select_nodes

    np.testing.assert_array_equal(select_nodes([False, True, False, True], 4), [1, 3])
    np.testing.assert_array_equal(select_nodes([2.0, 0], 4), [0, 2])  # whole floats are nodes
    with pytest.raises(IndexError, match="boolean node mask"):
        select_nodes([True, False], 4, "cost 'c'")
    for bad, text in ((True, "a bool is not a node"), ([2.7], "2.7 is not a node number"),
                      ([1, True], "mixed with node numbers"), (["a"], "'a' is not a node")):
        with pytest.raises(TypeError, match=text):
            select_nodes(bad, 4, "cost 'c'")


def test_a_term_switched_by_a_mask_is_active_exactly_there(prb):
    x = prb.get_variable("x")
    cost = prb.create_cost("mask_cost", x)
    mask = np.zeros(prb.n_nodes + 1, bool)
    mask[[0, 3]] = True
    cost.set_nodes(mask)
    np.testing.assert_array_equal(cost.nodes, [0, 3])


def test_stacked_bounds_and_weights_follow_each_terms_nodes_rows_and_values(prb):
    from horizon_mpc.problem.terms import stacked_bounds, stacked_weights

    x, u = prb.get_variable("x"), prb.get_variable("u")
    c1 = prb.create_constraint("c1", x, nodes=[1, 2], bounds=([-1.0, -2.0], [1.0, 2.0]))
    c2 = prb.create_constraint("c2", u[0], nodes=[0, 5])
    c2.set_bounds(-3.0, 4.0, nodes=5)
    lb, ub, act = stacked_bounds([c1, c2])
    assert lb.shape == ub.shape == act.shape == (3, prb.n_nodes + 1)
    np.testing.assert_array_equal(lb[:2], c1.lower_bounds)
    np.testing.assert_array_equal(ub[2], c2.upper_bounds[0])
    np.testing.assert_array_equal(act[0], c1.active)
    np.testing.assert_array_equal(act[2], c2.active)
    assert lb[2, 5] == -3.0 and ub[2, 0] == 0.0
    k1 = prb.create_cost("k1", x, nodes=[3], weight=[2.0, 5.0])
    k2 = prb.create_cost("k2", u, weight=7.0)
    w = stacked_weights([k1, k2])
    expected = np.zeros((3, prb.n_nodes + 1))
    expected[0, 3], expected[1, 3] = 2.0, 5.0
    expected[2, :prb.n_nodes] = 7.0
    np.testing.assert_array_equal(w, expected)
    assert stacked_weights([]).shape == (0, 0) and stacked_bounds([])[0].shape == (0, 0)


def _goal_problem(dt: float = 0.1) -> Problem:
    prb = Problem(10)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(x[1], u))
    prb.set_dt(dt)
    x.set_bounds([0.0, 0.0], [0.0, 0.0], nodes=0)
    prb.create_final_constraint("goal", x - np.array([1.0, 0.0]))
    prb.create_cost("effort", u)
    return prb


@pytest.mark.parametrize("solver_name", ["ipopt", "gnsqp", "ilqr"])
@pytest.mark.parametrize("change", ["dt", "transcription", "dynamics"])
def test_a_structural_change_after_the_build_is_refused_not_ignored(solver_name, change):
    """A solver built before set_dt/transcribe/set_dynamics would solve the old problem:
    it refuses; a solver built after the change solves the new one."""
    prb = _goal_problem()
    opts = {"codegen": False} if solver_name == "ilqr" else {}
    solver = make_solver(solver_name, prb, opts)
    assert solver.solve()
    if change == "dt":
        prb.set_dt(0.2)
    elif change == "transcription":
        prb.transcribe("multiple_shooting", integrator="euler")
    else:
        prb.set_dynamics(cs.vertcat(prb.states[0][1], 2 * prb.inputs[0]))
    with pytest.raises(RuntimeError, match="build a new solver"):
        solver.solve()
    fresh = make_solver(solver_name, prb, opts)
    assert fresh.solve()
    if change == "dt":  # half the control effort spread over twice the time
        reference = make_solver(solver_name, _goal_problem(0.2), opts)
        assert reference.solve()
        assert fresh.stats.cost == pytest.approx(reference.stats.cost, rel=1e-6)


def test_the_split_ilqr_iteration_refuses_a_changed_problem_too():
    prb = _goal_problem()
    solver = make_solver("ilqr", prb, {"codegen": False})
    assert solver.solve()
    prb.set_dt(0.05)
    with pytest.raises(RuntimeError, match="build a new solver"):
        solver.prepare()


def test_a_manifold_declared_after_a_collocation_transcription_is_refused_at_the_build():
    """transcribe('direct_collocation') refuses a manifold state; declared after it, the
    build crashed inside CasADi (dimension mismatch) or, with the tangent of the state's
    size, solved ignoring the manifold (an auditor's)."""
    prb = Problem(5)
    q = prb.create_state_variable("q", 1)
    u = prb.create_input_variable("u", 1)
    prb.set_dt(0.1)
    prb.transcribe("direct_collocation", degree=3)
    a, d, b = cs.SX.sym("a", 1), cs.SX.sym("d", 1), cs.SX.sym("b", 1)
    q.set_manifold(cs.Function("integrate", [a, d], [a + d]),
                   cs.Function("difference", [a, b], [cs.atan2(cs.sin(b - a), cs.cos(b - a))]),
                   1)
    prb.set_dynamics(u)
    prb.create_cost("effort", u - 1)
    for solver in ("ipopt", "gnsqp"):
        with pytest.raises(ValueError, match=r"direct_collocation supports vector-space states "
                                             r"only; \['q'\] on a manifold"):
            make_solver(solver, prb)


def test_a_manifold_declared_after_the_dynamics_is_caught_at_the_build():
    prb = Problem(5)
    q = prb.create_state_variable("q", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(u, 2 * u))
    a, d, b = cs.SX.sym("a", 2), cs.SX.sym("d", 1), cs.SX.sym("b", 2)
    rot = cs.vertcat(a[0] * cs.cos(d) - a[1] * cs.sin(d), a[0] * cs.sin(d) + a[1] * cs.cos(d))
    q.set_manifold(cs.Function("integrate", [a, d], [rot]),
                   cs.Function("difference", [a, b], [cs.atan2(a[0] * b[1] - a[1] * b[0],
                                                               a[0] * b[0] + a[1] * b[1])]), 1)
    prb.set_dt(0.1)
    prb.create_cost("effort", u - 1)
    with pytest.raises(ValueError, match="set the dynamics again"):
        make_solver("ipopt", prb)


def test_nan_bounds_and_crossed_one_sided_bounds_are_refused(prb):
    u = prb.get_variable("u")
    with pytest.raises(ValueError, match="NaN bound"):
        u.set_bounds(np.nan, 1.0)
    u.set_bounds(-1.0, 1.0)
    with pytest.raises(ValueError, match="lower bound above upper bound"):
        u.set_lower_bounds(2.0)
    with pytest.raises(ValueError, match="lower bound above upper bound"):
        u.set_upper_bounds(-2.0, nodes=0)
    with pytest.raises(ValueError, match="NaN bound"):
        u.set_upper_bounds(np.nan)
    np.testing.assert_array_equal(u.lower_bounds, -1.0)  # nothing written by a refusal
    np.testing.assert_array_equal(u.upper_bounds, 1.0)
    u.set_lower_bounds(0.5, nodes=1)
    assert u.lower_bounds[0, 1] == 0.5
    con = prb.create_constraint("c", prb.get_variable("x")[0])
    with pytest.raises(ValueError, match="NaN bound"):
        con.set_bounds(np.nan, 0.0)


def test_none_as_a_bound_is_no_bound_on_that_side(prb):
    """None was taken as NaN and refused as a 'NaN bound' (scipy and most OCP tools read it
    as no bound)."""
    u = prb.get_variable("u")
    u.set_bounds(None, 2.0)
    np.testing.assert_array_equal(u.lower_bounds, -np.inf)
    np.testing.assert_array_equal(u.upper_bounds, 2.0)
    u.set_bounds(-1.0, None, nodes=[0, 1])
    assert u.lower_bounds[0, 0] == -1.0 and u.upper_bounds[0, 1] == np.inf
    assert u.upper_bounds[0, 2] == 2.0
    u.set_upper_bounds(None)
    u.set_lower_bounds(None)
    np.testing.assert_array_equal(u.upper_bounds, np.inf)
    np.testing.assert_array_equal(u.lower_bounds, -np.inf)
    con = prb.create_constraint("c", prb.get_variable("x")[0], bounds=(0.0, None))
    np.testing.assert_array_equal(con.upper_bounds, np.inf)
    np.testing.assert_array_equal(con.lower_bounds, 0.0)
    # an element of a list too ('NaN bound' before; session 28 audit)
    x = prb.get_variable("x")
    x.set_bounds([None, 0.0], [1.0, None], nodes=3)
    assert x.lower_bounds[:, 3].tolist() == [-np.inf, 0.0]
    assert x.upper_bounds[:, 3].tolist() == [1.0, np.inf]
    x.set_bounds([[None, -1.0]] * 2, None, nodes=[4, 5])  # one column per node
    assert x.lower_bounds[:, 4:6].tolist() == [[-np.inf, -1.0], [-np.inf, -1.0]]



@pytest.mark.parametrize("solver", ["ipopt", "gnsqp", "ilqr"])
def test_a_bound_no_value_can_meet_is_refused_where_it_is_set(prb, solver):
    """lb = +inf or ub = -inf used to pass, then IPOPT raised CasADi's error and the others
    ended with 'not finite at the initial guess' or max_iter."""
    x, u = prb.get_variable("x"), prb.get_variable("u")
    prb.create_cost("effort", u)
    for refuse in (lambda: x.set_bounds([np.inf, -np.inf], [np.inf, np.inf], nodes=5),
                   lambda: x.set_upper_bounds(-np.inf, nodes=3),
                   lambda: x.set_lower_bounds(np.inf),
                   lambda: prb.create_constraint("c", x[0], bounds=(np.inf, np.inf)),
                   lambda: prb.create_constraint("d", x[0], bounds=(-np.inf, -np.inf))):
        with pytest.raises(ValueError, match=r"lower bound of \+inf or an upper bound of -inf"):
            refuse()
    assert not {"c", "d"} & set(prb.constraints)
    x.set_bounds(0.0, 0.0, nodes=0)
    x.set_bounds([-np.inf, -1.0], [np.inf, 1.0])  # no bound on one side is fine
    solver_ = make_solver(solver, prb)
    assert solver_.solve(), solver_.stats.status


@pytest.mark.parametrize("name", ["effort__u", "_c", "my cost", "jac", "hess", "null", "2c",
                                  "coût", ""])
def test_a_term_name_casadi_cannot_take_is_refused_when_the_term_is_created(prb, name):
    """It became a CasADi Function's name: make_solver raised CasADi's own error."""
    with pytest.raises(ValueError, match="term name .* is not valid"):
        prb.create_cost(name, prb.get_variable("u"))
    assert not prb.costs


def test_term_name_makes_frame_names_valid():
    from horizon_mpc.problem.terms import term_name

    assert term_name("leg-1.foot", "velocity") == "leg_1_foot_velocity"
    assert term_name("LF_FOOT", "no_force") == "LF_FOOT_no_force"
    assert term_name("1_foot__x", "touchdown") == "f_1_foot_x_touchdown"
    assert all(cs.Function.check_name(term_name(f, "c")) for f in ("_a", "b__", "é", "a b"))


def test_creation_bounds_may_give_one_column_per_active_node(prb):
    x, u = prb.get_variable("x"), prb.get_variable("u")
    c = prb.create_constraint("some", x, nodes=[5, 2],
                              bounds=(np.array([[0, 1], [2, 3]]), np.full((2, 2), 9.0)))
    # in the order listed, as set_bounds(lb, ub, nodes=[5, 2]) puts them
    np.testing.assert_array_equal(c.lower_bounds[:, [5, 2]], [[0, 1], [2, 3]])
    same = prb.create_constraint("same", x, nodes=[5, 2])
    same.set_bounds(np.array([[0, 1], [2, 3]]), 9.0, nodes=[5, 2])
    np.testing.assert_array_equal(same.lower_bounds, c.lower_bounds)
    np.testing.assert_array_equal(c.upper_bounds[:, [2, 5]], 9.0)
    e = prb.create_constraint("inputs", u, bounds=(-np.ones((1, 10)), np.ones((1, 10))))
    np.testing.assert_array_equal(e.lower_bounds[0, :10], -1.0)
    full = prb.create_constraint("full", x[0], bounds=(-np.ones((1, 11)), np.ones((1, 11))))
    np.testing.assert_array_equal(full.upper_bounds, 1.0)
    with pytest.raises(ValueError, match=r"\[3\] columns; give one per node 0..N \(11\) or "
                                         r"one per active node \(2\)"):
        prb.create_constraint("bad", x, nodes=[2, 5], bounds=(np.zeros((2, 3)), 1.0))


def test_a_constant_constraint_is_refused(prb):
    with pytest.raises(ValueError, match="constraint 'one' is a constant"):
        prb.create_constraint("one", 1.0)
    with pytest.raises(ValueError, match="is a constant"):
        prb.create_constraint("zero", prb.get_variable("x") * 0)

@pytest.mark.parametrize("build, error, match", [
    (lambda p, x, u: p.create_constraint("c", cs.MX.sym("m", 1)), TypeError, "MX"),
    (lambda p, x, u: p.create_cost("c", "x"), TypeError, "string 'x'"),
    (lambda p, x, u: p.set_dynamics(cs.MX.sym("m", 2)), TypeError, "dynamics: got a CasADi MX"),
    (lambda p, x, u: p.set_dynamics([x[1], "u"]), TypeError, "dynamics: got the string"),
    (lambda p, x, u: p.set_dt(float("inf")), ValueError, "finite number > 0"),
    (lambda p, x, u: p.set_dt(float("nan")), ValueError, "finite number > 0"),
    (lambda p, x, u: p.set_dt("0.1"), TypeError, "dt: got the string"),
    (lambda p, x, u: p.set_dt(np.array([-0.1])), ValueError, "finite number > 0, got -0.1"),
    (lambda p, x, u: p.set_dt(cs.DM(0.0)), ValueError, "finite number > 0, got 0"),
    (lambda p, x, u: p.set_dt([-0.1]), ValueError, "finite number > 0"),
    (lambda p, x, u: p.set_dt(True), TypeError, "got the bool"),
    (lambda p, x, u: p.create_general_cost("g", cs.MX.sym("m")), TypeError,
     "general cost 'g': got a CasADi MX"),
    (lambda p, x, u: p.create_general_cost("g", "x"), TypeError, "general cost 'g': got the"),
    (lambda p, x, u: p.create_constraint("c", x[0], bounds=1.0), TypeError, r"pair \(lb, ub\)"),
    (lambda p, x, u: p.set_stacked_initial_guess("states", np.zeros((2, 11))), KeyError,
     "kinds are: state"),
], ids=["mx_term", "string_cost", "mx_dynamics", "string_in_list", "dt_inf", "dt_nan",
        "dt_string", "dt_negative_array", "dt_zero_dm", "dt_negative_list", "dt_bool",
        "mx_general_cost", "string_general_cost", "scalar_bounds", "unknown_kind"])
def test_expressions_and_values_of_the_wrong_kind_are_named(prb, build, error, match):
    # raw CasADi 'Wrong number or type of arguments for overloaded function' and
    # KeyError('states') before; inf dt was accepted and failed at solve time; a negative
    # dt in an array, list or DM was solved backwards in time and called a success
    x, u = prb.get_variable("x"), prb.get_variable("u")
    with pytest.raises(error, match=match):
        build(prb, x, u)


def test_a_constant_dt_in_an_array_is_that_number(prb):
    for value in (np.array([0.05]), [0.05], cs.DM(0.05), np.float32(0.05)):
        prb.set_dt(value)
        assert isinstance(prb.dt, float) and prb.dt == pytest.approx(0.05)


def test_dynamics_may_be_a_list_of_expressions(prb):
    x, u = prb.get_variable("x"), prb.get_variable("u")
    prb.set_dynamics([x[1], u])
    assert prb.dynamics.shape == (2, 1)


def test_a_single_variable_refuses_a_node_set_it_would_ignore():
    p = Problem(5)
    x = p.create_state_variable("x", 1)
    T = p.create_single_variable("T", 1)
    p.set_dynamics(x * T)
    with pytest.raises(ValueError, match="one value for the whole horizon"):
        T.set_bounds(0.1, 1.0, nodes=3)
    T.set_bounds(0.1, 1.0)  # without nodes: fine
    np.testing.assert_array_equal(T.lower_bounds, [[0.1]])


@pytest.mark.parametrize("name, opts, match", [
    ("ilqr", {"max_iter": "a"}, "'max_iter' of solver 'ilqr' must be an int"),
    ("ipopt", {"tol": "small"}, "'tol' of solver 'ipopt' must be a number"),
    ("gnsqp", {"warm_start": 1}, "'warm_start' of solver 'gnsqp' must be a bool"),
    ("gnsqp", {"max_iter": 10.5}, "must be an int"),
])
def test_options_of_the_wrong_type_are_refused_by_name(prb, name, opts, match):
    with pytest.raises(TypeError, match=match):
        make_solver(name, prb, opts)


@pytest.mark.parametrize("name, opts, match", [
    ("ilqr", {"rho_init": 0.0}, "'rho_init' of solver 'ilqr' must be >0"),
    ("ilqr", {"tol": -1.0}, "'tol' .* must be >=0"),  # 0: never stationary
    ("ilqr", {"box_after": -3}, "'box_after' .* must be >=1"),
    ("ilqr", {"iterations_per_call": 0}, "'iterations_per_call' .* must be >=1"),
    ("ilqr", {"barrier_mu": float("nan")}, "'barrier_mu' .* must be >0"),
    ("ilqr", {"time_budget": -0.01}, "'time_budget' .* must be >0"),
    ("gnsqp", {"regularization": -1.0}, "'regularization' .* must be >=0"),  # QP failed
    ("gnsqp", {"armijo": 1.0}, "'armijo' .* must be \\(0,1\\)"),
    ("ipopt", {"max_iter": -5}, "'max_iter' of solver 'ipopt' must be >=0"),
    ("ipopt", {"tol": -1.0}, "'tol' .* must be >0"),
    ("ipopt", {"constr_viol_tol": float("nan")}, "'constr_viol_tol' .* must be >0"),
    ("ipopt", {"print_level": 99}, "'print_level' .* must be \\[0,12\\]"),
    ("ilqr", {"mu_max": 1e-12}, "mu_min 1e-10 is above mu_max 1e-12"),
])
def test_options_out_of_their_range_are_refused_by_name(prb, name, opts, match):
    """rho_init 0 ended a solve in 'linearisation not finite', regularization -1 in a QP
    failure after 2.4 s; tol -1 and box_after -3 were taken silently."""
    with pytest.raises(ValueError, match=match):
        make_solver(name, prb, opts)
    solver = make_solver(name, prb)
    with pytest.raises(ValueError, match=match):  # set_option checks the same
        solver.set_option(*next(iter(opts.items())))


def test_the_ilqr_regularisation_starts_within_its_range(prb):
    """mu_init 1e3 above mu_max 1 ran there (101 iterations for 86), 1e-12 below mu_min 1e-6
    was taken as is (session 28 audit); raising mu_min alone must not be an error."""
    for opts, mu in (({"mu_init": 1e3, "mu_max": 1.0}, 1.0),
                     ({"mu_init": 1e-12, "mu_min": 1e-6}, 1e-6),
                     ({"mu_min": 1e-6}, 1e-6), ({"mu_init": 0.0, "mu_min": 0.0}, 0.0)):
        assert make_solver("ilqr", prb, opts).mu == mu, opts
    solver = make_solver("ilqr", prb)
    solver.set_option("mu_min", 1e-6)
    solver.set_option("mu_init", 1e-9)
    assert solver.mu == 1e-6


def test_options_not_given_as_a_dict_or_a_callback_that_cannot_be_called_are_refused(prb):
    """A list of pairs was an AttributeError from deep in the IPOPT wrapper; an ILQR
    callback 3 failed only at the first iteration."""
    with pytest.raises(TypeError, match="options of solver 'ipopt' must be a dict"):
        make_solver("ipopt", prb, [("max_iter", 5)])
    with pytest.raises(TypeError, match="'callback' must be callable"):
        make_solver("ilqr", prb, {"callback": 3})
    make_solver("ilqr", prb, {"callback": print})


def test_a_none_default_option_takes_a_number_or_none(prb):
    solver = make_solver("ilqr", prb, {"time_budget": 0.01})
    solver.set_option("time_budget", None)
    with pytest.raises(TypeError, match="'time_budget' .* must be a number"):
        solver.set_option("time_budget", "1 ms")


def test_options_of_the_right_kind_pass(prb):
    solver = make_solver("ilqr", prb, {"max_iter": np.int64(5), "tol": 1, "verbose": False})
    assert solver.opts["max_iter"] == 5


def test_an_unavailable_qp_solver_is_named_at_the_build(prb):
    with pytest.raises(ValueError, match="QP solver 'nope' is not available.*qrqp"):
        make_solver("gnsqp", prb, {"qp_solver": "nope"})


def test_ipopt_reports_the_returned_points_violation_when_it_never_ran(prb):
    # Invalid_Option stops IPOPT before any evaluation: it reported violation 0 and a
    # garbage iteration count for an initial guess that violates the goal by 1
    prb.get_variable("x").set_bounds([0, 0], [0, 0], nodes=0)
    prb.create_final_constraint("goal", prb.get_variable("x") - np.array([1.0, 0.0]))
    # (an IPOPT option passed through unchecked: HSL is not installed here)
    solver = make_solver("ipopt", prb, {"ipopt.linear_solver": "ma27"})
    assert not solver.solve()
    assert solver.stats.constraint_violation == pytest.approx(1.0)
    assert solver.stats.iterations == 0


def test_ipopt_refuses_a_linear_solver_it_cannot_load_at_the_build(prb):
    """'ma27' without the HSL library was accepted and failed at the solve (Invalid_Option,
    cost 0); an unknown name too."""
    from horizon_mpc.solvers.ipopt import hsl_available

    if not hsl_available():
        with pytest.raises(ValueError, match="'ma27' needs the HSL library"):
            make_solver("ipopt", prb, {"linear_solver": "ma27"})
        solver = make_solver("ipopt", prb)
        with pytest.raises(ValueError, match="needs the HSL library"):
            solver.set_option("linear_solver", "ma57")
        assert solver.opts["linear_solver"] == "mumps"
    with pytest.raises(ValueError, match="'linear_solver' .* must be one of"):
        make_solver("ipopt", prb, {"linear_solver": "pardiso7"})
    make_solver("ipopt", prb, {"linear_solver": "spral"})


def test_ilqr_feedback_of_the_wrong_size_keeps_the_preparation(prb):
    x = prb.get_variable("x")
    x.set_bounds([0, 0], [0, 0], nodes=0)
    prb.create_cost("effort", prb.get_variable("u"))
    prb.create_final_cost("goal", x - np.array([1.0, 0.0]), weight=10.0)
    solver = make_solver("ilqr", prb, {"rti": True})
    assert solver.prepare()
    with pytest.raises(ValueError, match="nx = 2"):
        solver.feedback(np.zeros(3))
    assert solver.prepared
    assert solver.feedback(np.zeros(2))


def test_a_variable_named_x_beside_other_states_is_warned_about_and_stacked_stays_reachable(
        caplog):
    import logging

    from horizon_mpc.examples import build_double_integrator

    prb, _ = build_double_integrator(5)  # states 'x' (position) and 'v'
    with caplog.at_level(logging.WARNING):
        solver = make_solver("ipopt", prb)
    assert "solution['x'] will be the variable 'x', not the stacked states" in caplog.text
    assert solver.stacked_solution is None
    assert solver.solve()
    X, U, _ = solver.stacked_solution
    assert solver.solution["x"].shape == (1, 6) and X.shape == (2, 6) and U.shape == (1, 5)
    np.testing.assert_array_equal(X[:1], solver.solution["x"])


@pytest.mark.parametrize("name", ["ipopt", "gnsqp", "ilqr"])
def test_verbose_prints_the_iterations_and_quiet_prints_nothing(prb, name, capfd):
    """'verbose' was accepted by IPOPT and GN-SQP and did nothing; ILQR logged at INFO,
    which is silent unless the caller configures logging."""
    x = prb.get_variable("x")
    x.set_bounds([0.0, 0.0], [0.0, 0.0], nodes=0)
    prb.create_final_constraint("goal", x - np.array([1.0, 0.0]))
    prb.create_cost("effort", prb.get_variable("u"), weight=0.1)
    opts = {"codegen": False} if name == "ilqr" else {}
    assert make_solver(name, prb, opts).solve()
    quiet = capfd.readouterr().out
    assert quiet.strip() == ""
    assert make_solver(name, prb, {**opts, "verbose": True}).solve()
    out = capfd.readouterr().out
    # a line per iteration (IPOPT: its table); this QP converges in one step
    assert len(out.strip().splitlines()) >= 2, out
    assert "cost" in out or "objective" in out, out


def test_a_slice_past_the_nodes_is_refused_not_an_empty_selection(prb):
    """slice(20, 30) of 11 nodes set nothing without a word; Python's negative bounds
    still count from the end."""
    x = prb.get_variable("x")
    with pytest.raises(IndexError, match=r"slice\(20, 30, None\) out of range .* 0\.\.10"):
        x.set_bounds([0, 0], [1, 1], nodes=slice(20, 30))
    with pytest.raises(IndexError, match="out of range"):
        prb.create_constraint("c", x[0], nodes=slice(0, 12))
    x.set_bounds([0, 0], [1, 1], nodes=slice(-2, None))
    assert np.isfinite(x.lower_bounds).all(axis=0).tolist() == [False] * 9 + [True] * 2
    x.set_bounds([0, 0], [2, 2], nodes=slice(0, 11))  # up to the end is in range
    assert np.all(x.upper_bounds == 2)


@pytest.mark.parametrize("solver", ["ipopt", "gnsqp", "ilqr"])
def test_a_dt_parameter_that_is_not_positive_is_refused_at_the_solve(prb, solver):
    """set_dt checks a number; a parameter assigned -0.1 solved a time-reversed problem and
    each solver called it a success."""
    dt = prb.create_parameter("dt", 1)
    prb.set_dt(dt)
    x = prb.get_variable("x")
    x.set_bounds([0, 0], [0, 0], nodes=0)
    prb.create_final_constraint("goal", x - np.array([1.0, 0.0]))
    prb.create_cost("effort", prb.get_variable("u"), weight=0.1)
    dt.assign(0.1)
    s = make_solver(solver, prb)
    assert s.solve()
    for bad in (-0.1, 0.0, np.inf):
        dt.assign(bad)
        with pytest.raises(ValueError, match=r"dt must be a finite number > 0; .* at node 0"):
            s.solve()
    values = np.full((1, 11), 0.1)
    values[0, 7] = -0.1
    dt.assign(values)
    with pytest.raises(ValueError, match="at node 7"):
        s.solve()
    if solver == "ilqr":
        with pytest.raises(ValueError, match="at node 7"):
            s.prepare()
    # node N's dt is no interval's: any value there is taken (0 there was refused)
    values[0, 7], values[0, -1] = 0.1, 0.0
    dt.assign(values)
    assert s.solve()


@pytest.mark.parametrize("solver", ["ipopt", "gnsqp"])
def test_a_dt_of_a_single_variable_and_a_parameter_is_checked_at_the_guess(solver):
    """dt = T * frac (a free final time split by a parameter): a negative frac on a node
    solved a time-reversed interval, 'Solve_Succeeded' with T 2.12 for the optimum 2
    (session 28 audit). Checked where the solver starts: T's guess within its bounds."""
    prb = Problem(20)
    x = prb.create_state_variable("pos", 1)
    v = prb.create_state_variable("vel", 1)
    u = prb.create_input_variable("u", 1)
    T = prb.create_single_variable("T", 1)
    frac = prb.create_parameter("frac", 1)
    prb.set_dynamics(cs.vertcat(v, u))
    prb.set_dt(T * frac)
    x.set_bounds(0, 0, nodes=0)
    v.set_bounds(0, 0, nodes=0)
    u.set_bounds(-1, 1)
    T.set_bounds(0.1, 10)
    T.set_initial_guess(3)
    prb.create_final_constraint("goal", cs.vertcat(x - 1, v))
    prb.create_final_cost("time", T)
    fractions = np.full((1, 21), 1 / 20)
    frac.assign(fractions)
    s = make_solver(solver, prb)
    assert s.solve() and s.solution["T"].item() == pytest.approx(2.0, abs=1e-4)
    fractions[0, 5] = -0.05
    frac.assign(fractions)
    with pytest.raises(ValueError, match=r"single variables' initial guess it is -0\.1.* at "
                                         r"node 5"):
        s.solve()
    fractions[0, 5] = 1 / 20
    frac.assign(fractions)
    T.set_initial_guess(-1.0)  # clipped to its lower bound 0.1: where the solver starts
    assert s.solve()
    # a time T >= 0 guessed 0 starts on its bound: dt 0 there is no reversed interval
    # (refused for a moment in session 28; it solves)
    T.set_bounds(0.0, 10.0)
    T.set_initial_guess(0.0)
    assert s.solve() and s.solution["T"].item() == pytest.approx(2.0, abs=1e-4)


@pytest.mark.parametrize("name", ["ipopt", "gnsqp", "ilqr"])
def test_every_solver_resets_to_a_cold_start_by_one_name(prb, name, monkeypatch):
    """reset() on the NLP solvers, reset_multipliers() only on the ILQR: one name for all."""
    solver = make_solver(name, prb)
    prb.get_variable("x").set_bounds([1.0, 0.0], [1.0, 0.0], nodes=prb.n_nodes)
    assert solver.solve()
    if name == "ilqr":
        calls = []
        monkeypatch.setattr(solver, "reset_multipliers", lambda: calls.append(1))
        solver.reset()
        assert calls == [1]
    else:
        assert solver.lam_g is not None and solver.lam_x is not None
        solver.reset()
        assert solver.lam_g is None and solver.lam_x is None
    assert solver.solve()


def test_a_solver_that_fails_to_build_leaves_the_problem_changeable(prb):
    """A QP solver name gnsqp refuses, a state layout leapfrog refuses: the problem stayed
    frozen ('already built into a solver') though no solver was built."""
    u = prb.get_variable("u")
    with pytest.raises(ValueError, match="QP solver 'bogus'"):
        make_solver("gnsqp", prb, {"qp_solver": "bogus"})
    prb.create_cost("effort", u)  # still changeable
    with pytest.raises(TypeError, match="'qp_solver'"):  # a SWIG NotImplementedError before
        make_solver("gnsqp", prb, {"qp_solver": 5})
    with pytest.raises(ValueError, match="refuses its options"):
        make_solver("gnsqp", prb, {"qp_options": {"bogus": 1}})
    solver = make_solver("gnsqp", prb)
    with pytest.raises(ValueError, match="refuses its options"):
        solver.set_option("qp_options", {"bogus": 1})
    assert solver.opts["qp_options"] == {} and solver.solve()


def test_gnsqp_is_not_converged_by_steps_a_huge_regularisation_made_tiny(prb):
    """regularization 1e9 made every step tiny: 'converged' after 1 iteration at cost 16
    (optimum 12.03), stationarity 0.4."""
    x, u = prb.get_variable("x"), prb.get_variable("u")
    x.set_bounds([0, 0], [0, 0], nodes=0)
    x.set_bounds([1, 0], [1, 0], nodes=prb.n_nodes)
    prb.create_cost("effort", u)
    ref = make_solver("ipopt", prb)
    assert ref.solve()
    u.set_initial_guess(ref.solution["u"] + 0.5)
    x.set_initial_guess(ref.solution["x"])
    solver = make_solver("gnsqp", prb, {"regularization": 1e9, "max_iter": 5})
    assert not solver.solve()
    assert solver.stats.status == "max_iter reached"


def test_ilqr_reset_and_mu_init_act_as_on_a_fresh_solver():
    """reset() left the 'auto' box mode a solve had kept (the next solve took the box from
    iteration 0); set_option('mu_init') was read at the build only."""
    from horizon_mpc.examples import pendulum_dynamics

    prb = Problem(60)  # a swing-up whose input bound is active: 'auto' goes to the box
    th, om = prb.create_state_variable("th", 1), prb.create_state_variable("om", 1)
    tau = prb.create_input_variable("tau", 1)
    prb.set_dynamics(cs.vertcat(om, pendulum_dynamics(th, om, tau)))
    prb.set_dt(0.05)
    th.set_bounds(0, 0, nodes=0)
    om.set_bounds(0, 0, nodes=0)
    tau.set_bounds(-5.5, 5.5)
    th.set_initial_guess(np.linspace(0, np.pi, 61)[None])
    prb.create_final_constraint("up", cs.vertcat(th - np.pi, om))
    prb.create_cost("effort", 0.1 * tau)
    solver = make_solver("ilqr", prb)
    guesses = {v.name: v.initial_guess for v in (*prb.states, *prb.inputs)}
    solver.solve()
    first = (solver.stats.iterations, solver.stats.extra.get("box_from"))
    assert first[1] == 20, first  # the box took over: reset() must forget that
    solver.reset()
    for v in (*prb.states, *prb.inputs):
        v.set_initial_guess(guesses[v.name])
    solver.solve()
    assert (solver.stats.iterations, solver.stats.extra.get("box_from")) == first
    solver.set_option("mu_init", 1.0)
    assert solver.mu == 1.0


def test_an_exception_in_a_solve_leaves_no_earlier_success_in_the_stats(prb):
    prb.create_cost("effort", prb.get_variable("u"))
    solver = make_solver("ilqr", prb)
    assert solver.solve() and solver.stats.success

    def failing(_record):
        raise KeyError("boom")

    solver.set_option("callback", failing)
    with pytest.raises(KeyError):
        solver.solve()
    assert not solver.stats.success and solver.stats.status == "interrupted (KeyError)"


def test_none_as_a_value_or_guess_is_refused_where_it_is_given(prb):
    """numpy takes None as NaN: p.assign(None) and set_initial_guess(None) were stored and
    only the solve said something was not finite (a QA finding)."""
    p = prb.create_parameter("p", 2)
    with pytest.raises(TypeError, match="value of 'p' is or holds None"):
        p.assign(None)
    with pytest.raises(TypeError, match="initial guess of 'x' is or holds None"):
        prb.get_variable("x").set_initial_guess(None, nodes=2)
    # an element too (a bound's None element is no bound; a guess's was a NaN, session 28)
    with pytest.raises(TypeError, match="value of 'p' is or holds None"):
        p.assign([None, 1.0])
    with pytest.raises(TypeError, match="initial guess of 'x' is or holds None"):
        prb.get_variable("x").set_initial_guess([[None], [1.0]], nodes=2)
    assert np.isfinite(prb.get_variable("x").initial_guess).all()
    assert np.isfinite(p.values).all()
    u = prb.get_variable("u")
    u.set_bounds(np.array([None]), 1.0)  # an object array as the list it holds
    assert u.lower_bounds[0, 0] == -np.inf
