"""The whole-body walking problem (the paper's receding-horizon trot) on the Problem API.

Read it next to the paper: variables, dynamics, feasibility (under-actuation), contact
schedule, costs, solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np

from horizon_mpc.config import RobotConfig
from horizon_mpc.locomotion.formulation import (
    ContactTerms,
    add_contacts,
    add_torque_limits,
    base_rotation,
    floating_base_double_integrator,
)
from horizon_mpc.locomotion.gaits import feet_order_error
from horizon_mpc.locomotion.settings import MpcSettings, Weights
from horizon_mpc.model import RobotModel
from horizon_mpc.posture import standing_configuration
from horizon_mpc.problem import InputVariable, Parameter, Problem, StateVariable

__all__ = ["WalkingProblem", "build_walking_problem"]



@dataclass
class WalkingProblem:
    """The walking OCP and handles on what changes from tick to tick."""

    prb: Problem
    model: RobotModel
    feet: list[str]
    settings: MpcSettings
    q: StateVariable  # (nq,) configuration
    v: StateVariable  # (nv,) velocity
    a: InputVariable  # (nv,) acceleration
    f: InputVariable  # (3 n_feet,) contact forces, world frame
    contacts: ContactTerms
    v_ref: Parameter  # (6,) base twist reference in the base frame
    pose_ref: Parameter  # (4,) x, y, cos(yaw), sin(yaw) reference
    height_ref: Parameter  # (1,) base height reference (m, world z)
    q_nominal: np.ndarray  # standing configuration (nq,)
    base_height: float

    @property
    def n_nodes(self) -> int:
        """Number of intervals N."""
        return self.prb.n_nodes

    def standing_guess(self, q0: np.ndarray) -> None:
        """Initial guess: stand still at ``q0`` with the weight shared by all feet."""
        nf = len(self.feet)
        self.q.set_initial_guess(q0)
        self.v.set_initial_guess(0.0)
        self.a.set_initial_guess(0.0)
        f0 = np.tile([0.0, 0.0, self.model.mass * 9.81 / nf], nf)
        self.f.set_initial_guess(f0)

    def set_weights(self, weights: Weights) -> None:
        """Apply a :class:`Weights` to the costs (live, no rebuild)."""
        w = weights
        costs = self.prb.costs
        costs["base_velocity"].set_weight([*w.base_linear_velocity, *w.base_angular_velocity])
        costs["base_height"].set_weight(w.base_height)
        costs["base_orientation"].set_weight(w.base_orientation)
        costs["base_position"].set_weight(w.base_position)
        costs["base_yaw"].set_weight(w.base_yaw)
        costs["posture"].set_weight(w.posture)
        costs["foot_lateral"].set_weight(w.foot_lateral)
        costs["joint_velocity"].set_weight(w.joint_velocity)
        costs["acceleration"].set_weight(w.acceleration)
        costs["forces"].set_weight(w.force)
        costs["final_posture"].set_weight(w.final_posture)
        for term in self.contacts.clearance.values():
            if hasattr(term, "set_weight"):
                term.set_weight(w.swing_height)


def build_walking_problem(model: RobotModel, cfg: RobotConfig,
                          settings: MpcSettings | None = None) -> WalkingProblem:
    """Build the walking OCP for ``model`` with the robot config ``cfg``."""
    st = settings or MpcSettings.from_config(cfg)
    feet = list(cfg.feet)
    _, q_nom = standing_configuration(cfg, model.pin_model)  # the model's own joints
    q_base = q_nom.copy()
    q_base[:7] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]  # the base frame at the origin
    order = feet_order_error(feet, [np.asarray(model.fk(foot)(q_base)[0]).ravel()[:2]
                                    for foot in feet])
    if order is not None:
        raise ValueError(f"{cfg.source or cfg.name}: {order}")
    h_nom = float(q_nom[2]) if st.base_height is None else float(st.base_height)
    mu = cfg.friction if st.friction is None else st.friction

    prb = Problem(st.n_nodes)
    q = prb.create_state_variable("q", model.nq)
    v = prb.create_state_variable("v", model.nv)
    a = prb.create_input_variable("a", model.nv)
    f = prb.create_input_variable("f", 3 * len(feet))
    prb.set_dynamics(floating_base_double_integrator(model, q, v, a))
    prb.set_dt(st.dt)
    prb.transcribe("multiple_shooting", integrator="euler")

    # feasibility: the base wrench of inverse dynamics vanishes (under-actuation)
    tau = model.inverse_dynamics(feet)(q, v, a, f)
    prb.create_constraint("underactuation", tau[:6], nodes=range(prb.n_nodes))
    if st.torque_limits:
        add_torque_limits(prb, model, tau[6:])
    contacts = add_contacts(prb, model, feet, q, v, f, mu,
                            clearance=None if st.clearance == "none" else st.clearance,
                            clearance_weight=st.weights.swing_height,
                            foot_radius=cfg.foot_radius)
    # joint limits from the URDF (those written as zero are none: RobotModel.unset_limits)
    q.set_bounds(model.q_lower, model.q_upper)
    v_lim = model.v_limit.copy()
    v_lim[:6] = np.inf
    v.set_bounds(-v_lim, v_lim)

    # costs: base motion, posture, regularisation
    v_ref = prb.create_parameter("v_ref", 6)
    pose_ref = prb.create_parameter("pose_ref", 4)
    height_ref = prb.create_parameter("height_ref", 1)
    R = base_rotation(q)
    prb.create_cost("base_velocity", v[:6] - v_ref)
    prb.create_cost("base_height", q[2] - height_ref)
    prb.create_cost("base_orientation", R[0:2, 2])  # body z-axis upright: roll, pitch
    prb.create_cost("base_position", q[0:2] - pose_ref[0:2])
    prb.create_cost("base_yaw", R[1, 0] * pose_ref[2] - R[0, 0] * pose_ref[3])  # sin(yaw-yaw_ref)
    prb.create_cost("posture", q[7:] - q_nom[7:])
    # each foot's lateral offset from the base (base frame) near its standing one: the
    # support polygon keeps its width (without it the walk's three-foot stances put the
    # swing feet under the body, step after step, until the hind legs crossed)
    lateral = cs.vertcat(*[cs.dot(R[:, 1], model.fk(foot)(q)[0] - q[0:3]) for foot in feet])
    lateral_nom = cs.Function("lateral", [q], [lateral])(q_nom)
    prb.create_cost("foot_lateral", lateral - lateral_nom)
    prb.create_cost("joint_velocity", v[6:])
    prb.create_cost("acceleration", a)
    prb.create_cost("forces", f)
    prb.create_final_cost("final_posture", q[7:] - q_nom[7:])
    wp = WalkingProblem(prb, model, feet, st, q, v, a, f, contacts, v_ref, pose_ref, height_ref,
                        q_nom, h_nom)
    wp.set_weights(st.weights)
    pose_ref.assign([0.0, 0.0, 1.0, 0.0])
    height_ref.assign(h_nom)
    wp.standing_guess(q_nom)
    contacts.set_schedule(np.ones((len(feet), prb.n_nodes + 1), bool),
                          np.zeros((len(feet), prb.n_nodes + 1)))
    return wp
