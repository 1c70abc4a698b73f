"""The solution of a motion, in one container that every output and check reads."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["MotionResult"]


@dataclass
class MotionResult:
    """A solved motion (trajectories on nodes ``t = k dt``).

    Attributes:
        motion: ``'leap'``, ``'turn'`` or ``'walk'``.
        robot: robot config name.
        solver: solver name.
        feet: contact frame names (order of ``f`` and ``stance``).
        joint_names: the model's joints, in the order of ``q[7:]`` (``v[6:]``, ``tau[6:]``).
        dt: node spacing (s).
        q: (nq, N+1) configurations; v: (nv, N+1) velocities.
        a: (nv, N) accelerations; f: (3 n_feet, N) contact forces (world axes, N).
        tau: (nv, N) inverse dynamics of (q, v, a, f); ``tau[6:]`` joint torques (N m).
        stance: (n_feet, N+1) contact schedule.
        foot_radius: radius (m) of the ball feet of the formulation (0: point feet); the
            forces act that far below their frames.
        integrator: of the transcription: ``'rk4'`` (exact for inputs held over an
            interval: ``q (+) (dt v + dt^2 a / 2)``) or ``'euler'`` (``q (+) dt v``); the
            velocity is ``v + dt a`` with both.
        stats: solver statistics (JSON-ready: iterations, time, cost, violation, ...).
        summary: the motion's own figures (targets, final errors), JSON-ready.
        arrays: other per-node arrays to save (e.g. the walk's velocity reference).
    """

    motion: str
    robot: str
    solver: str
    feet: list[str]
    joint_names: list[str]
    dt: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    f: np.ndarray
    tau: np.ndarray
    stance: np.ndarray
    stats: dict[str, Any] = field(default_factory=dict)
    foot_radius: float = 0.0
    integrator: str = "rk4"
    summary: dict[str, Any] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        """Number of intervals N."""
        return int(self.a.shape[1])

    @property
    def t(self) -> np.ndarray:
        """Node times (s), shape (N+1,)."""
        return self.dt * np.arange(self.q.shape[1])

    def forces(self) -> np.ndarray:
        """Contact forces per foot, shape (n_feet, 3, N)."""
        return self.f.reshape(len(self.feet), 3, -1)
