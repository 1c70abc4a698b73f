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


def __getattr__(name: str) -> object:
    # the API on first use: importing the package alone (a node's entry point, which takes
    # the signals first: horizon_mpc.nodes.launcher) does not import CasADi and numpy
    if name == "Problem":
        from horizon_mpc.problem import Problem
        return Problem
    if name == "make_solver":
        from horizon_mpc.solvers import make_solver
        return make_solver
    if not name.startswith("_"):  # a subpackage, as `import horizon_mpc` used to load some
        import importlib
        try:
            return importlib.import_module(f"horizon_mpc.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"horizon_mpc.{name}":
                raise
    raise AttributeError(f"module 'horizon_mpc' has no attribute {name!r}")
