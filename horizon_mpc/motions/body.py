"""The robot's trunk as points to keep above the ground (the leap's body clearance).

The collision shapes of the links that ride on the floating base (the root link and those
fixed to it, e.g. anymal's faces and lidar cage) are read from the URDF with Pinocchio's
collision model (meshes bounded by their axis-aligned boxes, spheres and cylinders by
theirs) and reduced to the vertices of the convex hull of those boxes' corners. Whatever the
orientation of the base, the lowest point of the trunk is at or above the lowest of these
vertices, so keeping them above the ground keeps the trunk out of it (conservatively: a
box's corner sticks out of a rounded shape).
"""

from __future__ import annotations

import itertools
import logging

import casadi as cs
import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull, QhullError

from horizon_mpc.config import RobotConfig
from horizon_mpc.model.spatial import quat_to_rot
from horizon_mpc.posture import config_urdf_path
from horizon_mpc.sim.loading import resolve_mesh_uris

__all__ = ["point_heights", "trunk_points"]

log = logging.getLogger(__name__)


def trunk_points(cfg: RobotConfig, pin_model: pin.Model) -> np.ndarray:
    """(k, 3) points in the floating base's joint frame whose convex hull holds the
    collision shapes of the links riding on the base (empty when the URDF has none, or the
    model has no floating base).

    Raises:
        FileNotFoundError: a collision mesh of the URDF cannot be found.
    """
    if pin_model.njoints < 2 or pin_model.joints[1].shortname() != "JointModelFreeFlyer":
        return np.zeros((0, 3))
    text = resolve_mesh_uris(config_urdf_path(cfg))
    geom = pin.buildGeomFromUrdfString(pin_model, text, pin.GeometryType.COLLISION)
    corners = []
    for obj in geom.geometryObjects:
        if obj.parentJoint != 1:
            continue
        shape = obj.geometry
        shape.computeLocalAABB()
        box = shape.aabb_local
        lo, hi = np.array(box.min_), np.array(box.max_)
        local = np.array([[(lo, hi)[b][i] for i, b in enumerate(bits)]
                          for bits in itertools.product((0, 1), repeat=3)])
        corners.append(local @ obj.placement.rotation.T + obj.placement.translation)
    if not corners:
        return np.zeros((0, 3))
    pts = np.unique(np.round(np.vstack(corners), 9), axis=0)
    try:
        pts = pts[ConvexHull(pts).vertices]
    except QhullError:  # flat or degenerate (a single box of zero thickness): keep them all
        pass
    log.debug("%s: %d trunk points from %d collision shapes", cfg.name, len(pts),
              len(corners))
    return pts


def point_heights(q: cs.SX | np.ndarray, points: np.ndarray) -> cs.SX | np.ndarray:
    """World heights (k,) of ``points`` (k, 3, base joint frame) at configuration ``q``
    (base position, then Pinocchio's quaternion x, y, z, w): symbolic for a CasADi ``q``."""
    heights = q[2] + cs.mtimes(points, quat_to_rot(q[3:7])[2, :].T)
    return heights if isinstance(heights, (cs.SX, cs.MX)) else np.asarray(heights).ravel()
