"""Symbolic dynamics agree with Pinocchio on every listed robot (50 random states each)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from model_reference import ROBOTS, contact_fext, evaluate, model, random_states, rel_err

TOL = 1e-9  # relative to max(1, |reference|)
FORCE_SCALE = 50.0  # N: contact forces of the order of a quadruped's weight share


def _contact_frames(m) -> list[str]:
    """Two to four contacts on the deepest frames (different joints when possible)."""
    pm = m.pin_model
    depth = [0] * pm.njoints
    for j in range(1, pm.njoints):
        depth[j] = depth[pm.parents[j]] + 1
    chosen, joints = [], set()
    for name in sorted(m.frame_names, key=lambda n: -depth[pm.frames[m.frame_id(n)].parentJoint]):
        joint = pm.frames[m.frame_id(name)].parentJoint
        if joint not in joints:
            chosen.append(name)
            joints.add(joint)
        if len(chosen) == 4:
            break
    return chosen


@pytest.fixture(scope="module", params=(*ROBOTS, "centauro_wheels"))
def case(request):
    m = model(request.param)
    states = random_states(m)
    contacts = _contact_frames(m)
    rng = np.random.default_rng(1)
    states["f"] = FORCE_SCALE * rng.normal(size=(3 * len(contacts), states["q"].shape[1]))
    return m, states, contacts


def _columns(fn, s, *keys):
    n = s["q"].shape[1]
    return np.column_stack([fn(*(s[k][:, i] for k in keys)) for i in range(n)])


def test_inverse_dynamics_with_contacts_matches_rnea(case):
    m, s, contacts = case
    pm = m.pin_model
    data = pm.createData()

    def ref(q, v, a, f):
        pin.forwardKinematics(pm, data, q)
        return pin.rnea(pm, data, q, v, a, contact_fext(m, data, contacts, f))

    (tau,) = evaluate(m.inverse_dynamics(contacts), s["q"], s["v"], s["a"], s["f"])
    assert rel_err(tau[:, 0, :], _columns(ref, s, "q", "v", "a", "f")) < TOL


def test_forward_dynamics_with_contacts_matches_aba(case):
    m, s, contacts = case
    pm = m.pin_model
    data = pm.createData()
    s = dict(s, tau=s["a"] * 10.0)

    def ref(q, v, tau, f):
        pin.forwardKinematics(pm, data, q)
        return pin.aba(pm, data, q, v, tau, contact_fext(m, data, contacts, f))

    (acc,) = evaluate(m.forward_dynamics(contacts), s["q"], s["v"], s["tau"], s["f"])
    assert rel_err(acc[:, 0, :], _columns(ref, s, "q", "v", "tau", "f")) < TOL


def test_forward_dynamics_inverts_inverse_dynamics(case):
    m, s, contacts = case
    (tau,) = evaluate(m.inverse_dynamics(contacts), s["q"], s["v"], s["a"], s["f"])
    (acc,) = evaluate(m.forward_dynamics(contacts), s["q"], s["v"], tau[:, 0, :], s["f"])
    assert rel_err(acc[:, 0, :], s["a"]) < 1e-8  # M^-1 amplifies rounding by cond(M)


def test_mass_matrix_matches_crba(case):
    m, s, _ = case
    pm = m.pin_model
    data = pm.createData()

    def ref(q):
        mass = pin.crba(pm, data, q)
        return np.triu(mass) + np.triu(mass, 1).T  # Pinocchio may fill only the upper part

    (mass,) = evaluate(m.mass_matrix(), s["q"])
    expected = np.stack([ref(s["q"][:, i]) for i in range(s["q"].shape[1])], axis=2)
    assert rel_err(mass, expected) < TOL


def test_nonlinear_effects_and_gravity_match_pinocchio(case):
    m, s, _ = case
    pm = m.pin_model
    data = pm.createData()
    (nle,) = evaluate(m.nonlinear_effects(), s["q"], s["v"])
    (grav,) = evaluate(m.gravity(), s["q"])
    expected_nle = _columns(lambda q, v: pin.nonLinearEffects(pm, data, q, v), s, "q", "v")
    expected_g = _columns(lambda q: pin.computeGeneralizedGravity(pm, data, q), s, "q")
    assert rel_err(nle[:, 0, :], expected_nle) < TOL
    assert rel_err(grav[:, 0, :], expected_g) < TOL


def test_center_of_mass_position_and_velocity_match_pinocchio(case):
    m, s, _ = case
    pm = m.pin_model
    data = pm.createData()

    def ref(q, v):
        pin.centerOfMass(pm, data, q, v)
        return np.concatenate([data.com[0], data.vcom[0]])

    (com,) = evaluate(m.com(), s["q"])
    (vcom,) = evaluate(m.com_velocity(), s["q"], s["v"])
    expected = _columns(ref, s, "q", "v")
    assert rel_err(com[:, 0, :], expected[:3]) < TOL
    assert rel_err(vcom[:, 0, :], expected[3:]) < TOL


def test_total_mass_matches_pinocchio(case):
    m, _, _ = case
    assert m.mass == pytest.approx(pin.computeTotalMass(m.pin_model), rel=1e-12)


def test_centroidal_momentum_matches_pinocchio(case):
    m, s, _ = case
    pm = m.pin_model
    data = pm.createData()

    def ref(q, v):
        return pin.computeCentroidalMomentum(pm, data, q, v).vector

    (h,) = evaluate(m.centroidal_momentum(), s["q"], s["v"])
    assert rel_err(h[:, 0, :], _columns(ref, s, "q", "v")) < TOL


_INERTIAL = ('<inertial><origin xyz="0.1 0.02 -0.03"/><mass value="1.5"/><inertia ixx="0.1" '
             'ixy="0.01" ixz="0" iyy="0.2" iyz="0" izz="0.3"/></inertial>')


def test_a_second_free_flyer_below_the_root_has_the_crba_of_pinocchio():
    """A URDF 'floating' joint under the model's own free-flyer: its 6-column block of the
    CRBA was pushed through a 3-vector cross product (a CasADi dimension error)."""
    from horizon_mpc.model import RobotModel

    urdf = (f'<robot name="stacked"><link name="odom">{_INERTIAL}</link>'
            f'<link name="base">{_INERTIAL}</link><link name="arm">{_INERTIAL}</link>'
            '<joint name="float" type="floating"><parent link="odom"/><child link="base"/>'
            '</joint><joint name="j" type="revolute"><origin xyz="0.2 0 0" rpy="0.3 0 0"/>'
            '<parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>')
    m = RobotModel.from_urdf(urdf)
    pm = m.pin_model
    assert (pm.nq, pm.nv) == (15, 13)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
        ref = pin.crba(pm, pm.createData(), q)
        ref = np.triu(ref) + np.triu(ref, 1).T
        assert rel_err(np.asarray(m.mass_matrix()(q)), ref) < TOL
        v, a = rng.normal(size=pm.nv), rng.normal(size=pm.nv)
        tau = np.asarray(m.inverse_dynamics()(q, v, a, np.zeros(0))).ravel()
        assert rel_err(tau, pin.rnea(pm, pm.createData(), q, v, a)) < TOL


def test_a_joint_with_a_zero_axis_is_refused_by_name():
    """<axis xyz="0 0 0"/> built a model of NaNs with only a numpy warning."""
    from horizon_mpc.model import RobotModel

    urdf = (f'<robot name="zero"><link name="a">{_INERTIAL}</link><link name="b">{_INERTIAL}'
            '</link><joint name="j1" type="revolute"><parent link="a"/><child link="b"/>'
            '<axis xyz="0 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
            '</robot>')
    with pytest.raises(ValueError, match="joint 'j1' has a zero axis"):
        RobotModel.from_urdf(urdf, floating_base=False)
