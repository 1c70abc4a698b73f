"""integrate / difference on the configuration Lie group agree with Pinocchio."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pinocchio as pin
import pytest
from model_reference import ROBOTS, evaluate, model, random_states, rel_err

TOL = 1e-9


@pytest.fixture(scope="module", params=("go2", "solo12", "talos", "ur5", "centauro_wheels"))
def case(request):
    m = model(request.param)
    s = random_states(m)
    rng = np.random.default_rng(2)
    n = s["q"].shape[1]
    # Tangent steps from large (about 1 rad) down to tiny, to cover the small-angle branches.
    scales = np.logspace(0, -9, n)
    s["dq"] = rng.normal(size=(m.nv, n)) * scales
    return m, s


def _pin_columns(func, *cols):
    return np.column_stack([func(*(c[:, i] for c in cols)) for i in range(cols[0].shape[1])])


def test_integrate_matches_pinocchio(case):
    m, s = case
    (q_next,) = evaluate(m.integrate(), s["q"], s["dq"])
    expected = _pin_columns(lambda q, dq: pin.integrate(m.pin_model, q, dq), s["q"], s["dq"])
    assert rel_err(q_next[:, 0, :], expected) < TOL


def test_difference_matches_pinocchio(case):
    m, s = case
    q1 = _pin_columns(lambda q, dq: pin.integrate(m.pin_model, q, dq), s["q"], s["dq"])
    (dq,) = evaluate(m.difference(), s["q"], q1)
    expected = _pin_columns(lambda a, b: pin.difference(m.pin_model, a, b), s["q"], q1)
    assert rel_err(dq[:, 0, :], expected) < TOL
    assert rel_err(dq[:, 0, :], s["dq"]) < 1e-9


def test_integrate_keeps_quaternion_unit_norm_over_many_steps():
    m = model("go2")
    step = m.integrate()
    q = m.neutral()
    dq = np.random.default_rng(3).normal(size=m.nv) * 0.3
    for _ in range(1000):
        q = step(q, dq).full().ravel()
    assert abs(np.linalg.norm(q[3:7]) - 1.0) < 1e-12


def test_difference_of_a_configuration_with_itself_is_zero():
    m = model("go2")
    q = random_states(m, n=1)["q"][:, 0]
    assert np.max(np.abs(m.difference()(q, q).full())) < 1e-15  # rounding of conj(q) * q


@pytest.mark.parametrize("name", ROBOTS)
def test_neutral_matches_pinocchio(name):
    m = model(name)
    assert np.array_equal(m.neutral(), pin.neutral(m.pin_model))


def test_tangent_map_is_the_derivative_of_integrate_at_zero():
    m = model("centauro_wheels")
    s = random_states(m, n=5)
    q, dq = cs.SX.sym("q", m.nq), cs.SX.sym("dq", m.nv)
    jac = cs.Function("j", [q, dq], [cs.jacobian(m.integrate()(q, dq), dq)])
    for i in range(5):
        qi = s["q"][:, i]
        expected = jac(qi, np.zeros(m.nv)).full()
        assert rel_err(m.tangent_map()(qi).full(), expected) < 1e-12


def test_difference_after_integrate_has_identity_jacobian_at_zero():
    # Costs like ||difference(q, q_ref)|| are differentiated at q = q_ref: must be finite.
    m = model("centauro_wheels")
    q0, dq = cs.SX.sym("q", m.nq), cs.SX.sym("dq", m.nv)
    expr = m.difference()(q0, m.integrate()(q0, dq))
    jac = cs.Function("j", [q0, dq], [cs.jacobian(expr, dq)])
    for q in random_states(m, n=5)["q"].T:
        assert rel_err(jac(q, np.zeros(m.nv)).full(), np.eye(m.nv)) < 1e-12
