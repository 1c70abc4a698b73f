"""Reference optimal-control problems, shared by tests, benchmarks and documentation.

Each ``build_*`` function returns ``(prb, v)``: a ready-to-solve
:class:`~horizon_mpc.problem.Problem` and a dict of its variables by name.
"""

from horizon_mpc.examples.cartpole import build_cartpole, cartpole_dynamics
from horizon_mpc.examples.double_integrator import (
    build_double_integrator,
    double_integrator_optimum,
)
from horizon_mpc.examples.pendulum import (
    build_pendulum_min_time,
    energy_pumping_guess,
    pendulum_dynamics,
)

__all__ = [
    "build_cartpole",
    "build_double_integrator",
    "build_pendulum_min_time",
    "cartpole_dynamics",
    "double_integrator_optimum",
    "energy_pumping_guess",
    "pendulum_dynamics",
]
