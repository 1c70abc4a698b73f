"""The MPC node's output messages: pure functions of a plan, no DDS needed.

Built for the tick's hot path (``doc/mpc_node.md``, Measured): joint arrays go into messages
as ``array.array`` (the fastest type rclpy takes for ``sequence<double>``), and the messages
published at a lower rate (path, diagnostics) are refilled in place rather than rebuilt.
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
from horizon_mpc.nodes.conversions import NS_PER_S, duration_from_seconds, time_from_ns

__all__ = ["DiagnosticsMessage", "due", "fill_path", "period_ns", "set_stamp",
           "trajectory_from_plan"]


def trajectory_from_plan(plan: Plan, joint_names: list[str], n: int,
                         stamp_ns: int) -> JointTrajectory:
    """Nodes 0..n-1 of ``plan`` (joints in model order), ``time_from_start = k dt``.

    Efforts are ``plan.tau_head(n)[6:]``: the inverse dynamics of these nodes only.
    """
    msg = JointTrajectory()
    msg.header.stamp = time_from_ns(stamp_ns)
    msg.joint_names = joint_names
    n = min(n, plan.a.shape[1])
    # one C-ordered (4, n, nj) block: each point's field is one row of it
    rows = np.stack((plan.q[7:, :n].T, plan.v[6:, :n].T, plan.a[6:, :n].T,
                     plan.tau_head(n)[6:].T))
    points = []
    for k in range(n):
        pt = JointTrajectoryPoint()
        pt.positions = array.array("d", rows[0, k].tobytes())
        pt.velocities = array.array("d", rows[1, k].tobytes())
        pt.accelerations = array.array("d", rows[2, k].tobytes())
        pt.effort = array.array("d", rows[3, k].tobytes())
        pt.time_from_start = duration_from_seconds(k * plan.dt)
        points.append(pt)
    msg.points = points
    return msg


def fill_path(msg: Path, plan: Plan, stamp_ns: int, frame_id: str = "odom") -> Path:
    """``msg`` refilled in place with the planned base pose of every node of ``plan``
    (node k stamped ``stamp_ns + k dt``); its poses are created on the first call only
    (building 41 poses anew costs ~0.4 ms a tick)."""
    n = plan.q.shape[1]
    if len(msg.poses) != n:
        msg.header.frame_id = frame_id
        msg.poses = [PoseStamped() for _ in range(n)]
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
