"""Pendulum swing-up in minimum time with a torque limit (the interval duration is a
single decision variable).

State ``theta`` (rad, 0 = hanging down), ``omega`` (rad/s); input ``tau`` (N m). Parameters:
mass 1 kg at length 1 m, viscous damping 0.1 N m s, gravity 9.81 m/s^2.
"""

from __future__ import annotations

from typing import Any

import casadi as cs
import numpy as np

from horizon_mpc.problem import Problem

__all__ = ["build_pendulum_min_time", "energy_pumping_guess", "pendulum_dynamics"]

MASS, LENGTH, DAMPING, GRAVITY = 1.0, 1.0, 0.1, 9.81


def pendulum_dynamics(theta: Any, omega: Any, tau: Any) -> Any:
    """Angular acceleration of the damped point-mass pendulum (SX or float)."""
    sin = cs.sin if isinstance(theta, (cs.SX, cs.MX)) else np.sin
    return (tau - DAMPING * omega - MASS * GRAVITY * LENGTH * sin(theta)) / (MASS * LENGTH**2)


def energy_pumping_guess(n_nodes: int, tau_max: float, h: float = 1e-3,
                         t_max: float = 20.0) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """A physically sensible initial guess: roll out ``tau = tau_max sign(omega)`` (pump
    energy) until the upright energy is reached, then coast to the top.

    Returns:
        ``(T, theta (N+1,), omega (N+1,), tau (N,))`` resampled on ``n_nodes`` intervals,
        mirrored so that the swing ends near ``theta = +pi``.
    """
    th = om = t = 0.0
    samples = [(0.0, 0.0, 0.0, tau_max)]
    e_up = 2.0 * MASS * GRAVITY * LENGTH
    while abs(th) < np.pi and t < t_max:  # semi-implicit Euler on a fine grid
        energy = 0.5 * MASS * LENGTH**2 * om**2 + MASS * GRAVITY * LENGTH * (1 - np.cos(th))
        tau = 0.0 if energy >= e_up else tau_max * (np.sign(om) if om != 0.0 else 1.0)
        om += h * pendulum_dynamics(th, om, tau)
        th += h * om
        t += h
        samples.append((t, th, om, tau))
    s = np.array(samples) * np.array([1.0, *([np.sign(th) or 1.0] * 3)])
    grid = np.linspace(0.0, t, n_nodes + 1)
    return (t, np.interp(grid, s[:, 0], s[:, 1]), np.interp(grid, s[:, 0], s[:, 2]),
            np.interp(grid[:-1], s[:, 0], s[:, 3]))


def build_pendulum_min_time(n_nodes: int = 50, tau_max: float = 5.0,
                            time_bounds: tuple[float, float] = (0.5, 6.0),
                            w_effort: float = 1e-2, guess: str = "pumping",
                            transcription: str = "multiple_shooting", integrator: str | None = None,
                            degree: int | None = None) -> tuple[Problem, dict]:
    """Swing the pendulum from rest down to rest upright as fast as ``|tau| <= tau_max``
    allows (``tau_max`` below ``m g l`` forces pumping swings).

    The interval duration is the single variable ``dt``; the total time ``T = n_nodes * dt``
    is bounded by ``time_bounds`` (s). Cost ``T^2 + w_effort * mean_k tau_k^2`` (``T^2`` has
    the same minimiser as ``T`` and keeps the cost a sum of squares; the small effort term
    makes the optimum unique where the torque is not saturated). Initial guess
    (``guess``): ``'pumping'`` = :func:`energy_pumping_guess`, or ``'linear'`` = the angle
    rising linearly to pi in 3 s, zero torque (much harder for Gauss-Newton solvers).

    Returns:
        ``(prb, {'theta': theta, 'omega': omega, 'tau': tau, 'dt': dt})``.
    """
    if guess not in ("pumping", "linear"):
        raise ValueError(f"guess must be 'pumping' or 'linear', got {guess!r}")
    prb = Problem(n_nodes)
    theta = prb.create_state_variable("theta", 1)
    omega = prb.create_state_variable("omega", 1)
    tau = prb.create_input_variable("tau", 1)
    dt = prb.create_single_variable("dt", 1)
    prb.set_dynamics(cs.vertcat(omega, pendulum_dynamics(theta, omega, tau)))
    prb.set_dt(dt)
    prb.transcribe(transcription, integrator=integrator, degree=degree)

    dt.set_bounds(time_bounds[0] / n_nodes, time_bounds[1] / n_nodes)
    tau.set_bounds(-tau_max, tau_max)
    theta.set_bounds(0.0, 0.0, nodes=0)
    omega.set_bounds(0.0, 0.0, nodes=0)
    if guess == "pumping":
        t_guess, th, om, ta = energy_pumping_guess(n_nodes, tau_max)
        theta.set_initial_guess(th[None, :])
        omega.set_initial_guess(om[None, :])
        tau.set_initial_guess(ta[None, :])
    else:
        t_guess = 3.0
        theta.set_initial_guess(np.linspace(0.0, np.pi, n_nodes + 1)[None, :])
        omega.set_initial_guess(np.pi / t_guess)
    dt.set_initial_guess(np.clip(t_guess, *time_bounds) / n_nodes)

    prb.create_final_constraint("goal", cs.vertcat(theta - np.pi, omega))
    prb.create_final_cost("time", n_nodes * dt)
    prb.create_cost("effort", tau, weight=w_effort / n_nodes)
    return prb, {"theta": theta, "omega": omega, "tau": tau, "dt": dt}
