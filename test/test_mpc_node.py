"""The MPC node: input validation (no DDS) and the node in-process with a scripted state.

The node tests share one built :class:`WalkingMpc` (building takes seconds) and use a private
rclpy Context each. Without ``use_sim_time`` the node clock is the wall clock, so the scripted
states are stamped with it.
"""

from __future__ import annotations

import copy
import gc
import itertools
import logging
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path as FilePath

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from hypothesis import example, given
from hypothesis import strategies as st
from nav_msgs.msg import Odometry, Path
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.time import Time as RosTime
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from horizon_mpc.mpc.controller import WalkingMpc
from horizon_mpc.nodes import mpc_node
from horizon_mpc.nodes.conversions import (
    NS_PER_S,
    joint_state_to_msg,
    odometry_to_msg,
    seconds_from_duration,
    time_from_ns,
    time_to_ns,
)
from horizon_mpc.nodes.mpc_inputs import (
    ABSURD_ANGULAR,
    ABSURD_COMMAND,
    ABSURD_JOINT_VELOCITY,
    ABSURD_LINEAR,
    ABSURD_POSITION,
    JOINT_LIMIT_MARGIN,
    base_from_odometry,
    command_from_twist,
    joints_from_joint_state,
)
from horizon_mpc.nodes.mpc_node import MpcNode
from horizon_mpc.nodes.throttling import problem_kind
from horizon_mpc.posture import standing_configuration

assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"  # set by conftest.py

JOINTS = ["a", "b", "c"]
LIMITS = (1.0, 0.5, 1.0)
floats = st.floats(allow_nan=True, allow_infinity=True, width=64)


def twist(vx: float = 0.0, vy: float = 0.0, wz: float = 0.0) -> Twist:
    msg = Twist()
    msg.linear.x, msg.linear.y, msg.angular.z = float(vx), float(vy), float(wz)
    return msg


# ---------------------------------------------------------------------- validation, no DDS
@given(vx=floats, vy=floats, wz=floats)
def test_cmd_vel_is_finite_and_within_limits_or_rejected(vx, vy, wz):
    try:
        cmd, _ = command_from_twist(twist(vx, vy, wz), LIMITS)
    except ValueError as exc:
        assert "cmd_vel" in str(exc)
        assert not all(math.isfinite(x) and abs(x) <= ABSURD_COMMAND for x in (vx, vy, wz))
        return
    assert np.all(np.isfinite(cmd)) and np.all(np.abs(cmd) <= LIMITS)
    assert np.linalg.norm(cmd / np.array(LIMITS)) <= math.sqrt(2) * (1 + 1e-12)


def test_cmd_vel_beyond_the_limits_is_clamped_with_a_note():
    cmd, notes = command_from_twist(twist(3.0, -2.0, 0.1), LIMITS, max_norm=math.inf)
    np.testing.assert_array_equal(cmd, [1.0, -0.5, 0.1])
    assert "limited to [1.0, -0.5, 0.1]" in notes[0]
    # beyond the combined limit (two axes at their limits and a third): scaled down along
    # its direction to the normalised norm sqrt(2)
    cmd, notes = command_from_twist(twist(3.0, -2.0, 0.5), LIMITS)
    np.testing.assert_allclose(cmd, np.array([1.0, -0.5, 0.5]) * math.sqrt(2 / 2.25))
    assert "combined 1.41" in notes[0]
    cmd, notes = command_from_twist(twist(1.0, 0.5, 0.0), LIMITS)  # two at their limits
    np.testing.assert_array_equal(cmd, [1.0, 0.5, 0.0])
    assert notes == []


@given(
    order=st.permutations(JOINTS + ["extra"]),
    drop=st.sampled_from([None, *JOINTS]),
    pos=st.lists(floats, min_size=3, max_size=5),
    vel=st.lists(floats, min_size=0, max_size=5),
)
def test_joint_state_is_matched_by_name_or_rejected(order, drop, pos, vel):
    names = [n for n in order if n != drop]
    msg = JointState(name=names, position=pos, velocity=vel)
    try:
        qj, vj, _ = joints_from_joint_state(msg, JOINTS)
    except ValueError as exc:
        assert "JointState" in str(exc)
        return
    assert drop is None and len(pos) == len(names)
    for i, n in enumerate(JOINTS):
        assert qj[i] == pos[names.index(n)]
    assert np.all(np.isfinite(qj)) and np.all(np.isfinite(vj)) and vj.shape == (3,)


def test_joint_state_repairs_are_named():
    msg = JointState(name=["c", "a", "b", "x"], position=[3.0, 1.0, 2.0, 9.0],
                     velocity=[math.nan, 0.1, 0.2, 0.0])
    qj, vj, notes = joints_from_joint_state(msg, JOINTS)
    np.testing.assert_array_equal(qj, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(vj, [0.1, 0.2, 0.0])
    assert any("['x']" in n for n in notes) and any("non-finite velocities for ['c']" in n
                                                    for n in notes)


def test_joint_state_with_a_missing_joint_names_it():
    with pytest.raises(ValueError, match=r"lacks joints \['b'\]"):
        joints_from_joint_state(JointState(name=["a", "c"], position=[0.0, 0.0]), JOINTS)


def test_another_drivers_joint_state_and_a_mismatched_effort_are_named():
    """A gripper driver's JointState on the topic: 'lacks joints [all of them]' (its
    messages displace the robot's from the depth-1 queue: now said); an effort array of the
    wrong length was accepted without a word (efforts are not used)."""
    with pytest.raises(ValueError, match=r"none of the model's joints \['a', 'b', 'c'\] \(it "
                       r"names \['gripper_joint'\]\): another driver's on the same topic"):
        joints_from_joint_state(JointState(name=["gripper_joint"], position=[0.0]), JOINTS)
    # the robot's own driver with prefixed names is no second driver (a reviewer)
    with pytest.raises(ValueError, match=r"names with a prefix\? \('go2/a' ends in 'a'"):
        joints_from_joint_state(JointState(name=["go2/a", "go2/b", "go2/c"],
                                           position=[0.0] * 3), JOINTS)
    msg = JointState(name=JOINTS, position=[0.0] * 3, velocity=[0.0] * 3, effort=[math.nan])
    qj, _, notes = joints_from_joint_state(msg, JOINTS)
    assert notes == ["JointState.effort has 1 values for 3 names (efforts are not used)"]


def test_joint_readings_far_outside_the_limits_or_absurdly_fast_are_refused_by_name():
    # a calf at 10 rad (limits about [-2.7, -0.8]) was planned from and published as point 0
    limits = (np.array([-1.0, -1.0, -2.7]), np.array([1.0, 1.0, -0.8]))
    ok = JointState(name=JOINTS, position=[1.4, 0.0, -1.5], velocity=[0.0, 0.0, 0.0])
    qj, _, _ = joints_from_joint_state(ok, JOINTS, limits)  # 0.4 past a limit: a reading
    assert qj[0] == 1.4
    far = JointState(name=JOINTS, position=[0.0, 0.0, 10.0])
    with pytest.raises(ValueError, match=r"outside the joint limits: c=10"):
        joints_from_joint_state(far, JOINTS, limits)
    fast = JointState(name=JOINTS, position=[0.0, 0.0, -1.5], velocity=[0.0, 5e3, 0.0])
    with pytest.raises(ValueError, match=r"velocities beyond 1000: b=5000"):
        joints_from_joint_state(fast, JOINTS, limits)


near_limits = st.one_of(floats, st.sampled_from([-1.5, 1.5, -1.5000001, 1.5000001, 1e3,
                                                  -1e3, 1000.0000001]))


@given(pos=st.lists(near_limits, min_size=3, max_size=3),
       vel=st.lists(near_limits, min_size=3, max_size=3))
@example(pos=[0.0, 0.0, math.inf], vel=[0.0] * 3)  # a reviewer's: an unlimited joint at inf
@example(pos=[0.0, 0.0, -math.inf], vel=[0.0] * 3)  # was accepted by the fast path
def test_joint_readings_are_accepted_exactly_by_the_documented_rule(pos, vel):
    """The checks run first on the whole arrays (a fast path, session 31) and name the
    problem only when those fail: accepted iff every position is finite and within
    JOINT_LIMIT_MARGIN of its limits and every finite velocity within
    ABSURD_JOINT_VELOCITY; non-finite velocities are zeroed with a note."""
    limits = (np.full(3, -1.0), np.array([1.0, 1.0, math.inf]))
    msg = JointState(name=JOINTS, position=pos, velocity=vel)
    pos_ok = all(math.isfinite(x) and lo - JOINT_LIMIT_MARGIN <= x <= hi + JOINT_LIMIT_MARGIN
                 for x, lo, hi in zip(pos, *limits, strict=True))
    vel_ok = all(not math.isfinite(x) or abs(x) <= ABSURD_JOINT_VELOCITY for x in vel)
    try:
        qj, vj, notes = joints_from_joint_state(msg, JOINTS, limits)
    except ValueError as exc:
        assert not (pos_ok and vel_ok)
        assert ("non-finite positions" in str(exc) or "outside the joint limits" in str(exc)
                if not pos_ok else "velocities beyond 1000" in str(exc))
        return
    assert pos_ok and vel_ok
    assert qj.tolist() == pos
    assert vj.tolist() == [x if math.isfinite(x) else 0.0 for x in vel]
    assert any("non-finite velocities" in n for n in notes) == (
        not all(map(math.isfinite, vel)))


@given(values=st.lists(st.one_of(floats, st.sampled_from([1e5, -1e5, 100.0, -100.0,
                                                           100.00000001, 1e-7])),
                       min_size=13, max_size=13))
def test_odometry_is_accepted_exactly_by_the_documented_rule(values):
    """As the joints: accepted iff finite, position within ABSURD_POSITION (m), twist within
    ABSURD_LINEAR / ABSURD_ANGULAR, and a quaternion not (near) zero."""
    msg = Odometry()
    p, o, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    (p.x, p.y, p.z, o.x, o.y, o.z, o.w, tw.linear.x, tw.linear.y, tw.linear.z,
     tw.angular.x, tw.angular.y, tw.angular.z) = values
    position, quat, linear, angular = values[:3], values[3:7], values[7:10], values[10:]
    ok = (all(map(math.isfinite, values)) and max(map(abs, position)) <= ABSURD_POSITION
          and max(map(abs, linear)) <= ABSURD_LINEAR
          and max(map(abs, angular)) <= ABSURD_ANGULAR and max(map(abs, quat)) >= 1e-6)
    try:
        pos, unit, lin, ang, _ = base_from_odometry(msg)
    except ValueError as exc:
        assert not ok, exc
        return
    assert ok
    assert (pos.tolist(), lin.tolist(), ang.tolist()) == (position, linear, angular)
    np.testing.assert_allclose(unit * np.linalg.norm(quat), quat, atol=1e-12 * max(
        map(abs, quat)), rtol=1e-12)


def test_odometry_of_absurd_magnitude_is_refused_and_an_upside_down_base_noted():
    msg = odometry_to_msg(time_from_ns(0), [0, 0, 1e9], [0, 0, 0, 1], [0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="position .* beyond the plausible"):
        base_from_odometry(msg)
    flipped = odometry_to_msg(time_from_ns(0), [0, 0, 0.3], [1, 0, 0, 0], [0, 0, 0], [0, 0, 0])
    _, _, _, _, notes = base_from_odometry(flipped)
    assert any("upside down" in n for n in notes)


@given(pose=st.lists(floats, min_size=7, max_size=7), twist6=st.lists(floats, min_size=6,
                                                                        max_size=6))
def test_odometry_gives_a_unit_quaternion_or_is_rejected(pose, twist6):
    msg = Odometry()
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z, o.x, o.y, o.z, o.w = pose
    t = msg.twist.twist
    t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z = twist6
    try:
        pos, quat, lin, ang, _ = base_from_odometry(msg)
    except ValueError as exc:
        assert "Odometry" in str(exc)
        return
    assert all(np.all(np.isfinite(x)) for x in (pos, quat, lin, ang))
    assert abs(np.linalg.norm(quat) - 1.0) < 1e-9


def test_odometry_non_unit_quaternion_is_normalised_with_a_note_and_zero_rejected():
    msg = odometry_to_msg(time_from_ns(0), [0, 0, 0.3], [0, 0, 0, 2.0], [0, 0, 0], [0, 0, 0])
    _, quat, _, _, notes = base_from_odometry(msg)
    np.testing.assert_allclose(quat, [0, 0, 0, 1])
    assert "norm 2" in notes[0]
    msg.pose.pose.orientation.w = 0.0
    with pytest.raises(ValueError, match="zero quaternion"):
        base_from_odometry(msg)


# ---------------------------------------------------------------------- the node in-process
@pytest.fixture(scope="module")
def walking_mpc():
    return WalkingMpc("go2", iterations=1)


@pytest.fixture
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    yield ctx
    rclpy.try_shutdown(context=ctx)


class Harness:
    """An MpcNode plus a probe node that plays the robot (states) and the operator (cmd_vel)."""

    def __init__(self, context: rclpy.Context, mpc: WalkingMpc, **params: object) -> None:
        mpc.t_last = None  # a fresh bootstrap for every test
        overrides = [Parameter(k, value=v) for k, v in {"trigger": "state", **params}.items()]
        self.node = MpcNode(parameter_overrides=overrides, mpc=mpc, context=context)
        self.probe = Node("probe", context=context)
        self.trajectories: list[JointTrajectory] = []
        self.paths: list[Path] = []
        self.probe.create_subscription(JointTrajectory, "joint_trajectory",
                                       self.trajectories.append, 10)
        self.probe.create_subscription(Path, "/mpc/predicted_base_path", self.paths.append, 10)
        self.pub_js = self.probe.create_publisher(JointState, "joint_states", 10)
        self.pub_odom = self.probe.create_publisher(Odometry, "odom", 10)
        self.pub_cmd = self.probe.create_publisher(Twist, "cmd_vel", 10)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        _, self.q = standing_configuration(mpc.cfg)
        self.spin_until(lambda: self.pub_js.get_subscription_count() > 0
                        and self.pub_odom.get_subscription_count() > 0
                        and self.pub_cmd.get_subscription_count() > 0
                        and self.node._pub_traj.get_subscription_count() > 0)

    def spin_until(self, done: Callable[[], bool], timeout: float = 20.0) -> None:
        end = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < end, "timed out waiting in the executor"
            self.executor.spin_once(timeout_sec=0.01)

    def spin_for(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def publish_state(self, age: float = 0.0, stamp_ns: int | None = None) -> int:
        """The standing state, stamped ``age`` s before now (or at ``stamp_ns``); returns the
        stamp (ns)."""
        if stamp_ns is None:
            stamp_ns = self.probe.get_clock().now().nanoseconds - round(age * 1e9)
        stamp = time_from_ns(stamp_ns)
        q = self.q
        self.pub_js.publish(joint_state_to_msg(stamp, self.node.joint_names, q[7:],
                                               np.zeros(len(q) - 7)))
        self.pub_odom.publish(odometry_to_msg(stamp, q[:3], q[3:7], np.zeros(3), np.zeros(3)))
        return stamp_ns

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()


@pytest.fixture
def harness(context, walking_mpc):
    made: list[Harness] = []

    def make(**params: object) -> Harness:
        made.append(Harness(context, walking_mpc, **params))
        return made[-1]

    yield make
    for h in made:
        h.close()


def test_a_state_is_answered_by_a_well_formed_trajectory(harness):
    h = harness()
    stamp_ns = h.publish_state()
    h.spin_until(lambda: h.trajectories and h.paths)
    msg, plan = h.trajectories[-1], h.node.plan
    assert time_to_ns(msg.header.stamp) == stamp_ns  # the stamp of the state planned from
    assert list(msg.joint_names) == h.node.mpc.model.joint_names  # model order
    assert len(msg.points) == 6  # publish_points default
    for k, pt in enumerate(msg.points):
        assert seconds_from_duration(pt.time_from_start) == pytest.approx(k * plan.dt)
        np.testing.assert_array_equal(pt.positions, plan.q[7:, k])
        np.testing.assert_array_equal(pt.velocities, plan.v[6:, k])
        np.testing.assert_array_equal(pt.accelerations, plan.a[6:, k])
        np.testing.assert_array_equal(pt.effort, plan.tau[6:, k])
    assert len(h.paths[-1].poses) == plan.q.shape[1]
    assert h.paths[-1].header.frame_id == "odom"


def test_the_predicted_path_is_in_the_frame_of_the_odometry_pose(harness):
    # it was stamped 'odom' whatever frame the state came in
    h = harness()
    stamp = time_from_ns(h.probe.get_clock().now().nanoseconds)
    q = h.q
    h.pub_js.publish(joint_state_to_msg(stamp, h.node.joint_names, q[7:], np.zeros(len(q) - 7)))
    h.pub_odom.publish(odometry_to_msg(stamp, q[:3], q[3:7], np.zeros(3), np.zeros(3),
                                       frame_id="map"))
    h.spin_until(lambda: h.paths)
    assert h.paths[-1].header.frame_id == "map"
    assert {p.header.frame_id for p in h.paths[-1].poses} == {"map"}


def test_efforts_are_the_inverse_dynamics_of_the_plan(harness):
    h = harness()
    h.publish_state()
    h.spin_until(lambda: h.trajectories)
    plan, mpc = h.node.plan, h.node.mpc
    rnea = mpc.model.inverse_dynamics(mpc.wp.feet)
    for k, pt in enumerate(h.trajectories[-1].points):
        tau = np.asarray(rnea(plan.q[:, k], plan.v[:, k], plan.a[:, k], plan.f[:, k])).ravel()
        np.testing.assert_allclose(pt.effort, tau[6:], atol=1e-8)
    # standing: the joints carry the robot's weight (not zero torques)
    assert np.max(np.abs(h.trajectories[-1].points[0].effort)) > 1.0


class Sent:
    """Stands in for a publisher: keeps copies of what was published (the node refills its
    path and diagnostics messages in place)."""

    def __init__(self) -> None:
        self.msgs: list = []

    def publish(self, msg: object) -> None:
        self.msgs.append(copy.deepcopy(msg))


def drive_in_sim_time(node: MpcNode, n_ticks: int, period_ns: int = 20_000_000,
                      start_ns: int = 10 * NS_PER_S) -> dict:
    """Feed ``n_ticks`` standing states ``period_ns`` apart straight into the node's callbacks
    on a sim clock that follows the stamps; returns what it published, by output."""
    sent = {"traj": Sent(), "path": Sent(), "diag": Sent()}
    node._pub_traj, node._pub_path, node._pub_diag = sent["traj"], sent["path"], sent["diag"]
    _, q = standing_configuration(node.mpc.cfg)
    zeros = np.zeros(3)
    for k in range(n_ticks):
        ns = start_ns + k * period_ns
        node.get_clock().set_ros_time_override(RosTime(nanoseconds=ns))
        stamp = time_from_ns(ns)
        node._on_joint_state(joint_state_to_msg(stamp, node.joint_names, q[7:],
                                                np.zeros(len(q) - 7)))
        node._on_odom(odometry_to_msg(stamp, q[:3], q[3:7], zeros, zeros))
    return {k: s.msgs for k, s in sent.items()}


def sim_time_node(context: rclpy.Context, mpc: WalkingMpc, **params: object) -> MpcNode:
    mpc.t_last = None
    overrides = {"trigger": "state", "use_sim_time": True, **params}
    return MpcNode(parameter_overrides=[Parameter(k, value=v) for k, v in overrides.items()],
                   mpc=mpc, context=context)


def test_the_path_and_diagnostics_go_out_at_their_rates(context, walking_mpc):
    node = sim_time_node(context, walking_mpc, path_rate=10.0, diagnostics_rate=5.0)
    out = drive_in_sim_time(node, 21)  # 0.4 s of 50 Hz ticks
    assert len(out["traj"]) == 21  # the trajectory: every tick
    path_times = [time_to_ns(m.header.stamp) / NS_PER_S - 10.0 for m in out["path"]]
    np.testing.assert_allclose(path_times, [0.0, 0.1, 0.2, 0.3, 0.4], atol=1e-9)
    # the last path is the last plan's base poses, every node stamped at its time
    path, plan = out["path"][-1], node.plan
    assert len(path.poses) == plan.q.shape[1]
    for k, ps in enumerate(path.poses):
        p, o = ps.pose.position, ps.pose.orientation
        np.testing.assert_array_equal([p.x, p.y, p.z, o.x, o.y, o.z, o.w], plan.q[:7, k])
        assert time_to_ns(ps.header.stamp) == time_to_ns(path.header.stamp) + k * 20_000_000
    # diagnostics: at 5 Hz, or at once when the level rises above the last one sent
    sent = [(time_to_ns(m.header.stamp), m.status[0].level) for m in out["diag"]]
    assert 3 <= len(sent) < 21
    for (t0, level0), (t1, level1) in itertools.pairwise(sent):
        assert t1 - t0 >= 0.18 * NS_PER_S or level1 > level0
    node.destroy_node()


def test_a_sim_clock_that_restarts_does_not_silence_the_path(context, walking_mpc):
    node = sim_time_node(context, walking_mpc, path_rate=1.0)
    first = drive_in_sim_time(node, 3, period_ns=100_000_000, start_ns=20 * NS_PER_S)
    again = drive_in_sim_time(node, 1, start_ns=10 * NS_PER_S)  # the clock went back 10 s
    assert len(first["path"]) == 1 and len(again["path"]) == 1
    node.destroy_node()



def test_a_simulator_reset_is_not_blamed_on_clocks_that_differ(context, walking_mpc):
    """After a simulator restart the new clock's joint state paired with the old clock's
    odometry: 'odom is stamped 15.454 s ahead of the node's clock ... use_sim_time?'. The
    states from before the clock went back are dropped; the new pair restarts the MPC."""
    node = sim_time_node(context, walking_mpc, trigger="timer")
    said: list[tuple[str, str]] = []
    node._warn = lambda kind, text: said.append((kind, text))
    try:
        node._pub_traj, node._pub_path, node._pub_diag = Sent(), Sent(), Sent()
        _, q = standing_configuration(node.mpc.cfg)
        zeros = np.zeros(3)
        _feed_state(node, 15 * NS_PER_S, q)
        assert node.tick()
        _feed_state(node, 15 * NS_PER_S + 16_000_000, q)  # the old simulator's last state
        new = 20_000_000  # the restarted simulator's first joint state, its odom not yet
        node.get_clock().set_ros_time_override(RosTime(nanoseconds=new))
        node._on_joint_state(joint_state_to_msg(time_from_ns(new), node.joint_names, q[7:],
                                                np.zeros(len(q) - 7)))
        assert not node.tick()
        assert [k for k, _ in said] == ["clock_back"] and "went back 14.980 s" in said[0][1], said
        assert node._base is None and node._joints[0] == new
        assert not node.tick() and said[-1] == ("no_state", "no odom since the clock went back; "
                                                "not planning")
        node._on_odom(odometry_to_msg(time_from_ns(new), q[:3], q[3:7], zeros, zeros))
        assert node.tick() and node._last_tick_stamp == new
        assert node.stale_skips == 1  # counted, WARN diagnostics
        # states ahead of a clock that did not go back: a clock mismatch, as before
        ahead = new + NS_PER_S
        node._on_joint_state(joint_state_to_msg(time_from_ns(ahead), node.joint_names,
                                                q[7:], np.zeros(len(q) - 7)))
        node._on_odom(odometry_to_msg(time_from_ns(ahead), q[:3], q[3:7], zeros, zeros))
        assert not node.tick()
        assert said[-1][0] == "future" and "use_sim_time" in said[-1][1]
        # both streams ahead: both named (a tie named odom only, other stamps the later one)
        assert said[-1][1].startswith("joint_states and odom are stamped 1.000 s ahead")
        node._joints_recent.clear()  # (else the pair of equal stamps above is taken again)
        node._base_recent.clear()
        node._on_joint_state(joint_state_to_msg(time_from_ns(ahead + 200_000_000),
                                                node.joint_names, q[7:], np.zeros(len(q) - 7)))
        node._on_odom(odometry_to_msg(time_from_ns(ahead + 100_000_000), q[:3], q[3:7], zeros,
                                      zeros))
        assert not node.tick()
        assert said[-1][1].startswith("joint_states and odom are stamped 1.200 s ahead")
    finally:
        node.destroy_node()

def test_by_default_diagnostics_go_out_at_10_hz_and_count_the_ticks_between(
        context, walking_mpc):
    node = sim_time_node(context, walking_mpc)
    assert node.get_parameter("diagnostics_rate").value == 10.0
    out = drive_in_sim_time(node, 21)  # 0.4 s of 50 Hz ticks
    assert len(out["traj"]) == 21
    sent = [(time_to_ns(m.header.stamp), m.status[0].level,
             {kv.key: kv.value for kv in m.status[0].values}) for m in out["diag"]]
    # 10 Hz, or at once when the level rises
    assert 3 <= len(sent) <= 7
    for (t0, level0, _), (t1, level1, _) in itertools.pairwise(sent):
        assert t1 - t0 >= 0.09 * NS_PER_S or level1 > level0
    for stamp, _, values in sent:  # every tick counted, also those without a status
        assert int(values["ticks"]) == (stamp - 10 * NS_PER_S) // 20_000_000 + 1
        assert float(values["solve_time_max_ms"]) >= float(values["solve_time_ms"]) > 0.0
    node.destroy_node()


def test_diagnostics_warn_on_solver_failures_not_on_real_time_iterations(context, walking_mpc):
    """One iteration per tick rarely meets the solver's own tolerance (its stats say no
    success): still OK; a failure, whose plan is the standing fallback, is WARN."""
    node = sim_time_node(context, walking_mpc, diagnostics_rate=0.0)
    out = drive_in_sim_time(node, 6)
    statuses = [m.status[0] for m in out["diag"]]
    assert len(statuses) == 6 and all(s.level == DiagnosticStatus.OK for s in statuses)
    values = {kv.key: kv.value for kv in statuses[-1].values}
    assert values["solver_status"] == str(node.plan.stats.get("status"))
    node.mpc.failures = 1  # as WalkingMpc._healthy leaves it after a failed tick
    node._publish_diagnostics(node.plan, 11 * NS_PER_S)
    status = node._pub_diag.msgs[-1].status[0]
    assert status.level == DiagnosticStatus.WARN and "solver failure" in status.message
    node.mpc.failures = 0
    # a plan far from feasible (a collapsing gait: violation 100-140; walking: < 4) for
    # 0.1 s is WARN; one tick of it (a walking go2 at 100 Hz: up to 140) is not
    plan = copy.copy(node.plan)
    plan.stats = {**plan.stats, "constraint_violation": 120.0}
    for k, ms in enumerate((0, 20, 40, 60, 80, 100)):
        node._publish_diagnostics(plan, 12 * NS_PER_S + ms * 1_000_000)
        status = node._pub_diag.msgs[-1].status[0]
        assert (status.level == DiagnosticStatus.WARN) is (k == 5), ms
    assert "far from feasible" in status.message and "for 100 ms" in status.message
    node._publish_diagnostics(node.plan, 12 * NS_PER_S + 120_000_000)  # over: OK again
    assert node._pub_diag.msgs[-1].status[0].level == DiagnosticStatus.OK
    node._publish_diagnostics(plan, 12 * NS_PER_S + 140_000_000)  # a new streak, one tick
    assert node._pub_diag.msgs[-1].status[0].level == DiagnosticStatus.OK
    node.destroy_node()


def test_diagnostics_say_error_when_the_measured_base_is_a_fallen_robots(context,
                                                                          walking_mpc):
    """The status said OK while the robot lay on the ground in some falls (the violation of
    its plans stayed small): a base below 0.6 of its nominal height or tilted more than 0.5
    rad (the closed loop's fall test) is ERROR, with a warning."""
    node = sim_time_node(context, walking_mpc, diagnostics_rate=0.0)
    warned: list[str] = []
    node._warn = lambda kind, text: warned.append(text)
    try:
        drive_in_sim_time(node, 3)
        assert node._pub_diag.msgs[-1].status[0].level == DiagnosticStatus.OK
        ground = float(np.mean(node.mpc.ground_z))
        nominal = float(node.mpc.wp.height_ref.values[0, 0]) - ground
        standing = node.measured_base.copy()
        for base, what in ((ground + 0.5 * nominal, "above the ground"),
                           (ground + nominal, "tilted 0.60 rad")):
            node.measured_base = standing.copy()
            node.measured_base[2] = base
            if what.startswith("tilted"):  # rolled 0.6 rad
                node.measured_base[3:7] = [np.sin(0.3), 0.0, 0.0, np.cos(0.3)]
            node._publish_diagnostics(node.plan, 11 * NS_PER_S)
            status = node._pub_diag.msgs[-1].status[0]
            assert status.level == DiagnosticStatus.ERROR, what
            assert status.message.startswith("the robot seems to have fallen") and \
                what in status.message
            assert warned[-1] == status.message
        # nominal above the ground, as the closed loop's fall test (a sphere foot's frame
        # sits its radius up: the node said 0.312 m for go2, the closed loop 0.336)
        _, q = standing_configuration(node.mpc.cfg)  # feet frames at z = 0
        grounded = q[2] + node.mpc.cfg.foot_radius
        assert f"(nominal {grounded:.3f} m)" in status.message
        assert grounded == pytest.approx(0.336, abs=1e-3)
        node.measured_base = standing
        node._publish_diagnostics(node.plan, 12 * NS_PER_S)  # standing again
        assert node._pub_diag.msgs[-1].status[0].level == DiagnosticStatus.OK
    finally:
        node.destroy_node()


def test_a_fall_is_said_at_the_first_tick_of_its_state(context, walking_mpc):
    """The check read the plan's node 0, which a prepared tick closes on the measured state
    over ticks: a 1 rad roll was OK for 21 ticks, a base upside down for 8 (an auditor)."""
    node = sim_time_node(context, walking_mpc, diagnostics_rate=0.0)
    try:
        drive_in_sim_time(node, 5)
        _, q = standing_configuration(node.mpc.cfg)
        ns = 10 * NS_PER_S + 5 * 20_000_000
        node.get_clock().set_ros_time_override(RosTime(nanoseconds=ns))
        stamp = time_from_ns(ns)
        node._on_joint_state(joint_state_to_msg(stamp, node.joint_names, q[7:],
                                                np.zeros(len(q) - 7)))
        node._on_odom(odometry_to_msg(stamp, q[:3], [np.sin(0.5), 0.0, 0.0, np.cos(0.5)],
                                      np.zeros(3), np.zeros(3)))
        assert node.ticks == 6
        status = node._pub_diag.msgs[-1].status[0]
        assert status.level == DiagnosticStatus.ERROR and "tilted 1.00 rad" in status.message
    finally:
        node.destroy_node()


def test_diagnostics_rate_0_sends_a_status_every_tick(context, walking_mpc):
    node = sim_time_node(context, walking_mpc, diagnostics_rate=0.0)
    out = drive_in_sim_time(node, 4)
    assert len(out["diag"]) == len(out["traj"]) == 4
    values = {kv.key: kv.value for kv in out["diag"][-1].status[0].values}
    assert int(values["ticks"]) == 4 and float(values["solve_time_max_ms"]) > 0.0
    assert int(values["solver_errors"]) == 0
    # an exception in a tick is counted where a user can see it (it was an attribute only)
    update = node.mpc.update
    node.mpc.update = lambda *a, **k: (_ for _ in ()).throw(RuntimeError("boom"))
    try:
        out = drive_in_sim_time(node, 1, start_ns=11 * NS_PER_S)
    finally:
        node.mpc.update = update
    assert node.solver_errors == 1
    node._publish_diagnostics(node.plan, 12 * NS_PER_S)
    values = {kv.key: kv.value for kv in node._pub_diag.msgs[-1].status[0].values}
    assert int(values["solver_errors"]) == 1
    node.destroy_node()


def test_the_tick_pairs_joints_and_base_of_one_stamp(context, walking_mpc):
    """Timer trigger: joint_states of a newer step than the last odom are not mixed with
    it; the plan starts from the newest (joints, base) pair with one stamp, and from the
    newest of each when no stamps match (unsynchronised drivers)."""
    node = sim_time_node(context, walking_mpc, trigger="timer")
    sent = Sent()
    node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), Sent()
    _, q = standing_configuration(node.mpc.cfg)
    zeros, nj = np.zeros(3), len(q) - 7
    t1, t2, t3 = 10 * NS_PER_S, 10 * NS_PER_S + 4_000_000, 10 * NS_PER_S + 9_000_000
    bent = q[7:] + 0.05
    node.get_clock().set_ros_time_override(RosTime(nanoseconds=t2))
    node._on_joint_state(joint_state_to_msg(time_from_ns(t1), node.joint_names, q[7:],
                                            np.zeros(nj)))
    node._on_odom(odometry_to_msg(time_from_ns(t1), q[:3], q[3:7], zeros, zeros))
    node._on_joint_state(joint_state_to_msg(time_from_ns(t2), node.joint_names, bent,
                                            np.zeros(nj)))
    assert node.tick()
    assert time_to_ns(sent.msgs[-1].header.stamp) == t1
    np.testing.assert_allclose(node.plan.q[7:, 0], q[7:], atol=1e-9)
    # no common stamp: the newest of each, stamped with the older one
    node.get_clock().set_ros_time_override(RosTime(nanoseconds=t3 + 20_000_000))
    node._on_odom(odometry_to_msg(time_from_ns(t3), q[:3], q[3:7], zeros, zeros))
    node._joints_recent.clear()
    node._on_joint_state(joint_state_to_msg(time_from_ns(t3 + 1_000_000), node.joint_names,
                                            bent, np.zeros(nj)))
    node._base_recent.clear()
    node._on_odom(odometry_to_msg(time_from_ns(t3), q[:3], q[3:7], zeros, zeros))
    assert node.tick()
    assert time_to_ns(sent.msgs[-1].header.stamp) == t3
    np.testing.assert_allclose(node.plan.q[7:, 0], bent, atol=1e-9)


def test_the_solve_budget_applies_to_timer_ticks_only(context, walking_mpc):
    node = sim_time_node(context, walking_mpc, trigger="timer", solve_budget=0.5)
    assert node.mpc.time_budget == pytest.approx(0.5 * node.period)
    node.destroy_node()
    node = sim_time_node(context, walking_mpc, trigger="state", solve_budget=0.5)
    assert node.mpc.time_budget is None  # lockstep stays deterministic
    node.destroy_node()
    node = sim_time_node(context, walking_mpc, trigger="timer", solve_budget=0.0)
    assert node.mpc.time_budget is None


def test_a_stale_state_is_not_planned_from(harness):
    h = harness(state_timeout=0.2)
    h.publish_state(age=1.0)
    h.spin_until(lambda: h.node.stale_skips > 0)
    h.spin_for(0.2)
    assert h.trajectories == [] and h.node.plan is None



def test_states_stamped_0_are_named_as_unset_stamps(harness, monkeypatch):
    """A driver leaving header.stamp at 0 got 'the state is 1795703617.896 s old'. On wall
    time that is also a simulator's first state (session 32: it blamed the stamp only)."""
    h = harness(state_timeout=0.2)
    said: list[str] = []
    monkeypatch.setattr(h.node, "_warn", lambda kind, text: said.append(text))
    h.publish_state(stamp_ns=0)
    h.spin_until(lambda: h.node.stale_skips > 0)
    assert h.trajectories == []
    # on wall time, a stamp 0 is also a simulator's first state (sim time starts at 0)
    assert "joint_states and odom stamped 0: header.stamp unset, or a simulator's first " \
        "state read on another clock?" in said[-1] and "use_sim_time" in said[-1]
    assert mpc_node._unset_hint(5, 7) == ""  # sim time starts at 0: only the stale say so
    # on a sim clock some seconds on (use_sim_time true), stamp 0 is the driver's
    hint = mpc_node._unset_hint(0, 7, age=50.0)
    assert "joint_states stamped 0: header.stamp unset?" in hint and "simulator" not in hint


def test_states_on_another_clock_are_named_as_such(harness, monkeypatch):
    """sim_node's states (sim time, seconds since the start) read by a node left on wall
    time: 'the state is 1795748809.324 s old', and nothing about the clocks (an auditor's)."""
    h = harness(state_timeout=0.2)
    said: list[str] = []
    monkeypatch.setattr(h.node, "_warn", lambda kind, text: said.append(text))
    h.publish_state(stamp_ns=12_000_000_000)  # 12 s of sim time
    h.spin_until(lambda: h.node.stale_skips > 0)
    assert h.trajectories == []
    assert "do the publisher and this node use the same clock (use_sim_time)?" in said[-1]
    assert mpc_node._unset_hint(5, 7, age=2.0) == ""  # late, not on another clock

def test_states_that_stop_arriving_are_reported_stale(harness):
    """Timer trigger: when the states stop, the node publishes nothing new and, once the
    last state is older than state_timeout, counts stale skips and sends a WARN status (it
    went silent, its last status OK, before)."""
    h = harness(trigger="timer", control_rate=50.0, state_timeout=0.1, diagnostics_rate=0.0)
    statuses: list = []
    h.probe.create_subscription(DiagnosticArray, "/diagnostics",
                                lambda m: statuses.append(m.status[0]), 10)
    h.publish_state()
    h.spin_until(lambda: h.trajectories)
    n = len(h.trajectories)
    h.spin_until(lambda: h.node.stale_skips > 0 and statuses
                 and statuses[-1].level == DiagnosticStatus.WARN, timeout=5.0)
    assert len(h.trajectories) == n  # nothing new planned
    assert "stale state" in statuses[-1].message and h.node.last_state_age > 0.1
    h.publish_state()  # states again: planning again
    h.spin_until(lambda: len(h.trajectories) > n)


def test_a_state_stamped_in_the_future_is_not_planned_from(harness):
    """A state stamped 10 s ahead (a sim clock against a wall clock) has a negative age,
    which a one-sided check never catches."""
    h = harness(state_timeout=0.2)
    h.publish_state(age=-10.0)
    h.spin_until(lambda: h.node.stale_skips > 0)
    h.spin_for(0.2)
    assert h.trajectories == [] and h.node.plan is None
    assert h.node.last_state_age == pytest.approx(-10.0, abs=0.5)
    h.publish_state(age=-0.05)  # within state_timeout: planned from
    h.spin_until(lambda: h.node.plan is not None)


def test_one_stream_stamped_in_the_future_is_not_planned_from(harness):
    """joint_states 1 s ahead of the clock with a correct odom: the plan's stamp is the
    older stream's, and the newer one was never compared with the clock (planned from, no
    warning)."""
    h = harness(trigger="timer", control_rate=50.0, state_timeout=0.2)
    for _ in range(5):
        now = h.probe.get_clock().now().nanoseconds
        q = h.q
        h.pub_js.publish(joint_state_to_msg(time_from_ns(now + NS_PER_S), h.node.joint_names,
                                            q[7:], np.zeros(len(q) - 7)))
        h.pub_odom.publish(odometry_to_msg(time_from_ns(now), q[:3], q[3:7], np.zeros(3),
                                           np.zeros(3)))
        h.spin_for(0.05)
    h.spin_until(lambda: h.node.stale_skips > 0)
    assert h.trajectories == [] and h.node.plan is None
    assert "future" in h.node._last_warn
    assert h.node.last_state_age == pytest.approx(-1.0, abs=0.3)


def test_no_state_means_no_trajectory(harness):
    h = harness(trigger="timer", control_rate=50.0)
    h.spin_for(0.3)
    assert h.trajectories == [] and h.node.ticks == 0


def test_rejected_commands_keep_the_last_valid_one_until_its_timeout_and_say_so(harness,
                                                                                 monkeypatch):
    """A NaN cmd_vel stream after a valid command: the valid one stands until cmd_timeout
    after it came, then zero; the warnings said 'keeping the previous command' and then
    'no cmd_vel' while cmd_vel kept arriving."""
    h = harness(cmd_timeout=0.2)
    said: dict[str, str] = {}
    monkeypatch.setattr(h.node, "_warn", lambda kind, text: said.setdefault(kind, text))
    h.pub_cmd.publish(twist(0.3, 0.0, 0.0))
    h.spin_until(lambda: h.node._cmd is not None)
    for _ in range(3):
        h.pub_cmd.publish(twist(float("nan"), 0.0, 0.0))
    h.spin_until(lambda: h.node.rejected["cmd_vel"] == 3)
    np.testing.assert_array_equal(h.node.current_command(), [0.3, 0.0, 0.0])
    rejected = [text for kind, text in said.items() if kind.startswith("cmd_vel:")]
    assert len(rejected) == 1  # one problem (throttled per problem)
    assert "the last valid one stands until cmd_timeout (0.2 s)" in rejected[0]
    time.sleep(0.3)
    np.testing.assert_array_equal(h.node.current_command(), [0.0, 0.0, 0.0])
    assert said["cmd_timeout"] == ("no valid cmd_vel for more than 0.2 s (3 rejected "
                                   "since); commanding zero velocity")


def test_a_stale_command_becomes_zero(harness):
    h = harness(cmd_timeout=0.2)
    h.pub_cmd.publish(twist(0.3, 0.0, 0.2))
    h.spin_until(lambda: h.node._cmd is not None)
    np.testing.assert_array_equal(h.node.current_command(), [0.3, 0.0, 0.2])
    time.sleep(0.3)
    np.testing.assert_array_equal(h.node.current_command(), [0.0, 0.0, 0.0])


def test_bad_inputs_are_counted_and_do_not_kill_the_node(harness):
    h = harness()
    h.pub_cmd.publish(twist(math.nan, 0.0, 0.0))
    h.pub_js.publish(JointState(name=["nope"], position=[0.0]))
    bad = Odometry()  # zero quaternion
    bad.pose.pose.orientation.w = 0.0
    h.pub_odom.publish(bad)
    h.spin_until(lambda: all(h.node.rejected.values()))
    h.publish_state()
    h.spin_until(lambda: h.trajectories)


def test_gait_and_weights_change_live_and_bad_values_are_refused(harness):
    h = harness()
    max_vx = h.node.mpc.settings.max_velocity[0]
    res = h.node.set_parameters([Parameter("gait", value="walk"),
                                 Parameter("w_posture", value=2.0),
                                 Parameter("max_vx", value=0.4)])
    assert all(r.successful for r in res)
    st_ = h.node.mpc.settings
    assert st_.gait.name == h.node.mpc.scheduler.gait.name == "walk"
    assert st_.weights.posture == 2.0 and st_.max_velocity[0] == 0.4
    assert not h.node.set_parameters([Parameter("gait", value="moonwalk")])[0].successful
    assert not h.node.set_parameters([Parameter("robot", value="solo12")])[0].successful
    # 1e30 made the cost 1e32 and go2 sink to the ground: implausible weights are refused
    huge = h.node.set_parameters([Parameter("w_posture", value=1e30)])[0]
    assert not huge.successful and "[0, 1e+09]" in huge.reason
    assert h.node.mpc.settings.weights.posture == 2.0
    h.node.set_parameters([Parameter("gait", value="trot"), Parameter("w_posture", value=1.0),
                           Parameter("max_vx", value=max_vx)])


def test_diagnostics_name_the_gait_walked_and_the_one_pending(context, walking_mpc):
    """A gait set while walking is taken once the swings in progress end: diagnostics said
    the new one at once, beside the old one's gait_phase (an auditor's burst of gait sets
    alternated walk/trot there while the robot trotted on)."""
    node = sim_time_node(context, walking_mpc, diagnostics_rate=0.0)
    try:
        drive_in_sim_time(node, 3)
        sch = node.mpc.scheduler
        sch.command(node.mpc.t_last, True)  # walking (as a command would start it)
        assert sch.walking and sch.gait.name == "trot"
        assert node.set_parameters([Parameter("gait", value="walk")])[0].successful
        assert sch.gait.name == "trot" and sch.pending.name == "walk"
        node._publish_diagnostics(node.plan, 11 * NS_PER_S)
        values = {kv.key: kv.value for kv in node._pub_diag.msgs[-1].status[0].values}
        assert (values["gait"], values["gait_pending"]) == ("trot", "walk")
        assert values["gait_phase"] != "nan"
    finally:
        node.set_parameters([Parameter("gait", value="trot")])
        node.mpc.scheduler.reset(0.0)  # standing, the trot taken (a module-wide controller)
        node.destroy_node()


def test_use_sim_time_is_refused_live_and_its_value_kept(harness):
    """A live use_sim_time change was accepted: every state was then stale (or stamped ahead
    of the clock) until it was set back (sim_node refuses one). Setting the value it has is
    no change and succeeds."""
    h = harness()
    was = h.node.get_parameter("use_sim_time").value
    res = h.node.set_parameters([Parameter("use_sim_time", value=not was)])[0]
    assert not res.successful and "restart the node" in res.reason
    assert h.node.get_parameter("use_sim_time").value == was
    assert h.node.get_clock().ros_time_is_active == was
    assert h.node.set_parameters([Parameter("use_sim_time", value=was)])[0].successful


def test_a_state_older_than_the_last_one_planned_from_is_refused(harness):
    h = harness()
    used = h.publish_state()
    h.spin_until(lambda: h.trajectories)
    n, skips = len(h.trajectories), h.node.stale_skips
    # 60 ms before the one just used (clock not gone back; stamped from that one, not from
    # now: the bootstrap tick alone can take longer than 60 ms on a loaded machine)
    h.publish_state(stamp_ns=used - 60_000_000)
    h.spin_for(0.3)
    assert len(h.trajectories) == n and h.node.stale_skips == skips + 1
    h.publish_state()
    h.spin_until(lambda: len(h.trajectories) > n)


def test_states_without_ticks_get_explained(harness, monkeypatch):
    h = harness(trigger="timer", use_sim_time=True)  # and nothing publishes /clock
    said: list[str] = []
    monkeypatch.setattr(h.node, "_warn", lambda kind, text: said.append(kind))
    h.node._check_progress()  # no state yet: said so
    h.publish_state()
    h.spin_until(lambda: h.node._states_in >= 2)
    h.node._check_progress()
    assert said == ["no_state", "no_clock"] and not h.trajectories


def test_an_array_weight_set_as_ros2_param_set_delivers_it_applies(harness):
    # through the parameter services rclpy hands arrays over as array.array: the node died
    # on float(array('d', ...)) in its callback
    h = harness()
    msg = Parameter("w_base_linear_velocity", value=[10.0, 20.0, 5.0]).to_parameter_msg()
    wire = Parameter.from_parameter_msg(msg)
    assert type(wire.value).__name__ == "array"
    assert h.node.set_parameters([wire])[0].successful
    assert h.node.mpc.settings.weights.base_linear_velocity == [10.0, 20.0, 5.0]
    short = Parameter.from_parameter_msg(
        Parameter("w_base_linear_velocity", value=[1.0, 2.0]).to_parameter_msg())
    res = h.node.set_parameters([short])[0]
    assert not res.successful and "needs 3" in res.reason
    h.publish_state()
    h.spin_until(lambda: h.trajectories)



def test_an_integer_set_live_on_a_float_parameter_is_taken_as_that_float(harness):
    """'ros2 param set /mpc max_vx 1' sends an integer, which rclpy refused on a float
    parameter; a float list given as integers likewise. Other types still fail."""
    h = harness()
    names = ("max_vx", "w_base_linear_velocity", "w_posture")
    before = [Parameter(n, value=h.node.get_parameter(n).value) for n in names]
    wire = [Parameter.from_parameter_msg(Parameter(name, value=value).to_parameter_msg())
            for name, value in (("max_vx", 1), ("w_base_linear_velocity", [10, 20, 5]),
                                ("w_posture", 3))]
    assert [p.type_ for p in wire] == [Parameter.Type.INTEGER, Parameter.Type.INTEGER_ARRAY,
                                       Parameter.Type.INTEGER]
    assert all(r.successful for r in h.node.set_parameters(wire))
    st_ = h.node.mpc.settings
    assert st_.max_velocity[0] == 1.0 and st_.weights.posture == 3.0
    assert st_.weights.base_linear_velocity == [10.0, 20.0, 5.0]
    assert h.node.get_parameter("max_vx").type_ == Parameter.Type.DOUBLE
    text = h.node.set_parameters([Parameter("max_vx", value="fast")])[0]
    assert not text.successful and st_.max_velocity[0] == 1.0
    # an integer parameter keeps refusing a float
    assert not h.node.set_parameters([Parameter("publish_points", value=6.0)])[0].successful
    assert all(r.successful for r in h.node.set_parameters(before))


@pytest.mark.parametrize("second_after", [None, 0.1])
def test_sigterm_exits_cleanly_with_code_0(second_after):
    """Also with a second signal 100 ms after the first (ros2 launch forwarding its own
    after the terminal's), which killed the interpreter's teardown: exit -15."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen([sys.executable, "-m", "horizon_mpc.nodes.mpc_node"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        for line in proc.stdout:
            if "waiting for joint_states" in line:
                break
        proc.send_signal(signal.SIGTERM)
        if second_after is not None:
            time.sleep(second_after)
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()


def _cmdlines_naming(text: str) -> list[str]:
    found = []
    for proc_dir in FilePath("/proc").glob("[0-9]*"):
        try:
            cmd = (proc_dir / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if text in cmd:
            found.append(cmd)
    return found


def test_a_signal_while_the_problem_compiles_stops_the_compiler_and_exits_0(tmp_path):
    # a SIGTERM to the process waited for the whole build (~15 s; a launcher's kill
    # timeout escalates to SIGKILL) and left the compiler running
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path),
           "HORIZON_MPC_CACHE_DIR": str(tmp_path)}  # empty: everything compiles
    proc = subprocess.Popen([sys.executable, "-m", "horizon_mpc.nodes.mpc_node", "--ros-args",
                             "-p", "use_sim_time:=false"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        end = time.monotonic() + 120
        while not any(tmp_path.glob(".build_*")):
            assert proc.poll() is None and time.monotonic() < end
            time.sleep(0.05)
        time.sleep(0.3)
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=15) == 0
        assert time.monotonic() - sent < 5
        assert "Traceback" not in proc.stdout.read()
        time.sleep(0.2)
        assert not _cmdlines_naming(str(tmp_path)) and not any(tmp_path.glob(".build_*"))
    finally:
        if proc.poll() is None:
            proc.kill()


def test_the_executable_follows_the_sim_clock_unless_told_otherwise(tmp_path, walking_mpc):
    """use_sim_time defaults to true unless it is set FOR THIS NODE (rcl resolves -p rules
    and params-file sections): a shared file setting it for the sim only, or '-p
    sim:use_sim_time:=false', left mpc_node on the wall clock, never planning."""
    shared = tmp_path / "shared.yaml"
    shared.write_text("sim:\n  ros__parameters:\n    use_sim_time: false\n"
                      "mpc:\n  ros__parameters:\n    gait: trot\n")
    robot = tmp_path / "robot.yaml"
    robot.write_text("/**:\n  ros__parameters:\n    use_sim_time: false\n")
    cases = (([], True), (["-p", "sim:use_sim_time:=false"], True),
             (["--params-file", str(shared)], True), (["-p", "use_sim_time:=false"], False),
             (["-p", "mpc:use_sim_time:=false"], False),
             (["--params-file", str(robot)], False),
             (["--params-file", str(shared), "-r", "__node:=other"], True))
    for args, expected in cases:
        assert _use_sim_time(walking_mpc, ["mpc_node", "--ros-args", *args]) is expected, args
    # the library class keeps rclpy's default (tests and embedding code choose)
    assert _use_sim_time(walking_mpc, [], sim_time_default=False) is False


def _use_sim_time(mpc: WalkingMpc, argv: list[str], sim_time_default: bool = True) -> bool:
    """use_sim_time of an MpcNode built in a context initialised with ``argv``."""
    ctx = rclpy.Context()
    rclpy.init(args=argv, context=ctx)
    mpc.t_last = None
    try:
        node = MpcNode(mpc=mpc, context=ctx, sim_time_default=sim_time_default)
        value = node.get_parameter("use_sim_time").value
        node.destroy_node()
        return value
    finally:
        rclpy.try_shutdown(context=ctx)


def test_parameters_the_node_does_not_have_are_named(tmp_path, walking_mpc):
    """A misspelt parameter (max_xv for max_vx) was ignored without a word: the robot kept
    the default limit its user thought lowered."""
    from horizon_mpc.nodes.spin import undeclared_overrides

    typo = tmp_path / "typo.yaml"
    typo.write_text("mpc:\n  ros__parameters:\n    max_xv: 0.2\n    gait: trot\n")
    ctx = rclpy.Context()
    rclpy.init(args=["mpc_node", "--ros-args", "--params-file", str(typo), "-p", "foo:=1",
                     "-p", "use_sim_time:=true"], context=ctx)
    walking_mpc.t_last = None
    try:
        node = MpcNode(mpc=walking_mpc, context=ctx)
        assert undeclared_overrides(node) == ["foo", "max_xv"]
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_command_from_before_the_clock_went_back_is_no_command(context, walking_mpc):
    """A restarted simulator's clock starts again at 0: the last cmd_vel of the old run
    looked fresh (negative age) and the robot walked it, nobody commanding, for as long as
    the old run had lasted (3.76 m in 12 s)."""
    node = sim_time_node(context, walking_mpc)
    try:
        clock = node.get_clock()
        clock.set_ros_time_override(RosTime(nanoseconds=12_000_000_000))
        msg = Twist()
        msg.linear.x = 0.3
        node._on_cmd_vel(msg)
        assert node.current_command()[0] == pytest.approx(0.3)
        clock.set_ros_time_override(RosTime(nanoseconds=100_000_000))  # sim restarted
        np.testing.assert_array_equal(node.current_command(), 0.0)
        # and it stays dead when the new clock passes the old command's time
        clock.set_ros_time_override(RosTime(nanoseconds=12_100_000_000))
        np.testing.assert_array_equal(node.current_command(), 0.0)
        node._on_cmd_vel(msg)  # a new one is followed
        assert node.current_command()[0] == pytest.approx(0.3)
    finally:
        node.destroy_node()


def test_startup_errors_end_in_one_line_and_exit_code_1_interrupts_in_0(monkeypatch):
    """Out-of-range or mistyped parameters, bad YAML: one fatal line, exit code 1; a
    signal while the node is being built: exit code 0 (no traceback)."""
    import yaml
    from rclpy.exceptions import InvalidParameterValueException

    from horizon_mpc.nodes.spin import spin_until_signal

    monkeypatch.setattr(logging.getLogger("horizon_mpc"), "handlers", [])  # restored after
    logged: list[str] = []
    monkeypatch.setattr(rclpy.logging, "get_logger", lambda name: type(
        "L", (), {"fatal": lambda self, m: logged.append(m),
                  "info": lambda self, m: logged.append(m)})())
    for exc in (InvalidParameterValueException("control_rate", 0.0, "out of range"),
                yaml.YAMLError("bad"), KeyError("FL_foot")):
        def fail(exc=exc):
            raise exc
        assert spin_until_signal(fail, ["mpc_node"]) == 1
        assert logged[-1].startswith("cannot start:") and "Traceback" not in logged[-1]
    def bug():
        raise ZeroDivisionError("a bug")
    assert spin_until_signal(bug, ["mpc_node"]) == 1
    assert "Traceback" in logged[-1]  # not a user error: the traceback is kept

    def interrupted():
        os.kill(os.getpid(), signal.SIGINT)  # as Ctrl-C while compiling
        raise RuntimeError("compiling ... failed (the compiler was interrupted)")
    assert spin_until_signal(interrupted, ["mpc_node"]) == 0
    assert logged[-1] == "interrupted during start-up"
    assert spin_until_signal(lambda: None, ["mpc_node", "--ros-args", "-p"]) == 2


_HUNG_TEARDOWN = """
import re, sys, time
from rclpy.node import Node
from horizon_mpc.nodes import spin
spin.TEARDOWN_TIMEOUT, spin.TEARDOWN_BACKSTOP = 0.5, 0.5
class Hung(Node):
    def __init__(self):
        super().__init__("hung")
        print("READY", flush=True)
        if sys.argv[1] == "startup":
            raise ValueError("unknown robot 'go3'")
        if sys.argv[1] == "bug":
            self.create_timer(0.1, self.bug)
    def bug(self):
        raise RuntimeError("a bug in a callback")
    def destroy_node(self):
        if sys.argv[1] == "gil":  # a C call that keeps the GIL (exponential backtracking)
            re.match(r"(a+)+$", "a" * 40 + "b")
        else:
            time.sleep(60)  # waits with the GIL released
if sys.argv[1] == "startup":  # the start-up error's teardown hangs
    import rclpy
    rclpy.try_shutdown = lambda *a, **k: time.sleep(60)
sys.exit(spin.spin_until_signal(Hung, ["hung"], process_exits=True))
"""


@pytest.mark.parametrize("how, code, said", [
    ("sleep", 0, "the ROS/DDS teardown did not finish within 0.5 s"),
    ("gil", 1, "Timeout (0:00:01)!"),
    # a start-up error keeps its exit code (it exited 0: a reviewer)
    ("startup", 1, "the ROS/DDS teardown did not finish within 0.5 s"),
    # no stderr: no faulthandler (it raised in the teardown, exit code 1: a reviewer)
    ("no_stderr", 0, None),
    # an error in the spin keeps its exit code and traceback (0 and lost: a reviewer)
    ("bug", 1, "RuntimeError: a bug in a callback")])
def test_a_teardown_that_hangs_does_not_keep_the_process(how, code, said):
    """An auditor's mpc_node hung in Fast DDS's participant teardown after SIGINT (1 stop
    in ~14), 86 s and counting, SIGTERM ignored: an executable now ends itself
    TEARDOWN_TIMEOUT after its teardown began (exit code 0), and faulthandler ends it
    (stacks on stderr, exit code 1) when even that cannot run."""
    # no_stderr: closed, as with 2>&- (the child's sys.stderr is None)
    argv = (["sh", "-c", f'exec "{sys.executable}" -c "$0" {how} 2>&-', _HUNG_TEARDOWN]
            if how == "no_stderr" else [sys.executable, "-c", _HUNG_TEARDOWN, how])
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, text=True,
                            stderr=None if how == "no_stderr" else subprocess.PIPE)
    try:
        assert proc.stdout.readline().strip() == "READY"
        if how not in ("startup", "bug"):
            time.sleep(0.3)
            proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == code, err
    if said is not None:
        assert said in err
    if how == "bug":
        assert "the ROS/DDS teardown did not finish" in err


def test_an_integer_for_a_float_parameter_is_taken_at_startup(context, walking_mpc):
    """'-p control_rate:=50' (rcl types it an integer) is 50.0, not a type error."""
    node = sim_time_node(context, walking_mpc, control_rate=25, state_timeout=1,
                         w_base_linear_velocity=[40, 100, 10])  # an integer list: refused
    try:
        assert node.get_parameter("control_rate").value == 25.0
        assert node.period == pytest.approx(0.04) and node.state_timeout == 1.0
        assert node.get_parameter("w_base_linear_velocity").value == [40.0, 100.0, 10.0]
    finally:
        node.destroy_node()


@pytest.mark.slow
def test_sim_node_and_mpc_node_started_without_arguments_work_together():
    """Two processes, no arguments: the MPC plans on the simulator's states (real time)."""
    from trajectory_msgs.msg import JointTrajectory

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path),
           "ROS_DOMAIN_ID": str(60 + os.getpid() % 40)}
    procs = [subprocess.Popen([sys.executable, "-m", f"horizon_mpc.nodes.{name}"], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for name in ("sim_node", "mpc_node")]
    old = os.environ.get("ROS_DOMAIN_ID")
    os.environ["ROS_DOMAIN_ID"] = env["ROS_DOMAIN_ID"]
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = rclpy.create_node("listener", context=ctx)
        got: list[JointTrajectory] = []
        node.create_subscription(JointTrajectory, "joint_trajectory", got.append, 10)
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(node)
        deadline = time.monotonic() + 120.0
        while len(got) < 5 and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.5)
            assert all(p.poll() is None for p in procs), "a node exited"
        ex.shutdown()
        assert len(got) >= 5, "no trajectories from mpc_node within 120 s"
        assert all(len(m.points) > 0 and len(m.joint_names) == 12 for m in got)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
        if old is None:
            os.environ.pop("ROS_DOMAIN_ID", None)
        else:
            os.environ["ROS_DOMAIN_ID"] = old
        for p in procs:
            p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                assert p.wait(timeout=20) == 0
            finally:
                if p.poll() is None:
                    p.kill()


def test_iterations_per_tick_default_to_the_config_and_are_validated():
    from horizon_mpc.locomotion import MpcSettings
    from horizon_mpc.mpc import WalkingMpc

    assert MpcSettings().iterations == 1
    assert MpcSettings.from_dict({"iterations": 3}).iterations == 3
    mpc = WalkingMpc("go2")
    assert mpc.iterations == 1 and mpc.solver.opts["iterations_per_call"] == 1
    assert WalkingMpc("go2", iterations=2).solver.opts["iterations_per_call"] == 2
    with pytest.raises(ValueError, match="iterations per tick must be a whole number >= 1"):
        WalkingMpc("go2", iterations=0)


def test_a_tick_off_the_node_grid_moves_the_warm_start_by_the_fraction(walking_mpc):
    """Half a node later, each node's guess is halfway to the next node's (states on their
    manifold, inputs linearly); the last node keeps its own; on the grid nothing moves."""
    mpc = walking_mpc
    prb, N = mpc.wp.prb, mpc.wp.n_nodes
    q = prb.get_variable("q")
    a = prb.get_variable("a")
    q0 = mpc.wp.q_nominal.copy()
    k = np.arange(N + 1)
    Q = np.repeat(q0[:, None], N + 1, axis=1)
    Q[7:] += 0.01 * k  # joints moving linearly along the horizon
    q.set_initial_guess(Q)
    A = np.outer(np.ones(a.dim), np.arange(N, dtype=float))
    a.set_initial_guess(A)
    mpc._shift_fraction(0.01)  # within the tolerance: unchanged
    np.testing.assert_array_equal(q.initial_guess, Q)
    mpc._shift_fraction(0.5)
    np.testing.assert_allclose(q.initial_guess[7:, :N], Q[7:, :N] + 0.005, atol=1e-12)
    np.testing.assert_allclose(q.initial_guess[:7, :N], Q[:7, :N], atol=1e-12)
    np.testing.assert_array_equal(q.initial_guess[:, N], Q[:, N])
    np.testing.assert_allclose(a.initial_guess[:, :N - 1], A[:, :N - 1] + 0.5, atol=1e-12)
    mpc._shift_fraction(-0.5)  # back: interior nodes where they were
    np.testing.assert_allclose(q.initial_guess[7:, 1:N], Q[7:, 1:N], atol=1e-12)


def _feed_state(node: MpcNode, ns: int, q: np.ndarray) -> None:
    """One standing state stamped ``ns`` on a sim clock at ``ns``, into the callbacks."""
    node.get_clock().set_ros_time_override(RosTime(nanoseconds=ns))
    stamp, zeros = time_from_ns(ns), np.zeros(3)
    node._on_joint_state(joint_state_to_msg(stamp, node.joint_names, q[7:],
                                            np.zeros(len(q) - 7)))
    node._on_odom(odometry_to_msg(stamp, q[:3], q[3:7], zeros, zeros))


@pytest.mark.parametrize("trigger", ["state", "timer"])
def test_a_lockstep_tick_longer_than_the_period_is_an_overrun_not_a_deadline_miss(
        context, walking_mpc, trigger):
    """With trigger 'state' the lockstep simulator waits for each answer: a tick longer than
    the period only slows the loop below real time. Until session 32 such ticks were
    counted (and warned about) as deadline misses; with the timer they still are."""
    node = sim_time_node(context, walking_mpc, trigger=trigger, diagnostics_rate=0.0)
    said: list[tuple[str, str]] = []
    node._warn = lambda kind, text: said.append((kind, text))
    try:
        sent = Sent()
        node._pub_traj, node._pub_path, node._pub_diag = Sent(), Sent(), sent
        node.period = 1e-9  # every tick's work is longer than this
        _, q = standing_configuration(node.mpc.cfg)
        for k in range(4):
            _feed_state(node, 10 * NS_PER_S + k * 20_000_000, q)
            if trigger == "timer":
                node.tick()
        assert node.ticks == 4  # the bootstrap and three ticks, none late by itself
        late = (node.overruns, node.deadline_misses)
        assert late == ((3, 0) if trigger == "state" else (0, 3))
        kinds = {kind for kind, _ in said}
        if trigger == "state":
            assert "deadline" not in kinds
            text = next(t for k, t in said if k == "overrun")
            assert "slower than real time" in text and "misses no deadline" in text
        else:
            assert "overrun" not in kinds and "deadline" in kinds
        values = {kv.key: kv.value for kv in sent.msgs[-1].status[0].values}
        assert (int(values["overruns"]), int(values["deadline_misses"])) == late
    finally:
        node.destroy_node()


def test_a_timer_tick_plans_from_the_state_of_the_prepared_time_when_it_came(context,
                                                                              walking_mpc):
    """A timer tick sees the state of its own time and sometimes a newer one (a 250 Hz
    simulator's next state came before the tick's callback): planning from the newer one
    was a prepare miss (a whole tick, 12 % of go2's real-time ticks) or, with
    max_extrapolation, a prediction of the state (solo12 fell at 0.4 m/s in real time)."""
    node = sim_time_node(context, walking_mpc, trigger="timer", prepare_ahead=True)
    try:
        sent = Sent()
        node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), Sent()
        _, q = standing_configuration(node.mpc.cfg)
        start, period, state = 10 * NS_PER_S, 20_000_000, 4_000_000
        _feed_state(node, start, q)
        assert node.tick()  # the bootstrap, then the tick at start + period prepared
        misses = node.mpc.prepare_misses
        for k in range(1, 6):
            _feed_state(node, start + k * period, q)
            _feed_state(node, start + k * period + state, q)  # the next one came too
            assert node.tick()
            assert time_to_ns(sent.msgs[-1].header.stamp) == start + k * period
            assert node.mpc.solver.stats.status == "feedback"
        assert node.mpc.prepare_misses == misses
        # without the prepared time's state: the newest, a whole tick on its own time
        _feed_state(node, start + 6 * period + state, q)
        assert node.tick()
        assert time_to_ns(sent.msgs[-1].header.stamp) == start + 6 * period + state
        assert node.mpc.prepare_misses == misses + 1
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()


@pytest.mark.parametrize("trigger", ["state", "timer"])
def test_after_a_skipped_state_the_ticks_plan_from_the_newest_again(context, walking_mpc,
                                                                     trigger):
    """A state skipped as stale (the node's clock jumped: use_sim_time toggled) left the
    preparation's time on it: every later tick planned from the state before the newest,
    and a lockstep simulator, which steps on the answer to its newest state, waited out
    its lockstep_timeout at each step (a QA finding)."""
    node = sim_time_node(context, walking_mpc, trigger=trigger, prepare_ahead=True)
    try:
        sent = Sent()
        node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), Sent()
        _, q = standing_configuration(node.mpc.cfg)
        start, period = 10 * NS_PER_S, 20_000_000

        def step(k: int, clock_jump_ns: int = 0) -> None:
            ns = start + k * period
            # the state arrives on the node's clock, which may have jumped ahead
            node.get_clock().set_ros_time_override(RosTime(nanoseconds=ns + clock_jump_ns))
            stamp, zeros = time_from_ns(ns), np.zeros(3)
            node._on_joint_state(joint_state_to_msg(stamp, node.joint_names, q[7:],
                                                    np.zeros(len(q) - 7)))
            node._on_odom(odometry_to_msg(stamp, q[:3], q[3:7], zeros, zeros))
            if trigger == "timer":
                node.tick()

        for k in range(3):
            step(k)
        assert time_to_ns(sent.msgs[-1].header.stamp) == start + 2 * period
        step(3, clock_jump_ns=10 * NS_PER_S)
        assert node.stale_skips >= 1
        answered = len(sent.msgs)
        for k in range(4, 8):
            step(k)
            assert time_to_ns(sent.msgs[-1].header.stamp) == start + k * period
        assert len(sent.msgs) == answered + 4
        assert node.mpc.solver.stats.status == "feedback"  # prepared ticks again
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()


def test_lockstep_states_at_another_period_than_the_nodes_are_explained(context,
                                                                        walking_mpc):
    """A hand-started lockstep simulator stepping 10 ms (sim_node's default until session
    24) against the node's 20 ms: every tick ran whole, the go2 fell, and the warning
    blamed a loaded machine or control_rate. It names the states' spacing and the fix."""
    node = sim_time_node(context, walking_mpc, prepare_ahead=True)
    warnings: list[str] = []
    node._warn = lambda kind, text: warnings.append(text)
    try:
        node._pub_traj, node._pub_path, node._pub_diag = Sent(), Sent(), Sent()
        _, q = standing_configuration(node.mpc.cfg)
        start, period = 10 * NS_PER_S, 10_000_000
        for k in range(20):
            _feed_state(node, start + k * period, q)  # trigger 'state': a tick each
        assert node.ticks == 20 and node.mpc.prepare_misses >= 18
        misses = [w for w in warnings if "ran a whole tick" in w]
        assert misses, warnings
        assert "the states come 10 ms apart" in misses[-1]
        assert "one control period (20 ms" in misses[-1]
        assert "sim_node's control_period" in misses[-1]
        # a free-running stream (an auditor's 500 Hz sim_node) is told to use the timer
        assert "free-running state stream" in misses[-1] and "trigger 'timer'" in misses[-1]
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()


def test_a_drivers_states_off_the_tick_times_get_the_prepared_feedback_steps(context,
                                                                               walking_mpc):
    """A robot's driver stamps its states when it measures them (500 Hz, jittered), never
    on the node's tick times: every tick ran whole and the diagnostics warned of prepare
    misses forever (96 of 97 ticks). The state nearest the prepared time within
    feedback_tolerance (2 ms) gets the prepared step; the plan is stamped with its time."""
    node = sim_time_node(context, walking_mpc, trigger="timer", prepare_ahead=True)
    try:
        sent, sent_diag = Sent(), Sent()
        node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), sent_diag
        _, q = standing_configuration(node.mpc.cfg)
        start, period, driver = 10 * NS_PER_S + 317_000, 20_000_000, 2_000_000
        jitter = [0, 410_000, -380_000, 150_000, -90_000, 330_000, -270_000]
        stamps, k = [], 0
        for tick in range(12):
            while start + k * driver <= start + tick * period + 600_000:
                stamp = start + k * driver + jitter[k % len(jitter)]
                _feed_state(node, stamp, q)
                stamps.append(stamp)
                k += 1
            if tick == 0:
                assert node.tick()  # the bootstrap
                misses = node.mpc.prepare_misses
                continue
            prepared = node._prepared_ns
            assert node.tick()
            used = time_to_ns(sent.msgs[-1].header.stamp)
            assert used == min(stamps[-8:], key=lambda x: abs(x - prepared))
            assert abs(used - prepared) <= 2_000_000
            assert node.mpc.solver.stats.status == "feedback"
        assert node.mpc.prepare_misses == misses
        assert sent_diag.msgs[-1].status[0].level == DiagnosticStatus.OK
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()


def test_states_off_the_tick_grid_do_not_make_the_ticks_drift_back(context, walking_mpc):
    """States on a grid the ticks are not on (100 Hz ticks, 250 Hz states in the real-time
    closed loop): the state nearest the prepared time came before it, and the next
    preparation, one period after that state's stamp, drifted back by up to
    feedback_tolerance every tick: the plans were 32 ms old at 100 Hz. The preparations
    stay on the node's grid; the plans keep their states' stamps."""
    node = sim_time_node(context, walking_mpc, trigger="timer", prepare_ahead=True)
    try:
        sent = Sent()
        node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), Sent()
        _, q = standing_configuration(node.mpc.cfg)
        start, period, state = 10 * NS_PER_S, 20_000_000, 3_000_000  # 333 Hz states
        k = 0
        for tick in range(16):
            tick_ns = start + tick * period
            while start + k * state <= tick_ns + 600_000:  # what came before the tick
                _feed_state(node, start + k * state, q)
                k += 1
            if tick == 0:
                assert node.tick()  # the bootstrap, on the state at `start`
                misses = node.mpc.prepare_misses
                continue
            assert node._prepared_ns == tick_ns  # on the grid, every tick
            assert node.tick()
            used = time_to_ns(sent.msgs[-1].header.stamp)
            assert abs(used - tick_ns) <= 2_000_000 and used % state == start % state
            assert node.mpc.solver.stats.status == "feedback"
        assert node.mpc.prepare_misses == misses
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()



def test_separate_drivers_states_get_the_prepared_feedback_steps(context, walking_mpc):
    """joint_states and odom from separate drivers never share a stamp: the newest of each
    was taken, and when both were past the prepared time by more than feedback_tolerance
    (a timer callback late, states at ~250 Hz) the tick ran whole although a state of each
    within the tolerance had come (28-38 of 50 ticks whole at 200-250 Hz in an auditor's
    run). The joint state and the base state nearest the prepared time serve it."""
    node = sim_time_node(context, walking_mpc, trigger="timer", prepare_ahead=True)
    try:
        sent = Sent()
        node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), Sent()
        _, q = standing_configuration(node.mpc.cfg)
        zeros, ms = np.zeros(3), 1_000_000

        def joints(ns: int) -> None:
            node.get_clock().set_ros_time_override(RosTime(nanoseconds=ns))
            node._on_joint_state(joint_state_to_msg(time_from_ns(ns), node.joint_names,
                                                    q[7:], np.zeros(len(q) - 7)))

        def base(ns: int) -> None:
            node.get_clock().set_ros_time_override(RosTime(nanoseconds=ns))
            node._on_odom(odometry_to_msg(time_from_ns(ns), q[:3], q[3:7], zeros, zeros))

        joints(10 * NS_PER_S)
        base(10 * NS_PER_S + ms)
        assert node.tick()  # the bootstrap
        misses = node.mpc.prepare_misses
        for _ in range(5):
            prepared = node._prepared_ns
            joints(prepared - 10 * ms)  # stamps that meet now and then, far from it
            base(prepared - 10 * ms)
            joints(prepared - ms)
            base(prepared - 3 * ms // 2)
            base(prepared + 5 * ms // 2)
            joints(prepared + 3 * ms)  # both newest past the 2 ms tolerance
            assert node.tick()
            assert time_to_ns(sent.msgs[-1].header.stamp) == prepared - 3 * ms // 2
            assert node.mpc.solver.stats.status == "feedback"
        assert node.mpc.prepare_misses == misses
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()

def test_prepare_ahead_ticks_are_feedback_steps_stamped_at_their_plan_time(context,
                                                                             walking_mpc):
    """With prepare_ahead, a state on the prepared tick time is answered by the feedback
    step alone; one stamped 3 ms off is predicted to that time (the plan's stamp says so);
    10 ms off (past max_extrapolation) gets a whole tick stamped with the state's time."""
    node = sim_time_node(context, walking_mpc, prepare_ahead=True, max_extrapolation=0.005)
    try:
        sent, sent_diag = Sent(), Sent()
        node._pub_traj, node._pub_path, node._pub_diag = sent, Sent(), sent_diag
        _, q = standing_configuration(node.mpc.cfg)
        start, period = 10 * NS_PER_S, 20_000_000
        misses = node.mpc.prepare_misses
        offsets = [0, 0, 0, 0, -3_000_000, 0, 10_000_000]
        for k, off in enumerate(offsets):
            _feed_state(node, start + k * period + off, q)
        stamps = [time_to_ns(m.header.stamp) - start for m in sent.msgs]
        grid = [k * period for k in range(len(offsets))]
        # on the grid, and 3 ms early: planned at the prepared tick time
        assert stamps[:6] == grid[:6]
        # 10 ms late: a whole tick from the state's own stamp
        assert stamps[6] == grid[6] + 10_000_000
        assert node.mpc.prepare_misses == misses + 1
        assert node.mpc.solver.stats.status == "rti"
        assert node.last_prepare_time > 0.0  # the next tick was prepared after publishing
        # one late state: counted, not warned about (it suggested a misconfiguration 13
        # times in 47 s of a correct sim_node + mpc_node run); most of them late: warned
        assert "prepare_miss" not in node._last_warn
        assert node._last_diag[1] == DiagnosticStatus.OK
        late = start + len(offsets) * period + 10_000_000
        for k in range(12):
            _feed_state(node, late + k * period + (7_000_000 if k % 2 else 0), q)
        assert "prepare_miss" in node._last_warn
        # the diagnostics say so too, at WARN (the plans are still sent)
        status = sent_diag.msgs[-1].status[0]
        assert status.level == DiagnosticStatus.WARN and "prepare misses" in status.message
    finally:
        walking_mpc.settings.prepare_ahead = False  # the fixture is shared
        node.destroy_node()


def test_prepare_ahead_diagnostics_report_both_phases(context, walking_mpc):
    node = sim_time_node(context, walking_mpc, prepare_ahead=True)
    try:
        misses = walking_mpc.prepare_misses
        out = drive_in_sim_time(node, 5)
        values = {kv.key: kv.value for kv in out["diag"][-1].status[0].values}
        assert float(values["prepare_time_ms"]) > 0.0
        assert int(values["prepare_misses"]) == misses
        assert node.mpc.solver.stats.status == "feedback"
    finally:
        walking_mpc.settings.prepare_ahead = False
        node.destroy_node()


def test_the_executable_freezes_what_startup_allocated_out_of_the_collector(monkeypatch):
    """A full collection over the startup objects (~11 ms with go2) must not land in a tick:
    ``main`` builds the node, then freezes everything alive."""
    startup = [object()]
    monkeypatch.setattr(mpc_node, "MpcNode", lambda **_: startup[0])
    gc.unfreeze()
    try:
        assert mpc_node._node_with_frozen_startup() is startup[0]
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()


def test_the_diagnostics_message_is_refilled_with_each_ticks_values_and_keys():
    from horizon_mpc.nodes.mpc_outputs import DiagnosticsMessage

    diag = DiagnosticsMessage("mpc", "go2")
    first = diag.filled(1_500_000_000, b"\x00", "ok", {"a": 1, "b": [1.5, 2]})
    kvs = list(first.status[0].values)
    second = diag.filled(2_000_000_001, b"\x01", "solver: rti", {"a": 3.25, "b": "x"})
    status = second.status[0]
    assert [(kv.key, kv.value) for kv in status.values] == [("a", "3.25"), ("b", "x")]
    assert all(a is b for a, b in zip(kvs, status.values, strict=True))  # refilled in place
    assert (second.header.stamp.sec, second.header.stamp.nanosec) == (2, 1)
    assert status.level == b"\x01" and status.message == "solver: rti"
    third = diag.filled(3, b"\x00", "ok", {"a": 0, "c": None})  # other keys: new pairs
    assert [(kv.key, kv.value) for kv in third.status[0].values] == [("a", "0"), ("c", "None")]


def test_the_trajectory_message_is_refilled_with_each_plan():
    from types import SimpleNamespace

    from horizon_mpc.nodes.mpc_outputs import fill_trajectory

    def plan(seed, nodes=8, nj=3):
        rng = np.random.default_rng(seed)
        tau = rng.standard_normal((6 + nj, nodes))
        return SimpleNamespace(q=rng.standard_normal((7 + nj, nodes + 1)),
                               v=rng.standard_normal((6 + nj, nodes + 1)),
                               a=rng.standard_normal((6 + nj, nodes)), dt=0.02,
                               tau_head=lambda n: tau[:, :n])

    names = ["j0", "j1", "j2"]
    msg = JointTrajectory()
    first = fill_trajectory(msg, plan(0), names, 4, 1_500_000_000)
    points = list(first.points)
    p = plan(1)
    second = fill_trajectory(msg, p, names, 4, 2_000_000_001)
    assert second is msg and all(a is b for a, b in zip(points, second.points, strict=True))
    assert (second.header.stamp.sec, second.header.stamp.nanosec) == (2, 1)
    assert list(second.joint_names) == names
    for k, pt in enumerate(second.points):
        np.testing.assert_array_equal(pt.positions, p.q[7:, k])
        np.testing.assert_array_equal(pt.velocities, p.v[6:, k])
        np.testing.assert_array_equal(pt.accelerations, p.a[6:, k])
        np.testing.assert_array_equal(pt.effort, p.tau_head(4)[6:, k])
        assert seconds_from_duration(pt.time_from_start) == pytest.approx(0.02 * k)
    # fewer points (the plan's nodes or publish_points) or other joints: new points
    assert len(fill_trajectory(msg, plan(2, nodes=2), names, 4, 0).points) == 2
    third = fill_trajectory(msg, plan(3, nj=2), ["a", "b"], 4, 0)
    assert list(third.joint_names) == ["a", "b"] and len(third.points[0].effort) == 2


# ---------------------------------------------------------------------- model and horizon
def test_robot_model_comes_from_robot_description_then_urdf_path_then_the_config():
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.nodes.mpc_node import robot_model
    from horizon_mpc.robots import example_robot_files

    cfg = load_robot_config("go2")
    urdf = example_robot_files("go2").urdf
    solo = example_robot_files("solo12").urdf
    assert robot_model(cfg) is None  # nothing asked: WalkingMpc builds the config's model
    from_file = robot_model(cfg, urdf_path=str(urdf))
    assert from_file.nq == 19 and from_file.joint_names[0].startswith("FL_")
    # robot_description wins over urdf_path (here: another robot's file)
    from_text = robot_model(cfg, urdf_path=str(solo), robot_description=urdf.read_text())
    assert from_text.joint_names == from_file.joint_names
    with pytest.raises(ValueError, match="urdf_path"):
        robot_model(cfg, robot_description=str(urdf))  # a path is not URDF text
    with pytest.raises(FileNotFoundError, match="no_such.urdf"):
        robot_model(cfg, urdf_path="/tmp/no_such.urdf")


@pytest.mark.slow  # a renamed joint: the model's functions are compiled once (~15 s)
def test_the_log_names_where_the_model_comes_from(tmp_path):
    """A config with its own urdf_path (a user's robot, e.g. laikago, which walks the
    default profile from a 15-line config) was logged as 'model from example-robot-data'."""
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.nodes.mpc_node import model_source
    from horizon_mpc.robots import example_robot_files

    go2 = load_robot_config("go2")
    urdf = str(example_robot_files("go2").urdf)
    path = tmp_path / "mine.yaml"
    path.write_text(f"urdf_path: {urdf}\nfeet: {go2.feet}\n")
    mine = load_robot_config(str(path))
    assert model_source(go2) == "example-robot-data"
    assert model_source(mine) == urdf
    assert model_source(go2, "/x.urdf") == "/x.urdf"
    assert model_source(mine, "/x.urdf", "<robot name='r'/>") == "robot_description"


def test_the_node_plans_with_the_robot_description_it_is_given(context):
    from horizon_mpc.robots import example_robot_files

    # go2 with one joint renamed: only a node that reads this text plans with that name
    text = example_robot_files("go2").urdf.read_text().replace('"FL_hip_joint"',
                                                               '"FL_hip_joint_given"')
    assert "FL_hip_joint_given" in text
    node = MpcNode(parameter_overrides=[Parameter("trigger", value="state"),
                                        Parameter("use_sim_time", value=True),
                                        Parameter("robot_description", value=text)],
                   context=context)
    try:
        assert node.get_parameter("robot_description").value == text
        assert node.mpc.model.pin_model.nq == 19
        assert "FL_hip_joint_given" in node.joint_names
        out = drive_in_sim_time(node, 3)
        assert len(out["traj"]) == 3
        assert list(out["traj"][-1].joint_names) == node.joint_names
    finally:
        node.destroy_node()


def test_a_foot_the_urdf_does_not_have_is_named_at_startup(context):
    from horizon_mpc.robots import example_robot_files

    solo = str(example_robot_files("solo12").urdf)  # go2's config names go2's feet
    with pytest.raises(KeyError, match="FL_foot"):
        MpcNode(parameter_overrides=[Parameter("urdf_path", value=solo)], context=context)


def test_horizon_nodes_and_dt_are_parameters_with_the_config_defaults(context, walking_mpc):
    node = sim_time_node(context, walking_mpc)
    try:
        st_ = walking_mpc.settings
        assert node.get_parameter("n_nodes").value == st_.n_nodes
        assert node.get_parameter("dt").value == st_.dt
        assert node.get_parameter("control_rate").value == pytest.approx(1 / st_.dt)
    finally:
        node.destroy_node()
    with pytest.raises(ValueError, match="n_nodes/dt"):
        sim_time_node(context, walking_mpc, n_nodes=st_.n_nodes + 4)


@pytest.mark.slow
def test_a_node_built_with_another_horizon_plans_over_it(context):
    node = MpcNode(parameter_overrides=[Parameter("trigger", value="state"),
                                        Parameter("use_sim_time", value=True),
                                        Parameter("n_nodes", value=16),
                                        Parameter("dt", value=0.025)], context=context)
    try:
        assert (node.mpc.wp.n_nodes, node.mpc.settings.dt) == (16, 0.025)
        assert node.get_parameter("control_rate").value == pytest.approx(40.0)
        out = drive_in_sim_time(node, 3, period_ns=25_000_000)
        points = out["traj"][-1].points
        assert len(points) == 6
        assert points[1].time_from_start.nanosec == 25_000_000
        assert node.plan.q.shape == (19, 17)
    finally:
        node.destroy_node()


def test_time_outs_and_the_idle_stance_change_live(harness):
    h = harness()
    assert h.node.mpc.scheduler.stand_when_idle  # the config's default
    res = h.node.set_parameters([Parameter("cmd_timeout", value=0.05),
                                 Parameter("state_timeout", value=3.0),
                                 Parameter("stand_when_idle", value=False)])
    assert all(r.successful for r in res)
    assert (h.node.cmd_timeout, h.node.state_timeout) == (0.05, 3.0)
    assert not h.node.mpc.scheduler.stand_when_idle and not h.node.mpc.settings.stand_when_idle
    # a command older than the new time-out is zero; a 1 s old state is planned from now
    h.pub_cmd.publish(twist(0.3, 0.0, 0.0))
    h.spin_until(lambda: h.node._cmd is not None)
    time.sleep(0.1)
    np.testing.assert_array_equal(h.node.current_command(), [0.0, 0.0, 0.0])
    h.publish_state(age=1.0)
    h.spin_until(lambda: h.trajectories)
    assert h.node.stale_skips == 0
    # stepping in place with a zero command: some foot lifts within the horizon
    h.publish_state()
    h.spin_until(lambda: len(h.trajectories) >= 2)
    assert not h.node.plan.stance.all()
    assert not h.node.set_parameters([Parameter("cmd_timeout", value=-1.0)])[0].successful
    h.node.set_parameters([Parameter("stand_when_idle", value=True)])


def test_a_node_that_cannot_start_says_why_in_one_line_and_exits_1():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run([sys.executable, "-m", "horizon_mpc.nodes.mpc_node", "--ros-args",
                          "-p", "robot:=spot"], env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 1
    assert "cannot start: no robot config 'spot'; available:" in out.stderr + out.stdout
    assert "Traceback" not in out.stderr
    # an empty list: rcl gives no value, and rclpy's 'not initialized' said nothing useful
    out = subprocess.run([sys.executable, "-m", "horizon_mpc.nodes.mpc_node", "--ros-args",
                          "-p", "w_base_linear_velocity:=[]"], env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert ("cannot start: parameter 'w_base_linear_velocity' was given no value (an empty "
            "list?); its default is [40.0, 100.0, 10.0]") in out.stderr + out.stdout


def test_the_librarys_warnings_reach_the_ros_loggers(monkeypatch):
    """'ILQR failed ...: back to the standing warm start' is a Python logging warning of
    the library: the executables forward it to the ROS logger (console and /rosout)."""
    import logging

    from horizon_mpc.nodes.spin import _RosLogHandler, forward_library_warnings

    got: list[tuple[str, str, str]] = []

    class Logger:
        def __init__(self, name):
            self.name = name

        def warning(self, text):
            got.append((self.name, "warning", text))

        def error(self, text):
            got.append((self.name, "error", text))

        def info(self, text):
            got.append((self.name, "info", text))

    monkeypatch.setattr(rclpy.logging, "get_logger", Logger)
    lib = logging.getLogger("horizon_mpc")
    progress = logging.getLogger("horizon_mpc.codegen")
    before, before_progress = list(lib.handlers), list(progress.handlers)
    level = progress.level
    try:
        forward_library_warnings()
        forward_library_warnings()  # idempotent
        assert sum(isinstance(h, _RosLogHandler) for h in lib.handlers) == 1
        logging.getLogger("horizon_mpc.mpc.controller").warning("ILQR failed (%s)", "rti")
        logging.getLogger("horizon_mpc.mpc.controller").info("not forwarded")
        logging.getLogger("horizon_mpc.codegen").error("compiling failed")
        # the compilation's progress too (a first start compiled for minutes in silence),
        # once each
        logging.getLogger("horizon_mpc.codegen").info("compiling %s ...", "fk_foot")
        assert got == [("horizon_mpc.mpc.controller", "warning", "ILQR failed (rti)"),
                       ("horizon_mpc.codegen", "error", "compiling failed"),
                       ("horizon_mpc.codegen", "info", "compiling fk_foot ...")]
    finally:
        lib.handlers[:] = before
        progress.handlers[:] = before_progress
        progress.setLevel(level)


def test_input_notes_of_different_kinds_are_throttled_apart():
    """A clamp note must not silence an 'ignored fields' note of the same topic; the same
    note with other numbers stays one kind."""
    clamp = problem_kind("cmd_vel_note",
                         "cmd_vel [0.9, 0.0, 0.0] clamped to the limits [0.5, 0.3, 1]")
    clamp2 = problem_kind("cmd_vel_note",
                          "cmd_vel [1.5, -0.2, 0.0] clamped to the limits [0.5, 0.3, 1]")
    ignored = problem_kind("cmd_vel_note", "cmd_vel linear.z/angular.x/angular.y are ignored")
    assert clamp == clamp2 != ignored
    assert problem_kind("odom", "x") != problem_kind("cmd_vel", "x")
    # rejections: other joints or values are the same problem, another problem is not
    lacks = problem_kind("joint_states", "JointState lacks joints ['RR_calf_joint']")
    assert lacks == problem_kind("joint_states", "JointState lacks joints ['FL_hip', 'x']")
    assert lacks != problem_kind("joint_states", "positions of 'FL_hip' not finite (nan)")


def test_rejections_of_different_problems_on_one_topic_are_each_named(context, walking_mpc):
    """Rejections were throttled per topic: of three bad joint states 0.3 s apart only the
    first was named (a missing joint), not the NaN nor the wrong array length after it (a
    QA finding)."""
    node = sim_time_node(context, walking_mpc)
    logged: list[str] = []

    class Logger:
        def warning(self, text: str) -> None:
            logged.append(text)

    node.get_logger = Logger
    try:
        _, q = standing_configuration(node.mpc.cfg)
        names, pos = list(node.joint_names), q[7:]
        stamp = time_from_ns(10 * NS_PER_S)
        for _ in range(2):  # the second round: each problem again, throttled
            node._on_joint_state(joint_state_to_msg(stamp, names[:-1], pos[:-1],
                                                    np.zeros(len(pos) - 1)))
            node._on_joint_state(joint_state_to_msg(stamp, names, np.full(len(pos), np.nan),
                                                    np.zeros(len(pos))))
            bad = joint_state_to_msg(stamp, names, pos, np.zeros(len(pos)))
            bad.velocity = [0.0] * (len(pos) - 2)
            node._on_joint_state(bad)
        assert node.rejected["joint_states"] == 6
        assert len(logged) == 3, logged
        assert all(text.startswith("rejected joint_states") for text in logged)
        assert len({problem_kind("", text) for text in logged}) == 3
    finally:
        node.destroy_node()


def test_timing_settings_outside_where_the_robot_walked_are_warned_about():
    from horizon_mpc.nodes.mpc_parameters import timing_warnings

    assert timing_warnings(0.02, 24, 0.02, 6) == []  # the defaults
    assert timing_warnings(0.02, 24, 0.04, 6) == []  # 25 Hz: walked (go2, a1, solo12)
    assert timing_warnings(0.01, 24, 0.01, 6) == []
    # 10 Hz: go2, a1 and anymal_c fell in the lockstep loop (session 28 audit)
    assert [w for w in timing_warnings(0.02, 24, 0.1, 6) if "5 nodes a tick" in w]
    five_hz = timing_warnings(0.02, 24, 0.2, 6)
    assert any("ends before the next tick" in w and "publish_points >= 11" in w
               for w in five_hz)
    assert any("10 nodes a tick" in w for w in five_hz)
    # the last point is at (points - 1) dt: 5 points at 10 Hz end 0.08 s in, 1 point at once
    # (both passed, and fell in the lockstep loop)
    for period, points, need in ((0.1, 5, 6), (0.02, 1, 2)):
        assert any(f"publish_points >= {need}" in w
                   for w in timing_warnings(0.02, 24, period, points)), (period, points)
    assert not any("publish_points" in w for w in timing_warnings(0.02, 24, 0.1, 6))
    assert any("dt 0.04 s" in w for w in timing_warnings(0.04, 24, 0.04, 6))
    assert any("dt 0.03 s" in w for w in timing_warnings(0.03, 24, 0.03, 6))  # solo12 fell
    assert any("n_nodes 12" in w for w in timing_warnings(0.02, 12, 0.02, 6))
    assert any("n_nodes 16" in w for w in timing_warnings(0.02, 16, 0.02, 6))  # real time
    assert timing_warnings(0.02, 20, 0.02, 6) == []


def test_gait_settings_and_weights_outside_where_the_trot_walked_are_warned_about(harness,
                                                                                monkeypatch):
    """Accepted values that made the go2 fall (step_duration 0.8 s or more, duty factor 0.1,
    weights at 2e4x their defaults and more) were set without a word."""
    from horizon_mpc.locomotion.settings import Weights
    from horizon_mpc.nodes.mpc_parameters import gait_warnings, limit_warnings, weight_warnings

    assert gait_warnings("trot", 0.3, None) == gait_warnings("walk", 0.7, 0.3) == []
    # relative to the robot's own step and below the duty factor another robot fell with
    # (solo12: 0.6 s for its 0.2 fell, as 0.2 duty factor did; session 26 audit)
    assert gait_warnings("trot", 0.4, None, config_step=0.2) == []
    assert any("step_duration 0.6 s is 3x the robot config's 0.2 s" in w
               for w in gait_warnings("trot", 0.6, None, config_step=0.2))
    assert any("duty_factor 0.2 is below 0.25" in w for w in gait_warnings("trot", 0.3, 0.2))
    assert limit_warnings([0.6, 0.5, 0.8], [0.6, 0.5, 0.8]) == []
    fast = limit_warnings([1.0, 0.5, 0.8], [0.6, 0.5, 0.8])
    assert len(fast) == 1 and fast[0].startswith("max_vx 1 m/s is above the robot config's 0.6")
    assert any("step_duration 0.8 s is outside 0.15-0.7 s" in w
               for w in gait_warnings("trot", 0.8, None))
    assert any("duty_factor 0.1 is outside" in w for w in gait_warnings("trot", 0.3, 0.1))
    # a duty factor of 1 (in the declared range) makes the trot stand: said as such, not as
    # a value outside where it walked (a session 28 audit)
    assert gait_warnings("trot", 0.3, 1.0) == [
        "duty_factor 1: gait 'trot' never lifts a foot (it stands, like gait 'stand') and "
        "cmd_vel is not followed"]
    assert weight_warnings(Weights()) == []
    heavy = weight_warnings(Weights(posture=30.0, base_position=1e6))
    assert len(heavy) == 1 and heavy[0].startswith("w_base_position 1e+06 is up to 2e+04x")
    h = harness()
    warned: list[str] = []
    logger = h.node.get_logger()
    monkeypatch.setattr(logger, "warning", lambda text, *a, **k: warned.append(text))
    monkeypatch.setattr(h.node, "get_logger", lambda: logger)
    assert h.node.set_parameters([Parameter("step_duration", value=1.0)])[0].successful
    assert any("step_duration 1 s is outside" in w for w in warned)
    warned.clear()
    assert h.node.set_parameters([Parameter("w_base_orientation", value=1e8)])[0].successful
    assert len(warned) == 1 and warned[0].startswith("w_base_orientation 1e+08")
    warned.clear()
    assert h.node.set_parameters([Parameter("max_vx", value=0.4)])[0].successful
    assert warned == []  # a weight set before is not warned about again
    assert h.node.set_parameters([Parameter("max_vx", value=1.0)])[0].successful
    assert len(warned) == 1 and warned[0].startswith("max_vx 1 m/s is above")


def test_a_control_rate_faster_than_the_nodes_sets_dt_and_the_nodes():
    """At 100 Hz with 0.02 s nodes (half a node a tick) go2 fell; on 0.01 s nodes, 48 of
    them (the same horizon), it walked, in lockstep and in real time; 125 Hz on 60 of 8 ms
    too. Below 8 ms (not seen walking) and for slower rates the config's nodes stay."""
    from horizon_mpc.nodes.mpc_parameters import horizon_for_rate

    assert horizon_for_rate(0.02, 24, 100.0) == pytest.approx((0.01, 48))
    dt, n = horizon_for_rate(0.02, 24, 83.0)
    assert dt == pytest.approx(1 / 83) and n == 40
    assert horizon_for_rate(0.02, 24, 50.0) is None  # one node a tick
    assert horizon_for_rate(0.02, 24, 25.0) is None  # two
    assert horizon_for_rate(0.02, 24, 125.0) == pytest.approx((0.008, 60))
    assert horizon_for_rate(0.02, 24, 200.0) is None  # 5 ms nodes: never seen walking


def test_prepare_ahead_needs_whole_nodes_per_tick(context, walking_mpc):
    """100 Hz at dt 0.02 s (half a node a tick): go2 fell at 2.3-2.5 s in real time with
    prepare_ahead, walked with whole ticks."""
    for rate, prepared in ((100.0, False), (1000.0, False), (50.0, True), (25.0, True)):
        node = sim_time_node(context, walking_mpc, trigger="timer", control_rate=rate,
                             prepare_ahead=True)
        try:
            assert node.mpc.settings.prepare_ahead is prepared, rate
        finally:
            walking_mpc.settings.prepare_ahead = False  # the fixture is shared
            node.destroy_node()


def test_more_published_points_than_nodes_are_clamped_with_a_warning(context, walking_mpc,
                                                                     capfd):
    node = sim_time_node(context, walking_mpc, publish_points=100)
    try:
        assert node.publish_points == walking_mpc.settings.n_nodes  # was silent
        assert "publish_points 100 is more than the horizon's" in capfd.readouterr().err
    finally:
        node.destroy_node()


def test_help_prints_the_parameters_and_other_plain_arguments_are_named(monkeypatch, capsys):
    """'mpc_node --help' prints its usage (every declared parameter) without building a
    node; arguments outside --ros-args are ignored with a warning that names them."""
    from horizon_mpc.nodes import mpc_node, sim_node
    from horizon_mpc.nodes.mpc_parameters import parameter_names
    from horizon_mpc.nodes.spin import spin_until_signal

    def must_not_build():
        raise AssertionError("--help built the node")
    for exe, text in (("mpc_node", mpc_node.usage), ("sim_node", sim_node.usage)):
        assert spin_until_signal(must_not_build, [exe, "--help"], text) == 0
        out = capsys.readouterr().out
        assert out.startswith(f"usage: ros2 run horizon_mpc {exe}")
    assert mpc_node.main(["mpc_node", "-h", "--ros-args", "-p", "robot:=go2"]) == 0
    out = capsys.readouterr().out
    assert all(f"\n  {name} (default " in out for name in parameter_names())
    assert "w_posture (default" in out and "[live]" in out

    warned: list[str] = []
    monkeypatch.setattr(logging.getLogger("horizon_mpc"), "handlers", [])  # restored after
    monkeypatch.setattr(rclpy.logging, "get_logger", lambda name: type(
        "L", (), {"warning": lambda self, m: warned.append(m),
                  "fatal": lambda self, m: warned.append(m)})())

    def fail():
        raise ValueError("stop here")
    argv = ["mpc_node", "foo", "--ros-args", "-p", "robot:=go2", "--", "bar"]
    assert spin_until_signal(fail, argv, "usage") == 1
    assert "ignoring arguments that are not ROS arguments: foo bar" in warned[0]


def test_params_file_sections_that_match_no_node_are_named(tmp_path):
    """rcl ignores a params file section keyed for another node without a word (a file
    written for 'mpc_node:' under ros2 run, whose node is 'mpc')."""
    import yaml

    from horizon_mpc.nodes.spin import unmatched_params_file_sections

    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({
        "/**": {"ros__parameters": {"use_sim_time": False}},
        "mpc": {"ros__parameters": {"gait": "walk"}},
        "/**/m*": {"ros__parameters": {"max_vx": 0.4}},
        "mpc_node": {"ros__parameters": {"gait": "walk"}},
        "r1": {"mpc": {"ros__parameters": {"max_vy": 0.2}}}}))
    argv = ["mpc_node", "--ros-args", "--params-file", str(path)]
    notes = unmatched_params_file_sections(argv, "/mpc")
    assert len(notes) == 1 and "['mpc_node', 'r1/mpc']" in notes[0] and "/mpc" in notes[0]
    # namespaced: 'mpc:' is /mpc for rcl, not /r1/mpc
    notes = unmatched_params_file_sections(argv, "/r1/mpc")
    assert len(notes) == 1 and "['mpc', 'mpc_node']" in notes[0]
    assert unmatched_params_file_sections([*argv[:3], str(tmp_path / "none.yaml")],
                                          "/mpc") == []  # unreadable: rcl's to report
    # one file for both nodes: the other node's section is not named (both nodes warned
    # about it); another namespace's still is
    path.write_text(yaml.safe_dump({"mpc": {"ros__parameters": {"gait": "walk"}},
                                    "sim": {"ros__parameters": {"kp": 30.0}},
                                    "r1": {"sim": {"ros__parameters": {"kp": 30.0}}}}))
    for node in ("/mpc", "/sim"):
        notes = unmatched_params_file_sections(argv, node)
        assert len(notes) == 1 and "section(s) ['r1/sim'] match no node" in notes[0]
    assert "['mpc', 'sim']" in unmatched_params_file_sections(argv, "/r1/sim")[0]
    # the node's own default name is no sibling: mpc renamed mpc_left hears of 'mpc:'
    notes = unmatched_params_file_sections(argv, "/mpc_left", default_name="mpc")
    assert "section(s) ['mpc', 'r1/sim']" in notes[0]


def test_node_targeted_parameter_rules_that_match_no_node_are_named():
    """`-r __node:=other -p mpc:gait:=walk`: rcl applies the rule to a node 'mpc' only and
    the gait stayed trot without a word (a params-file section was already named)."""
    from horizon_mpc.nodes.spin import unmatched_parameter_rules

    argv = ["mpc_node", "--ros-args", "-r", "__node:=other", "-p", "mpc:gait:=walk",
            "-p", "other:max_vx:=0.4", "-p", "dt:=0.02", "--param", "/r1/mpc:n_nodes:=20",
            "-p", "/**:use_sim_time:=false", "-p", "w:=a:b"]
    notes = unmatched_parameter_rules(argv, "/other")
    assert len(notes) == 2, notes
    assert "-p mpc:gait:=walk: for the node 'mpc', and this node is /other" in notes[0]
    assert "'gait' is not applied" in notes[0] and "'/r1/mpc'" in notes[1]
    # namespaced: 'mpc:' is /mpc for rcl, not /r1/mpc
    assert [n.split(":")[0] for n in unmatched_parameter_rules(argv, "/r1/mpc")] == [
        "-p mpc", "-p other"]
    # outside --ros-args a -p is no rule of rcl's (named as a stray argument elsewhere)
    assert unmatched_parameter_rules(["mpc_node", "-p", "mpc:gait:=walk"], "/x") == []


def test_state_reliability_best_effort_hears_a_sensor_data_publisher(context, walking_mpc):
    """A driver publishing joint_states/odom with the sensor-data QoS (best effort) never
    reaches a reliable subscription: with state_reliability best_effort it does."""
    from rclpy.qos import qos_profile_sensor_data

    for reliability, heard in (("reliable", False), ("best_effort", True)):
        walking_mpc.t_last = None
        node = MpcNode(parameter_overrides=[Parameter("trigger", value="state"),
                                            Parameter("state_reliability", value=reliability)],
                       mpc=walking_mpc, context=context)
        probe = Node("driver", context=context)
        pub_js = probe.create_publisher(JointState, "joint_states", qos_profile_sensor_data)
        pub_odom = probe.create_publisher(Odometry, "odom", qos_profile_sensor_data)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        executor.add_node(probe)
        try:
            _, q = standing_configuration(walking_mpc.cfg)
            end = time.monotonic() + (5.0 if heard else 1.0)
            while time.monotonic() < end and node._joints is None:
                stamp = time_from_ns(probe.get_clock().now().nanoseconds)
                pub_js.publish(joint_state_to_msg(stamp, node.joint_names, q[7:],
                                                  np.zeros(len(q) - 7)))
                pub_odom.publish(odometry_to_msg(stamp, q[:3], q[3:7], np.zeros(3),
                                                 np.zeros(3)))
                executor.spin_once(timeout_sec=0.02)
            assert (node._joints is not None) == heard, reliability
        finally:
            executor.shutdown()
            node.destroy_node()
            probe.destroy_node()


def test_a_duty_factor_below_the_minimum_is_refused_at_start_up_too(context, walking_mpc):
    """Refused live, it built a gait of near-total flight at start-up."""
    with pytest.raises(ValueError, match="duty_factor 0.01 is below 0.05"):
        sim_time_node(context, walking_mpc, duty_factor=0.01)
    walking_mpc.set_gait("trot")  # the shared fixture
    node = sim_time_node(context, walking_mpc, max_command_norm=3.0)  # > sqrt(3): per axis
    try:
        assert node.mpc.settings.max_command_norm == 3.0
    finally:
        walking_mpc.settings.max_command_norm = math.sqrt(2)
        node.destroy_node()


def test_a_stopped_simulator_is_reported_on_the_wall_clock(context, walking_mpc):
    """sim_node is also the clock: when it stops, sim time stops and no timer tick can see
    the states age; the steady-clock watchdog says so (the node went silent before), in
    the log and on /diagnostics at every look (at the default 10 Hz rate, counted on the
    stopped clock, one WARN went out and then nothing: a viewer started later saw none)."""
    node = sim_time_node(context, walking_mpc)
    try:
        drive_in_sim_time(node, 3)
        skips = node.stale_skips
        node._check_progress()  # states came since the last look: nothing to say
        assert node.stale_skips == skips
        for look in range(1, 4):  # none since: stale, each look
            sent = len(node._pub_diag.msgs)
            node._check_progress()
            assert node.stale_skips == skips + look
            assert len(node._pub_diag.msgs) == sent + 1
            status = node._pub_diag.msgs[-1].status[0]
            assert status.level == DiagnosticStatus.WARN and "stale" in status.message
    finally:
        node.destroy_node()


def test_a_node_waiting_for_its_states_says_so_on_diagnostics(context, walking_mpc):
    """A node with no joint_states / odom yet published nothing on /diagnostics: an
    aggregator could not tell it from a node that is not running (an auditor's). The
    wall-clock watchdog now sends a WARN naming what is missing, every look, and says it
    in the log (throttled): a node on a sim clock that stands, or with trigger 'state',
    never ticked and logged nothing after 'waiting for ...' (an auditor)."""
    node = sim_time_node(context, walking_mpc)
    node._pub_diag = Sent()
    said: list[tuple[str, str]] = []
    node._warn = lambda kind, text: said.append((kind, text))
    try:
        for _ in range(2):
            sent = len(node._pub_diag.msgs)
            node._check_progress()
            assert len(node._pub_diag.msgs) == sent + 1
            status = node._pub_diag.msgs[-1].status[0]
            assert status.level == DiagnosticStatus.WARN
            assert status.message == "waiting for joint_states and odom: not planning"
            assert said[-1] == ("no_state", "no joint_states and no odom received yet; not "
                                            "planning")
        drive_in_sim_time(node, 3)  # planning: the watchdog has nothing to add
        sent = len(node._pub_diag.msgs)
        node._check_progress()
        assert len(node._pub_diag.msgs) == sent
    finally:
        node.destroy_node()


def test_a_remapped_input_is_named_with_its_topic(context, walking_mpc):
    """-r joint_states:=/foo: the node still said it waited for 'joint_states' (an
    auditor, as a ROS user)."""
    for args, said in ((["-r", "joint_states:=/foo"], "joint_states (remapped to /foo)"),
                       (["-r", "joint_states:=/robot2/joint_states"],
                        "joint_states (remapped to /robot2/joint_states)"),
                       (["-r", "__ns:=/robot1"], "joint_states")):  # its own namespace
        walking_mpc.t_last = None
        node = MpcNode(parameter_overrides=[Parameter("trigger", value="state")],
                       mpc=walking_mpc, context=context, cli_args=["--ros-args", *args])
        node._pub_diag = Sent()
        try:
            node._check_progress()
            status = node._pub_diag.msgs[-1].status[0]
            assert status.message == f"waiting for {said} and odom: not planning", args
        finally:
            node.destroy_node()


def test_a_remapped_input_is_named_in_its_rejections(context, walking_mpc):
    """A rejected message of a remapped input named the input only ("rejected
    joint_states"), not the topic it came on."""
    walking_mpc.t_last = None
    node = MpcNode(parameter_overrides=[Parameter("trigger", value="state")],
                   mpc=walking_mpc, context=context,
                   cli_args=["--ros-args", "-r", "joint_states:=/a/js", "-r", "odom:=/a/odom",
                             "-r", "cmd_vel:=/a/cmd"])
    logger = _Logger()
    logged = logger.warnings
    node.get_logger = lambda: logger
    try:
        stamp = time_from_ns(10 * NS_PER_S)
        names = list(node.joint_names)
        node._on_joint_state(joint_state_to_msg(stamp, names[:-1], np.zeros(len(names) - 1),
                                                np.zeros(len(names) - 1)))
        odom = Odometry()
        odom.pose.pose.position.x = math.nan
        node._on_odom(odom)
        twist = Twist()
        twist.linear.x = math.inf
        node._on_cmd_vel(twist)
        assert [text.split(":")[0] for text in logged] == [
            "rejected joint_states (remapped to /a/js)", "rejected odom (remapped to /a/odom)",
            "rejected cmd_vel (remapped to /a/cmd)"], logged
    finally:
        node.destroy_node()


def test_use_sim_time_outside_ros_args_is_no_parameter(walking_mpc):
    """'-p use_sim_time:=false' before --ros-args is ignored by rcl (warned about as a plain
    argument) and must not switch the sim-time default off either."""
    for args, expected in ((["mpc_node", "-p", "use_sim_time:=false"], True),
                           (["mpc_node", "--ros-args", "-p", "use_sim_time:=false"], False)):
        assert _use_sim_time(walking_mpc, args) is expected, args


class _Logger:
    """Stands in for a node's logger: keeps the warnings."""

    def __init__(self) -> None:
        self.warnings: list[str] = []

    def warning(self, text: str) -> None:
        self.warnings.append(text)

    def info(self, text: str) -> None:
        pass


def _feed_layout(node, q: np.ndarray, k: int, extra_joint: str,
                 children: tuple[str, ...]) -> None:
    """State k (20 ms apart) of a standing robot: a JointState with one joint the model lacks,
    and an Odometry per child frame name."""
    stamp = time_from_ns(10 * NS_PER_S + k * 20_000_000)
    node._on_joint_state(joint_state_to_msg(stamp, [*node.joint_names, extra_joint],
                                            np.append(q[7:], 0.0), np.zeros(len(q) - 6)))
    for child in children:
        odom = odometry_to_msg(stamp, q[:3], q[3:7], np.zeros(3), np.zeros(3))
        odom.child_frame_id = child
        node._on_odom(odom)


@pytest.fixture
def logged_node(context, walking_mpc, monkeypatch):
    """A sim-time node whose warnings are kept, and the standing configuration."""
    node = sim_time_node(context, walking_mpc)
    log = _Logger()
    monkeypatch.setattr(node, "get_logger", lambda: log)
    _, q = standing_configuration(walking_mpc.cfg)
    try:
        yield node, log, q
    finally:
        node.destroy_node()


def test_a_publishers_fixed_layout_is_said_once_repairs_stay_throttled(logged_node):
    """A robot with a gripper sends two joints the model lacks in every JointState: the
    note came every 2 s for as long as it ran (844 suppressed in a reviewer's run). Said
    once; so is an odometry child frame that is not the base link (its twist is taken as
    the base's), while the base link and an empty one are not."""
    node, log, q = logged_node
    for k in range(3):
        _feed_layout(node, q, k, "gripper_finger", ("imu_link", "base", ""))
        node._last_warn.clear()  # as if the throttle period had passed
    extra = [w for w in log.warnings if "gripper_finger" in w]
    frames = [w for w in log.warnings if "child_frame_id" in w]
    assert len(extra) == 1 and "said once" in extra[0], log.warnings
    assert len(frames) == 1 and "'imu_link'" in frames[0] and "base" in frames[0]


def test_a_layout_that_changes_per_message_is_throttled_and_its_names_clipped(logged_node):
    """Extra joint names and odometry child frames that change from message to message made
    one 'said once' line each (757 lines in 2 s in an auditor's run, and a key kept per
    message); 200 000 extra names made one 2 MB line. Past ONCE_KEYS different ones the
    kind is throttled, and a note lists NAMES_SHOWN names."""
    from horizon_mpc.nodes.mpc_inputs import NAMES_SHOWN
    from horizon_mpc.nodes.mpc_node import ONCE_KEYS

    node, log, q = logged_node
    for k in range(50):
        _feed_layout(node, q, k, f"grip_{k}", (f"imu_{k}",))
    extra = [w for w in log.warnings if "grip_" in w]
    frames = [w for w in log.warnings if "child_frame_id" in w]
    # ONCE_KEYS said once, then one throttled line (no wall time passed)
    assert len(extra) == len(frames) == ONCE_KEYS + 1, log.warnings
    assert "throttled" in extra[-1] and "throttled" in frames[-1]
    assert sum(len(v) for v in node._said_once.values()) == 2 * ONCE_KEYS
    many = [f"j{i:06d}_" + "x" * 100 for i in range(200_000)]
    for k in range(2):  # the second after the throttle period, as it were
        node._last_warn.clear()
        node._on_joint_state(joint_state_to_msg(
            time_from_ns(12 * NS_PER_S + k * 20_000_000), [*node.joint_names, *many],
            np.append(q[7:], np.zeros(len(many))), np.zeros(len(q) - 7 + len(many))))
    line = log.warnings[-1]
    assert f"and {len(many) - NAMES_SHOWN} more" in line and len(line) < 2000, line[:300]
    assert node.rejected["joint_states"] == 0


@pytest.mark.parametrize("reliability", ["best_effort", "reliable"])
def test_cmd_vel_from_a_best_effort_publisher_is_heard_by_default_else_named(
        context, walking_mpc, monkeypatch, reliability):
    """A joystick driver publishing cmd_vel best effort never reached the reliable
    subscription: the robot stood, diagnostics OK (an auditor's). By default the
    subscription is best effort (hears both kinds); set to reliable, the mismatch is named
    with the parameter to change."""
    from rclpy.qos import qos_profile_sensor_data

    node = sim_time_node(context, walking_mpc, cmd_reliability=reliability)
    log = _Logger()
    monkeypatch.setattr(node, "get_logger", lambda: log)
    joystick = Node("joystick", context=context)
    pub = joystick.create_publisher(Twist, "cmd_vel", qos_profile_sensor_data)
    msg = Twist()
    msg.linear.x = 0.2
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(joystick)
    try:
        end = time.monotonic() + (5.0 if reliability == "best_effort" else 1.5)
        while time.monotonic() < end and node._cmd is None:
            pub.publish(msg)
            executor.spin_once(timeout_sec=0.02)
        assert (node._cmd is not None) == (reliability == "best_effort")
        node._check_input_types()
        warned = [w for w in log.warnings if "best effort" in w]
        if reliability == "reliable":
            assert len(warned) == 1 and "-p cmd_reliability:=best_effort" in warned[0]
        else:
            assert not warned
    finally:
        executor.shutdown()
        joystick.destroy_node()
        node.destroy_node()


def test_a_second_clock_publisher_is_named(context, walking_mpc, monkeypatch):
    """Two simulators on one /clock (two robots, /clock not remapped): the node's warnings
    blamed a simulator reset, old states or use_sim_time (an auditor's two-robot graph)."""
    from rosgraph_msgs.msg import Clock

    node = sim_time_node(context, walking_mpc)
    log = _Logger()
    monkeypatch.setattr(node, "get_logger", lambda: log)
    # a restarted simulator: its dead participant stays listed for its DDS lease, under
    # the same name as the new one (a review's: '/sim, /sim' for ~16 s): said only if it
    # lasts
    restarted = [Node("sim", context=context) for _ in range(2)]
    sims = [Node(f"sim{k}", namespace=f"/r{k}", context=context) for k in (1, 2)]

    def check_until_warned(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not log.warnings:
            node._check_input_types()
            time.sleep(0.05)

    try:
        for sim in restarted:
            sim.create_publisher(Clock, "/clock", 10)
        check_until_warned(2.0)
        assert not log.warnings
        monkeypatch.setattr(mpc_node, "CLOCK_PUBLISHERS_FOR", 0.0)
        check_until_warned(5.0)
        assert len(log.warnings) == 1 and "/clock has 2 publishers (/sim, /sim)" in \
            log.warnings[0], log.warnings
        for sim in restarted:
            sim.destroy_node()
        restarted.clear()
        log.warnings.clear()
        # two robots' simulators: said at once
        monkeypatch.setattr(mpc_node, "CLOCK_PUBLISHERS_FOR", 1e9)
        sims[0].create_publisher(Clock, "/clock", 10)
        node._check_input_types()
        assert not log.warnings  # one simulator: fine
        sims[1].create_publisher(Clock, "/clock", 10)
        end = time.monotonic() + 5.0
        while time.monotonic() < end and not any("/r2/sim2" in w for w in log.warnings):
            node._check_input_types()
            time.sleep(0.05)
        node._check_input_types()
        assert len(log.warnings) == 1, log.warnings
        assert "/clock has 2 publishers (/r1/sim1, /r2/sim2)" in log.warnings[0]
        assert "-r /clock:=/<namespace>/clock" in log.warnings[0]
    finally:
        for sim in restarted + sims:
            sim.destroy_node()
        node.destroy_node()


def test_a_publisher_of_another_type_on_an_input_is_named(context, walking_mpc, monkeypatch):
    """A TwistStamped on cmd_vel (Jazzy's teleop and nav2 can send those) never connects
    to the node's Twist subscription: the robot stood and nothing said why."""
    from geometry_msgs.msg import TwistStamped

    node = sim_time_node(context, walking_mpc)
    log = _Logger()
    monkeypatch.setattr(node, "get_logger", lambda: log)
    # a process of its own, as a teleop is (one DDS participant refuses a second type on
    # a topic outright)
    other = rclpy.Context()
    rclpy.init(context=other)
    teleop = Node("teleop", context=other)
    try:
        teleop.create_publisher(TwistStamped, "cmd_vel", 10)
        end = time.monotonic() + 5.0
        while time.monotonic() < end and not log.warnings:
            node._check_input_types()
            time.sleep(0.05)
        for _ in range(3):
            node._check_input_types()
        assert len(log.warnings) == 1, log.warnings
        assert "/cmd_vel: " in log.warnings[0]  # the node's name, if discovered by then
        assert (" publishes geometry_msgs/msg/TwistStamped, this node subscribes "
                "geometry_msgs/msg/Twist") in log.warnings[0]
    finally:
        teleop.destroy_node()
        rclpy.try_shutdown(context=other)
        node.destroy_node()


def test_a_weight_whose_default_is_zero_is_not_compared_with_it(monkeypatch):
    """A term switched off by default (the natural way to add one) has no walked scale: its
    weight 5 was 'up to 5e+300x its library default' at every start (an extender's audit)."""
    from dataclasses import dataclass

    from horizon_mpc.locomotion.settings import Weights
    from horizon_mpc.nodes import mpc_parameters

    @dataclass
    class WithAnOffTerm(Weights):
        base_yaw: float = 0.0

    monkeypatch.setattr(mpc_parameters, "Weights", WithAnOffTerm)
    assert mpc_parameters.weight_warnings(WithAnOffTerm(base_yaw=5.0)) == []
    heavy = mpc_parameters.weight_warnings(WithAnOffTerm(posture=3e3))  # still compared
    assert len(heavy) == 1 and heavy[0].startswith("w_posture 3000 is up to 1e+04x")
