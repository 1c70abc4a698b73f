"""Nominal postures: SRDF reference configurations and a standing start on flat ground.

Configurations follow Pinocchio's convention, stated once in ``doc/model.md``:
``q = [base position (3), base quaternion (x, y, z, w), joint positions in model order]``.
Only numeric Pinocchio is used here (no CasADi), so the simulator can use it too.
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin

from horizon_mpc.config import RobotConfig, nearest_name
from horizon_mpc.model.loading import refuse_second_free_flyer
from horizon_mpc.robots import example_robot_files, known_robots

__all__ = ["config_urdf_path", "load_pin_model", "srdf_joint_values", "standing_configuration"]

log = logging.getLogger(__name__)


def config_urdf_path(cfg: RobotConfig) -> Path:
    """The URDF of ``cfg``: its ``urdf_path``, else its example-robot-data robot's."""
    if cfg.urdf_path:
        return Path(cfg.urdf_path)
    return example_robot_files(cfg.robot).urdf


def load_pin_model(cfg: RobotConfig, floating_base: bool = True) -> pin.Model:
    """The numeric Pinocchio model of ``cfg``'s URDF (free-flyer root by default)."""
    path = config_urdf_path(cfg)
    if not path.is_file():
        raise FileNotFoundError(f"URDF {str(path)!r} of robot config {cfg.name!r} does not exist")
    if floating_base:
        model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
        # (the simulator's path: a URDF floating joint was 'base_link is not the root link')
        refuse_second_free_flyer(model, f"URDF file {path}")
        return model
    return pin.buildModelFromUrdf(str(path))


def srdf_joint_values(srdf_path: str | Path, state_name: str) -> dict[str, float]:
    """Joint values of the SRDF ``<group_state name=state_name>``.

    Raises:
        KeyError: no such group state (the message lists the available ones).
    """
    root = ET.parse(str(srdf_path)).getroot()
    states = root.findall("group_state")
    for state in states:
        if state.get("name") == state_name:
            return {j.get("name"): float(j.get("value").split()[0]) for j in state.findall("joint")}
    names = sorted({s.get("name") for s in states})
    raise KeyError(f"no group_state {state_name!r} in {srdf_path}; available: {names}")


def _set_joint(model: pin.Model, q: np.ndarray, name: str, value: float) -> None:
    jid = model.getJointId(name)
    if jid >= model.njoints:
        return  # the SRDF may name joints the URDF variant does not have
    joint = model.joints[jid]
    if joint.nq == 1:
        q[joint.idx_q] = value
    elif joint.nq == 2 and joint.nv == 1:  # continuous joint stored as (cos, sin)
        q[joint.idx_q : joint.idx_q + 2] = (np.cos(value), np.sin(value))


def _outside_limits(model: pin.Model, q: np.ndarray) -> list[str]:
    """The one-dimensional joints of ``q`` outside their (non-empty) position limits."""
    out = []
    for j in range(2, model.njoints):
        joint = model.joints[j]
        if joint.nq != 1:
            continue
        i = joint.idx_q
        lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
        if lo < hi and not lo - 1e-9 <= q[i] <= hi + 1e-9:
            out.append(f"{model.names[j]}={q[i]:g} (limits [{lo:g}, {hi:g}])")
    return out


def standing_configuration(
    cfg: RobotConfig, model: pin.Model | None = None, clearance: float = 0.0
) -> tuple[pin.Model, np.ndarray]:
    """The robot standing on flat ground (z = 0) at its nominal posture.

    Joints come from the SRDF group state ``cfg.nominal_posture`` (if ``cfg.robot`` is an
    example robot that ships an SRDF: also for a URDF given in its place, by joint name),
    then ``cfg.nominal_joints`` overrides; a joint of the model they leave out stays at 0,
    with a warning. The base sits at x = y = 0 with identity
    orientation, at the height that puts the lowest contact frame of ``cfg.feet`` at
    ``clearance`` above the ground.

    Returns:
        ``(model, q)``: the free-flyer Pinocchio model and the configuration, shape (nq,).

    Raises:
        ValueError: a joint of ``nominal_joints`` the model does not have; a
            ``nominal_posture`` without an SRDF to read it from (a config with
            ``urdf_path:`` and no ``robot:``) while joints are left unset; a posture joint
            outside its URDF limits (a robot started there was refused as a wrong reading
            by the MPC at every state, and a lockstep simulator waited forever); a
            ``base_link`` that is neither the root link nor fixed to it.
        KeyError: a foot frame the model does not have (the message lists its links).
    """
    model = model if model is not None else load_pin_model(cfg)
    q = pin.neutral(model)
    values: dict[str, float] = {}
    # a URDF given instead of the example robot's (sim_node's urdf_path, a config's) keeps
    # its SRDF posture: the simulator started a go2 URDF with straight legs, which the MPC
    # (planning with the SRDF posture) refused as 1.5 rad outside the joint limits
    srdf = example_robot_files(cfg.robot).srdf if cfg.robot in known_robots() else None
    if srdf is not None and cfg.nominal_posture:
        values.update(srdf_joint_values(srdf, cfg.nominal_posture))
    unknown = [name for name in cfg.nominal_joints if not model.existJointName(name)
               or model.getJointId(name) < 2]
    if unknown:
        known = [model.names[j] for j in range(2, model.njoints)]
        hints = {name: nearest_name(name, known) for name in unknown}
        said = ", ".join(f"{name!r}" + (f" (did you mean {hint!r}?)" if hint else "")
                         for name, hint in hints.items())
        raise ValueError(f"config {cfg.name!r}: nominal_joints names joints the model does not "
                         f"have: {said}; its joints are {known}")
    values.update(cfg.nominal_joints)
    for name, value in values.items():
        _set_joint(model, q, name, value)
    unset = [model.names[j] for j in range(2, model.njoints) if model.joints[j].nq
             and model.names[j] not in values]
    if unset and cfg.nominal_posture and srdf is None:
        raise ValueError(f"config {cfg.name!r}: nominal_posture {cfg.nominal_posture!r} is an "
                         "SRDF group state, and there is no SRDF to read it from (no "
                         "example-robot-data 'robot:'): give every joint in nominal_joints "
                         f"(missing: {unset})")
    if values and unset:
        log.warning("config %r: the nominal posture leaves joints %s of the model at 0 (is "
                    "the URDF the config's robot?)", cfg.name, unset)
    outside = _outside_limits(model, q)
    if outside:
        raise ValueError(f"config {cfg.name!r}: the nominal posture puts joints outside their "
                         f"URDF limits: {', '.join(outside)} (a joint the posture leaves out "
                         "is at 0): set them in nominal_joints")
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    links = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
    missing = [f for f in cfg.feet if f not in links]
    if missing:
        raise KeyError(f"config {cfg.name!r}: foot frames {missing} are not links of the URDF "
                       f"(its links: {links})")
    # the base: the root link or one fixed to it (its pose and twist are the odometry's)
    base_links = [f.name for f in model.frames
                  if f.type == pin.FrameType.BODY and f.parentJoint <= 1]
    if cfg.base_link not in base_links:
        raise ValueError(f"config {cfg.name!r}: base_link {cfg.base_link!r} is not the URDF's "
                         f"root link or a link fixed to it (those are: {base_links})")
    lowest = min(data.oMf[model.getFrameId(f)].translation[2] for f in cfg.feet)
    q[2] = clearance - lowest
    return model, q
