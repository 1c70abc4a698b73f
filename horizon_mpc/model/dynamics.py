"""Symbolic rigid-body dynamics: RNEA, ABA, CRBA, centre of mass and centroidal momentum.

Featherstone's recursive algorithms in the joints' local frames (as Pinocchio does), with
point contact forces given in world axes at operational frames. See ``doc/model.md``.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from horizon_mpc.model.joints import JointSpec
from horizon_mpc.model.kinematics import FrameSpec, TreeKinematics
from horizon_mpc.model.spatial import (
    Force,
    Motion,
    Transform,
    cross_force,
    cross_motion,
    inertia_apply,
    inertia_matrix,
    transform_inertia_to_parent,
)

__all__ = [
    "contact_wrenches",
    "rnea",
    "aba",
    "crba",
    "center_of_mass",
    "centroidal_momentum",
]


def contact_wrenches(kin: TreeKinematics, frames: list[FrameSpec], f: cs.SX) -> dict[int, Force]:
    """External wrenches on joints, in their local frames, from point forces at frames.

    Args:
        kin: kinematics (placements are used).
        frames: contact frames, ``len(frames) = nc``.
        f: (3 nc,) forces in world axes, applied at the frames' origins.

    Returns:
        joint index -> summed wrench (f, n) in that joint's local frame.
    """
    out: dict[int, Force] = {}
    for k, fr in enumerate(frames):
        lin = kin.o_M[fr.parent].R.T @ f[3 * k : 3 * k + 3]
        ang = cs.cross(cs.SX(fr.p.reshape(3, 1)), lin)
        if fr.parent in out:
            prev = out[fr.parent]
            out[fr.parent] = (prev[0] + lin, prev[1] + ang)
        else:
            out[fr.parent] = (lin, ang)
    return out


def _gravity_in(tr: Transform, gravity: np.ndarray) -> Motion:
    """Spatial acceleration ``-g`` (uniform field) expressed in the frame ``oMi = tr``."""
    return tr.R.T @ cs.SX(-np.asarray(gravity, float).reshape(3, 1)), cs.SX.zeros(3, 1)


def _project(s: JointSpec, force: Force) -> list:
    """``S^T f`` for joint ``s``: one entry per DoF."""
    out = []
    for lin, ang in s.subspace():
        val = 0
        if np.any(lin):
            val = val + cs.dot(cs.SX(lin), force[0])
        if np.any(ang):
            val = val + cs.dot(cs.SX(ang), force[1])
        out.append(val)
    return out


def rnea(
    specs: list[JointSpec],
    kin: TreeKinematics,
    gravity: np.ndarray,
    nv: int,
    fext: dict[int, Force] | None = None,
) -> cs.SX:
    """Joint torques (nv,) of RNEA with external wrenches ``fext`` (joint local frames).

    ``kin`` must hold velocities and accelerations. ``tau = M a + b(q, v) - sum J^T f_ext``.
    """
    fext = fext or {}
    forces: dict[int, Force] = {}
    for s in specs:
        v = kin.vel[s.index]
        ag = _gravity_in(kin.o_M[s.index], gravity)
        acc = kin.acc[s.index]
        a = (acc[0] + ag[0], acc[1] + ag[1])
        ia = inertia_apply(s.mass, s.com, s.inertia_c, a)
        iv = inertia_apply(s.mass, s.com, s.inertia_c, v)
        vx = cross_force(v, iv)
        fi = (ia[0] + vx[0], ia[1] + vx[1])
        if s.index in fext:
            fi = (fi[0] - fext[s.index][0], fi[1] - fext[s.index][1])
        forces[s.index] = fi
    tau = [None] * nv
    for s in reversed(specs):
        fi = forces[s.index]
        for k, val in enumerate(_project(s, fi)):
            tau[s.idx_v + k] = val
        if s.parent > 0:
            fp = kin.li_M[s.index].act_force(fi)
            prev = forces[s.parent]
            forces[s.parent] = (prev[0] + fp[0], prev[1] + fp[1])
    return cs.vertcat(*tau)


def _subspace_matrix(s: JointSpec) -> np.ndarray:
    """S as a numeric (6, nv_j) matrix (rows lin, ang)."""
    return np.column_stack([np.concatenate([lin, ang]) for lin, ang in s.subspace()])


def _blocks_to_matrix(blocks: tuple) -> cs.SX:
    a, b, c = blocks
    return cs.vertcat(cs.horzcat(a, b), cs.horzcat(b.T, c))


def _matrix_to_blocks(m: cs.SX) -> tuple:
    return m[0:3, 0:3], m[0:3, 3:6], m[3:6, 3:6]


def _ldl_solve(d: cs.SX, rhs: cs.SX) -> cs.SX:
    """Solve ``d x = rhs`` for a small symmetric positive definite SX matrix (LDL^T)."""
    n = d.shape[0]
    if n == 1:
        return rhs / d[0, 0]
    lower = [[None] * n for _ in range(n)]
    diag = [None] * n
    for j in range(n):
        diag[j] = d[j, j] - sum(lower[j][k] ** 2 * diag[k] for k in range(j))
        for i in range(j + 1, n):
            acc = sum(lower[i][k] * lower[j][k] * diag[k] for k in range(j))
            lower[i][j] = (d[i, j] - acc) / diag[j]
    y = [None] * n
    for i in range(n):
        y[i] = rhs[i, :] - sum(lower[i][k] * y[k] for k in range(i))
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = y[i] / diag[i] - sum(lower[k][i] * x[k] for k in range(i + 1, n))
    return cs.vertcat(*x)


def aba(
    specs: list[JointSpec],
    kin: TreeKinematics,
    tau: cs.SX,
    gravity: np.ndarray,
    nv: int,
    fext: dict[int, Force] | None = None,
) -> cs.SX:
    """Joint accelerations (nv,) by the articulated-body algorithm.

    ``kin`` must hold placements and velocities (its accelerations are not used).
    """
    fext = fext or {}
    art: dict[int, cs.SX] = {}
    bias: dict[int, cs.SX] = {}
    cor: dict[int, Motion] = {}
    for s in specs:
        v = kin.vel[s.index]
        cor[s.index] = cross_motion(v, kin.vj[s.index])
        iv = inertia_apply(s.mass, s.com, s.inertia_c, v)
        pa = cross_force(v, iv)
        if s.index in fext:
            pa = (pa[0] - fext[s.index][0], pa[1] - fext[s.index][1])
        art[s.index] = _blocks_to_matrix(inertia_matrix(s.mass, s.com, s.inertia_c))
        bias[s.index] = cs.vertcat(*pa)
    u_mat: dict[int, cs.SX] = {}
    d_inv_u: dict[int, cs.SX] = {}
    for s in reversed(specs):
        i = s.index
        smat = cs.SX(_subspace_matrix(s))
        u = art[i] @ smat  # (6, nv_j)
        d = smat.T @ u
        uj = tau[s.idx_v : s.idx_v + s.nv] - smat.T @ bias[i]
        u_mat[i] = u
        # One factorisation for both the gain D^-1 U^T and the bias D^-1 u.
        sol = _ldl_solve(d, cs.horzcat(u.T, uj))
        d_inv_u[i] = sol
        if s.parent > 0:
            ia = art[i] - u @ sol[:, :6]
            c = cs.vertcat(*cor[i])
            pa = bias[i] + ia @ c + u @ sol[:, 6]
            li = kin.li_M[i]
            ia_p = transform_inertia_to_parent(li, _matrix_to_blocks(ia))
            art[s.parent] = art[s.parent] + _blocks_to_matrix(ia_p)
            fp = li.act_force((pa[0:3], pa[3:6]))
            bias[s.parent] = bias[s.parent] + cs.vertcat(*fp)
    acc: dict[int, cs.SX] = {}
    qdd = [None] * nv
    g = cs.SX(-np.asarray(gravity, float).reshape(3, 1))
    for s in specs:
        i = s.index
        if s.parent > 0:
            ap = kin.li_M[i].act_inv_motion((acc[s.parent][0:3], acc[s.parent][3:6]))
        else:
            ap = kin.li_M[i].act_inv_motion((g, cs.SX.zeros(3, 1)))
        a = cs.vertcat(*ap) + cs.vertcat(*cor[i])
        sol = d_inv_u[i]
        qj = sol[:, 6] - sol[:, :6] @ a
        for k in range(s.nv):
            qdd[s.idx_v + k] = qj[k]
        acc[i] = a + cs.SX(_subspace_matrix(s)) @ qj
    return cs.vertcat(*qdd)


def crba(specs: list[JointSpec], kin: TreeKinematics, nv: int) -> cs.SX:
    """Joint-space inertia matrix M(q) (nv x nv, symmetric) by the composite-body algorithm."""
    comp = {s.index: inertia_matrix(s.mass, s.com, s.inertia_c) for s in specs}
    mass = cs.SX.zeros(nv, nv)
    for s in reversed(specs):
        i = s.index
        smat = cs.SX(_subspace_matrix(s))
        force = _blocks_to_matrix(comp[i]) @ smat  # (6, nv_i), in frame i
        mass[s.idx_v : s.idx_v + s.nv, s.idx_v : s.idx_v + s.nv] = smat.T @ force
        j = i
        while specs[j - 1].parent > 0:
            lin, ang = kin.li_M[j].act_force((force[0:3, :], force[3:6, :]))
            force = cs.vertcat(lin, ang)
            j = specs[j - 1].parent
            sj = specs[j - 1]
            block = cs.SX(_subspace_matrix(sj)).T @ force
            mass[sj.idx_v : sj.idx_v + sj.nv, s.idx_v : s.idx_v + s.nv] = block
            mass[s.idx_v : s.idx_v + s.nv, sj.idx_v : sj.idx_v + sj.nv] = block.T
        if s.parent > 0:
            moved = transform_inertia_to_parent(kin.li_M[i], comp[i])
            comp[s.parent] = tuple(x + y for x, y in zip(comp[s.parent], moved, strict=True))
    return mass


def center_of_mass(
    specs: list[JointSpec], kin: TreeKinematics, total_mass: float, with_velocity: bool
) -> tuple[cs.SX, cs.SX | None]:
    """CoM position (3,) in world and, if ``with_velocity``, its velocity (3,)."""
    pos = cs.SX.zeros(3, 1)
    vel = cs.SX.zeros(3, 1)
    for s in specs:
        if s.mass == 0.0:
            continue
        o = kin.o_M[s.index]
        c = cs.SX(s.com.reshape(3, 1))
        pos = pos + s.mass * o.act_point(c)
        if with_velocity:
            lin, ang = kin.vel[s.index]
            vel = vel + s.mass * (o.R @ (lin + cs.cross(ang, c)))
    return pos / total_mass, (vel / total_mass if with_velocity else None)


def centroidal_momentum(specs: list[JointSpec], kin: TreeKinematics, com: cs.SX) -> cs.SX:
    """Centroidal momentum (6,): linear, then angular about the CoM, in world axes."""
    lin = cs.SX.zeros(3, 1)
    ang = cs.SX.zeros(3, 1)
    for s in specs:
        if s.mass == 0.0:
            continue
        h = inertia_apply(s.mass, s.com, s.inertia_c, kin.vel[s.index])
        hl, ha = kin.o_M[s.index].act_force(h)
        lin = lin + hl
        ang = ang + ha
    return cs.vertcat(lin, ang - cs.cross(com, lin))
