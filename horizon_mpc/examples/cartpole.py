"""Cart-pole swing-up: from hanging at rest to upright at rest.

State ``q = [p, theta]`` (cart position in m, pole angle in rad, 0 = hanging down, pi =
upright), ``v = dq/dt``; input ``u`` (1): horizontal force on the cart in N.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from horizon_mpc.problem import Problem

__all__ = ["build_cartpole", "cartpole_dynamics"]


def cartpole_dynamics(q: cs.SX, v: cs.SX, u: cs.SX, m_cart: float = 1.0, m_pole: float = 0.3,
                      length: float = 0.5, gravity: float = 9.81) -> cs.SX:
    """Accelerations ``ddq`` (2,) of a cart with a point-mass pole at distance ``length``."""
    s, c = cs.sin(q[1]), cs.cos(q[1])
    den = m_cart + m_pole * s**2
    pdd = (u[0] + m_pole * s * (length * v[1] ** 2 + gravity * c)) / den
    thdd = (-u[0] * c - m_pole * length * v[1] ** 2 * c * s
            - (m_cart + m_pole) * gravity * s) / (length * den)
    return cs.vertcat(pdd, thdd)


def build_cartpole(n_nodes: int = 100, duration: float = 2.0,
                   transcription: str = "multiple_shooting",
                   integrator: str | None = None, degree: int | None = None,
                   u_max: float | None = None, cart_limit: float | None = None,
                   w_effort: float = 1.0, w_velocity: float = 1e-2,
                   ) -> tuple[Problem, dict]:
    """Cart-pole swing-up in ``duration`` seconds on ``n_nodes`` intervals.

    Cost: ``w_effort * sum_k dt u_k^2 + w_velocity * sum_k dt ||v_k||^2`` (an approximation of
    the integrals). Constraints: rest at the origin on node 0 (variable bounds), upright at
    rest on node N (final equality constraints ``goal_q``, ``goal_v``); optional input bound
    ``|u| <= u_max`` and cart travel ``|p| <= cart_limit``. Initial guess: the pole angle
    interpolated linearly from 0 to pi, everything else 0.

    Returns:
        ``(prb, {'q': q, 'v': v, 'u': u})``.
    """
    prb = Problem(n_nodes)
    q = prb.create_state_variable("q", 2)
    v = prb.create_state_variable("v", 2)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(v, cartpole_dynamics(q, v, u)))
    dt = duration / n_nodes
    prb.set_dt(dt)
    prb.transcribe(transcription, integrator=integrator, degree=degree)

    q.set_bounds([0.0, 0.0], [0.0, 0.0], nodes=0)
    v.set_bounds([0.0, 0.0], [0.0, 0.0], nodes=0)
    if u_max is not None:
        u.set_bounds(-u_max, u_max)
    if cart_limit is not None:
        q.set_bounds([-cart_limit, -np.inf], [cart_limit, np.inf])
        q.set_bounds([0.0, 0.0], [0.0, 0.0], nodes=0)
    q.set_initial_guess(np.vstack([np.zeros(n_nodes + 1), np.linspace(0.0, np.pi, n_nodes + 1)]))

    prb.create_final_constraint("goal_q", q - np.array([0.0, np.pi]))
    prb.create_final_constraint("goal_v", v)
    prb.create_cost("effort", u, weight=w_effort * dt)
    if w_velocity > 0:
        prb.create_cost("velocity", v, weight=w_velocity * dt)
    return prb, {"q": q, "v": v, "u": u}
