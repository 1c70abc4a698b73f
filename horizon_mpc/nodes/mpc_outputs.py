"""The MPC node's output messages: pure functions of a plan, no DDS needed.

Built for the tick's hot path (``doc/mpc_node.md``, Measured): joint arrays go into messages
as ``array.array`` (the fastest type rclpy takes for ``sequence<double>``), and the messages
(trajectory, path, diagnostics) are refilled in place rather than rebuilt.
Conventions as in :mod:`horizon_mpc.nodes.conversions`.
"""

from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Path
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from horizon_mpc.mpc.controller import Plan
from horizon_mpc.nodes.conversions import NS_PER_S, duration_from_seconds

__all__ = ["DiagnosticsMessage", "due", "fill_path", "fill_trajectory", "period_ns",
           "set_stamp"]


def fill_trajectory(msg: JointTrajectory, plan: Plan, joint_names: list[str], n: int,
                    stamp_ns: int) -> JointTrajectory:
    """``msg`` refilled in place with nodes 0..n-1 of ``plan`` (joints in model order),
    ``time_from_start = k dt``; its points are created when their number or the joints
    change only (go2, 6 points: ~48 us to build anew, ~38 to refill; best of 5 x 200).

    Efforts are ``plan.tau_head(n)[6:]``: the inverse dynamics of these nodes only. Copy the
    message to keep it past the next call.
    """
    n = min(n, plan.a.shape[1])
    nj = len(joint_names)
    if len(msg.points) != n or list(msg.joint_names) != list(joint_names):
        msg.joint_names = list(joint_names)
        msg.points = [JointTrajectoryPoint(**{f: array.array("d", bytes(8 * nj))
                                              for f in _POINT_FIELDS}) for _ in range(n)]
    set_stamp(msg.header.stamp, stamp_ns)
    # one C-ordered (4, n, nj) block: each point's field is one row of it, copied into the
    # point's array in place
    rows = np.stack((plan.q[7:, :n].T, plan.v[6:, :n].T, plan.a[6:, :n].T,
                     plan.tau_head(n)[6:].T))
    for k, pt in enumerate(msg.points):
        for f, field in enumerate(_POINT_FIELDS):
            np.frombuffer(getattr(pt, field), np.float64)[:] = rows[f, k]
        d = duration_from_seconds(k * plan.dt)
        pt.time_from_start.sec, pt.time_from_start.nanosec = d.sec, d.nanosec
    return msg


_POINT_FIELDS = ("positions", "velocities", "accelerations", "effort")


def fill_path(msg: Path, plan: Plan, stamp_ns: int, frame_id: str = "odom") -> Path:
    """``msg`` refilled in place with the planned base pose of every node of ``plan``
    (node k stamped ``stamp_ns + k dt``); its poses are created on the first call only
    (building 41 poses anew costs ~0.4 ms a tick)."""
    n = plan.q.shape[1]
    if len(msg.poses) != n:
        msg.poses = [PoseStamped() for _ in range(n)]
    if msg.header.frame_id != frame_id or (msg.poses and msg.poses[0].header.frame_id
                                           != frame_id):
        msg.header.frame_id = frame_id
        for ps in msg.poses:
            ps.header.frame_id = frame_id
    set_stamp(msg.header.stamp, stamp_ns)
    for k, (ps, pose) in enumerate(zip(msg.poses, plan.q[:7].T.tolist(), strict=True)):
        set_stamp(ps.header.stamp, stamp_ns + round(k * plan.dt * NS_PER_S))
        p, o = ps.pose.position, ps.pose.orientation
        p.x, p.y, p.z, o.x, o.y, o.z, o.w = pose
    return msg


class DiagnosticsMessage:
    """One DiagnosticArray with one status (``name``, ``hardware_id``), refilled in place
    (its KeyValues too while the keys stay the same): copy it to keep it past the next
    :meth:`filled`."""

    def __init__(self, name: str, hardware_id: str) -> None:
        self.status = DiagnosticStatus(name=name, hardware_id=hardware_id)
        self.msg = DiagnosticArray(status=[self.status])

    def filled(self, stamp_ns: int, level: bytes, message: str,
               values: dict[str, object]) -> DiagnosticArray:
        """The message with this stamp, level, message and ``str()`` of each value."""
        set_stamp(self.msg.header.stamp, stamp_ns)
        self.status.level, self.status.message = level, message
        kvs = self.status.values
        if len(kvs) == len(values) and all(kv.key == k for kv, k in zip(kvs, values,
                                                                         strict=True)):
            # the same keys as last time (every tick): refill the values in place (building
            # ~16 KeyValue messages anew costs ~0.2 ms a tick)
            for kv, v in zip(kvs, values.values(), strict=True):
                kv.value = str(v)
        else:
            self.status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return self.msg


def period_ns(rate: float) -> int:
    """The period (ns) of a publication rate (Hz); 0 (every tick) for a rate of 0."""
    return round(NS_PER_S / rate) if rate > 0 else 0


def due(last_ns: int | None, period: int, now_ns: int) -> bool:
    """Whether a publication of period ``period`` (ns) last sent at ``last_ns`` is due at
    ``now_ns``. A tick a tenth of a period early still counts (a 10 Hz path is then every
    fifth 50 Hz tick despite timer jitter); a clock that went back (a restarted simulator)
    makes it due."""
    if last_ns is None or now_ns < last_ns:
        return True
    return now_ns - last_ns >= period - period // 10


def set_stamp(stamp: Time, ns: int) -> None:
    """Set a ``builtin_interfaces/Time`` in place to ``ns`` (as :func:`time_from_ns`)."""
    stamp.sec, stamp.nanosec = divmod(int(ns), NS_PER_S)
