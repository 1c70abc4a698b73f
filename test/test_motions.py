"""The paper's three motions (issue 6): leap, CENTAURO 90-degree turn, receding-horizon walk.

Each motion is solved once per module (fixtures) with the settings of
``config/motions/<motion>.yaml``; the tests then read the solution the way the issue's
Verification section states it. Dynamic consistency is checked with numeric Pinocchio
(RNEA, CRBA, Jacobians, integrate), independently of the symbolic model the solvers used.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from horizon_mpc.config import load_robot_config
from horizon_mpc.locomotion import make_gait
from horizon_mpc.motions import (
    LeapSettings,
    TurnSettings,
    WalkSettings,
    dynamics_check,
    load_motion_config,
    run_leap,
    run_turn,
    run_walk,
)
from horizon_mpc.motions.analysis import flight_phases, foot_heights, loaded, roll_pitch_yaw
from horizon_mpc.motions.leap import leap_schedule
from horizon_mpc.motions.schedule import (
    crawl_order,
    lift_off_nodes,
    timeline_schedule,
    touchdown_nodes,
)
from horizon_mpc.motions.settings import MotionConfig
from horizon_mpc.motions.turn import turn_schedule
from horizon_mpc.motions.wholebody import build_whole_body, quaternion_error, robot_model
from horizon_mpc.posture import standing_configuration

ROOT = Path(__file__).resolve().parents[1]
G = 9.81


def _settings(motion: str, cls, robot: str, **overrides):
    return load_motion_config(motion).settings_for(cls, robot, overrides)


# --------------------------------------------------------------------------------------------
# Schedules, settings and helpers (fast)

def test_timeline_sampling_puts_lift_off_and_touchdown_nodes_in_stance():
    s = timeline_schedule([[(0.2, 0.6)], []], n_nodes=10, dt=0.1, step_height=0.1)
    np.testing.assert_array_equal(s.stance[0], [1, 1, 1, 0, 0, 0, 1, 1, 1, 1, 1])
    assert s.stance[1].all()
    np.testing.assert_allclose(s.swing_progress[0, 3:6], [0.25, 0.5, 0.75])
    assert s.swing_height()[0].max() == pytest.approx(0.1)  # apex on the middle node
    assert [n.tolist() for n in touchdown_nodes(s.stance)] == [[6], []]
    assert [n.tolist() for n in lift_off_nodes(s.stance)] == [[2], []]


def test_timeline_times_off_the_node_grid_are_named_in_a_warning(caplog):
    """The leap's push of 0.25 s at dt 0.02 was sampled as 0.24 s, its flight as 0.16 s,
    silently; the default timeline is now on the grid and needs no warning."""
    with caplog.at_level("WARNING", logger="horizon_mpc.motions.schedule"):
        s = timeline_schedule([[(0.45, 0.75)]], n_nodes=60, dt=0.02)
    assert "[0.45, 0.75] s are not on the 0.02 s node grid: taken as [0.44, 0.76] s" \
        in caplog.text
    assert np.flatnonzero(~s.stance[0]).tolist() == list(range(23, 38))
    caplog.clear()
    with caplog.at_level("WARNING", logger="horizon_mpc.motions.schedule"):
        st = _settings("leap", LeapSettings, "go2")
        leap_schedule(st, [0, 1], [2, 3])
    assert caplog.text == ""


@pytest.mark.parametrize("intervals", [3, 5, 7])
def test_a_swing_over_an_odd_number_of_intervals_reaches_its_apex_on_the_nodes(intervals):
    # no node at mid-swing: the apex used to be 0.79 (3 intervals) / 0.92 (5) of the height
    s = timeline_schedule([[(0.1, 0.1 + 0.1 * intervals)]], n_nodes=10, dt=0.1,
                          step_height=0.1)
    h = s.swing_height()[0]
    assert h.max() == pytest.approx(0.1) and np.sum(np.isclose(h, 0.1)) == 2
    assert np.all(np.diff(h[:np.argmax(h) + 1]) >= 0)  # up, then down
    assert np.all(np.diff(h[np.argmax(h) + 1:]) <= 0)


@pytest.mark.parametrize("swings, match", [
    ([[(0.2, 0.25)]], "fewer than two"),
    ([[(0.2, 0.6), (0.5, 0.9)]], "overlaps"),
    ([[(0.5, 1.5)]], "leaves the horizon"),
])
def test_timeline_rejects_bad_swings(swings, match):
    with pytest.raises(ValueError, match=match):
        timeline_schedule(swings, n_nodes=10, dt=0.1)


def test_trunk_points_are_the_corners_of_the_base_collision_box():
    """a1's trunk is one collision box (0.2675 x 0.194 x 0.114 m) and a zero-size IMU box;
    anymal_c's base carries boxes and cylinders on links fixed to it."""
    from horizon_mpc.motions.body import point_heights, trunk_points
    from horizon_mpc.posture import load_pin_model

    cfg = load_robot_config("a1")
    pts = trunk_points(cfg, load_pin_model(cfg))
    assert len(pts) == 8
    np.testing.assert_allclose(np.sort(np.unique(np.abs(pts).round(4))),
                               [0.057, 0.097, 0.1338], atol=1e-3)
    q = np.zeros(19)
    q[2], q[6] = 0.3, 1.0
    np.testing.assert_allclose(point_heights(q, pts), 0.3 + pts[:, 2])
    q[3:7] = [np.sin(np.pi / 4), 0.0, 0.0, np.cos(np.pi / 4)]  # 90 deg about x: y goes up
    np.testing.assert_allclose(point_heights(q, pts), 0.3 + pts[:, 1], atol=1e-12)
    cfg = load_robot_config("anymal_c")
    pts = trunk_points(cfg, load_pin_model(cfg))
    assert pts[:, 0].max() > 0.5 and pts[:, 2].max() > 0.15  # the faces, the lidar cage


def test_crawl_order_lifts_each_foot_once_in_the_walk_gaits_order():
    order = crawl_order()
    assert sorted(order) == [0, 1, 2, 3]
    s = make_gait("walk").schedule(0.0, 400, 0.005)
    first_lift = [int(np.flatnonzero(~row)[0]) for row in s.stance]
    assert order == list(np.argsort(first_lift))


def test_turn_schedule_is_eight_steps_one_foot_at_a_time():
    st = _settings("turn", TurnSettings, "centauro")
    s = turn_schedule(st)
    np.testing.assert_array_equal(s.count_swings(), [2, 2, 2, 2])
    assert (~s.stance).sum(axis=0).max() == 1
    assert s.stance[:, 0].all() and s.stance[:, -1].all()


def test_leap_schedule_front_feet_lift_first_and_land_first():
    st = _settings("leap", LeapSettings, "go2")
    s = leap_schedule(st, front=[0, 1], hind=[2, 3])
    lift = [int(n[0]) for n in lift_off_nodes(s.stance)]
    land = [int(n[0]) for n in touchdown_nodes(s.stance)]
    assert max(lift[:2]) < min(lift[2:]) and max(land[:2]) < min(land[2:])
    assert (~s.stance).all(axis=0).any()  # a flight phase


def test_motion_settings_come_from_the_file_with_per_robot_overrides():
    mc = MotionConfig("m", "go2", "ipopt", {"dt": 0.05, "distance": 0.3},
                      {"solo12": {"distance": 0.2}})
    assert mc.settings_for(LeapSettings, "go2").distance == 0.3
    assert mc.settings_for(LeapSettings, "solo12").distance == 0.2
    assert mc.settings_for(LeapSettings, "solo12", {"distance": 0.1}).distance == 0.1
    assert mc.settings_for(LeapSettings, "solo12").dt == 0.05


def test_mapping_settings_merge_key_by_key_and_none_is_taken_where_it_is_a_value():
    """--set mpc={gait: {name: trot}} replaced walk.yaml's whole mpc mapping: its 40 nodes
    became the robot's 24 without a word; trunk_clearance null (documented: no clearance)
    was refused as not a number (session 28 audit)."""
    from horizon_mpc.motions.walk import WalkSettings

    walk = load_motion_config("walk")
    st = walk.settings_for(WalkSettings, "go2", {"mpc": {"gait": {"name": "walk"}}})
    assert st.mpc["n_nodes"] == 40 and st.mpc["gait"]["name"] == "walk"
    mc = MotionConfig("m", "go2", "ipopt", {"mpc": {"gait": {"name": "trot",
                                                               "step_duration": 0.3}}}, {})
    st = mc.settings_for(WalkSettings, "go2", {"mpc": {"gait": {"step_height": 0.05}}})
    assert st.mpc == {"gait": {"name": "trot", "step_duration": 0.3, "step_height": 0.05}}
    leap = load_motion_config("leap")
    assert leap.settings_for(LeapSettings, "go2", {"trunk_clearance": None}).trunk_clearance \
        is None
    with pytest.raises(ValueError, match="'distance' must be a number, got None"):
        leap.settings_for(LeapSettings, "go2", {"distance": None})


def test_unknown_motion_setting_names_the_known_ones():
    mc = load_motion_config("leap")
    with pytest.raises(ValueError, match="distance"):
        mc.settings_for(LeapSettings, "go2", {"distnace": 0.5})


def test_unknown_motion_config_lists_the_available_ones():
    with pytest.raises(FileNotFoundError, match="leap.*turn.*walk"):
        load_motion_config("backflip")


def test_quaternion_error_vanishes_only_at_the_target_orientation():
    target = np.array([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # yaw 90 deg
    err = np.asarray(quaternion_error(target, target), float).ravel()
    np.testing.assert_allclose(err, 0.0, atol=1e-15)
    small = np.array([0.0, 0.0, np.sin(np.pi / 4 + 0.01), np.cos(np.pi / 4 + 0.01)])
    err = np.asarray(quaternion_error(small, target), float).ravel()
    np.testing.assert_allclose(err, [0.0, 0.0, np.sin(0.01)], atol=1e-12)  # half the angle


def test_locked_joint_patterns_reduce_the_model_and_unknown_ones_raise():
    cfg = load_robot_config("centauro")
    model = robot_model(cfg, ["j_arm*", "j_wheel_*"])
    assert not any(n.startswith(("j_arm", "j_wheel")) for n in model.joint_names)
    assert "torso_yaw" in model.joint_names and len(model.joint_names) == 39 - 16
    with pytest.raises(ValueError, match="match no joint"):
        robot_model(cfg, ["j_leg*"])


def test_cli_rejects_bad_settings_before_solving_in_one_line(capsys):
    """An unknown key, or a value of the wrong kind: one error line, exit code 2, no
    solve (a raw TypeError from deep in the problem before)."""
    from horizon_mpc.motions.cli import main

    for setting, text in (("distnace=0.5", "unknown setting"),
                          ("cycles=abc", "setting 'cycles' must be a whole number"),
                          ("cycles=1.5", "setting 'cycles' must be a whole number"),
                          ("dt=fast", "setting 'dt' must be a number")):
        motion = "leap" if setting.startswith("distnace") else "turn"
        assert main([motion, "--set", setting, "--no-animation"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("motion: error:") and text in err and "Traceback" not in err
        if setting.startswith("distnace"):  # named as the --set it came from, not the file's
            assert "motion: error: --set: unknown setting(s) ['distnace']" in err
    # another motion's config: named as the motion run, the file's motion a hint
    assert main(["walk", "--config", "leap", "--no-animation"]) == 2
    err = capsys.readouterr().err
    assert "for motion 'walk' (a config of the 'leap' motion?)" in err


@pytest.mark.parametrize("motion, setting, text", [
    ("leap", "dt=0", "'dt' must be > 0"),                          # ZeroDivisionError
    ("leap", "stand=-0.1", "'stand' must be >= 0"),                 # after the NLP build
    ("leap", "friction=abc", "'friction' must be a number"),        # a CasADi TypeError
    ("walk", "duration=0", "'duration' must be > 0"),               # IndexError
    ("walk", "iterations=0", "'iterations' must be > 0"),           # 'solved', standing still
    ("walk", "velocity=[0.2]", "'velocity' must be 3 finite numbers"),
    ("walk", "mpc=5", "'mpc' must be a mapping"),
    ("walk", "average_cycles=0", "'average_cycles' must be > 0"),   # NaN velocities
    ("walk", "w_touchdown=-1", "'w_touchdown' must be >= 0"),
    ("walk", "mpc={gait: {step_height: -0.1}}", "'mpc.gait.step_height' must be"),  # feet
    ("walk", "mpc={friction: -1}", "'mpc.friction' must be"),  # 4.8 cm underground, 'solved'
    ("walk", "mpc={gait: trot}", "'mpc.gait' must be a mapping"),  # a dict() error
    ("walk", "foo", "--set expects KEY=VALUE"),                     # exit code 1 before
    ("turn", "locked_joints=[foo]", "foo"),                         # a traceback before
    ("leap", "locked_joints=[1]", "locked_joints must be a list of joint names"),  # TypeError
    ("leap", "distance=[0.3", "--set 'distance=[0.3': not a YAML value"),  # 6 lines of YAML's
], ids=lambda x: x if isinstance(x, str) and "=" in x else None)
def test_cli_rejects_settings_it_cannot_run_before_building(capsys, motion, setting, text):
    from horizon_mpc.motions.cli import main

    assert main([motion, "--set", setting, "--no-animation"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("motion: error:") and text in err and "Traceback" not in err
    assert err.count("\n") == 1, err


def test_cli_refuses_an_out_path_that_is_a_file_before_solving(tmp_path, capsys):
    from horizon_mpc.motions.cli import main

    (tmp_path / "taken").write_text("")
    assert main(["leap", "--out", str(tmp_path / "taken"), "--no-animation"]) == 2
    assert "exists and is not a folder" in capsys.readouterr().err
    # a folder under a file: a traceback after the solve, exit 1, before
    assert main(["walk", "--out", str(tmp_path / "taken" / "sub"), "--no-animation"]) == 2
    assert "cannot make that folder" in capsys.readouterr().err


def test_cli_refuses_an_out_folder_it_cannot_write_in_before_solving(tmp_path, capsys,
                                                                     monkeypatch):
    """An existing read-only folder passed, the solve ran (70-100 s for a turn), then the
    write failed with a traceback and exit 1 (an auditor's read-only mount)."""
    import errno
    import types

    from horizon_mpc.motions import cli

    def refused(*_args, **_kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(cli, "tempfile", types.SimpleNamespace(TemporaryFile=refused))
    monkeypatch.setattr("horizon_mpc.motions.walk.run_walk",
                        lambda *a, **k: pytest.fail("solved before the check"))
    assert cli.main(["walk", "--out", str(tmp_path), "--no-animation"]) == 2
    assert "cannot write in that folder (Read-only file system)" in capsys.readouterr().err


def test_cli_leaves_no_out_folder_behind_for_a_bad_locked_joint(tmp_path, capsys):
    from horizon_mpc.motions.cli import main

    out = tmp_path / "new"
    assert main(["turn", "--set", "locked_joints=[foo]", "--out", str(out)]) == 2
    assert "foo" in capsys.readouterr().err and not out.exists()


def test_cli_leaves_no_out_folder_behind_for_a_motion_it_cannot_build(tmp_path, capsys):
    """A walk too short to build: the folders made for its outputs were left empty (an
    auditor's); a folder that was there stays."""
    from horizon_mpc.motions.cli import main

    out = tmp_path / "new" / "deeper"
    assert main(["walk", "--set", "duration=0.02", "--out", str(out)]) == 2
    assert "cannot build the walk" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()
    assert main(["walk", "--set", "duration=0.02", "--out", str(tmp_path)]) == 2
    assert tmp_path.is_dir()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_cli_interrupted_while_solving_exits_130_in_one_line(tmp_path, sig):
    """Ctrl-C or a SIGTERM while the solver runs: one line and exit code 130 (it was a
    KeyboardInterrupt traceback from inside CasADi, or the default SIGTERM death)."""
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    proc = subprocess.Popen(
        [sys.executable, "-u", "-m", "horizon_mpc.motions", "leap", "--no-animation",
         "--no-replay", "--out", str(tmp_path / "out")], cwd=tmp_path, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        header = proc.stdout.readline()  # printed once the model is built, before the solve
        assert header.startswith("leap: "), header
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
        assert proc.returncode == 130, err[-2000:]
        assert "motion: interrupted" in err and "Traceback" not in err, err[-2000:]
        assert "solved" not in out and not (tmp_path / "out").exists()
    finally:
        if proc.poll() is None:
            proc.kill()


_LONG_C_CALL = """
import hashlib, sys
from horizon_mpc.motions import cli, leap

def stuck(*args, **kwargs):  # a C call that never returns to Python (as nlpsol's build)
    hashlib.pbkdf2_hmac("sha256", b"x", b"y", 2 ** 31 - 1)

leap.run_leap = stuck
sys.exit(cli.main(sys.argv[1:]))
"""


def test_cli_interrupted_inside_a_long_c_call_ends_after_a_grace_period(tmp_path):
    """SIGTERM while CasADi built IPOPT's derivatives of a go2 turn (a minute in C, where
    Python runs no signal handler): the turn ended 69 s later. Now FORCE_EXIT_AFTER s, with
    the one line, exit code 130 and no output folder left."""
    from horizon_mpc.motions.cli import FORCE_EXIT_AFTER

    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    proc = subprocess.Popen(
        [sys.executable, "-u", "-c", _LONG_C_CALL, "leap", "--no-animation", "--no-replay",
         "--out", str(tmp_path / "out" / "leap")], cwd=tmp_path, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        header = proc.stdout.readline()
        assert header.startswith("leap: "), header
        time.sleep(0.5)  # inside the call
        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        waited = time.monotonic() - t0
        assert proc.returncode == 130, err[-2000:]
        assert FORCE_EXIT_AFTER <= waited < FORCE_EXIT_AFTER + 20, waited
        assert "motion: interrupted inside a long solver call" in err, err[-2000:]
        assert "Traceback" not in err and not (tmp_path / "out").exists()
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.mark.slow
def test_a_walk_duration_off_the_tick_grid_is_rounded_with_a_warning(go2, caplog):
    cfg, model = go2
    st = _settings("walk", WalkSettings, "go2", duration=0.05)
    with caplog.at_level("WARNING"):
        res = run_walk(cfg, "ilqr", st, model=model)
    assert res.n_nodes == 2  # 0.05 s of 0.02 s ticks: rounded to 2 (silently before)
    assert "not a whole number of 0.02 s ticks: walking 2 ticks" in caplog.text
    # far shorter than the averaging cycles: the mean velocity is of the start-up, and the
    # summary says so (its warning blamed the command)
    assert res.summary["window_includes_start_up"] is True
    assert "averaging over all of it, start-up included" in caplog.text


@pytest.mark.slow
def test_cli_a_walk_shorter_than_two_ticks_is_an_error(capsys):
    from horizon_mpc.motions.cli import main

    assert main(["walk", "--set", "duration=0.001", "--no-animation"]) == 2
    err = capsys.readouterr().err
    assert "shorter than two MPC ticks" in err and "Traceback" not in err


@pytest.mark.parametrize("body, text", [
    ("settings: [1, 2]\n", "'settings' must be a mapping"),
    ("robots: {go2: 5}\n", "'robots' must map robot names"),
    ("robots: [go2]\n", "'robots' must map robot names"),
    ("solver: snopt\n", "unknown solver 'snopt'"),
    # became the robot 'None' ("no robot config 'None'") and the solver 'None' (a reviewer)
    ("robot: null\n", "'robot' must be a robot name, got None"),
    ("robot: [go2]\n", "'robot' must be a robot name, got ['go2']"),
    ("solver: 3\n", "'solver' must be a solver name, got 3"),
])
def test_a_malformed_motion_config_is_one_error_line(tmp_path, capsys, body, text):
    from horizon_mpc.motions.cli import main

    path = tmp_path / "walk.yaml"
    path.write_text(body)
    assert main(["walk", "--config", str(path), "--no-animation"]) == 2
    assert text in capsys.readouterr().err


def test_a_walk_that_breaks_the_physics_is_not_solved(tmp_path, capsys):
    # 3 m/s: defects of 3.5 and a 48 N base wrench, printed 'solved' with exit code 0
    from horizon_mpc.motions.cli import main

    assert main(["walk", "--set", "velocity=[3, 0, 0]",
                 "--no-animation", "--out", str(tmp_path)]) == 1
    printed = capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    stats = summary["solver_stats"]
    # why, on the console too (it was only in summary.json)
    assert f"walk: NOT solved (ilqr status: {stats['status']}) in" in printed
    assert "(the figures below are of the plan the solver stopped at, not of a solved walk" \
        in printed
    assert stats["success"] is False and stats["status"] != "consistent"
    # what it executed breaks the physics, or its first horizon never converged
    assert (summary["results"]["max_dynamics_defect"] > 1e-6
            or stats["status"].startswith("bootstrap"))


def test_a_misspelt_robot_under_robots_is_warned_about(tmp_path, caplog):
    """`robots: {sol12: ...}` dropped its settings for solo12 without a word; another
    robot's entry (go1 beside go2) is no typo, and the entry of the robot run none."""
    from horizon_mpc.motions.settings import load_motion_config

    path = tmp_path / "leap.yaml"
    path.write_text("robots:\n  sol12: {distance: 0.2}\n  go1: {distance: 0.3}\n")
    mc = load_motion_config(path)
    with caplog.at_level("WARNING", logger="horizon_mpc.motions.settings"):
        assert mc.settings_for(LeapSettings, "solo12").distance == LeapSettings().distance
        assert mc.settings_for(LeapSettings, "go2").distance == LeapSettings().distance
        assert mc.settings_for(LeapSettings, "go1").distance == 0.3
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: robots: 'sol12' is no robot config and not 'solo12', the robot run: a "
        "misspelling? Its settings are not used"]


def test_motion_settings_take_whole_floats_and_ints_as_their_kinds():
    from horizon_mpc.motions.settings import load_motion_config
    from horizon_mpc.motions.turn import TurnSettings

    st = load_motion_config("turn").settings_for(TurnSettings, None, {"cycles": 2.0, "dt": 1})
    assert st.cycles == 2 and isinstance(st.cycles, int)
    assert st.dt == 1.0 and isinstance(st.dt, float)


# --------------------------------------------------------------------------------------------
# The solved motions (module fixtures: each motion is solved once)

@pytest.fixture(scope="module")
def go2():
    cfg = load_robot_config("go2")
    return cfg, robot_model(cfg)


@pytest.fixture(scope="module")
def leap(go2):
    cfg, model = go2
    st = _settings("leap", LeapSettings, "go2")
    res = run_leap(cfg, "ipopt", st, model=model)
    assert res.stats["success"], res.stats["status"]
    return res, st, model, cfg


@pytest.fixture(scope="module")
def turn():
    cfg = load_robot_config("centauro")
    st = _settings("turn", TurnSettings, "centauro")
    model = robot_model(cfg, st.locked_joints)
    res = run_turn(cfg, "ipopt", st, model=model)
    assert res.stats["success"], res.stats["status"]
    return res, st, model


@pytest.fixture(scope="module")
def walk(go2):
    cfg, model = go2
    st = _settings("walk", WalkSettings, "go2")
    return run_walk(cfg, "ilqr", st, model=model), st, model


@pytest.mark.slow
@pytest.mark.parametrize("motion", ["leap", "turn", "walk"])
def test_pinocchio_dynamics_reproduce_the_states_and_the_base_wrench_vanishes(motion, request):
    res, _, model, *_ = request.getfixturevalue(motion)
    check = dynamics_check(res, model.pin_model, res.foot_radius, res.integrator)
    # the walk's states are its ticks' node 1: 3 real-time ILQR iterations close each gap to
    # second order, not exactly (measured: p99 1.5e-8, max 2.8e-6 over 200 ticks; the offline
    # NLP motions ~1e-14); an error in the dynamics shows at 1e-4 and above (next test)
    assert check["max_defect"] <= (1e-5 if motion == "walk" else 1e-6)
    # one millionth of the robot's weight (the defects above integrate with zero base torque)
    assert check["max_base_wrench"] <= 1e-6 * model.mass * G


@pytest.mark.slow
@pytest.mark.parametrize("motion", ["leap", "turn", "walk"])
def test_every_solved_motion_is_reported_without_a_false_warning(motion, request):
    """The CLI's warnings of each motion's real summary: every CLI turn ended in a
    TypeError after writing its outputs (its per-foot swing apexes went through the walk's
    check, session 30), exit code 1 for a solved turn (an auditor's)."""
    from horizon_mpc.motions.cli import motion_warnings

    res, st, *_ = request.getfixturevalue(motion)
    assert motion_warnings(motion, res.summary, st) == []


@pytest.mark.slow
@pytest.mark.parametrize("motion", ["leap", "turn", "walk"])
def test_every_motion_summary_has_the_physics_checks(motion, request):
    res, _, model, *_ = request.getfixturevalue(motion)
    s = res.summary
    ratio = np.abs(res.tau[6:]) / model.joint_effort_limit[:, None]
    # at most the limit, to the solver's constraint tolerance (the turn: 1 + 5e-11)
    assert s["max_torque_ratio"] == pytest.approx(ratio.max())
    assert 0 < s["max_torque_ratio"] <= 1 + 1e-8
    check = dynamics_check(res, model.pin_model, res.foot_radius, res.integrator)
    assert s["max_dynamics_defect"] == check["max_defect"]
    assert s["max_base_wrench"] == check["max_base_wrench"]
    # the loaded feet's figures for the NLP motions (the walk's states are MPC ticks)
    assert ("max_loaded_foot_slip" in s) == (motion != "walk")


@pytest.mark.slow
def test_dynamics_check_sees_a_state_off_the_dynamics_and_an_unbalanced_base(leap):
    res, _, model, _ = leap
    q, v, a = res.q.copy(), res.v.copy(), res.a.copy()
    try:
        res.v[10, 31] += 1e-4  # a joint velocity the interval before does not reach
        res.a[2, 20] += 1e-3  # vertical base acceleration the forces do not explain
        check = dynamics_check(res, model.pin_model, res.foot_radius, res.integrator)
    finally:
        res.q, res.v, res.a = q, v, a
    assert check["defect"][30] >= 0.9e-4
    assert np.abs(check["base_wrench"][:, 20]).max() >= 0.5e-3 * model.mass


@pytest.mark.slow
@pytest.mark.parametrize("motion", ["leap", "turn"])
def test_loaded_feet_stay_on_the_ground_between_the_nodes(motion, request):
    res, *_ = request.getfixturevalue(motion)
    s = res.summary
    assert s["max_loaded_foot_height"] <= 0.005 and s["max_loaded_foot_slip"] <= 0.005
    assert s["loaded_off_ground_intervals"] == 0 and res.stats["success"]


def test_contact_check_sees_a_loaded_foot_lifted_within_an_interval(leap):
    """A turn with 1 m steps pushed 227 N through stance feet up to 33 cm above the ground
    between the nodes and was reported solved: the check samples inside the intervals."""
    from horizon_mpc.motions.analysis import (
        CONTACT_TOLERANCE,
        check_contacts,
        contact_check,
        loaded,
    )

    res, _, model, _ = leap
    k = int(np.flatnonzero(loaded(res).all(axis=0))[0])  # every foot pushes
    v, summary, stats = res.v.copy(), dict(res.summary), dict(res.stats)
    try:
        res.v[2, k] += 1.0  # the base (and the feet with it) rises 0.1 m/s x dt within k
        check = contact_check(res, model.pin_model)
        res.summary.update(check)
        check_contacts(res)
        assert check["max_loaded_foot_height"] >= 0.9 * res.dt > CONTACT_TOLERANCE
        assert not res.stats["success"] and "inconsistent contacts" in res.stats["status"]
    finally:
        res.v, res.summary, res.stats = v, summary, stats


# ---- leap

@pytest.mark.slow
def test_leap_lands_within_1_cm_of_the_target_at_rest_as_it_started(leap):
    res, st, model, _ = leap
    q0 = res.q[:, 0]
    target = q0[:3] + [st.distance, 0.0, 0.0]
    assert np.linalg.norm(res.q[:3, -1] - target) <= 0.01
    np.testing.assert_allclose(res.q[3:7, -1], q0[3:7], atol=1e-6)  # orientation = initial
    np.testing.assert_allclose(res.q[7:, -1], q0[7:], atol=1e-6)  # joints = initial
    np.testing.assert_allclose(res.v[:, -1], 0.0, atol=1e-6)


@pytest.mark.slow
def test_leap_has_a_flight_phase_with_every_foot_unloaded(leap):
    res, st, *_ = leap
    load = loaded(res)
    flights = flight_phases(load)
    assert flights, "no interval with all feet unloaded"
    k0, k1 = max(flights, key=lambda f: f[1] - f[0])
    assert (k1 - k0) * res.dt >= 0.5 * st.flight
    assert np.all(np.abs(res.f[:, k0:k1]) < 1e-6)  # unloaded: no force at all


@pytest.mark.slow
def test_leap_hind_feet_leave_last_and_front_feet_land_first(leap):
    res, *_ = leap
    load = loaded(res)
    k0, k1 = flight_phases(load)[0]
    front, hind = [0, 1], [2, 3]  # config order FL, FR, RL, RR
    last_push = [np.flatnonzero(load[i, :k0])[-1] for i in range(4)]
    first_load = [k1 + np.flatnonzero(load[i, k1:])[0] for i in range(4)]
    assert min(last_push[i] for i in hind) > max(last_push[i] for i in front)
    assert max(first_load[i] for i in front) < min(first_load[i] for i in hind)


@pytest.mark.slow
def test_leap_joint_torques_stay_within_the_urdf_limits(leap):
    res, _, model, _ = leap
    assert np.all(np.abs(res.tau[6:]) <= model.joint_effort_limit[:, None] * (1 + 1e-6))


@pytest.mark.slow
def test_leap_keeps_the_trunk_above_the_ground(leap):
    """An auditor's Pinocchio check of the collision meshes: the go2 landed nose-down with
    its trunk 9 cm below the ground (the replay leaned on it, 134 N of its 158 N weight).
    Checked here with Pinocchio's collision model and distance to the plane, independent of
    the plan's own trunk points."""
    import pinocchio as pin

    from horizon_mpc.motions.body import trunk_points

    res, st, model, cfg = leap
    assert st.trunk_clearance is not None and st.trunk_clearance > 0
    assert res.summary["min_trunk_height"] >= st.trunk_clearance - 1e-6
    # the trunk points bound the base's collision shapes: every vertex of its box is one of
    # them or inside their hull; their heights are Pinocchio's placements of those points
    pts = trunk_points(cfg, model.pin_model)
    assert len(pts) >= 4
    data = model.pin_model.createData()
    lowest = np.inf
    for k in range(res.q.shape[1]):
        pin.forwardKinematics(model.pin_model, data, res.q[:, k])
        base = data.oMi[1]
        lowest = min(lowest, float(np.min(pts @ base.rotation[2] + base.translation[2])))
    assert lowest == pytest.approx(res.summary["min_trunk_height"], abs=1e-9)


def test_the_leap_replay_is_never_softer_than_the_robots_own_joint_gains():
    """Every robot was replayed with go2's 100 / 3: hyq (its own 300 / 8) landed 0.12 m
    ahead of its 0.4 m plan, not standing (an auditor's; with its own gains 0.334 m)."""
    import dataclasses

    from horizon_mpc.motions.leap import LeapSettings, replay_gains

    for robot, gains in (("go2", (100.0, 3.0)), ("hyq", (300.0, 8.0)),
                         ("b1", (150.0, 4.0)), ("centauro", (400.0, 10.0)),
                         ("solo12", (5.0, 0.15))):  # solo12: its own leap setting
        st = _settings("leap", LeapSettings, robot)
        assert replay_gains(st, load_robot_config(robot)) == gains, robot
    # per-joint gains of a config: raised joint by joint
    cfg = load_robot_config("go2")
    cfg = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, kp=[50.0] * 6 + [200.0] * 6))
    kp, _ = replay_gains(LeapSettings(), cfg)
    assert kp == [100.0] * 6 + [200.0] * 6


@pytest.mark.slow
def test_leap_replayed_open_loop_in_pybullet_lands_upright_near_the_target(leap):
    from horizon_mpc.motions.leap import replay_gains
    from horizon_mpc.motions.replay import replay

    res, st, model, cfg = leap
    rep = replay(res, cfg, model.pin_model, *replay_gains(st, cfg), settle=1.0)
    assert abs(rep.displacement[0] - st.distance) <= 0.15
    assert abs(rep.displacement[1]) <= 0.15
    assert np.all(np.abs(rep.final_rpy[:2]) < 0.2)  # upright: roll, pitch below ~11 deg
    assert rep.q[-1, 2] > 0.8 * rep.q[0, 2]  # standing, not lying on the ground


# ---- turn

@pytest.mark.slow
def test_turn_ends_at_90_degrees_yaw_within_1_degree(turn):
    res, st, _ = turn
    yaw = np.degrees(np.unwrap(roll_pitch_yaw(res.q[3:7].T)[:, 2]))
    assert abs(yaw[-1] - yaw[0] - 90.0) <= 1.0
    rpy = roll_pitch_yaw(res.q[3:7, -1])
    assert abs(rpy[0]) < 1e-3 and abs(rpy[1]) < 1e-3


@pytest.mark.slow
def test_turn_brings_the_base_back_within_2_cm_and_the_joints_to_their_start(turn):
    res, *_ = turn
    assert np.linalg.norm(res.q[:3, -1] - res.q[:3, 0]) <= 0.02
    np.testing.assert_allclose(res.q[7:, -1], res.q[7:, 0], atol=1e-6)


@pytest.mark.slow
def test_turn_takes_exactly_8_steps_each_foot_twice_one_at_a_time(turn):
    res, _, model = turn
    in_air = foot_heights(model, res) > 1e-3  # read from the motion, not the schedule
    starts = (in_air[:, 1:] & ~in_air[:, :-1]).sum(axis=1) + in_air[:, 0]
    np.testing.assert_array_equal(starts, [2, 2, 2, 2])
    assert in_air.sum(axis=0).max() == 1


@pytest.mark.slow
def test_turn_swing_feet_reach_the_clearance_height(turn):
    res, st, model = turn
    z = foot_heights(model, res)
    for i in range(len(res.feet)):
        in_air = np.flatnonzero(z[i] > 1e-3)
        runs = np.split(in_air, np.flatnonzero(np.diff(in_air) > 1) + 1)
        assert len(runs) == 2
        for run in runs:
            assert z[i, run].max() >= st.step_height - 1e-4


# ---- walk

@pytest.mark.slow
def test_walk_average_velocity_over_the_last_cycles_is_within_3_percent(walk):
    res, st, _ = walk
    period = make_gait("trot").period
    n = int(round(st.average_cycles * period / res.dt))
    assert res.n_nodes >= 3 * n  # the average leaves out the start
    vx = res.v[0, -n - 1:-1].mean()  # base frame, forward
    # measured 0.6 % (the pose reference integrates the command; 7.8 % below when it
    # restarted from the current pose at every tick)
    assert abs(vx - st.velocity[0]) <= 0.03 * st.velocity[0]
    assert abs(res.v[1, -n - 1:-1].mean()) <= 0.02 * st.velocity[0]


def test_the_walks_velocity_error_counts_the_linear_part_and_the_yaw_rate():
    """An arc (0.2, 0, 0.4) walked without turning scored 0.03 before: only its linear
    part was compared."""
    from horizon_mpc.motions.walk import velocity_errors

    ref = np.array([0.2, 0.0, 0.4])
    assert velocity_errors(np.array([0.194, -0.003, 0.0]), ref)[0] == pytest.approx(1.0)
    err, lin, yaw = velocity_errors(np.array([0.194, -0.003, 0.3946]), ref)
    assert (lin, yaw) == (pytest.approx(np.hypot(0.006, 0.003) / 0.2),
                          pytest.approx(0.0054 / 0.4))
    assert err == max(lin, yaw)
    assert velocity_errors(np.array([0.0, 0.0, 0.49]), np.array([0.0, 0.0, 0.5]))[1:] == (
        None, pytest.approx(0.02))
    assert velocity_errors(np.array([0.03, -0.04, 0.1]), np.zeros(3)) == (
        pytest.approx(0.05), None, None)  # standing: the drift speed (m/s)


@pytest.mark.slow
def test_walk_turning_in_place_converges_its_first_horizon_and_tracks_the_yaw_rate(go2):
    """The first horizon of go2 turning in place takes 335 iterations (a cap of 50 had it
    'NOT solved')."""
    cfg, model = go2
    st = _settings("walk", WalkSettings, "go2", velocity=[0.0, 0.0, 0.5], duration=2.0)
    res = run_walk(cfg, "ilqr", st, model=model)
    assert res.stats["success"], res.stats["status"]
    assert res.summary["velocity_error"] <= 0.05  # measured 0.015


@pytest.mark.slow
def test_walk_of_another_robot_is_solved_and_tracks():
    """go1 with its config only: its first horizon never converged with the augmented
    Lagrangian on the inequality rows (max_iter at 50, 100, 300 iterations); with the
    walking MPC's barrier in 19, and it walks within 3 % of the reference."""
    cfg = load_robot_config("go1")
    res = run_walk(cfg, "ilqr", _settings("walk", WalkSettings, "go1"))
    assert res.stats["success"], res.stats["status"]
    assert res.summary["velocity_error"] <= 0.05  # measured 0.021


@pytest.mark.slow
def test_walk_contact_forces_are_periodic(walk):
    res, _, _ = walk
    n = int(round(make_gait("trot").period / res.dt))
    last, previous = res.f[:, -n:], res.f[:, -2 * n:-n]
    assert np.linalg.norm(last - previous) <= 0.05 * np.linalg.norm(last)
    # and it is a trot: diagonal pairs carry the weight in turn
    load = loaded(res)[:, -n:]
    np.testing.assert_array_equal(load[0], load[3])
    np.testing.assert_array_equal(load[1], load[2])
    assert not np.any(load[0] & load[1])


@pytest.mark.slow
def test_walk_stance_feet_are_on_the_ground_and_push_only_while_down(walk):
    res, _, model = walk
    z = foot_heights(model, res) - foot_heights(model, res)[:, :1]  # standing height 0
    assert np.all(np.abs(z[res.stance]) <= 2e-3)
    lifting = res.stance[:, :-1] & ~res.stance[:, 1:]  # the interval a foot lifts off in
    assert np.all(np.abs(res.forces()[:, 2, :][lifting]) <= 1e-6)
    # the summary's swing apexes are those of the swing nodes (a cost: below step_height)
    lo, hi = res.summary["swing_apex"]
    swing_z = z[~res.stance]
    assert hi == pytest.approx(swing_z.max()) and 0.01 < lo <= hi < res.summary["step_height"]


@pytest.mark.slow
def test_walk_shifts_the_horizon_one_node_per_tick(walk):
    res, st, _ = walk
    assert res.n_nodes == round(st.duration / res.dt)
    assert np.all(res.arrays["iterations"][1:] == st.iterations)  # real-time iterations


@pytest.mark.slow
def test_a_whole_body_solution_carries_its_transcription_s_integrator(go2):
    """build_whole_body(integrator=...) solved: the result said 'rk4', and the dynamics
    check of a correct Euler solution found defects of 3.7e-3 (an auditor's)."""
    cfg, model = go2
    _, q0 = standing_configuration(cfg, model.pin_model)
    n, integrator = 6, "euler"
    wb = build_whole_body(model, list(cfg.feet), n, 0.02, q0, 0.6, integrator=integrator)
    q_final = q0.copy()
    q_final[2] -= 0.02
    wb.add_final_state(q_final, joints=False)
    wb.set_schedule(timeline_schedule([[] for _ in cfg.feet], n, 0.02))
    wb.prb.create_cost("acceleration", wb.a, weight=1e-3)
    res = wb.solve("ipopt")
    assert res.stats["success"] and res.integrator == integrator
    assert dynamics_check(res, model.pin_model, res.foot_radius, res.integrator)[
        "max_defect"] <= 1e-6
    assert dynamics_check(res, model.pin_model, res.foot_radius, "rk4")["max_defect"] > 1e-5


@pytest.fixture(scope="module")
def short_walks(go2):
    """Three ticks of the walk with each NLP solver (both converge at every tick)."""
    cfg, model = go2
    st = _settings("walk", WalkSettings, "go2", duration=0.06)
    return {s: run_walk(cfg, s, st, model=model) for s in ("ipopt", "gnsqp")}


@pytest.mark.slow
@pytest.mark.parametrize("solver", ["ipopt", "gnsqp"])
def test_walk_is_solvable_with_the_nlp_solvers(solver, short_walks, go2):
    res = short_walks[solver]
    assert res.n_nodes == 3
    it = res.arrays["iterations"]  # converged: below the iteration limits
    assert it[0] < 200 and np.all(it[1:] < _settings("walk", WalkSettings, "go2").nlp_max_iter)
    assert res.stats["max_constraint_violation"] <= 1e-6
    check = dynamics_check(res, go2[1].pin_model, res.foot_radius, res.integrator)
    assert check["max_defect"] <= 1e-6


@pytest.mark.slow
def test_ipopt_and_gnsqp_walk_the_same_way(short_walks):
    a, b = short_walks["ipopt"], short_walks["gnsqp"]
    np.testing.assert_allclose(a.q, b.q, atol=1e-4)


# --------------------------------------------------------------------------------------------
# Outputs and the executable

@pytest.mark.slow
def test_outputs_hold_the_solution_figures_animation_and_summary(walk, tmp_path):
    from PIL import Image

    from horizon_mpc.motions.output import load_solution, write_outputs

    res, _, model = walk
    files = write_outputs(res, load_robot_config("go2"), tmp_path,
                          effort_limit=model.joint_effort_limit)
    data = load_solution(files["solution"])
    np.testing.assert_array_equal(data["q"], res.q)
    np.testing.assert_array_equal(data["f"], res.f)
    assert list(data["feet"]) == res.feet
    # the file says how to check it: the walk integrates Euler steps, with forces at the
    # foot frames and a stance condition on rolling ball feet (an auditor read RK4 and
    # point feet, and found defects the solution does not have)
    assert str(data["integrator"]) == res.integrator == "euler"
    assert float(data["foot_radius"]) == 0.0
    assert float(data["stance_foot_radius"]) == load_robot_config("go2").foot_radius > 0
    for name in ("contact_forces", "base_and_torques"):
        assert Image.open(files[name]).size[0] >= 600
    gif = Image.open(files["animation"])
    assert gif.n_frames >= 10
    frames = []
    for i in (0, gif.n_frames - 1):
        gif.seek(i)
        frames.append(np.asarray(gif.convert("RGB"), float))
    assert np.abs(frames[0] - frames[1]).mean() > 1.0  # the robot moved
    summary = json.loads(files["summary"].read_text())
    assert summary["motion"] == "walk" and summary["solver"] == "ilqr"
    assert summary["results"]["velocity_error"] == pytest.approx(
        res.summary["velocity_error"])
    # a run without the animation into the same folder leaves no GIF of the earlier run
    files = write_outputs(res, load_robot_config("go2"), tmp_path, animation=False)
    assert not (tmp_path / "animation.gif").exists() and "animation" not in files
    assert "animation" not in json.loads(files["summary"].read_text())["files"]
    # a run interrupted while writing (after its solution) leaves none of the earlier run's
    # summary or plots beside it (session 28 audit: a go2 solution beside a laikago summary)
    write_outputs(res, load_robot_config("go2"), tmp_path, animation=False)

    def interrupted(*_args, **_kwargs):
        raise KeyboardInterrupt

    from horizon_mpc.motions import plots

    original = plots.plot_contact_forces
    plots.plot_contact_forces = interrupted
    try:
        with pytest.raises(KeyboardInterrupt):
            write_outputs(res, load_robot_config("go2"), tmp_path, animation=False)
    finally:
        plots.plot_contact_forces = original
    assert sorted(p.name for p in tmp_path.iterdir()) == ["solution.npz"]


@pytest.mark.slow
def test_motion_executable_writes_every_output(tmp_path):
    out = tmp_path / "walk"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    proc = subprocess.run(
        [sys.executable, "-m", "horizon_mpc.motions", "walk", "--set", "duration=0.6",
         "--out", str(out)], cwd=tmp_path, env=env, capture_output=True, text=True,
        timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert sorted(p.name for p in out.iterdir()) == [
        "animation.gif", "base_and_torques.png", "contact_forces.png", "solution.npz",
        "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["settings"]["duration"] == 0.6 and summary["nodes"] == 30



def test_the_leap_events_follow_the_scheduled_flight_not_the_first_unloaded_run():
    # a 1 m leap unloaded all feet for 4 intervals while standing: its lift-offs were read
    # before that (None) and its front touch-down at 0.12 s instead of 0.60 s
    from horizon_mpc.motions.analysis import best_overlap

    runs = [(2, 6), (22, 30), (36, 37)]
    assert best_overlap(runs, 22, 30) == (22, 30)
    assert best_overlap(runs, 21, 28) == (22, 30)
    assert best_overlap(runs, 10, 12) == (22, 30)  # no overlap: the longest


@pytest.mark.slow
def test_the_walk_with_a_gait_that_never_lifts_a_foot_is_summarised(tmp_path, capsys):
    """gait 'stand' (no cycle: period inf): the summary averaged over 'the last cycles' and
    the run ended in an OverflowError after the solve, no outputs. Its 0.3 m/s command is
    not followed: said (it was 'solved' without a word)."""
    import json

    from horizon_mpc.motions.cli import main

    out = tmp_path / "stand"
    assert main(["walk", "--set", "mpc={gait: {name: stand}}", "--set", "duration=1.0",
                 "--out", str(out), "--no-animation"]) == 0
    summary = json.loads((out / "summary.json").read_text())["results"]
    assert summary["gait_period"] == "inf" and summary["window"] == [0.0, 1.0]
    assert "force_periodicity" not in summary and summary["swing_apex"] is None
    printed = capsys.readouterr().out
    assert "walk: solved" in printed
    mean = [round(x, 3) for x in summary["mean_velocity"]]
    assert f"WARNING: the walk's mean velocity (vx, vy, wz) {mean} is" in printed, printed


def test_a_walk_far_from_its_velocity_reference_or_skimming_the_ground_is_warned_about():
    """Both were 'solved' without a word (auditors: the gait stand asked for 0.3 m/s; a new
    robot's walk with swing apexes of 0.45 mm for a 4 cm step height)."""
    from horizon_mpc.motions.cli import walk_warnings

    walk = {"velocity_reference": [0.3, 0.0, 0.0], "mean_velocity": [0.29, 0.01, 0.0],
            "swing_apex": [0.05, 0.07], "step_height": 0.07}
    assert walk_warnings({**walk, "velocity_error": 0.047}) == []
    assert walk_warnings({**walk, "velocity_error": 0.5}) == [
        "the walk's mean velocity (vx, vy, wz) [0.29, 0.01, 0.0] is 50% off its reference "
        "[0.3, 0.0, 0.0]: the motion is consistent, but does not follow the command"]
    # a walk shorter than the averaging window: its start from standing, not the command
    # (an auditor's 0.6 s walk was told it does not follow the command)
    short = walk_warnings({**walk, "velocity_error": 0.5, "window_includes_start_up": True})
    assert len(short) == 1 and "its start from standing included" in short[0] \
        and "does not follow the command" not in short[0]
    standing = {"velocity_reference": [0.0, 0.0, 0.0], "mean_velocity": [0.25, 0.0, 0.0],
                "velocity_error": 0.25}
    assert "0.250 m/s for a zero reference" in walk_warnings(standing)[0]
    skim = {**walk, "velocity_error": 0.04, "swing_apex": [0.00015, 0.00045],
            "step_height": 0.04}
    assert walk_warnings(skim) == [
        "the swing feet rise at most 0.04 cm for a step_height of 4.00 cm: they skim the "
        "ground (the clearance is a cost: mpc.weights.swing_height against the others)"]
    # asked for, but 'solved' without a word while the feet slid (a known item until
    # session 31): said
    assert walk_warnings({**skim, "step_height": 0.0}) == [
        "step_height is 0: the swing feet are not lifted (they rise at most 0.04 cm, sliding "
        "or skimming the ground)"]
    assert walk_warnings({"final_yaw": 1.57}) == []  # a leap, a turn


def test_only_a_walk_gets_the_walk_warnings_and_the_torque_warning_names_what_exists():
    """A turn's summary (per-foot swing apexes, a step height) went through the walk's
    checks: a TypeError after every CLI turn. The walk, which has no torque_limit_scale,
    was told 'torque_limit_scale None'."""
    from horizon_mpc.motions.cli import motion_warnings

    turn = {"swing_apex": [[0.1, 0.1]] * 4, "step_height": 0.1, "max_torque_ratio": 0.9}
    assert motion_warnings("turn", turn, TurnSettings()) == []
    over = {**turn, "max_torque_ratio": 1.08}
    assert motion_warnings("turn", over, TurnSettings(torque_limit_scale=0.8)) == [
        "the plan's torques reach 1.08 times the URDF effort limits (torque_limit_scale "
        "0.8): more than the robot's motors are rated for"]
    walk = {"velocity_reference": [0.3, 0.0, 0.0], "mean_velocity": [0.3, 0.0, 0.0],
            "velocity_error": 0.01, "swing_apex": [0.0, 0.0], "step_height": 0.0,
            "max_torque_ratio": 1.08}
    assert motion_warnings("walk", walk, WalkSettings()) == [
        "the plan's torques reach 1.08 times the URDF effort limits: more than the robot's "
        "motors are rated for",
        "step_height is 0: the swing feet are not lifted (they rise at most 0.00 cm, sliding "
        "or skimming the ground)"]


@pytest.mark.slow
def test_cli_turn_solves_and_exits_zero(tmp_path, capsys):
    """Every CLI turn ended in a TypeError (exit code 1) after printing 'solved' and writing
    its outputs (session 30's walk warnings; an auditor's). go2, one cycle, -45 degrees:
    ~40 s."""
    from horizon_mpc.motions.cli import main

    code = main(["turn", "--robot", "go2", "--set", "yaw=-45", "--set", "cycles=1",
                 "--set", "step_height=0.04", "--no-animation", "--out", str(tmp_path)])
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    assert "turn: solved in" in out.out and "WARNING" not in out.out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["results"]["final_yaw_deg"] == pytest.approx(-45.0, abs=1.0)


def test_a_turn_beyond_180_degrees_per_gait_cycle_is_refused():
    """yaw 1e9 ran a 276 s solve to 'NOT solved' (an auditor's); 360 in two cycles solves."""
    assert TurnSettings(yaw=-360.0, cycles=2).yaw == -360.0
    with pytest.raises(ValueError, match=r"setting 'yaw' must be within \+-180 degrees per "
                       r"gait cycle \(cycles 1: \+-180\), got 1e\+09; more cycles"):
        TurnSettings(yaw=1e9, cycles=1)
    with pytest.raises(ValueError, match="'yaw'"):
        TurnSettings(yaw=float("nan"))


def test_verbose_prints_the_solvers_iterations_as_they_go(tmp_path, capsys):
    """`-v` was debug logging only: a GN-SQP turn ran minutes without a line."""
    from horizon_mpc.motions.cli import main

    assert main(["walk", "--set", "duration=0.06", "--no-animation", "-v",
                 "--out", str(tmp_path)]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("ilqr: ")]
    assert len(lines) > 3, lines  # the first horizon's iterations, then the ticks'


def test_a_leap_replay_that_ends_collapsed_is_not_within_tolerance():
    """anymal_c's replay ended 26.5 cm low and pitched 0.37 rad and was reported as landing
    8 cm off target only (session 28 audit): the summary says whether it ended standing."""
    from types import SimpleNamespace

    from horizon_mpc.motions.cli import _replay_warning
    from horizon_mpc.motions.replay import ReplayResult, replay_summary

    q = np.zeros((19, 5))
    q[2] = 0.5  # the plan ends at its start height
    plan = SimpleNamespace(q=q)

    def rep(dz, pitch, dx=0.40):
        return ReplayResult(np.zeros(1), np.zeros((1, 19)), np.zeros((1, 4)),
                            np.array([dx, 0.0, dz]), np.array([0.0, pitch, 0.0]), abs(pitch))

    ok = replay_summary(rep(-0.01, 0.05), plan, 0.4)
    assert ok["ended_standing"] and ok["within_tolerance"]
    assert ok["height_error"] == pytest.approx(-0.01)
    fallen = replay_summary(rep(-0.265, 0.365, dx=0.467), plan, 0.4)
    assert not fallen["ended_standing"] and not fallen["within_tolerance"]
    assert "did not end standing: its base 26.5 cm below the plan's final height" in (
        _replay_warning(fallen))
    long = replay_summary(rep(0.0, 0.0, dx=0.477), plan, 0.4)
    assert long["ended_standing"] and not long["within_tolerance"]
    assert "lands 0.077 m from its target" in _replay_warning(long)


def test_the_python_api_defaults_to_the_settings_the_cli_runs(monkeypatch):
    """run_turn() built the whole 39-joint CENTAURO (the file locks its arms and wheels),
    run_walk() 24 nodes (the file: 40), run_leap('solo12') 0.4 m (the file: 0.25)."""
    from horizon_mpc.motions import walk as walk_module
    from horizon_mpc.motions.settings import motion_settings
    from horizon_mpc.motions.turn import TurnSettings
    from horizon_mpc.motions.walk import WalkSettings

    assert motion_settings("turn", TurnSettings, "centauro").locked_joints
    assert motion_settings("walk", WalkSettings, "go2").mpc["n_nodes"] == 40
    assert motion_settings("leap", LeapSettings, "solo12").distance == pytest.approx(0.25)
    asked = []

    def short(motion, cls, robot):
        asked.append((motion, cls, robot))
        st = motion_settings(motion, cls, robot)
        st.duration = 0.06
        return st

    monkeypatch.setattr(walk_module, "motion_settings", short)
    res = walk_module.run_walk("go2")
    assert asked == [("walk", WalkSettings, "go2")] and res.n_nodes == 3


@pytest.mark.slow  # the ILQR's leap functions compile once (~40 s), then ~5 s
def test_an_unsolved_leap_the_simulator_refuses_to_replay_is_written_and_said(tmp_path, capsys):
    """`leap --solver ilqr` (not solved, as documented) ended in a traceback from the replay
    (a joint asked to move at 110 rad/s) with nothing written; its torques at 6x the URDF
    limits went without a word (an auditor's)."""
    from horizon_mpc.motions.cli import main

    assert main(["leap", "--solver", "ilqr", "--no-animation", "--out", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert "leap: NOT solved (ilqr status:" in out
    assert "WARNING: not replayed in PyBullet: points " in out
    assert "times the URDF effort limits" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert "per s, beyond 100" in summary["pybullet_replay"]["not_replayed"]


def test_fuzzed_motion_settings_fail_with_a_value_error_naming_the_setting(tmp_path):
    """An auditor's fuzzing: a huge integer was an OverflowError, mixed-type keys a
    TypeError from sorted(), a list or a mapping for a number setting was taken (friction
    [-5]), 'settings: 0' was no settings, a date that is none a bare 'month must be in
    1..12'."""
    from horizon_mpc.motions.cli import _overrides
    from horizon_mpc.motions.settings import load_motion_config

    leap = load_motion_config("leap")
    huge = "1" + "0" * 400
    for item, match in ((f"dt={huge}", "'dt' must be a number"),
                        ("friction=[1, 2]", "'friction' must be a number"),
                        ("foot_radius={a: 1}", "'foot_radius' must be a number")):
        with pytest.raises(ValueError, match=match):
            leap.settings_for(LeapSettings, "go2", _overrides([item]))
    with pytest.raises(ValueError, match=r"--set 'duration=2001-13-45': not a YAML value"):
        _overrides(["duration=2001-13-45"])
    for text, match in (("settings: {dt: 0.02}\n1: x\nfoo: y\n",
                         r"unknown key\(s\) \['1', 'foo'\]"),
                        ("settings: 0\n", "'settings' must be a mapping")):
        path = tmp_path / "m.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match=match):
            load_motion_config(path)
