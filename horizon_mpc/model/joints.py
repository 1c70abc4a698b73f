"""Joint models: what each Pinocchio joint contributes to the symbolic model.

A :class:`JointSpec` is read from a numeric Pinocchio model (tree, placement, inertia, index in
q and v) and knows how to build its own transform ``jMc(q)`` and motion subspace ``S``.

Supported Pinocchio joint types (all that its URDF parser creates for single-DoF and root
joints):

========================  ==========  ==  ==  =========================================
Pinocchio                 kind        nq  nv  configuration
========================  ==========  ==  ==  =========================================
JointModelFreeFlyer       free_flyer  7   6   ``[x, y, z, qx, qy, qz, qw]``
JointModelR{X,Y,Z}        revolute    1   1   angle (rad)
JointModelRevoluteUnal.   revolute    1   1   angle (rad), arbitrary unit axis
JointModelP{X,Y,Z}        prismatic   1   1   displacement (m)
JointModelPrismaticUnal.  prismatic   1   1   displacement (m), arbitrary unit axis
JointModelRUB{X,Y,Z}      continuous  2   1   ``[cos(angle), sin(angle)]``
JointModelRevoluteUnb.Un  continuous  2   1   ``[cos(angle), sin(angle)]``, arbitrary axis
========================  ==========  ==  ==  =========================================
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np
import pinocchio as pin

from horizon_mpc.model.spatial import Transform, axis_angle_rot, quat_to_rot

__all__ = ["JointSpec", "joint_specs"]

_FREE_FLYER = "free_flyer"
_REVOLUTE = "revolute"
_PRISMATIC = "prismatic"
_CONTINUOUS = "continuous"


@dataclass(frozen=True)
class JointSpec:
    """One movable joint of the kinematic tree (Pinocchio joint index ``index`` >= 1)."""

    index: int
    name: str
    kind: str  # free_flyer | revolute | prismatic | continuous
    parent: int  # Pinocchio index of the parent joint (0 = universe)
    idx_q: int
    idx_v: int
    nq: int
    nv: int
    axis: np.ndarray  # (3,) unit axis in the joint frame (unused for free_flyer)
    placement_R: np.ndarray  # (3, 3) parent joint frame <- this joint frame at q = neutral
    placement_p: np.ndarray  # (3,)
    mass: float
    com: np.ndarray  # (3,) centre of mass in the joint frame
    inertia_c: np.ndarray  # (3, 3) rotational inertia about the centre of mass

    @property
    def placement(self) -> Transform:
        """Constant ``parentMjoint`` (joint placement of the URDF)."""
        return Transform.from_numeric(self.placement_R, self.placement_p)

    def joint_transform(self, q: cs.SX) -> Transform:
        """Joint motion ``Mj(q)`` (the part of ``parentMchild`` that depends on q).

        Args:
            q: full configuration (nq,); this joint reads ``q[idx_q : idx_q + nq]``.
        """
        qj = q[self.idx_q : self.idx_q + self.nq]
        zero = cs.SX.zeros(3, 1)
        if self.kind == _FREE_FLYER:
            return Transform(quat_to_rot(qj[3:7]), qj[0:3])
        if self.kind == _REVOLUTE:
            return Transform(axis_angle_rot(self.axis, cs.cos(qj[0]), cs.sin(qj[0])), zero)
        if self.kind == _CONTINUOUS:
            # Pinocchio uses (cos, sin) as stored, without normalising them.
            return Transform(axis_angle_rot(self.axis, qj[0], qj[1]), zero)
        return Transform(cs.SX.eye(3), cs.SX(self.axis.reshape(3, 1)) * qj[0])

    def subspace(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Columns of the motion subspace S as (lin, ang) numeric pairs, one per DoF."""
        e = np.eye(3)
        z = np.zeros(3)
        if self.kind == _FREE_FLYER:
            return [(e[k], z) for k in range(3)] + [(z, e[k]) for k in range(3)]
        if self.kind == _PRISMATIC:
            return [(self.axis, z)]
        return [(z, self.axis)]

    def joint_velocity(self, v: cs.SX) -> tuple[cs.SX, cs.SX]:
        """Spatial joint velocity ``S vj`` as (lin, ang) SX 3-vectors."""
        vj = v[self.idx_v : self.idx_v + self.nv]
        if self.kind == _FREE_FLYER:
            return vj[0:3], vj[3:6]
        axis = cs.SX(self.axis.reshape(3, 1)) * vj[0]
        zero = cs.SX.zeros(3, 1)
        return (axis, zero) if self.kind == _PRISMATIC else (zero, axis)


#: Pinocchio's joints of one axis (the URDF loader's revolute, continuous and prismatic)
_ONE_AXIS_JOINTS = frozenset(
    [f"JointModel{kind}{axis}" for kind in ("R", "P", "RUB") for axis in "XYZ"]
    + ["JointModelRevoluteUnaligned", "JointModelRevoluteUnboundedUnaligned",
       "JointModelPrismaticUnaligned"])


def _classify(jmodel: pin.JointModel, name: str = "") -> tuple[str, np.ndarray]:
    """Kind and axis of a Pinocchio joint, read from its motion subspace.

    Raises:
        NotImplementedError: a joint type the model does not support.
        ValueError: a joint whose axis is zero (``<axis xyz="0 0 0"/>``: it moves nothing).
    """
    short = jmodel.shortname()
    if short == "JointModelFreeFlyer":
        return _FREE_FLYER, np.zeros(3)
    # by name: a composite (or any other) joint of one degree of freedom has a motion axis
    # too, and its inner placements would be dropped without a word
    if short not in _ONE_AXIS_JOINTS:
        raise NotImplementedError(
            f"joint {name!r}: joint type {short} is not supported; supported: free-flyer "
            "(URDF 'floating'), revolute, prismatic and continuous joints (see "
            "horizon_mpc.model.joints)"
        )
    jdata = jmodel.createData()
    jmodel.calc(jdata, _neutral(jmodel))
    s = np.asarray(jdata.S).reshape(6)
    lin, ang = s[:3], s[3:]
    if max(np.linalg.norm(lin), np.linalg.norm(ang)) < 1e-12:
        raise ValueError(f"joint {name!r} has a zero axis (URDF <axis xyz=\"0 0 0\"/>): it "
                         "moves nothing; give its axis, or make it a fixed joint")
    if jmodel.nq == 2:
        return _CONTINUOUS, ang / np.linalg.norm(ang)
    if np.linalg.norm(ang) > 0.5:
        return _REVOLUTE, ang / np.linalg.norm(ang)
    return _PRISMATIC, lin / np.linalg.norm(lin)


def _neutral(jmodel: pin.JointModel) -> np.ndarray:
    return np.array([1.0, 0.0]) if jmodel.nq == 2 else np.zeros(jmodel.nq)


def joint_specs(model: pin.Model) -> list[JointSpec]:
    """The movable joints of ``model`` in Pinocchio order (index 1 .. njoints - 1)."""
    specs = []
    for i in range(1, model.njoints):
        jm = model.joints[i]
        kind, axis = _classify(jm, model.names[i])
        placement = model.jointPlacements[i]
        inertia = model.inertias[i]
        specs.append(
            JointSpec(
                index=i,
                name=model.names[i],
                kind=kind,
                parent=int(model.parents[i]),
                idx_q=jm.idx_q,
                idx_v=jm.idx_v,
                nq=jm.nq,
                nv=jm.nv,
                axis=axis,
                placement_R=np.array(placement.rotation),
                placement_p=np.array(placement.translation),
                mass=float(inertia.mass),
                com=np.array(inertia.lever),
                inertia_c=np.array(inertia.inertia),
            )
        )
    return specs
