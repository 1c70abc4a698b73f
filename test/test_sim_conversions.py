"""ROS message <-> numpy conversions, and fuzzing of everything a message can carry into the
simulator (no DDS: messages are built and converted in-process)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Duration, Time
from hypothesis import event, given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from horizon_mpc.nodes.conversions import (
    duration_from_seconds,
    joint_state_from_msg,
    joint_state_to_msg,
    joint_trajectory_from_msg,
    joint_trajectory_to_msg,
    odometry_from_msg,
    odometry_to_msg,
    quaternion_from_msg,
    quaternion_to_msg,
    seconds_from_duration,
    state_from_msgs,
    time_from_ns,
    time_from_seconds,
    time_to_ns,
)
from horizon_mpc.sim import JointTrajectoryCommand, Simulator
from horizon_mpc.sim.trajectory import ReferenceGenerator

JOINTS = ["j0", "j1", "j2"]


def test_time_round_trips_exactly_in_nanoseconds():
    for ns in (0, 1, 999_999_999, 1_000_000_000, 12_345_678_901_234):
        assert time_to_ns(time_from_ns(ns)) == ns
    assert time_to_ns(time_from_seconds(1.002)) == 1_002_000_000
    with pytest.raises(ValueError):
        time_from_ns(-1)


def test_negative_durations_round_trip():
    for t in (-1.5, -0.001, 0.0, 0.25, 3.0):
        assert seconds_from_duration(duration_from_seconds(t)) == pytest.approx(t, abs=1e-9)


def test_quaternions_are_xyzw_and_normalised():
    msg = quaternion_to_msg([0.0, 0.0, 1.0, 1.0])
    assert (msg.z, msg.w) == (1.0, 1.0)
    np.testing.assert_allclose(quaternion_from_msg(msg), [0, 0, 2**-0.5, 2**-0.5])
    with pytest.raises(ValueError, match="invalid quaternion"):
        quaternion_from_msg(quaternion_to_msg([0.0, 0.0, 0.0, 0.0]))


def test_joint_state_is_matched_by_name():
    msg = joint_state_to_msg(Time(), ["j2", "j0", "j1"], [2.0, 0.0, 1.0], [20.0, 0.0, 10.0])
    q, v, tau = joint_state_from_msg(msg, JOINTS)
    np.testing.assert_array_equal(q, [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(v, [0.0, 10.0, 20.0])
    np.testing.assert_array_equal(tau, 0.0)  # not given: zeros
    with pytest.raises(ValueError, match="lacks joints \\['j3'\\]"):
        joint_state_from_msg(msg, [*JOINTS, "j3"])
    bad = JointState(name=JOINTS, position=[1.0])
    with pytest.raises(ValueError, match="position has 1 values for 3 names"):
        joint_state_from_msg(bad, JOINTS)


def test_odometry_and_state_round_trip():
    pos, quat = np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.0, np.sin(0.3), np.cos(0.3)])
    lin, ang = np.array([0.1, 0.2, 0.3]), np.array([-0.1, 0.0, 0.5])
    odom = odometry_to_msg(time_from_ns(7), pos, quat, lin, ang, child_frame_id="base")
    assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base")
    for a, b in zip(odometry_from_msg(odom), (pos, quat, lin, ang), strict=True):
        np.testing.assert_allclose(a, b)
    js = joint_state_to_msg(time_from_ns(7), JOINTS, [0.1, 0.2, 0.3], [1.0, 2.0, 3.0])
    q, v = state_from_msgs(js, odom, JOINTS)
    np.testing.assert_allclose(q, [*pos, *quat, 0.1, 0.2, 0.3])
    np.testing.assert_allclose(v, [*lin, *ang, 1.0, 2.0, 3.0])


def test_joint_trajectory_round_trip():
    cmd = JointTrajectoryCommand(JOINTS, 2.5, np.array([0.0, 0.1]), np.ones((2, 3)),
                                 np.zeros((2, 3)), np.full((2, 3), 4.0))
    back = joint_trajectory_from_msg(joint_trajectory_to_msg(cmd), now=0.0)
    assert back.joint_names == JOINTS and back.t0 == pytest.approx(2.5)
    for field in ("times", "positions", "velocities", "efforts"):
        np.testing.assert_allclose(getattr(back, field), getattr(cmd, field))


def test_zero_stamp_means_now_and_empty_arrays_mean_not_given():
    msg = JointTrajectory(joint_names=JOINTS)
    msg.points.append(JointTrajectoryPoint(positions=[0.0, 0.0, 0.0]))
    cmd = joint_trajectory_from_msg(msg, now=4.2)
    assert cmd.t0 == 4.2 and cmd.velocities is None and cmd.efforts is None


def test_ragged_points_are_named():
    msg = JointTrajectory(joint_names=JOINTS)
    msg.points.append(JointTrajectoryPoint(positions=[0.0] * 3, velocities=[0.0] * 3))
    msg.points.append(JointTrajectoryPoint(positions=[0.0] * 3, time_from_start=Duration(sec=1)))
    with pytest.raises(ValueError, match="point 1 has 0 velocities for 3 joints"):
        joint_trajectory_from_msg(msg, now=0.0)


# ---------------------------------------------------------------- fuzzing
@pytest.fixture(scope="module")
def go2():
    sim = Simulator("go2")
    sim.step(1000)  # t = 1 s: stamps 0..4 s in the fuzzed messages lie around "now"
    yield sim
    sim.close()


_DEFECTS = ["unknown", "missing", "duplicate", "ragged", "nan", "backwards", "late", "empty"]


@st.composite
def trajectory_messages(draw, joint_names):
    """JointTrajectory messages: valid (in any joint order) or with one kind of defect."""
    defect = draw(st.sampled_from(["none", "none", "none", *_DEFECTS]))
    names = draw(st.permutations(list(joint_names)))
    if defect == "unknown":
        names[draw(st.integers(0, len(names) - 1))] = "no_such_joint"
    elif defect == "missing":
        names.pop(draw(st.integers(0, len(names) - 1)))
    elif defect == "duplicate":
        names[0] = names[1]
    nj = len(names)
    msg = JointTrajectory(joint_names=names)
    # the simulator is at t ~ 1 s; 0 means "now"
    stamp = draw(st.one_of(st.just(0), st.integers(6 * 10**8, 14 * 10**8)))
    if defect == "late":
        stamp = draw(st.sampled_from([3 * 10**9, 1]))  # 2 s ahead / 1 s behind
    msg.header.stamp = time_from_ns(stamp)
    n_points = 0 if defect == "empty" else draw(st.integers(1, 4))
    bad_point = draw(st.integers(0, n_points - 1)) if n_points else -1
    has_v, has_e = draw(st.booleans()), draw(st.booleans())
    t = draw(st.integers(0, 10**8))
    finite = st.floats(-3, 3)
    for k in range(n_points):
        if k:
            step = draw(st.integers(1, 2 * 10**8))
            t += -step if defect == "backwards" and k == bad_point else step
        ragged = defect == "ragged" and k == bad_point
        length = nj + (draw(st.sampled_from([-1, 1])) if ragged else 0)
        row = draw(st.lists(finite, min_size=length, max_size=length))
        if defect == "nan" and k == bad_point and row:
            row[draw(st.integers(0, len(row) - 1))] = draw(st.sampled_from([math.nan, math.inf]))
        point = JointTrajectoryPoint(positions=row)
        if has_v:
            point.velocities = draw(st.lists(finite, min_size=nj, max_size=nj))
        if has_e:
            point.effort = draw(st.lists(st.floats(-50, 50), min_size=nj, max_size=nj))
        point.time_from_start = duration_from_seconds(t * 1e-9)
        msg.points.append(point)
    return msg


@settings(max_examples=150)
@given(data=st.data())
def test_fuzz_message_to_simulator(go2, data):
    """A message is either accepted, giving finite torques within limits, or rejected with a
    ValueError that leaves the previous command in force."""
    msg = data.draw(trajectory_messages(go2.joint_names))
    now = go2.time
    before = [x.copy() for x in go2.reference.reference(now)]
    try:
        cmd = joint_trajectory_from_msg(msg, now=now)
        go2.set_trajectory(cmd)
    except ValueError as exc:
        assert str(exc)  # says what was wrong
        event(f"rejected: {str(exc)[:12]}")
        after = go2.reference.reference(now)
        for x, y in zip(before, after, strict=True):
            np.testing.assert_array_equal(x, y)
        return
    event("accepted")
    for t in (now, now + 0.05, now + 0.5):
        q, v, tau = go2.reference.reference(t)
        assert np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and np.all(np.isfinite(tau))
    go2.step(1)
    assert np.all(np.abs(go2.state().tau) <= go2.effort_limit)
    go2.reset(reset_time=False)


@given(
    times=st.lists(st.floats(0, 2), min_size=1, max_size=5, unique=True).map(sorted),
    velocities=st.booleans(),
    t=st.floats(-1, 5),
)
def test_fuzz_reference_is_finite_and_continuous_at_points(times, velocities, t):
    k = len(times)
    rng = np.random.default_rng(k)
    # close points move little (validate refuses more than PLAUSIBLE_SPEED between points,
    # and set_command from the reference, 0 at now = 0, to a first point ahead of it)
    ends = [0.0, *times] if times[0] > 0 else times
    gap = float(np.min(np.diff(ends))) if len(ends) > 1 else 1.0
    scale = min(1.0, 10.0 * gap)
    cmd = JointTrajectoryCommand(JOINTS, 0.0, np.array(times), scale * rng.normal(size=(k, 3)),
                                 rng.normal(size=(k, 3)) if velocities else None, None)
    ref = ReferenceGenerator(3, timeout=100.0)
    ref.hold(np.zeros(3), np.zeros(3))
    ref.set_command(cmd.validate(JOINTS), now=0.0)
    q, v, tau = ref.reference(max(t, 0.0))
    assert np.all(np.isfinite(q)) and np.all(np.isfinite(v)) and np.all(np.isfinite(tau))


@given(
    link=st.sampled_from(["base", "FL_foot", "", "nope", "FL_calf"]),
    force=st.lists(st.one_of(st.floats(-100, 100), st.just(math.nan)), min_size=2, max_size=4),
    duration=st.floats(-1, 1),
)
def test_fuzz_pushes(go2, link, force, duration):
    try:
        go2.push(link, force, None, duration)
    except ValueError as exc:
        assert str(exc)
        return
    assert link in go2.robot.link_index and len(force) == 3 and duration > 0
    go2.reset(reset_time=False)
