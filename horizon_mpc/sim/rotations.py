"""Quaternion and rigid-transform helpers in the project's conventions.

Quaternions are ``(x, y, z, w)`` (Pinocchio's ``q[3:7]``, pybullet's and ROS's order) and
unit-norm; rotation matrices map body-frame vectors to the world frame.
Plain numpy on purpose: these run a few times per published state, not per physics step.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "quat_conjugate",
    "quat_from_yaw",
    "quat_multiply",
    "quat_to_matrix",
    "quat_yaw",
    "transform_inverse",
    "transform_multiply",
]


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of the quaternion ``(x, y, z, w)`` (normalised here)."""
    x, y, z, w = np.asarray(quat, dtype=float) / np.linalg.norm(quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` of two ``(x, y, z, w)`` quaternions (rotation a after b)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def quat_conjugate(quat: np.ndarray) -> np.ndarray:
    """Inverse rotation of a unit quaternion ``(x, y, z, w)``."""
    x, y, z, w = quat
    return np.array([-x, -y, -z, w])


def quat_from_yaw(yaw: float) -> np.ndarray:
    """Quaternion ``(x, y, z, w)`` of a rotation by ``yaw`` (rad) about the world z axis."""
    return np.array([0.0, 0.0, np.sin(0.5 * yaw), np.cos(0.5 * yaw)])


def quat_yaw(quat: np.ndarray) -> float:
    """Yaw (rad, in (-pi, pi]) of the quaternion ``(x, y, z, w)`` of any norm (ZYX Euler
    convention); plain floats (the MPC calls it every tick)."""
    x, y, z, w = np.asarray(quat, dtype=float).tolist()
    return math.atan2(2.0 * (w * z + x * y), w * w + x * x - y * y - z * z)


def transform_multiply(
    pos_a: np.ndarray, quat_a: np.ndarray, pos_b: np.ndarray, quat_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Compose rigid transforms: ``T_a * T_b`` as ``(position (3,), quaternion (4,))``."""
    pos = np.asarray(pos_a, dtype=float) + quat_to_matrix(quat_a) @ np.asarray(pos_b, dtype=float)
    return pos, quat_multiply(quat_a, quat_b)


def transform_inverse(pos: np.ndarray, quat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse rigid transform ``T^-1`` as ``(position (3,), quaternion (4,))``."""
    conj = quat_conjugate(quat)
    return -(quat_to_matrix(conj) @ np.asarray(pos, dtype=float)), conj
