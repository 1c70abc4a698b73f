"""The MPC node as a child process of the real-time closed loop (:mod:`horizon_mpc.closed_loop`).

In real time the simulator and the MPC must run in parallel on two cores; Python threads
cannot (the GIL), so ``mpc_node`` runs as a process of its own and talks to the simulator
through the ROS topics only. This module starts it, tells when it died (with the end of its
output), stops it (SIGINT, then SIGTERM, then SIGKILL) and reads its memory and CPU time
from ``/proc``. :class:`MpcMonitor` is the parent's ear: the plans (``joint_trajectory``)
and tick statistics (``/diagnostics``) the child publishes.
"""

from __future__ import annotations

import ctypes
import json
import logging
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

import horizon_mpc
from horizon_mpc.nodes.conversions import NS_PER_S, time_to_ns

__all__ = ["MpcMonitor", "MpcProcess", "MpcProcessError", "TickRecord", "default_domain_id",
           "private_domain_id", "process_cpu_seconds", "process_memory_mb", "wait_until"]

log = logging.getLogger(__name__)

#: The command that runs ``mpc_node`` (the ``mpc_node`` executable's module).
MPC_NODE_COMMAND = (sys.executable, "-m", "horizon_mpc.nodes.mpc_node")
#: Domain ids whose DDS ports are valid on Linux (0, everybody's default, left out).
PRIVATE_DOMAIN_IDS = (*range(1, 102), *range(215, 233))
MAX_DOMAIN_ID = 232  # the largest ROS_DOMAIN_ID whose ports fit on Linux
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


class MpcProcessError(RuntimeError):
    """The MPC process exited or did not get ready; the message ends with its output."""


def private_domain_id(pid: int | None = None) -> int:
    """A ``ROS_DOMAIN_ID`` derived from ``pid`` (default: this process), so that closed
    loops started in parallel by different processes do not hear each other; never the
    environment's ``ROS_DOMAIN_ID``, the domain of the user's other nodes (a user's
    exported 83 met a lockstep run that took 83: a hand-started mpc_node drove its
    simulator)."""
    pid = os.getpid() if pid is None else pid
    taken = os.environ.get("ROS_DOMAIN_ID", "").strip()
    ids = [d for d in PRIVATE_DOMAIN_IDS if str(d) != taken]
    return ids[pid % len(ids)]


def default_domain_id() -> int:
    """``ROS_DOMAIN_ID`` from the environment when set (to watch the run from another
    terminal), else :func:`private_domain_id`.

    Raises:
        ValueError: the variable is set to no domain id (0..:data:`MAX_DOMAIN_ID`): 300
            ended the run inside DDS without a word, -1 in a traceback, and 'abc' was
            ignored for a private domain silently.
    """
    text = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return private_domain_id()
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']!r} in the environment is "
                         f"no ROS domain (0..{MAX_DOMAIN_ID} on Linux): set it right, unset it "
                         "(a private domain), or give --domain-id")
    return value


def _parent_death_signal() -> Callable[[], None] | None:
    """A ``preexec_fn`` asking Linux to SIGTERM the child if this process dies (even by
    SIGKILL, when no cleanup can run); None where ``prctl`` is not available."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl  # resolved before the fork
    except (OSError, AttributeError):
        return None

    def preexec() -> None:
        prctl(_PR_SET_PDEATHSIG, int(signal.SIGTERM))
    return preexec


class MpcProcess:
    """``mpc_node`` (timer trigger, sim clock) in a process of its own.

    Its stdout and stderr go to an anonymous temporary file (a pipe nobody reads would fill
    and block it); :meth:`log_tail` reads the end. Use as a context manager: leaving the
    block stops the process, also on an exception or a KeyboardInterrupt.

    Args:
        robot: robot config name, passed as the node's ``robot`` parameter.
        iterations: ILQR iterations per tick (``iterations`` parameter; None: the config's).
        domain_id: the child's ``ROS_DOMAIN_ID`` (default: :func:`default_domain_id`).
        parameters: more ``-p name:=value`` node parameters (value written as ROS args).
        command: the program to run instead of ``python -m horizon_mpc.nodes.mpc_node``
            (e.g. a benchmark wrapper); the ROS arguments are appended to it.
    """

    def __init__(self, robot: str, iterations: int | None = None, domain_id: int | None = None,
                 parameters: Mapping[str, object] | None = None,
                 command: Sequence[str] | None = None) -> None:
        # diagnostics_rate 0: /diagnostics on every tick, the closed loop's per-tick solve
        # times (ticks themselves are counted by their plans)
        params: dict[str, object] = {"robot": robot, "use_sim_time": True, "trigger": "timer"}
        if iterations is not None:  # None: the robot config's mpc.iterations
            params["iterations"] = int(iterations)
        params.update({"diagnostics_rate": 0.0, **dict(parameters or {})})
        self.argv = [*(command or MPC_NODE_COMMAND), "--ros-args",
                     *(a for k, v in params.items() for a in ("-p", f"{k}:={_ros_value(v)}"))]
        self.domain_id = default_domain_id() if domain_id is None else int(domain_id)
        self.proc: subprocess.Popen | None = None
        self.returncode: int | None = None
        self._log = None

    def environment(self) -> dict[str, str]:
        """The child's environment: this one, with the domain id, discovery on localhost
        unless set otherwise, and this checkout of horizon_mpc first on ``PYTHONPATH``."""
        env = dict(os.environ)
        env["ROS_DOMAIN_ID"] = str(self.domain_id)
        env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        source = str(Path(horizon_mpc.__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join([source, *filter(None, [env.get("PYTHONPATH")])])
        env.setdefault("PYTHONUNBUFFERED", "1")
        return env

    def start(self) -> MpcProcess:
        """Start the process (returns at once; it builds the MPC for seconds)."""
        if self.proc is not None:
            raise RuntimeError("the MPC process was already started")
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(self.argv, env=self.environment(), stdin=subprocess.DEVNULL,
                                     stdout=self._log, stderr=subprocess.STDOUT,
                                     preexec_fn=_parent_death_signal())  # noqa: PLW1509
        log.info("started mpc_node (pid %d, ROS_DOMAIN_ID %d): %s", self.proc.pid,
                 self.domain_id, " ".join(self.argv))
        return self

    @property
    def pid(self) -> int | None:
        """The process id (None before :meth:`start`)."""
        return None if self.proc is None else self.proc.pid

    def alive(self) -> bool:
        """Whether the process runs."""
        return self.proc is not None and self.proc.poll() is None

    def check_alive(self, when: str) -> None:
        """Raise :class:`MpcProcessError` (exit code and output tail) if the process exited."""
        if self.proc is None or self.proc.poll() is None:
            return
        raise MpcProcessError(f"mpc_node exited with code {self.proc.returncode} {when}; "
                              f"its output ends with:\n{self.log_tail()}")

    def log_tail(self, lines: int = 30) -> str:
        """The last ``lines`` lines of the process's output (stdout and stderr)."""
        if self._log is None or self._log.closed:
            return ""
        self._log.flush()
        size = self._log.seek(0, os.SEEK_END)
        self._log.seek(max(0, size - 16384))
        text = self._log.read().decode("utf-8", errors="replace")
        return "\n".join(text.splitlines()[-lines:])

    def stop(self, timeout: float = 5.0) -> int | None:
        """Stop the process: SIGINT (the node exits cleanly with 0), SIGTERM after
        ``timeout`` s, SIGKILL after as long again. Returns the exit code; idempotent."""
        if self.proc is None:
            return None
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            if self.proc.poll() is not None:
                break
            if sig != signal.SIGINT:
                log.warning("mpc_node (pid %d) did not exit within %.0f s; sending %s",
                            self.proc.pid, timeout, sig.name)
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                continue
        self.returncode = self.proc.wait()
        return self.returncode

    def close(self) -> None:
        """Stop the process and close its log."""
        try:
            self.stop()
        finally:
            if self._log is not None:
                self._log.close()

    def __enter__(self) -> MpcProcess:
        return self.start() if self.proc is None else self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _ros_value(value: object) -> str:
    """A parameter value as written after ``:=`` in ROS arguments (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def process_memory_mb(pid: int) -> dict[str, float]:
    """``{"current", "peak"}`` resident set size (MB) of process ``pid`` (``/proc``; NaN
    where unavailable)."""
    out = {"current": math.nan, "peak": math.nan}
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            key, _, value = line.partition(":")
            if key in ("VmRSS", "VmHWM"):
                out["current" if key == "VmRSS" else "peak"] = float(value.split()[0]) / 1024
    except (OSError, ValueError, IndexError):
        pass
    return out


def process_cpu_seconds(pid: int) -> float:
    """User + system CPU time (s) process ``pid`` has used so far (``/proc``; NaN if not)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return math.nan


@dataclass
class TickRecord:
    """What the parent heard from the MPC process, in order of arrival.

    Plans: ``plan_t`` the stamp of each ``joint_trajectory`` (the state time it planned
    from, s), ``plan_age`` the simulator's time at reception minus that stamp (s). Ticks,
    from ``/diagnostics``: ``tick_t`` stamp, ``tick_time`` solve time (s, the node's
    ``solve_time_ms``: ``WalkingMpc.start``/``update``), ``prepare_time`` (s, the node's
    ``prepare_time_ms``: the next tick's preparation after it, 0 without ``prepare_ahead``),
    ``iterations``, ``command`` (the
    node's ramped command at that tick). Counters: the node's latest values.
    """

    plan_t: list[float] = field(default_factory=list)
    plan_age: list[float] = field(default_factory=list)
    tick_t: list[float] = field(default_factory=list)
    tick_time: list[float] = field(default_factory=list)
    prepare_time: list[float] = field(default_factory=list)
    iterations: list[float] = field(default_factory=list)
    command: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    counters: dict[str, float] = field(default_factory=lambda: {
        "ticks": 0, "deadline_misses": 0, "overruns": 0, "stale_skips": 0,
        "prepare_misses": 0})


class MpcMonitor(Node):
    """Subscribes to the MPC's ``joint_trajectory`` and ``/diagnostics`` into a
    :class:`TickRecord`. ``sim_time_ns``: the simulator's clock (called on each plan)."""

    def __init__(self, sim_time_ns: Callable[[], int], node_name: str = "closed_loop_monitor",
                 **kwargs: object) -> None:
        super().__init__(node_name, **kwargs)
        self.record = TickRecord()
        self._sim_time_ns = sim_time_ns
        # deep queues: this process may stall for a while under load, and no tick may be lost
        self.create_subscription(JointTrajectory, "joint_trajectory", self._on_plan, 100)
        self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 100)

    @property
    def plans(self) -> int:
        """Number of plans received."""
        return len(self.record.plan_t)

    def _on_plan(self, msg: JointTrajectory) -> None:
        stamp = time_to_ns(msg.header.stamp)
        self.record.plan_t.append(stamp / NS_PER_S)
        self.record.plan_age.append((self._sim_time_ns() - stamp) / NS_PER_S)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith("walking MPC"):
                self._on_mpc_status(time_to_ns(msg.header.stamp) / NS_PER_S,
                                    {kv.key: kv.value for kv in status.values})

    def _on_mpc_status(self, stamp: float, values: dict[str, str]) -> None:
        rec = self.record
        ticks = _number(values.get("ticks"))
        if ticks > rec.counters["ticks"]:  # a published plan (stale skips publish too)
            rec.tick_t.append(stamp)
            rec.tick_time.append(_number(values.get("solve_time_ms")) / 1e3)
            rec.prepare_time.append(_number(values.get("prepare_time_ms")) / 1e3)
            rec.iterations.append(_number(values.get("iterations")))
            try:
                rec.command = [float(c) for c in json.loads(values.get("command", ""))]
            except (ValueError, TypeError):
                pass
        for key in rec.counters:
            value = _number(values.get(key))
            if math.isfinite(value):
                rec.counters[key] = value


def _number(text: str | None) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def wait_until(condition: Callable[[], bool], spin: Callable[[], None], child: MpcProcess,
               timeout: float, what: str) -> None:
    """Spin until ``condition()``; raise :class:`MpcProcessError` if ``child`` exits or
    ``timeout`` (s, wall) passes first, naming ``what`` was awaited."""
    deadline = time.monotonic() + timeout
    while not condition():
        child.check_alive(f"while the closed loop waited for {what}")
        if time.monotonic() > deadline:
            raise MpcProcessError(f"no {what} within {timeout:g} s (mpc_node pid {child.pid}); "
                                  f"its output ends with:\n{child.log_tail()}")
        spin()
