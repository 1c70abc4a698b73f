"""The closed loop, through the ROS topics: lockstep (sim_node + mpc_node in one process,
the acceptance tests) and real time (mpc_node in a process of its own)."""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import Twist
from processes import process_exists

from horizon_mpc.closed_loop import (
    DEFAULT_PROFILE,
    Push,
    Recording,
    Segment,
    command_at,
    load_profile,
    load_pushes,
    main,
    run,
)
from horizon_mpc.closed_loop_report import roll_pitch_yaw, summarise, write_report
from horizon_mpc.nodes.mpc_process import MpcProcess, MpcProcessError, private_domain_id


def test_the_default_profile_is_the_documented_one():
    segs = load_profile(DEFAULT_PROFILE)
    assert [(s.duration, s.vx, s.vy, s.wz) for s in segs] == [
        (1.0, 0.0, 0.0, 0.0), (4.0, 0.3, 0.0, 0.0), (3.0, 0.0, 0.2, 0.0),
        (3.0, 0.0, 0.0, 0.5), (2.0, 0.0, 0.0, 0.0)]


def test_command_at_follows_the_segments_then_stops():
    segs = [Segment(1.0), Segment(2.0, vx=0.3)]
    np.testing.assert_array_equal(command_at(segs, 0.5), [0, 0, 0])
    np.testing.assert_array_equal(command_at(segs, 1.0), [0.3, 0, 0])
    np.testing.assert_array_equal(command_at(segs, 3.5), [0, 0, 0])


def test_pushes_are_read_from_the_profile(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("segments:\n  - {duration: 1.0}\npushes:\n"
                    "  - {time: 0.5, force: [0, 40, 0], duration: 0.2}\n")
    assert load_pushes(path) == [Push(0.5, (0.0, 40.0, 0.0), 0.2)]
    assert load_pushes(DEFAULT_PROFILE) == []
    path.write_text("segments:\n  - {duration: 1.0}\npushes:\n  - {time: 0.5, force: [1, 2]}\n")
    with pytest.raises(ValueError, match="push 0"):
        load_pushes(path)


def test_a_bad_profile_names_the_problem(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("- {duration: 1.0, vz: 2.0}\n")
    with pytest.raises(ValueError, match="segment 0"):
        load_profile(path)


@pytest.mark.parametrize("text, match", [
    ("- {duration: .inf}\n", "duration must be finite"),            # ran forever
    ("- {duration: 1.0, vx: .nan}\n", "vx must be finite"),
    ("- {duration: 1.0, vx: 50}\n", "beyond 10"),                    # the node rejects it
    ("- {duration: 1.0, vx: fast}\n", "vx must be a number, got 'fast'"),
    ("- {duration: true}\n", "duration must be a number"),            # read as 1.0
    ("- 1.0\n", "segment 0 must be a mapping"),                       # a raw TypeError
    ("segmnts:\n  - {duration: 1.0}\n", r"unknown key\(s\) \['segmnts'\]"),
    ("segments: [{duration: 1.0\n", "not valid YAML"),
    ("- {duration: 2, vx: 0.2, 1: 3}\n", r"only vx/vy/wz, got \['1', 'duration', 'vx'\]"),
], ids=["inf", "nan", "absurd", "string", "bool", "scalar", "typo", "yaml", "int_key"])
def test_profile_segments_that_cannot_run_are_refused(tmp_path, text, match):
    path = tmp_path / "p.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_profile(path)


def test_a_run_from_python_checks_what_the_cli_checks():
    """run() from Python: a NaN duration never ended, a misspelt mpc parameter ran the
    default without a word, a negative segment ran 1 tick (an auditor of the API)."""
    for kwargs, match in (({"duration": float("nan")}, "duration must be a finite"),
                          ({"duration": -1.0}, "duration must be a finite"),
                          ({"iterations": 0}, "iterations must be an integer >= 1"),
                          ({"mpc_parameters": {"n_nodez": 3}},
                           "mpc_parameters: n_nodez: mpc_node has no such parameter"),
                          ({"mpc_parameters": {"trigger": "timer"}},
                           "set by the closed loop itself")):
        with pytest.raises(ValueError, match=match):
            run("go2", [Segment(0.5)], gif=False, **kwargs)
    for args, match in (((-1.0, 0.2), "non-positive duration"),
                        ((1.0, float("nan")), "vx must be finite"),
                        ((1.0, 0.0, 50.0), "beyond 10")):
        with pytest.raises(ValueError, match=match):
            Segment(*args)
    with pytest.raises(ValueError, match="time must be >= 0"):
        Push(-1.0, (1.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="force must be a list"):
        Push(1.0, (1.0, 0.0))


@pytest.mark.parametrize("push, match", [
    ("{time: 0.5, force: '123'}", r"force must be a list"),            # read as (1, 2, 3)
    ("{time: .nan, force: [1, 0, 0]}", "time must be finite"),         # never applied
    ("{time: -3, force: [1, 0, 0]}", "time must be >= 0"),
    ("{time: 0.5, force: [1e9, 0, 0]}", "force beyond"),              # crashed after the build
    ("{time: 0.5, force: [1, 0, 0], duraton: 1}", "needs 'time', 'force'"),  # ignored
], ids=["string", "nan", "negative", "huge", "typo"])
def test_pushes_that_cannot_run_are_refused(tmp_path, push, match):
    path = tmp_path / "p.yaml"
    path.write_text(f"segments:\n  - {{duration: 1.0}}\npushes:\n  - {push}\n")
    with pytest.raises(ValueError, match=match):
        load_pushes(path)


def test_yaml_numbers_without_a_dot_are_numbers(tmp_path):
    # YAML 1.1 reads 1e3 as a string
    path = tmp_path / "p.yaml"
    path.write_text("segments:\n  - {duration: 2}\npushes:\n  - {time: 1, force: [1e3, 0, 0]}\n")
    assert load_pushes(path) == [Push(1.0, (1000.0, 0.0, 0.0), 0.1)]


@pytest.mark.parametrize("args, match", [
    (["--duration", "0"], "--duration must be"),
    (["--robot", "nosuch"], "no robot config 'nosuch'"),
    (["-p", "nosuch=1"], "mpc_node has no such parameter"),           # silently ignored
    (["-p", "robot=solo12"], "set by the closed loop"),                # hung
    (["-p", "max_vx=abc"], "expecting type 'DOUBLE'"),               # a raw traceback
    (["-p", "gait=gallop"], "unknown gait 'gallop'"),                 # traceback, exit 1
    (["-p", "w_posture=-1"], "w_posture"),                            # traceback, exit 1
    (["-s", "lockstep_latncy=0.004"], "expected NAME=VALUE"),
    (["-s", "lockstep_latency=-0.004"], "must be finite and >= 0"),
    (["-s", "lockstep_latency=0.012", "-s", "lockstep_state_offset=0.004", "-s",
      "lockstep_latency_jitter=0.004"], "shorter than control_period"),
    (["-s", "lockstep_seed=99999999999999999999"], "must be in [0, 2^63)"),  # traceback
    (["--mode", "realtime", "-s", "lockstep_latency=0.004"], "lockstep mode only"),
    (["-p", "control_rate=0"], "control_rate"),  # a ZeroDivisionError traceback
], ids=["duration", "robot", "unknown_param", "harness_param", "param_type", "gait",
        "weight", "sim_param_name", "sim_param_value", "sim_param_sum", "sim_param_seed",
        "sim_param_realtime", "control_rate_zero"])
def test_the_cli_refuses_what_cannot_run_in_one_line_with_code_2(tmp_path, caplog, args, match):
    from horizon_mpc.closed_loop import main

    profile = tmp_path / "p.yaml"
    profile.write_text("- {duration: 0.5}\n")
    with caplog.at_level("ERROR"):
        assert main(["--profile", str(profile), "--out", str(tmp_path / "out"), "--no-gif",
                     *args]) == 2
    assert any(match in r.getMessage() for r in caplog.records), caplog.text


def test_a_refused_command_line_leaves_no_output_folder(tmp_path):
    from horizon_mpc.closed_loop import main

    out = tmp_path / "deep" / "out"
    assert main(["--duration", "-1", "--out", str(out), "--no-gif"]) == 2
    assert not (tmp_path / "deep").exists()  # it was made before the arguments were checked


def test_an_out_that_is_not_a_folder_is_refused_before_the_run(tmp_path, caplog):
    """It was found when the report was written, after the run: a traceback, the run lost."""
    from horizon_mpc.closed_loop import main

    out = tmp_path / "afile"
    out.write_text("")
    with caplog.at_level("ERROR"):
        assert main(["--out", str(out), "--no-gif", "--duration", "0.5"]) == 2
    assert "exists and is not a folder" in caplog.text


def test_a_profile_is_any_file_given_by_path_and_its_problems_name_it(tmp_path):
    text = tmp_path / "walk.txt"  # was 'no command profile ...; available: default'
    text.write_text("- {duration: 1.0, vx: 0.2}\n")
    assert load_profile(text) == [Segment(1.0, vx=0.2)]
    folder = tmp_path / "dir.yaml"  # was 'does not exist'
    folder.mkdir()
    with pytest.raises(FileNotFoundError, match="is a folder"):
        load_profile(folder)
    binary = tmp_path / "b.yaml"  # was a bare 'utf-8' codec error
    binary.write_bytes(b"\xff\xfe\x00segments")
    with pytest.raises(ValueError, match=r"b\.yaml: not a text file"):
        load_profile(binary)


def _steady_recording(seconds: float, v: np.ndarray, **fields) -> Recording:
    """A go2-sized recording, standing pose, base velocity ``v`` (18,), every 0.02 s."""
    rec = Recording(**fields)
    q0 = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, np.zeros(12)]
    for ti in np.arange(0.0, seconds, 0.02):
        rec.t.append(float(ti))
        rec.q.append(q0)
        rec.v.append(v)
        rec.cmd.append(np.zeros(3))
        rec.cmd_mpc.append(np.zeros(3))
        rec.contact.append(np.ones(4, bool))
    return rec


def test_a_segment_the_duration_cut_short_says_so():
    rec = _steady_recording(2.0, np.zeros(18))
    segs = summarise(rec, [Segment(1.5), Segment(3.5, vx=0.2), Segment(1.0)])["segments"]
    assert "cut_short" not in segs[0] and segs[0]["end"] == 1.5
    assert segs[1]["cut_short"] and segs[1]["planned_end"] == 5.0
    assert segs[1]["end"] == pytest.approx(1.98)
    assert segs[2]["cut_short"] and segs[2]["samples"] == 0 and "mean" not in segs[2]
    # never reached (it starts at 5.0 s, the run ended at 2 s): no end of its own (its end
    # was its start, 5.0, a time the run never saw)
    assert segs[2]["end"] is None and segs[2]["reached"] is False
    assert "reached" not in segs[1] and segs[2]["planned_end"] == 6.0


def test_the_mpc_parameter_names_are_the_nodes(walking_mpc_node_parameters):
    from horizon_mpc.nodes.mpc_parameters import parameter_names

    rclpys_own = {"use_sim_time", "start_type_description_service"}
    assert set(parameter_names()) == walking_mpc_node_parameters - rclpys_own


@pytest.fixture
def walking_mpc_node_parameters():
    import rclpy

    from horizon_mpc.nodes.mpc_node import MpcNode

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = MpcNode(context=ctx)
        names = set(node._parameters)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return names


# the acceptance profile of the closed-loop issue (lockstep, through the ROS topics)
STAND, FORWARD_T, LATERAL_T, TURN_T, STOP_T = 1.0, 8.0, 3.0, 3.0, 3.0
FORWARD, LATERAL, YAW_RATE = 0.3, 0.2, 0.5
ACCEPTANCE = [Segment(STAND), Segment(FORWARD_T, vx=FORWARD), Segment(LATERAL_T, vy=LATERAL),
              Segment(TURN_T, wz=YAW_RATE), Segment(STOP_T)]


def _window(rec, t0: float, t1: float) -> np.ndarray:
    t = np.asarray(rec.t)
    return (t >= t0 - 1e-9) & (t < t1 - 1e-9)


@pytest.fixture(scope="module")
def acceptance_run(tmp_path_factory):
    """go2 trot: stand, 8 s forward, 3 s lateral, 3 s turning, stop; with the report."""
    rec = run("go2", ACCEPTANCE, mode="lockstep", gif=True, stop_after_fall=0.5)
    summary = summarise(rec, ACCEPTANCE, robot="go2")
    out = tmp_path_factory.mktemp("closed_loop")
    return rec, summary, write_report(rec, summary, out), out


@pytest.mark.slow
def test_the_run_writes_summary_plots_and_gif(acceptance_run):
    rec, summary, written, out = acceptance_run
    names = {p.name for p in written}
    assert {"summary.json", "velocity_tracking.png", "base_pose.png", "contacts.png",
            "solve_time.png", "run.gif"} <= names
    assert all((out / n).stat().st_size > 0 for n in names)
    data = json.loads((out / "summary.json").read_text())
    for key in ("segments", "distance_travelled", "falls", "tick_time_ms", "deadline_misses",
                "real_time_factor", "ticks_per_sim_second", "plan_age_ms", "bootstrap_ms"):
        assert key in data
    # lockstep: one MPC tick per control period (20 ms), each on a state published by the
    # sim, the last recorded one included
    assert summary["ticks"] == len(rec.t)
    assert summary["ticks_per_sim_second"] == pytest.approx(50, rel=1e-9)
    assert summary["periods_without_tick_percent"] == pytest.approx(0.0, abs=1e-9)
    assert summary["plan_age_ms"]["max"] == 0  # the sim waits for every plan
    # isolated: a private domain, nobody else heard
    assert data["domain_id"] == private_domain_id() and data["foreign_publishers"] == []


@pytest.mark.slow
def test_the_robot_stands_still_before_the_first_command(acceptance_run):
    rec, _, _, _ = acceptance_run
    q = np.asarray(rec.q)[_window(rec, 0.0, STAND)]
    assert len(q) >= STAND / 0.02 - 1
    assert np.linalg.norm(q[-1, :2] - q[0, :2]) < 0.02


@pytest.mark.slow
def test_the_robot_never_falls(acceptance_run):
    rec, summary, _, _ = acceptance_run
    assert summary["falls"]["count"] == 0, summary["falls"]
    assert rec.t[-1] >= sum(s.duration for s in ACCEPTANCE) - 0.05  # the whole profile ran
    assert summary["min_base_height"] > 0.6 * rec.nominal_height
    assert summary["max_abs_roll_pitch"] < 0.5


@pytest.mark.slow
def test_forward_walking_tracks_the_command(acceptance_run):
    """Mean forward velocity over the last 5 s within 15 %; lateral drift < 0.3 m and yaw
    drift < 0.2 rad over the forward segment."""
    rec, _, _, _ = acceptance_run
    t0, t1 = STAND, STAND + FORWARD_T
    v = np.asarray(rec.v)[_window(rec, t1 - 5.0, t1)]
    assert v[:, 0].mean() == pytest.approx(FORWARD, rel=0.15)
    q = np.asarray(rec.q)[_window(rec, t0, t1)]
    yaw = np.unwrap(roll_pitch_yaw(q[:, 3:7])[:, 2])
    heading = np.array([np.cos(yaw[0]), np.sin(yaw[0])])
    d = q[-1, :2] - q[0, :2]
    assert abs(heading[0] * d[1] - heading[1] * d[0]) < 0.3
    assert abs(yaw[-1] - yaw[0]) < 0.2


@pytest.mark.slow
@pytest.mark.parametrize("axis, segment, command", [(1, 2, LATERAL), (5, 3, YAW_RATE)])
def test_lateral_and_turning_phases_track_within_20_percent(acceptance_run, axis, segment,
                                                            command):
    rec, _, _, _ = acceptance_run
    start = sum(s.duration for s in ACCEPTANCE[:segment])
    end = start + ACCEPTANCE[segment].duration
    v = np.asarray(rec.v)[_window(rec, start + 1.0, end)]  # after 1 s of transition
    assert v[:, axis].mean() == pytest.approx(command, rel=0.2)


@pytest.mark.slow
def test_the_robot_stands_within_2_s_of_the_stop(acceptance_run):
    rec, _, _, _ = acceptance_run
    start = sum(s.duration for s in ACCEPTANCE[:4])
    v = np.asarray(rec.v)[_window(rec, start + 2.0, start + STOP_T)]
    assert len(v) > 10
    assert np.max(np.linalg.norm(v[:, :2], axis=1)) < 0.05


@pytest.mark.slow
# two phases of the trot; with 1 ILQR iteration per tick the push at 3.5 s made the go2 fall
# ~2 s later, with 2 (the default since) it walks on after both
@pytest.mark.parametrize("push_time", [3.0, 3.5])
def test_a_lateral_push_during_the_trot_does_not_make_it_fall(push_time):
    """0.1 s at 30 % of body weight, sideways, in the middle of a 0.3 m/s trot."""
    segs = [Segment(STAND), Segment(6.0, vx=FORWARD)]
    weight = 9.81 * 16.085  # go2 mass from the URDF (test_sim_physics checks it)
    rec = run("go2", segs, mode="lockstep", gif=False, stop_after_fall=0.5,
              pushes=[Push(time=push_time, force=(0.0, 0.3 * weight, 0.0), duration=0.1)])
    summary = summarise(rec, segs, robot="go2")
    assert summary["falls"]["count"] == 0, summary["falls"]
    assert rec.t[-1] >= 6.95
    # no GIF, no frame period (it gave 0.05 s for the GIF not made until session 32)
    assert summary["gif_frames"] == 0 and summary["gif_frame_period"] is None
    # it was pushed (lateral speed during the push) and walks on afterwards
    v = np.asarray(rec.v)
    assert np.max(np.abs(v[_window(rec, push_time, push_time + 0.5), 1])) > 0.1
    assert v[_window(rec, 5.5, 7.0), 0].mean() == pytest.approx(FORWARD, rel=0.25)


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["solo12", "anymal_c"])
def test_other_robots_walk_forward_with_their_configs_only(robot):
    segs = [Segment(STAND), Segment(4.0, vx=0.2)]
    rec = run(robot, segs, mode="lockstep", gif=False, stop_after_fall=0.5)
    summary = summarise(rec, segs, robot=robot)
    assert summary["falls"]["count"] == 0, summary["falls"]
    assert rec.t[-1] >= 4.95
    v = np.asarray(rec.v)[_window(rec, 3.0, 5.0)]
    assert v[:, 0].mean() > 0.1  # it walks forward (tracking quality is reported, not gated)


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["solo12", "go2"])
def test_states_sampled_before_the_tick_and_late_plans_do_not_make_it_fall(robot):
    """The real-time loop's delays in lockstep: states 4 ms before each tick, plans applied
    4 ms after their stamp. With a constant-velocity prediction solo12 fell at 2.7 s (vx
    1.1 m/s, yaw rate +-2 rad/s), as it did in real time."""
    segs = [Segment(STAND), Segment(4.0, vx=0.3)]
    rec = run(robot, segs, mode="lockstep", gif=False, stop_after_fall=0.5,
              sim_parameters={"lockstep_state_offset": 0.004, "lockstep_latency": 0.004})
    summary = summarise(rec, segs, robot=robot)
    assert summary["falls"]["count"] == 0, summary["falls"]
    assert rec.t[-1] >= 4.95
    v = np.asarray(rec.v)[_window(rec, 3.0, 5.0)]
    assert v[:, 0].mean() == pytest.approx(0.3, rel=0.2)
    assert np.sqrt(np.mean(v[:, 5] ** 2)) < 0.2  # yaw rate


def test_a_segment_beyond_the_limits_is_scored_against_the_clamped_command():
    """The node clamps 1.2 m/s to the 0.6 limit: a robot doing 0.6 tracked it perfectly;
    a command beyond the combined limit is scored against its scaled-down value."""
    from horizon_mpc.closed_loop import command_limits
    from horizon_mpc.config import load_robot_config

    rec = _steady_recording(3.0, np.r_[0.6, 0.0, 0.0, 0.0, 0.0, -0.3, np.zeros(12)],
                            nominal_height=0.3, max_velocity=[0.6, 0.5, 0.8])
    s = summarise(rec, [Segment(3.0, vx=1.2, wz=-0.3)])
    seg = s["segments"][0]
    assert seg["command"] == {"vx": 1.2, "vy": 0.0, "wz": -0.3}  # what was asked
    assert seg["command_clamped"] == {"vx": 0.6, "vy": 0.0, "wz": -0.3}  # what it got
    assert seg["rmse"]["vx"] == pytest.approx(0.0) and seg["rmse"]["wz"] == pytest.approx(0.0)
    rec.max_velocity = None  # limits unknown: scored against the command as given
    assert summarise(rec, [Segment(3.0, vx=1.2)])["segments"][0]["rmse"]["vx"] == \
        pytest.approx(0.6)
    # all three axes at their limits: beyond the combined limit, scaled down to it
    rec.max_velocity, rec.max_command_norm = [0.6, 0.5, 0.8], math.sqrt(2)
    seg = summarise(rec, [Segment(3.0, vx=0.6, vy=-0.5, wz=-0.8)])["segments"][0]
    scale = math.sqrt(2 / 3)
    assert seg["command_clamped"] == pytest.approx(
        {"vx": 0.6 * scale, "vy": -0.5 * scale, "wz": -0.8 * scale})
    # the limits of a run: the config's, or the node parameters given
    assert command_limits(load_robot_config("solo12")) == ([0.4, 0.3, 0.6], math.sqrt(2))
    assert command_limits(load_robot_config("go2"), {"max_vx": 0.3, "max_command_norm": 2.0}
                          ) == ([0.3, 0.5, 0.8], 2.0)


def test_one_tumble_is_one_fall_and_a_second_fall_later_counts_again():
    """A robot rolling over crosses the tilt threshold back and forth: one fall; a new fall
    more than FALL_EPISODE later: two."""
    from horizon_mpc.closed_loop_report import FALL_EPISODE

    def recording(tilted_at):
        rec = Recording(nominal_height=0.3)
        for ti in np.arange(0.0, 8.0, 0.02):
            tilt = 1.0 if any(a <= ti < b for a, b in tilted_at) else 0.0
            quat = [np.sin(tilt / 2), 0.0, 0.0, np.cos(tilt / 2)]  # roll = tilt
            rec.t.append(float(ti))
            rec.q.append(np.r_[0.0, 0.0, 0.3, quat, np.zeros(12)])
            rec.v.append(np.zeros(18))
            rec.cmd.append(np.zeros(3))
            rec.cmd_mpc.append(np.zeros(3))
            rec.contact.append(np.ones(4, bool))
        return rec

    tumble = [(2.0, 2.3), (2.5, 2.9), (3.1, 4.0)]  # three onsets within 1.1 s
    assert summarise(recording(tumble), [Segment(8.0)])["falls"]["times"] == \
        pytest.approx([2.0])
    later = [*tumble, (3.1 + FALL_EPISODE + 1.0, 8.0)]
    falls = summarise(recording(later), [Segment(8.0)])["falls"]
    assert falls["count"] == 2 and falls["times"] == pytest.approx([2.0, 6.1])


# ---------------------------------------------------------------------- summary of the ticks
def test_the_summary_counts_ticks_per_sim_second_and_keeps_the_bootstrap_apart():
    """10 control periods of 20 ms, 9 ticks (one period missed), the first one the bootstrap."""
    rec = Recording(nominal_height=0.3)
    t = np.arange(10) * 0.02
    q0 = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, np.zeros(12)]
    for ti in t:
        rec.t.append(float(ti))
        rec.q.append(q0)
        rec.v.append(np.zeros(18))
        rec.cmd.append(np.zeros(3))
        rec.cmd_mpc.append(np.zeros(3))
        rec.contact.append(np.ones(4, bool))
    rec.tick_t = [float(x) for x in np.delete(t, 5)]
    rec.tick_time = [0.050] + [0.010] * 7 + [0.030]
    rec.plan_t = list(rec.tick_t)
    rec.plan_age = [0.0] * 4 + [0.012] * 5
    rec.deadline_misses, rec.wall_time = 1, 0.2
    s = summarise(rec, [Segment(0.2)], mode="realtime")
    assert s["ticks"] == 9
    assert s["ticks_per_sim_second"] == pytest.approx(45.0)  # 9 ticks in 10 periods of 20 ms
    assert s["periods_without_tick_percent"] == pytest.approx(10.0)
    assert s["bootstrap_ms"] == pytest.approx(50.0)
    assert s["tick_time_ms"]["median"] == pytest.approx(10.0)
    assert s["tick_time_ms"]["max"] == pytest.approx(30.0)
    assert s["deadline_miss_percent"] == pytest.approx(12.5)  # 1 of the 8 ticks after the bootstrap
    assert s["plan_age_ms"]["median"] == pytest.approx(12.0)
    # a lockstep run's long ticks are overruns (the simulator waited), not misses
    rec.deadline_misses, rec.overruns = 0, 2
    s = summarise(rec, [Segment(0.2)], mode="lockstep")
    assert (s["deadline_misses"], s["overruns"]) == (0, 2)


@pytest.mark.slow
def test_a_lockstep_run_reports_another_node_publishing_on_its_domain(tmp_path, caplog):
    """Two lockstep runs on one domain corrupted each other silently (a1 counted 96 ticks
    per sim second): a foreign cmd_vel publisher on the run's domain is reported."""
    domain = private_domain_id(os.getpid() + 1)
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=domain)
    try:
        intruder = rclpy.create_node("intruder", context=ctx)
        intruder.create_publisher(Twist, "cmd_vel", 10)
        rec = run("go2", [Segment(2.5)], mode="lockstep", gif=False, domain_id=domain)
        profile = tmp_path / "stand.yaml"
        profile.write_text("segments:\n  - {duration: 1.5}\n")
        code = main(["--profile", str(profile), "--domain-id", str(domain), "--no-gif",
                     "--out", str(tmp_path / "out")])
        intruder.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    assert rec.domain_id == domain
    assert rec.foreign_publishers == ["cmd_vel: 2 publishers, 1 expected"]
    assert code == 1 and "the run was not isolated" in caplog.text  # the CLI fails the run


def test_the_cli_refuses_a_domain_id_ros_cannot_use(caplog):
    assert main(["--domain-id", "233", "--no-gif"]) == 2
    assert "--domain-id must be in 0..232" in caplog.text


# ---------------------------------------------------------------------- real-time mode
def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.fixture
def started_processes(monkeypatch):
    """The MpcProcess objects a real-time run starts (to check on them afterwards)."""
    started = []
    original = MpcProcess.start

    def start(self):
        started.append(self)
        return original(self)

    monkeypatch.setattr(MpcProcess, "start", start)
    return started


REALTIME_SHORT = [Segment(1.0), Segment(1.5, vx=0.2)]


@pytest.fixture(scope="module")
def realtime_run(tmp_path_factory):
    """go2 in real time for 2.5 s (stand 1 s, forward 0.2 m/s), MPC in its own process."""
    rec = run("go2", REALTIME_SHORT, mode="realtime", gif=True)
    summary = summarise(rec, REALTIME_SHORT, mode="realtime", robot="go2")
    out = tmp_path_factory.mktemp("closed_loop_realtime")
    return rec, summary, write_report(rec, summary, out)


@pytest.mark.slow
def test_realtime_mode_runs_the_mpc_in_a_second_process(realtime_run):
    rec, summary, _ = realtime_run
    child = summary["mpc_process"]
    assert child["pid"] != os.getpid() and child["exit_code"] == 0
    assert not process_exists(child["pid"])  # stopped and reaped at the end of the run
    assert child["memory_mb"]["peak"] > 50  # it built a walking MPC of its own
    assert child["cpu_s"] > 0.1 * summary["sim_time"]
    assert "bootstrapped" in rec.mpc_log  # its output is kept
    assert summary["domain_id"] == child["domain_id"] and summary["foreign_publishers"] == []


def test_a_report_removes_the_earlier_runs_files_before_writing_its_own(tmp_path):
    """A Ctrl-C while a real-time run's report was written left the earlier (lockstep)
    run's plots and GIF beside the new summary (session 28 audit): they go first."""
    from horizon_mpc.closed_loop_report import REPORT_FILES

    for name in REPORT_FILES:
        (tmp_path / name).write_text("an earlier run's\n")
    (tmp_path / "mine.txt").write_text("the user's\n")
    rec = Recording()  # no period recorded: the summary (and log) only, as when interrupted
    rec.mpc_log = "log"
    written = write_report(rec, {"robot": "go2"}, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mine.txt", "mpc_node.log",
                                                           "summary.json"]
    assert [p.name for p in written] == ["summary.json", "mpc_node.log"]


@pytest.mark.slow
def test_a_report_without_a_gif_or_a_log_removes_an_earlier_runs(realtime_run, tmp_path):
    """A --no-gif (or lockstep) run into the folder of an earlier real-time run with a GIF
    left that run's run.gif and mpc_node.log beside its own summary."""
    import copy
    import shutil

    rec, summary, written = realtime_run
    out = tmp_path / "reused"
    shutil.copytree(written[0].parent, out)
    assert (out / "run.gif").exists() and (out / "mpc_node.log").exists()
    lean = copy.copy(rec)
    lean.frames, lean.mpc_log = [], ""
    files = write_report(lean, summary, out)
    assert not (out / "run.gif").exists() and not (out / "mpc_node.log").exists()
    assert all(p.exists() for p in files)


@pytest.mark.slow
def test_realtime_mode_hears_the_ticks_of_the_child_through_ros(realtime_run):
    """Structure and sane bounds only: real time on a shared machine is noisy."""
    rec, summary, _ = realtime_run
    assert rec.t[-1] >= 2.5 - 0.05
    assert 0.5 < summary["real_time_factor"] < 1.1  # the sim keeps to the wall clock
    assert 10 < summary["ticks_per_sim_second"] <= 51  # a timer at 50 Hz on the sim clock
    # plans counted as the sim got them, tick times from the diagnostics published just
    # after each plan: the run may end between the two (110 plans, 109 ticks on a loaded
    # machine, session 28)
    assert len(rec.tick_time) == len(rec.tick_iterations)
    assert 0 <= summary["ticks"] - len(rec.tick_time) <= 1
    assert all(i >= 1 for i in rec.tick_iterations)
    assert 0 < summary["tick_time_ms"]["median"] < summary["tick_time_ms"]["max"] < 1000
    assert np.isfinite(summary["bootstrap_ms"])
    # every plan is stamped with the state it started from: the sim got it later, never before
    # the run may end between the last plan and its diagnostics (published just after it)
    assert summary["ticks"] - 2 <= len(rec.plan_age) <= summary["ticks"] + 1
    assert min(rec.plan_age) >= 0 and summary["plan_age_ms"]["median"] < 500
    assert 0 <= summary["deadline_misses"] <= summary["ticks"]
    # the MPC's ramped command, read from its diagnostics, follows the profile's 0.2 m/s:
    # standing before it, 0.2 in the last half second (the run waits for the MPC's cmd_vel
    # subscription before its clock starts; once a loaded machine lost the command)
    t, cmd = np.asarray(rec.t), np.asarray(rec.cmd_mpc)[:, 0]
    assert np.all(np.abs(cmd[t < 0.9]) < 1e-6)
    assert np.median(cmd[t > t[-1] - 0.5]) == pytest.approx(0.2, abs=0.05)


@pytest.mark.slow
def test_realtime_mode_renders_the_gif_afterwards_from_the_recorded_states(realtime_run):
    rec, summary, written = realtime_run
    assert "run.gif" in {p.name for p in written} and "mpc_node.log" in {p.name for p in written}
    assert summary["gif_frames"] == pytest.approx((rec.t[-1] - rec.t[0]) / 0.05 + 1, abs=1)
    assert rec.frames[0].shape == (240, 320, 3)


def test_a_long_runs_gif_frames_are_spread_out_to_bound_their_memory():
    """Every frame is held until the GIF is written: a 40 s run held 400 MB more with its
    GIF than without (session 28 audit). At most MAX_GIF_FRAMES frames, further apart."""
    from horizon_mpc.closed_loop import _Loop
    from horizon_mpc.closed_loop_report import MAX_GIF_FRAMES, gif_frame_period

    assert gif_frame_period(10.0) == 0.05 and gif_frame_period(19.95) == 0.05
    for duration in (20.0, 38.0, 40.0, 100.0, 600.0):  # frames at both ends: at most MAX
        period = gif_frame_period(duration)
        assert 0.8 * MAX_GIF_FRAMES < len(np.arange(0.0, duration + 1e-9, period)) \
            <= MAX_GIF_FRAMES, duration
        # whole centiseconds, what a GIF stores (95.2 ms played as 90: 5 % fast)
        assert period * 100 == pytest.approx(round(period * 100), abs=1e-9), duration
    assert gif_frame_period(38.0) == 0.1
    assert gif_frame_period(math.inf) == 0.05
    assert _Loop([Segment(40.0)], 40.0, True, 1.0, []).rec.frame_period == 0.11


def test_an_unknown_robot_fails_before_any_process_starts(started_processes):
    with pytest.raises(FileNotFoundError, match="go3"):
        run("go3", REALTIME_SHORT, mode="realtime")
    assert started_processes == []


def test_an_mpc_process_that_fails_to_start_is_a_clear_error(started_processes):
    with pytest.raises(MpcProcessError,
                       match=r"(?s)exited with code 1 .*state_reliability must be"):
        run("go2", REALTIME_SHORT, mode="realtime", gif=False,
            mpc_parameters={"state_reliability": "sometimes"})
    assert len(started_processes) == 1 and not started_processes[0].alive()


@pytest.mark.slow
def test_the_mpc_process_is_stopped_when_the_run_raises(started_processes, monkeypatch):
    import horizon_mpc.closed_loop as closed_loop

    def boom(*_):
        raise RuntimeError("boom in the run loop")

    monkeypatch.setattr(closed_loop, "command_at", boom)  # first called after the first plan
    with pytest.raises(RuntimeError, match="boom in the run loop"):
        run("go2", REALTIME_SHORT, mode="realtime", gif=False)
    (child,) = started_processes
    assert child.returncode == 0  # SIGINT: a clean exit
    assert not process_exists(child.pid)


def _start_cli_and_wait_for_its_child(tmp_path: Path) -> tuple[subprocess.Popen, int]:
    """``closed_loop --mode realtime`` for a long profile; returns it and its MPC process."""
    profile = tmp_path / "long.yaml"
    profile.write_text("- {duration: 60.0}\n")
    # stderr to a file (a pipe nobody reads could fill and block the parent); with the
    # fault handler, SIGABRT makes it write every thread's stack there (see _stop_or_dump)
    with (tmp_path / "closed_loop.stderr").open("w") as err:
        parent = subprocess.Popen(
            [sys.executable, "-m", "horizon_mpc.closed_loop", "--mode", "realtime",
             "--no-gif", "--profile", str(profile), "--out", str(tmp_path / "out")],
            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path),
                 "PYTHONFAULTHANDLER": "1"},
            stdout=subprocess.DEVNULL, stderr=err)
    deadline = time.monotonic() + 120
    children: list[int] = []
    while not children and time.monotonic() < deadline and parent.poll() is None:
        time.sleep(0.2)
        children = _children(parent.pid)
    assert children, "the closed loop started no MPC process"
    time.sleep(1.0)  # let the parent reach its run loop or readiness wait
    return parent, children[0]


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_no_mpc_process_outlives_a_stopped_or_killed_closed_loop(tmp_path, sig):
    """SIGINT (Ctrl-C): the parent stops its child on the way out. SIGKILL: no cleanup can
    run, the kernel sends the child SIGTERM (parent-death signal)."""
    parent, child = _start_cli_and_wait_for_its_child(tmp_path)
    try:
        parent.send_signal(sig)
        _wait_or_dump(parent, 60, tmp_path / "closed_loop.stderr")
        deadline = time.monotonic() + 30
        while process_exists(child) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not process_exists(child) or _zombie(child), (
            f"mpc_node {child} outlived its parent; its output ends with:\n"
            + _stacks_of(child))
    finally:
        for pid in (parent.pid, child):
            if process_exists(pid):
                os.kill(pid, signal.SIGKILL)
        parent.wait(timeout=10)


def _wait_or_dump(proc: subprocess.Popen, timeout: float, stderr: Path) -> None:
    """Wait for ``proc``; if it does not exit in time, make it dump its threads' stacks
    (SIGABRT, fault handler on) and fail with the end of its stderr."""
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=10)
        pytest.fail(f"the closed loop did not exit within {timeout:g} s; its stderr ends "
                    f"with:\n{stderr.read_text(errors='replace')[-6000:]}")


def _stacks_of(pid: int) -> str:
    """The end of a surviving MPC process's output (the dead parent's anonymous temporary
    file, still open in the child as its stdout) after SIGABRT made its fault handler write
    every thread's stack there: what it was stuck in (seen once, in a loaded CI run)."""
    try:
        with open(f"/proc/{pid}/fd/1", "rb") as out:  # opened before the process ends
            os.kill(pid, signal.SIGABRT)
            time.sleep(2.0)
            out.seek(0)
            return out.read().decode(errors="replace")[-6000:]
    except OSError as exc:
        return f"(unreadable: {exc})"


def _zombie(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return False


def test_the_control_period_is_the_nodes(tmp_path):
    """The real-time run stepped and recorded on the config's dt whatever -p dt or
    control_rate said: -p dt=0.03 reported a third of the periods without a tick."""
    from horizon_mpc.closed_loop import control_period

    assert control_period("go2") == pytest.approx(0.02)
    assert control_period("go2", {"dt": 0.03}) == pytest.approx(0.03)
    assert control_period("go2", {"dt": 0.03, "control_rate": 25.0}) == pytest.approx(0.04)
    # a value that is no number: the same one-line error as 0 (a traceback, exit 1, before)
    from horizon_mpc.closed_loop import SettingError

    for given in ({"dt": "abc"}, {"control_rate": [50]}, {"control_rate": True},
                  {"dt": 0.0}):
        with pytest.raises(SettingError, match="must be a finite number > 0"):
            control_period("go2", given)


def test_the_lockstep_loop_steps_at_the_nodes_control_rate():
    """Lockstep stepped the simulator by the node dt whatever control_rate said: with -p
    control_rate=100 every tick was a prepare miss (states 20 ms apart for ticks prepared
    10 ms ahead)."""
    segs = [Segment(0.5)]
    rec = run("go2", segs, mode="lockstep", gif=False, mpc_parameters={"control_rate": 25.0})
    summary = summarise(rec, segs, robot="go2")
    assert summary["ticks_per_sim_second"] == pytest.approx(25, rel=1e-9)
    assert summary["periods_without_tick_percent"] == pytest.approx(0.0, abs=1e-9)
    assert rec.prepare_misses == 0  # each tick on the state it prepared for


@pytest.mark.slow
def test_a_control_rate_faster_than_the_nodes_walks_on_nodes_of_its_period():
    """-p control_rate=100 with the config's 0.02 s nodes: half a node a tick, and go2 fell
    at 2.9 s. A faster control rate now sets dt (0.01 s) and the nodes (48, the same
    0.48 s horizon) unless they are given: it walks, tracking as at 50 Hz."""
    segs = [Segment(1.0), Segment(3.0, 0.3)]
    rec = run("go2", segs, mode="lockstep", gif=False, mpc_parameters={"control_rate": 100})
    summary = summarise(rec, segs, robot="go2")
    assert summary["falls"]["count"] == 0
    assert summary["ticks_per_sim_second"] == pytest.approx(100, rel=1e-9)
    assert rec.prepare_misses == 0
    assert summary["segments"][1]["mean"]["vx"] == pytest.approx(0.3, abs=0.03)


def _interrupt_the_loop_at(monkeypatch, t_stop: float) -> None:
    """Ctrl-C in the closed loop's first control period at or after ``t_stop`` (sim s)."""
    from horizon_mpc import closed_loop

    period = closed_loop._Loop.period

    def interrupting(loop, sim, t, *args, **kwargs):
        if t >= t_stop:
            raise KeyboardInterrupt
        return period(loop, sim, t, *args, **kwargs)

    monkeypatch.setattr(closed_loop._Loop, "period", interrupting)


def test_an_interrupted_run_writes_what_it_has_and_exits_130(tmp_path, monkeypatch, caplog):
    """Ctrl-C (or SIGTERM, which the CLI turns into the same) printed a traceback and left
    an empty output folder."""
    from horizon_mpc import closed_loop

    _interrupt_the_loop_at(monkeypatch, 0.6)
    out = tmp_path / "out"
    with caplog.at_level("WARNING"):
        assert closed_loop.main(["--out", str(out), "--no-gif", "--duration", "2"]) == 130
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 0.55 <= summary["sim_time"] <= 0.65
    assert summary["ticks_per_sim_second"] > 45 and summary["wall_time"] > 0  # kept
    assert "interrupted at t = 0.58 s" in caplog.text


def test_a_ctrl_c_while_the_outputs_are_written_keeps_the_summary(tmp_path, monkeypatch,
                                                                    caplog):
    """Ctrl-C just after the run, while matplotlib was imported and the plots drawn: a
    traceback and no output at all (a reviewer's `timeout -s INT`). The summary is written
    first; the interruption says what was written, exit code 130."""
    import matplotlib.figure

    from horizon_mpc import closed_loop

    def interrupted_plot(*_args, **_kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", interrupted_plot)
    out = tmp_path / "out"
    with caplog.at_level("ERROR"):
        assert closed_loop.main(["--out", str(out), "--no-gif", "--duration", "0.2"]) == 130
    assert json.loads((out / "summary.json").read_text())["sim_time"] == pytest.approx(0.2)
    assert f"interrupted while writing the outputs to {out}: written ['summary.json'], " \
        "the rest not" in caplog.text
    assert not list(out.glob("*.png"))


@pytest.mark.slow
def test_an_interrupted_realtime_run_keeps_the_mpc_process_figures(tmp_path, monkeypatch):
    """The child's pid, memory and CPU were lost ("mpc_process": {}) when Ctrl-C came, and
    its exit code, which a whole run's summary has, until session 25."""
    from horizon_mpc import closed_loop

    _interrupt_the_loop_at(monkeypatch, 0.6)
    out = tmp_path / "out"
    assert closed_loop.main(["--out", str(out), "--no-gif", "--duration", "2", "--mode",
                             "realtime"]) == 130
    summary = json.loads((out / "summary.json").read_text())
    child = summary["mpc_process"]
    assert summary["interrupted"] is True
    assert child["pid"] != os.getpid() and child["memory_mb"]["peak"] > 50
    assert child["cpu_s"] > 0.0 and not process_exists(child["pid"])
    assert child["exit_code"] == 0


def test_a_signal_after_the_realtime_loop_keeps_its_ticks_and_the_mpc_figures(
        tmp_path, monkeypatch):
    """A Ctrl-C in the last isolation check (up to 2 s after the loop) wrote a summary of no
    tick, no MPC process figures and no mpc_node.log (session 28 audit)."""
    from horizon_mpc import closed_loop

    check = closed_loop._final_isolation_check

    def then_interrupted(*args, **kwargs):
        check(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(closed_loop, "_final_isolation_check", then_interrupted)
    out = tmp_path / "out"
    assert closed_loop.main(["--out", str(out), "--no-gif", "--duration", "1", "--mode",
                             "realtime"]) == 130
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["ticks"] > 10
    assert summary["mpc_process"]["exit_code"] == 0 and (out / "mpc_node.log").is_file()


def test_the_environments_domain_id_is_checked_like_the_option(monkeypatch, caplog,
                                                               tmp_path):
    """ROS_DOMAIN_ID=300 ended a real-time run inside DDS without a word, -1 in a traceback,
    'abc' went to a private domain silently (session 28 audit)."""
    from horizon_mpc.closed_loop import main
    from horizon_mpc.nodes.mpc_process import default_domain_id

    for value in ("300", "-1", "abc"):
        monkeypatch.setenv("ROS_DOMAIN_ID", value)
        with pytest.raises(ValueError, match=f"ROS_DOMAIN_ID='{value}' in the environment"):
            default_domain_id()
        caplog.clear()
        with caplog.at_level("ERROR"):
            assert main(["--mode", "realtime", "--duration", "0.1", "--no-gif", "--out",
                         str(tmp_path / "out")]) == 2
        assert "is no ROS domain (0..232" in caplog.text
        assert not (tmp_path / "out").exists()
    monkeypatch.setenv("ROS_DOMAIN_ID", " 7 ")
    assert default_domain_id() == 7
    monkeypatch.setenv("ROS_DOMAIN_ID", "")
    assert 1 <= default_domain_id() <= 232


def test_a_robot_config_the_nodes_cannot_start_with_is_one_line_exit_2(tmp_path, caplog):
    """A foot that is no link, a missing URDF: tracebacks, exit 1 (the nodes said it in one
    line)."""
    from horizon_mpc.closed_loop import main

    bad = tmp_path / "bad.yaml"
    for text, said in (("robot: go2\nfeet: [FL_foot, FR_footx, RL_foot, RR_foot]\n",
                        "['FR_footx'] are not links of the URDF"),
                       (f"urdf_path: {tmp_path / 'none.urdf'}\nfeet: [a, b, c, d]\n",
                        "none.urdf")):
        bad.write_text(text)
        caplog.clear()
        with caplog.at_level("ERROR"):
            assert main(["--robot", str(bad), "--duration", "0.1", "--no-gif",
                         "--out", str(tmp_path / "out")]) == 2
        assert "cannot run: " in caplog.text and said in caplog.text
        assert "Traceback" not in caplog.text


def test_segments_shorter_than_the_control_period_are_warned_about(monkeypatch, caplog):
    """200 segments of 5 ms alternating 1 and 0 m/s ran as 1 m/s, exit 0: the profile is
    sampled once per 20 ms control period (an auditor's profile)."""
    from horizon_mpc import closed_loop
    from horizon_mpc.closed_loop_profile import Segment

    monkeypatch.setattr(closed_loop, "_run_lockstep", lambda robot, it, loop, *a: loop.rec)
    segments = [Segment(0.005, vx=float(i % 2)) for i in range(4)] + [Segment(1.0)]
    with caplog.at_level("WARNING", logger=closed_loop.__name__):
        closed_loop.run("go2", segments)
    assert "segment(s) [0, 1, 2, 3] last less than the control period (0.02 s)" in caplog.text


@pytest.mark.parametrize("ticks, warned", [(11.0, True), (49.6, False)])
def test_a_run_that_did_not_keep_the_control_rate_says_so(monkeypatch, caplog, tmp_path,
                                                            ticks, warned):
    """A 2 s real-time run on a loaded host ticked 11 times per sim second at 50 Hz and
    said nothing (an auditor's): its figures are no real-time loop's."""
    from types import SimpleNamespace

    from horizon_mpc import closed_loop, closed_loop_report

    summary = {"plan_age_ms": {"median": 4.0, "p95": 6.0}, "sim_time": 2.0, "wall_time": 2.1,
               "real_time_factor": 0.95, "ticks_per_sim_second": ticks,
               "tick_time_ms": {"median": 5.0}, "falls": {"count": 0, "times": []},
               "foreign_publishers": []}
    monkeypatch.setattr(closed_loop, "run", lambda *a, **k: SimpleNamespace(interrupted=False))
    monkeypatch.setattr(closed_loop_report, "summarise", lambda *a, **k: summary)
    monkeypatch.setattr(closed_loop_report, "write_report", lambda *a, **k: None)
    with caplog.at_level("WARNING", logger=closed_loop.__name__):
        assert main(["--mode", "realtime", "--duration", "2", "--no-gif",
                     "--out", str(tmp_path / "out")]) == 0
    said = "the MPC ticked 11.0 times per sim second, 22 % of its 50 Hz control rate"
    assert (said in caplog.text) == warned, caplog.text


@pytest.mark.parametrize("argv0, prog", [
    ("/opt/ws/install/horizon_mpc/lib/horizon_mpc/closed_loop", "closed_loop"),  # ros2 run
    ("/venv/bin/closed_loop", "closed_loop"),
    ("/src/horizon_mpc/closed_loop.py", "python -m horizon_mpc.closed_loop")])
def test_the_usage_names_the_program_the_way_it_was_run(monkeypatch, capsys, argv0, prog):
    """`ros2 run horizon_mpc closed_loop --help` printed `python -m ...` as its usage."""
    monkeypatch.setattr(sys, "argv", [argv0, "--help"])
    with pytest.raises(SystemExit) as exit_:
        main(["--help"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: {prog} [-h]")


def test_a_profile_in_the_working_folder_is_found_by_its_relative_path(tmp_path, monkeypatch):
    """`--profile ./std.txt` was looked up as a profile name (pathlib drops './'): 'no
    command profile'; a bare file name says how to give it (QA finding)."""
    (tmp_path / "std.txt").write_text("segments:\n  - {duration: 2, vx: 0.3}\n")
    monkeypatch.chdir(tmp_path)
    assert [s.duration for s in load_profile("./std.txt")] == [2.0]
    with pytest.raises(FileNotFoundError, match=r"give it as \./std\.txt"):
        load_profile("std.txt")


def test_a_key_given_twice_in_a_profile_is_refused(tmp_path):
    """PyYAML keeps the last: two `segments:` blocks ran the second only, and
    {vx: 0.3, vx: 0.0} as vx 0, exit 0 (QA finding)."""
    for text in ("segments:\n  - {duration: 2, vx: 0.3}\nsegments:\n  - {duration: 1}\n",
                 "segments:\n  - {duration: 2, vx: 0.3, vx: 0.0}\n"):
        path = tmp_path / "dup.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match=r"dup.yaml: not valid YAML \(key '(segments|vx)' "
                                             r"given twice"):
            load_profile(path)


def test_segments_the_commands_ramp_cannot_reach_are_found():
    """+-0.4 m/s flipped every 0.5 s ran a ramped command between -0.1 and +0.4 (1 m/s^2
    needs 0.8 s per flip): go2 ended 0.97 m ahead of a profile averaging zero, with no word
    (QA finding). The closed loop warns about such segments."""
    from horizon_mpc.closed_loop_profile import unreached_segments

    flips = [Segment(1.0)] + [Segment(0.5, vx=0.4 * (-1) ** k) for k in range(12)] + [
        Segment(4.0)]
    found = unreached_segments(flips, [0.6, 0.5, 0.8], [1.0, 1.0, 2.0])
    assert [i for i, _ in found] == list(range(2, 13))  # the first one only rises 0.4
    assert found[0][1] == pytest.approx(0.8)
    # commands are clipped to the limits first; the default profile is reachable
    assert unreached_segments([Segment(0.3, vx=5.0), Segment(1.0)], [0.2, 0.5, 0.8],
                              [1.0, 1.0, 2.0]) == []
    assert unreached_segments(load_profile(DEFAULT_PROFILE), [0.6, 0.5, 0.8],
                              [1.0, 1.0, 2.0]) == []
    # the combined limit as the MPC applies it: (0.6, 0.5, 0.8) is cut to 0.82 of each, and
    # the ramp's accelerations are combined too: (0.49, 0.41, 0.65) takes 0.72 s
    corner = [Segment(0.75, vx=0.6, vy=0.5, wz=0.8), Segment(1.0)]
    assert unreached_segments(corner, [0.6, 0.5, 0.8], [1.0, 1.0, 2.0]) == []
    found = unreached_segments(corner, [0.6, 0.5, 0.8], [1.0, 1.0, 2.0], max_command_norm=2.0)
    assert [i for i, _ in found] == [0] and found[0][1] == pytest.approx(
        math.sqrt(0.6 ** 2 + 0.5 ** 2 + 0.4 ** 2))
    # an axis that cannot accelerate never reaches a command (no 0/0 warnings on the others)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = unreached_segments([Segment(1.0, vx=0.3), Segment(1.0, vy=0.2), Segment(1.0)],
                                   [0.6, 0.5, 0.8], [1.0, 0.0, 2.0])
    assert found == [(1, math.inf)]


def test_the_ramp_warning_uses_the_nodes_command_limits(caplog):
    """It used the config's limits: a +-0.8 m/s flip with -p max_vx=1.0 (1.6 s ramps in 1.2 s
    segments) was not warned about, and with -p gait=walk (a third of the limits) a
    reachable segment was (session 28 audit)."""
    from horizon_mpc.closed_loop import warn_unreached_segments
    from horizon_mpc.config import load_robot_config

    cfg = load_robot_config("go2")
    flips = [Segment(1.0)] + [Segment(1.2, vx=0.8 * (-1) ** k) for k in range(4)] + [
        Segment(2.0)]
    with caplog.at_level("WARNING", logger="horizon_mpc.closed_loop"):
        warn_unreached_segments(flips, cfg, {"max_vx": 1.0})
    assert "segment(s) [2, 3, 4] end before the command's ramp (1.6, 1.6, 1.6 s" in caplog.text
    caplog.clear()
    walk = [Segment(0.3, vx=0.4), Segment(0.3, vx=-0.4), Segment(1.0)]
    with caplog.at_level("WARNING", logger="horizon_mpc.closed_loop"):
        warn_unreached_segments(walk, cfg, {"gait": "walk"})
    assert "segment(s) [1] end before the command's ramp (0.4 s" in caplog.text


def test_a_duration_past_the_profile_is_a_zero_command_segment_of_its_own(tmp_path, caplog):
    """--duration 9 on a 5 s profile: 4 s of zero command, in no segment of the summary
    (its distance counted all the same), without a word (an auditor's endurance run)."""
    from horizon_mpc.closed_loop import main
    from horizon_mpc.closed_loop_profile import with_zero_tail

    assert with_zero_tail([Segment(1.0, vx=0.2)], 3.0) == [Segment(1.0, vx=0.2), Segment(2.0)]
    assert with_zero_tail([Segment(1.0, vx=0.2)], 1.0) == [Segment(1.0, vx=0.2)]
    assert with_zero_tail([Segment(1.0, vx=0.2)], None) == [Segment(1.0, vx=0.2)]
    profile = tmp_path / "short.yaml"
    profile.write_text("segments:\n  - {duration: 0.2, vx: 0.1}\n")
    out = tmp_path / "out"
    with caplog.at_level("INFO"):
        assert main(["--profile", str(profile), "--duration", "0.4", "--out", str(out),
                     "--no-gif"]) == 0
    assert "runs 0.2 s past the profile's end: the command is zero then (segment 1" \
        in caplog.text
    segments = json.loads((out / "summary.json").read_text())["segments"]
    assert [s["command"] for s in segments] == [{"vx": 0.1, "vy": 0.0, "wz": 0.0},
                                                {"vx": 0.0, "vy": 0.0, "wz": 0.0}]
    assert segments[1]["start"] == pytest.approx(0.2)


def test_segments_and_pushes_take_numpy_numbers_and_keep_plain_floats():
    """Push(1.0, np.array([...])) worked before they checked themselves (the simulator takes
    arrays), np.float32 / np.int64 too; a '2' was checked but kept as text (a reviewer)."""
    import numpy as np

    push = Push(np.float32(1.0), np.array([10.0, 0.0, 0.0]))
    assert push.force == (10.0, 0.0, 0.0) and type(push.time) is float
    seg = Segment(np.int64(2), np.float32(0.25))
    assert (seg.duration, seg.vx) == (2.0, 0.25) and type(seg.duration) is float
    assert Segment("2").duration == 2.0
    with pytest.raises(ValueError, match="force must be a list"):
        Push(1.0, [[1.0, 2.0], [3.0]])


def test_fuzzed_profiles_fail_with_a_value_error_naming_the_file(tmp_path):
    """A huge integer was an OverflowError, mixed-type top-level keys a TypeError from
    sorted() (an auditor's fuzzing)."""
    huge = "1" + "0" * 400
    for text, match in ((f"segments: [{{duration: {huge}}}]\n", "duration must be finite"),
                        ("segments: [{duration: 1.0}]\n1: x\nfoo: y\n",
                         r"unknown key\(s\) \['1', 'foo'\]")):
        path = tmp_path / "p.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match=match) as err:
            load_profile(path)
        assert "p.yaml" in str(err.value)
