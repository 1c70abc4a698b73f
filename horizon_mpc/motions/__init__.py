"""The paper's three motions, solved offline: leap, 90-degree turn, receding-horizon walk.

Each motion is a small module on the locomotion building blocks (``doc/motions.md``):

* :mod:`.leap`: ``run_leap`` (go2 by default, IPOPT, finite horizon);
* :mod:`.turn`: ``run_turn`` (CENTAURO by default, IPOPT, finite horizon);
* :mod:`.walk`: ``run_walk`` (go2, ILQR in receding horizon; IPOPT and GN-SQP too).

They return a :class:`MotionResult`; :func:`write_outputs` writes its solution, plots,
animation and summary; :func:`dynamics_check` verifies it with numeric Pinocchio. The
``motion`` executable (:mod:`.cli`) does all of it from the command line.
"""

from horizon_mpc.motions.analysis import dynamics_check
from horizon_mpc.motions.leap import LeapSettings, run_leap
from horizon_mpc.motions.output import write_outputs
from horizon_mpc.motions.result import MotionResult
from horizon_mpc.motions.settings import load_motion_config
from horizon_mpc.motions.turn import TurnSettings, run_turn
from horizon_mpc.motions.walk import WalkSettings, run_walk

__all__ = [
    "LeapSettings",
    "MotionResult",
    "TurnSettings",
    "WalkSettings",
    "dynamics_check",
    "load_motion_config",
    "run_leap",
    "run_turn",
    "run_walk",
    "write_outputs",
]
