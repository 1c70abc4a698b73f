"""The base pose reference of a velocity command: the planar pose ``(x, y, yaw)`` integrated
along the command, and its values on the horizon nodes.

Integrating the command from where the reference was (not from the measured pose) is the
integral action of velocity tracking: a robot that lags falls behind its reference, and the
pose cost pulls it back to the commanded speed. The reference is kept within a leash of the
measured pose so that it never winds up (a blocked robot is not asked to sprint later).
Plain floats: called once per MPC tick, where numpy's per-call overhead dominates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from horizon_mpc.sim.rotations import quat_yaw

__all__ = ["advance_pose", "base_yaw", "horizon_poses", "wrap_angle"]


def base_yaw(q: np.ndarray) -> float:
    """Yaw (rad) of the base quaternion ``q[3:7]`` (x, y, z, w; any norm)."""
    return quat_yaw(q[3:7])


def wrap_angle(a: float) -> float:
    """``a`` wrapped into [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def advance_pose(pose: Sequence[float], cmd: Sequence[float], q: np.ndarray, dt: float,
                 leash: float, yaw_leash: float) -> np.ndarray:
    """The reference pose ``(x, y, yaw)`` after ``dt`` s of the base-frame command ``cmd =
    (vx, vy, wz)`` (one Euler step in the plane), then pulled within ``leash`` (m) and
    ``yaw_leash`` (rad) of the measured pose ``q`` (nq,). Returns shape (3,)."""
    x, y, yaw = (float(p) for p in pose)
    vx, vy, wz = (float(c) for c in cmd)
    qx, qy = float(q[0]), float(q[1])
    c, s = math.cos(yaw), math.sin(yaw)
    x, y, yaw = x + dt * (c * vx - s * vy), y + dt * (s * vx + c * vy), yaw + dt * wz
    dist = math.hypot(x - qx, y - qy)
    if dist > leash:
        x, y = qx + (x - qx) * leash / dist, qy + (y - qy) * leash / dist
    yaw_q = base_yaw(q)
    yaw = yaw_q + min(max(wrap_angle(yaw - yaw_q), -yaw_leash), yaw_leash)
    return np.array([x, y, yaw])


def horizon_poses(pose: Sequence[float], cmd: Sequence[float], n_nodes: int,
                  dt: float) -> np.ndarray:
    """``(x, y, cos yaw, sin yaw)`` on nodes ``k = 0..n_nodes`` (t = k dt) of the constant
    base-frame command ``cmd = (vx, vy, wz)`` from ``pose = (x, y, yaw)`` (the exact
    integration of a constant planar twist). Shape (4, n_nodes + 1)."""
    x0, y0, yaw0 = (float(p) for p in pose)
    vx, vy, wz = (float(c) for c in cmd)
    k = np.arange(n_nodes + 1) * dt
    yaw = yaw0 + wz * k
    if abs(wz) > 1e-6:
        sx = (np.sin(yaw) - math.sin(yaw0)) / wz
        cx = (math.cos(yaw0) - np.cos(yaw)) / wz
        px, py = x0 + vx * sx - vy * cx, y0 + vx * cx + vy * sx
    else:
        c, s = math.cos(yaw0), math.sin(yaw0)
        px, py = x0 + k * (c * vx - s * vy), y0 + k * (s * vx + c * vy)
    return np.vstack([px, py, np.cos(yaw), np.sin(yaw)])
