"""Analytical derivatives of inverse dynamics with point contacts, in world-frame spatial algebra.

For ``tau(q, v, a, f) = RNEA(q, v, a) - sum_c J_c^T f_c`` this builds ``dtau/dq`` (on the
tangent space), ``dtau/dv``, ``dtau/da = M`` and ``dtau/df`` in O(n d) work (n DoFs, d tree
depth), far less SX than differentiating the recursion with AD.

Derivation (all motions and forces in world axes at the world origin). Perturbing DoF j of
joint J moves the subtree of J rigidly with the twist ``s_j`` (the world column of S), so a
body-fixed quantity X changes by ``s_j x X``, except for what the subtree inherits from the
parent ``p`` of J, which does not move: ``ov_p``, ``oa_p`` (gravity included) and the
contact forces (fixed in world, applied at moving points). Collecting the non-rigid parts
over the subtree of joint K (composites ``Ic`` inertia, ``Bc = sum(ov x* oI - oI ov x)``,
``Hc`` momentum, ``Fc`` net force, ``FCc`` contact force, ``Pc = sum((p.f) I - f p^T)``)
gives, for a DoF k of a joint K in the subtree of J (J included)::

    dtau_k/dq_j = -alpha_k . psi_j + beta_k . dv_j + gamma_k . omega_j
    dtau_k/dv_j =  alpha_k . nu_j + beta_k . s_j
    dtau_k/da_j =  alpha_k . s_j

with ``alpha_k = Ic_K s_k``, ``beta_k = Bc_K^T s_k - s_k x* Hc_K``,
``gamma_k = FCc_K x s_k.lin + Pc_K^T s_k.ang``, ``dv_j = ov_p x s_j``,
``psi_j = s_j x oa_p + dv_j x ov_p``, ``omega_j = s_j.ang``,
``nu_j = (ov_p + ov_J) x s_j`` (``2 dv_j`` for a one-DoF joint); the term ``(s_j x s_k)^T Fc_K``
from the moving axis cancels ``s_k^T (s_j x* Fc_K)``. For a DoF k of a strict ancestor of J,
``s_k`` does not move and ``dtau_k/d(.)_j = s_k . Gamma_j`` with Gamma_j the derivative of
``Fc_J`` (same terms, plus ``s_j x* Fc_J`` for q).
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from horizon_mpc.model.joints import JointSpec
from horizon_mpc.model.kinematics import FrameSpec, TreeKinematics, frame_placement
from horizon_mpc.model.spatial import Transform, cross_force, cross_motion, skew

__all__ = ["inverse_dynamics_derivatives"]

Vec6 = cs.SX  # (6, 1): (lin, ang) or (force, moment)


class _Inertia:
    """World-frame spatial inertia at the origin, ``[[M I, -[h]], [[h], I_O]]``.

    ``M`` total mass, ``h = M c`` first moment, ``I_O`` rotational inertia about the world
    origin: 10 numbers instead of 36, and sums of them are composite inertias.
    """

    def __init__(self, mass, h: cs.SX, i_o: cs.SX) -> None:
        self.mass, self.h, self.i_o = mass, h, i_o

    def __add__(self, other: _Inertia) -> _Inertia:
        return _Inertia(self.mass + other.mass, self.h + other.h, self.i_o + other.i_o)

    def apply(self, x: Vec6) -> Vec6:
        v, w = x[0:3], x[3:6]
        return cs.vertcat(self.mass * v - cs.cross(self.h, w), self.i_o @ w + cs.cross(self.h, v))


class _Variation:
    """``B = ov x* oI - oI ov x`` (symmetric): ``[[0, [u]], [-[u], D]]``, D symmetric 3x3."""

    def __init__(self, u: cs.SX, d: cs.SX) -> None:
        self.u, self.d = u, d

    def __add__(self, other: _Variation) -> _Variation:
        return _Variation(self.u + other.u, self.d + other.d)

    def apply(self, x: Vec6) -> Vec6:
        xl, xa = x[0:3], x[3:6]
        return cs.vertcat(cs.cross(self.u, xa), self.d @ xa - cs.cross(self.u, xl))


def _body_inertia(s: JointSpec, o_m: Transform) -> _Inertia:
    com = o_m.act_point(cs.SX(s.com.reshape(3, 1)))
    rot = o_m.R
    i_w = rot @ cs.SX(s.inertia_c) @ rot.T
    i_o = i_w + s.mass * (cs.dot(com, com) * cs.SX.eye(3) - com @ com.T)
    return _Inertia(s.mass, s.mass * com, _symmetrize(i_o))


def _symmetrize(m: cs.SX) -> cs.SX:
    """Reuse the upper triangle's nodes below the diagonal (halves later sums)."""
    out = cs.SX(m.shape[0], m.shape[1])
    for r in range(m.shape[0]):
        for c in range(r, m.shape[1]):
            out[r, c] = m[r, c]
            out[c, r] = m[r, c]
    return out


def _variation(inertia: _Inertia, vel: Vec6) -> _Variation:
    v, w = vel[0:3], vel[3:6]
    h, i_o = inertia.h, inertia.i_o
    u = cs.cross(h, w) - inertia.mass * v
    wx = skew(w)
    d = 2 * cs.dot(v, h) * cs.SX.eye(3) - v @ h.T - h @ v.T + wx @ i_o - i_o @ wx
    return _Variation(u, _symmetrize(d))


def _mx(a: Vec6, b: Vec6) -> Vec6:
    """Motion cross product ``a x b``."""
    return cs.vertcat(*cross_motion((a[0:3], a[3:6]), (b[0:3], b[3:6])))


def _fx(a: Vec6, b: Vec6) -> Vec6:
    """Force cross product ``a x* b``."""
    return cs.vertcat(*cross_force((a[0:3], a[3:6]), (b[0:3], b[3:6])))


def _world_columns(s: JointSpec, o_m: Transform) -> list[Vec6]:
    """World-frame motion subspace columns of joint ``s``, one 6-vector per DoF."""
    cols = []
    for lin, ang in s.subspace():
        w = o_m.R @ ang if np.any(ang) else cs.SX.zeros(3, 1)
        v = o_m.R @ lin if np.any(lin) else cs.SX.zeros(3, 1)
        if np.any(ang):
            v = v + cs.cross(o_m.p, w)
        cols.append(cs.vertcat(v, w))
    return cols


def inverse_dynamics_derivatives(
    specs: list[JointSpec],
    kin: TreeKinematics,
    v: cs.SX,
    a: cs.SX,
    gravity: np.ndarray,
    nv: int,
    frames: list[FrameSpec],
    f: cs.SX,
) -> tuple[cs.SX, cs.SX, cs.SX, cs.SX, cs.SX]:
    """``tau, dtau_dq, dtau_dv, dtau_da, dtau_df`` (see the module docstring).

    Args:
        specs: joints; ``kin``: their placements (q symbolic; velocities not needed).
        v, a: (nv,) velocity and acceleration; ``gravity``: (3,) field, e.g. (0, 0, -9.81).
        frames, f: contact frames and their stacked world forces (3 per frame).
    """
    ov: dict[int, Vec6] = {0: cs.SX.zeros(6, 1)}
    oa: dict[int, Vec6] = {0: cs.vertcat(-cs.SX(np.asarray(gravity, float)), cs.SX.zeros(3, 1))}
    cols: dict[int, list[Vec6]] = {}
    ic: dict[int, _Inertia] = {}
    bc: dict[int, _Variation] = {}
    hc: dict[int, Vec6] = {}
    fc: dict[int, Vec6] = {}
    for s in specs:
        i, p = s.index, s.parent
        cols[i] = _world_columns(s, kin.o_M[i])
        vi, ai = ov[p], oa[p]
        for k, col in enumerate(cols[i]):
            vi = vi + col * v[s.idx_v + k]
        for k, col in enumerate(cols[i]):
            ai = ai + col * a[s.idx_v + k] + _mx(vi, col) * v[s.idx_v + k]
        ov[i], oa[i] = vi, ai
        inertia = _body_inertia(s, kin.o_M[i])
        h = inertia.apply(vi)
        ic[i], bc[i], hc[i] = inertia, _variation(inertia, vi), h
        fc[i] = inertia.apply(ai) + _fx(vi, h)
    fcc: dict[int, cs.SX] = {s.index: cs.SX.zeros(3, 1) for s in specs}
    pc: dict[int, cs.SX] = {s.index: cs.SX.zeros(3, 3) for s in specs}
    points = []
    for c, fr in enumerate(frames):
        fk = f[3 * c : 3 * c + 3]
        pt = frame_placement(kin, fr).p
        points.append(pt)
        j = fr.parent
        if j == 0:  # a frame fixed to the world: its force does not enter the dynamics
            continue
        fc[j] = fc[j] - cs.vertcat(fk, cs.cross(pt, fk))
        fcc[j] = fcc[j] + fk
        pc[j] = pc[j] + cs.dot(pt, fk) * cs.SX.eye(3) - fk @ pt.T
    for s in reversed(specs):  # composites over subtrees
        i, p = s.index, s.parent
        if p > 0:
            ic[p], bc[p], hc[p] = ic[p] + ic[i], bc[p] + bc[i], hc[p] + hc[i]
            fc[p], fcc[p], pc[p] = fc[p] + fc[i], fcc[p] + fcc[i], pc[p] + pc[i]

    dofs = [(s, k, col) for s in specs for k, col in enumerate(cols[s.index])]
    tau = cs.SX.zeros(nv, 1)
    alpha, beta, gamma = {}, {}, {}
    for s, k, col in dofs:
        i, r = s.index, s.idx_v + k
        tau[r] = cs.dot(col, fc[i])
        alpha[r] = ic[i].apply(col)
        beta[r] = bc[i].apply(col) - _fx(col, hc[i])
        gamma[r] = cs.cross(fcc[i], col[0:3]) + pc[i].T @ col[3:6]

    subtree: dict[int, list[int]] = {s.index: [] for s in specs}  # DoF rows, joint included
    for s in reversed(specs):
        subtree[s.index] = list(range(s.idx_v, s.idx_v + s.nv)) + subtree[s.index]
        if s.parent > 0:
            subtree[s.parent] = subtree[s.parent] + subtree[s.index]
    dq, dv, da = cs.SX.zeros(nv, nv), cs.SX.zeros(nv, nv), cs.SX.zeros(nv, nv)
    for s, k, col in dofs:
        i, p, c = s.index, s.parent, s.idx_v + k
        dvel = _mx(ov[p], col)
        # d(oa)/dv_j of the joint's body: (ov_p + ov_i) x s_j (= 2 dvel for one DoF)
        nu = _mx(ov[p] + ov[i], col)
        psi = _mx(col, oa[p]) + _mx(dvel, ov[p])
        omega = col[3:6]
        for r in subtree[i]:
            dq[r, c] = -cs.dot(alpha[r], psi) + cs.dot(beta[r], dvel) + cs.dot(gamma[r], omega)
            dv[r, c] = cs.dot(alpha[r], nu) + cs.dot(beta[r], col)
            da[r, c] = cs.dot(alpha[r], col)
            da[c, r] = da[r, c]  # M is symmetric: the ancestors' rows come for free
        if p == 0:
            continue
        gq = (
            _fx(col, fc[i])
            - ic[i].apply(psi)
            + _fx(dvel, hc[i])
            + bc[i].apply(dvel)
            + cs.vertcat(cs.cross(omega, fcc[i]), pc[i] @ omega)
        )
        gv = ic[i].apply(nu) + bc[i].apply(col) + _fx(col, hc[i])
        anc = p
        while anc > 0:
            sa = specs[anc - 1]
            for ka, col_a in enumerate(cols[anc]):
                r = sa.idx_v + ka
                dq[r, c] = cs.dot(col_a, gq)
                dv[r, c] = cs.dot(col_a, gv)
            anc = sa.parent
    df = cs.SX.zeros(nv, 3 * len(frames))
    for c, fr in enumerate(frames):
        anc = fr.parent
        while anc > 0:
            sa = specs[anc - 1]
            for ka, col_a in enumerate(cols[anc]):
                row = -(col_a[0:3] + cs.cross(col_a[3:6], points[c]))
                df[sa.idx_v + ka, 3 * c : 3 * c + 3] = row.T
            anc = sa.parent
    return tau, dq, dv, da, df
