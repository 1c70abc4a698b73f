"""Jacobians of the symbolic inverse dynamics agree with Pinocchio's RNEA derivatives."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pinocchio as pin
import pytest
from model_reference import FEET, contact_fext, evaluate, model, random_states, rel_err

TOL = 1e-7  # the brief's bound for derivatives (observed: ~1e-13)
N = 50


def _pin_derivatives(m, contacts, q, v, a, f):
    """Pinocchio's (dtau_dq, dtau_dv, M) for forces fixed in world axes.

    ``computeRNEADerivatives`` holds ``fext`` fixed in the joint frames; a force fixed in
    world axes also turns with the frame, which adds ``-J_lin^T [f_local]x J_ang`` per
    contact (LOCAL Jacobians, ``f_local`` the force in the contact frame).
    """
    pm = m.pin_model
    data = pm.createData()
    pin.forwardKinematics(pm, data, q)
    pin.computeRNEADerivatives(pm, data, q, v, a, contact_fext(m, data, contacts, f))
    dq, dv = data.dtau_dq.copy(), data.dtau_dv.copy()
    mass = np.triu(data.M) + np.triu(data.M, 1).T
    pin.computeJointJacobians(pm, data, q)
    pin.updateFramePlacements(pm, data)
    for k, name in enumerate(contacts):
        fid = m.frame_id(name)
        jac = pin.getFrameJacobian(pm, data, fid, pin.ReferenceFrame.LOCAL)
        f_local = data.oMf[fid].rotation.T @ f[3 * k : 3 * k + 3]
        dq -= jac[:3].T @ pin.skew(f_local) @ jac[3:]
    return dq, dv, mass


def _contacts(name):
    if name in FEET:
        return FEET[name]
    return ["contact_1", "contact_2", "contact_3", "contact_4"]  # centauro's wheel frames


@pytest.mark.parametrize("name", ["go2", pytest.param("centauro_wheels", marks=pytest.mark.slow)])
def test_inverse_dynamics_jacobians_match_rnea_derivatives(name):
    m = model(name)
    contacts = _contacts(name)
    s = random_states(m, n=N)
    f = 50.0 * np.random.default_rng(4).normal(size=(3 * len(contacts), N))
    fn = m.inverse_dynamics_derivatives(contacts)
    tau, dq, dv, da, df = evaluate(fn, s["q"], s["v"], s["a"], f)
    (tau_ref,) = evaluate(m.inverse_dynamics(contacts), s["q"], s["v"], s["a"], f)
    assert rel_err(tau, tau_ref) < 1e-12
    for i in range(N):
        cols = (s["q"][:, i], s["v"][:, i], s["a"][:, i], f[:, i])
        ref_dq, ref_dv, ref_da = _pin_derivatives(m, contacts, *cols)
        assert rel_err(dq[:, :, i], ref_dq) < TOL
        assert rel_err(dv[:, :, i], ref_dv) < TOL
        assert rel_err(da[:, :, i], ref_da) < TOL


def test_contact_force_jacobian_is_minus_the_contact_jacobian_transposed():
    m = model("go2")
    contacts = FEET["go2"]
    s = random_states(m, n=5)
    f = np.ones((12, 5))
    (df,) = evaluate(m.inverse_dynamics_derivatives(contacts), s["q"], s["v"], s["a"], f)[4:]
    for i in range(5):
        jacs = [m.jacobian(c, "LOCAL_WORLD_ALIGNED")(s["q"][:, i]).full()[:3] for c in contacts]
        assert rel_err(df[:, :, i], -np.vstack(jacs).T) < 1e-12


@pytest.mark.parametrize("name", ["solo12", "anymal_c", "panda", "ur5"])
def test_analytical_derivatives_match_casadi_ad(name):
    # Other joint types (unaligned revolute, prismatic) and fixed bases, against plain AD.
    m = model(name)
    contacts = [m.frame_names[-1], m.frame_names[len(m.frame_names) // 2]]
    q, v, a = (cs.SX.sym(x, n) for x, n in (("q", m.nq), ("v", m.nv), ("a", m.nv)))
    f = cs.SX.sym("f", 6)
    tau = m.inverse_dynamics(contacts)(q, v, a, f)
    jq = cs.jacobian(tau, q) @ m.tangent_map()(q)
    ad = cs.Function("ad", [q, v, a, f], [tau, jq] + [cs.jacobian(tau, x) for x in (v, a, f)])
    s = random_states(m, n=20)
    forces = 50.0 * np.random.default_rng(5).normal(size=(6, 20))
    args = (s["q"], s["v"], s["a"], forces)
    got = evaluate(m.inverse_dynamics_derivatives(contacts), *args)
    for value, expected in zip(got, evaluate(ad, *args), strict=True):
        assert rel_err(value, expected) < 1e-9


def test_casadi_ad_of_inverse_dynamics_through_integrate_matches_pinocchio():
    # What a solver does with the plain ID Function: d/d(dq) ID(integrate(q, dq), ...) at 0.
    m = model("go2")
    contacts = FEET["go2"]
    q, dq = cs.SX.sym("q", m.nq), cs.SX.sym("dq", m.nv)
    v, a, f = cs.SX.sym("v", m.nv), cs.SX.sym("a", m.nv), cs.SX.sym("f", 12)
    tau = m.inverse_dynamics(contacts)(m.integrate()(q, dq), v, a, f)
    jacs = [cs.jacobian(tau, x) for x in (dq, v, a)]
    ad = cs.Function("ad", [q, dq, v, a, f], jacs)
    s = random_states(m, n=10)
    forces = 50.0 * np.random.default_rng(6).normal(size=(12, 10))
    for i in range(10):
        cols = (s["q"][:, i], s["v"][:, i], s["a"][:, i], forces[:, i])
        got = ad(cols[0], np.zeros(m.nv), *cols[1:])
        for value, expected in zip(got, _pin_derivatives(m, contacts, *cols), strict=True):
            assert rel_err(value.full(), expected) < TOL
