"""Locomotion building blocks: gaits, contact terms, the walking problem and its MPC."""

from horizon_mpc.locomotion.formulation import (
    ContactTerms,
    add_contacts,
    add_torque_limits,
    base_rotation,
    floating_base_double_integrator,
)
from horizon_mpc.locomotion.gaits import GAITS, ContactSchedule, Gait, make_gait, speed_scale
from horizon_mpc.locomotion.settings import GaitSettings, MpcSettings, Weights, config_gait
from horizon_mpc.locomotion.walking import WalkingProblem, build_walking_problem

__all__ = [
    "GAITS",
    "ContactSchedule",
    "ContactTerms",
    "Gait",
    "GaitSettings",
    "MpcSettings",
    "WalkingProblem",
    "Weights",
    "add_contacts",
    "add_torque_limits",
    "base_rotation",
    "build_walking_problem",
    "config_gait",
    "floating_base_double_integrator",
    "make_gait",
    "speed_scale",
]
