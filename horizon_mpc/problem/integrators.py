"""One-step integrators on (possibly manifold) state spaces.

Every integrator has the signature ``step(f, integrate, x, dt) -> x_next`` where
``f(x) -> xdot`` is the tangent-space time derivative (inputs, parameters held constant over
the step) and ``integrate(x, dx) -> x`` is the manifold's retraction (``x + dx`` on R^n).
Stages are combined in the tangent space at ``x`` and retracted once, so a quaternion in
the state stays unit norm whatever the integrator.

A user-supplied integrator with the same signature can be passed wherever a name is taken.
"""

from __future__ import annotations

from collections.abc import Callable

import casadi as cs

Derivative = Callable[[cs.SX], cs.SX]
Retraction = Callable[[cs.SX, cs.SX], cs.SX]
Integrator = Callable[[Derivative, Retraction, cs.SX, cs.SX], cs.SX]

__all__ = ["INTEGRATORS", "euler", "get_integrator", "leapfrog", "rk2", "rk4"]


def euler(f: Derivative, integrate: Retraction, x: cs.SX, dt: cs.SX) -> cs.SX:
    """Explicit Euler: ``x (+) dt f(x)``; order 1."""
    return integrate(x, dt * f(x))


def rk2(f: Derivative, integrate: Retraction, x: cs.SX, dt: cs.SX) -> cs.SX:
    """Explicit midpoint rule; order 2."""
    k1 = f(x)
    k2 = f(integrate(x, 0.5 * dt * k1))
    return integrate(x, dt * k2)


def rk4(f: Derivative, integrate: Retraction, x: cs.SX, dt: cs.SX) -> cs.SX:
    """Classical Runge-Kutta; order 4 on vector spaces."""
    k1 = f(x)
    k2 = f(integrate(x, 0.5 * dt * k1))
    k3 = f(integrate(x, 0.5 * dt * k2))
    k4 = f(integrate(x, dt * k3))
    return integrate(x, dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4))


def leapfrog(f: Derivative, integrate: Retraction, x: cs.SX, dt: cs.SX) -> cs.SX:
    """Kick-drift-kick leapfrog (velocity Verlet) for second-order systems; symplectic.

    The tangent space must split in two equal halves ``[position, velocity]`` whose
    position rate depends on the velocity only (``qdot = v``-like systems).
    """
    ndx = f(x).shape[0]
    if ndx % 2:
        raise ValueError(f"leapfrog needs a tangent space [position, velocity] of even "
                         f"dimension; got {ndx}")
    h = ndx // 2
    # the layout it needs, checked: the position rate must not read the position half
    # (states declared per axis, [x1, v1, x2, v2], gave a wrong step without a word)
    npos = x.shape[0] - h
    if cs.depends_on(f(x)[:h], x[:npos]):
        raise ValueError("leapfrog needs the states ordered [positions, velocities] with "
                         "position rates that depend on the velocities only (qdot = v); "
                         "these dynamics' first half depends on the first half of the state: "
                         "declare the positions first, or use rk4")
    zeros = cs.SX.zeros(h)
    # kick: half a step on the velocity
    x_half = integrate(x, cs.vertcat(zeros, 0.5 * dt * f(x)[h:]))
    # drift: full step on the position with the half-step velocity
    x_drift = integrate(x_half, cs.vertcat(dt * f(x_half)[:h], zeros))
    # kick: the second half step on the velocity
    return integrate(x_drift, cs.vertcat(zeros, 0.5 * dt * f(x_drift)[h:]))


INTEGRATORS: dict[str, Integrator] = {"euler": euler, "rk2": rk2, "rk4": rk4,
                                      "leapfrog": leapfrog}


def get_integrator(integrator: str | Integrator) -> Integrator:
    """An integrator by name (``euler``, ``rk2``, ``rk4``, ``leapfrog``) or a callable."""
    if callable(integrator):
        return integrator
    try:
        return INTEGRATORS[integrator]
    except KeyError:
        raise ValueError(f"unknown integrator {integrator!r}; choose one of "
                         f"{sorted(INTEGRATORS)} or pass a callable") from None
