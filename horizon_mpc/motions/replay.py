"""Open-loop replay of a motion in PyBullet: joint PD tracking plus feed-forward torques.

The physical realism check of a plan: the simulated robot (its own contact model, the
URDF's collision shapes) receives the plan's joint positions, velocities and torques as a
joint trajectory, nothing else; no feedback on the base. Within each interval the plan
holds accelerations and forces constant, so the reference is sampled ``substeps`` times per
interval from the exact solution (``q (+) (s v + s^2 a / 2)``, ``v + s a``) with the
inverse-dynamics torques at those instants (Pinocchio).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from horizon_mpc.config import RobotConfig
from horizon_mpc.motions.analysis import contact_torques, roll_pitch_yaw
from horizon_mpc.motions.result import MotionResult

__all__ = ["REPLAY_HEIGHT_TOLERANCE", "REPLAY_TILT_TOLERANCE", "REPLAY_TOLERANCE", "ReplayResult",
           "joint_reference", "replay", "replay_summary"]

log = logging.getLogger(__name__)


# m: a leap whose open-loop PyBullet replay lands further than this from the target is
# reported (the 0.4 m go2 leap lands 7.7 cm long, solo12's 0.25 m one 4.5 cm long)
REPLAY_TOLERANCE = 0.05
# m and rad: a replay that ends with its base further than this from the plan's final
# height, or rolled or pitched more, did not end standing (anymal_c's leap ended 26.5 cm
# low, pitched 0.37 rad, and was reported as landing 8 cm off only; session 28 audit)
REPLAY_HEIGHT_TOLERANCE = 0.05
REPLAY_TILT_TOLERANCE = 0.2


@dataclass
class ReplayResult:
    """What the simulated robot did (times in s from the start of the replay).

    Attributes:
        t: (K,) sample times; q: (K, nq) simulated configurations (Pinocchio convention,
            the simulator's full joint set); foot_force: (K, n_feet) normal forces (N).
        displacement: (3,) base displacement from the start to the end (m).
        final_rpy: (3,) final roll, pitch, yaw (rad); max_tilt: max |roll|, |pitch| (rad).
    """

    t: np.ndarray
    q: np.ndarray
    foot_force: np.ndarray
    displacement: np.ndarray
    final_rpy: np.ndarray
    max_tilt: float


def joint_reference(res: MotionResult, model: pin.Model, substeps: int = 4,
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Joint trajectory of a solution: times (K,), positions, velocities, torques (K, nj).

    ``model`` is the Pinocchio model the solution was computed with.
    """
    data = model.createData()
    times, pos, vel, eff = [], [], [], []
    for k in range(res.n_nodes):
        q, v, a, f = res.q[:, k], res.v[:, k], res.a[:, k], res.f[:, k]
        for j in range(substeps):
            s = res.dt * j / substeps
            qs = pin.integrate(model, q, s * v + 0.5 * s * s * a)
            vs = v + s * a
            tau = pin.rnea(model, data, qs, vs, a) - contact_torques(
                model, data, qs, res.feet, f, res.foot_radius)
            times.append(k * res.dt + s)
            pos.append(qs[7:])
            vel.append(vs[6:])
            eff.append(tau[6:])
    times.append(res.n_nodes * res.dt)
    pos.append(res.q[7:, -1])
    vel.append(res.v[6:, -1])
    eff.append(eff[-1])
    return np.array(times), np.array(pos), np.array(vel), np.array(eff)


def replay(res: MotionResult, cfg: RobotConfig, model: pin.Model, kp: float | None = None,
           kd: float | None = None, settle: float = 1.0, substeps: int = 4,
           sample_period: float = 0.01) -> ReplayResult:
    """Replay ``res`` open loop in PyBullet, then hold its last posture for ``settle`` s.

    Args:
        res: the solution; ``model``: its Pinocchio model (joints matched by name).
        cfg: the robot config (simulator gains and feet); ``kp``, ``kd`` override its gains.
        settle: time (s) simulated after the end of the motion.
        substeps: reference samples per interval of the solution.
        sample_period: period (s) of the recorded samples.
    """
    from horizon_mpc.sim.simulator import Simulator
    from horizon_mpc.sim.trajectory import JointTrajectoryCommand

    times, pos, vel, eff = joint_reference(res, model, substeps)
    duration = float(times[-1]) + settle
    with Simulator(cfg, kp=kp, kd=kd, trajectory_timeout=duration + 1.0) as sim:
        names = list(model.names)[2:]
        cmd = JointTrajectoryCommand(names, sim.time, times, pos, vel, eff)
        # joints the solution does not have (locked) hold the simulator's standing posture
        if set(names) != set(sim.joint_names):
            cmd = _complete(cmd, sim)
        start = sim.state().q
        sim.set_trajectory(cmd)
        stride = max(1, round(sample_period / sim.dt))
        t, qs, forces = [], [], []
        for _ in range(int(round(duration / (stride * sim.dt)))):
            sim.step(stride)
            s = sim.state()
            t.append(s.time)
            qs.append(s.q)
            forces.append(s.foot_force)
    q = np.array(qs)
    rpy = roll_pitch_yaw(q[:, 3:7])
    out = ReplayResult(np.array(t), q, np.array(forces), q[-1, :3] - start[:3], rpy[-1],
                       float(np.abs(rpy[:, :2]).max()))
    log.info("replay: displacement %s m, final roll/pitch/yaw %s rad",
             np.round(out.displacement, 3).tolist(), np.round(out.final_rpy, 3).tolist())
    return out


def _complete(cmd, sim):
    """``cmd`` extended with the simulator's joints it lacks, held at their standing angle."""
    from horizon_mpc.sim.trajectory import JointTrajectoryCommand

    missing = [n for n in sim.joint_names if n not in cmd.joint_names]
    idx = [sim.joint_names.index(n) for n in missing]
    k = len(cmd.times)
    hold = np.tile(sim.q_start[7:][idx], (k, 1))
    effort = np.tile(sim.tau_standing[idx], (k, 1))
    return JointTrajectoryCommand(
        [*cmd.joint_names, *missing], cmd.t0, cmd.times,
        np.hstack([cmd.positions, hold]), np.hstack([cmd.velocities, np.zeros_like(hold)]),
        np.hstack([cmd.efforts, effort]))


def replay_summary(rep: ReplayResult, res: MotionResult, target_x: float) -> dict:
    """The replay's figures for a summary: the base's ``displacement`` against the plan's
    (``target_displacement``: ``target_x`` ahead, on the start's line), ``landing_error``
    (horizontal, m), ``height_error`` (final base height against the plan's, m), the final
    roll / pitch / yaw and the largest tilt on the way, ``ended_standing`` (height and
    final roll and pitch within :data:`REPLAY_HEIGHT_TOLERANCE` /
    :data:`REPLAY_TILT_TOLERANCE`) and ``within_tolerance`` (standing, and landed within
    :data:`REPLAY_TOLERANCE`)."""
    target = np.array([target_x, 0.0])
    landing = float(np.linalg.norm(rep.displacement[:2] - target))
    height = float(rep.displacement[2] - (res.q[2, -1] - res.q[2, 0]))
    standing = bool(abs(height) <= REPLAY_HEIGHT_TOLERANCE
                    and np.all(np.abs(rep.final_rpy[:2]) <= REPLAY_TILT_TOLERANCE))
    return {"displacement": rep.displacement.tolist(), "target_displacement": target.tolist(),
            "landing_error": landing, "height_error": height,
            "final_roll_pitch_yaw": rep.final_rpy.tolist(), "max_tilt": rep.max_tilt,
            "ended_standing": standing,
            "within_tolerance": standing and landing <= REPLAY_TOLERANCE}
