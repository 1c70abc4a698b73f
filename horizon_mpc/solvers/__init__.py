"""Solvers behind one interface: ``make_solver(name, prb, opts)``.

``ipopt`` (CasADi nlpsol), ``gnsqp`` (sparse Gauss-Newton SQP) and ``ilqr``
(multiple-shooting constrained iterative LQR).
"""

from __future__ import annotations

import importlib
from typing import Any

from horizon_mpc.problem import Problem
from horizon_mpc.solvers.base import Solver, SolverStats

__all__ = ["SOLVERS", "Solver", "SolverStats", "make_solver"]

SOLVERS = {
    "ipopt": "horizon_mpc.solvers.ipopt:IpoptSolver",
    "gnsqp": "horizon_mpc.solvers.gnsqp:GnSqpSolver",
    "ilqr": "horizon_mpc.solvers.ilqr:IlqrSolver",
}


def make_solver(name: str, prb: Problem, opts: dict[str, Any] | None = None) -> Solver:
    """Build solver ``name`` for ``prb`` (the problem is frozen from then on).

    Raises:
        ValueError: unknown solver name or option.
    """
    if name not in SOLVERS:
        raise ValueError(f"unknown solver {name!r}; choose one of {sorted(SOLVERS)}")
    module, cls = SOLVERS[name].split(":")
    frozen = prb.finalized
    try:
        return getattr(importlib.import_module(module), cls)(prb, opts)
    except Exception:
        if not frozen:  # refused (a QP solver, an integrator's state layout...): the user
            prb._release()  # can still fix the problem
        raise
