"""horizon_mpc: receding-horizon model-predictive control for legged robots.

A ROS 2 (Jazzy) ament_python package. The library modules (problem transcription, solvers,
robot models, simulator) are plain Python and never import ``rclpy``; only
``horizon_mpc.nodes`` and the closed-loop launcher bring ROS in.
"""

import os

# The solvers' hot loops are many small BLAS calls: a multi-threaded BLAS only adds
# contention on small machines (measured here: 7.5 ms vs 60 ms per Riccati pass at N=40).
# Effective when horizon_mpc is imported before numpy; users may override the variable.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from typing import TYPE_CHECKING  # noqa: E402

if TYPE_CHECKING:
    from horizon_mpc.problem import Problem
    from horizon_mpc.solvers import make_solver

__version__ = "0.1.0"

__all__ = ["Problem", "__version__", "make_solver"]


_API = {"Problem": "horizon_mpc.problem", "make_solver": "horizon_mpc.solvers"}


def __getattr__(name: str) -> object:
    # the API and subpackages on first use: importing the package alone (a node's entry
    # point, which takes the signals first: horizon_mpc.nodes.launcher) does not import
    # CasADi and numpy
    import importlib

    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    if not name.startswith("_"):
        try:
            return importlib.import_module(f"horizon_mpc.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"horizon_mpc.{name}":
                raise
    raise AttributeError(f"module 'horizon_mpc' has no attribute {name!r}")
