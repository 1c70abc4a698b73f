"""Symbolic forward kinematics of the joint tree and of operational frames.

All spatial quantities of joints are held in the joint's own (LOCAL) frame, as in Pinocchio's
``data.v`` / ``data.a``; frame quantities are then expressed in the reference frame asked for:

* ``LOCAL``: the frame itself;
* ``WORLD``: world axes, at the world origin (spatial velocity);
* ``LOCAL_WORLD_ALIGNED``: world axes, at the frame origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np
import pinocchio as pin

from horizon_mpc.model.joints import JointSpec
from horizon_mpc.model.spatial import Motion, Transform, cross_motion

__all__ = [
    "REFERENCE_FRAMES",
    "FrameSpec",
    "TreeKinematics",
    "frame_specs",
    "frame_placement",
    "frame_velocity",
    "frame_acceleration",
    "frame_jacobian",
]

LOCAL = "LOCAL"
WORLD = "WORLD"
LOCAL_WORLD_ALIGNED = "LOCAL_WORLD_ALIGNED"
REFERENCE_FRAMES = (LOCAL, WORLD, LOCAL_WORLD_ALIGNED)


@dataclass(frozen=True)
class FrameSpec:
    """An operational frame: rigidly attached to joint ``parent`` with placement ``jMf``."""

    name: str
    parent: int
    R: np.ndarray  # (3, 3)
    p: np.ndarray  # (3,)

    @property
    def placement(self) -> Transform:
        """The frame's fixed placement in its parent joint's frame, as a symbolic Transform."""
        return Transform.from_numeric(self.R, self.p)


def frame_specs(model: pin.Model) -> list[FrameSpec]:
    """All frames of ``model`` in Pinocchio order (same indices as ``model.frames``)."""
    return [
        FrameSpec(
            fr.name,
            int(fr.parentJoint),
            np.array(fr.placement.rotation),
            np.array(fr.placement.translation),
        )
        for fr in model.frames
    ]


def _zero_motion() -> Motion:
    return cs.SX.zeros(3, 1), cs.SX.zeros(3, 1)


class TreeKinematics:
    """Placements, velocities and accelerations of every joint for symbolic (q, v, a).

    ``li_M[i]`` is ``parentMi(q)``, ``o_M[i]`` is ``oMi(q)``, ``vel[i]``/``acc[i]`` are the
    spatial velocity / acceleration of joint i in its local frame (acceleration without
    gravity, like ``data.a`` after Pinocchio's ``forwardKinematics(model, data, q, v, a)``).
    Index 0 is the universe. ``v`` and ``a`` may be None (then only placements / velocities
    are built).
    """

    def __init__(
        self, specs: list[JointSpec], q: cs.SX, v: cs.SX | None = None, a: cs.SX | None = None
    ) -> None:
        self.specs = specs
        self.li_M: dict[int, Transform] = {}
        self.o_M: dict[int, Transform] = {0: Transform.identity()}
        self.vel: dict[int, Motion] = {0: _zero_motion()}
        self.acc: dict[int, Motion] = {0: _zero_motion()}
        self.vj: dict[int, Motion] = {}
        for s in specs:
            li = _compose_placement(s, s.joint_transform(q))
            self.li_M[s.index] = li
            self.o_M[s.index] = self.o_M[s.parent] * li
            if v is None:
                continue
            vj = s.joint_velocity(v)
            self.vj[s.index] = vj
            vp = li.act_inv_motion(self.vel[s.parent]) if s.parent else _zero_motion()
            vi = (vp[0] + vj[0], vp[1] + vj[1])
            self.vel[s.index] = vi
            if a is None:
                continue
            aj = s.joint_velocity(a)  # S * a_j: same structure as S * v_j
            ap = li.act_inv_motion(self.acc[s.parent]) if s.parent else _zero_motion()
            cor = cross_motion(vi, vj)  # c_j = 0 for all supported joints
            self.acc[s.index] = (ap[0] + aj[0] + cor[0], ap[1] + aj[1] + cor[1])

    def support(self, joint: int) -> list[int]:
        """Joint indices from the root to ``joint`` (inclusive), universe excluded."""
        chain = []
        while joint > 0:
            chain.append(joint)
            joint = self.specs[joint - 1].parent
        return chain[::-1]


def _compose_placement(s: JointSpec, mj: Transform) -> Transform:
    # Skip the multiplication by an identity placement (most URDF joints): fewer SX nodes.
    if np.array_equal(s.placement_R, np.eye(3)):
        if not np.any(s.placement_p):
            return mj
        return Transform(mj.R, cs.SX(s.placement_p.reshape(3, 1)) + mj.p)
    return s.placement * mj


def frame_placement(kin: TreeKinematics, frame: FrameSpec) -> Transform:
    """``oMf(q)``."""
    return kin.o_M[frame.parent] * frame.placement


def _express(kin: TreeKinematics, frame: FrameSpec, m_joint: Motion, ref: str) -> Motion:
    """A motion given in the parent joint's local frame, expressed in ``ref`` of ``frame``."""
    if ref == WORLD:
        return kin.o_M[frame.parent].act_motion(m_joint)
    local = frame.placement.act_inv_motion(m_joint)
    if ref == LOCAL:
        return local
    r = frame_placement(kin, frame).R
    return r @ local[0], r @ local[1]


def frame_velocity(kin: TreeKinematics, frame: FrameSpec, ref: str) -> Motion:
    """Spatial velocity (lin, ang) of ``frame`` expressed in ``ref``."""
    return _express(kin, frame, kin.vel[frame.parent], ref)


def frame_acceleration(kin: TreeKinematics, frame: FrameSpec, ref: str) -> Motion:
    """Classical acceleration (lin, ang) of ``frame`` in ``ref``.

    Spatial acceleration plus ``omega x v`` on the linear part, with both taken in ``ref``
    (Pinocchio's ``getFrameClassicalAcceleration``).
    """
    vel = frame_velocity(kin, frame, ref)
    acc = _express(kin, frame, kin.acc[frame.parent], ref)
    return acc[0] + cs.cross(vel[1], vel[0]), acc[1]


def frame_jacobian(kin: TreeKinematics, frame: FrameSpec, ref: str, nv: int) -> cs.SX:
    """Frame Jacobian (6 x nv), rows (lin, ang), such that ``J v`` = frame velocity in ``ref``."""
    jac = cs.SX.zeros(6, nv)
    o_f = frame_placement(kin, frame)
    for j in kin.support(frame.parent):
        s = kin.specs[j - 1]
        o_j = kin.o_M[j]
        for k, (lin, ang) in enumerate(s.subspace()):
            # Column in world axes, taken at the frame origin (LOCAL_WORLD_ALIGNED).
            w = o_j.R @ ang if np.any(ang) else cs.SX.zeros(3, 1)
            vlin = o_j.R @ lin if np.any(lin) else cs.SX.zeros(3, 1)
            if np.any(ang):
                if ref == WORLD:
                    vlin = vlin + cs.cross(o_j.p, w)
                else:
                    vlin = vlin + cs.cross(o_j.p - o_f.p, w)
            if ref == LOCAL:
                vlin, w = o_f.R.T @ vlin, o_f.R.T @ w
            jac[0:3, s.idx_v + k] = vlin
            jac[3:6, s.idx_v + k] = w
    return jac
