"""Building blocks of the seed's whole-body formulation on the Problem API.

State ``x = [q, v]`` (configuration with quaternion, generalised velocity), input
``u = [a, f]`` (generalised acceleration, contact forces in world axes, 3 per foot).
Conventions: ``doc/model.md``; node conventions: ``doc/problem.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import casadi as cs
import numpy as np

from horizon_mpc.model import RobotModel
from horizon_mpc.problem import Constraint, Cost, Parameter, Problem
from horizon_mpc.problem.terms import term_name

__all__ = [
    "ContactTerms",
    "add_contacts",
    "add_torque_limits",
    "base_rotation",
    "floating_base_double_integrator",
]


def floating_base_double_integrator(model: RobotModel, q: cs.SX, v: cs.SX, a: cs.SX
                                     ) -> cs.SX:
    """Double-integrator dynamics on the configuration manifold: ``q' = v``, ``v' = a``.

    Declares ``q``'s manifold (Lie-group integrate/difference of the model) so that every
    integrator keeps the quaternion unit norm. Returns the tangent derivative ``[v; a]``.
    """
    for name, x, size in (("q", q, model.nq), ("v", v, model.nv), ("a", a, model.nv)):
        if x.shape[0] != size:  # [v; f] of a wrong-size input was returned without a word
            raise ValueError(f"{name} has {x.shape[0]} rows; the model needs {size}")
    q.set_manifold(model.integrate(), model.difference(), model.nv)
    return cs.vertcat(v, a)


def base_rotation(q: cs.SX) -> cs.SX:
    """World-from-base rotation matrix of a free-flyer configuration (quaternion x, y, z, w)."""
    x, y, z, w = q[3], q[4], q[5], q[6]
    return cs.vertcat(
        cs.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        cs.horzcat(2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        cs.horzcat(2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


@dataclass
class ContactTerms:
    """The per-foot constraints/costs created by :func:`add_contacts`, by foot name."""

    velocity: dict[str, Constraint] = field(default_factory=dict)
    friction: dict[str, Constraint] = field(default_factory=dict)
    zero_force: dict[str, Constraint] = field(default_factory=dict)
    clearance: dict[str, Constraint | Cost] = field(default_factory=dict)
    swing_z: Parameter | None = None  # the swing height Parameter (n_feet)

    def set_schedule(self, stance: np.ndarray, swing_z: np.ndarray | None = None) -> None:
        """Activate stance/swing terms per node from ``stance`` (n_feet, N+1) booleans.

        ``swing_z``: world height of each foot per node (n_feet, N+1): the swing profile
        while it swings, the ground while it stands.
        """
        self.set_stance(stance)
        if swing_z is not None:
            self.set_swing_height(swing_z)

    def set_stance(self, stance: np.ndarray) -> None:
        """The node sets of :meth:`set_schedule` only (``stance``: (n_feet, N+1) booleans)."""
        stance = np.asarray(stance, bool)
        stage = np.ones(stance.shape[-1], bool)  # node masks: the force terms end at N-1
        stage[-1] = False
        for i, foot in enumerate(self.velocity):
            st = stance[i]
            self.velocity[foot].set_nodes(st)
            self.friction[foot].set_nodes(st & stage)
            self.zero_force[foot].set_nodes(~st & stage)
            # a clearance cost stays on every node (stance: the ground height, so a landing
            # foot is pulled onto the ground); a constraint would repeat the stance rows
            if isinstance(self.clearance.get(foot), Constraint):
                self.clearance[foot].set_nodes(~st)

    def set_swing_height(self, swing_z: np.ndarray) -> None:
        """World height (m) of each foot per node, (n_feet, N+1): the swing profile, the
        ground in stance (see :meth:`set_schedule`); no-op without clearance terms."""
        if self.swing_z is not None:
            self.swing_z.assign(swing_z)


def add_contacts(prb: Problem, model: RobotModel, feet: list[str], q: cs.SX, v: cs.SX,
                 f: cs.SX, mu: float,
                 clearance: str | None = "constraint", clearance_weight: float = 1e3,
                 foot_radius: float = 0.0) -> ContactTerms:
    """Contact constraints of each foot, to be switched per node by a schedule.

    Stance (node k): velocity of the contact point zero (world axes, 3 rows): with
    ``foot_radius`` r > 0 the foot is a sphere of radius r around the foot frame that rolls
    on the ground, and the contact point ``p_foot - r e_z`` (not the frame) is at rest, i.e.
    ``v_foot + omega_foot x (-r e_z) = 0``; force inside the linearised
    friction cone ``|f_x|, |f_y| <= mu f_z`` and ``f_z >= 0`` (5 rows, stage nodes).
    Swing: force zero (3 rows); clearance: the foot height follows the parameter
    ``swing_z`` (a constraint on swing nodes, or a cost of weight ``clearance_weight`` on
    every node, where ``swing_z`` is the ground height in stance; or None). Without that
    cost in stance a plan could land a foot above the ground: the stance rows hold the
    contact point still wherever it is.
    All terms start active on every node; call ``ContactTerms.set_schedule``.
    """
    terms = ContactTerms()
    if clearance not in (None, "constraint", "cost"):
        raise ValueError(f"clearance must be 'constraint', 'cost' or None, got {clearance!r}")
    # everything checked before the first term is made: a wrong foot name used to leave the
    # feet before it, and swing_z, in the problem (variables cannot be removed)
    if isinstance(feet, str) or not feet or len(set(feet)) != len(feet):
        raise ValueError(f"feet must be a non-empty list of distinct frame names, got {feet!r}")
    for foot in feet:
        model.frame_id(foot)  # UnknownNameError naming the frame and the valid ones
    if f.shape[0] != 3 * len(feet):
        raise ValueError(f"f has {f.shape[0]} rows; {len(feet)} feet need {3 * len(feet)} "
                         "(a force in world axes per foot)")
    for name, value, positive in (("mu", mu, True), ("foot_radius", foot_radius, False),
                                  ("clearance_weight", clearance_weight, False)):
        if not (math.isfinite(value) and (value > 0 if positive else value >= 0)):
            raise ValueError(f"{name} must be a finite number {'>' if positive else '>='} 0, "
                             f"got {value!r}")
    swing_z = prb.create_parameter("swing_z", len(feet)) if clearance else None
    terms.swing_z = swing_z
    cone = np.array([[1.0, 0.0, mu], [-1.0, 0.0, mu], [0.0, 1.0, mu], [0.0, -1.0, mu],
                     [0.0, 0.0, 1.0]])
    for i, foot in enumerate(feet):
        fi = f[3 * i:3 * i + 3]
        lin, ang = model.frame_velocity(foot, ref="LOCAL_WORLD_ALIGNED")(q, v)
        if foot_radius > 0.0:
            lin = lin + cs.cross(ang, cs.DM([0.0, 0.0, -foot_radius]))
        terms.velocity[foot] = prb.create_constraint(term_name(foot, "velocity"), lin)
        terms.friction[foot] = prb.create_constraint(
            term_name(foot, "friction"), cs.mtimes(cs.DM(cone), fi), bounds=(0.0, np.inf))
        terms.zero_force[foot] = prb.create_constraint(term_name(foot, "no_force"), fi)
        if clearance:
            pos, _ = model.fk(foot)(q)
            res = pos[2] - swing_z[i]
            if clearance == "constraint":
                terms.clearance[foot] = prb.create_constraint(term_name(foot, "clearance"), res)
            else:
                terms.clearance[foot] = prb.create_cost(term_name(foot, "clearance"), res,
                                                        weight=clearance_weight)
    return terms


def add_torque_limits(prb: Problem, model: RobotModel, tau_joints: cs.SX,
                      scale: float = 1.0) -> Constraint:
    """Joint torques (from inverse dynamics) within ``scale`` times the URDF effort limits."""
    lim = scale * model.joint_effort_limit
    lim = np.where(np.isfinite(lim), lim, np.inf)
    return prb.create_constraint("torque_limits", tau_joints, bounds=(-lim, lim),
                                 nodes=range(prb.n_nodes))
