"""``python -m horizon_mpc.closed_loop``: simulator node + MPC node, one process, ROS in the loop.

Both nodes and a command player share one rclpy context and one single-threaded executor.
In ``lockstep`` mode the loop is paced by the messages themselves: the simulator publishes a
state, the MPC node (``trigger: state``) answers with a trajectory stamped like that state,
the simulator advances one control period and publishes the next state. ``realtime`` mode
runs the simulator free at realtime factor 1 and the MPC on its timer (sim clock). See
``doc/closed_loop.md`` for the outputs (summary.json, plots, GIF).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rclpy
import yaml
from geometry_msgs.msg import Twist
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from horizon_mpc.nodes.mpc_node import MpcNode
from horizon_mpc.nodes.sim_node import SimNode

__all__ = ["Push", "Recording", "Segment", "load_profile", "load_pushes", "main", "run"]

log = logging.getLogger(__name__)

DEFAULT_PROFILE = Path(__file__).resolve().parent.parent / "config" / "commands" / "default.yaml"


@dataclass
class Segment:
    """A constant command ``(vx, vy, wz)`` (base frame) held for ``duration`` s."""

    duration: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0


@dataclass
class Push:
    """A world-frame ``force`` (N) on the base for ``duration`` s from sim time ``time``."""

    time: float
    force: tuple[float, float, float]
    duration: float = 0.1


def load_pushes(path: str | Path) -> list[Push]:
    """The optional ``pushes:`` list of a profile YAML (``{time, force: [fx, fy, fz],
    duration}``); empty when the profile has none."""
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    items = data.get("pushes", []) if isinstance(data, dict) else []
    pushes = []
    for i, item in enumerate(items or []):
        try:
            force = tuple(float(f) for f in item["force"])
            push = Push(float(item["time"]), force, float(item.get("duration", 0.1)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: push {i} needs time, force [fx, fy, fz] and an optional "
                             f"duration ({exc})") from None
        if len(force) != 3 or not push.duration > 0 or not all(map(math.isfinite, force)):
            raise ValueError(f"{path}: push {i}: force must be 3 finite numbers and the "
                             "duration positive")
        pushes.append(push)
    return pushes


def load_profile(path: str | Path) -> list[Segment]:
    """Segments of a command profile YAML (a list, or a mapping with ``segments:``)."""
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    items = data.get("segments") if isinstance(data, dict) else data
    if not isinstance(items, list) or not items:
        raise ValueError(f"{path}: expected a list of segments {{duration, vx, vy, wz}}")
    segs = []
    for i, item in enumerate(items):
        unknown = set(item) - {"duration", "vx", "vy", "wz"}
        if unknown or "duration" not in item:
            raise ValueError(f"{path}: segment {i} needs 'duration' and only vx/vy/wz, got "
                             f"{sorted(item)}")
        seg = Segment(**{k: float(v) for k, v in item.items()})
        if not seg.duration > 0:
            raise ValueError(f"{path}: segment {i} has non-positive duration {seg.duration}")
        segs.append(seg)
    return segs


def command_at(segments: Sequence[Segment], t: float) -> np.ndarray:
    """The profile's ``(vx, vy, wz)`` at time ``t`` (zero after the last segment)."""
    end = 0.0
    for seg in segments:
        end += seg.duration
        if t < end - 1e-9:
            return np.array([seg.vx, seg.vy, seg.wz])
    return np.zeros(3)


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
    tick_iterations: list[float] = field(default_factory=list)
    frames: list[np.ndarray] = field(default_factory=list)
    feet: list[str] = field(default_factory=list)
    wall_time: float = 0.0
    deadline_misses: int = 0
    nominal_height: float = math.nan
    build_time: float = math.nan

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-period lists as arrays (rows = time)."""
        names = ("t", "q", "v", "cmd", "cmd_mpc", "contact", "tick_t", "tick_time",
                 "tick_iterations")
        return {n: np.asarray(getattr(self, n)) for n in names}


def run(robot: str = "go2", segments: Sequence[Segment] | None = None,
        duration: float | None = None, mode: str = "lockstep", gif: bool = True,
        iterations: int = 1, stop_after_fall: float = 1.0,
        pushes: Sequence[Push] = ()) -> Recording:
    """Run the closed loop; returns the recording (see :func:`summarise` for the metrics).

    ``pushes`` are applied to the simulated base (ground truth, not through ROS).
    """
    from horizon_mpc.closed_loop_report import FRAME_PERIOD, fallen

    segments = list(segments or load_profile(DEFAULT_PROFILE))
    if duration is None:
        duration = sum(s.duration for s in segments)
    if mode not in ("lockstep", "realtime"):
        raise ValueError(f"mode must be 'lockstep' or 'realtime', got {mode!r}")
    lockstep = mode == "lockstep"
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    rec = Recording()
    try:
        t_build = time.perf_counter()
        mpc = MpcNode(context=ctx, parameter_overrides=[
            Parameter("robot", value=robot), Parameter("use_sim_time", value=True),
            Parameter("trigger", value="state" if lockstep else "timer"),
            Parameter("iterations", value=int(iterations))])
        rec.build_time = time.perf_counter() - t_build
        dt = mpc.mpc.settings.dt
        sim = SimNode(context=ctx, parameter_overrides=[
            Parameter("robot", value=robot), Parameter("lockstep", value=lockstep),
            Parameter("control_period", value=dt), Parameter("lockstep_timeout", value=10.0),
            Parameter("realtime_factor", value=1.0)])
        player = Node("command_player", context=ctx)
        pub_cmd = player.create_publisher(Twist, "cmd_vel", 10)
        executor = SingleThreadedExecutor(context=ctx)
        for node in (sim, mpc, player):
            executor.add_node(node)
        rec.feet = list(sim.sim.feet) if hasattr(sim.sim, "feet") else []
        st0 = sim.sim.state()
        rec.nominal_height = float(st0.q[2])
        dt_ns = round(dt * 1e9)
        last_rec_ns, next_frame, fell_at = -1, 0.0, None
        wall0 = time.perf_counter()
        ticks_seen = 0
        pending = sorted(pushes, key=lambda p: p.time)
        while True:
            executor.spin_once(timeout_sec=0.05)
            now_ns = sim.now_ns
            if mpc.ticks > ticks_seen:
                ticks_seen = mpc.ticks
                rec.tick_t.append(mpc.plan.t0)
                rec.tick_time.append(mpc.last_solve_time)
                rec.tick_iterations.append(mpc.plan.stats.get("iterations", math.nan))
            if now_ns - last_rec_ns < dt_ns and last_rec_ns >= 0:
                continue
            last_rec_ns = now_ns
            t = now_ns / 1e9
            while pending and t >= pending[0].time - 1e-9:
                push = pending.pop(0)
                sim.sim.push(sim.sim.cfg.base_link, push.force, duration=push.duration)
                log.info("push %s N for %.2f s at t = %.2f s", push.force, push.duration, t)
            st = sim.sim.state()
            cmd_next = command_at(segments, t + dt)  # heard before the next state's tick
            pub_cmd.publish(_twist(cmd_next))
            rec.t.append(t)
            rec.q.append(st.q)
            rec.v.append(st.v)
            rec.cmd.append(command_at(segments, t))
            rec.cmd_mpc.append(mpc.mpc.cmd.copy())
            rec.contact.append(st.foot_contact.copy())
            if gif and t >= next_frame - 1e-9:
                rec.frames.append(sim.sim.render())
                next_frame += FRAME_PERIOD
            if fell_at is None and fallen(st.q, rec.nominal_height):
                fell_at = t
                log.warning("the robot fell at t = %.2f s", t)
            if t >= duration - 1e-9 or (fell_at is not None and t - fell_at >= stop_after_fall):
                break
        rec.wall_time = time.perf_counter() - wall0
        rec.deadline_misses = mpc.deadline_misses
        executor.shutdown()
        for node in (player, mpc, sim):
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return rec


def _twist(cmd: np.ndarray) -> Twist:
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = (float(c) for c in cmd)
    return msg


def main(argv: Sequence[str] | None = None) -> int:
    """CLI: run the closed loop and write summary.json, plots and a GIF into ``--out``."""
    from horizon_mpc.closed_loop_report import summarise, write_report

    ap = argparse.ArgumentParser(prog="python -m horizon_mpc.closed_loop",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="go2", help="robot config name (default go2)")
    ap.add_argument("--profile", default=str(DEFAULT_PROFILE),
                    help="command profile YAML (default config/commands/default.yaml)")
    ap.add_argument("--out", default="out/closed_loop", help="output folder")
    ap.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep")
    ap.add_argument("--duration", type=float, default=None,
                    help="sim seconds to run (default: the profile's length)")
    ap.add_argument("--iterations", type=int, default=1, help="ILQR iterations per tick")
    ap.add_argument("--gif", action=argparse.BooleanOptionalAction, default=True,
                    help="render a GIF (every 50 ms of sim time)")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = ap.parse_args(remove_ros_args(["closed_loop", *argv])[1:])  # tolerate --ros-args
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    profile = args.profile or DEFAULT_PROFILE  # an empty --profile (launch default) = default
    segments = load_profile(profile)
    pushes = load_pushes(profile)
    log.info("closed loop: %s, %s, profile %s", args.robot, args.mode, profile)
    rec = run(args.robot, segments, args.duration, args.mode, args.gif, args.iterations,
              pushes=pushes)
    summary = summarise(rec, segments, mode=args.mode, robot=args.robot)
    written = write_report(rec, summary, args.out)
    log.info("sim %.2f s in %.1f s wall (real-time factor %.3f); tick median %.1f ms; falls: %d",
             summary["sim_time"], summary["wall_time"], summary["real_time_factor"],
             summary["tick_time_ms"]["median"], summary["falls"]["count"])
    for path in written:
        log.info("wrote %s", path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
