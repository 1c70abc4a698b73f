"""Shared helpers for the symbolic-model tests: random states and Pinocchio references.

Not a test module (no ``test_`` prefix): imported by ``test_model_*.py``.
"""

from __future__ import annotations

import re
from functools import cache

import casadi as cs
import numpy as np
import pinocchio as pin

from horizon_mpc.model import RobotModel

N_STATES = 50  # random states per robot and quantity (the brief asks for 50+)
REFS = ("LOCAL", "WORLD", "LOCAL_WORLD_ALIGNED")
# Robots of the brief; ur5 and panda are fixed-base arms.
ROBOTS = ("go2", "go1", "a1", "solo12", "anymal_c", "hyq", "centauro", "talos", "ur5", "panda")
FEET = {
    "go2": ["FL_foot", "FR_foot", "RL_foot", "RR_foot"],
    "solo12": ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"],
}

# The centauro URDF marks its wheel joints "revolute" with a comment "actually continuous":
# turning them into continuous joints gives a real robot with nq != nv (JointModelRUB*).
_WHEEL_JOINT = re.compile(r'(<joint name="j_wheel_\d" type=)"revolute"')


@cache
def model(name: str) -> RobotModel:
    """One RobotModel per robot for the whole session (Functions are cached inside)."""
    if name == "centauro_wheels":
        return RobotModel.from_urdf(centauro_wheels_urdf(), name="centauro_wheels")
    return RobotModel.from_example(name)


def centauro_wheels_urdf() -> str:
    """Centauro's URDF text with its four wheels as continuous joints."""
    from horizon_mpc.robots import example_robot_files

    text = example_robot_files("centauro").urdf.read_text()
    text, count = _WHEEL_JOINT.subn(r'\1"continuous"', text)
    assert count == 4
    return text


def random_states(m: RobotModel, n: int = N_STATES, seed: int = 0) -> dict[str, np.ndarray]:
    """Columns of random q (nq, n), v, a (nv, n) within the joint limits where finite."""
    rng = np.random.default_rng(seed)
    pm = m.pin_model
    qs = np.empty((m.nq, n))
    for k in range(n):
        q = m.neutral()
        for j in range(1, pm.njoints):
            jm = pm.joints[j]
            iq = jm.idx_q
            short = jm.shortname()
            if short == "JointModelFreeFlyer":
                q[iq : iq + 3] = rng.uniform(-1, 1, 3)
                quat = rng.normal(size=4)
                q[iq + 3 : iq + 7] = quat / np.linalg.norm(quat)
            elif jm.nq == 2:
                angle = rng.uniform(-np.pi, np.pi)
                q[iq : iq + 2] = np.cos(angle), np.sin(angle)
            else:
                lo, hi = pm.lowerPositionLimit[iq], pm.upperPositionLimit[iq]
                if np.isfinite(lo) and np.isfinite(hi) and hi > lo and hi - lo < 1e3:
                    q[iq] = rng.uniform(lo, hi)
                else:
                    q[iq] = rng.normal()
        qs[:, k] = q
    return {
        "q": qs,
        "v": rng.normal(size=(m.nv, n)),
        "a": rng.normal(size=(m.nv, n)),
    }


def evaluate(fn: cs.Function, *args: np.ndarray) -> list[np.ndarray]:
    """All outputs of ``fn`` over the columns of ``args`` in one mapped call.

    Output k of state i is ``out[k][..., i]`` with the output's own shape in front.
    """
    n = args[0].shape[1]
    res = fn.map(n)(*args)
    res = res if isinstance(res, (list, tuple)) else [res]
    outs = []
    for k, r in enumerate(res):
        shape = fn.size_out(k)
        arr = np.asarray(cs.DM(r).full()).reshape(shape[0], n, shape[1])
        outs.append(np.moveaxis(arr, 1, 2))
    return outs


def rel_err(value: np.ndarray, ref: np.ndarray) -> float:
    """max |value - ref| / max(1, |ref|), elementwise."""
    value, ref = np.asarray(value, float), np.asarray(ref, float)
    assert value.shape == ref.shape, (value.shape, ref.shape)
    return float(np.max(np.abs(value - ref) / np.maximum(1.0, np.abs(ref))))


def contact_fext(m: RobotModel, data: pin.Data, frames: list[str], f: np.ndarray) -> list:
    """Pinocchio ``fext`` (one pin.Force per joint, local frames) of world point forces.

    ``data`` must hold the placements of q (``forwardKinematics``).
    """
    pm = m.pin_model
    fext = [pin.Force.Zero() for _ in range(pm.njoints)]
    for k, name in enumerate(frames):
        frame = pm.frames[m.frame_id(name)]
        j = frame.parentJoint
        lin = data.oMi[j].rotation.T @ f[3 * k : 3 * k + 3]
        fext[j] = fext[j] + pin.Force(lin, np.cross(frame.placement.translation, lin))
    return fext


def frames_to_check(m: RobotModel, n_random: int = 3, seed: int = 0) -> list[str]:
    """Frames worth checking: the ones on the deepest joints, plus a few random ones."""
    pm = m.pin_model
    depth = [0] * pm.njoints
    for j in range(1, pm.njoints):
        depth[j] = depth[pm.parents[j]] + 1
    names = list(dict.fromkeys(f.name for f in pm.frames))
    ranked = sorted(names, key=lambda n: -depth[pm.frames[m.frame_id(n)].parentJoint])
    rng = np.random.default_rng(seed)
    chosen = ranked[:5] + list(rng.choice(names, size=n_random, replace=False))
    return list(dict.fromkeys(chosen))
