"""The pybullet simulator: a legged robot on flat ground, driven by joint trajectories.

Conventions (see ``doc/simulator.md``):

* ``q = [base position (3), base quaternion (x, y, z, w), joint positions]`` and
  ``v = [base linear velocity (3), base angular velocity (3), joint velocities]``, joints in
  Pinocchio model order, base velocities expressed in the BASE frame, base pose = the URDF
  root link frame (not pybullet's centre-of-mass frame of that link).
* Joint control every physics step: ``tau = clip(tau_ff + kp (q_ref - q) + kd (v_ref - v),
  -effort_limit, effort_limit)`` with the reference from :class:`ReferenceGenerator`.

Each instance owns its own ``p.DIRECT`` physics client: several simulators in one process
do not interfere. No ROS here.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import numbers
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.posture import standing_configuration
from horizon_mpc.sim.loading import LoadedRobot, load_robot
from horizon_mpc.sim.pybullet_import import import_pybullet
from horizon_mpc.sim.render import checker_texture, render_following
from horizon_mpc.sim.rotations import (
    quat_from_yaw,
    quat_multiply,
    quat_to_matrix,
    transform_inverse,
    transform_multiply,
)
from horizon_mpc.sim.standing import standing_feedforward
from horizon_mpc.sim.trajectory import JointTrajectoryCommand, ReferenceGenerator

p = import_pybullet()  # the module, without its banner (pybullet_import.py)

__all__ = ["SimState", "Simulator"]

_LOG = logging.getLogger(__name__)


#: share beyond a joint's effort limit a commanded effort may go before set_trajectory
#: says it is clipped (a plan's torques may exceed their bounds by its constraint violation)
EFFORT_NOTE_MARGIN = 0.1


@dataclass
class SimState:
    """Ground truth at one instant (arrays are copies).

    Attributes:
        time: sim time (s).
        q: (nq,) configuration, Pinocchio convention.
        v: (nv,) velocity, Pinocchio convention (base twist in the base frame).
        joint_positions: (nj,) joint angles (rad) / positions (m), model order.
        joint_velocities: (nj,) joint velocities.
        tau: (nj,) joint efforts applied during the last physics step (N m / N).
        base_position: (3,) base frame origin in the world (m).
        base_quaternion: (4,) base orientation ``(x, y, z, w)``.
        base_linear_velocity: (3,) velocity of the base frame origin, base frame (m/s).
        base_angular_velocity: (3,) base angular velocity, base frame (rad/s).
        foot_contact: (nf,) whether each foot of the config touches the ground.
        foot_force: (nf,) total normal contact force on each foot (N).
    """

    time: float
    q: np.ndarray
    v: np.ndarray
    joint_positions: np.ndarray
    joint_velocities: np.ndarray
    tau: np.ndarray
    base_position: np.ndarray
    base_quaternion: np.ndarray
    base_linear_velocity: np.ndarray
    base_angular_velocity: np.ndarray
    foot_contact: np.ndarray
    foot_force: np.ndarray


def _gains(value: float | Sequence[float] | np.ndarray, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be a non-negative scalar or ({n},) array, got {value!r}")
    return arr


#: N (N m): a push beyond this is garbage (it would blow the physics up)
PLAUSIBLE_WRENCH = 1e6


class Simulator:
    """A legged robot in pybullet, joint-trajectory controlled, in Pinocchio conventions."""

    def __init__(
        self,
        robot: str | RobotConfig = "go2",
        dt: float | None = None,
        urdf_path: str | Path | None = None,
        kp: float | Sequence[float] | None = None,
        kd: float | Sequence[float] | None = None,
        friction: float | None = None,
        base_pose: tuple[float, float, float] | None = None,
        trajectory_timeout: float = 0.5,
        max_stamp_offset: float = 1.0,
        search_dirs: Sequence[str | Path] | None = None,
    ) -> None:
        """Load the robot standing at its nominal posture on the ground.

        Args:
            robot: robot config name (``config/<name>.yaml``), YAML path or a RobotConfig.
            dt: physics step (s); default ``1 / cfg.sim.physics_rate`` (1 kHz).
            urdf_path: URDF to load instead of the config's (same for Pinocchio and pybullet).
            kp, kd: joint PD gains (N m/rad, N m s/rad), scalar or (nj,); default config ``sim:``.
            friction: foot-ground friction coefficient; default ``cfg.sim.lateral_friction``.
            base_pose: start ``(x, y, yaw)`` (m, m, rad) of the base; default (0, 0, 0).
            trajectory_timeout: a command older than this (s) is stale; the robot then holds.
            max_stamp_offset: commands stamped further than this (s) from now are rejected.
            search_dirs: extra folders holding ROS packages, for ``package://`` mesh URIs.
        """
        cfg = robot if isinstance(robot, RobotConfig) else load_robot_config(robot)
        if urdf_path is not None:
            cfg = dataclasses.replace(cfg, urdf_path=str(urdf_path))
        self.cfg = cfg
        self.dt = float(dt) if dt is not None else 1.0 / cfg.sim.physics_rate
        # each checked before anything is built (dt inf read 'time inf', a negative time-out
        # refused every trajectory, a NaN friction was taken)
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"dt must be a finite number > 0, got {dt}")
        for name, value, rule in (("friction", friction, "a finite number >= 0"),
                                  ("trajectory_timeout", trajectory_timeout, "a number > 0"),
                                  ("max_stamp_offset", max_stamp_offset, "a number > 0")):
            # (the time-outs may be inf: no limit)
            ok = value is None or (isinstance(value, numbers.Real) and not isinstance(
                value, (bool, np.bool_)) and (math.isfinite(value) and value >= 0
                                              if name == "friction" else value > 0))
            if not ok:
                raise ValueError(f"{name} must be {rule}, got {value!r}")
        if base_pose is not None and not (
                np.shape(base_pose) == (3,) and np.all(np.isfinite(np.asarray(base_pose,
                                                                               float)))):
            raise ValueError(f"base_pose must be (x, y, yaw), 3 finite numbers, got "
                             f"{base_pose!r}")
        self.max_stamp_offset = max_stamp_offset
        self.model, q_stand = standing_configuration(cfg)
        self._check_model()
        if base_pose is not None:
            x, y, yaw = base_pose
            q_stand[0:2] = (x, y)
            q_stand[3:7] = quat_multiply(quat_from_yaw(yaw), q_stand[3:7])

        names = list(self.model.names)[2:]
        self.joint_names: list[str] = names
        self.n_joints = len(names)
        joints = [self.model.joints[i] for i in range(2, self.model.njoints)]
        self._idx_q = np.array([j.idx_q for j in joints])
        self._continuous = np.array([j.nq == 2 for j in joints])
        self.effort_limit = np.array([
            lim if np.isfinite(lim) and lim > 0 else np.inf
            for lim in self.model.effortLimit[6:]
        ])
        self.kp = _gains(cfg.sim.kp if kp is None else kp, self.n_joints, "kp")
        self.kd = _gains(cfg.sim.kd if kd is None else kd, self.n_joints, "kd")
        self.friction = float(cfg.sim.lateral_friction if friction is None else friction)

        self.client = p.connect(p.DIRECT)
        self._closed = False
        self.urdf_path = Path(cfg.urdf_path) if cfg.urdf_path else _example_urdf(cfg)
        self._search_dirs = [Path(d) for d in (search_dirs or [])]
        self._build_world()
        # pybullet's base pose is the root link's inertial frame: T_com->base, applied on reads
        self._com_to_base = tuple(
            tuple(float(x) for x in a)
            for a in transform_inverse(self.robot.inertial_pos, self.robot.inertial_quat))
        missing = [n for n in names if n not in self.robot.joint_index]
        if missing:
            raise ValueError(f"joints {missing} of the Pinocchio model are not in pybullet's")
        self._pb_joints = [self.robot.joint_index[n] for n in names]
        self.feet = list(cfg.feet)
        self._foot_of_link: dict[int, int] = {}
        for i, foot in enumerate(self.feet):
            if foot not in self.robot.link_index:
                raise ValueError(f"foot {foot!r} is not a URDF link; links: "
                                 f"{sorted(self.robot.link_index)}")
            for link in self.robot.rigid_group(foot):
                self._foot_of_link[link] = i

        self.q_start = self._grounded(q_stand)
        self.tau_standing, self.standing_forces = standing_feedforward(
            self.model, self.q_start, self.feet)
        self.reference = ReferenceGenerator(self.n_joints, trajectory_timeout)
        self._tau = np.zeros(self.n_joints)
        self._pushes: list[tuple[int, np.ndarray, np.ndarray, int]] = []
        self._steps = 0
        self._touched = False  # stepped since the world was built (see reset)
        self.reset()

    # ------------------------------------------------------------------ setup helpers
    def _build_world(self) -> None:
        """Gravity, time step, ground and robot in the (empty) pybullet world."""
        g = float(np.linalg.norm(self.model.gravity.linear))
        p.setGravity(0.0, 0.0, -g, physicsClientId=self.client)
        p.setPhysicsEngineParameter(fixedTimeStep=self.dt, physicsClientId=self.client)
        self.ground = self._create_ground()
        self.robot: LoadedRobot = load_robot(self.client, self.urdf_path, self._search_dirs,
                                             self.friction)
        self.body = self.robot.body

    def _check_model(self) -> None:
        for i in range(2, self.model.njoints):
            j = self.model.joints[i]
            if j.nv != 1:
                raise ValueError(f"joint {self.model.names[i]!r} has {j.nv} DoF; the simulator "
                                 "supports 1-DoF joints only")

    def _create_ground(self) -> int:
        col = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=self.client)
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[50.0, 50.0, 0.005],
                                  visualFramePosition=[0.0, 0.0, -0.005],
                                  rgbaColor=[0.55, 0.6, 0.55, 1.0], physicsClientId=self.client)
        ground = p.createMultiBody(0.0, col, vis, physicsClientId=self.client)
        with tempfile.TemporaryDirectory(prefix="horizon_mpc_sim_") as tmp:
            texture = p.loadTexture(str(checker_texture(Path(tmp))), physicsClientId=self.client)
        p.changeVisualShape(ground, -1, textureUniqueId=texture, rgbaColor=[1, 1, 1, 1],
                            physicsClientId=self.client)
        # pybullet multiplies the two bodies' coefficients: the robot's links carry `friction`.
        p.changeDynamics(ground, -1, lateralFriction=1.0, restitution=0.0,
                         physicsClientId=self.client)
        return ground

    def _grounded(self, q: np.ndarray) -> np.ndarray:
        """``q`` with the base height adjusted so the lowest collision point is at z = 0.

        The posture module puts the foot *frames* on the ground; a foot's collision shape
        (a sphere around the frame, a wheel) usually reaches lower.
        """
        q = q.copy()
        self.set_state(q)
        points = p.getClosestPoints(self.body, self.ground, distance=1.0,
                                    physicsClientId=self.client)
        if points:
            q[2] -= min(pt[8] for pt in points)
        return q

    # ------------------------------------------------------------------ basic API
    @property
    def time(self) -> float:
        """Sim time (s) since the last reset."""
        return self._steps * self.dt

    @property
    def steps(self) -> int:
        """Physics steps taken since the last reset (exact integer sim time)."""
        return self._steps

    def total_mass(self) -> float:
        """Total mass of the simulated robot (kg), as pybullet sees it."""
        n = p.getNumJoints(self.body, physicsClientId=self.client)
        return float(sum(p.getDynamicsInfo(self.body, i, physicsClientId=self.client)[0]
                         for i in range(-1, n)))

    def reset(self, reset_time: bool = True) -> None:
        """Back to the standing start: nominal posture on the ground, at rest, holding it.

        Drops the trajectory and any push. ``reset_time=False`` keeps the clock running (the
        ROS node does, so that ``/clock`` never jumps back). The world is rebuilt (0.1-0.3
        s) once it has been stepped: pybullet keeps contact data across a
        teleport (the feet's forces of before the reset, runs that differed from a fresh
        simulator's by 0.5 mm) and NaNs a blown-up step left in its caches (a reset robot
        then fell through the ground while its state read finite).
        """
        if self._touched:
            p.resetSimulation(physicsClientId=self.client)
            self._build_world()
        self.set_state(self.q_start)
        self._touched = False
        self.reference.hold(self._joint_angles(self.q_start), self.tau_standing)
        self._tau[:] = 0.0
        self._pushes.clear()
        if reset_time:
            self._steps = 0

    def set_state(self, q: np.ndarray, v: np.ndarray | None = None) -> None:
        """Teleport the robot to ``q`` (nq,) with velocity ``v`` (nv,) (Pinocchio conventions).

        Raises:
            ValueError: a shape other than (nq,) / (nv,), a value that is not finite, a zero
                quaternion (nothing changed).
        """
        q = np.asarray(q, dtype=float)
        v = np.zeros(self.model.nv) if v is None else np.asarray(v, dtype=float)
        if q.shape != (self.model.nq,) or v.shape != (self.model.nv,):
            raise ValueError(f"set_state: q of shape {q.shape}, v {v.shape}; the model has q "
                             f"({self.model.nq},), v ({self.model.nv},)")
        if not (np.isfinite(q).all() and np.isfinite(v).all()):
            raise ValueError("set_state: the state is not finite")
        if not np.linalg.norm(q[3:7]) > 1e-9:
            raise ValueError("set_state: the base quaternion is zero")
        quat = q[3:7] / np.linalg.norm(q[3:7])
        com_pos, com_quat = transform_multiply(q[0:3], quat, self.robot.inertial_pos,
                                               self.robot.inertial_quat)
        p.resetBasePositionAndOrientation(self.body, com_pos.tolist(), com_quat.tolist(),
                                          physicsClientId=self.client)
        rot = quat_to_matrix(quat)
        omega = rot @ v[3:6]
        v_com = rot @ v[0:3] + np.cross(omega, com_pos - q[0:3])
        p.resetBaseVelocity(self.body, v_com.tolist(), omega.tolist(),
                            physicsClientId=self.client)
        angles = self._joint_angles(q)
        for j, pb in enumerate(self._pb_joints):
            p.resetJointState(self.body, pb, float(angles[j]), float(v[6 + j]),
                              physicsClientId=self.client)
        # contact points as of the new pose (normal forces stay 0 until the next step)
        p.performCollisionDetection(physicsClientId=self.client)

    def _joint_angles(self, q: np.ndarray) -> np.ndarray:
        """(nj,) joint angles of ``q`` (continuous joints' (cos, sin) turned into angles)."""
        angles = q[self._idx_q].copy()
        if self._continuous.any():
            c = self._idx_q[self._continuous]
            angles[self._continuous] = np.arctan2(q[c + 1], q[c])
        return angles

    # ------------------------------------------------------------------ commands
    def set_trajectory(self, cmd: JointTrajectoryCommand) -> str | None:
        """Follow ``cmd`` from now on (replacing the previous one).

        Returns a note when its efforts exceed the joints' effort limits by more than
        :data:`EFFORT_NOTE_MARGIN` (the torque is clipped to them: the command is not what
        the robot gets; solo12's URDF limits of 1000 threw the robot 18 m up under efforts
        of 5e6 without a word), else None.

        Raises:
            ValueError: the command is invalid (see :meth:`JointTrajectoryCommand.validate`);
                the previous command stays in force.
        """
        valid = cmd.validate(self.joint_names, self.time, self.max_stamp_offset)
        ordered = valid.reordered(self.joint_names)
        self.reference.set_command(ordered, self.time)
        if ordered.efforts is None:
            return None
        excess = np.max(np.abs(ordered.efforts), axis=0) / self.effort_limit
        j = int(np.argmax(excess))
        if excess[j] <= 1.0 + EFFORT_NOTE_MARGIN:
            return None
        return (f"efforts beyond the effort limits are clipped to them: "
                f"{self.joint_names[j]} {np.max(np.abs(ordered.efforts[:, j])):.4g} "
                f"(limit {self.effort_limit[j]:.4g}; {int(np.sum(excess > 1.0))} joint(s) over)")

    def push(
        self,
        link: str,
        force: Sequence[float],
        torque: Sequence[float] | None = None,
        duration: float = 0.1,
    ) -> None:
        """Apply a world-frame ``force`` (N) and ``torque`` (N m) at ``link``'s origin.

        Applied during every physics step of the next ``duration`` seconds.

        Raises:
            ValueError: unknown link, non-finite or wrongly shaped values, duration <= 0.
        """
        if link not in self.robot.link_index:
            raise ValueError(f"unknown link {link!r}; links are: {sorted(self.robot.link_index)}")
        f = np.asarray(force, dtype=float)
        tq = np.zeros(3) if torque is None else np.asarray(torque, dtype=float)
        if f.shape != (3,) or tq.shape != (3,):
            raise ValueError(f"force and torque must have 3 components, got {f.shape}, {tq.shape}")
        if not (np.all(np.isfinite(f)) and np.all(np.isfinite(tq))):
            raise ValueError(f"force/torque contains NaN/Inf: {f}, {tq}")
        if max(np.max(np.abs(f)), np.max(np.abs(tq))) > PLAUSIBLE_WRENCH:
            raise ValueError(f"force/torque beyond the plausible {PLAUSIBLE_WRENCH:g} N (N m): "
                             f"{f}, {tq}")
        if (isinstance(duration, bool) or not isinstance(duration, (int, float, np.number))
                or not (np.isfinite(duration) and duration > 0)):
            raise ValueError(f"push duration must be a positive number of seconds, got "
                             f"{duration!r}")
        end = self._steps + max(1, round(duration / self.dt))
        self._pushes.append((self.robot.link_index[link], f, tq, end))

    # ------------------------------------------------------------------ physics
    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps with the joint controller running at every step.

        Raises:
            ValueError: ``n`` is not an integer >= 0.
        """
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"step(n): n must be an integer >= 0, got {n!r}")
        if n:
            self._touched = True
        body, cid, joints = self.body, self.client, self._pb_joints
        kp, kd, lim, dt = self.kp, self.kd, self.effort_limit, self.dt
        reference = self.reference.reference
        for _ in range(n):
            # hot loop: one pybullet read, one write, one step; no per-joint Python work
            states = p.getJointStates(body, joints, physicsClientId=cid)
            q = np.array([s[0] for s in states])
            v = np.array([s[1] for s in states])
            q_ref, v_ref, tau_ff = reference(self._steps * dt)
            tau = np.clip(tau_ff + kp * (q_ref - q) + kd * (v_ref - v), -lim, lim)
            p.setJointMotorControlArray(body, joints, p.TORQUE_CONTROL, forces=tau.tolist(),
                                        physicsClientId=cid)
            if self._pushes:
                self._apply_pushes()
            p.stepSimulation(physicsClientId=cid)
            self._tau = tau
            self._steps += 1

    def _apply_pushes(self) -> None:
        for link, force, torque, _ in self._pushes:
            pos = self.link_pose_index(link)[0]
            p.applyExternalForce(self.body, link, force.tolist(), pos.tolist(), p.WORLD_FRAME,
                                 physicsClientId=self.client)
            if torque.any():
                p.applyExternalTorque(self.body, link, torque.tolist(), p.WORLD_FRAME,
                                      physicsClientId=self.client)
        self._pushes = [push for push in self._pushes if push[3] > self._steps + 1]

    # ------------------------------------------------------------------ state
    def _base_kinematics(self) -> tuple[tuple, tuple, tuple, tuple, tuple]:
        """pybullet reads: (base pos, base quat, COM pos, COM linear vel, angular vel), world."""
        cid = self.client
        com_pos, com_quat = p.getBasePositionAndOrientation(self.body, physicsClientId=cid)
        pos, quat = p.multiplyTransforms(com_pos, com_quat, *self._com_to_base,
                                         physicsClientId=cid)
        lin, ang = p.getBaseVelocity(self.body, physicsClientId=cid)
        return pos, quat, com_pos, lin, ang

    def base_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Base (URDF root link) frame: position (3,) m and quaternion (4,) ``(x, y, z, w)``."""
        com_pos, com_quat = p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        pos, quat = p.multiplyTransforms(com_pos, com_quat, *self._com_to_base,
                                         physicsClientId=self.client)
        return np.array(pos), np.array(quat)

    def link_pose_index(self, link: int) -> tuple[np.ndarray, np.ndarray]:
        """World pose of the URDF frame of pybullet link ``link`` (-1: base)."""
        if link == -1:
            return self.base_pose()
        ls = p.getLinkState(self.body, link, computeForwardKinematics=True,
                            physicsClientId=self.client)
        return np.array(ls[4]), np.array(ls[5])

    def link_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World pose ``(position (3,), quaternion (4,))`` of the URDF link ``name``'s frame."""
        if name not in self.robot.link_index:
            raise ValueError(f"unknown link {name!r}; links are: {sorted(self.robot.link_index)}")
        return self.link_pose_index(self.robot.link_index[name])

    def state(self) -> SimState:
        """Ground-truth state now (cheap enough to call at the publishing rate)."""
        pos_t, quat_t, com, lin, (wx, wy, wz) = self._base_kinematics()
        pos, quat = np.array(pos_t), np.array(quat_t)
        rot_t = np.array(p.getMatrixFromQuaternion(quat_t, physicsClientId=self.client))
        rot_t = rot_t.reshape(3, 3).T
        # velocity of the base origin = COM velocity + omega x (origin - COM), in the world
        dx, dy, dz = pos_t[0] - com[0], pos_t[1] - com[1], pos_t[2] - com[2]
        v_origin = (lin[0] + wy * dz - wz * dy, lin[1] + wz * dx - wx * dz,
                    lin[2] + wx * dy - wy * dx)
        v_lin, v_ang = rot_t @ v_origin, rot_t @ (wx, wy, wz)
        states = p.getJointStates(self.body, self._pb_joints, physicsClientId=self.client)
        qj = np.array([s[0] for s in states])
        vj = np.array([s[1] for s in states])
        q = np.zeros(self.model.nq)
        q[0:3], q[3:7] = pos, quat
        q[self._idx_q] = qj
        if self._continuous.any():
            c = self._idx_q[self._continuous]
            q[c], q[c + 1] = np.cos(qj[self._continuous]), np.sin(qj[self._continuous])
        v = np.concatenate((v_lin, v_ang, vj))
        contact = np.zeros(len(self.feet), dtype=bool)
        force = np.zeros(len(self.feet))
        for pt in p.getContactPoints(self.body, self.ground, physicsClientId=self.client):
            foot = self._foot_of_link.get(pt[3])
            if foot is not None:
                contact[foot] = True
                force[foot] += pt[9]
        return SimState(
            time=self.time, q=q, v=v, joint_positions=qj, joint_velocities=vj,
            tau=self._tau.copy(), base_position=pos, base_quaternion=quat,
            base_linear_velocity=v_lin, base_angular_velocity=v_ang,
            foot_contact=contact, foot_force=force,
        )

    # ------------------------------------------------------------------ rendering, teardown
    def render(self, width: int = 320, height: int = 240, distance: float = 1.5,
               yaw: float = 45.0, pitch: float = -25.0) -> np.ndarray:
        """RGB image (height, width, 3) uint8 from a camera following the base (headless).

        ``yaw``/``pitch`` (deg) place the camera relative to the base heading.
        """
        pos, quat = self.base_pose()
        return render_following(self.client, pos, quat, width, height, distance, yaw, pitch)

    def close(self) -> None:
        """Disconnect the physics client (idempotent)."""
        if not self._closed:
            self._closed = True
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:  # already gone
                pass

    def __enter__(self) -> Simulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        if hasattr(self, "_closed"):
            self.close()


def _example_urdf(cfg: RobotConfig) -> Path:
    from horizon_mpc.robots import example_robot_files

    if not cfg.robot:
        raise ValueError(f"config {cfg.name!r} names neither a robot nor a URDF path")
    return example_robot_files(cfg.robot).urdf

