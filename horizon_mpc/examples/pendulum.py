"""Pendulum swing-up in minimum time with a torque limit (the interval duration is a
single decision variable).

State ``theta`` (rad, 0 = hanging down), ``omega`` (rad/s); input ``tau`` (N m).
"""

from __future__ import annotations

import casadi as cs
import numpy as np

from horizon_mpc.problem import Problem

__all__ = ["build_pendulum_min_time", "pendulum_dynamics"]


def pendulum_dynamics(theta: cs.SX, omega: cs.SX, tau: cs.SX, mass: float = 1.0,
                      length: float = 1.0, damping: float = 0.1,
                      gravity: float = 9.81) -> cs.SX:
    """Angular acceleration (1,) of a damped point-mass pendulum."""
    return (tau - damping * omega - mass * gravity * length * cs.sin(theta)) / (mass * length**2)


def build_pendulum_min_time(n_nodes: int = 50, tau_max: float = 5.0,
                            time_bounds: tuple[float, float] = (0.5, 6.0), time_guess: float = 3.0,
                            w_effort: float = 1e-2,
                            transcription: str = "multiple_shooting", integrator: str = "rk4",
                            degree: int = 3) -> tuple[Problem, dict]:
    """Swing the pendulum from rest down to rest upright as fast as ``|tau| <= tau_max``
    allows (``tau_max`` below ``m g l`` forces pumping swings).

    The interval duration is the single variable ``dt``; the total time ``T = n_nodes * dt``
    is bounded by ``time_bounds`` (s) and guessed as ``time_guess`` (with the angle rising
    linearly to pi). Cost ``T^2 + w_effort * mean_k tau_k^2`` (``T^2`` has the same minimiser
    as ``T`` and keeps the cost a sum of squares; the small effort term makes the optimum
    unique where the torque is not saturated).

    Returns:
        ``(prb, {'theta': theta, 'omega': omega, 'tau': tau, 'dt': dt})``.
    """
    prb = Problem(n_nodes)
    theta = prb.create_state_variable("theta", 1)
    omega = prb.create_state_variable("omega", 1)
    tau = prb.create_input_variable("tau", 1)
    dt = prb.create_single_variable("dt", 1)
    prb.set_dynamics(cs.vertcat(omega, pendulum_dynamics(theta, omega, tau)))
    prb.set_dt(dt)
    prb.transcribe(transcription, integrator=integrator, degree=degree)

    dt.set_bounds(time_bounds[0] / n_nodes, time_bounds[1] / n_nodes)
    dt.set_initial_guess(time_guess / n_nodes)
    tau.set_bounds(-tau_max, tau_max)
    theta.set_bounds(0.0, 0.0, nodes=0)
    omega.set_bounds(0.0, 0.0, nodes=0)
    theta.set_initial_guess(np.linspace(0.0, np.pi, n_nodes + 1)[None, :])
    omega.set_initial_guess(np.pi / time_guess)

    prb.create_final_constraint("goal", cs.vertcat(theta - np.pi, omega))
    prb.create_final_cost("time", n_nodes * dt)
    prb.create_cost("effort", tau, weight=w_effort / n_nodes)
    return prb, {"theta": theta, "omega": omega, "tau": tau, "dt": dt}
