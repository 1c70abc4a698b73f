"""Benchmark of the MPC node in the closed loop (issues 8 and 9: tick times, tracking, RSS).

For each robot, :func:`horizon_mpc.closed_loop.run` drives ``sim_node`` + ``mpc_node``
(everything through the ROS topics) in REAL-TIME mode: ``mpc_node`` in a process of its own
(timer trigger, 50 Hz on the sim clock), the simulator free at realtime factor 1 with the
command player and the recorder in the run's process, so the two use the machine's two
cores; on a short profile: stand 1 s, forward ``FORWARD[robot]`` m/s 4 s (0.3 for go2, 0.2
for solo12 and anymal_c), lateral 0.2 m/s 2 s, yaw 0.5 rad/s 2 s, stop 1 s; ``--repeats N``
runs each robot N times (falls are counted per robot out of N). go2 also runs the same
profile in LOCKSTEP mode (one process; the sim waits for each answer): the tick time without
real-time pressure, the deterministic reference.

Recorded per run (``<out>/<run>/summary.json``, the closed-loop report's plots, and
``tick_breakdown.png``):

* tick time distribution (median, p95, p99, max, mean; wall and thread CPU time) of
  ``MpcNode.tick`` (the bootstrap tick, a converging standing solve, is left out and given
  apart), deadline misses (ticks longer than the period: count and %; the node's own count,
  which times ``WalkingMpc.update`` only; and in real time the control periods that got no
  tick at all), real-time factor (sim s / wall s), achieved control rate (ticks per sim s);
* the per-tick breakdown, from wrappers monkeypatched around the node's methods for the run
  (nothing in ``horizon_mpc/`` changes; in real time they are installed in the MPC process,
  which this script then runs as ``--mpc-probe FILE``, and come back in FILE): state
  handling (message conversion in the joint_states/odom callbacks since the previous tick +
  the tick's own state assembly) / shift of the warm start (``solver.shift``) / references,
  command ramp and contact schedule (the rest of ``WalkingMpc.update``) / ILQR
  (``solver.solve``, split by ``solver.timings``: quadratise / backward / rollout /
  line_search / other) / plan extraction (inverse dynamics of the plan,
  ``WalkingMpc._plan``) / publish (trajectory, predicted path, diagnostics);
* where the wall time went per sim second (simulator callbacks, MPC ticks, MPC input
  callbacks, the rest; in real time, the two processes' CPU time too);
* plan age: the simulator's time when a plan arrives minus the stamp of the state it was
  planned from (``closed_loop``'s recorder; 0 in lockstep), and the node's ``state_age``;
* tracking RMSE and mean velocity per segment (``closed_loop_report.summarise``: 1 s of
  settling), pooled RMSE per axis, falls;
* memory: peak and current RSS of the MPC node's process (real time: the ``mpc_node``
  process, from ``/proc/<pid>/status`` at the end of the run; lockstep: the one process of
  sim, MPC and rclpy) and the RSS the MPC node's construction added;
* load average (``os.getloadavg``) before and after, and whether a pytest run was going.

By default each run is a subprocess of its own (``--no-isolate``: all in this process), so
the peak RSS is that run's. The GIF is rendered AFTER a real-time run by replaying the
recorded states into a fresh simulator (rendering inside the loop would steal time from the
controller it measures); ``--no-gif`` skips it. The lockstep reference writes no GIF.

Aggregate: ``<out>.json`` (default ``bench/results/closed_loop.json``: every run's figures,
the targets of the issues and whether each run meets them), ``<out>.png`` (stacked mean
breakdown per run with the tick percentiles), and a table on stdout. go2's tick is compared
with Crocoddyl's per-iteration time on the same robot: ``--peer`` runs the peer
(``bench/bench_ilqr.py``'s, with ``.venv-peer``) before every run and after the last, and
each run's ratio is taken against the two rounds around it (this machine's speed drifts by
tens of percent over minutes: the peer measured 8-14 ms per iteration in one sitting), with
the ratio against every round of the run beside it; otherwise the figure is read from
``bench/results/ilqr.json`` and labelled as that file's run.

Diagnostics: ``--realtime-factor F`` and ``--state-rate HZ`` override sim_node's parameters
in the real-time runs (e.g. a slower simulator gives the MPC more wall time per period).

Run: ``python bench/bench_closed_loop.py [--robots go2 solo12 anymal_c] [--duration S]
[--repeats N] [--out bench/results/closed_loop] [--mode realtime|lockstep] [--no-gif]
[--peer]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):  # before numpy: single thread
    os.environ.setdefault(_var, "1")
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import random  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable, Iterator, Sequence  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT, ROOT / "bench"):  # source checkout without an install; bench_ilqr's helpers
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

import bench_ilqr  # noqa: E402
from cli_checks import (  # noqa: E402
    output_folder,
    output_stem,
    positive_float,
    positive_int,
    refuse_duplicates,
    sibling,
)

from horizon_mpc.closed_loop import Segment, run  # noqa: E402
from horizon_mpc.closed_loop_report import render_replay, summarise, write_report  # noqa: E402
from horizon_mpc.config import load_robot_config  # noqa: E402
from horizon_mpc.mpc.controller import WalkingMpc  # noqa: E402
from horizon_mpc.nodes import mpc_node as mpc_node_module  # noqa: E402
from horizon_mpc.nodes.mpc_node import MpcNode  # noqa: E402
from horizon_mpc.nodes.mpc_parameters import DIAGNOSTICS_RATE  # noqa: E402
from horizon_mpc.nodes.sim_node import SimNode  # noqa: E402

ROBOTS = ("go2", "solo12", "anymal_c")
FORWARD = {"go2": 0.3, "solo12": 0.2, "anymal_c": 0.2}  # m/s, the forward segment's command
RESULTS = ROOT / "bench" / "results"
DEFAULT_OUT = RESULTS / "closed_loop"
ILQR_JSON = RESULTS / "ilqr.json"
REFERENCE_ROBOT = "go2"  # also run in lockstep mode (the deterministic reference)
PEER_ROBOT = "go2"  # the robot of Crocoddyl's trot in bench/peer_crocoddyl.py
TIMING_KEYS = ("quadratise", "backward", "rollout", "line_search")
# per-tick phases (ms), in the order they happen; "ilqr" is split further by solver.timings
PHASES = ("state", "shift", "references", "ilqr", "plan", "publish")
ILQR_PARTS = (*TIMING_KEYS, "ilqr_other")
# finer splits: of "references" (node-0 bounds and warm start; references and contact
# schedule into the problem; the rest: command ramp, pose reference, gait scheduler) and of
# "publish" (building the three messages; the rest: rclpy's publish calls)
SUB_PARTS = ("set_state", "set_references", "references_other", "trajectory_msg", "path_msg",
             "diagnostics", "publish_other")
# the issues' targets (issue 8: the node; issue 9: the closed loop)
TARGETS = {
    "median_tick_over_crocoddyl_iteration": 1 / 3,  # about 4 ms here
    "p99_over_median": 2.0,
    "rss_mb": 800.0,
    "tracking_rmse": 0.05,  # m/s and rad/s
    "real_time_factor": 1.0,
    "control_rate_hz": 50.0,
    "deadline_miss_percent": 1.0,
}
# real-time factor and control rate: met within 1 % (the run's wall clock includes the
# bootstrap solve, and the first/last control periods are cut by the run's ends)
RATE_TOLERANCE = 0.01


def profile(robot: str) -> list[Segment]:
    """The benchmark's command profile (10 s): stand, forward, lateral, yaw, stop."""
    return [Segment(1.0), Segment(4.0, vx=FORWARD.get(robot, 0.2)), Segment(2.0, vy=0.2),
            Segment(2.0, wz=0.5), Segment(1.0)]


# ---------------------------------------------------------------------- instrumentation
class Probe:
    """Wrappers timing the closed loop's pieces for one run (installed by :meth:`installed`).

    ``rows``: one dict per tick that published a plan from ``WalkingMpc.update`` (ms, plus
    the tick's sim time ``t``); ``bootstrap_ms``: the first tick (``WalkingMpc.start``);
    ``wall``: seconds of wall time spent in each kind of callback; ``rss_build``: RSS (MB)
    before and after the MPC node's construction.
    """

    def __init__(self, sim_parameters: dict | None = None) -> None:
        self.sim_parameters = dict(sim_parameters or {})  # SimNode parameter overrides
        self.rows: list[dict[str, float]] = []
        self.bootstrap_ms = math.nan
        self.wall = {"sim": 0.0, "mpc_tick": 0.0, "mpc_inputs": 0.0}
        self.rss_build: dict[str, float] = {}
        self.period = math.nan  # s, the node's control period (1 / control_rate)
        self.sim_node: SimNode | None = None
        self.messages = {"joint_states": 0, "odom": 0}
        self._conv = 0.0  # s of message conversion since the last tick
        self._tick_wall = 0.0  # s of tick time, for callbacks that tick inside (lockstep)
        self._cur: dict | None = None

    def export(self) -> dict:
        """The MPC-side figures, JSON-ready (written by the MPC process of a real-time run)."""
        return {"rows": self.rows, "bootstrap_ms": self.bootstrap_ms, "period": self.period,
                "wall": {k: self.wall[k] for k in ("mpc_tick", "mpc_inputs")},
                "rss_build": self.rss_build, "messages": self.messages}

    def absorb(self, data: dict) -> None:
        """Take the MPC-side figures :meth:`export` wrote in the MPC process."""
        self.rows = list(data["rows"])
        self.bootstrap_ms, self.period = data["bootstrap_ms"], data["period"]
        self.wall.update(data["wall"])
        self.rss_build, self.messages = dict(data["rss_build"]), dict(data["messages"])

    @contextmanager
    def installed(self) -> Iterator[None]:
        """Patch the node classes and the mpc_node module for the duration of the block."""
        patches = [
            (MpcNode, "__init__", self._wrap_mpc_init),
            (MpcNode, "tick", self._wrap_tick),
            (MpcNode, "_on_joint_state", self._wrap_input),
            (MpcNode, "_on_odom", self._wrap_input),
            (MpcNode, "_on_cmd_vel", self._wrap_input),
            (mpc_node_module, "joints_from_joint_state", self._wrap_conversion("joint_states")),
            (mpc_node_module, "base_from_odometry", self._wrap_conversion("odom")),
            (WalkingMpc, "update", self._wrap_update),
            (WalkingMpc, "prepare", self._wrap_section("prepare")),
            (WalkingMpc, "_plan", self._wrap_section("plan")),
            (WalkingMpc, "_set_state", self._wrap_section("set_state")),
            (WalkingMpc, "_set_references", self._wrap_section("set_references")),
            (MpcNode, "trajectory_msg", self._wrap_section("trajectory_msg")),
            (MpcNode, "path_msg", self._wrap_section("path_msg")),
            (MpcNode, "_publish_diagnostics", self._wrap_section("diagnostics")),
            (SimNode, "__init__", self._wrap_sim_init),
            (SimNode, "_on_free_timer", self._wrap_sim),
            (SimNode, "_on_lockstep_timer", self._wrap_sim),
            (SimNode, "_on_trajectory", self._wrap_sim),
        ]
        saved = [(obj, name, obj.__dict__[name]) for obj, name, _ in patches]
        try:
            for obj, name, wrap in patches:
                setattr(obj, name, wrap(obj.__dict__[name]))
            yield self
        finally:
            for obj, name, orig in saved:
                setattr(obj, name, orig)

    # each _wrap_* takes the original function and returns its replacement
    def _wrap_mpc_init(self, orig: Callable) -> Callable:
        probe = self

        def __init__(node, *args, **kwargs):  # noqa: N807 - replaces MpcNode.__init__
            probe.rss_build["before_mb"] = rss_mb()["current"]
            orig(node, *args, **kwargs)
            probe.rss_build["after_mb"] = rss_mb()["current"]
            probe.period = node.period
            probe._instrument_solver(node.mpc.solver)
        return __init__

    def _wrap_sim_init(self, orig: Callable) -> Callable:
        """Override SimNode parameters the closed loop sets (diagnostics: realtime_factor,
        state_rate)."""
        probe = self

        def __init__(node, *args, parameter_overrides=None, **kwargs):  # noqa: N807
            from rclpy.parameter import Parameter

            params = [p for p in (parameter_overrides or [])
                      if p.name not in probe.sim_parameters]
            params += [Parameter(k, value=v) for k, v in probe.sim_parameters.items()]
            orig(node, *args, parameter_overrides=params, **kwargs)
            probe.sim_node = node
        return __init__

    def _instrument_solver(self, solver: object) -> None:
        """Instance-level wrappers of ``solve``, the split iteration (``prepare``,
        ``feedback``) and ``shift`` (the solver is built by the node)."""
        shift = solver.shift
        probe = self

        def timed(fn, counts_iterations: bool):
            def wrapper(*args, **kwargs):
                # solver.timings: a new dict per solve()/prepare(), feedback() adds to it
                before_obj = getattr(solver, "timings", None)
                before = dict(before_obj or {})
                t0 = time.perf_counter()
                out = fn(*args, **kwargs)
                dt = time.perf_counter() - t0
                if probe._cur is not None:
                    probe._cur["ilqr"] += dt * 1e3
                    timings = getattr(solver, "timings", {}) or {}
                    base = before if timings is before_obj else {}
                    for key in TIMING_KEYS:
                        probe._cur[key] += (timings.get(key, 0.0) - base.get(key, 0.0)) * 1e3
                    if counts_iterations:
                        probe._cur["solves"] += 1
                        probe._cur["iterations"] += getattr(solver.stats, "iterations", 0) or 0
                return out
            return wrapper

        # an iteration split in prepare() + feedback() counts once, with its feedback
        solver.solve = timed(solver.solve, True)
        if hasattr(solver, "feedback"):
            solver.feedback = timed(solver.feedback, True)
            solver.prepare = timed(solver.prepare, False)

        def timed_shift(*args, **kwargs):
            t0 = time.perf_counter()
            out = shift(*args, **kwargs)
            if probe._cur is not None:
                probe._cur["shift"] += (time.perf_counter() - t0) * 1e3
                probe._cur["shifts"] += 1
            return out

        solver.shift = timed_shift

    def _wrap_tick(self, orig: Callable) -> Callable:
        probe = self

        def tick(node):
            t0, c0 = time.perf_counter(), time.thread_time()
            sim_now = probe.sim_node.now_ns / 1e9 if probe.sim_node is not None else math.nan
            cur = probe._cur = dict.fromkeys(
                ("shift", "ilqr", *TIMING_KEYS, "plan", "shifts", "solves", "iterations",
                 "set_state", "set_references", "trajectory_msg", "path_msg", "diagnostics",
                 "prepare"),
                0.0)
            cur["update_start"] = cur["update_end"] = None
            try:
                published = orig(node)
            finally:
                t1 = time.perf_counter()
                probe._cur = None
                probe._tick_wall += t1 - t0
                probe.wall["mpc_tick"] += t1 - t0
            if published and cur["update_start"] is None:  # the bootstrap (WalkingMpc.start)
                probe.bootstrap_ms = (t1 - t0) * 1e3
            elif published:
                # with prepare_ahead the tick also prepares the next one after publishing:
                # WalkingMpc.prepare counts with update (its shift, ILQR and references)
                update = (cur["update_end"] - cur["update_start"]) * 1e3 + cur["prepare"]
                references = update - cur["shift"] - cur["ilqr"] - cur["plan"]
                publish = (t1 - cur["update_end"]) * 1e3 - cur["prepare"]
                row = {
                    "t": node.plan.t0,
                    "tick": (t1 - t0) * 1e3,
                    "tick_cpu": (time.thread_time() - c0) * 1e3,
                    "state": (cur["update_start"] - t0) * 1e3 + probe._conv * 1e3,
                    "state_in_tick": (cur["update_start"] - t0) * 1e3,
                    "update": update,
                    "shift": cur["shift"],
                    "references": references,
                    "ilqr": cur["ilqr"],
                    **{k: cur[k] for k in TIMING_KEYS},
                    "ilqr_other": cur["ilqr"] - sum(cur[k] for k in TIMING_KEYS),
                    "plan": cur["plan"],
                    "publish": publish,
                    "set_state": cur["set_state"],
                    "set_references": cur["set_references"],
                    "references_other": references - cur["set_state"] - cur["set_references"],
                    "trajectory_msg": cur["trajectory_msg"],
                    "path_msg": cur["path_msg"],
                    "diagnostics": cur["diagnostics"],
                    "publish_other": publish - cur["trajectory_msg"] - cur["path_msg"]
                    - cur["diagnostics"],
                    "shifts": cur["shifts"],
                    "iterations": cur["iterations"],
                    "state_age": node.last_state_age * 1e3,
                    "state_lag": (sim_now - node.plan.t0) * 1e3,
                }
                probe.rows.append(row)
                probe._conv = 0.0
            return published
        return tick

    def _wrap_update(self, orig: Callable) -> Callable:
        probe = self

        def update(mpc, *args, **kwargs):
            cur = probe._cur
            if cur is not None:
                cur["update_start"] = time.perf_counter()
            try:
                return orig(mpc, *args, **kwargs)
            finally:
                if cur is not None:
                    cur["update_end"] = time.perf_counter()
        return update

    def _wrap_section(self, key: str) -> Callable:
        probe = self

        def wrap(orig: Callable) -> Callable:
            def section(*args, **kwargs):
                t0 = time.perf_counter()
                try:
                    return orig(*args, **kwargs)
                finally:
                    if probe._cur is not None:
                        probe._cur[key] += (time.perf_counter() - t0) * 1e3
            return section
        return wrap

    def _wrap_conversion(self, topic: str) -> Callable:
        probe = self

        def wrap(orig: Callable) -> Callable:
            def conversion(*args, **kwargs):
                t0 = time.perf_counter()
                try:
                    return orig(*args, **kwargs)
                finally:
                    probe._conv += time.perf_counter() - t0
                    probe.messages[topic] += 1
            return conversion
        return wrap

    def _wrap_input(self, orig: Callable) -> Callable:
        probe = self

        def callback(node, msg):
            t0, ticks0 = time.perf_counter(), probe._tick_wall
            try:
                return orig(node, msg)
            finally:  # a lockstep tick runs inside the odom callback: not input handling
                probe.wall["mpc_inputs"] += time.perf_counter() - t0 - (probe._tick_wall - ticks0)
        return callback

    def _wrap_sim(self, orig: Callable) -> Callable:
        probe = self

        def callback(node, *args):
            t0 = time.perf_counter()
            try:
                return orig(node, *args)
            finally:
                probe.wall["sim"] += time.perf_counter() - t0
        return callback


# ---------------------------------------------------------------------- measurements
def rss_mb() -> dict[str, float]:
    """Current and peak resident set size of this process (MB), from /proc (ru_maxrss else)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux
    out = {"current": math.nan, "peak": peak, "ru_maxrss": peak}
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                out["current" if key == "VmRSS" else "peak"] = float(value.split()[0]) / 1024.0
    except OSError:
        pass
    return out


def machine_load() -> dict:
    """Load average and whether a pytest run shares the machine (``pgrep -f pytest``)."""
    try:
        proc = subprocess.run(["pgrep", "-f", "pytest"], capture_output=True, text=True,
                              timeout=10, check=False)
        pids = [int(p) for p in proc.stdout.split() if int(p) != os.getpid()]
    except (OSError, subprocess.TimeoutExpired, ValueError):
        pids = None
    if pids is not None:  # our own test run (test_bench_closed_loop) does not count
        pids = [p for p in pids if p not in _ancestors()]
    return {"loadavg": [round(x, 2) for x in os.getloadavg()],
            "pytest_running": None if pids is None else bool(pids)}


def _ancestors() -> set[int]:
    pids, pid = set(), os.getpid()
    while pid > 1:
        pids.add(pid)
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            pid = int(stat.rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            break
    return pids


def distribution(x: Sequence[float]) -> dict[str, float]:
    """median, p95, p99, max, mean, min of the finite values of ``x`` (NaN when none)."""
    a = np.asarray(x, dtype=float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return dict.fromkeys(("median", "p95", "p99", "max", "mean", "min"), math.nan)
    return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
            "p99": float(np.percentile(a, 99)), "max": float(a.max()),
            "mean": float(a.mean()), "min": float(a.min())}


def tick_summary(probe: Probe, sim_time: float, node_misses: int,
                 fall_time: float | None = None, realtime_factor: float = 1.0) -> dict:
    """Tick time distribution, breakdown and deadline misses of a run (ms).

    A deadline miss: a tick longer than the control period in wall time (the period divided
    by ``realtime_factor`` when the simulator runs slower than real time: diagnostics).

    ``fall_time``: the first fall's onset; ``tick_ms_before_fall`` then leaves out the ticks
    of the fallen robot (the run goes on for 1 s after a fall).
    """
    rows, period = probe.rows, probe.period
    n = len(rows)
    col = {k: [r[k] for r in rows] for k in (rows[0] if rows else ())}
    breakdown = {k: float(np.mean(col[k])) if n else math.nan
                 for k in (*PHASES, *ILQR_PARTS, *SUB_PARTS)}
    deadline_ms = period * 1e3 / realtime_factor
    misses = sum(r["tick"] > deadline_ms for r in rows)
    expected = sim_time / period  # control periods in the run (ticks if none were skipped)
    t = np.asarray(col.get("t", []))
    gaps = np.diff(t) if t.size > 1 else np.zeros(0)
    return {
        "n": n,
        "period_ms": period * 1e3,
        "deadline_ms": deadline_ms,
        "tick_ms": distribution(col.get("tick", [])),
        "tick_ms_before_fall": distribution([r["tick"] for r in rows if fall_time is None
                                             or r["t"] < fall_time]),
        "tick_cpu_ms": distribution(col.get("tick_cpu", [])),
        "update_ms": distribution(col.get("update", [])),
        "ilqr_ms": distribution(col.get("ilqr", [])),
        "bootstrap_ms": probe.bootstrap_ms,
        "p99_over_median": (distribution(col["tick"])["p99"] / distribution(col["tick"])[
            "median"]) if n else math.nan,
        "breakdown_ms_mean": breakdown,
        "breakdown_ms_median": {k: float(np.median(col[k])) if n else math.nan
                                for k in (*PHASES, *ILQR_PARTS, *SUB_PARTS)},
        "state_in_tick_ms_mean": float(np.mean(col["state_in_tick"])) if n else math.nan,
        "iterations_per_tick": float(np.mean(col["iterations"])) if n else math.nan,
        "shifts_per_tick": float(np.mean(col["shifts"])) if n else math.nan,
        "state_age_ms": distribution(col.get("state_age", [])),
        "state_lag_ms": distribution(col.get("state_lag", [])),
        "plan_age_ms": distribution(col.get("plan_age", [])),
        "state_note": "state_age: the node's own figure (its clock, from /clock, minus the "
                      "state's stamp); state_lag (lockstep only, one process): the "
                      "simulator's time at the tick minus the stamp of the state the tick "
                      "plans from; plan_age: the simulator's time when the plan arrived minus "
                      "that stamp (the loop's delay)",
        "messages": dict(probe.messages),
        "deadline_misses": {
            "count": int(misses), "percent": 100.0 * misses / n if n else math.nan,
            "node_count": int(node_misses),
            "note": "count: ticks (MpcNode.tick, all of it) longer than deadline_ms; "
                    "node_count: the node's own count (WalkingMpc.update longer than the "
                    "period, the bootstrap excluded)"},
        "control_periods": {
            "expected": expected,
            "ticks": n,
            "without_tick_percent": 100.0 * max(expected - n, 0.0) / expected
            if expected > 0 else math.nan,
            "rate_hz": n / sim_time if sim_time > 0 else math.nan,
            "tick_interval_ms": distribution(gaps * 1e3),
        },
    }


def pooled_rmse(segments: list[dict]) -> dict[str, float]:
    """RMSE per axis over the settled samples of every segment (each against its command)."""
    out = {}
    for axis in ("vx", "vy", "wz"):
        num = sum(s["samples"] * s["rmse"][axis] ** 2 for s in segments if "rmse" in s)
        den = sum(s["samples"] for s in segments if "rmse" in s)
        out[axis] = math.sqrt(num / den) if den else math.nan
    return out


def measure(robot: str, mode: str = "realtime", duration: float | None = None,
            gif: bool = True, out: Path | None = None, iterations: int | None = None,
            sim_parameters: dict | None = None) -> dict:
    """One closed-loop run with the probes installed; returns (and writes into ``out``, with
    the report's plots) the closed-loop summary plus a ``bench`` section.

    ``sim_parameters``: SimNode parameters overriding the closed loop's (diagnostics). In
    real time the MPC-side probes run in the MPC process (:func:`mpc_probe_main`).
    """
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 101)))
    segments = profile(robot)
    load0 = machine_load()
    probe = Probe(sim_parameters)
    realtime = mode == "realtime"
    with tempfile.TemporaryDirectory(prefix="bench_closed_loop_") as tmp:
        child_figures = Path(tmp) / "mpc_probe.json"
        command = [sys.executable, str(Path(__file__).resolve()), "--mpc-probe",
                   str(child_figures)] if realtime else None
        t0 = time.perf_counter()
        with probe.installed():
            # the MPC process as deployed: MpcProcess asks /diagnostics at every tick (the
            # closed loop's per-tick solve times), the probe needs none of it
            rec = run(robot, segments, duration, mode, gif=False, iterations=iterations,
                      mpc_command=command,
                      mpc_parameters={"diagnostics_rate": DIAGNOSTICS_RATE} if realtime
                      else None)
        run_wall = time.perf_counter() - t0
        if realtime:
            if not child_figures.exists():
                raise RuntimeError(f"the MPC process wrote no figures; its output ends with:\n"
                                   f"{rec.mpc_log}")
            probe.absorb(json.loads(child_figures.read_text()))
    load1 = machine_load()
    summary = summarise(rec, segments, mode=mode, robot=robot)
    sim_time = summary["sim_time"]
    if len(rec.t):  # the MPC process ticks during the hold before the clock runs, too
        probe.rows = [r for r in probe.rows if rec.t[0] - 1e-9 <= r["t"] <= rec.t[-1] + 1e-9]
    age = dict(zip(np.round(rec.plan_t, 6), rec.plan_age, strict=True))
    for row in probe.rows:
        row["plan_age"] = age.get(round(row["t"], 6), math.nan) * 1e3
    falls = summary["falls"]["times"]
    rtf = (sim_parameters or {}).get("realtime_factor", 1.0) if realtime else 1.0
    ticks = tick_summary(probe, sim_time, rec.deadline_misses, falls[0] if falls else None,
                         rtf)

    def per_sim_s(x: float) -> float:
        return x / sim_time if sim_time > 0 else math.nan

    budget = {k: per_sim_s(v) for k, v in probe.wall.items()}
    if realtime:
        proc = rec.mpc_process
        budget["rest"] = per_sim_s(rec.wall_time - probe.wall["mpc_tick"]
                                   - probe.wall["mpc_inputs"])
        budget["cpu_mpc_process"] = per_sim_s(proc["cpu_s"])
        budget["cpu_sim_process"] = per_sim_s(proc["sim_process_cpu_s"])
        memory = {**proc["memory_mb"], "process": "mpc_node (its own process)",
                  "sim_process": rss_mb()}
    else:
        budget["rest"] = per_sim_s(rec.wall_time - sum(probe.wall.values()))
        memory = {**rss_mb(), "process": "the closed loop (sim, MPC and rclpy in one)"}
    summary["bench"] = {
        "mode": mode,
        "iterations_per_tick_setting": iterations,
        "sim_parameters": dict(sim_parameters or {}),
        "profile": [vars(s) for s in segments],
        "ticks": ticks,
        "tracking_rmse_pooled": pooled_rmse(summary["segments"]),
        "wall_s_per_sim_s": budget,
        "wall_s_per_sim_s_note": BUDGET_NOTES[mode],
        "memory_mb": {**memory, "mpc_node_construction": probe.rss_build.get("after_mb", math.nan)
                      - probe.rss_build.get("before_mb", math.nan),
                      "before_mpc_node": probe.rss_build.get("before_mb", math.nan)},
        "load": {"start": load0, "end": load1},
        "run_wall_s_incl_build": run_wall,
    }
    if out is not None:
        out = Path(out)
        if gif:
            rec.frames = render_replay(robot, rec.t, rec.q)
        write_report(rec, bench_ilqr.jsonable(summary), out)  # summary.json: strict JSON
        plot_ticks(probe.rows, probe.period, out / "tick_breakdown.png", f"{robot}, {mode}")
        write_rows(probe.rows, out / "ticks.csv")
    return summary


BUDGET_NOTES = {
    "lockstep": "one executor thread: sim = SimNode timer/trajectory callbacks (physics + state "
                "publishing), mpc_tick = MpcNode.tick, mpc_inputs = its joint_states/odom/"
                "cmd_vel callbacks, rest = executor overhead + the run loop's recording + idle",
    "realtime": "two processes: sim = SimNode callbacks (the run's process); mpc_tick, "
                "mpc_inputs = MpcNode.tick and its input callbacks (the MPC process), rest = "
                "the MPC process's executor overhead and idle time; cpu_* = CPU s (user + "
                "system) of each process per sim s",
}


def mpc_probe_main(path: Path, ros_args: Sequence[str]) -> int:
    """The MPC process of a real-time run with the probes installed: ``mpc_node`` until
    SIGINT/SIGTERM, then the probe's figures (:meth:`Probe.export`) written to ``path``."""
    probe = Probe()
    with probe.installed():
        code = mpc_node_module.main(["mpc_node", *ros_args])
    path.write_text(json.dumps(probe.export()))
    return code


def write_rows(rows: list[dict], path: Path) -> None:
    """Per-tick figures as CSV (ms; ``t`` in s)."""
    if not rows:
        return
    keys = list(rows[0])
    lines = [",".join(keys)] + [",".join(f"{r[k]:.4g}" for k in keys) for r in rows]
    path.write_text("\n".join(lines) + "\n")


# ---------------------------------------------------------------------- peer reference
PEER_REPEATS, PEER_TICKS = 5, 20  # per peer round (one round before the runs, one after)
# the peer's warm ticks are also measured after this much sleep each, as the node's ticks
# come at its control rate: a tick after an idle control period runs ~1.5x slower than one
# right after the last, for Crocoddyl as for us (doc/benchmarks.md, Session 16)
PEER_PACE_S = 1.0 / TARGETS["control_rate_hz"]


def peer_round(python: str) -> dict:
    """One run of the peer (``bench_ilqr.run_peer``, no profiler), with the load around it."""
    load = machine_load()
    out = bench_ilqr.run_peer(python, ticks=PEER_TICKS, repeats=PEER_REPEATS, profile=False,
                              pace=PEER_PACE_S)
    out["load"] = {"start": load, "end": machine_load()}
    return out


def crocoddyl_reference(rounds: Sequence[dict] = (), reason: str = "",
                        ilqr_json: Path = ILQR_JSON) -> dict:
    """Crocoddyl's FDDP time per iteration on its go2 trot (ms, median; wall and CPU): from
    the peer ``rounds`` measured in this run, else read from ``ilqr_json`` (the last
    ``bench_ilqr.py`` results)."""
    if rounds:
        peer = bench_ilqr.summarise_peer(list(rounds))
        per_round = [{"ms_per_iteration": float(np.median(
                          [x["ms_per_iteration"] for x in r["converging"]["solves"]])),
                      "cpu_ms_per_iteration": float(np.median(
                          [x["cpu_ms_per_iteration"] for x in r["converging"]["solves"]])),
                      "paced_tick_ms": float(np.median(r["paced_ticks"]["tick_ms"]))
                      if "paced_ticks" in r else None,
                      "load": r["load"]} for r in rounds]
        paced = peer.get("paced_ticks")
        return {"source": f"measured in this run: {len(rounds)} peer rounds (before and after "
                          f"the closed-loop runs), {PEER_REPEATS} converging solves each",
                "same_run": True, "rounds": per_round,
                "ms_per_iteration": peer["converging"]["ms_per_iteration"]["median"],
                "cpu_ms_per_iteration": peer["converging"]["cpu_ms_per_iteration"]["median"],
                "warm_tick_ms": peer["ticks"]["tick_ms"]["median"],
                "paced_tick_ms": paced["tick_ms"]["median"] if paced else None,
                "pace_s": paced["pace_s"] if paced else None,
                "nodes": peer["problem"]["nodes"]}
    try:
        data = json.loads(ilqr_json.read_text())
        peer = data["peer"]
        if not peer.get("available"):
            return {"source": f"{_shown(ilqr_json)}: no peer figures",
                    "same_run": False, "ms_per_iteration": None}
    except (OSError, KeyError, json.JSONDecodeError) as exc:
        return {"source": f"{ilqr_json}: unreadable ({exc})", "same_run": False,
                "ms_per_iteration": None}
    return {"source": f"{_shown(ilqr_json)} (its own run, commit "
                      f"{(data.get('code') or {}).get('commit', '?')[:7]}, load average "
                      f"{data['machine'].get('loadavg_start')}), NOT this run"
                      + (f"; peer not run here: {reason}" if reason else ""),
            "same_run": False,
            "ms_per_iteration": peer["converging"]["ms_per_iteration"]["median"],
            "cpu_ms_per_iteration": peer["converging"]["cpu_ms_per_iteration"]["median"],
            "warm_tick_ms": peer["ticks"]["tick_ms"]["median"],
            "nodes": peer["problem"]["nodes"]}


def _shown(path: Path) -> str:
    """``path`` relative to the repository when inside it."""
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


# ---------------------------------------------------------------------- aggregate
def compact(name: str, summary: dict) -> dict:
    """The figures of one run that go into the aggregate JSON and the table."""
    b = summary["bench"]
    t = b["ticks"]
    segs = [{"command": s["command"], "rmse": s.get("rmse"), "mean": s.get("mean"),
             "samples": s["samples"], "cut_short": bool(s.get("cut_short", False))}
            for s in summary["segments"]]
    return {
        "run": name, "robot": summary["robot"], "mode": summary["mode"],
        "sim_time": summary["sim_time"], "wall_time": summary["wall_time"],
        "real_time_factor": summary["real_time_factor"],
        "mpc_build_time": summary["mpc_build_time"],
        "tick_ms": t["tick_ms"], "tick_cpu_ms": t["tick_cpu_ms"],
        "tick_ms_before_fall": t["tick_ms_before_fall"],
        "p99_over_median": t["p99_over_median"],
        "bootstrap_ms": t["bootstrap_ms"],
        "deadline_misses": t["deadline_misses"],
        "control_periods": t["control_periods"],
        "plan_age_ms": t["plan_age_ms"],
        "state_age_ms": t["state_age_ms"],
        "diagnostics": {k: summary.get(k) for k in (
            "ticks_per_sim_second", "periods_without_tick_percent", "tick_time_ms",
            "deadline_misses", "deadline_miss_percent", "plan_age_ms")},
        "breakdown_ms_mean": t["breakdown_ms_mean"],
        "iterations_per_tick": t["iterations_per_tick"],
        "wall_s_per_sim_s": b["wall_s_per_sim_s"],
        "tracking_rmse_pooled": b["tracking_rmse_pooled"],
        "segments": segs,
        "falls": summary["falls"],
        "min_base_height": summary["min_base_height"],
        "max_abs_roll_pitch": summary["max_abs_roll_pitch"],
        "memory_mb": b["memory_mb"],
        "load": b["load"],
    }


def adjacent_crocoddyl_ms(croc: dict, name: str,
                          key: str = "ms_per_iteration") -> float | None:
    """The mean of Crocoddyl's per-iteration times (ms; ``key`` "paced_tick_ms": its paced
    warm ticks) in the peer rounds right before and after run ``name`` (None when those were
    not measured)."""
    idx = (croc.get("adjacent_rounds") or {}).get(name)
    values = [croc["rounds"][i].get(key) for i in idx or ()]
    if not values or None in values:
        return None
    return float(np.mean(values))


def targets_status(run_: dict, croc: dict) -> dict:
    """Each target of the issues against one run: value, target, met. The tick target (a
    third of Crocoddyl's iteration on the same robot) exists for go2 only (the peer's); its
    reference is the peer rounds right around the run when measured (the machine's speed
    drifts over minutes), else every round of the run."""
    t = run_["tick_ms"]
    croc_ms = None
    if run_["robot"] == PEER_ROBOT:
        croc_ms = adjacent_crocoddyl_ms(croc, run_["run"]) or croc.get("ms_per_iteration")
    rmse = [v for s in run_["segments"] if s["rmse"] for v in s["rmse"].values()]
    out = {
        "median_tick_ms": {"value": t["median"],
                           "target": None if croc_ms is None else
                           croc_ms * TARGETS["median_tick_over_crocoddyl_iteration"]},
        "p99_over_median": {"value": run_["p99_over_median"],
                            "target": TARGETS["p99_over_median"]},
        "rss_mb": {"value": run_["memory_mb"]["peak"], "target": TARGETS["rss_mb"]},
        "tracking_rmse_max": {"value": max(rmse) if rmse else math.nan,
                              "target": TARGETS["tracking_rmse"]},
        "real_time_factor": {"value": run_["real_time_factor"],
                             "target": TARGETS["real_time_factor"]},
        "control_rate_hz": {"value": run_["control_periods"]["rate_hz"],
                            "target": TARGETS["control_rate_hz"]},
        "deadline_miss_percent": {"value": run_["deadline_misses"]["percent"],
                                  "target": TARGETS["deadline_miss_percent"]},
    }
    upper = {"median_tick_ms", "p99_over_median", "rss_mb", "tracking_rmse_max",
             "deadline_miss_percent"}
    for key, entry in out.items():
        v, tgt = entry["value"], entry["target"]
        ok = None if tgt is None or v is None or not math.isfinite(v) else (
            v <= tgt if key in upper else v >= tgt * (1 - RATE_TOLERANCE))
        entry["met"] = ok
    # the tick target is a real-time figure against the peer measured in this run: a
    # lockstep tick, or one against an earlier run's peer file, is context, not rated (both
    # were 'met': true)
    unrated = ("a lockstep tick is no real-time figure" if run_.get("mode") != "realtime"
               else None if croc.get("same_run") else
               "the peer was not measured in this run (--peer)")
    if croc_ms and unrated:
        out["median_tick_ms"]["met"] = None
        out["median_tick_ms"]["not_rated"] = unrated
    if run_.get("mode") != "realtime":  # the sim waits for every plan: no clock to keep
        for key in ("real_time_factor", "control_rate_hz", "deadline_miss_percent"):
            out[key]["met"] = None
            out[key]["not_rated"] = "lockstep: the simulator waits for every plan"
    if any(s.get("cut_short") for s in run_["segments"]):  # --duration ended it early
        out["tracking_rmse_max"]["met"] = None
        out["tracking_rmse_max"]["not_rated"] = "the run ended before the profile's last segment"
    if croc_ms:
        out["median_tick_ms"]["crocoddyl_ms_per_iteration"] = croc_ms
        out["median_tick_ms"]["over_crocoddyl_iteration"] = t["median"] / croc_ms
        if croc.get("ms_per_iteration"):
            out["median_tick_ms"]["over_crocoddyl_iteration_all_rounds"] = (
                t["median"] / croc["ms_per_iteration"])
        cpu = croc.get("cpu_ms_per_iteration")
        out["median_tick_ms"]["cpu_over_crocoddyl_cpu_iteration"] = (
            run_["tick_cpu_ms"]["median"] / cpu if cpu else None)
        # context, not the target: Crocoddyl's warm tick paced at the control rate (both
        # ticks then start after an idle period)
        paced = adjacent_crocoddyl_ms(croc, run_["run"], "paced_tick_ms")
        if paced:
            out["median_tick_ms"]["crocoddyl_paced_tick_ms"] = paced
            out["median_tick_ms"]["over_crocoddyl_paced_tick"] = t["median"] / paced
    return out


def aggregate(runs: dict[str, dict], croc: dict, args: argparse.Namespace,
              load: dict) -> dict:
    """The aggregate document (``closed_loop.json``)."""
    compacts = {name: compact(name, s) for name, s in runs.items()}
    return {
        "code": bench_ilqr.git_state(),
        "machine": {"python": platform.python_version(), "numpy": np.__version__,
                    "cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                    "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS"),
                    "load": load},
        "settings": {"robots": args.robots, "mode": args.mode, "duration": args.duration,
                     "repeats": args.repeats,
                     "reference": f"{REFERENCE_ROBOT} lockstep" if args.reference else None,
                     "isolated_processes": args.isolate, "iterations": args.iterations,
                     "sim_parameters_realtime": sim_parameters(args, "realtime")},
        "crocoddyl": croc,
        "targets": TARGETS,
        "per_robot": per_robot(compacts),
        "runs": compacts,
        "status": {name: targets_status(c, croc) for name, c in compacts.items()},
    }


def per_robot(compacts: dict[str, dict]) -> dict[str, dict]:
    """Per (robot, mode): how many runs fell, and each run's headline figures, in order."""
    out: dict[str, dict] = {}
    for r in compacts.values():
        key = r["robot"] if r["mode"] == "realtime" else f"{r['robot']}_{r['mode']}"
        entry = out.setdefault(key, {"runs": 0, "runs_with_falls": 0, "first_fall_s": [],
                                     "ticks_per_sim_s": [], "tick_ms_median": [],
                                     "tick_ms_p99": [], "plan_age_ms_median": [],
                                     "deadline_miss_percent": [], "rmse_pooled": []})
        entry["runs"] += 1
        falls = r["falls"]["times"]
        entry["runs_with_falls"] += bool(falls)
        entry["first_fall_s"].append(falls[0] if falls else None)
        entry["ticks_per_sim_s"].append(r["control_periods"]["rate_hz"])
        entry["tick_ms_median"].append(r["tick_ms"]["median"])
        entry["tick_ms_p99"].append(r["tick_ms"]["p99"])
        entry["plan_age_ms_median"].append(r["plan_age_ms"]["median"])
        entry["deadline_miss_percent"].append(r["deadline_misses"]["percent"])
        entry["rmse_pooled"].append(r["tracking_rmse_pooled"])
    return out


def _f(x: float | None, fmt: str = ".1f") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else \
        format(x, fmt)


def table(agg: dict) -> str:
    """The aggregate as text tables."""
    lines = ["run | ticks | tick ms median/p95/p99/max (CPU median/p99) | p99/med | misses "
             "(%) | ticks/sim s | plan age ms median/p95 | RTF | RSS MB peak | falls"]
    for name, r in agg["runs"].items():
        t, d = r["tick_ms"], r["deadline_misses"]
        lines.append(
            f"{name} | {r['control_periods']['ticks']} | {_f(t['median'])}/{_f(t['p95'])}/"
            f"{_f(t['p99'])}/{_f(t['max'])} ({_f(r['tick_cpu_ms']['median'])}/"
            f"{_f(r['tick_cpu_ms']['p99'])}) | "
            f"{_f(r['p99_over_median'], '.2f')} | {d['count']} ({_f(d['percent'])}) | "
            f"{_f(r['control_periods']['rate_hz'])} | {_f(r['plan_age_ms']['median'])}/"
            f"{_f(r['plan_age_ms']['p95'])} | {_f(r['real_time_factor'], '.2f')} | "
            f"{_f(r['memory_mb']['peak'], '.0f')} | {r['falls']['count']} "
            f"{[round(x, 2) for x in r['falls']['times']]}")
    lines.append("")
    lines.append("run | breakdown ms (mean): state / shift / refs / ILQR (quad / back / roll / "
                 "ls / other) / plan / publish | wall s per sim s: sim / tick / inputs / rest")
    for name, r in agg["runs"].items():
        b, w = r["breakdown_ms_mean"], r["wall_s_per_sim_s"]
        lines.append(
            f"{name} | {_f(b['state'], '.2f')} / {_f(b['shift'], '.2f')} / "
            f"{_f(b['references'], '.2f')} / {_f(b['ilqr'], '.2f')} ("
            + " / ".join(_f(b[k], ".2f") for k in ILQR_PARTS)
            + f") / {_f(b['plan'], '.2f')} / {_f(b['publish'], '.2f')} | "
            f"{_f(w['sim'], '.2f')} / {_f(w['mpc_tick'], '.2f')} / {_f(w['mpc_inputs'], '.2f')}"
            f" / {_f(w['rest'], '.2f')}")
    lines.append("")
    lines.append("run | references: set_state / set_references / other | publish: trajectory "
                 "msg / path msg / diagnostics / other (ms, mean)")
    for name, r in agg["runs"].items():
        b = r["breakdown_ms_mean"]
        lines.append(f"{name} | " + " / ".join(_f(b[k], ".2f") for k in SUB_PARTS[:3]) + " | "
                     + " / ".join(_f(b[k], ".2f") for k in SUB_PARTS[3:]))
    lines.append("")
    lines.append("run | segment: command -> mean (RMSE) | pooled RMSE vx / vy / wz")
    for name, r in agg["runs"].items():
        parts = []
        for s in r["segments"]:
            c = s["command"]
            axis = max(("vx", "vy", "wz"), key=lambda a: abs(c[a]))
            if s["mean"] is None:
                parts.append(f"{axis} {c[axis]:g}: no samples")
            else:
                parts.append(f"{axis} {c[axis]:g} -> {s['mean'][axis]:.3f} "
                             f"({s['rmse'][axis]:.3f})")
        p = r["tracking_rmse_pooled"]
        lines.append(f"{name} | " + "; ".join(parts)
                     + f" | {_f(p['vx'], '.3f')} / {_f(p['vy'], '.3f')} / {_f(p['wz'], '.3f')}")
    lines.append("")
    for key, e in agg.get("per_robot", {}).items():
        lines.append(f"{key}: fell in {e['runs_with_falls']} of {e['runs']} runs "
                     f"(first falls {e['first_fall_s']}); ticks/sim s "
                     + ", ".join(_f(x) for x in e["ticks_per_sim_s"]))
    croc = agg["crocoddyl"]
    lines.append("")
    if croc.get("ms_per_iteration"):
        lines.append(f"Crocoddyl FDDP per iteration (go2 trot, {croc.get('nodes')} nodes): "
                     f"{croc['ms_per_iteration']:.1f} ms wall, "
                     f"{_f(croc.get('cpu_ms_per_iteration'))} ms CPU (source: {croc['source']})")
        for name, st in agg["status"].items():
            m = st["median_tick_ms"]
            if "over_crocoddyl_iteration" in m:
                around = ("the rounds around it" if adjacent_crocoddyl_ms(croc, name)
                          else "the source above")
                rated = (f"not rated: {m['not_rated']}" if m.get("not_rated") else
                         f"target <= 0.33: {'met' if m['met'] else 'NOT met'}")
                lines.append(f"{name}: median tick / Crocoddyl iteration = "
                             f"{_f(m['over_crocoddyl_iteration'], '.2f')} wall against "
                             f"{around} ({_f(m['crocoddyl_ms_per_iteration'])} ms), "
                             f"{_f(m.get('over_crocoddyl_iteration_all_rounds'), '.2f')} "
                             f"against all rounds, "
                             f"{_f(m.get('cpu_over_crocoddyl_cpu_iteration'), '.2f')} CPU "
                             f"({rated})")
            if "over_crocoddyl_paced_tick" in m:
                lines.append(f"{name}: median tick / Crocoddyl's warm tick paced at "
                             f"{1 / PEER_PACE_S:g} Hz = "
                             f"{_f(m['over_crocoddyl_paced_tick'], '.2f')} "
                             f"({_f(m['crocoddyl_paced_tick_ms'])} ms; context, not the "
                             "target)")
    else:
        lines.append(f"Crocoddyl: no figure ({croc['source']})")
    return "\n".join(lines)


# ---------------------------------------------------------------------- plots
def plot_ticks(rows: list[dict], period: float, path: Path, title: str) -> None:
    """Per-tick stacked breakdown over sim time, and the tick time histogram."""
    if not rows:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.array([r["t"] for r in rows])
    fig, axes = plt.subplots(1, 2, figsize=(12, 4), gridspec_kw={"width_ratios": [3, 1]})
    parts = ("state", "shift", "references", *TIMING_KEYS, "ilqr_other", "plan", "publish")
    stack = np.array([[max(r[k], 0.0) for k in parts] for r in rows]).T
    axes[0].stackplot(t, stack, labels=parts, linewidth=0)
    axes[0].plot(t, [r["tick"] for r in rows], "k", lw=0.6, label="tick (all)")
    axes[0].axhline(period * 1e3, color="r", ls=":", label="control period")
    axes[0].set_xlabel("sim time (s)")
    axes[0].set_ylabel("ms")
    axes[0].set_title(f"MPC tick breakdown ({title})")
    axes[0].legend(fontsize=7, ncol=4, loc="upper left")
    axes[0].grid(alpha=0.3)
    tick = np.array([r["tick"] for r in rows])
    axes[1].hist(tick, bins=40, color="#4c72b0")
    for q, ls in ((50, "-"), (95, "--"), (99, ":")):
        axes[1].axvline(np.percentile(tick, q), color="k", ls=ls, lw=1, label=f"p{q}")
    axes[1].axvline(period * 1e3, color="r", ls=":", label="period")
    axes[1].set_xlabel("tick (ms)")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_aggregate(agg: dict, path: Path) -> None:
    """Stacked mean breakdown per run, with the tick median / p95 / p99 and the period."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = agg["runs"]
    parts = ("state", "shift", "references", *TIMING_KEYS, "ilqr_other", "plan", "publish")
    colors = plt.get_cmap("tab10").colors
    fig, ax = plt.subplots(figsize=(max(8.0, 0.8 * len(runs)), 5.2))
    for i, r in enumerate(runs.values()):
        bottom = 0.0
        for j, k in enumerate(parts):
            h = max(r["breakdown_ms_mean"][k] or 0.0, 0.0)
            ax.bar(i, h, bottom=bottom, color=colors[j % 10], width=0.6,
                   label=k if i == 0 else None)
            bottom += h
        for q, ls in (("median", "-"), ("p95", "--"), ("p99", ":")):
            ax.plot([i - 0.35, i + 0.35], [r["tick_ms"][q]] * 2, color="k", ls=ls, lw=1.5,
                    label=f"tick {q}" if i == 0 else None)
    ax.axhline(20.0, color="r", ls=":", lw=1, label="20 ms period (50 Hz)")
    croc = agg["crocoddyl"].get("ms_per_iteration")
    if croc:
        ax.axhline(croc / 3, color="g", ls="-.", lw=1, label="target: Crocoddyl iteration / 3")
    ax.set_xticks(range(len(runs)), [f"{n}\nRTF {r['real_time_factor']:.2f}"
                                     for n, r in runs.items()],
                  fontsize=8 if len(runs) <= 6 else 6, rotation=0 if len(runs) <= 6 else 45)
    ax.set_ylabel("ms per tick (mean breakdown)")
    ax.set_title("MPC node in the closed loop: tick breakdown and percentiles")
    ax.legend(fontsize=7, ncol=2, loc="upper left", bbox_to_anchor=(1.0, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# ---------------------------------------------------------------------- main
def run_isolated(robot: str, mode: str, args: argparse.Namespace, out: Path,
                 gif: bool) -> dict:
    """One measurement in a fresh interpreter (its peak RSS is then this run's alone)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", "--robots", robot,
           "--mode", mode, "--out", str(out)]
    if args.iterations is not None:
        cmd += ["--iterations", str(args.iterations)]
    if args.duration is not None:
        cmd += ["--duration", str(args.duration)]
    if not gif:
        cmd.append("--no-gif")
    for key, value in sim_parameters(args, mode).items():
        cmd += [f"--{key.replace('_', '-')}", str(value)]
    proc = subprocess.run(cmd, check=False, timeout=3600)
    if proc.returncode != 0:
        raise RuntimeError(f"measurement failed (exit {proc.returncode}): {' '.join(cmd)}")
    return json.loads((out / "summary.json").read_text())


def sim_parameters(args: argparse.Namespace, mode: str) -> dict:
    """SimNode overrides of the real-time runs (``--realtime-factor``, ``--state-rate``)."""
    if mode != "realtime":
        return {}
    return {k: float(v) for k, v in (("realtime_factor", args.realtime_factor),
                                     ("state_rate", args.state_rate)) if v is not None}


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Command line (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", nargs="+", default=list(ROBOTS), help="robots (all three)")
    ap.add_argument("--duration", type=positive_float, default=None,
                    help="sim seconds per run (default: the profile's 10 s)")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT,
                    help="output folder: <out>/<run>/ per run, <out>.json the aggregate")
    ap.add_argument("--mode", choices=("realtime", "lockstep"), default="realtime",
                    help="mode of the per-robot runs (default realtime)")
    ap.add_argument("--reference", action=argparse.BooleanOptionalAction, default=True,
                    help=f"also run {REFERENCE_ROBOT} in lockstep (when --mode realtime)")
    ap.add_argument("--gif", action=argparse.BooleanOptionalAction, default=True,
                    help="write run.gif per robot (rendered after the run, from its states)")
    ap.add_argument("--iterations", type=positive_int, default=None,
                    help="ILQR iterations per tick (default: the robot config's mpc.iterations)")
    ap.add_argument("--repeats", type=positive_int, default=1,
                    help="real-time runs per robot (robots interleaved; GIF of the first only)")
    ap.add_argument("--isolate", action=argparse.BooleanOptionalAction, default=True,
                    help="one subprocess per run (peak RSS per run)")
    ap.add_argument("--realtime-factor", type=positive_float, default=None,
                    help="diagnostics: sim s per wall s of the real-time runs (default 1)")
    ap.add_argument("--state-rate", type=positive_float, default=None,
                    help="diagnostics: sim_node's state publishing rate, Hz (closed_loop's "
                         "real-time default: 250)")
    ap.add_argument("--peer", action="store_true",
                    help="measure Crocoddyl's per-iteration time in this run (needs .venv-peer)")
    ap.add_argument("--peer-python", default=None, help="peer interpreter")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    args.reference = args.reference and args.mode == "realtime"
    if not args.worker:  # checked once, before anything is measured
        refuse_duplicates(ap, args.robots, "--robots")
        for robot in args.robots:
            try:
                load_robot_config(robot)
            except (FileNotFoundError, ValueError) as exc:
                ap.error(f"--robots: {exc}")
        args.out = output_stem(ap, args.out)
        output_folder(ap, args.out)
    return args


def plan_runs(args: argparse.Namespace) -> list[tuple[str, str, str, bool]]:
    """(run name, robot, mode, gif) of every measurement: ``--repeats`` rounds over the
    robots (``go2``, then ``go2_r2``, ...), then the lockstep reference."""
    runs = [(robot if k == 1 else f"{robot}_r{k}", robot, args.mode, args.gif and k == 1)
            for k in range(1, args.repeats + 1) for robot in args.robots]
    if args.reference:
        runs.append((f"{REFERENCE_ROBOT}_lockstep", REFERENCE_ROBOT, "lockstep", False))
    return runs


def main(argv: Sequence[str] | None = None) -> int:
    """Measure, write the per-run folders and the aggregate, print the table."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--mpc-probe"]:  # the MPC process of a real-time measurement
        return mpc_probe_main(Path(argv[1]), argv[2:])
    args = parse_args(argv)
    if args.worker:  # one measurement, written into --out
        measure(args.robots[0], args.mode, args.duration, args.gif, args.out, args.iterations,
                sim_parameters(args, args.mode))
        return 0
    load0 = machine_load()
    python, reason = bench_ilqr.find_peer_python(args.peer_python) if args.peer else (None, "")
    rounds: list[dict] = []

    def peer() -> None:
        nonlocal python, reason
        if python:
            print(f"[peer] Crocoddyl ({python})", flush=True)  # noqa: T201
            try:
                rounds.append(peer_round(python))
            except (RuntimeError, subprocess.TimeoutExpired) as exc:
                python, reason = None, str(exc)

    # a peer round before every run and after the last: each run is compared with the
    # rounds right around it too (this machine's speed drifts over minutes)
    runs, adjacent = {}, {}
    for name, robot, mode, gif in plan_runs(args):
        peer()
        first = len(rounds) - 1
        print(f"[{name}] {robot} {mode} (load {machine_load()})", flush=True)  # noqa: T201
        out = args.out / name
        runs[name] = (run_isolated(robot, mode, args, out, gif) if args.isolate else
                      measure(robot, mode, args.duration, gif, out, args.iterations,
                              sim_parameters(args, mode)))
        adjacent[name] = [first, first + 1]
    peer()
    croc = crocoddyl_reference(rounds if python else (), reason)
    if python and croc.get("rounds"):
        croc["adjacent_rounds"] = {n: [i for i in idx if 0 <= i < len(croc["rounds"])]
                                   for n, idx in adjacent.items()}
    agg = aggregate(runs, croc, args, {"start": load0, "end": machine_load()})
    agg = bench_ilqr.jsonable(agg)
    path, png = sibling(args.out, ".json"), sibling(args.out, ".png")
    path.write_text(json.dumps(agg, indent=1, allow_nan=False) + "\n")
    plot_aggregate(agg, png)
    sys.stdout.write(table(agg) + f"\nwritten {path}, {png}, {args.out}/<run>/\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
