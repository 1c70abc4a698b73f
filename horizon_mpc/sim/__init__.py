"""PyBullet simulator of the robots horizon_mpc controls (no ROS dependency).

See ``doc/simulator.md`` for conventions and the API. The names below are imported lazily, so
that ``horizon_mpc.sim.trajectory`` (pure numpy, used by the ROS message conversions) can be
imported without loading pybullet and Pinocchio.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["JointTrajectoryCommand", "ReferenceGenerator", "SimState", "Simulator", "write_gif"]

_WHERE = {
    "JointTrajectoryCommand": "horizon_mpc.sim.trajectory",
    "ReferenceGenerator": "horizon_mpc.sim.trajectory",
    "SimState": "horizon_mpc.sim.simulator",
    "Simulator": "horizon_mpc.sim.simulator",
    "write_gif": "horizon_mpc.sim.render",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(_WHERE[name]), name)
    raise AttributeError(f"module 'horizon_mpc.sim' has no attribute {name!r}")
