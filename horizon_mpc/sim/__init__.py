"""PyBullet simulator of the robots horizon_mpc controls (no ROS dependency).

See ``doc/simulator.md`` for conventions and the API.
"""

from horizon_mpc.sim.render import write_gif
from horizon_mpc.sim.simulator import SimState, Simulator
from horizon_mpc.sim.trajectory import JointTrajectoryCommand, ReferenceGenerator

__all__ = ["JointTrajectoryCommand", "ReferenceGenerator", "SimState", "Simulator", "write_gif"]
