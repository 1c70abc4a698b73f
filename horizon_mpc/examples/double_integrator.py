"""Minimum-energy rest-to-rest transfer of a double integrator, with its exact optimum.

``x'' = u``, from rest at 0 to rest at ``distance`` in time ``T``, minimising
``integral u^2 dt``. Continuous optimum: ``u(t) = (L/T^2) (6 - 12 t/T)``, cost ``12 L^2/T^3``.
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from horizon_mpc.problem import Problem

__all__ = ["build_double_integrator", "double_integrator_optimum"]


def build_double_integrator(n_nodes: int = 20, duration: float = 1.0, distance: float = 1.0,
                            transcription: str = "multiple_shooting", integrator: str | None = None,
                            degree: int | None = None) -> tuple[Problem, dict]:
    """The transfer on ``n_nodes`` intervals with piecewise-constant ``u``.

    Cost ``sum_k dt u_k^2`` (the exact integral of a piecewise-constant ``u``); start at
    rest by variable bounds on node 0, arrival at rest by a final equality constraint.

    Returns:
        ``(prb, {'x': x, 'v': v, 'u': u})``.
    """
    prb = Problem(n_nodes)
    x = prb.create_state_variable("x", 1)
    v = prb.create_state_variable("v", 1)
    u = prb.create_input_variable("u", 1)
    prb.set_dynamics(cs.vertcat(v, u))
    dt = duration / n_nodes
    prb.set_dt(dt)
    prb.transcribe(transcription, integrator=integrator, degree=degree)
    x.set_bounds(0.0, 0.0, nodes=0)
    v.set_bounds(0.0, 0.0, nodes=0)
    prb.create_final_constraint("arrive", cs.vertcat(x - distance, v))
    prb.create_cost("effort", u, weight=dt)
    return prb, {"x": x, "v": v, "u": u}


def double_integrator_optimum(n_nodes: int, duration: float = 1.0,
                              distance: float = 1.0) -> tuple[np.ndarray, float]:
    """Exact optimum ``(u (N,), cost)`` over piecewise-constant inputs with exact dynamics
    (what RK2/RK4 multiple shooting and collocation of degree >= 2 compute, since the state
    is a quadratic in time on each interval).

    With ``h = T/N`` and interval midpoints ``t_k``: ``u_k = beta (T/2 - t_k)``,
    ``beta = 12 L / (T (T^2 - h^2))``, cost ``L beta``; it tends to the continuous optimum
    ``12 L^2/T^3`` as ``O(h^2)``.
    """
    T, L = duration, distance
    h = T / n_nodes
    beta = 12.0 * L / (T * (T**2 - h**2))
    t_mid = (np.arange(n_nodes) + 0.5) * h
    return beta * (T / 2 - t_mid), L * beta
