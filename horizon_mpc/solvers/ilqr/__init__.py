"""Multiple-shooting constrained ILQR (see :mod:`horizon_mpc.solvers.ilqr.solver`)."""

from horizon_mpc.solvers.ilqr.solver import IlqrSolver

__all__ = ["IlqrSolver"]
