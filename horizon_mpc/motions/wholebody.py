"""The seed's whole-body formulation, assembled for a finite-horizon motion.

State ``x = [q, v]``, input ``u = [a, f]`` (generalised accelerations, contact forces in
world axes, 3 per foot); double-integrator dynamics on the configuration manifold; initial
state fixed at node 0; under-actuation (base wrench of inverse dynamics zero); URDF joint
position, velocity and torque limits; contact terms switched by a contact schedule.
Conventions: ``doc/model.md`` (q, v, f), ``doc/problem.md`` (nodes).

Added here on top of :func:`horizon_mpc.locomotion.add_contacts`, which a finite motion
needs: the foot lands *on* the ground (height zero on touch-down nodes; the stance velocity
constraint then keeps it there) and a swinging foot stays above it.
"""

from __future__ import annotations

import fnmatch
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import casadi as cs
import numpy as np
import pinocchio as pin

from horizon_mpc.config import RobotConfig
from horizon_mpc.locomotion import (
    ContactSchedule,
    ContactTerms,
    add_contacts,
    add_torque_limits,
    floating_base_double_integrator,
)
from horizon_mpc.model import RobotModel
from horizon_mpc.motions.result import MotionResult
from horizon_mpc.motions.schedule import touchdown_nodes
from horizon_mpc.posture import standing_configuration
from horizon_mpc.problem import Constraint, Problem
from horizon_mpc.problem.terms import term_name
from horizon_mpc.robots import example_robot_files
from horizon_mpc.sim.rotations import quat_conjugate, quat_multiply
from horizon_mpc.solvers import make_solver

__all__ = ["SOLVER_DEFAULTS", "WholeBodyProblem", "build_whole_body", "final_state_errors",
           "quaternion_error", "robot_model"]

log = logging.getLogger(__name__)

#: options of a one-shot offline solve, per solver (merged under the caller's)
SOLVER_DEFAULTS: dict[str, dict[str, Any]] = {
    # rows only where terms are active (the schedule is fixed); adaptive barrier: ~2x
    # fewer iterations than the monotone default on the leap
    "ipopt": {"constraint_rows": "active", "tol": 1e-6, "max_iter": 1000,
              "ipopt.mu_strategy": "adaptive"},
    # qrqp (gnsqp's default QP solver) needs minutes per QP of a whole-body horizon
    "gnsqp": {"constraint_rows": "active", "max_iter": 300, "qp_solver": "osqp"},
    "ilqr": {"max_iter": 300},
}


@dataclass
class WholeBodyProblem:
    """A whole-body OCP and handles on its variables and contact terms.

    Attributes:
        prb: the Problem (N intervals).
        model: the symbolic robot model.
        feet: contact frame names (order of ``f``).
        q, v, a, f: the variables ((nq | nv | 3 n_feet) rows).
        tau: inverse-dynamics torque expression ``(nv,)`` of ``(q, v, a, f)``.
        contacts: the :class:`ContactTerms` of ``add_contacts``.
        touchdown: per foot, ``foot z == ground`` (active on touch-down nodes).
        above_ground: per foot, ``foot z >= swing_floor`` (active on swing nodes).
        q0: initial configuration (nq,).
        schedule: the contact schedule applied last (None before).
    """

    prb: Problem
    model: RobotModel
    feet: list[str]
    q: object
    v: object
    a: object
    f: object
    tau: cs.SX
    contacts: ContactTerms
    touchdown: dict[str, Constraint]
    above_ground: dict[str, Constraint]
    q0: np.ndarray
    schedule: ContactSchedule | None = None
    rest_at_end: bool = False
    foot_radius: float = 0.0
    integrator: str = "rk4"  # of the transcription (the solution's consistency check uses it)

    def add_final_state(self, q_final: np.ndarray, position: bool = True,
                        orientation: bool = True, joints: bool = True,
                        rest: bool = True) -> None:
        """Final constraints on node N: base position, base orientation and joints as in
        ``q_final`` (nq,), and (``rest``) zero velocity. Call before :meth:`set_schedule`."""
        q, v = self.q, self.v
        q_final = np.asarray(q_final, float)
        if position:
            self.prb.create_final_constraint("final_position", q[:3] - q_final[:3])
        if orientation:
            self.prb.create_final_constraint("final_orientation",
                                             quaternion_error(q[3:7], q_final[3:7]))
        if joints:
            diff = self.model.difference()(q_final, q)
            self.prb.create_final_constraint("final_joints", diff[6:])
        if rest:
            self.prb.create_final_constraint("final_velocity", v)
            self.rest_at_end = True

    @property
    def n_nodes(self) -> int:
        """Number of intervals N."""
        return self.prb.n_nodes

    def set_schedule(self, schedule: ContactSchedule, ground: float = 0.0,
                     floor: bool = False) -> None:
        """Switch every contact term per node from ``schedule`` (ground height ``ground`` m).

        ``floor``: swinging feet stay above the schedule's swing height profile (an
        inequality; without it they stay above the ground).
        """
        st = np.asarray(schedule.stance, bool)
        self.contacts.set_schedule(st, ground + schedule.swing_height())
        self.prb.get_variable("swing_floor").assign(
            ground + (schedule.swing_height() if floor else 0.0))
        # no stance velocity rows where the state is already pinned (node 0 at rest; node N
        # when the final velocity is constrained): they would be redundant rows
        pinned = [0, self.n_nodes] if self.rest_at_end else [0]
        # a foot pushes over interval k only if it is down at both of its ends (no force
        # while it lifts off or lands within the interval)
        loaded = st[:, :-1] & st[:, 1:]
        for i, foot in enumerate(self.feet):
            self.contacts.velocity[foot].set_nodes(np.setdiff1d(np.flatnonzero(st[i]), pinned))
            self.contacts.friction[foot].set_nodes(np.flatnonzero(loaded[i]))
            self.contacts.zero_force[foot].set_nodes(np.flatnonzero(~loaded[i]))
        for foot, nodes in zip(self.feet, touchdown_nodes(st), strict=True):
            self.touchdown[foot].set_nodes(nodes)
        for i, foot in enumerate(self.feet):
            self.above_ground[foot].set_nodes(np.flatnonzero(~st[i]))
        self.schedule = schedule

    def solve(self, solver: str = "ipopt", opts: dict[str, Any] | None = None,
              motion: str = "motion", robot: str = "") -> MotionResult:
        """Solve from the current guesses with ``make_solver(solver, prb, opts)``.

        Default options (merged under ``opts``) suit a one-shot offline solve. Returns the
        solution with the inverse-dynamics torques of the formulation, and the solver's
        statistics (no history) in ``stats``.
        """
        options = {**SOLVER_DEFAULTS.get(solver, {}), **(opts or {})}
        t0 = time.perf_counter()
        slv = make_solver(solver, self.prb, options)
        build = time.perf_counter() - t0
        slv.solve()
        sol = slv.solution
        stats = slv.stats.as_dict()
        stats.pop("history", None)
        stats["build_time"] = build
        log.info("%s with %s: %s, %d iterations, %.2f s, violation %.1e", motion, solver,
                 slv.stats.status, slv.stats.iterations, slv.stats.time,
                 slv.stats.constraint_violation)
        tau_fn = cs.Function("tau", [self.q, self.v, self.a, self.f], [self.tau])
        N = self.n_nodes
        tau = np.asarray(tau_fn.map(N)(sol["q"][:, :N], sol["v"][:, :N], sol["a"], sol["f"]))
        stance = self.schedule.stance if self.schedule is not None else np.ones(
            (len(self.feet), N + 1), bool)
        return MotionResult(motion, robot, solver, list(self.feet),
                            list(self.model.joint_names), float(self.prb.dt),
                            sol["q"].copy(), sol["v"].copy(), sol["a"].copy(), sol["f"].copy(),
                            tau, np.asarray(stance, bool).copy(), stats,
                            foot_radius=self.foot_radius, integrator=self.integrator)

    def guess(self, q: np.ndarray, stance: np.ndarray | None = None) -> None:
        """Initial guess: configurations ``q`` ((nq,) or (nq, N+1)), velocities from their
        finite differences, zero accelerations, the weight shared by the stance feet."""
        N, nf = self.n_nodes, len(self.feet)
        q = np.asarray(q, float)
        q = np.repeat(q[:, None], N + 1, axis=1) if q.ndim == 1 else q
        diff = self.model.difference()
        dt = float(self.prb.dt)
        v = np.zeros((self.model.nv, N + 1))
        for k in range(N):
            v[:, k] = np.asarray(diff(q[:, k], q[:, k + 1])).ravel() / dt
        v[:, 0] = 0.0
        stance = np.ones((nf, N + 1), bool) if stance is None else np.asarray(stance, bool)
        loaded = stance[:, :N] & stance[:, 1:]
        n_down = np.maximum(loaded.sum(axis=0), 1)
        fz = np.where(loaded, self.model.mass * 9.81 / n_down, 0.0)
        f = np.zeros((3 * nf, N))
        f[2::3] = fz
        self.q.set_initial_guess(q)
        self.v.set_initial_guess(v)
        self.a.set_initial_guess(0.0)
        self.f.set_initial_guess(f)


def robot_model(cfg: RobotConfig, locked: Sequence[str] = ()) -> RobotModel:
    """The symbolic model of a robot config (its URDF path, or its example-robot-data name).

    ``locked``: joint names or ``fnmatch`` patterns (``'j_arm*'``) of joints held at the
    config's nominal posture: they leave the model, their links ride rigidly on their
    parents (Pinocchio's ``buildReducedModel``).

    Raises:
        ValueError: ``locked`` is not a list of names, or a pattern matches no joint (the
            message lists the joints).
    """
    if isinstance(locked, str) or not all(isinstance(p, str) for p in locked):
        # (fnmatch on an int was a TypeError traceback out of the motion CLI)
        raise ValueError(f"locked_joints must be a list of joint names or patterns, got "
                         f"{list(locked) if not isinstance(locked, str) else locked!r}")
    full = RobotModel.from_config(cfg)
    if not locked:
        return full
    names = [n for n in full.joint_names if any(fnmatch.fnmatchcase(n, p) for p in locked)]
    unmatched = [p for p in locked if not any(fnmatch.fnmatchcase(n, p) for n in names)]
    if unmatched:
        raise ValueError(f"locked joint pattern(s) {unmatched} match no joint of {full.name}; "
                         f"joints are: {', '.join(full.joint_names)}")
    pm, q_ref = standing_configuration(cfg, full.pin_model)
    reduced = pin.buildReducedModel(pm, [pm.getJointId(n) for n in names], q_ref)
    log.info("%s: %d joints locked at the nominal posture, %d left", full.name, len(names),
             len(full.joint_names) - len(names))
    srdf = None if cfg.urdf_path else example_robot_files(cfg.robot).srdf
    return RobotModel(reduced, name=full.name, srdf=srdf)


def final_state_errors(model: RobotModel, res: MotionResult, q_final: np.ndarray) -> dict:
    """Errors of the last node against ``q_final`` (nq,): base position (m, norm and
    vector), base orientation (deg, angle of the relative rotation), joints (rad, max
    abs), velocity (max abs)."""
    q = res.q[:, -1]
    dq = np.asarray(model.difference()(q_final, q)).ravel()
    rel = quat_multiply(quat_conjugate(q_final[3:7]), q[3:7] / np.linalg.norm(q[3:7]))
    angle = 2.0 * np.arctan2(np.linalg.norm(rel[:3]), abs(rel[3]))
    return {"final_position": q[:3].tolist(),
            "final_position_error": float(np.linalg.norm(q[:3] - q_final[:3])),
            "final_position_error_xyz": (q[:3] - q_final[:3]).tolist(),
            "final_orientation_error_deg": float(np.degrees(angle)),
            "final_joint_error": float(np.max(np.abs(dq[6:]), initial=0.0)),
            "final_velocity": float(np.max(np.abs(res.v[:, -1])))}


def quaternion_error(quat: cs.SX, target: np.ndarray) -> cs.SX:
    """Vector part (3,) of ``target^-1 * quat`` (quaternions ``(x, y, z, w)``).

    Zero exactly when the two orientations agree (for ``quat`` in the target's hemisphere);
    about half the rotation vector between them for small errors.
    """
    tx, ty, tz, tw = (float(c) for c in np.asarray(target, float) / np.linalg.norm(target))
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    t = cs.DM([tx, ty, tz])
    qv = cs.vertcat(x, y, z)
    return tw * qv - w * t - cs.cross(t, qv)


def _contact_offset_torques(model: RobotModel, feet: list[str], q, f, radius: float) -> cs.SX:
    """``sum_c J_ang,c^T (o x f_c)``, ``o = (0, 0, -radius)``: the generalised torque of the
    moment of each force about its frame when it acts at the ball's lowest point."""
    out = 0
    for i, foot in enumerate(feet):
        fi = f[3 * i:3 * i + 3]
        moment = cs.vertcat(radius * fi[1], -radius * fi[0], 0.0)
        J = model.jacobian(foot, ref="LOCAL_WORLD_ALIGNED")(q)
        out = out + cs.mtimes(J[3:6, :].T, moment)
    return out


def build_whole_body(model: RobotModel, feet: list[str], n_nodes: int, dt: float,
                     q0: np.ndarray, mu: float, clearance: str | None = None,
                     torque_limit_scale: float | None = 1.0, foot_radius: float = 0.0,
                     integrator: str = "rk4") -> WholeBodyProblem:
    """The whole-body problem of a finite motion starting at rest at ``q0``.

    Args:
        model: robot model; ``feet`` its contact frames.
        n_nodes, dt: horizon (intervals) and interval duration (s).
        q0: initial configuration (nq,), fixed on node 0 with zero velocity.
        mu: friction coefficient of the linearised cones.
        clearance: ``'constraint'`` (swing feet follow the schedule's height profile),
            ``'cost'`` or None (swing feet only stay above the ground).
        torque_limit_scale: bound the joint torques by this fraction of the URDF effort
            limits (None: no torque limits).
        foot_radius: radius (m) of ball feet centred on the contact frames (0: point
            feet). A stance foot then rolls (its lowest point is at rest, as in
            ``add_contacts``) and its force acts at that point: inverse dynamics includes
            the force's moment about the frame.
        integrator: of the multiple-shooting transcription (``rk4`` is exact for the
            double integrator with inputs constant over an interval).

    Call :meth:`WholeBodyProblem.set_schedule` before solving, then add the motion's
    costs and final constraints.
    """
    q0 = np.asarray(q0, float)
    if q0.shape != (model.nq,):
        raise ValueError(f"q0 must have shape ({model.nq},), got {q0.shape}")
    prb = Problem(n_nodes)
    q = prb.create_state_variable("q", model.nq)
    v = prb.create_state_variable("v", model.nv)
    a = prb.create_input_variable("a", model.nv)
    f = prb.create_input_variable("f", 3 * len(feet))
    prb.set_dynamics(floating_base_double_integrator(model, q, v, a))
    prb.set_dt(dt)
    prb.transcribe("multiple_shooting", integrator=integrator)

    # the dynamics defects live in the tangent space (3 rows for the base orientation): the
    # unit norm pins the fourth quaternion component (without it the NLP is singular there)
    prb.create_constraint("unit_quaternion", cs.dot(q[3:7], q[3:7]) - 1.0,
                          nodes=range(1, n_nodes + 1))
    # feasibility: the base wrench of inverse dynamics vanishes (under-actuation)
    tau = model.inverse_dynamics(feet)(q, v, a, f)
    if foot_radius > 0:
        tau = tau - _contact_offset_torques(model, feet, q, f, foot_radius)
    prb.create_constraint("underactuation", tau[:6], nodes=range(n_nodes))
    if torque_limit_scale is not None:
        add_torque_limits(prb, model, tau[6:], scale=torque_limit_scale)
    contacts = add_contacts(prb, model, feet, q, v, f, mu, clearance=clearance,
                            foot_radius=foot_radius)
    touchdown, above = {}, {}
    floor = prb.create_parameter("swing_floor", len(feet))
    for i, foot in enumerate(feet):
        z = model.fk(foot)(q)[0][2]
        # floor = ground on stance nodes: the foot lands on the ground
        touchdown[foot] = prb.create_constraint(term_name(foot, "touchdown"), z - floor[i],
                                                nodes=[])
        above[foot] = prb.create_constraint(term_name(foot, "above_ground"), z - floor[i],
                                            nodes=[], bounds=(0.0, np.inf))

    # limits from the URDF (those written as zero are none: RobotModel.unset_limits)
    q.set_bounds(model.q_lower, model.q_upper)
    v_lim = model.v_limit.copy()
    v_lim[:6] = np.inf
    v.set_bounds(-v_lim, v_lim)
    # initial state: at rest at q0
    q.set_bounds(q0, q0, nodes=0)
    v.set_bounds(0.0, 0.0, nodes=0)
    log.debug("whole-body problem: %s, N=%d, dt=%.3f s, %d feet", model.name, n_nodes, dt,
              len(feet))
    wb = WholeBodyProblem(prb, model, list(feet), q, v, a, f, tau, contacts, touchdown, above,
                          q0, foot_radius=foot_radius, integrator=integrator)
    wb.guess(q0)
    return wb
