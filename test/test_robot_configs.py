"""Every robot config in ``config/`` describes its robot, and every legged one walks.

Fast checks: the config loads, its feet and base are frames of the model, and
``foot_radius`` is the height of the foot frames when the simulated robot stands at its
nominal posture. Slow: each quadruped config walks forward (0.3 m/s, solo12 0.2) for 4 s in a direct
lockstep loop (simulator and :class:`WalkingMpc`, no ROS) with the default MPC settings,
no code of its own, holds its config's velocity limits all at once (within the combined
limit), then stops, and stands at its nominal height.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from horizon_mpc.config import load_robot_config
from horizon_mpc.model import RobotModel

CONFIG_DIR = Path(__file__).resolve().parent.parent / "config"
ROBOTS = sorted(p.stem for p in CONFIG_DIR.glob("*.yaml"))
# wheeled-leg CENTAURO has its own motions (config/motions), not the trot
WALKERS = [r for r in ROBOTS if r != "centauro"]
SPEED = {"solo12": 0.2}  # m/s forward; 0.3 for the others (solo12 is 2.5 kg, 0.2 m steps)


def test_the_configs_are_the_expected_ones():
    assert {"go2", "solo12", "anymal_c", "a1", "go1", "b1", "anymal_b", "hyq",
            "laikago"} <= set(WALKERS)


@pytest.mark.parametrize("robot", ROBOTS)
def test_feet_and_base_are_frames_of_the_model(robot):
    cfg = load_robot_config(robot)
    model = RobotModel.from_example(cfg.robot)
    q = model.neutral()
    for frame in [*cfg.feet, cfg.base_link]:
        pos, _ = model.fk(frame)(q)  # raises on an unknown frame
        assert np.all(np.isfinite(np.asarray(pos, float)))


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_nominal_posture_names_every_joint(robot, caplog):
    """The laikago config (no SRDF) left its hip joints to the 'others at 0' and every
    node that loaded it warned that the posture left them at 0."""
    from horizon_mpc.posture import standing_configuration

    with caplog.at_level("WARNING"):
        standing_configuration(load_robot_config(robot))
    assert "leaves joints" not in caplog.text


@pytest.mark.parametrize("robot", WALKERS)
def test_foot_radius_is_the_foot_height_when_standing(robot):
    from horizon_mpc.sim.simulator import Simulator

    cfg = load_robot_config(robot)
    sim = Simulator(cfg)
    st = sim.state()
    model = RobotModel.from_example(cfg.robot)
    heights = [float(model.fk(foot)(st.q)[0][2]) for foot in cfg.feet]
    assert heights == pytest.approx([cfg.foot_radius] * len(heights), abs=1e-3)
    assert st.foot_contact.all()


def _walk(robot: str, vx: float | np.ndarray, seconds: float, stop: float = math.inf
          ) -> tuple[np.ndarray, np.ndarray, float]:
    """Lockstep loop: 1 s standing, then the command ``vx`` (a forward speed, or
    (vx, vy, wz)) until ``stop`` s, then zero; returns times, states q (rows) and the
    nominal base height."""
    from horizon_mpc.mpc import WalkingMpc
    from horizon_mpc.sim.simulator import Simulator
    from horizon_mpc.sim.trajectory import JointTrajectoryCommand

    cfg = load_robot_config(robot)
    sim = Simulator(cfg)
    mpc = WalkingMpc(cfg)
    dt = mpc.settings.dt
    steps = round(dt / sim.dt)
    h0 = float(sim.state().q[2])
    plan, ts, qs = None, [], []
    while True:
        st = sim.state()
        ts.append(st.time)
        qs.append(st.q.copy())
        if st.time >= seconds or _fallen(st.q, h0):
            break
        cmd = np.zeros(3)
        if 1.0 <= st.time < stop:
            cmd = np.array([vx, 0.0, 0.0]) if np.ndim(vx) == 0 else np.asarray(vx, float)
        plan = (mpc.start(st.q, st.v, st.time) if plan is None
                else mpc.update(st.time, st.q, st.v, cmd))
        n = min(6, plan.a.shape[1])
        sim.set_trajectory(JointTrajectoryCommand(
            sim.joint_names, st.time, dt * np.arange(n), plan.q[7:, :n].T, plan.v[6:, :n].T,
            plan.tau_head(n)[6:].T))
        sim.step(steps)
    return np.array(ts), np.array(qs), h0


def _fallen(q: np.ndarray, h0: float) -> bool:
    x, y, z, w = q[3:7]
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    return q[2] < 0.6 * h0 or abs(roll) > 0.5 or abs(pitch) > 0.5


@pytest.mark.slow
@pytest.mark.parametrize("robot", WALKERS)
def test_each_quadruped_walks_forward_with_its_config_only(robot):
    speed = SPEED.get(robot, 0.3)
    t, q, h0 = _walk(robot, speed, 4.0)
    assert t[-1] >= 4.0 - 1e-9, f"{robot} fell at t = {t[-1]:.2f} s"
    sel = t >= 2.5  # after the command ramp (1 m/s^2) and the first steps
    vx = (q[sel][-1, 0] - q[sel][0, 0]) / (t[sel][-1] - t[sel][0])
    assert vx == pytest.approx(speed, rel=0.33)
    assert abs(q[-1, 1] - q[0, 1]) < 0.2  # little lateral drift


@pytest.mark.slow
@pytest.mark.parametrize("robot", WALKERS)
def test_each_quadruped_holds_its_velocity_limits_combined_then_stops(robot):
    """The config's velocity limits (mpc.max_velocity) are ones the robot sustains: every
    limit at once (forward, to the right, turning right) for 5 s, then a stop, without a
    fall. The go2 defaults made solo12, anymal_c, a1 and go1 fall; with every axis at its
    limit (no combined limit) go2, go1 and solo12 fell after ~5 s: the command is limited
    to the combined norm sqrt(2) (locomotion/command.py), 0.82 of each limit here."""
    from horizon_mpc.locomotion import MpcSettings

    limits = MpcSettings.from_dict(load_robot_config(robot).section("mpc")).max_velocity
    cmd = np.array(limits) * [1.0, -1.0, -1.0]
    t, q, h0 = _walk(robot, cmd, 8.0, stop=6.0)
    assert t[-1] >= 8.0 - 1e-9, f"{robot} fell at t = {t[-1]:.2f} s (command {cmd})"
    sel = (t >= 2.5) & (t <= 4.0)
    travelled = np.hypot(*(q[sel][-1, :2] - q[sel][0, :2])) / (t[sel][-1] - t[sel][0])
    assert travelled > 0.3 * math.hypot(limits[0], limits[1])  # it walked, not stood


@pytest.mark.slow
@pytest.mark.parametrize("robot", WALKERS)
def test_each_quadruped_stands_at_its_nominal_height(robot):
    """Zero command: the base holds its nominal height (the barrier of the joint limits
    and friction cones pulled go2 11 % and solo12 8 % low with the base height weight
    at 100; within 3.1 % at 1000)."""
    t, q, h0 = _walk(robot, 0.0, 3.0)
    assert t[-1] >= 3.0 - 1e-9
    assert q[-1, 2] == pytest.approx(h0, rel=0.04), f"{robot} stands at {q[-1, 2]:.4f} m"
    assert np.hypot(*(q[-1, :2] - q[0, :2])) < 0.05  # and stays about where it is


def _config(tmp_path: Path, text: str):
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    return load_robot_config(str(path))


_GO2 = "robot: go2\nfeet: [FL_foot, FR_foot, RL_foot, RR_foot]\n"


@pytest.mark.parametrize("extra, match", [
    ("mcp: {n_nodes: 30}\n", r"unknown key\(s\) 'mcp' \(did you mean 'mpc'\?\)"),
    ("frictoin: 0.3\n", r"'frictoin' \(did you mean 'friction'\?\)"),
    ("sim: 5\n", r"'sim' must be a mapping, got 5"),
    ("sim: {kp: fast}\n", r"'sim.kp' must be a number, got 'fast'"),
    ("sim: {kp: []}\n", r"'sim.kp' is an empty list"),
    ("sim: {kd: [1, -2]}\n", r"'sim.kd\[1\]' must be >= 0, got -2"),
    ("sim: {physics_rate: 0}\n", r"'sim.physics_rate' must be > 0"),
    ("sim: {kpp: 3}\n", r"unknown keys in 'sim': \['kpp'\]"),
    ("nominal_joints: [a, b]\n", r"'nominal_joints' must be a mapping"),
    ("nominal_joints: {FL_calf_joint: abc}\n",
     r"'nominal_joints.FL_calf_joint' must be a number, got 'abc'"),
    ("friction: abc\n", r"'friction' must be a number, got 'abc'"),
    ("friction: 0\n", r"'friction' must be > 0"),
    ("friction: .nan\n", r"'friction' must be > 0"),
    ("friction: true\n", r"'friction' must be a number, got True"),
])
def test_a_config_value_of_the_wrong_kind_is_one_error_naming_file_and_key(tmp_path, extra,
                                                                           match):
    """An auditor's configs: a misspelt section or key was ignored without a word (the
    defaults used), and values of the wrong type ended in a traceback (sim: 5, a list for
    nominal_joints) or a message naming neither the file nor the key (friction: abc)."""
    with pytest.raises(ValueError, match=match) as err:
        _config(tmp_path, _GO2 + extra)
    assert "mine.yaml" in str(err.value)


@pytest.mark.parametrize("text, match", [
    ("robot: [go2]\nfeet: [FL_foot, FR_foot, RL_foot, RR_foot]\n",
     r"'robot' must be a name, got \['go2'\]"),
    ("robot: go2\nfeet: [FL_foot, FL_foot, RL_foot, RR_foot]\n",
     r"'feet' names \['FL_foot'\] more than once"),
    ("robot: go2\nfeet: [FL_foot, FR_foot, RL_foot, base]\n", "'feet' names the base link 'base'"),
    (_GO2 + "MPC: {n_nodes: 30}\n", r"'MPC' \(did you mean 'mpc'\?\)"),
])
def test_a_config_a_robot_cannot_be_built_from_is_refused_by_key(tmp_path, text, match):
    """An auditor's configs: a list for robot was 'unhashable type' from deep inside, a foot
    named twice "a constraint or cost called 'FL_foot_velocity' already exists", and an
    'MPC:' section was ignored (warned about) and the defaults used."""
    with pytest.raises(ValueError, match=match) as err:
        _config(tmp_path, text)
    assert "mine.yaml" in str(err.value)


@pytest.mark.parametrize("section, match", [
    ("mpc: [1]\n", r"'mpc' must be a mapping of \["),
    ("mpc: trot\n", r"'mpc' must be a mapping of \["),
    ("mpc: {n_nodes: 1}\n", r"'mpc.n_nodes' must be an integer in \[2, 500\], got 1"),
    ("mpc: {dt: 0.6}\n", r"'mpc.dt' must be in \[0.001, 0.5\], got 0.6"),
    ("mpc: {iterations: 60}\n", r"'mpc.iterations' must be an integer in \[1, 50\]"),
    ("mpc: {gait: {step_height: 0.35}}\n", r"'mpc.gait.step_height' must be in \[0, 0.3\]"),
    ("mpc: {gait: {step_duration: 3.0}}\n", r"'mpc.gait.step_duration' must be in \[0.05, 2\]"),
    ("mpc: {gait: {duty_factor: 0.01}}\n", r"'mpc.gait.duty_factor' must be in \[0.05, 1\]"),
    ("mpc: {max_velocity: [6.0, 0.3, 0.5]}\n", r"'mpc.max_velocity' must be 3 numbers in \[0, 5\]"),
    ("mpc: {max_command_norm: 0.001}\n", r"'mpc.max_command_norm' must be in \[0.01, 10\]"),
    ("mpc: {weights: {posture: 2.0e+9}}\n",
     r"'mpc.weights.posture' must be a number in \[0, 1e\+09\]"),
])
def test_mpc_settings_the_node_refuses_are_refused_everywhere_naming_the_file(tmp_path,
                                                                              section, match):
    """The MPC node declares its parameters with these ranges; the library and the motion
    CLI took the values (a walk of 1 node 'solved') and the node said 'Parameter n_nodes out
    of range', a parameter the user never set. And the file was not named."""
    from horizon_mpc.locomotion import MpcSettings

    cfg = _config(tmp_path, _GO2 + section)
    with pytest.raises(ValueError, match=match) as err:
        MpcSettings.from_config(cfg)
    assert str(err.value).startswith(str(tmp_path / "mine.yaml"))


def test_exponents_without_a_point_are_numbers_and_overrides_merge_key_by_key(tmp_path):
    """PyYAML read 1e-4 as the text '1e-4' ("must be a finite number", of a number); a
    gait override replaced the config's whole gait (the walk CLI's --set mpc={gait: {name:
    walk}} took the library's step duration and height, not solo12's)."""
    from horizon_mpc.locomotion import MpcSettings

    cfg = _config(tmp_path, _GO2 + "mpc: {weights: {acceleration: 1e-4, force: 2E+3, "
                  "posture: 1.5e3, base_yaw: .5e1}, "
                  "gait: {step_duration: 0.25, step_height: 0.04}}\n")
    st = MpcSettings.from_config(cfg, {"gait": {"name": "walk"}, "weights": {"posture": 1.0}})
    assert (st.weights.acceleration, st.weights.force, st.weights.posture) == (1e-4, 2e3, 1.0)
    assert MpcSettings.from_config(cfg).weights.posture == 1500.0
    assert st.weights.base_yaw == 5.0
    from horizon_mpc.config import parse_yaml

    assert [parse_yaml(t) for t in ("._e3", "1.2.3", "e5", "0x1F")] == ["._e3", "1.2.3",
                                                                         "e5", 31]
    assert (st.gait.name, st.gait.step_duration, st.gait.step_height) == ("walk", 0.25, 0.04)


def test_a_key_far_from_any_known_one_is_ignored_with_a_warning(tmp_path, caplog):
    """A user's own note in a config (not a typo of a known key) does not stop the robot."""
    with caplog.at_level("WARNING", logger="horizon_mpc.config"):
        cfg = _config(tmp_path, _GO2 + "description: my quadruped\n")
    assert cfg.robot == "go2"
    assert "unknown key(s) ['description'] ignored" in caplog.text


def test_per_joint_gains_in_the_config_reach_the_simulator(tmp_path):
    """doc/simulator.md: the sim gains are a number or one per joint (a list was a
    TypeError traceback in every executable)."""
    from horizon_mpc.sim.simulator import Simulator

    kp = [30.0] * 11 + [40.0]
    cfg = _config(tmp_path, _GO2 + f"sim: {{kp: {kp}, kd: 2}}\n")
    assert cfg.sim.kp == kp and cfg.sim.kd == 2.0
    sim = Simulator(cfg)
    try:
        assert sim.kp.tolist() == kp and sim.kd.tolist() == [2.0] * 12
    finally:
        sim.close()
    cfg = _config(tmp_path, _GO2 + "sim: {kp: [30, 30]}\n")
    with pytest.raises(ValueError, match=r"kp must be a non-negative scalar or \(12,\) array"):
        Simulator(cfg)


def test_a_config_the_robot_cannot_stand_with_is_refused_by_name(tmp_path):
    """A user's config (an auditor's): a1 with urdf_path: in place of robot: kept
    'nominal_posture: standing' with no SRDF to read it from: every joint at 0, calves
    outside their limits; the MPC refused every state and the lockstep simulator waited
    10 s per step. A base_link on a leg (odometry of the root labelled as the hip) and a
    joint named as a foot were taken too."""
    from horizon_mpc.posture import standing_configuration
    from horizon_mpc.robots import example_robot_files

    a1 = example_robot_files("a1").urdf
    feet = "[FL_foot, FR_foot, RL_foot, RR_foot]"
    cfg = _config(tmp_path, f"urdf_path: {a1}\nbase_link: trunk\nfeet: {feet}\n"
                            "nominal_posture: standing\n")
    with pytest.raises(ValueError, match="no SRDF to read it from .* nominal_joints"):
        standing_configuration(cfg)
    cfg = _config(tmp_path, f"urdf_path: {a1}\nbase_link: trunk\nfeet: {feet}\n"
                            "nominal_posture: null\n")
    with pytest.raises(ValueError, match=r"outside their URDF limits: FL_calf_joint=0 "):
        standing_configuration(cfg)
    cfg = _config(tmp_path, f"robot: go2\nbase_link: FL_hip\nfeet: {feet}\n")
    with pytest.raises(ValueError, match="base_link 'FL_hip' is not the URDF's root link"):
        standing_configuration(cfg)
    cfg = _config(tmp_path, "robot: go2\nbase_link: base\n"
                            "feet: [FL_calf_joint, FR_foot, RL_foot, RR_foot]\n")
    with pytest.raises(KeyError, match=r"\['FL_calf_joint'\] are not links of the URDF"):
        standing_configuration(cfg)
    # the working form of the same: every joint named
    joints = {f"{leg}_{j}_joint": v for leg in ("FL", "FR", "RL", "RR")
              for j, v in (("hip", 0.0), ("thigh", 0.8), ("calf", -1.5))}
    cfg = _config(tmp_path, f"urdf_path: {a1}\nbase_link: trunk\nfeet: {feet}\n"
                            f"nominal_posture: null\nnominal_joints: {joints}\n")
    _, q = standing_configuration(cfg)
    assert q[2] > 0.2


def test_a_misspelt_nominal_joint_is_refused_with_the_name_it_meant(tmp_path):
    """An auditor's config: nominal_joints {FL_thigh_jiont: 1.2} was dropped without a word
    (the SRDF's 0.785 stood)."""
    from horizon_mpc.posture import standing_configuration

    cfg = _config(tmp_path, "robot: go2\nbase_link: base\n"
                            "feet: [FL_foot, FR_foot, RL_foot, RR_foot]\n"
                            "nominal_joints: {FL_thigh_jiont: 1.2, FR_calf_joint: -1.6}\n")
    with pytest.raises(ValueError, match=r"does not have: 'FL_thigh_jiont' \(did you mean "
                                         r"'FL_thigh_joint'\?\)"):
        standing_configuration(cfg)
    cfg = _config(tmp_path, "robot: go2\nbase_link: base\n"
                            "feet: [FL_foot, FR_foot, RL_foot, RR_foot]\n"
                            "nominal_joints: {root_joint: 0.1}\n")
    with pytest.raises(ValueError, match="'root_joint'"):
        standing_configuration(cfg)


def test_a_relative_urdf_path_is_taken_from_the_configs_folder(tmp_path, monkeypatch):
    """It was taken from the working folder: a config with its URDF beside it worked from
    that folder only (session 28 audit)."""
    import shutil

    from horizon_mpc.posture import config_urdf_path
    from horizon_mpc.robots import example_robot_files

    (tmp_path / "myrobot").mkdir()
    shutil.copy(example_robot_files("go2").urdf, tmp_path / "myrobot" / "robot.urdf")
    cfg_file = tmp_path / "mine.yaml"
    cfg_file.write_text("urdf_path: myrobot/robot.urdf\nfeet: [FL_foot, FR_foot, RL_foot, "
                        "RR_foot]\n")
    monkeypatch.chdir("/")
    cfg = load_robot_config(str(cfg_file))
    assert config_urdf_path(cfg) == tmp_path / "myrobot" / "robot.urdf"
    assert config_urdf_path(cfg).is_file()
    cfg_file.write_text("urdf_path: 3\nfeet: [FL_foot]\n")
    with pytest.raises(ValueError, match="'urdf_path' must be a file path, got 3"):
        load_robot_config(str(cfg_file))


def test_the_walking_mpc_names_what_it_cannot_take():
    """ur5 (a fixed-base arm) was refused as having 'continuous joints', which it has not;
    a continuous joint was not named."""
    from horizon_mpc.nodes.mpc_node import _check_joints

    with pytest.raises(ValueError, match="'ur5' has a fixed base"):
        _check_joints(RobotModel.from_example("ur5"))
    _check_joints(RobotModel.from_example("go2"))


_HUGE = "1" + "0" * 400  # an integer beyond a float's range


@pytest.mark.parametrize("text, match", [
    (_GO2 + f"friction: {_HUGE}\n", "'friction' must be"),
    (_GO2 + f"sim: {{lateral_friction: {_HUGE}}}\n", "'sim.lateral_friction' must be"),
    (_GO2 + "sim: {1: 2, foo: 3}\n", r"unknown keys in 'sim': \['1', 'foo'\]"),
    ("robot: go2\nbase_link: null\nfeet: [FL_foot, FR_foot, RL_foot, RR_foot]\n",
     "'base_link' must be a name, got None"),
    ("robot: go2\nfeet: [FL_foot, null, 3, RR_foot]\n", "'feet' must be a non-empty list"),
    ("robot: go2\nfeet: ['']\n", "'feet' must be a non-empty list"),
    (_GO2 + "note: " + "[" * 3000 + "]" * 3000 + "\n", "nested too deeply"),
])
def test_fuzzed_robot_configs_fail_with_a_value_error_naming_the_file(tmp_path, text, match):
    """An auditor's fuzzing: a huge integer was an OverflowError, mixed-type keys a
    TypeError from sorted(), deep nesting a RecursionError; base_link null and non-text feet
    were taken ('None', '3')."""
    with pytest.raises(ValueError, match=match) as err:
        _config(tmp_path, text)
    assert "mine.yaml" in str(err.value)


@pytest.mark.parametrize("section, match", [
    (f"mpc: {{friction: {_HUGE}}}\n", "'mpc.friction' must be finite"),
    (f"mpc: {{n_nodes: {_HUGE}}}\n", "'mpc.n_nodes' must be"),
    (f"mpc: {{weights: {{base_height: {_HUGE}}}}}\n", "'mpc.weights.base_height'"),
    ("mpc: {1: 2, foo: 3}\n", r"unknown key\(s\) \['1', 'foo'\] in 'mpc'"),
    ("mpc: {rho_init: [], friction: [-1]}\n", "'mpc.friction' must be a number, got"),
    ("mpc: {gait: {name: [a]}}\n", "'mpc.gait.name' must be one of"),
    ("mpc: {weights: {base_linear_velocity: [[1], [1, 2], 3]}}\n",
     "'mpc.weights.base_linear_velocity' must be 3 numbers"),
])
def test_fuzzed_mpc_sections_fail_with_a_value_error_naming_the_key(tmp_path, section, match):
    from horizon_mpc.locomotion import MpcSettings

    with pytest.raises(ValueError, match=match):
        MpcSettings.from_config(_config(tmp_path, _GO2 + section))


def test_an_empty_mpc_section_keeps_the_overrides_and_merge_keys_are_yaml(tmp_path):
    """'mpc:' with nothing under it dropped the walk's overrides (40 nodes -> 24); YAML
    merge keys ('<<: *base') were 'not valid YAML'."""
    from horizon_mpc.locomotion import MpcSettings

    cfg = _config(tmp_path, _GO2 + "mpc:\n  # n_nodes: 30\n")
    assert MpcSettings.from_config(cfg, {"n_nodes": 40}).n_nodes == 40
    cfg = _config(tmp_path, _GO2 + "base: &b {lateral_friction: 0.8}\n"
                  "sim: {<<: *b, kp: 20.0}\n")
    assert (cfg.sim.lateral_friction, cfg.sim.kp) == (0.8, 20.0)
