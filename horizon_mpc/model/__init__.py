"""Symbolic robot model: URDF -> CasADi Functions of kinematics and dynamics.

See ``doc/model.md`` for conventions and examples.
"""

from horizon_mpc.model.robot_model import FIXED_BASE_ROBOTS, RobotModel, UnknownNameError

__all__ = ["RobotModel", "UnknownNameError", "FIXED_BASE_ROBOTS"]
