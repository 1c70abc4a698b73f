"""Integrator order and energy behaviour through ``Problem.discrete_dynamics``."""

from __future__ import annotations

import casadi as cs
import numpy as np
import pytest
import scipy.linalg

from horizon_mpc.problem import Problem

# a damped oscillator (eigenvalues -0.25 +- 1.98j): smooth, not symmetric, not trivial
A = np.array([[0.0, 1.0], [-4.0, -0.5]])
X0 = np.array([1.0, 0.0])
T_FINAL = 2.0


def step_function(integrator: str, xdot) -> cs.Function:
    """``F(x, u, s, p)`` of a problem whose dt is the parameter ``h``."""
    prb = Problem(1)
    x = prb.create_state_variable("x", 2)
    h = prb.create_parameter("h", 1)
    prb.set_dynamics(xdot(x))
    prb.set_dt(h)
    return prb.discrete_dynamics(integrator)


def final_state(F: cs.Function, h: float, n_steps: int, x0=X0) -> np.ndarray:
    # mapaccum: all steps in one CasADi call
    return F.mapaccum(n_steps)(x0, cs.DM(0, n_steps), cs.DM(0, 1), h).full()[:, -1]


@pytest.mark.parametrize(("integrator", "order"), [("euler", 1), ("rk2", 2), ("rk4", 4)])
def test_global_error_scales_with_the_order(integrator, order):
    F = step_function(integrator, lambda x: cs.mtimes(cs.DM(A), x))
    exact = scipy.linalg.expm(A * T_FINAL) @ X0
    steps = np.array([40, 80, 160, 320])
    errors = [np.linalg.norm(final_state(F, T_FINAL / n, n) - exact) for n in steps]
    slope = np.polyfit(np.log(T_FINAL / steps), np.log(errors), 1)[0]
    assert abs(slope - order) < 0.3, f"{integrator}: fitted order {slope:.2f}"


def oscillator_energy(x: np.ndarray) -> np.ndarray:
    return 0.5 * (x[0] ** 2 + x[1] ** 2)


def trajectory(integrator: str, h: float, n_steps: int) -> np.ndarray:
    F = step_function(integrator, lambda x: cs.vertcat(x[1], -x[0]))  # q'' = -q
    return F.mapaccum(n_steps)(X0, cs.DM(0, n_steps), cs.DM(0, 1), h).full()


def test_leapfrog_conserves_oscillator_energy_over_ten_thousand_steps():
    # symplectic: velocity Verlet exactly conserves (q^2 (1 - h^2/4) + v^2)/2, so the energy
    # error oscillates within h^2/4 * E0 = 3.1e-4 at h = 0.05, with no drift
    energy = oscillator_energy(trajectory("leapfrog", 0.05, 10_000))
    assert np.max(np.abs(energy - 0.5)) < 1e-3
    assert abs(np.mean(energy[-1000:]) - np.mean(energy[:1000])) < 1e-5


def test_euler_does_not_conserve_the_oscillator_energy():
    # the contrast: explicit Euler multiplies the energy by (1 + h^2) per step
    energy = oscillator_energy(trajectory("euler", 0.05, 10_000))
    assert energy[-1] > 1e5


def test_leapfrog_is_second_order():
    F = step_function("leapfrog", lambda x: cs.vertcat(x[1], -x[0]))
    exact = np.array([np.cos(T_FINAL), -np.sin(T_FINAL)])
    steps = np.array([40, 80, 160, 320])
    errors = [np.linalg.norm(final_state(F, T_FINAL / n, n) - exact) for n in steps]
    slope = np.polyfit(np.log(T_FINAL / steps), np.log(errors), 1)[0]
    assert abs(slope - 2) < 0.3


def test_leapfrog_refuses_states_not_ordered_positions_then_velocities():
    # declared per axis ([x1, v1], [x2, v2]) its step was silently wrong (0.27625 against
    # rk4's 0.275 for x1 after one step); the layout is now checked
    from horizon_mpc import make_solver

    prb = Problem(5)
    a = prb.create_state_variable("a", 2)
    b = prb.create_state_variable("b", 2)
    u = prb.create_input_variable("u", 2)
    prb.set_dynamics(cs.vertcat(a[1], u[0], b[1], u[1]))
    prb.set_dt(0.1)
    with pytest.raises(ValueError, match=r"\[positions, velocities\]"):
        prb.transcribe("multiple_shooting", integrator="leapfrog")
        make_solver("ipopt", prb)
