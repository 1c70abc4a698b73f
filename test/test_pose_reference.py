"""The base pose reference of a velocity command (horizon_mpc.locomotion.pose_reference)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from horizon_mpc.locomotion.pose_reference import (
    advance_pose,
    base_yaw,
    horizon_poses,
    wrap_angle,
)
from horizon_mpc.sim.rotations import quat_from_yaw


def _q(x: float, y: float, yaw: float) -> np.ndarray:
    return np.concatenate(([x, y, 0.3], quat_from_yaw(yaw), np.zeros(12)))


def _euler(pose, cmd, t: float, steps: int = 200_000) -> np.ndarray:
    x, y, yaw = pose
    vx, vy, wz = cmd
    h = t / steps
    for _ in range(steps):
        c, s = math.cos(yaw), math.sin(yaw)
        x, y, yaw = x + h * (c * vx - s * vy), y + h * (s * vx + c * vy), yaw + h * wz
    return np.array([x, y, yaw])


@pytest.mark.parametrize("cmd", [(0.3, -0.2, 0.8), (0.4, 0.1, 0.0), (0.0, 0.0, -0.5)])
def test_horizon_poses_integrate_the_constant_twist_exactly(cmd):
    pose = (1.0, -2.0, 2.9)
    poses = horizon_poses(pose, cmd, 10, 0.05)
    assert poses.shape == (4, 11)
    np.testing.assert_allclose(poses[:, 0], [1.0, -2.0, math.cos(2.9), math.sin(2.9)])
    end = _euler(pose, cmd, 0.5)
    np.testing.assert_allclose(poses[:2, -1], end[:2], atol=1e-5)
    np.testing.assert_allclose(poses[2:, -1], [math.cos(end[2]), math.sin(end[2])], atol=1e-5)


def test_advance_pose_moves_along_the_command_in_the_reference_heading():
    pose = advance_pose((0.0, 0.0, math.pi / 2), (0.5, 0.0, 1.0), _q(0, 0, math.pi / 2), 0.1,
                        leash=1.0, yaw_leash=1.0)
    np.testing.assert_allclose(pose, [0.0, 0.05, math.pi / 2 + 0.1], atol=1e-12)


def test_advance_pose_stays_within_the_leash_of_the_measured_pose():
    # the robot is stuck at the origin, facing +x, while the reference runs ahead and turns
    pose, q = np.zeros(3), _q(0.0, 0.0, 0.0)
    for _ in range(500):
        pose = advance_pose(pose, (0.6, 0.0, 0.8), q, 0.02, leash=0.4, yaw_leash=0.3)
    assert math.hypot(pose[0], pose[1]) == pytest.approx(0.4)
    assert pose[2] == pytest.approx(0.3)


def test_the_yaw_leash_measures_across_the_angle_wrap():
    # measured yaw just below pi, reference just past it (-pi + 0.05): 0.1 rad apart, not 6.18
    pose = advance_pose((0.0, 0.0, -math.pi + 0.05), (0.0, 0.0, 0.0), _q(0, 0, math.pi - 0.05),
                        0.02, leash=0.4, yaw_leash=0.3)
    assert wrap_angle(pose[2] - (-math.pi + 0.05)) == pytest.approx(0.0, abs=1e-12)


def test_base_yaw_reads_any_norm_of_the_quaternion():
    q = _q(0, 0, -2.0)
    q[3:7] *= 3.0
    assert base_yaw(q) == pytest.approx(-2.0)
