"""Checks of a motion against numeric Pinocchio and figures read from its force profile.

Nothing here uses CasADi: the solution is verified with Pinocchio's own algorithms
(RNEA, CRBA, frame Jacobians, ``integrate``/``difference``), independently of the symbolic
model the optimiser used.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from horizon_mpc.closed_loop_report import roll_pitch_yaw
from horizon_mpc.motions.result import MotionResult

__all__ = [
    "best_overlap",
    "contact_torques",
    "dynamics_check",
    "flight_phases",
    "loaded",
    "roll_pitch_yaw",
    "swing_intervals",
]


def contact_torques(model: pin.Model, data: pin.Data, q: np.ndarray, feet: list[str],
                    f: np.ndarray, foot_radius: float = 0.0) -> np.ndarray:
    """Generalised force (nv,) of the contact forces ``f`` (3 per foot, world axes).

    Each force acts ``foot_radius`` below its frame (at the lowest point of a ball foot;
    at the frame origin for 0): ``sum_c J_c^T [f_c; o x f_c]``, ``o = (0, 0, -radius)``.
    """
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    out = np.zeros(model.nv)
    offset = np.array([0.0, 0.0, -foot_radius])
    for i, foot in enumerate(feet):
        J = pin.getFrameJacobian(model, data, model.getFrameId(foot), pin.LOCAL_WORLD_ALIGNED)
        fi = f[3 * i:3 * i + 3]
        out += J[:3].T @ fi + J[3:].T @ np.cross(offset, fi)
    return out


def dynamics_check(res: MotionResult, model: pin.Model, foot_radius: float = 0.0,
                   integrator: str = "rk4") -> dict:
    """Integrate the solution's inputs through Pinocchio's dynamics, interval by interval.

    For each interval k: the joint torques ``tau_j`` of inverse dynamics (RNEA minus the
    contact forces), the base wrench left over (zero when under-actuation holds), the
    forward dynamics ``a = M^-1 (S^T tau_j + J_c^T f - h)`` with *zero* base torque, and the
    state reached with it, ``q (+) (dt v + dt^2 a / 2)``, ``v + dt a`` (the exact solution
    for inputs held over the interval, which the rk4 transcription reproduces; with
    ``integrator='euler'``: ``q (+) dt v``).

    Returns:
        ``max_defect`` (inf-norm of the state mismatch at the next node, mixed units m,
        rad, m/s, rad/s), ``max_base_wrench`` (N, N m), per-interval arrays ``defect`` (N,)
        and ``base_wrench`` (6, N), and ``tau`` (nv, N) from Pinocchio.
    """
    if integrator not in ("rk4", "euler"):
        raise ValueError(f"integrator must be 'rk4' or 'euler', got {integrator!r}")
    half = 0.5 if integrator == "rk4" else 0.0
    data = model.createData()
    N, dt = res.n_nodes, res.dt
    defect = np.zeros(N)
    wrench = np.zeros((6, N))
    taus = np.zeros((model.nv, N))
    for k in range(N):
        q, v, a, f = res.q[:, k], res.v[:, k], res.a[:, k], res.f[:, k]
        contact = contact_torques(model, data, q, res.feet, f, foot_radius)
        tau = pin.rnea(model, data, q, v, a) - contact
        taus[:, k] = tau
        wrench[:, k] = tau[:6]
        actuated = np.concatenate([np.zeros(6), tau[6:]])
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.nonLinearEffects(model, data, q, v)
        a_fd = np.linalg.solve(M, actuated + contact - h)
        q_next = pin.integrate(model, q, dt * v + half * dt * dt * a_fd)
        v_next = v + dt * a_fd
        defect[k] = max(np.max(np.abs(pin.difference(model, res.q[:, k + 1], q_next))),
                        np.max(np.abs(v_next - res.v[:, k + 1])))
    return {"max_defect": float(defect.max(initial=0.0)),
            "max_base_wrench": float(np.abs(wrench).max(initial=0.0)),
            "defect": defect, "base_wrench": wrench, "tau": taus}


def loaded(res: MotionResult, threshold: float | None = None) -> np.ndarray:
    """(n_feet, N) whether each foot carries a normal force above ``threshold`` (N) on each
    interval; default threshold 1% of the total weight ``sum f_z`` at rest."""
    fz = res.forces()[:, 2, :]
    if threshold is None:
        threshold = 0.01 * float(np.max(fz.sum(axis=0), initial=0.0))
    return fz > threshold


def flight_phases(load: np.ndarray) -> list[tuple[int, int]]:
    """Runs of intervals ``[k0, k1)`` on which no foot is loaded (``load``: (n_feet, N))."""
    air = ~np.any(load, axis=0)
    return _runs(air)


def best_overlap(runs: list[tuple[int, int]], start: int, stop: int) -> tuple[int, int]:
    """The run ``[a, b)`` of ``runs`` (non-empty) that overlaps ``[start, stop)`` most;
    the longest when none does."""
    overlap = [max(0, min(b, stop) - max(a, start)) for a, b in runs]
    if max(overlap) > 0:
        return runs[int(np.argmax(overlap))]
    return max(runs, key=lambda ab: ab[1] - ab[0])


def swing_intervals(stance: np.ndarray) -> list[list[tuple[int, int]]]:
    """Per foot, the runs of swing nodes ``[k0, k1)`` of a schedule (n_feet, N+1)."""
    return [_runs(~np.asarray(row, bool)) for row in stance]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
