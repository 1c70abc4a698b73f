"""Feed-forward joint torques that hold a robot standing still on its feet.

At rest (v = 0, a = 0) the floating-base dynamics reduce to

    g(q) = S^T tau + J_c(q)^T f,

with g (nv,) the generalized gravity, S = [0 I] the actuation selector, J_c (3 nc, nv) the
stacked world-aligned linear Jacobians of the nc contact frames and f (3 nc,) the contact
forces. The first six rows (the unactuated base) constrain f only:
``g_base = J_base^T f``. We take the f closest to an equal share of the weight per foot,
``f_eq = (0, 0, m g / nc)`` each, that satisfies those rows (least-norm correction through a
pseudo-inverse), then read tau off the joint rows: ``tau = g_joints - J_joints^T f``.
Computed once per start posture; the simulator adds it to its PD hold so the robot does not sag.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

__all__ = ["standing_feedforward"]


def standing_feedforward(
    model: pin.Model, q: np.ndarray, feet: Sequence[str]
) -> tuple[np.ndarray, np.ndarray]:
    """Joint torques and foot forces balancing gravity at configuration ``q``.

    Args:
        model: free-flyer Pinocchio model (gravity as set in ``model.gravity``).
        q: (nq,) configuration.
        feet: contact frame names.

    Returns:
        ``(tau, f)``: joint torques (nv - 6,) in N m and contact forces (len(feet), 3) in N,
        world frame.
    """
    data = model.createData()
    g = pin.computeGeneralizedGravity(model, data, q)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jac = np.vstack([
        pin.getFrameJacobian(model, data, model.getFrameId(foot),
                             pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:3]
        for foot in feet
    ])
    weight = pin.computeTotalMass(model) * np.linalg.norm(model.gravity.linear)
    f_eq = np.tile([0.0, 0.0, weight / len(feet)], len(feet))
    a = jac[:, :6].T  # (6, 3 nc)
    f = f_eq + np.linalg.pinv(a) @ (g[:6] - a @ f_eq)
    tau = g[6:] - jac[:, 6:].T @ f
    return tau, f.reshape(len(feet), 3)
