"""The MPC node as a child process (``horizon_mpc.nodes.mpc_process``): command line,
environment, shutdown escalation, and what the parent reads from its /diagnostics."""

from __future__ import annotations

import math
import os
import sys
import time

import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from processes import process_exists
from trajectory_msgs.msg import JointTrajectory

from horizon_mpc.nodes.mpc_process import (
    MpcMonitor,
    MpcProcess,
    MpcProcessError,
    private_domain_id,
    process_cpu_seconds,
    process_memory_mb,
    wait_until,
)

# a stand-in for mpc_node that ignores SIGINT (as a node stuck in a long build would)
STUBBORN = ("import signal, sys, time; signal.signal(signal.SIGINT, signal.SIG_IGN); "
            "print('stubborn up', flush=True); time.sleep(60)")


def test_the_command_line_sets_the_node_parameters():
    proc = MpcProcess("solo12", iterations=2, domain_id=7, parameters={"state_timeout": 0.5})
    assert proc.argv[:3] == [sys.executable, "-m", "horizon_mpc.nodes.mpc_node"]
    ros = proc.argv[proc.argv.index("--ros-args") + 1:]
    assert ros == ["-p", "robot:=solo12", "-p", "use_sim_time:=true", "-p", "trigger:=timer",
                   "-p", "iterations:=2", "-p", "diagnostics_rate:=0.0",
                   "-p", "state_timeout:=0.5"]
    # no iterations given: the node takes the robot config's mpc.iterations
    assert not any(a.startswith("iterations:=") for a in MpcProcess("go2").argv)


def test_the_child_environment_isolates_the_run_and_runs_this_checkout(monkeypatch):
    monkeypatch.delenv("ROS_AUTOMATIC_DISCOVERY_RANGE", raising=False)
    env = MpcProcess("go2", domain_id=33).environment()
    assert env["ROS_DOMAIN_ID"] == "33"
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    import horizon_mpc

    source = os.path.dirname(os.path.dirname(os.path.abspath(horizon_mpc.__file__)))
    assert env["PYTHONPATH"].split(os.pathsep)[0] == source


def test_the_default_domain_is_the_environment_s_else_private_to_this_process(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert MpcProcess("go2").domain_id == 42
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert MpcProcess("go2").domain_id == private_domain_id(os.getpid())
    assert private_domain_id(1) != private_domain_id(2)
    assert all(0 < private_domain_id(pid) < 233 for pid in range(500))


def test_a_private_domain_is_never_the_environment_s(monkeypatch):
    """An auditor's exported ROS_DOMAIN_ID=83 was the private domain a lockstep run derived
    from its pid: the auditor's hand-started mpc_node drove that run's simulator."""
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    free = [private_domain_id(pid) for pid in range(500)]
    for pid in (0, 7, 118, 119, 499):
        monkeypatch.setenv("ROS_DOMAIN_ID", str(free[pid]))
        assert private_domain_id(pid) != free[pid]
        assert 0 < private_domain_id(pid) < 233
    monkeypatch.setenv("ROS_DOMAIN_ID", "not a number")  # nothing to avoid
    assert [private_domain_id(pid) for pid in range(500)] == free


def test_a_child_ignoring_sigint_is_terminated_after_the_timeout():
    proc = MpcProcess("go2", command=[sys.executable, "-c", STUBBORN]).start()
    try:
        deadline = time.monotonic() + 20
        while "stubborn up" not in proc.log_tail() and time.monotonic() < deadline:
            time.sleep(0.05)
        t0 = time.monotonic()
        code = proc.stop(timeout=0.5)
        assert code == -15  # SIGINT ignored, SIGTERM ended it
        assert 0.4 < time.monotonic() - t0 < 5
        assert not process_exists(proc.pid)
        assert proc.stop() == -15  # idempotent
    finally:
        proc.close()


def test_a_child_that_exits_is_reported_with_its_output():
    script = "import sys; sys.stderr.write('no such robot: go3\\n'); sys.exit(3)"
    with MpcProcess("go2", command=[sys.executable, "-c", script]) as proc:
        proc.proc.wait(timeout=20)
        with pytest.raises(MpcProcessError, match=r"(?s)exited with code 3 at startup.*"
                                                  r"no such robot: go3"):
            proc.check_alive("at startup")


def test_waiting_gives_up_after_the_timeout_with_the_child_output():
    sleeper = "import time; print('up', flush=True); time.sleep(60)"
    with MpcProcess("go2", command=[sys.executable, "-c", sleeper]) as proc:
        with pytest.raises(MpcProcessError, match="no first plan within 0.3 s"):
            wait_until(lambda: False, lambda: time.sleep(0.05), proc, 0.3, "first plan")
    assert not process_exists(proc.pid)


def test_memory_and_cpu_of_a_process_are_read_from_proc():
    mem = process_memory_mb(os.getpid())
    assert 10 < mem["current"] <= mem["peak"]
    assert process_cpu_seconds(os.getpid()) > 0
    assert math.isnan(process_memory_mb(2**22 + 12345)["peak"])  # no such process
    assert math.isnan(process_cpu_seconds(2**22 + 12345))


def _status(ticks: int, solve_ms: float, misses: int = 0) -> DiagnosticArray:
    values = {"solve_time_ms": solve_ms, "iterations": 1, "deadline_misses": misses,
              "ticks": ticks, "stale_skips": 0, "command": [0.3, 0.0, 0.0]}
    msg = DiagnosticArray(status=[DiagnosticStatus(
        name="mpc: walking MPC", values=[KeyValue(key=k, value=str(v)) for k, v in
                                         values.items()])])
    msg.header.stamp = Time(sec=1, nanosec=20_000_000 * ticks)
    return msg


def test_the_monitor_records_ticks_plans_and_counters():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        now = [1_100_000_000]
        monitor = MpcMonitor(lambda: now[0], context=ctx)
        monitor._on_diagnostics(_status(1, 30.0))
        monitor._on_diagnostics(_status(2, 11.0, misses=1))
        monitor._on_diagnostics(_status(2, 11.0, misses=1))  # a stale skip: no new tick
        plan = JointTrajectory()
        plan.header.stamp = Time(sec=1, nanosec=80_000_000)
        monitor._on_plan(plan)
        rec = monitor.record
        assert rec.tick_t == pytest.approx([1.02, 1.04])
        assert rec.tick_time == pytest.approx([0.030, 0.011])
        assert rec.counters["deadline_misses"] == 1 and rec.counters["ticks"] == 2
        assert rec.command == [0.3, 0.0, 0.0]
        assert rec.plan_t == pytest.approx([1.08]) and rec.plan_age == pytest.approx([0.02])
        assert monitor.plans == 1
        monitor.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
