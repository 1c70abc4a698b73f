"""ROS message <-> numpy conversions shared by the horizon_mpc nodes.

Conventions (``doc/simulator.md``): quaternions are numpy ``(x, y, z, w)``; times are sim
(or ROS) seconds as float, or exact integer nanoseconds where stamps are compared; joint
arrays follow the order of the ``joint_names`` argument (the Pinocchio model order), messages
are matched BY NAME. ``nav_msgs/Odometry`` carries the pose in ``header.frame_id`` (the world,
``odom``) and the twist in ``child_frame_id`` (the BASE frame), as REP 105 says.

Functions raise ``ValueError`` with a message naming the problem on malformed input; they
never trust message array lengths.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Quaternion, Vector3
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from horizon_mpc.sim.trajectory import JointTrajectoryCommand

__all__ = [
    "NS_PER_S",
    "duration_from_seconds",
    "joint_state_from_msg",
    "joint_state_to_msg",
    "joint_trajectory_from_msg",
    "joint_trajectory_to_msg",
    "odometry_from_msg",
    "odometry_to_msg",
    "quaternion_from_msg",
    "quaternion_to_msg",
    "seconds_from_duration",
    "seconds_from_time",
    "state_from_msgs",
    "time_from_ns",
    "time_from_seconds",
    "time_to_ns",
    "vector3_from_msg",
    "vector3_to_msg",
]

NS_PER_S = 1_000_000_000


# ---------------------------------------------------------------------- time
def time_from_ns(ns: int) -> Time:
    """``builtin_interfaces/Time`` of ``ns`` nanoseconds (>= 0)."""
    ns = int(ns)
    if ns < 0:
        raise ValueError(f"negative time {ns} ns")
    return Time(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def time_to_ns(stamp: Time) -> int:
    """Exact nanoseconds of a ``builtin_interfaces/Time`` (compare stamps with this)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def time_from_seconds(t: float) -> Time:
    """``builtin_interfaces/Time`` of ``t`` seconds (rounded to the nanosecond)."""
    return time_from_ns(round(t * NS_PER_S))


def seconds_from_time(stamp: Time) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return time_to_ns(stamp) / NS_PER_S


def duration_from_seconds(t: float) -> Duration:
    """``builtin_interfaces/Duration`` of ``t`` seconds (t may be negative)."""
    ns = round(t * NS_PER_S)
    return Duration(sec=ns // NS_PER_S, nanosec=ns % NS_PER_S)


def seconds_from_duration(d: Duration) -> float:
    """Seconds of a ``builtin_interfaces/Duration``."""
    return (int(d.sec) * NS_PER_S + int(d.nanosec)) / NS_PER_S


# ---------------------------------------------------------------------- geometry
def quaternion_to_msg(quat: Sequence[float]) -> Quaternion:
    """``geometry_msgs/Quaternion`` of a numpy ``(x, y, z, w)`` quaternion."""
    x, y, z, w = (float(c) for c in quat)
    return Quaternion(x=x, y=y, z=z, w=w)


def quaternion_from_msg(msg: Quaternion) -> np.ndarray:
    """(4,) ``(x, y, z, w)`` of a ``geometry_msgs/Quaternion``, normalised.

    Raises:
        ValueError: zero or non-finite quaternion.
    """
    quat = np.array([msg.x, msg.y, msg.z, msg.w], dtype=float)
    norm = np.linalg.norm(quat)
    if not np.isfinite(norm) or norm < 1e-9:
        raise ValueError(f"invalid quaternion {quat}")
    return quat / norm


def vector3_to_msg(vec: Sequence[float]) -> Vector3:
    """``geometry_msgs/Vector3`` of a (3,) array."""
    x, y, z = (float(c) for c in vec)
    return Vector3(x=x, y=y, z=z)


def vector3_from_msg(msg: Vector3) -> np.ndarray:
    """(3,) array of a ``geometry_msgs/Vector3`` (or Point)."""
    return np.array([msg.x, msg.y, msg.z], dtype=float)


# ---------------------------------------------------------------------- joint states
def joint_state_to_msg(
    stamp: Time,
    joint_names: Sequence[str],
    positions: np.ndarray,
    velocities: np.ndarray | None = None,
    efforts: np.ndarray | None = None,
) -> JointState:
    """``sensor_msgs/JointState``; arrays (nj,) in the order of ``joint_names``."""
    msg = JointState()
    msg.header.stamp = stamp
    msg.name = list(joint_names)
    msg.position = np.asarray(positions, dtype=float).tolist()
    if velocities is not None:
        msg.velocity = np.asarray(velocities, dtype=float).tolist()
    if efforts is not None:
        msg.effort = np.asarray(efforts, dtype=float).tolist()
    return msg


def joint_state_from_msg(
    msg: JointState, joint_names: Sequence[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, velocities, efforts (each (nj,)) of ``joint_names``, matched by name.

    Missing velocity/effort arrays give zeros. Extra joints in the message are ignored.

    Raises:
        ValueError: a joint is missing, or an array length does not match ``msg.name``.
    """
    names = list(msg.name)
    index = {n: i for i, n in enumerate(names)}
    missing = [n for n in joint_names if n not in index]
    if missing:
        raise ValueError(f"JointState lacks joints {missing}")
    idx = [index[n] for n in joint_names]
    out = []
    for field in ("position", "velocity", "effort"):
        arr = np.asarray(getattr(msg, field), dtype=float)
        if arr.size == 0 and field != "position":
            out.append(np.zeros(len(idx)))
            continue
        if arr.shape != (len(names),):
            raise ValueError(f"JointState.{field} has {arr.size} values for {len(names)} names")
        out.append(arr[idx])
    return out[0], out[1], out[2]


# ---------------------------------------------------------------------- odometry
def odometry_to_msg(
    stamp: Time,
    position: np.ndarray,
    quaternion: np.ndarray,
    linear_velocity: np.ndarray,
    angular_velocity: np.ndarray,
    frame_id: str = "odom",
    child_frame_id: str = "base",
) -> Odometry:
    """``nav_msgs/Odometry``: base pose in ``frame_id``, base twist in the BASE frame.

    Args:
        position: (3,) base origin in the world (m).
        quaternion: (4,) base orientation ``(x, y, z, w)``.
        linear_velocity: (3,) base origin velocity in the base frame (m/s).
        angular_velocity: (3,) base angular velocity in the base frame (rad/s).
    """
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    x, y, z = (float(c) for c in position)
    msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = x, y, z
    msg.pose.pose.orientation = quaternion_to_msg(quaternion)
    msg.twist.twist.linear = vector3_to_msg(linear_velocity)
    msg.twist.twist.angular = vector3_to_msg(angular_velocity)
    return msg


def odometry_from_msg(msg: Odometry) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(position (3,), quaternion (4,), linear velocity (3,), angular velocity (3,))``.

    Velocities are as carried by the message: in ``child_frame_id`` (the base frame).
    """
    return (
        vector3_from_msg(msg.pose.pose.position),
        quaternion_from_msg(msg.pose.pose.orientation),
        vector3_from_msg(msg.twist.twist.linear),
        vector3_from_msg(msg.twist.twist.angular),
    )


def state_from_msgs(
    joint_state: JointState, odom: Odometry, joint_names: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Pinocchio ``(q, v)`` from a JointState and an Odometry.

    ``q = [base position, base quaternion (x, y, z, w), joint positions]`` (7 + nj,) and
    ``v = [base linear velocity, base angular velocity (both base frame), joint velocities]``
    (6 + nj,), joints in the order of ``joint_names``. (Models with continuous joints store
    (cos, sin) in q: convert those entries yourself.)
    """
    qj, vj, _ = joint_state_from_msg(joint_state, joint_names)
    pos, quat, lin, ang = odometry_from_msg(odom)
    return np.concatenate((pos, quat, qj)), np.concatenate((lin, ang, vj))


# ---------------------------------------------------------------------- trajectories
def joint_trajectory_to_msg(
    cmd: JointTrajectoryCommand, stamp: Time | None = None
) -> JointTrajectory:
    """``trajectory_msgs/JointTrajectory`` of a command.

    ``header.stamp`` is ``stamp`` if given, else ``cmd.t0``; ``time_from_start`` of point k is
    ``cmd.times[k]``.
    """
    msg = JointTrajectory()
    msg.header.stamp = stamp if stamp is not None else time_from_seconds(cmd.t0)
    msg.joint_names = list(cmd.joint_names)
    positions = np.asarray(cmd.positions, dtype=float)
    velocities = None if cmd.velocities is None else np.asarray(cmd.velocities, dtype=float)
    efforts = None if cmd.efforts is None else np.asarray(cmd.efforts, dtype=float)
    for k, t in enumerate(np.asarray(cmd.times, dtype=float)):
        point = JointTrajectoryPoint()
        point.positions = positions[k].tolist()
        if velocities is not None:
            point.velocities = velocities[k].tolist()
        if efforts is not None:
            point.effort = efforts[k].tolist()
        point.time_from_start = duration_from_seconds(float(t))
        msg.points.append(point)
    return msg


def _point_field(msg: JointTrajectory, field: str, nj: int, required: bool) -> np.ndarray | None:
    rows = [list(getattr(pt, field)) for pt in msg.points]
    lengths = {len(r) for r in rows}
    if lengths == {0} and not required:
        return None  # ROS: an empty array means "not given"
    for k, row in enumerate(rows):
        if len(row) != nj:
            raise ValueError(
                f"point {k} has {len(row)} {field} for {nj} joints"
                + ("" if required else f" (give {field} for every point or for none)")
            )
    return np.array(rows, dtype=float).reshape(len(rows), nj)


def joint_trajectory_from_msg(msg: JointTrajectory, now: float) -> JointTrajectoryCommand:
    """The command carried by a ``trajectory_msgs/JointTrajectory``.

    A zero ``header.stamp`` means "now" (``t0 = now``, sim seconds). Accelerations are ignored.
    The result is NOT validated against a robot: call :meth:`JointTrajectoryCommand.validate`.

    Raises:
        ValueError: no points, or an array length that does not match ``joint_names``.
    """
    stamp_ns = time_to_ns(msg.header.stamp)
    t0 = now if stamp_ns == 0 else stamp_ns / NS_PER_S
    if not msg.points:
        raise ValueError("the trajectory has no points")
    nj = len(msg.joint_names)
    times = np.array([seconds_from_duration(pt.time_from_start) for pt in msg.points])
    positions = _point_field(msg, "positions", nj, required=True)
    velocities = _point_field(msg, "velocities", nj, required=False)
    efforts = _point_field(msg, "effort", nj, required=False)
    if not math.isfinite(t0):
        raise ValueError(f"invalid stamp {t0}")
    return JointTrajectoryCommand(list(msg.joint_names), t0, times, positions, velocities, efforts)
