"""Small optimal control problems, and a trotting go2 MPC, shared by the solver tests."""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as cs
import numpy as np

from horizon_mpc import Problem

if TYPE_CHECKING:
    from horizon_mpc.mpc import WalkingMpc


def pendulum_swing_up(u_max: float, n_nodes: int = 60) -> Problem:
    """Swing-up of an undamped pendulum in 3 s (60 x 0.05 s) with ``|u| <= u_max`` and the
    upright state as a final equality; below ~6.5 the bound is active (it must pump)."""
    prb = Problem(n_nodes)
    x = prb.create_state_variable("x", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(x[1], -9.81 * cs.sin(x[0]) + u))
    prb.set_dt(0.05)
    x.set_bounds([0, 0], [0, 0], nodes=0)
    u.set_bounds(-u_max, u_max)
    prb.create_cost("effort", u, weight=0.1)
    prb.create_final_constraint("upright", x - np.array([np.pi, 0.0]))
    return prb


def planar_double_integrator_at_rest(n_nodes: int, dt: float = 0.1
                                     ) -> tuple[Problem, cs.SX, cs.SX, cs.SX]:
    """A point in the plane (position ``p``, velocity ``v``, acceleration input ``a``, 2 each)
    starting at rest at the origin; returns ``(prb, p, v, a)`` for the caller's terms."""
    prb = Problem(n_nodes)
    p = prb.create_state_variable("p", 2)
    v = prb.create_state_variable("v", 2)
    a = prb.create_input_variable("a", 2)
    prb.set_dynamics(cs.vertcat(v, a))
    prb.set_dt(dt)
    p.set_bounds([0, 0], [0, 0], nodes=0)
    v.set_bounds([0, 0], [0, 0], nodes=0)
    return prb, p, v, a


def double_integrator_with_a_nan_derivative_at_rest() -> Problem:
    """The planar double integrator with a speed residual ``|v|``, which has no derivative
    at ``v = 0``: the all-zero guess is feasible and its linearisation NaN."""
    prb, p, v, a = planar_double_integrator_at_rest(20)
    prb.create_cost("effort", a, weight=0.1)
    prb.create_cost("speed", cs.norm_2(v), weight=0.1)
    prb.create_final_cost("goal", p - [1.0, 0.5], weight=10.0)
    return prb


def trotting_go2_mpc(ticks: int) -> WalkingMpc:
    """A go2 ``WalkingMpc`` started standing and ticked ``ticks`` times (0.02 s apart, the
    state held) under a forward, sideways and turning command: trotting, so its problem has
    projected rows, stance changes and terminal rows."""
    from horizon_mpc.mpc import WalkingMpc

    mpc = WalkingMpc("go2")
    q, v = mpc.wp.q.initial_guess[:, 0].copy(), mpc.wp.v.initial_guess[:, 0].copy()
    mpc.start(q, v, 0.0)
    for k in range(1, ticks + 1):
        mpc.update(0.02 * k, q, v, np.array([0.3, 0.1, 0.2]))
    return mpc
