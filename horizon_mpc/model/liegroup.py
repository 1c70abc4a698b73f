"""Configuration-space operations on the Lie group of the robot (integrate, difference).

Matches Pinocchio: the free-flyer lives on SE(3) with ``integrate(q, v) = q * exp6(v)``
(v = [linear, angular] in the base frame), continuous joints on SO(2) stored as
``(cos, sin)``, other joints on R. One difference: for a rotation step beyond pi, Pinocchio
flips the resulting quaternion into the input's hemisphere; ours keeps the product (the
same rotation, the opposite sign), which stays smooth in the step. Small-angle branches use
Taylor expansions so that values and derivatives are exact at zero (SX ``if_else`` discards
the unused branch, NaN included).
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as cs
import numpy as np

from horizon_mpc.model.joints import JointSpec
from horizon_mpc.model.spatial import quat_to_rot

__all__ = ["integrate", "difference", "neutral", "quat_multiply", "tangent_map"]

_SMALL2 = 1e-6  # squared angle below which Taylor expansions are used (error < 1e-19)


def quat_multiply(q1: cs.SX, q2: cs.SX) -> cs.SX:
    """Hamilton product ``q1 * q2`` of quaternions stored (x, y, z, w)."""
    x1, y1, z1, w1 = q1[0], q1[1], q1[2], q1[3]
    x2, y2, z2, w2 = q2[0], q2[1], q2[2], q2[3]
    return cs.vertcat(
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
    )


def _series(t2: cs.SX, exact: Callable[[cs.SX], cs.SX], coeffs: tuple) -> cs.SX:
    """``exact(t2)`` for ``t2 >= _SMALL2``, else the polynomial ``sum c_k t2^k``.

    ``exact`` is evaluated at a safe argument inside the Taylor region: SX differentiates
    ``if_else`` as ``cond * d(branch)``, so a NaN derivative in the unused branch would leak.
    """
    poly = coeffs[-1]
    for c in reversed(coeffs[:-1]):
        poly = c + t2 * poly
    small = t2 < _SMALL2
    return cs.if_else(small, poly, exact(cs.if_else(small, 1.0, t2)))


def _se3_integrate(q: cs.SX, v: cs.SX) -> cs.SX:
    p, quat = q[0:3], q[3:7]
    lin, w = v[0:3], v[3:6]
    t2 = cs.dot(w, w)
    # exp6 translation: V(w) lin, V = I + b [w] + c [w]^2
    b = _series(t2, lambda x: (1 - cs.cos(cs.sqrt(x))) / x, (1 / 2, -1 / 24, 1 / 720))
    c = _series(
        t2,
        lambda x: (cs.sqrt(x) - cs.sin(cs.sqrt(x))) / (x * cs.sqrt(x)),
        (1 / 6, -1 / 120, 1 / 5040),
    )
    wl = cs.cross(w, lin)
    trans = lin + b * wl + c * cs.cross(w, wl)
    half = _series(t2, lambda x: cs.sin(cs.sqrt(x) / 2) / cs.sqrt(x), (1 / 2, -1 / 48, 1 / 3840))
    cos_half = _series(t2, lambda x: cs.cos(cs.sqrt(x) / 2), (1, -1 / 8, 1 / 384))
    dquat = cs.vertcat(half * w, cos_half)
    quat1 = quat_multiply(quat, dquat)
    # Pinocchio re-normalises to first order after each step: keeps |quat| = 1 over time.
    quat1 = quat1 * (3 - cs.dot(quat1, quat1)) / 2
    return cs.vertcat(p + quat_to_rot(quat) @ trans, quat1)


def _se3_difference(q0: cs.SX, q1: cs.SX) -> cs.SX:
    conj0 = cs.vertcat(-q0[3:6], q0[6])
    dq = quat_multiply(conj0, q1[3:7])
    sign = cs.if_else(dq[3] < 0, -1, 1)  # shortest rotation
    vec, cw = sign * dq[0:3], sign * dq[3]
    n2 = cs.dot(vec, vec)  # sin(theta / 2)^2
    # theta / n, with atan(x)/x = 1 - x^2/3 + x^4/5 for x = n / cw
    ratio = _series(
        n2,
        lambda x: 2 * cs.atan2(cs.sqrt(x), cw) / cs.sqrt(x),
        (2 / cw, -2 / (3 * cw**3), 2 / (5 * cw**5)),
    )
    w = ratio * vec
    # V^{-1} = I - [w]/2 + alpha [w]^2,  alpha = (1 - (t/2) cot(t/2)) / t^2, cot(t/2) = cw / n;
    # in terms of n2: t = 2 atan2(n, cw) and t^2 = ratio^2 n2.
    alpha = _series(n2, lambda x: _alpha(x, cw), (1 / 12, 1 / 180, 1 / 420))
    trans = quat_to_rot(q0[3:7]).T @ (q1[0:3] - q0[0:3])
    wt = cs.cross(w, trans)
    lin = trans - wt / 2 + alpha * cs.cross(w, wt)
    return cs.vertcat(lin, w)


def _alpha(n2: cs.SX, cw: cs.SX) -> cs.SX:
    n = cs.sqrt(n2)
    theta = 2 * cs.atan2(n, cw)
    return (1 - theta / 2 * cw / n) / theta**2


def integrate(specs: list[JointSpec], q: cs.SX, dq: cs.SX, nq: int) -> cs.SX:
    """``q (+) dq`` (nq,), with dq (nv,) in the tangent space (see module docstring)."""
    out = [None] * nq
    for s in specs:
        qs = q[s.idx_q : s.idx_q + s.nq]
        vs = dq[s.idx_v : s.idx_v + s.nv]
        if s.kind == "free_flyer":
            res = _se3_integrate(qs, vs)
        elif s.kind == "continuous":
            c, sn = cs.cos(vs[0]), cs.sin(vs[0])
            res = cs.vertcat(c * qs[0] - sn * qs[1], sn * qs[0] + c * qs[1])
            res = res * (3 - cs.dot(res, res)) / 2
        else:
            res = qs + vs
        for k in range(s.nq):
            out[s.idx_q + k] = res[k]
    return cs.vertcat(*out)


def difference(specs: list[JointSpec], q0: cs.SX, q1: cs.SX, nv: int) -> cs.SX:
    """``q1 (-) q0`` (nv,): the tangent vector such that ``integrate(q0, dq) = q1``."""
    out = [None] * nv
    for s in specs:
        a = q0[s.idx_q : s.idx_q + s.nq]
        b = q1[s.idx_q : s.idx_q + s.nq]
        if s.kind == "free_flyer":
            res = _se3_difference(a, b)
        elif s.kind == "continuous":
            res = cs.atan2(a[0] * b[1] - a[1] * b[0], a[0] * b[0] + a[1] * b[1])
        else:
            res = b - a
        for k in range(s.nv):
            out[s.idx_v + k] = res[k]
    return cs.vertcat(*out)


def tangent_map(specs: list[JointSpec], q: cs.SX, nq: int, nv: int) -> cs.SX:
    """``d integrate(q, dq) / d dq`` at ``dq = 0`` (nq x nv)."""
    t = cs.SX.zeros(nq, nv)
    for s in specs:
        iq, iv = s.idx_q, s.idx_v
        if s.kind == "free_flyer":
            quat = q[iq + 3 : iq + 7]
            t[iq : iq + 3, iv : iv + 3] = quat_to_rot(quat)
            x, y, z, w = quat[0], quat[1], quat[2], quat[3]
            # d(quat * [w/2, 1]) / dw
            t[iq + 3 : iq + 7, iv + 3 : iv + 6] = 0.5 * cs.vertcat(
                cs.horzcat(w, -z, y),
                cs.horzcat(z, w, -x),
                cs.horzcat(-y, x, w),
                cs.horzcat(-x, -y, -z),
            )
        elif s.kind == "continuous":
            t[iq, iv] = -q[iq + 1]
            t[iq + 1, iv] = q[iq]
        else:
            t[iq, iv] = 1
    return t


def neutral(specs: list[JointSpec], nq: int) -> np.ndarray:
    """Neutral configuration (nq,): base at the origin, identity quaternion, joints at 0."""
    q = np.zeros(nq)
    for s in specs:
        if s.kind == "free_flyer":
            q[s.idx_q + 6] = 1.0
        elif s.kind == "continuous":
            q[s.idx_q] = 1.0
    return q
