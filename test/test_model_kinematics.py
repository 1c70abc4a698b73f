"""Symbolic kinematics agree with Pinocchio on every listed robot (50 random states each)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from model_reference import (
    REFS,
    ROBOTS,
    evaluate,
    frames_to_check,
    model,
    random_states,
    rel_err,
)

TOL = 1e-9  # relative to max(1, |reference|): a few hundred roundings of double precision

ROBOTS_AND_WHEELS = (*ROBOTS, "centauro_wheels")


def _reference(m, states, frames):
    """Pinocchio placements, velocities, classical accelerations and Jacobians per frame."""
    pm = m.pin_model
    data = pm.createData()
    n = states["q"].shape[1]
    out = {}
    for name in frames:
        fid = m.frame_id(name)
        rec = {"pos": np.empty((3, 1, n)), "rot": np.empty((3, 3, n))}
        for ref in REFS:
            rec[f"vel_{ref}"] = np.empty((6, 1, n))
            rec[f"acc_{ref}"] = np.empty((6, 1, n))
            rec[f"jac_{ref}"] = np.empty((6, m.nv, n))
        out[name] = rec
    for i in range(n):
        q, v, a = states["q"][:, i], states["v"][:, i], states["a"][:, i]
        pin.forwardKinematics(pm, data, q, v, a)
        pin.updateFramePlacements(pm, data)
        pin.computeJointJacobians(pm, data, q)
        for name in frames:
            fid = m.frame_id(name)
            rec = out[name]
            rec["pos"][:, 0, i] = data.oMf[fid].translation
            rec["rot"][:, :, i] = data.oMf[fid].rotation
            for ref in REFS:
                rf = getattr(pin.ReferenceFrame, ref)
                rec[f"vel_{ref}"][:, 0, i] = pin.getFrameVelocity(pm, data, fid, rf).vector
                acc = pin.getFrameClassicalAcceleration(pm, data, fid, rf).vector
                rec[f"acc_{ref}"][:, 0, i] = acc
                rec[f"jac_{ref}"][:, :, i] = pin.getFrameJacobian(pm, data, fid, rf)
    return out


@pytest.fixture(scope="module", params=ROBOTS_AND_WHEELS)
def case(request):
    m = model(request.param)
    states = random_states(m)
    frames = frames_to_check(m)
    return m, states, frames, _reference(m, states, frames)


def test_forward_kinematics_matches_pinocchio(case):
    m, s, frames, ref = case
    for name in frames:
        pos, rot = evaluate(m.fk(name), s["q"])
        assert rel_err(pos, ref[name]["pos"]) < TOL, name
        assert rel_err(rot, ref[name]["rot"]) < TOL, name


@pytest.mark.parametrize("frame_ref", REFS)
def test_frame_velocity_matches_pinocchio(case, frame_ref):
    m, s, frames, ref = case
    for name in frames:
        lin, ang = evaluate(m.frame_velocity(name, frame_ref), s["q"], s["v"])
        assert rel_err(np.vstack([lin, ang]), ref[name][f"vel_{frame_ref}"]) < TOL, name


@pytest.mark.parametrize("frame_ref", REFS)
def test_classical_frame_acceleration_matches_pinocchio(case, frame_ref):
    m, s, frames, ref = case
    for name in frames:
        fn = m.frame_acceleration(name, frame_ref)
        lin, ang = evaluate(fn, s["q"], s["v"], s["a"])
        assert rel_err(np.vstack([lin, ang]), ref[name][f"acc_{frame_ref}"]) < TOL, name


@pytest.mark.parametrize("frame_ref", REFS)
def test_frame_jacobian_matches_pinocchio(case, frame_ref):
    m, s, frames, ref = case
    for name in frames:
        (jac,) = evaluate(m.jacobian(name, frame_ref), s["q"])
        assert rel_err(jac, ref[name][f"jac_{frame_ref}"]) < TOL, name
