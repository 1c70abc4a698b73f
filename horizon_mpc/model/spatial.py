"""Spatial algebra on CasADi SX, written with 3x3 blocks.

Conventions (identical to Pinocchio, see ``doc/model.md``):

* a placement ``aMb`` is a :class:`Transform` ``(R, p)``: ``R`` (3x3) rotates coordinates of
  frame b into frame a, ``p`` (3,) is the origin of b expressed in a;
* a spatial motion is a pair ``(lin, ang)`` of 3-vectors (linear first);
* a spatial force is a pair ``(f, n)`` of 3-vectors (force first, then moment about the
  frame origin);
* a rigid-body inertia is ``(m, c, I_c)``: mass, centre of mass in the body frame and rotational
  inertia about the centre of mass.

Everything accepts numeric (numpy / DM) or symbolic (SX) arguments. Constant zeros and ones are
simplified away by SX, so there is no need to special-case sparse joint axes here.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np

__all__ = [
    "Transform",
    "Motion",
    "Force",
    "skew",
    "quat_to_rot",
    "axis_angle_rot",
    "cross_motion",
    "cross_force",
    "inertia_apply",
    "inertia_matrix",
    "transform_inertia_to_parent",
]

Vec = cs.SX | np.ndarray
Motion = tuple  # (lin (3,), ang (3,))
Force = tuple  # (f (3,), n (3,))


def _sx(x) -> cs.SX:
    return x if isinstance(x, cs.SX) else cs.SX(np.asarray(x, dtype=float))


def skew(v: Vec) -> cs.SX:
    """Cross-product matrix ``[v]`` (3x3) with ``[v] w = v x w``."""
    v = _sx(v)
    return cs.vertcat(
        cs.horzcat(0, -v[2], v[1]),
        cs.horzcat(v[2], 0, -v[0]),
        cs.horzcat(-v[1], v[0], 0),
    )


def quat_to_rot(quat: Vec) -> cs.SX:
    """Rotation matrix (3x3) of the quaternion ``quat = (x, y, z, w)``.

    Uses the same polynomial as Eigen's ``toRotationMatrix`` (no normalisation), so that values
    agree with Pinocchio bit for bit up to rounding, also for slightly non-unit quaternions.
    """
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    tx, ty, tz = 2 * x, 2 * y, 2 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    return cs.vertcat(
        cs.horzcat(1 - (tyy + tzz), txy - twz, txz + twy),
        cs.horzcat(txy + twz, 1 - (txx + tzz), tyz - twx),
        cs.horzcat(txz - twy, tyz + twx, 1 - (txx + tyy)),
    )


def axis_angle_rot(axis: np.ndarray, c: cs.SX, s: cs.SX) -> cs.SX:
    """Rotation (3x3) about the unit ``axis`` (numeric, (3,)) given ``c = cos``, ``s = sin``.

    Coordinate axes give the familiar sparse matrices (SX removes the zero terms).
    """
    a = np.asarray(axis, dtype=float).reshape(3)
    aat = np.outer(a, a)
    return c * cs.SX(np.eye(3) - aat) + s * skew(a) + cs.SX(aat)


@dataclass(frozen=True)
class Transform:
    """Rigid transform ``aMb = (R, p)``; see the module docstring for the convention."""

    R: cs.SX  # (3, 3)
    p: cs.SX  # (3, 1)

    @staticmethod
    def identity() -> Transform:
        """The identity transform."""
        return Transform(cs.SX.eye(3), cs.SX.zeros(3, 1))

    @staticmethod
    def from_numeric(R: np.ndarray, p: np.ndarray) -> Transform:
        """A constant transform from a numeric rotation (3, 3) and translation (3,)."""
        return Transform(cs.SX(np.asarray(R, float)), cs.SX(np.asarray(p, float).reshape(3, 1)))

    def __mul__(self, other: Transform) -> Transform:
        """Composition ``aMc = aMb * bMc``."""
        return Transform(self.R @ other.R, self.p + self.R @ other.p)

    def act_point(self, x: Vec) -> cs.SX:
        """Point given in b, expressed in a: ``R x + p``."""
        return self.p + self.R @ x

    def act_motion(self, m: Motion) -> Motion:
        """Motion expressed in b -> the same motion expressed in a."""
        ang = self.R @ m[1]
        return self.R @ m[0] + cs.cross(self.p, ang), ang

    def act_inv_motion(self, m: Motion) -> Motion:
        """Motion expressed in a -> the same motion expressed in b."""
        return self.R.T @ (m[0] - cs.cross(self.p, m[1])), self.R.T @ m[1]

    def act_force(self, f: Force) -> Force:
        """Force expressed in b -> the same force expressed in a; ``f``'s parts may be
        (3, k) blocks of k forces (a multi-DoF joint's columns in the CRBA)."""
        lin = self.R @ f[0]
        if lin.size2() == 1:
            return lin, self.R @ f[1] + cs.cross(self.p, lin)
        moment = cs.horzcat(*(cs.cross(self.p, lin[:, c]) for c in range(lin.size2())))
        return lin, self.R @ f[1] + moment


def cross_motion(m1: Motion, m2: Motion) -> Motion:
    """Spatial motion cross product ``m1 x m2``."""
    v1, w1 = m1
    v2, w2 = m2
    return cs.cross(w1, v2) + cs.cross(v1, w2), cs.cross(w1, w2)


def cross_force(m: Motion, f: Force) -> Force:
    """Spatial force cross product ``m x* f``."""
    v, w = m
    lin, ang = f
    return cs.cross(w, lin), cs.cross(w, ang) + cs.cross(v, lin)


def inertia_apply(mass: float, com: np.ndarray, inertia_c: np.ndarray, m: Motion) -> Force:
    """Momentum ``I * m`` of a rigid body with constant inertia ``(mass, com, inertia_c)``."""
    v, w = m
    lin = mass * (v - cs.cross(_sx(com), w))
    return lin, _sx(inertia_c) @ w + cs.cross(_sx(com), lin)


def inertia_matrix(mass: float, com: np.ndarray, inertia_c: np.ndarray) -> tuple:
    """Blocks ``(A, B, C)`` of the 6x6 spatial inertia ``[[A, B], [B^T, C]]`` (lin, ang order)."""
    c = np.asarray(com, float).reshape(3)
    cx = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    a = mass * np.eye(3)
    b = -mass * cx
    cc = np.asarray(inertia_c, float) - mass * cx @ cx
    return cs.SX(a), cs.SX(b), cs.SX(cc)


def transform_inertia_to_parent(tr: Transform, blocks: tuple) -> tuple:
    """Express a 6x6 (articulated) inertia given in frame b in frame a, with ``tr = aMb``.

    ``blocks = (A, B, C)`` with ``[[A, B], [B^T, C]]`` mapping motion (lin, ang) to force (f, n).
    """
    a, b, c = blocks
    r = tr.R
    a1 = r @ a @ r.T
    b1 = r @ b @ r.T
    c1 = r @ c @ r.T
    px = skew(tr.p)
    b_p = b1 - a1 @ px
    c_p = c1 - b1.T @ px + px @ b1 - px @ a1 @ px
    return a1, b_p, c_p


