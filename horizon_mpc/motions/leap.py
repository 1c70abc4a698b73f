"""The leap (the paper's Spot leap, here on an example-robot-data quadruped).

Finite horizon, multiple shooting, IPOPT. Contact timeline: all four feet down; the front
feet lift and the hind legs push; flight; the front feet land first, then the hind feet.
Final constraints: base position ``p_des`` (``distance`` ahead of the start, same height),
base orientation and joints as at the start, velocity zero.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.locomotion import ContactSchedule
from horizon_mpc.model import RobotModel
from horizon_mpc.motions.analysis import (
    best_overlap,
    check_contacts,
    flight_phases,
    loaded,
    physics_summary,
)
from horizon_mpc.motions.body import point_heights, trunk_points
from horizon_mpc.motions.result import MotionResult
from horizon_mpc.motions.schedule import timeline_schedule
from horizon_mpc.motions.settings import check_settings, motion_settings
from horizon_mpc.motions.wholebody import (
    WholeBodyProblem,
    build_whole_body,
    final_state_errors,
    quaternion_error,
    robot_model,
)
from horizon_mpc.posture import standing_configuration

__all__ = ["LeapProblem", "LeapSettings", "build_leap", "leap_schedule", "leap_summary",
           "replay_gains", "run_leap"]

log = logging.getLogger(__name__)


@dataclass
class LeapSettings:
    """Timeline (s), target and weights of the leap (``config/motions/leap.yaml``)."""

    dt: float = 0.02
    stand: float = 0.2  # all feet down before the leap
    push: float = 0.24  # front feet up, hind legs pushing
    flight: float = 0.16  # all feet in the air
    land: float = 0.16  # front feet down, hind feet still in the air
    settle: float = 0.44  # all feet down until the end
    distance: float = 0.4  # forward displacement of the base (m)
    swing_floor: float = 0.08  # mid-swing height (m) the swinging feet must stay above
    # m the trunk (its collision shapes, horizon_mpc.motions.body) stays above the ground on
    # every node; None: unconstrained (the go2 landed nose-down, its trunk 9 cm deep)
    trunk_clearance: float | None = 0.02
    friction: float | None = None  # None: the robot config's
    foot_radius: float | None = None  # ball feet (m); None: the robot config's
    locked_joints: list[str] = field(default_factory=list)  # held at the nominal posture
    torque_limit_scale: float = 0.8  # fraction of the URDF effort limits the plan may use
    # joint PD gains of the open-loop PyBullet replay, raised to the robot's own simulator
    # gains where those are stiffer (replay_gains)
    replay_kp: float = 100.0
    replay_kd: float = 3.0
    w_posture: float = 1.0
    w_pitch: float = 10.0  # the leap pitches the base: a light cost
    w_roll_yaw: float = 1000.0  # it should neither roll nor turn
    w_lateral: float = 10.0
    w_velocity: float = 0.1
    w_acceleration: float = 1e-3
    w_force: float = 1e-4
    w_torque: float = 1e-3

    def __post_init__(self) -> None:
        check_settings(self, positive=("dt", "push", "flight", "land", "friction",
                                       "torque_limit_scale"),
                       non_negative=("stand", "settle", "swing_floor", "foot_radius",
                                     "trunk_clearance",
                                     "replay_kp", "replay_kd", "w_posture", "w_pitch",
                                     "w_roll_yaw", "w_lateral", "w_velocity", "w_acceleration",
                                     "w_force", "w_torque"))

    @property
    def duration(self) -> float:
        """Total duration (s)."""
        return self.stand + self.push + self.flight + self.land + self.settle

    @property
    def n_nodes(self) -> int:
        """Number of intervals of the horizon."""
        return int(round(self.duration / self.dt))


def replay_gains(settings: LeapSettings, cfg: RobotConfig
                 ) -> tuple[float | list[float], float | list[float]]:
    """The joint PD gains (kp, kd) of the leap's open-loop replay: ``replay_kp`` /
    ``replay_kd``, or the robot config's simulator gains (``sim.kp``/``kd``, a number or
    one per joint) where those are stiffer. go2's closed-loop gains (30) let its replay
    sag, so the leap's are stiffer; every robot got go2's 100 until session 32, and hyq
    (its own 300) landed 0.12 m ahead of a 0.4 m plan, not standing."""
    def stiffer(leap: float, own: float | list[float]) -> float | list[float]:
        if isinstance(own, list):
            return [max(leap, float(g)) for g in own]
        return max(leap, float(own))

    return stiffer(settings.replay_kp, cfg.sim.kp), stiffer(settings.replay_kd, cfg.sim.kd)


@dataclass
class LeapProblem:
    """The leap's whole-body problem and its targets."""

    wb: WholeBodyProblem
    settings: LeapSettings
    p_des: np.ndarray  # (3,) final base position (m)
    front: list[int]  # indices of the front feet in ``wb.feet``
    hind: list[int]
    trunk: np.ndarray  # (k, 3) points of the trunk in the base frame (horizon_mpc.motions.body)


def leap_schedule(st: LeapSettings, front: list[int], hind: list[int]) -> ContactSchedule:
    """Front feet in the air from ``stand`` to ``stand+push+flight``; hind feet from
    ``stand+push`` to ``stand+push+flight+land``."""
    t_front_up = st.stand
    t_hind_up = st.stand + st.push
    t_front_down = t_hind_up + st.flight
    t_hind_down = t_front_down + st.land
    swings: list[list[tuple[float, float]]] = [[] for _ in range(len(front) + len(hind))]
    for i in front:
        swings[i] = [(t_front_up, t_front_down)]
    for i in hind:
        swings[i] = [(t_hind_up, t_hind_down)]
    return timeline_schedule(swings, st.n_nodes, st.dt, st.swing_floor)


def front_and_hind(model: RobotModel, feet: list[str], q0: np.ndarray) -> tuple[list[int],
                                                                                list[int]]:
    """Split the feet by their x position in the base frame at ``q0`` (front: x > 0)."""
    x = np.array([float(model.fk(foot)(q0)[0][0]) for foot in feet]) - q0[0]
    front = [i for i in range(len(feet)) if x[i] > 0]
    hind = [i for i in range(len(feet)) if x[i] <= 0]
    if not front or not hind:
        raise ValueError(f"cannot tell front from hind feet: x = {x.round(3).tolist()}")
    return front, hind


def build_leap(model: RobotModel, cfg: RobotConfig, st: LeapSettings) -> LeapProblem:
    """The leap problem for ``model`` standing at its nominal posture (``cfg``)."""
    _, q0 = standing_configuration(cfg, model.pin_model)
    feet = list(cfg.feet)
    front, hind = front_and_hind(model, feet, q0)
    mu = cfg.friction if st.friction is None else st.friction
    wb = build_whole_body(model, feet, st.n_nodes, st.dt, q0, mu, clearance=None,
                          torque_limit_scale=st.torque_limit_scale,
                          foot_radius=cfg.foot_radius if st.foot_radius is None
                          else st.foot_radius)
    prb, q, v, a, f = wb.prb, wb.q, wb.v, wb.a, wb.f
    p_des = q0[:3] + np.array([st.distance, 0.0, 0.0])
    q_final = q0.copy()
    q_final[:3] = p_des
    wb.add_final_state(q_final)
    sched = leap_schedule(st, front, hind)
    wb.set_schedule(sched, floor=True)
    trunk, why = np.zeros((0, 3)), f"{model.name} has no collision shape on its base"
    try:
        trunk = trunk_points(cfg, model.pin_model)
    except FileNotFoundError as exc:  # a collision mesh the URDF names is missing
        why = str(exc)
    if st.trunk_clearance is not None and len(trunk):
        prb.create_constraint("trunk_clearance", point_heights(q, trunk),
                              bounds=(np.full(len(trunk), st.trunk_clearance),
                                      np.full(len(trunk), np.inf)))
    elif st.trunk_clearance is not None:
        log.warning("leap: the trunk's height is not constrained: %s", why)

    diff = model.difference()(q0, q)

    prb.create_cost("posture", diff[6:], weight=st.w_posture)
    prb.create_cost("base_orientation", quaternion_error(q[3:7], q0[3:7]),
                    weight=[st.w_roll_yaw, st.w_pitch, st.w_roll_yaw])
    prb.create_cost("lateral", q[1] - q0[1], weight=st.w_lateral)
    prb.create_cost("velocity", v, weight=st.w_velocity)
    prb.create_cost("acceleration", a, weight=st.w_acceleration)
    prb.create_cost("forces", f, weight=st.w_force)
    prb.create_cost("torques", wb.tau[6:], weight=st.w_torque)

    # initial guess: the standing posture carried from the start to the target at constant
    # speed, the weight shared by the feet in stance
    s = np.linspace(0.0, 1.0, st.n_nodes + 1)
    qg = np.repeat(q0[:, None], st.n_nodes + 1, axis=1)
    qg[:3] += np.outer(p_des - q0[:3], s)
    wb.guess(qg, sched.stance)
    log.info("leap: %s, N=%d, dt=%.3f s, target %s", model.name, st.n_nodes, st.dt,
             np.round(p_des, 3).tolist())
    return LeapProblem(wb, st, p_des, front, hind, trunk)


def leap_summary(res: MotionResult, lp: LeapProblem, model: RobotModel) -> dict:
    """The leap's figures: final errors, phases read from the forces, torque use, dynamics.

    Times in s, distances in m, angles in deg. The flight is the run of unloaded intervals
    that overlaps the scheduled one most (``flight_phases`` lists every run; others, e.g. a
    plan that unloads all feet for a moment while standing, are also in
    ``unscheduled_flights``). ``hind_lift_off`` / ``front_lift_off``: end of the last loaded
    interval of each foot before the flight; ``front_touchdown`` / ``hind_touchdown``: start
    of its first loaded interval after it.
    """
    st = lp.settings
    q_final = lp.wb.q0.copy()
    q_final[:3] = lp.p_des
    out = {"target": lp.p_des.tolist(), "distance": st.distance,
           **final_state_errors(model, res, q_final)}
    load = loaded(res)
    flights = flight_phases(load)
    out["flight_phases"] = [[a * res.dt, b * res.dt] for a, b in flights]
    if flights:
        s0 = round((st.stand + st.push) / res.dt)
        s1 = s0 + max(1, round(st.flight / res.dt))
        k0, k1 = best_overlap(flights, s0, s1)
        out["unscheduled_flights"] = [[a * res.dt, b * res.dt] for a, b in flights
                                      if (a, b) != (k0, k1)]

        def last_before(i: int) -> float | None:
            idx = np.flatnonzero(load[i, :k0])
            return float((idx[-1] + 1) * res.dt) if idx.size else None

        def first_after(i: int) -> float | None:
            idx = np.flatnonzero(load[i, k1:])
            return float((k1 + idx[0]) * res.dt) if idx.size else None

        out["front_lift_off"] = [last_before(i) for i in lp.front]
        out["hind_lift_off"] = [last_before(i) for i in lp.hind]
        out["front_touchdown"] = [first_after(i) for i in lp.front]
        out["hind_touchdown"] = [first_after(i) for i in lp.hind]
    # the trunk's lowest point on the nodes (m; null without collision shapes)
    out["min_trunk_height"] = (float(min(point_heights(qk, lp.trunk).min() for qk in res.q.T))
                               if len(lp.trunk) else None)
    out.update(physics_summary(res, model))
    return out


def run_leap(robot: str | RobotConfig = "go2", solver: str = "ipopt",
             settings: LeapSettings | None = None, opts: dict | None = None,
             model: RobotModel | None = None) -> MotionResult:
    """Build and solve the leap; the result's ``summary`` holds :func:`leap_summary`.
    Without ``settings``, those of ``config/motions/leap.yaml`` for the robot (as the
    ``motion`` CLI)."""
    cfg = load_robot_config(robot) if isinstance(robot, str) else robot
    settings = settings or motion_settings("leap", LeapSettings, cfg.name)
    model = model or robot_model(cfg, settings.locked_joints)
    lp = build_leap(model, cfg, settings)
    res = lp.wb.solve(solver, opts, motion="leap", robot=cfg.name)
    res.summary = leap_summary(res, lp, model)
    check_contacts(res)
    res.arrays["p_des"] = lp.p_des
    return res
