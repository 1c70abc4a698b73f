"""The receding-horizon trot (the paper's Spot walk, here on go2), solved offline.

The walking problem of :func:`horizon_mpc.locomotion.build_walking_problem` (whole-body,
under-actuation, contacts switched by the trot schedule, a constant base velocity reference
and a postural cost, no final constraint) is solved online for several seconds: at each tick
the horizon starts at the current state, the trot schedule is sampled from the current time
(the horizon shifts node by node), the solver is warm-started from the previous solution
shifted by one node and runs (ILQR: ``iterations`` real-time iterations), and the robot
moves along the solution: its first node is the next measured state (a perfect model).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import casadi as cs
import numpy as np

from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.locomotion import MpcSettings, WalkingProblem, build_walking_problem, make_gait
from horizon_mpc.locomotion.pose_reference import advance_pose, base_yaw, horizon_poses
from horizon_mpc.model import RobotModel
from horizon_mpc.motions.analysis import foot_heights, physics_summary, swing_intervals
from horizon_mpc.motions.result import MotionResult
from horizon_mpc.motions.schedule import touchdown_nodes
from horizon_mpc.motions.settings import check_settings, motion_settings
from horizon_mpc.motions.wholebody import robot_model
from horizon_mpc.problem.terms import term_name
from horizon_mpc.solvers import make_solver

__all__ = ["WalkSettings", "run_walk", "walk_summary"]

log = logging.getLogger(__name__)


@dataclass
class WalkSettings:
    """Duration, command and solver budget of the walk (``config/motions/walk.yaml``)."""

    duration: float = 4.0  # s of motion (ticks = duration / dt of the walking problem)
    velocity: list[float] = field(default_factory=lambda: [0.3, 0.0, 0.0])  # vx, vy, wz
    iterations: int = 3  # ILQR real-time iterations per tick
    # the first horizon is solved to convergence: 15-335 iterations for the 8 quadrupeds with
    # configs and three commands (go2 turning in place 335; doc/motions.md)
    bootstrap_iterations: int = 500
    nlp_max_iter: int = 30  # IPOPT / GN-SQP iterations per tick (warm started)
    average_cycles: int = 2  # gait cycles at the end over which the velocity is averaged
    w_touchdown: float = 1e6  # ILQR: touch-down height cost (1/m^2; the NLPs: a constraint)
    mpc: dict[str, Any] = field(default_factory=dict)  # overrides of the robot's ``mpc:``

    def __post_init__(self) -> None:
        check_settings(self, positive=("duration", "iterations", "bootstrap_iterations",
                                       "nlp_max_iter", "average_cycles"),
                       non_negative=("w_touchdown",))
        v = self.velocity
        if not (isinstance(v, (list, tuple)) and len(v) == 3 and all(
                isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
                for x in v)):
            raise ValueError(f"setting 'velocity' must be 3 finite numbers [vx, vy, wz], "
                             f"got {v!r}")
        if not isinstance(self.mpc, dict):
            raise ValueError(f"setting 'mpc' must be a mapping of the robot's mpc: overrides, "
                             f"got {self.mpc!r}")
        try:  # its keys and kinds, before any build
            MpcSettings.from_dict(self.mpc)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"setting 'mpc': {exc}") from None


def _solver_options(solver: str, st: WalkSettings, mpc: MpcSettings) -> dict[str, Any]:
    if solver == "ilqr":  # the inequality rows as the walking MPC treats them (its settings)
        return {"rti": True, "iterations_per_call": st.iterations, "rho_init": mpc.rho_init,
                "inequality": mpc.inequality, "barrier_mu": mpc.barrier_mu,
                "barrier_delta": mpc.barrier_delta}
    if solver == "ipopt":  # rows on every valid node: the schedule moves between solves
        return {"max_iter": st.nlp_max_iter, "tol": 1e-6}
    # qrqp (gnsqp's default) needs minutes per QP at this size, osqp a fraction of a second;
    # with osqp's steps the stationarity measure cycles around 1e-5 once the cost is
    # converged (to 8 digits): stop at 1e-4
    return {"max_iter": st.nlp_max_iter, "qp_solver": "osqp", "tol": 1e-4}


#: largest dynamics defect (per unit of the state) and base wrench (per unit of the weight) of
#: an executed walk that counts as physically consistent
CONSISTENCY = 1e-6


def run_walk(robot: str | RobotConfig = "go2", solver: str = "ilqr",
             settings: WalkSettings | None = None, opts: dict | None = None,
             model: RobotModel | None = None) -> MotionResult:
    """Walk for ``settings.duration`` s under the receding-horizon controller.

    Returns the executed motion: states on every tick (``q``, ``v``: (n, T+1)), the first
    input of each solution (``a``, ``f``, ``tau``: (n, T)), the stance of each tick, and in
    ``arrays``: ``v_ref`` (6,), per-tick ``tick_time`` (s), ``iterations`` and
    ``violation``; ``summary`` holds :func:`walk_summary`. Without ``settings``, those of
    ``config/motions/walk.yaml`` for the robot (as the ``motion`` CLI).
    """
    cfg = load_robot_config(robot) if isinstance(robot, str) else robot
    st = settings or motion_settings("walk", WalkSettings, cfg.name)
    model = model or robot_model(cfg)
    mpc = MpcSettings.from_config(cfg, st.mpc)
    wp = build_walking_problem(model, cfg, mpc)
    prb, N, dt = wp.prb, wp.n_nodes, mpc.dt
    if solver != "ilqr":
        # the NLP sees all four quaternion components; the tangent-space defects pin three
        prb.create_constraint("unit_quaternion", cs.dot(wp.q[3:7], wp.q[3:7]) - 1.0,
                              nodes=range(1, N + 1))
    # the walking problem keeps a stance foot still but never puts it on the ground: a foot
    # lands where its swing ends (measured: ~2 cm up). Touch-down at the standing height: a
    # constraint for the NLP solvers, a stiff cost for the ILQR (with the constraint, whose
    # state-only rows move with the schedule, it diverged)
    touchdown = {}
    for foot in wp.feet:
        z = model.fk(foot)(wp.q)[0][2] - float(model.fk(foot)(wp.q_nominal)[0][2])
        name = term_name(foot, "touchdown")
        touchdown[foot] = (prb.create_cost(name, z, nodes=[], weight=st.w_touchdown)
                           if solver == "ilqr" else prb.create_constraint(name, z, nodes=[]))
    t0 = time.perf_counter()
    slv = make_solver(solver, prb, {**_solver_options(solver, st, mpc), **(opts or {})})
    build = time.perf_counter() - t0
    g = mpc.gait
    gait = make_gait(g.name, g.step_duration, g.step_height, g.duty_factor, len(wp.feet))
    cmd = np.asarray(st.velocity, float)
    wp.v_ref.assign([cmd[0], cmd[1], 0.0, 0.0, 0.0, cmd[2]])
    tau_fn = model.inverse_dynamics(wp.feet)

    q, v = wp.q_nominal.copy(), np.zeros(model.nv)
    n_ticks = int(round(st.duration / dt))
    if n_ticks < 2:  # one tick has no motion to measure (its figures were of the start)
        raise ValueError(f"walk duration {st.duration:g} s is shorter than two MPC ticks of "
                         f"{dt:g} s")
    if abs(n_ticks * dt - st.duration) > 1e-9:
        log.warning("walk duration %g s is not a whole number of %g s ticks: walking %d "
                    "ticks (%g s)", st.duration, dt, n_ticks, n_ticks * dt)
    Q, V, A, F, TAU, S = [q], [v], [], [], [], []
    tick_time, iterations, violation = [], [], []
    # the pose reference integrates the command from the start pose (within the leash of
    # the measured pose): the integral action of the walking MPC (WalkingMpc)
    pose = np.array([q[0], q[1], base_yaw(q)])
    for i in range(n_ticks):
        if i:
            pose = advance_pose(pose, cmd, q, dt, mpc.pose_leash, mpc.yaw_leash)
        _set_tick(wp, touchdown, q, v, cmd, pose, gait.schedule(i * dt, N, dt))
        first = i == 0
        if first:  # bootstrap: the first horizon to convergence
            if solver == "ilqr":
                slv.set_option("rti", False)
                slv.set_option("max_iter", st.bootstrap_iterations)
            else:
                slv.set_option("max_iter", max(st.bootstrap_iterations, 200))
        slv.solve()
        if first:
            bootstrap_status = (slv.stats.success, slv.stats.status)
            if solver == "ilqr":
                slv.set_option("rti", True)
            else:
                slv.set_option("max_iter", st.nlp_max_iter)
        sol = slv.solution
        if not all(np.all(np.isfinite(sol[k])) for k in ("q", "v", "a", "f")):
            raise RuntimeError(f"walk: {solver} returned a non-finite solution at tick {i} "
                               f"({slv.stats.status})")
        a, f = sol["a"][:, 0].copy(), sol["f"][:, 0].copy()
        A.append(a)
        F.append(f)
        TAU.append(np.asarray(tau_fn(q, v, a, f)).ravel())
        S.append(gait.schedule(i * dt, 0, dt).stance[:, 0])
        tick_time.append(slv.stats.time)
        iterations.append(slv.stats.iterations)
        violation.append(slv.stats.constraint_violation)
        q, v = sol["q"][:, 1].copy(), sol["v"][:, 1].copy()  # perfect model
        Q.append(q)
        V.append(v)
        slv.shift()
    S.append(S[-1])
    stats = {"solver": solver, "build_time": build, "ticks": n_ticks,
             "bootstrap_time": tick_time[0], "bootstrap_iterations": iterations[0],
             "iterations_per_tick": float(np.mean(iterations[1:] or [0])),
             "time": float(np.sum(tick_time)), **_percentiles(np.array(tick_time[1:])),
             "max_constraint_violation": float(np.max(violation[1:] or [0.0]))}
    res = MotionResult("walk", cfg.name, solver, list(wp.feet), list(model.joint_names), dt,
                       np.array(Q).T, np.array(V).T, np.array(A).T, np.array(F).T,
                       np.array(TAU).T, np.array(S).T, stats, integrator="euler")
    # the dynamics apply the forces at the foot frames (res.foot_radius 0), the stance
    # condition holds a rolling ball foot still: one foot model for both is not solved
    res.arrays.update(stance_foot_radius=cfg.foot_radius,
                      v_ref=np.array([cmd[0], cmd[1], 0.0, 0.0, 0.0, cmd[2]]),
                      tick_time=np.array(tick_time), iterations=np.array(iterations),
                      violation=np.array(violation))
    res.summary = walk_summary(res, gait.period, st, model, mpc.gait.step_height)
    # success: the first horizon converged and the motion executed is consistent (its
    # Euler steps and the dynamics hold: the motion a perfect model would follow); a tick
    # may end unconverged (real-time iterations), but not a motion that breaks the physics
    # (0 iterations per tick: defects of 0.085; 3 m/s: 3.5)
    consistent = (res.summary["max_dynamics_defect"] <= CONSISTENCY
                  and res.summary["max_base_wrench"] <= CONSISTENCY * model.mass * 9.81)
    stats["success"] = bool(bootstrap_status[0] and consistent)
    stats["status"] = ("consistent" if stats["success"] else
                       f"bootstrap: {bootstrap_status[1]}" if not bootstrap_status[0] else
                       f"inconsistent motion (dynamics defect "
                       f"{res.summary['max_dynamics_defect']:.2g}, base wrench "
                       f"{res.summary['max_base_wrench']:.2g} N)")
    log.info("walk with %s: %d ticks, %.1f ms per tick (median), mean vx %.3f m/s",
             solver, n_ticks, stats["tick_ms_median"], res.summary["mean_velocity"][0])
    return res


def _set_tick(wp: WalkingProblem, touchdown: dict, q: np.ndarray, v: np.ndarray,
              cmd: np.ndarray, pose: np.ndarray, sched) -> None:
    """Measured state on node 0, pose reference from ``pose`` (x, y, yaw) along ``cmd``,
    contact schedule of the horizon
    (feet on the ground at touch-down; a foot pushes only over intervals it is down at both
    ends of, not over the one in which it lifts off)."""
    wp.q.set_bounds(q, q, nodes=0)
    wp.v.set_bounds(v, v, nodes=0)
    wp.q.set_initial_guess(q, nodes=0)
    wp.v.set_initial_guess(v, nodes=0)
    wp.pose_ref.assign(horizon_poses(pose, cmd, wp.n_nodes, wp.settings.dt))
    st = np.asarray(sched.stance, bool)
    wp.contacts.set_schedule(st, sched.swing_height())
    loaded = st[:, :-1] & st[:, 1:]
    for i, (foot, nodes) in enumerate(zip(wp.feet, touchdown_nodes(st), strict=True)):
        touchdown[foot].set_nodes(nodes[nodes > 0])  # node 0 is the measured state
        wp.contacts.friction[foot].set_nodes(np.flatnonzero(loaded[i]))
        wp.contacts.zero_force[foot].set_nodes(np.flatnonzero(~loaded[i]))


def _percentiles(x: np.ndarray) -> dict[str, float]:
    if x.size == 0:
        return {"tick_ms_median": math.nan, "tick_ms_p95": math.nan, "tick_ms_max": math.nan}
    return {"tick_ms_median": float(np.median(x) * 1e3),
            "tick_ms_p95": float(np.percentile(x, 95) * 1e3),
            "tick_ms_max": float(np.max(x) * 1e3)}


def velocity_errors(mean: np.ndarray, ref: np.ndarray) -> tuple[float, float | None,
                                                                 float | None]:
    """``(velocity_error, linear part, yaw-rate part)`` of a mean base-frame velocity
    ``(vx, vy, wz)`` against its reference (see :func:`walk_summary`)."""
    lin_ref = float(np.linalg.norm(ref[:2]))
    lin_err = float(np.linalg.norm(mean[:2] - ref[:2]) / lin_ref) if lin_ref > 0 else None
    yaw_err = float(abs(mean[2] - ref[2]) / abs(ref[2])) if ref[2] != 0 else None
    parts = [e for e in (lin_err, yaw_err) if e is not None]
    return (max(parts) if parts else float(np.linalg.norm(mean[:2]))), lin_err, yaw_err


def walk_summary(res: MotionResult, period: float, st: WalkSettings,
                 model: RobotModel, step_height: float = math.nan) -> dict:
    """Velocity over the last ``average_cycles`` gait cycles and force periodicity.

    ``mean_velocity``: mean base-frame ``(vx, vy, wz)`` over the window;
    ``velocity_error``: the larger of ``|mean - reference| / |reference|`` of the linear
    part and of the yaw rate (each where its reference is not zero), or the mean linear
    speed (m/s) when the whole reference is zero; ``linear_velocity_error`` and
    ``yaw_rate_error``: the two parts (None where that reference is zero);
    ``distance``: the base's net displacement in the plane (m), ``path_length`` the length
    of its path;
    ``force_periodicity``: ``||f(last cycle) - f(cycle before)|| / ||f(last cycle)||``
    (absent for a gait without cycles, ``stand``: the window is then the whole motion);
    ``window_includes_start_up``: the walk is shorter than ``average_cycles`` cycles, and
    its mean velocity includes the start from standing;
    ``swing_apex``: ``[lowest, highest]`` apex over the planned swings (m above the foot's
    standing height), beside the gait's ``step_height`` (the clearance is a cost: an apex
    below it is the compromise the weights made).
    """
    cyclic = math.isfinite(period)  # a gait that never lifts a foot has no cycle
    n_cycle = int(round(period / res.dt)) if cyclic else res.n_nodes
    n_win = min(st.average_cycles * n_cycle, res.n_nodes)
    if cyclic and n_win < st.average_cycles * n_cycle:
        log.warning("walk of %.2f s: shorter than the %d gait cycles (%.2f s) the velocity "
                    "is averaged over; averaging over all of it, start-up included",
                    res.t[-1], st.average_cycles, st.average_cycles * period)
    v = res.v[:, -n_win - 1:-1]
    mean = np.array([v[0].mean(), v[1].mean(), v[5].mean()])
    ref = np.asarray(st.velocity, float)
    err, lin_err, yaw_err = velocity_errors(mean, ref)
    out = {"velocity_reference": ref.tolist(), "mean_velocity": mean.tolist(),
           "velocity_error": err, "linear_velocity_error": lin_err, "yaw_rate_error": yaw_err,
           "window": [float(res.t[-n_win - 1]), float(res.t[-1])],
           # a walk shorter than the averaging cycles: its start from standing is in it
           "window_includes_start_up": bool(cyclic and n_win < st.average_cycles * n_cycle),
           "gait_period": period,
           "distance": float(np.linalg.norm(res.q[:2, -1] - res.q[:2, 0])),  # net, start to end
           "path_length": float(np.sum(np.linalg.norm(np.diff(res.q[:2], axis=1), axis=0)))}
    if cyclic and res.n_nodes >= 2 * n_cycle:
        last, prev = res.f[:, -n_cycle:], res.f[:, -2 * n_cycle:-n_cycle]
        out["force_periodicity"] = float(np.linalg.norm(last - prev) / np.linalg.norm(last))
    z = foot_heights(model, res)
    z = z - z[:, :1]  # above the standing height (the walk starts standing)
    apexes = [float(z[i, a:b].max()) for i, runs in enumerate(swing_intervals(res.stance))
              for a, b in runs if b > a]
    out["swing_apex"] = [min(apexes), max(apexes)] if apexes else None
    out["step_height"] = float(step_height)
    out.update(physics_summary(res, model, contacts=False))
    return out
