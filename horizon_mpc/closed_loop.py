"""``python -m horizon_mpc.closed_loop``: simulator node + MPC node, ROS in the loop.

``lockstep`` mode: both nodes and a command player share one rclpy context and one
single-threaded executor, and the loop is paced by the messages themselves: the simulator
publishes a state, the MPC node (``trigger: state``) answers with a trajectory stamped like
that state, the simulator advances one control period and publishes the next state.

``realtime`` mode: the MPC node runs in a process of its own (``mpc_node``, timer trigger on
the sim clock; :mod:`horizon_mpc.nodes.mpc_process`) so that it and the simulator, free at
realtime factor 1 in this process with the command player and the recorder, use two cores.
The tick statistics come from the MPC's ``/diagnostics``, the plans' age from its
``joint_trajectory``. See ``doc/closed_loop.md`` for the outputs (summary.json, plots, GIF).
"""

from __future__ import annotations

import argparse
import logging
import math
import numbers
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import Twist
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.publisher import Publisher
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from horizon_mpc.closed_loop_profile import (
    DEFAULT_PROFILE,
    Push,
    Segment,
    command_at,
    load_profile,
    load_pushes,
    unreached_segments,
    with_zero_tail,
)
from horizon_mpc.closed_loop_report import (
    FRAME_PERIOD,
    fallen,
    gif_frame_period,
    render_replay,
)
from horizon_mpc.config import RobotConfig, load_robot_config, parse_yaml
from horizon_mpc.locomotion import GaitSettings, MpcSettings, config_gait, speed_scale
from horizon_mpc.nodes.mpc_node import MpcNode
from horizon_mpc.nodes.mpc_parameters import MODEL_PARAMETERS, gait_duty_factor, parameter_names
from horizon_mpc.nodes.mpc_process import (
    MAX_DOMAIN_ID,
    MpcMonitor,
    MpcProcess,
    MpcProcessError,
    TickRecord,
    default_domain_id,
    private_domain_id,
    process_cpu_seconds,
    process_memory_mb,
    wait_until,
)
from horizon_mpc.nodes.sim_node import SimNode

__all__ = ["DEFAULT_PROFILE", "Push", "Recording", "Segment", "command_at", "control_period",
           "load_profile", "load_pushes", "main", "run"]

log = logging.getLogger(__name__)

#: s (wall) to wait for the MPC process to connect, and again for its first plan
READY_TIMEOUT = 120.0
#: s (wall) per control period while the simulator holds for the MPC's first plan
HOLD_PERIOD = 0.25
#: Hz (sim) of the simulator's states in real time (sim_node's default is 500): measured on
#: go2, the same plan age and ticks per second, ~0.1 core less in each process
REALTIME_STATE_RATE = 250.0
#: s (wall) after the loop's nodes start before the last check for other publishers on the
#: run's domain (discovery is not instantaneous; a short lockstep run is over in 0.3 s)
DISCOVERY_SETTLE = 2.0


@dataclass
class Recording:
    """Ground truth and controller data, one row per recorded control period."""

    t: list[float] = field(default_factory=list)
    q: list[np.ndarray] = field(default_factory=list)  # (nq,) Pinocchio q
    v: list[np.ndarray] = field(default_factory=list)  # (nv,) base twist in the base frame
    cmd: list[np.ndarray] = field(default_factory=list)  # profile command (vx, vy, wz)
    cmd_mpc: list[np.ndarray] = field(default_factory=list)  # the MPC's ramped command
    contact: list[np.ndarray] = field(default_factory=list)  # (n_feet,) bool
    tick_t: list[float] = field(default_factory=list)  # state time of each MPC tick
    tick_time: list[float] = field(default_factory=list)  # wall s of each tick's solve
    # wall s of the next tick's preparation after each tick (0 without prepare_ahead)
    prepare_time: list[float] = field(default_factory=list)
    tick_iterations: list[float] = field(default_factory=list)
    plan_t: list[float] = field(default_factory=list)  # stamp of each plan the sim got
    plan_age: list[float] = field(default_factory=list)  # sim time at receipt - stamp (s)
    frames: list[np.ndarray] = field(default_factory=list)
    frame_period: float = FRAME_PERIOD  # sim s between two frames (gif_frame_period)
    feet: list[str] = field(default_factory=list)
    wall_time: float = 0.0
    deadline_misses: int = 0  # the MPC node's count (solve longer than the period)
    overruns: int = 0  # the same with trigger 'state' (lockstep: the simulator waits)
    stale_skips: int = 0  # ticks the MPC node skipped: state older than its state_timeout
    # whole ticks on a state off the prepared tick time (with prepare_ahead)
    prepare_misses: int = 0
    nominal_height: float = math.nan
    # the MPC node's command limits (vx, vy m/s, wz rad/s) and its combined limit (see
    # locomotion/command.py): commands beyond are limited
    max_velocity: list[float] | None = None
    max_command_norm: float = math.inf
    build_time: float = math.nan  # s (wall) until the MPC could tick (realtime: 1st plan)
    mpc_process: dict = field(default_factory=dict)  # realtime: pid, memory, CPU, exit code
    mpc_log: str = ""  # realtime: the end of the MPC process's output
    domain_id: int | None = None  # the run's ROS_DOMAIN_ID
    # other nodes heard publishing the loop's topics ("joint_trajectory: 2 publishers, 1
    # expected"): the run was not isolated, its figures may mix in theirs
    foreign_publishers: list[str] = field(default_factory=list)
    interrupted: bool = False  # Ctrl-C / SIGTERM ended the run before its duration

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-period lists as arrays (rows = time)."""
        names = ("t", "q", "v", "cmd", "cmd_mpc", "contact", "tick_t", "tick_time",
                 "prepare_time",
                 "tick_iterations", "plan_t", "plan_age")
        return {n: np.asarray(getattr(self, n)) for n in names}


def run(robot: str = "go2", segments: Sequence[Segment] | None = None,
        duration: float | None = None, mode: str = "lockstep", gif: bool = True,
        iterations: int | None = None, stop_after_fall: float = 1.0,
        pushes: Sequence[Push] = (), *, domain_id: int | None = None,
        mpc_parameters: Mapping[str, object] | None = None,
        mpc_command: Sequence[str] | None = None,
        ready_timeout: float = READY_TIMEOUT,
        sim_parameters: Mapping[str, object] | None = None) -> Recording:
    """Run the closed loop; returns the recording (see :func:`summarise` for the metrics).

    ``pushes`` are applied to the simulated base (ground truth, not through ROS).

    ``mpc_parameters``: more ``mpc_node`` parameters (name -> value).

    ``sim_parameters`` (lockstep only): the simulator's real-time emulation,
    ``lockstep_latency``, ``lockstep_latency_jitter``, ``lockstep_seed`` and
    ``lockstep_state_offset`` (``doc/simulator.md``, Lockstep protocol; name -> value).

    ``domain_id``: the ``ROS_DOMAIN_ID`` of the run; default in lockstep a private one
    derived from this process id (:func:`~horizon_mpc.nodes.mpc_process.private_domain_id`:
    parallel runs, and nodes on the environment's domain, do not hear it), in real time the
    environment's, else that private one
    (:func:`~horizon_mpc.nodes.mpc_process.default_domain_id`). Either way other publishers
    of the loop's topics are looked for once per sim second and reported
    (``Recording.foreign_publishers``).

    Real-time mode only (``doc/closed_loop.md``): ``mpc_command`` replaces ``python -m
    horizon_mpc.nodes.mpc_node`` as the MPC process's program (a benchmark's wrapper);
    ``ready_timeout`` (s, wall) bounds the wait for the MPC process's readiness and for its
    first plan. Raises :class:`~horizon_mpc.nodes.mpc_process.MpcProcessError` (with the end
    of its output) when the MPC process exits or is not ready in time.
    """
    segments = list(segments or load_profile(DEFAULT_PROFILE))
    if duration is None:
        duration = sum(s.duration for s in segments)
    # the CLI's checks, for a call from Python too (a NaN duration never ended; a misspelt
    # parameter ran the default without a word)
    if isinstance(duration, bool) or not (isinstance(duration, numbers.Real)
                                          and math.isfinite(duration) and duration > 0):
        raise ValueError(f"duration must be a finite number of seconds > 0, got {duration!r}")
    if iterations is not None and (isinstance(iterations, bool) or not (
            isinstance(iterations, numbers.Integral) and iterations >= 1)):
        raise ValueError(f"iterations must be an integer >= 1, got {iterations!r}")
    check_mpc_parameter_names(list(mpc_parameters or {}), "mpc_parameters: ")
    if mode not in ("lockstep", "realtime"):
        raise ValueError(f"mode must be 'lockstep' or 'realtime', got {mode!r}")
    cfg = load_robot_config(robot)  # an unknown robot fails here, before any node or process
    sim_parameters = dict(sim_parameters or {})
    unknown = sorted(set(sim_parameters) - set(SIM_LOCKSTEP_PARAMETERS))
    if unknown:
        raise ValueError(f"unknown simulator parameters {unknown}; the settable ones are "
                         f"{list(SIM_LOCKSTEP_PARAMETERS)}")
    if sim_parameters and mode != "lockstep":
        raise ValueError(f"{sorted(sim_parameters)}: lockstep mode only")
    period = control_period(robot, mpc_parameters)
    short = [i for i, seg in enumerate(segments) if seg.duration < period]
    if short:  # the commands are sampled once per period: such a segment may never be sent
        log.warning("segment(s) %s last less than the control period (%g s): their commands "
                    "may never reach the MPC (the profile is sampled once per period)",
                    short, period)
    warn_unreached_segments(segments, cfg, mpc_parameters)
    loop = _Loop(segments, duration, gif, stop_after_fall, pushes)
    domain_id = run_domain_id(mode, domain_id)
    try:
        if mode == "lockstep":
            rec = _run_lockstep(robot, iterations, loop, mpc_parameters, domain_id,
                                sim_parameters)
        else:
            rec = _run_realtime(robot, iterations, loop, domain_id, mpc_parameters,
                                mpc_command, ready_timeout)
    except KeyboardInterrupt:  # Ctrl-C, or SIGTERM in the CLI: the run so far, if any
        rec = loop.rec
        if not rec.t:
            raise
        rec.interrupted = True
        log.warning("interrupted at t = %.2f s of sim time: what follows is the run so far",
                    rec.t[-1])
    rec.max_velocity, rec.max_command_norm = command_limits(cfg, mpc_parameters)
    return rec


def warn_unreached_segments(segments: Sequence[Segment], cfg: RobotConfig,
                            mpc_parameters: Mapping[str, object] | None = None) -> None:
    """Warn about the segments the MPC's command ramp cannot reach
    (:func:`~horizon_mpc.closed_loop_profile.unreached_segments`), with the node's command
    limits (:func:`command_limits`: its ``-p max_vx``..., gait and ``max_command_norm``,
    not the config's alone) and the config's ``max_acceleration``."""
    st = MpcSettings.from_config(cfg)
    try:
        max_velocity, max_norm = command_limits(cfg, mpc_parameters)
    except (TypeError, ValueError):  # a bad -p value: the MPC node refuses it, naming it
        max_velocity, max_norm = st.max_velocity, st.max_command_norm
    unreached = unreached_segments(segments, max_velocity, st.max_acceleration, max_norm)
    if unreached:
        log.warning("segment(s) %s end before the command's ramp (%s s at the config's "
                    "max_acceleration %s) reaches them: the robot follows the ramped command, "
                    "which need not average as the profile does (a +-0.4 m/s flip every 0.5 s "
                    "drove go2 0.97 m forward)", [i for i, _ in unreached],
                    ", ".join(f"{r:.2g}" for _, r in unreached), st.max_acceleration)


def command_limits(cfg: RobotConfig, mpc_parameters: Mapping[str, object] | None = None
                   ) -> tuple[list[float], float]:
    """The MPC node's command limits for this config and parameters: per axis (vx, vy, wz),
    its ``max_vx``/``max_vy``/``max_wz``, else the config's ``mpc.max_velocity``, times the
    gait's :func:`~horizon_mpc.locomotion.speed_scale` (``-p gait``, ``step_duration``,
    ``duty_factor`` against the config's gait); and the combined one, ``max_command_norm``
    (:func:`horizon_mpc.locomotion.command.limit_command`)."""
    st = MpcSettings.from_config(cfg)
    given = dict(mpc_parameters or {})
    g = st.gait
    gait = GaitSettings(str(given.get("gait", g.name)),
                        float(given.get("step_duration", g.step_duration)),
                        gait_duty_factor(float(given["duty_factor"])) if "duty_factor" in given
                        else g.duty_factor, g.step_height).to_gait(len(cfg.feet))
    scale = speed_scale(gait, config_gait(cfg))
    return ([scale * float(given.get(name, lim)) for name, lim in
             zip(("max_vx", "max_vy", "max_wz"), st.max_velocity, strict=True)],
            float(given.get("max_command_norm", st.max_command_norm)))


@dataclass
class _Loop:
    """What both modes do once per control period: pushes, the command for the next
    period, the recording, the fall check and the end of the run."""

    segments: list[Segment]
    duration: float
    gif: bool
    stop_after_fall: float
    pushes: Sequence[Push]
    rec: Recording = field(default_factory=Recording)
    fell_at: float | None = None
    next_frame: float = 0.0

    def __post_init__(self) -> None:
        self.pending = sorted(self.pushes, key=lambda p: p.time)
        self.rec.frame_period = gif_frame_period(self.duration)

    def period(self, sim: SimNode, t: float, dt: float, pub_cmd: Publisher,
               cmd_mpc: np.ndarray, render: bool) -> bool:
        """Record the control period at sim time ``t``; returns whether the run is over."""
        rec = self.rec
        while self.pending and t >= self.pending[0].time - 1e-9:
            push = self.pending.pop(0)
            sim.sim.push(sim.sim.cfg.base_link, push.force, duration=push.duration)
            log.info("push %s N for %.2f s at t = %.2f s", push.force, push.duration, t)
        st = sim.sim.state()
        cmd_next = command_at(self.segments, t + dt)  # heard before the next state's tick
        pub_cmd.publish(_twist(cmd_next))
        rec.t.append(t)
        rec.q.append(st.q)
        rec.v.append(st.v)
        rec.cmd.append(command_at(self.segments, t))
        rec.cmd_mpc.append(np.array(cmd_mpc, dtype=float))
        rec.contact.append(st.foot_contact.copy())
        if render and self.gif and t >= self.next_frame - 1e-9:
            rec.frames.append(sim.sim.render())
            self.next_frame += rec.frame_period
        if self.fell_at is None and fallen(st.q, rec.nominal_height):
            self.fell_at = t
            log.warning("the robot fell at t = %.2f s", t)
        return t >= self.duration - 1e-9 or (
            self.fell_at is not None and t - self.fell_at >= self.stop_after_fall)


#: the simulator parameters a lockstep run may set (``--sim-param``): the delays of a
#: real-time loop, reproduced deterministically (doc/simulator.md, Lockstep protocol)
SIM_LOCKSTEP_PARAMETERS = {"lockstep_latency": float, "lockstep_latency_jitter": float,
                           "lockstep_seed": int, "lockstep_state_offset": float}

# the loop's topics and how many publishers each has in the loop itself
_LOOP_PUBLISHERS = {"joint_trajectory": 1, "joint_states": 1, "odom": 1, "cmd_vel": 1,
                    "/clock": 1}


class SettingError(ValueError):
    """A setting the MPC node (``-p``) or the simulator (``-s``) refused while it was built
    (lockstep: in this process)."""


def _foreign_publishers(node: Node, rec: Recording) -> None:
    """Add to ``rec.foreign_publishers`` (and log once) the loop's topics that have more
    publishers than the loop's own: another node on the run's domain."""
    for topic, own in _LOOP_PUBLISHERS.items():
        n = node.count_publishers(topic)
        note = f"{topic}: {n} publishers, {own} expected"
        if n > own and note not in rec.foreign_publishers:
            rec.foreign_publishers.append(note)
            log.warning("another node publishes on this run's domain (ROS_DOMAIN_ID %s): %s;"
                        " the run is not isolated (use another --domain-id)", rec.domain_id,
                        note)


def _final_isolation_check(node: Node, rec: Recording, since: float) -> None:
    """The isolation check once more at the end of a run, at least ``DISCOVERY_SETTLE`` s
    of wall time after ``node`` was created (``since``, ``time.perf_counter()``): discovery
    takes a while, and a short lockstep run (1.5 sim s in 0.3 s of wall time) ended before
    it found a publisher that was there all along. It waits without spinning: the graph is
    the middleware's, and the loop's nodes stay where the run ended."""
    time.sleep(max(0.0, since + DISCOVERY_SETTLE - time.perf_counter()))
    _foreign_publishers(node, rec)


def _run_lockstep(robot: str, iterations: int | None, loop: _Loop,
                  mpc_parameters: Mapping[str, object] | None, domain_id: int,
                  sim_parameters: Mapping[str, object] | None = None) -> Recording:
    """One process, one executor: the simulator waits for each plan (deterministic)."""
    ctx = rclpy.Context()
    # Ctrl-C: KeyboardInterrupt in this thread (see _run_realtime)
    # args=[]: the process's ROS arguments (a launch file's '-r __node:=closed_loop') would
    # rename every node of the loop alike
    rclpy.init(args=[], context=ctx, domain_id=domain_id,
               signal_handler_options=SignalHandlerOptions.NO)
    rec = loop.rec
    rec.domain_id = domain_id
    try:
        t_build = time.perf_counter()
        try:
            mpc = MpcNode(context=ctx, parameter_overrides=[
                Parameter("robot", value=robot), Parameter("use_sim_time", value=True),
                Parameter("trigger", value="state"),
                *([] if iterations is None else [Parameter("iterations",
                                                            value=int(iterations))]),
                *(Parameter(k, value=v) for k, v in (mpc_parameters or {}).items())])
        except ValueError as exc:  # a -p value mpc_node refuses (an unknown gait, ...)
            raise SettingError(str(exc)) from exc
        rec.build_time = time.perf_counter() - t_build
        dt = mpc.period  # its control period: 1 / control_rate, else the node dt
        try:
            sim = SimNode(context=ctx, parameter_overrides=[
                Parameter("robot", value=robot), Parameter("lockstep", value=True),
                Parameter("control_period", value=dt), Parameter("lockstep_timeout", value=10.0),
                Parameter("realtime_factor", value=1.0),
                *(Parameter(k, value=v) for k, v in (sim_parameters or {}).items())])
        except ValueError as exc:  # a -s value sim_node refuses (delays beyond the period)
            mpc.destroy_node()
            raise SettingError(f"sim_node: {exc}") from exc
        player = Node("command_player", context=ctx)
        t_player = time.perf_counter()
        pub_cmd = player.create_publisher(Twist, "cmd_vel", 10)
        executor = SingleThreadedExecutor(context=ctx)
        for node in (sim, mpc, player):
            executor.add_node(node)
        rec.feet = list(sim.sim.feet) if hasattr(sim.sim, "feet") else []
        st0 = sim.sim.state()
        rec.nominal_height = float(st0.q[2])
        dt_ns = round(dt * 1e9)
        last_rec_ns = -1
        wall0 = time.perf_counter()
        ticks_seen = 0
        check_ns = 0

        def record_ticks() -> bool:
            nonlocal ticks_seen
            if mpc.ticks == ticks_seen:
                return False
            ticks_seen = mpc.ticks
            rec.tick_t.append(mpc.plan.t0)
            rec.tick_time.append(mpc.last_solve_time)
            rec.prepare_time.append(mpc.last_prepare_time)
            rec.tick_iterations.append(mpc.plan.stats.get("iterations", math.nan))
            rec.plan_t.append(mpc.plan.t0)
            rec.plan_age.append(sim.now_ns / 1e9 - mpc.plan.t0)
            return True

        try:
            while True:
                executor.spin_once(timeout_sec=0.05)
                now_ns = sim.now_ns
                record_ticks()
                if now_ns >= check_ns:  # once per sim second
                    check_ns = now_ns + 1_000_000_000
                    _foreign_publishers(player, rec)
                if now_ns - last_rec_ns < dt_ns and last_rec_ns >= 0:
                    continue
                last_rec_ns = now_ns
                if loop.period(sim, now_ns / 1e9, dt, pub_cmd, mpc.mpc.cmd, render=True):
                    break
            # the tick on the last recorded state (the sim waits for its plan: it comes
            # within a few spins; the run's tick count then covers every recorded period)
            deadline = time.perf_counter() + 5.0
            while time.perf_counter() < deadline and not record_ticks():
                executor.spin_once(timeout_sec=0.05)
        finally:  # also for an interrupted run: its figures so far
            rec.wall_time = time.perf_counter() - wall0
            rec.deadline_misses = mpc.deadline_misses
            rec.overruns = mpc.overruns
            rec.prepare_misses = mpc.mpc.prepare_misses
            rec.stale_skips = mpc.stale_skips
        _final_isolation_check(player, rec, t_player)
        executor.shutdown()
        for node in (player, mpc, sim):
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return rec


def control_period(robot: str, mpc_parameters: Mapping[str, object] | None = None) -> float:
    """The MPC node's control period (s): ``1 / control_rate`` when given, else its ``dt``
    (a ``-p dt`` or the config's ``mpc.dt``); SettingError for one that is not > 0. The
    simulator steps and the run records on this grid (it was the config's dt: with ``-p
    dt=0.03`` a third of the periods were reported without a tick, none missing)."""
    given = dict(mpc_parameters or {})
    name = "control_rate" if "control_rate" in given else "dt"
    raw = given.get(name, MpcSettings.from_config(load_robot_config(robot)).dt)
    # a YAML number; a text, a list or a bool is no rate
    value = float(raw) if isinstance(raw, (int, float)) and not isinstance(raw, bool) else (
        math.nan)
    if not (math.isfinite(value) and value > 0.0):
        # the node refuses it too; here first, before dividing by it
        raise SettingError(f"{name} must be a finite number > 0, got {given[name]!r}")
    return 1.0 / value if name == "control_rate" else value


def _process_figures(child: MpcProcess, cpu0: tuple[float, float]) -> dict:
    """The MPC process's pid, domain, memory and CPU seconds since ``cpu0`` (this process's,
    the child's), and this process's CPU and memory: ``Recording.mpc_process``."""
    return {"pid": child.pid, "domain_id": child.domain_id,
            "memory_mb": process_memory_mb(child.pid),
            "cpu_s": process_cpu_seconds(child.pid) - cpu0[1],
            "sim_process_cpu_s": time.process_time() - cpu0[0],
            "sim_process_memory_mb": process_memory_mb(os.getpid())}


def _run_realtime(robot: str, iterations: int | None, loop: _Loop, domain_id: int | None,
                  mpc_parameters: Mapping[str, object] | None,
                  mpc_command: Sequence[str] | None, ready_timeout: float) -> Recording:
    """The MPC in a process of its own (timer trigger), the simulator free at realtime
    factor 1 in this one; the clock starts once the MPC's first plan has arrived."""
    rec = loop.rec
    dt = control_period(robot, mpc_parameters)
    t_start = time.perf_counter()
    with MpcProcess(robot, iterations, domain_id, mpc_parameters, mpc_command) as child:
        rec.domain_id = child.domain_id
        ctx = rclpy.Context()
        # Ctrl-C is Python's KeyboardInterrupt here, raised in this thread (rclpy's handlers
        # would shut the context down from a thread of their own): the cleanup below runs
        rclpy.init(args=[], context=ctx, domain_id=child.domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        try:
            sim = SimNode(context=ctx, parameter_overrides=[
                Parameter("robot", value=robot), Parameter("lockstep", value=False),
                Parameter("control_period", value=dt), Parameter("realtime_factor", value=1.0),
                Parameter("state_rate", value=REALTIME_STATE_RATE)])
            player = Node("command_player", context=ctx)
            t_player = time.perf_counter()
            pub_cmd = player.create_publisher(Twist, "cmd_vel", 10)
            monitor = MpcMonitor(lambda: sim.now_ns, context=ctx)
            executor = SingleThreadedExecutor(context=ctx)
            for node in (player, monitor):  # the simulator joins once the MPC has planned
                executor.add_node(node)
            rec.feet = list(sim.sim.feet)
            rec.nominal_height = float(sim.sim.state().q[2])
            _wait_for_first_plan(executor, sim, monitor, child, pub_cmd, ready_timeout)
            rec.build_time = time.perf_counter() - t_start
            executor.add_node(sim)
            cpu0 = (time.process_time(), process_cpu_seconds(child.pid))
            wall0 = time.perf_counter()
            try:
                rec.wall_time = _realtime_loop(executor, sim, monitor, child, pub_cmd, dt,
                                               loop, lambda: _foreign_publishers(player, rec))
                _final_isolation_check(player, rec, t_player)
                rec.mpc_process = _process_figures(child, cpu0)
                _copy_ticks(monitor.record, rec)
            except KeyboardInterrupt:  # the figures of the run so far (also when the
                # signal came after the loop: in the final check's 2 s, the summary said
                # the MPC had never ticked)
                rec.wall_time = rec.wall_time or time.perf_counter() - wall0
                rec.mpc_process = _process_figures(child, cpu0)  # it was left {} here
                _copy_ticks(monitor.record, rec)
                rec.mpc_process["exit_code"] = child.stop()  # as a whole run's summary has
                rec.mpc_log = child.log_tail(lines=200)
                raise
            executor.shutdown()
            for node in (player, monitor, sim):
                node.destroy_node()
        finally:
            rclpy.try_shutdown(context=ctx)
        try:
            rec.mpc_process["exit_code"] = child.stop()
        finally:  # a signal while it stops: the log all the same
            rec.mpc_log = child.log_tail(lines=200)
    if loop.gif:  # rendered from the recorded states, not in the loop (it would steal time)
        rec.frames = render_replay(robot, rec.t, rec.q, rec.frame_period)
    return rec


def _wait_for_first_plan(executor: SingleThreadedExecutor, sim: SimNode, monitor: MpcMonitor,
                         child: MpcProcess, pub_cmd: Publisher, timeout: float) -> None:
    """Wait until the MPC process is connected (its state and command subscriptions, its
    trajectory publisher), then hold the simulator (one control period per ``HOLD_PERIOD``
    of wall time, so that the MPC's sim-clock timer fires) until its first plan (the
    bootstrap solve) arrives. The profile's first command then reaches the MPC: without the
    wait for ``cmd_vel`` a late discovery on a loaded machine could lose it for good."""
    def spin() -> None:
        executor.spin_once(timeout_sec=0.05)

    wait_until(lambda: sim.peers_ready and pub_cmd.get_subscription_count() > 0, spin, child,
               timeout, "mpc_node's joint_states and cmd_vel subscriptions and "
               "joint_trajectory publisher")
    next_step = 0.0

    def hold() -> None:
        nonlocal next_step
        if time.monotonic() >= next_step:
            sim.step_once()
            next_step = time.monotonic() + HOLD_PERIOD
        spin()

    wait_until(lambda: monitor.plans > 0, hold, child, timeout,
               "first joint_trajectory (the MPC's bootstrap solve)")
    log.info("mpc_node's first plan at t = %.2f s (sim); the clock runs", sim.now_ns / 1e9)


def _realtime_loop(executor: SingleThreadedExecutor, sim: SimNode, monitor: MpcMonitor,
                   child: MpcProcess, pub_cmd: Publisher, dt: float, loop: _Loop,
                   check_isolation: Callable[[], None]) -> float:
    """Spin until the run is over, recording every control period (and calling
    ``check_isolation`` once per sim second); returns the wall time."""
    dt_ns = round(dt * 1e9)
    start_ns = next_ns = check_ns = sim.now_ns
    wall0 = time.perf_counter()
    while True:
        executor.spin_once(timeout_sec=0.05)
        now_ns = sim.now_ns
        if now_ns < next_ns:
            continue
        next_ns = start_ns + ((now_ns - start_ns) // dt_ns + 1) * dt_ns  # the next period
        child.check_alive("during the run")
        if now_ns >= check_ns:
            check_ns = now_ns + 1_000_000_000
            check_isolation()
        if loop.period(sim, now_ns / 1e9, dt, pub_cmd, monitor.record.command, render=False):
            return time.perf_counter() - wall0


def _copy_ticks(heard: TickRecord, rec: Recording) -> None:
    """The MPC process's ticks and plans, as heard through ROS, into the recording."""
    rec.tick_t, rec.tick_time = list(heard.tick_t), list(heard.tick_time)
    rec.prepare_time = list(heard.prepare_time)
    rec.tick_iterations = list(heard.iterations)
    rec.plan_t, rec.plan_age = list(heard.plan_t), list(heard.plan_age)
    rec.deadline_misses = int(heard.counters["deadline_misses"])
    rec.overruns = int(heard.counters["overruns"])
    rec.stale_skips = int(heard.counters["stale_skips"])
    rec.prepare_misses = int(heard.counters["prepare_misses"])


def _twist(cmd: np.ndarray) -> Twist:
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = (float(c) for c in cmd)
    return msg


def _interrupt(*_: object) -> None:
    raise KeyboardInterrupt


def _prog() -> str:
    """The usage's program name: the executable's (``closed_loop``, also under ``ros2 run``)
    when run as one, else the module's."""
    name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return "closed_loop" if name == "closed_loop" else "python -m horizon_mpc.closed_loop"


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: run the closed loop and write summary.json, plots and a GIF into ``--out``.

    Exit code 0; 1 when the robot fell, the MPC process (real-time mode) failed or another
    node published on the run's topics (the log says which); 2 for arguments it cannot run
    with (profile, robot, ``-p``, durations), in one error line before anything starts; 130
    when Ctrl-C or SIGTERM ended the run (the outputs, marked ``interrupted``, cover the run
    so far).
    """
    from horizon_mpc.closed_loop_report import summarise, write_report

    ap = argparse.ArgumentParser(prog=_prog(), description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="go2",
                    help="robot config name or YAML path (default go2)")
    ap.add_argument("--profile", default=DEFAULT_PROFILE,
                    help="command profile: a YAML file, or the name of one in "
                         "config/commands (default: 'default')")
    ap.add_argument("--out", default="out/closed_loop",
                    help="output folder (default out/closed_loop)")
    ap.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep",
                    help="lockstep (default: the simulator waits for each plan) or "
                    "realtime (the MPC node in a process of its own)")
    ap.add_argument("--duration", type=float, default=None,
                    help="sim seconds to run (default: the profile's length)")
    ap.add_argument("--iterations", type=int, default=None,
                    help="ILQR iterations per tick (default: the robot config's mpc.iterations)")
    ap.add_argument("--gif", action=argparse.BooleanOptionalAction, default=True,
                    help="render a GIF (a frame every 50 ms of sim time; at most 400 "
                    "frames, further apart for runs over 20 s)")
    ap.add_argument("--domain-id", type=int, default=None,
                    help="ROS_DOMAIN_ID of the run (default: lockstep a private one from "
                    "the process id; realtime the environment's, else that private one)")
    ap.add_argument("-p", "--mpc-param", action="append", default=[], metavar="NAME=VALUE",
                    help="an mpc_node parameter (YAML value), e.g. -p prepare_ahead=true; "
                    "repeatable")
    ap.add_argument("-s", "--sim-param", action="append", default=[], metavar="NAME=VALUE",
                    help="lockstep only: a simulator delay of a real-time loop, "
                    f"{', '.join(SIM_LOCKSTEP_PARAMETERS)} (sim s; the seed an integer), e.g. "
                    "-s lockstep_latency=0.004; repeatable")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = ap.parse_args(remove_ros_args(["closed_loop", *argv])[1:])  # tolerate --ros-args
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if threading.current_thread() is threading.main_thread():
        # Ctrl-C / SIGINT stops the run and its MPC process, also when this process was
        # started with SIGINT ignored (a background job of a non-interactive shell inherits
        # that, and Python keeps it: the run would go on, deaf to SIGINT)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        # SIGTERM (a supervisor, `timeout`) ends the run as Ctrl-C does: the MPC process is
        # stopped at once and the run so far written (it died with no cleanup, its child
        # orphaned until the parent-death signal reached it)
        signal.signal(signal.SIGTERM, _interrupt)
    # DDS discovery on this host only, for this process and the MPC process alike
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    profile = args.profile or DEFAULT_PROFILE  # an empty --profile (launch default) = default
    try:
        segments, pushes, mpc_parameters = _checked_arguments(args, profile)
        sim_parameters = _sim_parameters(args)
        length = sum(seg.duration for seg in segments)
        segments = with_zero_tail(segments, args.duration)
        if args.duration is not None and args.duration > length + 1e-9:
            log.info("--duration %g s runs %g s past the profile's end: the command is zero "
                     "then (segment %d of the summary)", args.duration,
                     args.duration - length, len(segments) - 1)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        log.error("cannot run: %s", message)
        return 2
    domain_id = run_domain_id(args.mode, args.domain_id)  # resolved here to be told
    log.info("closed loop: %s, %s, profile %s, ROS_DOMAIN_ID %d%s", args.robot, args.mode,
             profile, domain_id, " (this run's own; --domain-id to choose)"
             if args.domain_id is None and args.mode == "lockstep" else "")
    try:
        rec = run(args.robot, segments, args.duration, args.mode, args.gif, args.iterations,
                  pushes=pushes, mpc_parameters=mpc_parameters, domain_id=domain_id,
                  sim_parameters=sim_parameters)
    except KeyboardInterrupt:
        log.error("interrupted before the run started: no outputs written")
        return 130
    except MpcProcessError as exc:
        log.error("%s", exc)
        return 1
    except (ParameterException, SettingError) as exc:  # a -p/-s value a node refuses
        log.error("cannot run: %s", exc)
        return 2
    except (KeyError, FileNotFoundError, ValueError) as exc:
        # a robot config the nodes cannot start with (a foot that is no link, a missing
        # URDF, a posture outside the joint limits): it was a traceback, exit 1
        log.error("cannot run: %s", exc.args[0] if isinstance(exc, KeyError) and exc.args
                  else exc)
        return 2
    written: list[Path] = []
    try:
        summary = summarise(rec, segments, mode=args.mode, robot=args.robot)
        write_report(rec, summary, args.out, written)
    except KeyboardInterrupt:  # after the run: it was a traceback, and no outputs
        log.error("interrupted while writing the outputs to %s: written %s, the rest not",
                  args.out, [p.name for p in written])
        return 130
    age = summary["plan_age_ms"]
    log.info("sim %.2f s in %.1f s wall (real-time factor %.3f); %.1f ticks per sim s, tick "
             "median %.1f ms, plan age median %.1f ms (p95 %.1f); falls: %d",
             summary["sim_time"], summary["wall_time"], summary["real_time_factor"],
             summary["ticks_per_sim_second"], summary["tick_time_ms"]["median"],
             age["median"], age["p95"], summary["falls"]["count"])
    for path in written:
        log.info("wrote %s", path)
    rate = 1.0 / control_period(args.robot, mpc_parameters)
    if summary["ticks_per_sim_second"] < TICK_RATE_KEPT * rate:  # a loaded host, real time
        log.warning("the MPC ticked %.1f times per sim second, %.0f %% of its %.0f Hz control "
                    "rate: this run is no real-time loop at that rate (other jobs on the "
                    "cores?); --mode lockstep does not depend on the host's speed",
                    summary["ticks_per_sim_second"],
                    100 * summary["ticks_per_sim_second"] / rate, rate)
    if rec.interrupted:
        log.error("interrupted: the outputs cover the run until t = %.2f s", rec.t[-1])
        return 130
    if summary["falls"]["count"]:
        log.error("the robot fell (first at t = %.2f s)", summary["falls"]["times"][0])
        return 1
    if summary["foreign_publishers"]:
        log.error("the run was not isolated (%s): its figures may mix in another node's "
                  "messages", "; ".join(summary["foreign_publishers"]))
        return 1
    return 0


#: fraction of the control rate below which a run is said not to have kept it (a 2 s real-time
#: run on a loaded host ticked 11 times per sim second at 50 Hz and said nothing)
TICK_RATE_KEPT = 0.8


def run_domain_id(mode: str, domain_id: int | None = None) -> int:
    """The ``ROS_DOMAIN_ID`` of a run (:func:`run`'s ``domain_id``): the one given, else in
    lockstep a private one from this process id, in real time the environment's or that
    private one."""
    if domain_id is not None:
        return int(domain_id)
    return private_domain_id() if mode == "lockstep" else default_domain_id()


# set by this launcher (the simulator is built for --robot, lockstep needs trigger 'state')
_HARNESS_PARAMETERS = (*MODEL_PARAMETERS, "trigger", "use_sim_time")


def check_mpc_parameter_names(names: Sequence[str], prefix: str = "") -> None:
    """``ValueError`` for a name that is no ``mpc_node`` parameter or one the closed loop
    sets itself (the robot, the mode's trigger and clock)."""
    known = parameter_names()
    for name in names:
        if name in _HARNESS_PARAMETERS:
            raise ValueError(f"{prefix}{name}: set by the closed loop itself (robot, mode)")
        if name not in known:
            raise ValueError(f"{prefix}{name}: mpc_node has no such parameter; it has "
                             f"{', '.join(n for n in known if n not in _HARNESS_PARAMETERS)}")


def _sim_parameters(args: argparse.Namespace) -> dict[str, object]:
    """The ``--sim-param NAME=VALUE`` settings, typed, or ValueError naming the bad one (the
    simulator checks that the delays fit in the control period)."""
    out: dict[str, object] = {}
    for item in args.sim_param:
        name, sep, value = item.partition("=")
        kind = SIM_LOCKSTEP_PARAMETERS.get(name.strip())
        if not sep or kind is None:
            raise ValueError(f"--sim-param {item!r}: expected NAME=VALUE with NAME one of "
                             f"{list(SIM_LOCKSTEP_PARAMETERS)}")
        try:
            number = kind(value)
        except ValueError:
            raise ValueError(f"--sim-param {item!r}: {value!r} is not a {kind.__name__}") \
                from None
        if kind is float and not (math.isfinite(number) and number >= 0):
            raise ValueError(f"--sim-param {item!r}: must be finite and >= 0")
        if kind is int and not 0 <= number < 2**63:  # a ROS integer parameter (int64)
            raise ValueError(f"--sim-param {item!r}: must be in [0, 2^63)")
        out[name.strip()] = number
    if out and args.mode != "lockstep":
        raise ValueError("--sim-param: lockstep mode only (real time has its own delays)")
    return out


def _checked_arguments(args: argparse.Namespace, profile: str) -> tuple[list, list, dict]:
    """Profile segments and pushes, and the ``-p`` parameters, all checked before a run.

    Raises:
        ValueError / FileNotFoundError / KeyError: what cannot run, in one message.
    """
    load_robot_config(args.robot)  # an unknown robot, named with the known ones
    out = Path(args.out)
    if out.exists() and not out.is_dir():  # found after the run, the run was lost
        raise ValueError(f"--out {out} exists and is not a folder")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ValueError(f"--duration must be a finite number of seconds > 0, got "
                         f"{args.duration}")
    if args.iterations is not None and args.iterations < 1:
        raise ValueError(f"--iterations must be >= 1, got {args.iterations}")
    if args.domain_id is not None and not 0 <= args.domain_id <= MAX_DOMAIN_ID:
        raise ValueError(f"--domain-id must be in 0..{MAX_DOMAIN_ID} (ROS 2 on Linux), got "
                         f"{args.domain_id}")
    run_domain_id(args.mode, args.domain_id)  # the environment's, checked the same way
    segments = load_profile(profile)
    pushes = load_pushes(profile)
    end = args.duration if args.duration is not None else sum(s.duration for s in segments)
    late = [p.time for p in pushes if p.time >= end]
    if late:
        raise ValueError(f"push time(s) {late} s at or after the end of the run ({end:g} s)")
    params = {}
    for item in args.mpc_param:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--mpc-param needs NAME=VALUE, got {item!r}")
        check_mpc_parameter_names([name], "-p ")
        try:
            params[name] = parse_yaml(value)
        except (yaml.YAMLError, ValueError) as exc:  # (ValueError: a date 2001-13-45)
            raise ValueError(f"-p {name}: {value!r} is not a YAML value ({exc})") from None
    try:  # last: a refused command line leaves no folder behind
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ValueError(f"--out {out}: cannot make that folder ({exc.strerror})") from None
    return segments, pushes, params


if __name__ == "__main__":
    raise SystemExit(main())
