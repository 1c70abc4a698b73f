"""Horizon-style optimal-control problems: variables on nodes, dynamics, constraints, costs."""

from horizon_mpc.problem.integrators import INTEGRATORS, euler, leapfrog, rk2, rk4
from horizon_mpc.problem.problem import Problem
from horizon_mpc.problem.terms import Constraint, Cost, GeneralCost
from horizon_mpc.problem.variables import (
    InputVariable,
    Parameter,
    SingleVariable,
    StateVariable,
)

__all__ = [
    "INTEGRATORS",
    "Constraint",
    "Cost",
    "GeneralCost",
    "InputVariable",
    "Parameter",
    "Problem",
    "SingleVariable",
    "StateVariable",
    "euler",
    "leapfrog",
    "rk2",
    "rk4",
]
