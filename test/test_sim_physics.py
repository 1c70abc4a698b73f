"""The pybullet simulator library: model fidelity, conventions, control, pushes (no ROS)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from horizon_mpc.sim import JointTrajectoryCommand, Simulator, write_gif
from horizon_mpc.sim.rotations import quat_from_yaw
from horizon_mpc.sim.standing import standing_feedforward


@pytest.fixture(scope="module")
def go2():
    sim = Simulator("go2")
    yield sim
    sim.close()


@pytest.fixture(autouse=True)
def _fresh(request):
    """Tests using the shared go2 start from the standing start at t = 0."""
    if "go2" in request.fixturenames:
        request.getfixturevalue("go2").reset()


def random_configuration(sim: Simulator, seed: int) -> np.ndarray:
    """A configuration with a tilted, raised base and joints spread within their limits."""
    rng = np.random.default_rng(seed)
    q = sim.q_start.copy()
    q[0:3] += rng.uniform(-0.3, 0.3, 3) + [0.0, 0.0, 0.5]
    axis = rng.normal(size=3)
    rot = pin.AngleAxis(0.6, axis / np.linalg.norm(axis)).matrix()
    q[3:7] = pin.Quaternion(rot).coeffs()
    q[7:] += rng.uniform(-0.3, 0.3, sim.n_joints)
    return q


# ---------------------------------------------------------------- model fidelity
@pytest.mark.parametrize("robot", ["go2", "solo12", "anymal_c", "centauro"])
def test_total_mass_matches_pinocchio(robot):
    """Links without <inertial> (anymal's base, CENTAURO's contact frames) must not add 1 kg."""
    with Simulator(robot) as sim:
        expected = pin.computeTotalMass(sim.model)
        assert sim.total_mass() == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("robot", ["go2", "anymal_c"])
def test_state_round_trips_in_pinocchio_conventions(robot):
    """set_state(q, v) then state() gives q, v back (base frame twist, joints by name)."""
    with Simulator(robot) as sim:
        q = random_configuration(sim, 1)
        v = np.random.default_rng(2).uniform(-1.0, 1.0, sim.model.nv)
        sim.set_state(q, v)
        st = sim.state()
        np.testing.assert_allclose(st.q[:3], q[:3], atol=1e-6)
        assert abs(abs(st.q[3:7] @ q[3:7]) - 1.0) < 1e-6  # same rotation (q ~ -q)
        np.testing.assert_allclose(st.q[7:], q[7:], atol=1e-6)
        np.testing.assert_allclose(st.v, v, atol=1e-6)


@pytest.mark.parametrize("robot", ["go2", "anymal_c", "solo12"])
def test_link_positions_match_pinocchio_forward_kinematics(robot):
    """pybullet's URDF link frames equal Pinocchio's FK at the simulator's q.

    go2's root link has an offset, rotated inertial frame (pybullet's base pose is that
    frame); anymal's pybullet joint order differs from Pinocchio's.
    """
    with Simulator(robot) as sim:
        sim.set_state(random_configuration(sim, 3))
        sim.step(5)  # let it fall a little: a state pybullet computed itself
        q = sim.state().q
        data = sim.model.createData()
        pin.framesForwardKinematics(sim.model, data, q)
        for foot in sim.feet:
            pos, _ = sim.link_pose(foot)
            expected = data.oMf[sim.model.getFrameId(foot)].translation
            np.testing.assert_allclose(pos, expected, atol=1e-6, err_msg=foot)


def test_twist_is_expressed_in_the_base_frame(go2):
    """Yawed 90 deg and moving along world +y, the base moves along its own +x."""
    q = go2.q_start.copy()
    q[2] += 1.0
    q[3:7] = quat_from_yaw(np.pi / 2)
    go2.set_state(q)
    p.resetBaseVelocity(go2.body, [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=go2.client)
    st = go2.state()
    np.testing.assert_allclose(st.base_linear_velocity, [1.0, 0.0, 0.0], atol=1e-6)
    p.resetBaseVelocity(go2.body, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], physicsClientId=go2.client)
    st = go2.state()
    np.testing.assert_allclose(st.base_angular_velocity, [0.0, -1.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(st.v[3:6], st.base_angular_velocity)


def test_joint_velocity_motors_are_disabled(go2):
    """With zero gains the legs fold under gravity: nothing else holds the joints."""
    go2.kp[:] = 0.0
    go2.kd[:] = 0.0
    go2.reference.hold(np.zeros(go2.n_joints), np.zeros(go2.n_joints))
    try:
        go2.step(300)
        assert go2.state().q[2] < go2.q_start[2] - 0.1
    finally:
        go2.kp[:] = go2.cfg.sim.kp
        go2.kd[:] = go2.cfg.sim.kd


def test_applied_torques_respect_the_effort_limits(go2):
    target = go2.state().joint_positions + 3.0  # far away: the PD term saturates
    go2.set_trajectory(JointTrajectoryCommand(go2.joint_names, 0.0, np.array([0.0]),
                                              target[None, :]))
    go2.step(2)
    tau = go2.state().tau
    assert np.all(np.abs(tau) <= go2.effort_limit + 1e-9)
    np.testing.assert_allclose(np.abs(tau), go2.effort_limit)


def test_standing_feedforward_balances_gravity(go2):
    """g(q) = S^T tau + J_c^T f holds exactly, and the weight is shared by the feet."""
    tau, f = go2.tau_standing, go2.standing_forces
    model, q = go2.model, go2.q_start
    data = model.createData()
    g = pin.computeGeneralizedGravity(model, data, q)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jt_f = sum(
        pin.getFrameJacobian(model, data, model.getFrameId(foot),
                             pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3].T @ f[i]
        for i, foot in enumerate(go2.feet)
    )
    np.testing.assert_allclose(g, np.concatenate((np.zeros(6), tau)) + jt_f, atol=1e-6)
    assert f[:, 2].sum() == pytest.approx(pin.computeTotalMass(model) * 9.81, rel=1e-3)


# ---------------------------------------------------------------- behaviour
@pytest.mark.slow  # 10 s of sim time per robot (~1-1.5 s wall each on an idle machine)
@pytest.mark.parametrize("robot", ["go2", "solo12", "anymal_c"])
def test_standing_hold_keeps_height_for_10s(robot):
    """PD hold + gravity-compensating feed-forward: base height within 2 cm for 10 s."""
    with Simulator(robot) as sim:
        start = sim.state()
        assert start.foot_contact.all()
        heights = []
        for _ in range(100):
            sim.step(round(0.1 / sim.dt))
            heights.append(sim.state().q[2])
        assert sim.time == pytest.approx(10.0)
        assert np.max(np.abs(np.array(heights) - sim.q_start[2])) < 0.02
        end = sim.state()
        assert end.foot_contact.all()
        # standing still: the weight is on the feet and nothing moves
        assert end.foot_force.sum() == pytest.approx(sim.total_mass() * 9.81, rel=0.05)
        assert np.abs(end.v).max() < 0.05


def test_simulators_in_one_process_are_independent():
    with Simulator("go2") as a, Simulator("go2") as b:
        a.push(a.robot.root_link, [0.0, 60.0, 0.0], duration=0.1)
        a.step(100)
        b.step(100)
        assert a.client != b.client
        assert a.state().q[1] > 0.005
        assert abs(b.state().q[1]) < 1e-3


def test_push_moves_the_base_in_the_push_direction(go2):
    go2.push(go2.robot.root_link, [0.0, 40.0, 0.0], duration=0.1)
    go2.step(100)
    st = go2.state()
    assert st.q[1] > 0.005  # m, moved along +y ...
    assert abs(st.q[0]) < st.q[1] / 2  # ... and mainly along y
    assert st.base_linear_velocity[1] > 0.1


def test_push_on_a_foot_link_and_bad_pushes(go2):
    go2.push(go2.feet[0], [0.0, 0.0, 30.0], duration=0.05)
    go2.step(50)
    with pytest.raises(ValueError, match="unknown link 'nope'"):
        go2.push("nope", [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="NaN"):
        go2.push(go2.robot.root_link, [np.nan, 0.0, 0.0])
    with pytest.raises(ValueError, match="duration"):
        go2.push(go2.robot.root_link, [1.0, 0.0, 0.0], duration=0.0)
    for odd in ("0.1", None, True):  # "0.1" was a TypeError from numpy
        with pytest.raises(ValueError, match="a positive number of seconds"):
            go2.push(go2.robot.root_link, [1.0, 0.0, 0.0], duration=odd)


def test_reset_restores_the_start_state(go2):
    go2.push(go2.robot.root_link, [50.0, 0.0, 0.0], duration=0.2)
    go2.step(300)
    go2.reset()
    st = go2.state()
    assert go2.time == 0.0
    np.testing.assert_allclose(st.q, go2.q_start, atol=1e-9)
    np.testing.assert_allclose(st.v, 0.0, atol=1e-9)
    assert go2.reference.holding
    go2.step(200)  # and the pushes are gone
    assert np.abs(go2.state().q[:2]).max() < 0.01


def crouch(sim: Simulator, depth: float = 0.25, duration: float = 1.0, points: int = 21):
    """A smooth go2 crouch from the standing posture: thighs +depth, calves -2 depth (rad)."""
    start = sim.state().joint_positions
    delta = np.array([depth if n.endswith("thigh_joint") else -2 * depth
                      if n.endswith("calf_joint") else 0.0 for n in sim.joint_names])
    times = np.linspace(0.0, duration, points)
    s = 0.5 - 0.5 * np.cos(np.pi * times / duration)
    ds = 0.5 * np.pi / duration * np.sin(np.pi * times / duration)
    q_end = sim.q_start.copy()
    q_end[7:] = start + delta
    tau_end, _ = standing_feedforward(sim.model, q_end, sim.feet)
    efforts = sim.tau_standing + s[:, None] * (tau_end - sim.tau_standing)
    cmd = JointTrajectoryCommand(sim.joint_names, sim.time, times,
                                 start + s[:, None] * delta, ds[:, None] * delta, efforts)
    return cmd, lambda t: start + (0.5 - 0.5 * np.cos(np.pi * min(t, duration) / duration)) * delta


def test_trajectory_is_tracked_then_held():
    with Simulator("go2", trajectory_timeout=5.0) as sim:
        cmd, ref = crouch(sim)
        sim.set_trajectory(cmd)
        errors = []
        for _ in range(100):
            sim.step(10)
            st = sim.state()
            errors.append(np.abs(st.joint_positions - ref(st.time)).max())
        # 0.1 rad: PD (kp 30) with static feed-forward only, during a 1 s crouch of 0.5 rad
        assert max(errors) < 0.1
        heights = []
        for _ in range(20):
            sim.step(100)
            heights.append(sim.state().q[2])
        st = sim.state()
        assert sim.reference.holding
        # 0.05 rad = 1.5 N m at kp 30: the real load sharing differs from the feed-forward's
        assert np.abs(st.joint_positions - cmd.positions[-1]).max() < 0.05
        assert np.ptp(heights) < 0.005  # m: holding still, not sagging
        assert heights[-1] < sim.q_start[2] - 0.05  # and crouched


def test_invalid_command_is_rejected_and_the_last_good_one_kept(go2):
    cmd, _ = crouch(go2)
    go2.set_trajectory(cmd)
    go2.step(100)
    before = go2.reference.reference(go2.time)
    bad = JointTrajectoryCommand(go2.joint_names[:-1], go2.time, np.array([0.0]),
                                 np.zeros((1, go2.n_joints - 1)))
    with pytest.raises(ValueError, match="missing joint names"):
        go2.set_trajectory(bad)
    after = go2.reference.reference(go2.time)
    for x, y in zip(before, after, strict=True):
        np.testing.assert_array_equal(x, y)


def test_commands_are_matched_by_joint_name(go2):
    cmd, _ = crouch(go2)
    order = list(reversed(go2.joint_names))
    go2.set_trajectory(cmd.reordered(order))
    q_reversed = go2.reference.reference(0.5)[0].copy()
    go2.set_trajectory(cmd)
    np.testing.assert_array_equal(q_reversed, go2.reference.reference(0.5)[0])


def test_render_and_gif(go2, tmp_path):
    frames = []
    for _ in range(3):
        go2.step(20)
        frames.append(go2.render(64, 48))
    assert frames[0].shape == (48, 64, 3) and frames[0].dtype == np.uint8
    assert frames[0].std() > 5  # not a blank image
    path = write_gif(tmp_path / "go2.gif", frames, fps=10)
    assert path.stat().st_size > 0


def test_an_absurd_push_is_refused(go2):
    with pytest.raises(ValueError, match="beyond the plausible"):
        go2.push("base", [1e12, 0.0, 0.0])


def test_reset_recovers_a_world_whose_state_went_non_finite(go2):
    # pybullet keeps the NaNs in its contact caches: teleporting alone left a robot that
    # fell through the floor (z -45 m two seconds after a reset)
    q = go2.state().q.copy()
    v = np.zeros(go2.model.nv)
    v[6:] = 1e200
    go2.set_state(q, v)
    go2.step(5)
    assert not np.all(np.isfinite(go2.state().q))
    go2.reset(reset_time=False)
    go2.step(1000)
    st = go2.state()
    assert np.all(np.isfinite(st.q)) and st.q[2] == pytest.approx(go2.q_start[2], abs=0.03)


def test_a_reset_world_runs_as_a_fresh_one(go2):
    """pybullet keeps contact data across a teleport: after a reset the feet still carried
    the forces of before, and a run differed from a fresh simulator's by 0.5 mm; a blown
    world teleported back to a finite pose before the reset sank through the ground."""
    go2.step(500)
    go2.reset()
    assert np.all(go2.state().foot_force == 0.0)
    fresh = Simulator("go2")
    try:
        for _ in range(3):
            go2.step(300)
            fresh.step(300)
            np.testing.assert_array_equal(go2.state().q, fresh.state().q)
    finally:
        fresh.close()
    v = np.zeros(go2.model.nv)
    v[6:] = 1e200
    go2.set_state(go2.q_start, v)
    go2.step(3)
    go2.set_state(go2.q_start)  # a finite pose again, NaNs still in the caches
    go2.reset()
    go2.step(600)
    assert go2.state().q[2] == pytest.approx(go2.q_start[2], abs=0.03)


def test_set_state_and_step_refuse_what_they_cannot_do(go2):
    q, v = go2.q_start.copy(), np.zeros(go2.model.nv)
    bad_v = v.copy()
    bad_v[8] = np.nan
    zero_quat = q.copy()
    zero_quat[3:7] = 0.0
    for args, match in (((q, bad_v), "not finite"), ((q[:-1],), "shape"),
                        ((np.r_[q, 0.0, 0.0],), "shape"), ((zero_quat,), "quaternion is zero")):
        with pytest.raises(ValueError, match=match):
            go2.set_state(*args)
    for n in (-5, 1.5, True):
        with pytest.raises(ValueError, match="integer >= 0"):
            go2.step(n)
    np.testing.assert_allclose(go2.state().q, go2.q_start, atol=1e-7)  # nothing changed


def test_the_simulator_imports_pybullet_without_its_banner_and_keeps_stderr():
    """pybullet writes its build time on stderr at import (every sim_node start showed it):
    the simulator's modules import it quietly, and stderr works as before afterwards."""
    import subprocess
    import sys

    code = ("import sys; import horizon_mpc.sim.simulator as s; "
            "print('after', s.p.getAPIVersion() > 0, file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True)
    assert out.stderr == "after True\n"
    plain = subprocess.run([sys.executable, "-c", "import pybullet"], capture_output=True,
                           text=True, timeout=120, check=True)
    assert "pybullet build time" in plain.stderr  # what the quiet import hides


def test_the_urdf_importers_notes_on_what_the_loader_corrects_stay_off_stdout():
    """pybullet's importer printed ~20 b3Warning lines on stdout per anymal/hyq/a1 start
    (links without <inertial>, placeholder 1e-6 inertias: both corrected by the loader);
    now those are dropped, anymal_c's zeroed camera inertias are named at INFO, and
    stdout works as before afterwards."""
    import subprocess
    import sys

    code = ("import logging, sys; logging.basicConfig(level=logging.INFO, stream=sys.stderr)\n"
            "from horizon_mpc.sim import Simulator\n"
            "for robot in ('anymal_b', 'a1', 'hyq', 'anymal_c', 'centauro'): Simulator(robot)\n"
            "print('after')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, check=True)
    assert out.stdout == "after\n"
    assert "b3Warning" not in out.stderr
    # CENTAURO's 9 links without <inertial>: one note, then their names; those after the
    # first were warnings (ball1_tip, D435_*, contact_1..4)
    assert "WARNING" not in out.stderr, out.stderr
    assert ("anymal.urdf: pybullet zeroed the inertia tensors of depth_camera_front_camera, "
            "depth_camera_rear_camera, depth_camera_left_camera, depth_camera_right_camera, "
            "hatch") in out.stderr


def test_a_urdf_pybullet_cannot_load_is_refused_with_what_its_parser_said(tmp_path):
    from horizon_mpc.sim.loading import load_robot

    urdf = tmp_path / "broken.urdf"
    urdf.write_text('<robot name="r"><link name="a"/><joint name="j" type="revolute">'
                    '<parent link="a"/><child link="nowhere"/></joint></robot>')
    client = p.connect(p.DIRECT)
    try:
        with pytest.raises(ValueError, match=r"pybullet could not load the URDF .*broken.urdf "
                                             r".*its parser said: .*does not specify limits"):
            load_robot(client, urdf)
    finally:
        p.disconnect(client)


def test_an_empty_urdf_range_does_not_lock_the_joint(tmp_path):
    """lower="0" upper="0" (an exporter's unknown range): pybullet locked every joint at 0,
    and the standing go2 rose on straight legs (0.336 -> 0.436 m) under the MPC."""
    import re

    from horizon_mpc.config import load_robot_config
    from horizon_mpc.robots import example_robot_files

    text = example_robot_files("go2").urdf.read_text()
    text = re.sub(r'(lower|upper)="[^"]*"', r'\1="0"', text)
    (tmp_path / "go2_no_ranges.urdf").write_text(text)
    (tmp_path / "mine.yaml").write_text("robot: go2\nurdf_path: go2_no_ranges.urdf\n"
                                        "feet: [FL_foot, FR_foot, RL_foot, RR_foot]\n")
    finals = []
    for cfg in ("go2", load_robot_config(str(tmp_path / "mine.yaml"))):
        with Simulator(cfg) as sim:
            target = sim.q_start[7:] + 0.2  # within go2's real ranges, 0 outside the empty
            sim.set_trajectory(JointTrajectoryCommand(sim.joint_names, 0.0, np.array([0.0]),
                                                      target[None, :]))
            sim.step(round(0.5 / sim.dt))
            finals.append(sim.state().q)
    # locked, the joints stayed 0.12-0.2 rad from where go2's moved
    np.testing.assert_allclose(finals[1], finals[0], atol=1e-6)


def test_a_simulator_leaves_no_folder_behind(tmp_path, monkeypatch):
    """Each simulator left a /tmp/horizon_mpc_sim_* folder with its ground texture (377 on
    an auditor's host); the texture is loaded from a folder removed right after."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    sim = Simulator("go2")
    try:
        assert not list(tmp_path.glob("horizon_mpc_sim_*"))
        assert sim.render(width=32, height=24).shape[:2] == (24, 32)  # the texture is loaded
    finally:
        sim.close()
    assert not list(tmp_path.iterdir())


def test_efforts_beyond_the_limits_are_said_to_be_clipped(go2):
    """solo12's URDF limits (1000) let efforts of 5e6 throw it 18 m up, without a word (an
    auditor's standalone use of sim_node); a plan's own torques say nothing."""
    q = go2.q_start[7:][None, :]
    assert go2.set_trajectory(JointTrajectoryCommand(
        go2.joint_names, 0.0, np.array([0.0]), q, efforts=go2.tau_standing[None, :])) is None
    efforts = go2.tau_standing[None, :].copy()
    efforts[0, 2] = 5e6
    note = go2.set_trajectory(JointTrajectoryCommand(go2.joint_names, 0.0, np.array([0.0]), q,
                                                     efforts=efforts))
    assert note.startswith("efforts beyond the effort limits are clipped to them: "
                           f"{go2.joint_names[2]} 5e+06 (limit ")
    assert "1 joint(s) over" in note


@pytest.mark.parametrize("kwargs, match", [
    ({"dt": float("inf")}, "dt must be a finite number > 0"),
    ({"friction": float("nan")}, "friction must be a finite number >= 0"),
    ({"friction": -1.0}, "friction must be a finite number >= 0"),
    ({"trajectory_timeout": -1.0}, "trajectory_timeout must be a number > 0"),
    ({"max_stamp_offset": float("nan")}, "max_stamp_offset must be a number > 0"),
    ({"base_pose": (1.0, 2.0)}, r"base_pose must be \(x, y, yaw\)"),
])
def test_simulator_arguments_that_cannot_run_are_refused_by_name(kwargs, match):
    """dt inf read 'time inf' and a NaN base, a negative time-out refused every trajectory,
    a NaN friction was taken, a 2-number pose was 'not enough values to unpack'."""
    with pytest.raises(ValueError, match=match):
        Simulator("go2", **kwargs)


def test_simulator_arguments_of_numpy_kinds_and_infinite_time_outs_are_taken():
    """They ran before the arguments were checked (a reviewer): keep them."""
    with Simulator("go2", friction=np.int64(1), trajectory_timeout=np.inf, dt=np.float32(1e-3),
                   base_pose=np.array([0.1, 0.0, 0.2])) as sim:
        sim.step(5)
        assert sim.friction == 1.0 and np.isfinite(sim.state().q).all()
