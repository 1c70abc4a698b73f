"""The walking MPC without ROS: :class:`WalkingMpc` (the ``mpc_node`` wraps it)."""

from horizon_mpc.mpc.controller import Plan, WalkingMpc
from horizon_mpc.mpc.schedule import GaitScheduler

__all__ = ["GaitScheduler", "Plan", "WalkingMpc"]
