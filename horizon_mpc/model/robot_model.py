"""``RobotModel``: symbolic kinematics and dynamics of a URDF robot as CasADi Functions.

Conventions (Pinocchio's; full statement in ``doc/model.md``):

* ``q = [p (3), quat (x, y, z, w), joints]`` for a floating base, ``q = joints`` otherwise;
  continuous joints take two entries ``(cos, sin)``;
* ``v = [base linear (3), base angular (3), joint velocities]``, base part in the base frame;
* contact forces ``f`` stack 3 components per contact frame, in world axes, applied at the
  frame origin.

Every method returns a ``casadi.Function`` with named inputs and outputs, built in SX and
cached per (kind, frames, reference frame).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import casadi as cs
import numpy as np
import pinocchio as pin

from horizon_mpc import codegen
from horizon_mpc.config import did_you_mean
from horizon_mpc.model import kinematics, liegroup
from horizon_mpc.model.functions import SymbolicFunctions
from horizon_mpc.model.joints import joint_specs
from horizon_mpc.model.kinematics import REFERENCE_FRAMES, FrameSpec, TreeKinematics
from horizon_mpc.model.loading import load_pin_model
from horizon_mpc.model.srdf import read_group_states

if TYPE_CHECKING:
    from horizon_mpc.config import RobotConfig

__all__ = ["RobotModel", "UnknownNameError"]

log = logging.getLogger(__name__)

#: example-robot-data robots that are bolted to the ground
FIXED_BASE_ROBOTS = frozenset({"ur5", "panda"})
_BIG = 1e300  # Pinocchio writes "no limit" as the largest double


def _listed(names: list[str], shown: int = 8) -> str:
    """``names`` joined by commas, the first ``shown`` of them and how many more."""
    more = f", ... {len(names) - shown} more" if len(names) > shown else ""
    return ", ".join(names[:shown]) + more


class UnknownNameError(KeyError):
    """A frame, joint or posture name that the model does not have (message lists valid ones)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def _no_limit(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    x[x >= _BIG] = np.inf
    x[x <= -_BIG] = -np.inf
    return x


class RobotModel(SymbolicFunctions):
    """Symbolic model of one robot, on top of a numeric Pinocchio model.

    Attributes:
        name: robot name.
        pin_model: the numeric ``pinocchio.Model`` (reference for verification).
        nq, nv: sizes of q and v.
        floating_base: True if the root joint is a free-flyer.
        joint_names: actuated joint names in model order (root free-flyer excluded).
        frame_names: all frame names in model order (first occurrence of duplicates).
        mass: total mass (kg).
        q_lower, q_upper: (nq,) position limits (+-inf where unbounded).
        v_limit, effort_limit: (nv,) velocity / effort limits (inf where unbounded).
        unset_limits: ``{"position" | "velocity" | "effort": [joint names]}``: the URDF's
            limits of zero (a range with lower >= upper), read as no limit (inf) and
            logged.
        joint_position_lower, joint_position_upper, joint_velocity_limit, joint_effort_limit:
            the same limits per actuated joint, ``(len(joint_names),)``.
        joint_idx_q, joint_idx_v: joint name -> first index in q / v.
    """

    def __init__(
        self, pin_model: pin.Model, name: str | None = None, srdf: str | Path | None = None
    ) -> None:
        if not isinstance(pin_model, pin.Model):  # RobotModel("go2"): 'no attribute armature'
            raise TypeError(f"RobotModel takes a pinocchio.Model, got {pin_model!r}: use "
                            "RobotModel.from_example(name) or RobotModel.from_urdf(path)")
        armature = np.asarray(pin_model.armature, dtype=float)
        if np.any(armature != 0.0):
            # Pinocchio's crba/rnea/aba add it; the symbolic dynamics here do not
            joints = [pin_model.names[j] for j in range(1, pin_model.njoints)
                      if np.any(armature[pin_model.idx_vs[j]:pin_model.idx_vs[j]
                                         + pin_model.nvs[j]] != 0.0)]
            raise ValueError(f"pin_model.armature is not zero (joints {joints}): rotor "
                             "inertia is not modelled by RobotModel's dynamics; set "
                             "pin_model.armature[:] = 0 or add it to your model's terms")
        self.pin_model = pin_model
        self.name = name or pin_model.name
        self._specs = joint_specs(pin_model)
        self._frames = kinematics.frame_specs(pin_model)
        self.nq, self.nv = int(pin_model.nq), int(pin_model.nv)
        self.floating_base = bool(self._specs) and self._specs[0].kind == "free_flyer"
        actuated = [s for s in self._specs if s.kind != "free_flyer"]
        self.joint_names = [s.name for s in actuated]
        self.joint_idx_q = {s.name: s.idx_q for s in actuated}
        self.joint_idx_v = {s.name: s.idx_v for s in actuated}
        self._frame_index: dict[str, int] = {}
        for k, fr in enumerate(self._frames):
            self._frame_index.setdefault(fr.name, k)  # duplicates: first in model order
        self.frame_names = list(self._frame_index)
        self.mass = float(sum(s.mass for s in self._specs))
        self.q_lower = _no_limit(pin_model.lowerPositionLimit)
        self.q_upper = _no_limit(pin_model.upperPositionLimit)
        self.v_limit = _no_limit(pin_model.velocityLimit)
        self.effort_limit = _no_limit(pin_model.effortLimit)
        for s in self._specs:
            if s.kind in ("free_flyer", "continuous"):
                self.q_lower[s.idx_q : s.idx_q + s.nq] = -np.inf
                self.q_upper[s.idx_q : s.idx_q + s.nq] = np.inf
        self.unset_limits = self._drop_unset_limits(actuated)
        # continuous joints have nq = 2 and no position limit
        self.joint_position_lower = np.array([self.q_lower[s.idx_q] for s in actuated])
        self.joint_position_upper = np.array([self.q_upper[s.idx_q] for s in actuated])
        self.joint_velocity_limit = np.array([self.v_limit[s.idx_v] for s in actuated])
        self.joint_effort_limit = np.array([self.effort_limit[s.idx_v] for s in actuated])
        self._gravity = np.array(pin_model.gravity.linear)
        self._srdf = Path(srdf) if srdf is not None else None
        self._states: dict[str, dict[str, list[float]]] | None = None
        self._q = cs.SX.sym("q", self.nq)
        self._v = cs.SX.sym("v", self.nv)
        self._a = cs.SX.sym("a", self.nv)
        self._kin: dict[tuple[str, str], TreeKinematics] = {}
        self._functions: dict[tuple, cs.Function] = {}

    def _drop_unset_limits(self, actuated: list) -> dict[str, list[str]]:
        """Limits the URDF writes as zero read as no limit (inf), in place: an effort or
        velocity <= 0 and a position range with lower >= upper (URDF exporters write 0 for
        a value they do not know; a revolute joint's range defaults to [0, 0]: CENTAURO's
        wheels). Bounds of zero made the walking problem infeasible (a go2 URDF with
        ``effort="0"`` fell in 0.4 s) or froze the robot (``lower = upper = 0``: it stood
        still, no word). Returns ``{"position" | "velocity" | "effort": [joint names]}``
        of the limits so read, logged once here: at INFO for ranges of [0, 0] only (the
        URDF's own default, a shipped robot's wheels), else a warning."""
        unset: dict[str, list[str]] = {"position": [], "velocity": [], "effort": []}
        inverted = False  # lower > upper: a URDF's mistake rather than its default
        for s in actuated:
            iq, iv = slice(s.idx_q, s.idx_q + s.nq), slice(s.idx_v, s.idx_v + s.nv)
            if np.any(self.q_lower[iq] >= self.q_upper[iq]):
                unset["position"].append(s.name)
                inverted |= bool(np.any(self.q_lower[iq] > self.q_upper[iq]))
                self.q_lower[iq], self.q_upper[iq] = -np.inf, np.inf
            for kind, limit in (("velocity", self.v_limit), ("effort", self.effort_limit)):
                if np.any(limit[iv] <= 0.0):
                    unset[kind].append(s.name)
                    limit[iv] = np.inf
        said = [f"{kind} ({_listed(names)})" for kind, names in unset.items() if names]
        if said:
            level = (logging.WARNING if inverted or unset["velocity"] or unset["effort"]
                     else logging.INFO)
            log.log(level, "%s: URDF limits of zero (or lower >= upper) taken as no limit: %s",
                    self.name, "; ".join(said))
        return unset

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_urdf(
        cls,
        urdf: str | Path,
        floating_base: bool = True,
        srdf: str | Path | None = None,
        name: str | None = None,
    ) -> RobotModel:
        """Model from a URDF file path or a URDF XML string.

        Args:
            urdf: path to a ``.urdf`` file, or the XML text itself.
            floating_base: add a free-flyer root joint (legged robots); False for arms.
            srdf: optional SRDF path for :meth:`reference_configuration`.
            name: model name (default: the URDF robot name).

        Raises:
            FileNotFoundError: ``urdf`` looks like a path and the file does not exist.
            ValueError: the URDF cannot be parsed.
            NotImplementedError: the URDF has a joint type this model does not handle.
        """
        return cls(load_pin_model(urdf, floating_base), name=name, srdf=srdf)

    @classmethod
    def from_example(cls, name: str, floating_base: bool | None = None) -> RobotModel:
        """Model of an example-robot-data robot (``go2``, ``solo12``, ``anymal_c``, ...).

        ``floating_base`` defaults to False for the arms (ur5, panda), True otherwise.

        Raises:
            KeyError: unknown robot name (the message lists the known ones).
        """
        from horizon_mpc.robots import example_robot_files

        files = example_robot_files(name)
        if floating_base is None:
            floating_base = name not in FIXED_BASE_ROBOTS
        return cls.from_urdf(files.urdf, floating_base=floating_base, srdf=files.srdf, name=name)

    @classmethod
    def from_config(cls, cfg: RobotConfig) -> RobotModel:
        """Model of a robot config (:class:`horizon_mpc.config.RobotConfig`): its
        ``urdf_path`` when it has one, else its example-robot-data robot."""
        return cls.from_urdf(cfg.urdf_path) if cfg.urdf_path else cls.from_example(cfg.robot)

    # ------------------------------------------------------------------ information
    @property
    def root_link(self) -> str:
        """The URDF's root link (the body the free-flyer or the fixed base carries)."""
        return next(f.name for f in self.pin_model.frames
                    if f.type == pin.FrameType.BODY and f.parentJoint <= 1)

    def neutral(self) -> np.ndarray:
        """Neutral configuration (nq,): base at origin, identity quaternion, joints at 0."""
        return liegroup.neutral(self._specs, self.nq)

    def reference_configuration_names(self) -> list[str]:
        """Names of the SRDF postures (empty without SRDF)."""
        return list(self._group_states())

    def reference_configuration(self, name: str, with_base: bool = False) -> np.ndarray:
        """Configuration (nq,) of the SRDF ``<group_state name=...>`` posture.

        The base is at the origin with identity orientation (unless ``with_base`` and the
        state gives the root joint's 7 values); joints the state does not list keep their
        neutral value. Continuous joints get ``(cos, sin)`` of the listed angle.

        Raises:
            UnknownNameError: no such posture (or no SRDF).
        """
        states = self._group_states()
        if name not in states:
            raise UnknownNameError(
                f"unknown reference configuration {name!r} for {self.name}; "
                f"available: {', '.join(states) or 'none (no SRDF given)'}"
            )
        q = self.neutral()
        by_name = {s.name: s for s in self._specs}
        for joint, values in states[name].items():
            s = by_name.get(joint)
            if s is None:
                log.warning("SRDF state %r: joint %r is not in the model", name, joint)
            elif s.kind == "free_flyer":
                if with_base and len(values) == 7:
                    q[s.idx_q : s.idx_q + 7] = values
            elif s.kind == "continuous":
                q[s.idx_q : s.idx_q + 2] = np.cos(values[0]), np.sin(values[0])
            else:
                q[s.idx_q] = values[0]
        return q

    def _group_states(self) -> dict[str, dict[str, list[float]]]:
        if self._states is None:
            self._states = read_group_states(self._srdf) if self._srdf else {}
        return self._states

    def frame_id(self, frame: str) -> int:
        """Pinocchio index of ``frame`` (a name shared by a link and a joint: the first one).

        Raises:
            UnknownNameError: naming the frame and listing the valid ones.
        """
        index = self._frame_index.get(frame) if isinstance(frame, str) else None
        if index is None:
            raise UnknownNameError(
                f"unknown frame {frame!r}{did_you_mean(frame, list(self.frame_names))} in "
                f"{self.name}; frames are: {', '.join(self.frame_names)}"
            )
        return index

    def _frame(self, frame: str) -> FrameSpec:
        return self._frames[self.frame_id(frame)]

    @staticmethod
    def _ref(ref: str | pin.ReferenceFrame) -> str:
        name = ref.name if isinstance(ref, pin.ReferenceFrame) else str(ref).upper()
        if name not in REFERENCE_FRAMES:
            raise ValueError(
                f"unknown reference frame {ref!r}; use one of {', '.join(REFERENCE_FRAMES)}"
            )
        return name

    # ------------------------------------------------------------------ symbolic passes
    def _kinematics(self, vel: str = "sym", acc: str = "none") -> TreeKinematics:
        """Cached symbolic forward pass; ``vel``/``acc`` are 'sym', 'zero' or 'none'."""
        key = (vel, acc)
        if key not in self._kin:
            pick = {"sym": None, "zero": cs.SX.zeros(self.nv, 1), "none": None}
            v = self._v if vel == "sym" else pick[vel]
            a = self._a if acc == "sym" else pick[acc]
            self._kin[key] = TreeKinematics(self._specs, self._q, v, a)
        return self._kin[key]

    def _cached(self, key: tuple, build: Callable[[], cs.Function]) -> cs.Function:
        fn = self._functions.get(key)
        if fn is None:
            fn = build()
            self._functions[key] = fn
        return fn

    def _contacts(self, contacts: Sequence[str] | None) -> tuple[str, ...]:
        if isinstance(contacts, str):
            contacts = [contacts]
        names = tuple(contacts or ())
        for c in names:
            self.frame_id(c)
        return names

    def compile(self, fn: cs.Function, name: str | None = None) -> cs.Function:
        """Compiled twin of ``fn`` (same signature); see :mod:`horizon_mpc.codegen`."""
        return codegen.compile_function(fn, name=name)

    def __repr__(self) -> str:
        base = "floating" if self.floating_base else "fixed"
        return (
            f"RobotModel({self.name!r}, nq={self.nq}, nv={self.nv}, {base} base, "
            f"mass={self.mass:.3f} kg)"
        )
