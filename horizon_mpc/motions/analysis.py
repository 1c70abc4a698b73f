"""Checks of a motion against numeric Pinocchio and figures read from its force profile.

Nothing here uses CasADi: the solution is verified with Pinocchio's own algorithms
(RNEA, CRBA, frame Jacobians, ``integrate``/``difference``), independently of the symbolic
model the optimiser used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from horizon_mpc.closed_loop_report import roll_pitch_yaw
from horizon_mpc.motions.result import MotionResult

if TYPE_CHECKING:
    from horizon_mpc.model import RobotModel

__all__ = [
    "CONTACT_TOLERANCE",
    "best_overlap",
    "check_contacts",
    "contact_check",
    "contact_torques",
    "dynamics_check",
    "flight_phases",
    "foot_heights",
    "loaded",
    "physics_summary",
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


def physics_summary(res: MotionResult, model: RobotModel, contacts: bool = True) -> dict:
    """The summary figures every motion reports from its checks against numeric Pinocchio:
    ``max_torque_ratio`` (largest joint torque over its effort limit), ``max_dynamics_defect``
    and ``max_base_wrench`` (:func:`dynamics_check`) and, with ``contacts``, the figures of
    :func:`contact_check`."""
    out = {"max_torque_ratio": float(np.max(np.abs(res.tau[6:])
                                            / model.joint_effort_limit[:, None]))}
    dyn = dynamics_check(res, model.pin_model, res.foot_radius, res.integrator)
    out["max_dynamics_defect"] = dyn["max_defect"]
    out["max_base_wrench"] = dyn["max_base_wrench"]
    if contacts:
        out.update(contact_check(res, model.pin_model))
    return out


#: m: a loaded foot may leave the ground or slide by this much within an interval (rolling
#: ball feet move their frames by a few mm; the default turns: at most 3.7 mm)
CONTACT_TOLERANCE = 0.01


def contact_check(res: MotionResult, model: pin.Model, samples: int = 4,
                  threshold: float | None = None) -> dict:
    """Where the feet are while they push: for every interval on which a foot is loaded
    (:func:`loaded`), its height relative to node 0 (the robot standing on the ground) and
    its horizontal displacement from the interval's start, at ``samples`` + 1 points of the
    exact per-interval motion ``q_k (+) (t v_k + t^2 a_k / 2)`` (the grid's constraints
    only hold on the nodes: a stance foot could float between them).

    Returns:
        ``max_loaded_foot_height``, ``max_loaded_foot_slip`` (m, largest over the loaded
        feet and intervals) and ``loaded_off_ground_intervals`` (how many intervals have a
        loaded foot beyond :data:`CONTACT_TOLERANCE` either way).
    """
    data = model.createData()
    frames = [model.getFrameId(f) for f in res.feet]

    def feet(q: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(model, data, q)
        return np.array([data.oMf[i].translation for i in frames])

    ground = feet(res.q[:, 0])[:, 2]
    load = loaded(res, threshold)
    height = slip = 0.0
    bad = 0
    for k in np.flatnonzero(load.any(axis=0)):
        q, v, a = res.q[:, k], res.v[:, k], res.a[:, k]
        pts = np.array([feet(pin.integrate(model, q, t * v + 0.5 * t * t * a))
                        for t in np.linspace(0.0, res.dt, samples + 1)])  # (S, feet, 3)
        on = load[:, k]
        h = np.abs(pts[:, on, 2] - ground[on]).max()
        d = np.linalg.norm(pts[:, on, :2] - pts[0, on, :2], axis=2).max()
        height, slip = max(height, float(h)), max(slip, float(d))
        bad += int(h > CONTACT_TOLERANCE or d > CONTACT_TOLERANCE)
    return {"max_loaded_foot_height": height, "max_loaded_foot_slip": slip,
            "loaded_off_ground_intervals": bad}


def check_contacts(res: MotionResult) -> None:
    """Mark a solved motion whose summary shows loaded feet off the ground or sliding
    (:func:`contact_check`) as not solved: the solver met its constraints on the nodes only
    (a turn with 1 m steps pushed 227 N through feet up to 33 cm up, reported 'solved')."""
    s = res.summary
    worst = max(s["max_loaded_foot_height"], s["max_loaded_foot_slip"])
    if res.stats.get("success", True) and worst > CONTACT_TOLERANCE:
        res.stats["success"] = False
        height, slip = s["max_loaded_foot_height"], s["max_loaded_foot_slip"]
        res.stats["status"] = (f"inconsistent contacts: a loaded foot {height:.3f} m off the "
                               f"ground, sliding {slip:.3f} m "
                               f"within an interval (> {CONTACT_TOLERANCE} m) in "
                               f"{s['loaded_off_ground_intervals']} intervals; solver: "
                               f"{res.stats.get('status')}")


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


def foot_heights(model: RobotModel, res: MotionResult) -> np.ndarray:
    """Height (m) of each contact frame on each node, shape (n_feet, N+1)."""
    n = res.q.shape[1]
    return np.vstack([np.asarray(model.fk(foot).map(n)(res.q)[0])[2] for foot in res.feet])


def swing_intervals(stance: np.ndarray) -> list[list[tuple[int, int]]]:
    """Per foot, the runs of swing nodes ``[k0, k1)`` of a schedule (n_feet, N+1)."""
    return [_runs(~np.asarray(row, bool)) for row in stance]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(m[1:] != m[:-1])
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
