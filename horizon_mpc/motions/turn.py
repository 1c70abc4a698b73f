"""The 90-degree in-place turn (the paper's CENTAURO turn).

Finite horizon, multiple shooting, IPOPT. Two full cycles of the library's ``walk`` gait
(crawl: one leg at a time, 8 steps), a short four-foot stance between steps; each swinging
foot follows the swing height profile as a constraint (the seed's clearance constraint).
Final constraints: base yaw 90 degrees (roll and pitch 0), base position and joints as at
the start, velocity zero.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.locomotion import ContactSchedule, base_rotation
from horizon_mpc.model import RobotModel
from horizon_mpc.motions.analysis import (
    check_contacts,
    foot_heights,
    physics_summary,
    roll_pitch_yaw,
    swing_intervals,
)
from horizon_mpc.motions.result import MotionResult
from horizon_mpc.motions.schedule import crawl_order, timeline_schedule
from horizon_mpc.motions.settings import check_settings, motion_settings
from horizon_mpc.motions.wholebody import (
    WholeBodyProblem,
    build_whole_body,
    final_state_errors,
    robot_model,
)
from horizon_mpc.posture import standing_configuration
from horizon_mpc.sim.rotations import quat_from_yaw, quat_multiply

__all__ = ["TurnProblem", "TurnSettings", "build_turn", "run_turn", "turn_schedule",
           "turn_summary"]

log = logging.getLogger(__name__)


#: degrees a gait cycle (four steps) may turn: 45 per step (a 360-degree turn in the default
#: two cycles solves; 1e9 degrees ran a 276 s solve to 'NOT solved')
MAX_YAW_PER_CYCLE = 180.0


@dataclass
class TurnSettings:
    """Timeline (s), target and weights of the turn (``config/motions/turn.yaml``)."""

    dt: float = 0.1
    stand: float = 0.4  # all feet down before the first step
    step: float = 0.6  # swing duration of one step
    pause: float = 0.2  # all feet down between two steps
    settle: float = 0.6  # all feet down after the last step
    cycles: int = 2  # gait cycles (one step per foot each)
    yaw: float = 90.0  # final base yaw (deg)
    step_height: float = 0.1  # swing apex (m), followed as a constraint
    friction: float | None = None  # None: the robot config's
    foot_radius: float | None = None  # ball feet (m); None: the robot config's
    locked_joints: list[str] = field(default_factory=list)  # held at the nominal posture
    torque_limit_scale: float = 1.0
    w_position: float = 10.0
    w_height: float = 10.0
    w_upright: float = 100.0
    w_yaw: float = 10.0  # tracking a yaw ramp from 0 to ``yaw`` over the steps
    w_posture: float = 1.0
    w_velocity: float = 0.1
    w_acceleration: float = 1e-3
    w_force: float = 1e-5

    def __post_init__(self) -> None:
        check_settings(self, positive=("dt", "step", "cycles", "step_height", "friction",
                                       "torque_limit_scale"),
                       non_negative=("stand", "pause", "settle", "foot_radius", "w_position",
                                     "w_height", "w_upright", "w_yaw", "w_posture",
                                     "w_velocity", "w_acceleration", "w_force"))
        if not abs(self.yaw) <= MAX_YAW_PER_CYCLE * self.cycles:
            raise ValueError(f"setting 'yaw' must be within +-{MAX_YAW_PER_CYCLE:g} degrees per "
                             f"gait cycle (cycles {self.cycles}: +-"
                             f"{MAX_YAW_PER_CYCLE * self.cycles:g}), got {self.yaw:g}; more "
                             "cycles turn further")

    @property
    def duration(self) -> float:
        """Total duration (s)."""
        return self.stand + self.n_steps * (self.step + self.pause) - self.pause + self.settle

    @property
    def n_steps(self) -> int:
        """Number of steps (four per cycle)."""
        return 4 * self.cycles

    @property
    def n_nodes(self) -> int:
        """Number of intervals of the horizon."""
        return int(round(self.duration / self.dt))


@dataclass
class TurnProblem:
    """The turn's whole-body problem and its target."""

    wb: WholeBodyProblem
    settings: TurnSettings
    q_final: np.ndarray  # (nq,) final configuration (base yawed, joints as at the start)


def turn_schedule(st: TurnSettings, n_feet: int = 4) -> ContactSchedule:
    """One foot at a time in the ``walk`` gait's order, ``cycles`` times."""
    order = crawl_order(n_feet)
    swings: list[list[tuple[float, float]]] = [[] for _ in range(n_feet)]
    t = st.stand
    for j in range(st.n_steps):
        swings[order[j % n_feet]].append((t, t + st.step))
        t += st.step + st.pause
    return timeline_schedule(swings, st.n_nodes, st.dt, st.step_height)


def build_turn(model: RobotModel, cfg: RobotConfig, st: TurnSettings) -> TurnProblem:
    """The turn problem for ``model`` standing at its nominal posture (``cfg``)."""
    _, q0 = standing_configuration(cfg, model.pin_model)
    feet = list(cfg.feet)
    mu = cfg.friction if st.friction is None else st.friction
    wb = build_whole_body(model, feet, st.n_nodes, st.dt, q0, mu, clearance="constraint",
                          torque_limit_scale=st.torque_limit_scale,
                          foot_radius=cfg.foot_radius if st.foot_radius is None
                          else st.foot_radius)
    prb, q, v, a, f = wb.prb, wb.q, wb.v, wb.a, wb.f
    yaw = np.radians(st.yaw)
    q_final = q0.copy()
    q_final[3:7] = quat_multiply(quat_from_yaw(yaw), q0[3:7])
    wb.add_final_state(q_final)
    sched = turn_schedule(st, len(feet))
    wb.set_schedule(sched)

    # yaw reference: a ramp over the stepping part of the motion
    t = st.dt * np.arange(st.n_nodes + 1)
    t_end = st.duration - st.settle
    yaw_ref = yaw * np.clip((t - st.stand) / (t_end - st.stand), 0.0, 1.0)
    heading = prb.create_parameter("heading_ref", 2)
    heading.assign(np.vstack([np.cos(yaw_ref), np.sin(yaw_ref)]))
    R = base_rotation(q)
    diff = model.difference()(q0, q)
    prb.create_cost("base_position", q[0:2] - q0[0:2], weight=st.w_position)
    prb.create_cost("base_height", q[2] - q0[2], weight=st.w_height)
    prb.create_cost("base_upright", R[0:2, 2], weight=st.w_upright)
    # sin(yaw - yaw_ref) from the rotation matrix's first column
    prb.create_cost("base_yaw", R[1, 0] * heading[0] - R[0, 0] * heading[1], weight=st.w_yaw)
    prb.create_cost("posture", diff[6:], weight=st.w_posture)
    prb.create_cost("velocity", v, weight=st.w_velocity)
    prb.create_cost("acceleration", a, weight=st.w_acceleration)
    prb.create_cost("forces", f, weight=st.w_force)

    # initial guess: the standing posture turning along the yaw ramp
    qg = np.repeat(q0[:, None], st.n_nodes + 1, axis=1)
    for k, yk in enumerate(yaw_ref):
        qg[3:7, k] = quat_multiply(quat_from_yaw(yk), q0[3:7])
    wb.guess(qg, sched.stance)
    log.info("turn: %s, N=%d, dt=%.3f s, %d steps, yaw %.1f deg", model.name, st.n_nodes,
             st.dt, st.n_steps, st.yaw)
    return TurnProblem(wb, st, q_final)


def turn_summary(res: MotionResult, tp: TurnProblem, model: RobotModel,
                 air_height: float | None = None) -> dict:
    """The turn's figures: final errors, swing phases read from the feet heights, apexes.

    ``swings_per_foot``: runs of nodes on which the foot is more than ``air_height`` (m;
    default a tenth of the step height: rolling ball feet move their frames by a few mm,
    which a 1 mm threshold counted as swings) above the ground (read from the motion, not
    the schedule); ``swing_apex``: the highest foot height of each of them (m). Angles in
    deg.
    """
    st = tp.settings
    if air_height is None:
        air_height = 0.1 * st.step_height
    out = {"target_yaw_deg": st.yaw, **final_state_errors(model, res, tp.q_final)}
    yaw = np.degrees(np.unwrap(roll_pitch_yaw(res.q[3:7].T)[:, 2]))
    out["final_yaw_deg"] = float(yaw[-1] - yaw[0])
    out["final_yaw_error_deg"] = float(out["final_yaw_deg"] - st.yaw)
    z = foot_heights(model, res)
    in_air = z > air_height
    swings = swing_intervals(~in_air)
    out["swings_per_foot"] = [len(s) for s in swings]
    out["swing_apex"] = [[float(z[i, a:b].max()) for a, b in s] for i, s in enumerate(swings)]
    out["step_height"] = st.step_height
    out.update(physics_summary(res, model))
    return out


def run_turn(robot: str | RobotConfig = "centauro", solver: str = "ipopt",
             settings: TurnSettings | None = None, opts: dict | None = None,
             model: RobotModel | None = None) -> MotionResult:
    """Build and solve the turn; the result's ``summary`` holds :func:`turn_summary`.
    Without ``settings``, those of ``config/motions/turn.yaml`` for the robot (as the
    ``motion`` CLI)."""
    cfg = load_robot_config(robot) if isinstance(robot, str) else robot
    settings = settings or motion_settings("turn", TurnSettings, cfg.name)
    model = model or robot_model(cfg, settings.locked_joints)
    tp = build_turn(model, cfg, settings)
    res = tp.wb.solve(solver, opts, motion="turn", robot=cfg.name)
    res.summary = turn_summary(res, tp, model)
    check_contacts(res)
    return res
