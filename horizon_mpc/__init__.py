"""horizon_mpc: receding-horizon model-predictive control for legged robots.

A ROS 2 (Jazzy) ament_python package. The library modules (problem transcription, solvers,
robot models, simulator) are plain Python and never import ``rclpy``; only
``horizon_mpc.nodes`` and the closed-loop launcher bring ROS in.
"""

from horizon_mpc.problem import Problem
from horizon_mpc.solvers import make_solver

__version__ = "0.1.0"

__all__ = ["Problem", "__version__", "make_solver"]
