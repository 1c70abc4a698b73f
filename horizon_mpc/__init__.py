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

from horizon_mpc.problem import Problem  # noqa: E402
from horizon_mpc.solvers import make_solver  # noqa: E402

__version__ = "0.1.0"

__all__ = ["Problem", "__version__", "make_solver"]
