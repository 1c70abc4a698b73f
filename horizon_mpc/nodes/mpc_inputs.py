"""Validation of the MPC node's inputs: pure functions on ROS messages, no DDS needed.

Each function returns the numbers the controller needs plus a list of *notes* (repairs it
made, e.g. "normalised a quaternion of norm 1.2"), or raises ``ValueError`` naming what was
wrong. The node turns notes into throttled warnings and errors into a rejected message
(:mod:`horizon_mpc.nodes.mpc_node`, ``doc/mpc_node.md``). Conventions as in
:mod:`horizon_mpc.nodes.conversions`: quaternions ``(x, y, z, w)``, twist in the base frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState

from horizon_mpc.locomotion.command import DEFAULT_MAX_NORM, limit_command

__all__ = [
    "ABSURD_COMMAND",
    "JOINT_LIMIT_MARGIN",
    "QUATERNION_TOLERANCE",
    "NAMES_SHOWN",
    "LayoutNote",
    "base_from_odometry",
    "clipped",
    "command_from_twist",
    "joints_from_joint_state",
]

#: |vx|, |vy| (m/s) or |wz| (rad/s) above this is not a velocity command but garbage.
ABSURD_COMMAND = 10.0
#: A quaternion whose norm is further than this from 1 is normalised with a note.
QUATERNION_TOLERANCE = 1e-3
#: rad (or m): a joint further than this outside its URDF limits is a wrong reading.
JOINT_LIMIT_MARGIN = 0.5
#: rad/s (or m/s): a joint velocity beyond this is a wrong reading.
ABSURD_JOINT_VELOCITY = 1e3
#: m, m/s, rad/s: odometry position, linear or angular velocity beyond these is garbage.
ABSURD_POSITION, ABSURD_LINEAR, ABSURD_ANGULAR = 1e5, 100.0, 100.0


def command_from_twist(
    msg: Twist, limits: Sequence[float], max_norm: float = DEFAULT_MAX_NORM
) -> tuple[np.ndarray, list[str]]:
    """``(vx, vy, wz)`` (m/s, m/s, rad/s, base frame) of a ``cmd_vel`` Twist, limited.

    Only ``linear.x``, ``linear.y`` and ``angular.z`` are used (a note says when the other
    components are non-zero). Components beyond ``limits`` (3,) are clamped, and a command
    beyond the combined limit ``max_norm`` scaled down (:func:`limit_command`), with a note.

    Raises:
        ValueError: a non-finite component, or one beyond :data:`ABSURD_COMMAND`.
    """
    # three numbers: plain floats (numpy costs more than the work on arrays this small)
    raw = (float(msg.linear.x), float(msg.linear.y), float(msg.angular.z))
    names = ("linear.x", "linear.y", "angular.z")
    bad = [f"{n}={x}" for n, x in zip(names, raw, strict=True) if not math.isfinite(x)]
    if bad:
        raise ValueError(f"cmd_vel has non-finite components {', '.join(bad)}")
    absurd = [f"{n}={x:g}" for n, x in zip(names, raw, strict=True) if abs(x) > ABSURD_COMMAND]
    if absurd:
        raise ValueError(f"cmd_vel components {', '.join(absurd)} exceed the plausible "
                         f"{ABSURD_COMMAND:g} (m/s or rad/s)")
    notes = []
    if msg.linear.z != 0.0 or msg.angular.x != 0.0 or msg.angular.y != 0.0:
        notes.append("cmd_vel linear.z/angular.x/angular.y are ignored (planar command)")
    lim = [abs(float(x)) for x in limits]
    cmd = list(limit_command(raw, lim, max_norm))
    if cmd != list(raw):
        notes.append(f"cmd_vel {list(raw)} limited to {[round(c, 4) for c in cmd]} (limits "
                     f"{lim}, combined {max_norm:.3g})")
    return np.array(cmd), notes


#: names a note lists at most, each clipped to NAME_CHARS characters (a message with 200 000
#: extra joints made one 2 MB log line)
NAMES_SHOWN = 8
NAME_CHARS = 64


def clipped(name: str, limit: int = NAME_CHARS) -> str:
    """``name``, cut to ``limit`` characters with an ellipsis (for log lines)."""
    return name if len(name) <= limit else name[:limit - 3] + "..."


class LayoutNote(str):
    """A note on how a publisher lays out its messages (joints the model does not have),
    the same in every message: worth saying once, not every few seconds."""

    __slots__ = ()


@lru_cache(maxsize=16)
def _name_match(names: tuple[str, ...], joint_names: tuple[str, ...]) -> tuple[
        np.ndarray, list[str]]:
    """Indices of ``joint_names`` in ``names`` and the notes of that matching (cached: a
    robot sends the same names in every message).

    Raises:
        ValueError: a missing or duplicated joint.
    """
    index: dict[str, int] = {}
    duplicates = set()
    for i, n in enumerate(names):
        if n in index:
            duplicates.add(n)
        index[n] = i
    missing = [n for n in joint_names if n not in index]
    if missing and names and len(missing) == len(joint_names):
        shown = [clipped(n) for n in names[:NAMES_SHOWN]]
        more = f" and {len(names) - NAMES_SHOWN} more" if len(names) > NAMES_SHOWN else ""
        # the model's names under a prefix ('go2/FL_hip_joint'): the robot's own driver
        prefixed = next(((n, j) for n in names for j in joint_names
                         if n != j and n.endswith(j)), None)
        why = (f"names with a prefix? ({clipped(prefixed[0])!r} ends in {prefixed[1]!r}; the "
               "model's joint names are the URDF's)" if prefixed else
               "another driver's on the same topic (a gripper's?): the robot's own are then "
               "the ones that arrive between its messages")
        model = list(joint_names[:NAMES_SHOWN]) + (["..."] if len(joint_names) > NAMES_SHOWN
                                                    else [])
        raise ValueError(f"JointState has none of the model's joints {model} (it names "
                         f"{shown}{more}): {why}")
    if missing:
        raise ValueError(f"JointState lacks joints {missing}")
    needed_duplicates = sorted(duplicates & set(joint_names))
    if needed_duplicates:
        raise ValueError(f"JointState names joints {needed_duplicates} more than once")
    notes = []
    extra = sorted(set(names) - set(joint_names))
    if extra:
        shown = [clipped(n) for n in extra[:NAMES_SHOWN]]
        more = f" and {len(extra) - NAMES_SHOWN} more" if len(extra) > NAMES_SHOWN else ""
        notes.append(LayoutNote(f"JointState joints {shown}{more} are not in the model; "
                                "ignored"))
    idx = np.array([index[n] for n in joint_names], dtype=int)
    idx.flags.writeable = False  # shared by every call with these names
    return idx, notes


def joints_from_joint_state(
    msg: JointState, joint_names: Sequence[str],
    limits: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Joint positions and velocities (each (nj,), order of ``joint_names``), matched by name.

    Repaired with a note: extra joints (ignored), no velocities (zeros), non-finite
    velocities (zeros). Reordered joints are simply matched by name. ``limits``: the
    joints' (lower, upper) position limits (infinite for none).

    Raises:
        ValueError: a missing or duplicated joint, a position/velocity array whose length
            differs from ``msg.name``, a non-finite position, a position more than
            :data:`JOINT_LIMIT_MARGIN` outside its limits, or a velocity beyond
            :data:`ABSURD_JOINT_VELOCITY`.
    """
    names = tuple(msg.name)
    idx, name_notes = _name_match(names, tuple(joint_names))
    pos = np.asarray(msg.position, dtype=float)
    vel = np.asarray(msg.velocity, dtype=float)
    if pos.shape != (len(names),):
        raise ValueError(f"JointState.position has {pos.size} values for {len(names)} names")
    if vel.size and vel.shape != (len(names),):
        raise ValueError(f"JointState.velocity has {vel.size} values for {len(names)} names")
    notes = list(name_notes)
    if len(msg.effort) not in (0, len(names)):  # not used: said, not refused
        notes.append(LayoutNote(f"JointState.effort has {len(msg.effort)} values for "
                                f"{len(names)} names (efforts are not used)"))
    # the checks of a good reading first, in few numpy calls (a node reads every state a
    # driver sends, 500 Hz from the simulator); the details only when one fails
    qj = pos[idx]
    good = np.isfinite(qj)
    if limits is not None:  # (an infinite limit, a wheel's, lets inf through: hence both)
        good &= (qj >= limits[0] - JOINT_LIMIT_MARGIN) & (qj <= limits[1] + JOINT_LIMIT_MARGIN)
    good = good.all()
    if not good:
        _refuse_positions(qj, joint_names, limits)
    if not vel.size:
        notes.append("JointState has no velocities; using zeros")
        return qj, np.zeros(len(idx)), notes
    vj = vel[idx]
    if not (np.abs(vj) <= ABSURD_JOINT_VELOCITY).all():  # NaN fails too
        vj = _repaired_velocities(vj, joint_names, notes)
    return qj, vj, notes


def _refuse_positions(qj: np.ndarray, joint_names: Sequence[str],
                      limits: tuple[np.ndarray, np.ndarray] | None) -> None:
    """Raise the ValueError naming the non-finite or far out-of-limits positions."""
    if not np.isfinite(qj).all():
        bad = [n for n, x in zip(joint_names, qj, strict=True) if not math.isfinite(x)]
        raise ValueError(f"JointState has non-finite positions for {bad}")
    lo, hi = limits
    out = (qj < lo - JOINT_LIMIT_MARGIN) | (qj > hi + JOINT_LIMIT_MARGIN)
    bad = [f"{n}={x:g} (limits [{a:g}, {b:g}])" for n, x, a, b, o in
           zip(joint_names, qj, lo, hi, out, strict=True) if o]
    raise ValueError(f"JointState positions far outside the joint limits: {', '.join(bad)}")


def _repaired_velocities(vj: np.ndarray, joint_names: Sequence[str],
                         notes: list[str]) -> np.ndarray:
    """``vj`` with non-finite velocities zeroed (noted); raises the ValueError naming those
    beyond :data:`ABSURD_JOINT_VELOCITY`."""
    if not np.isfinite(vj).all():
        bad = [n for n, x in zip(joint_names, vj, strict=True) if not math.isfinite(x)]
        notes.append(f"JointState has non-finite velocities for {bad}; using zeros for those")
        vj = np.where(np.isfinite(vj), vj, 0.0)
    if (np.abs(vj) > ABSURD_JOINT_VELOCITY).any():
        bad = [f"{n}={x:g}" for n, x in zip(joint_names, vj, strict=True)
               if abs(x) > ABSURD_JOINT_VELOCITY]
        raise ValueError(f"JointState velocities beyond {ABSURD_JOINT_VELOCITY:g}: "
                         f"{', '.join(bad)}")
    return vj


def base_from_odometry(
    msg: Odometry,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """``(position (3,), quaternion (4,) unit, linear (3,), angular (3,), notes)`` of odom.

    The pose is in the world (``header.frame_id``), the twist in the base frame
    (``child_frame_id``), REP 105. A quaternion whose norm differs from 1 by more than
    :data:`QUATERNION_TOLERANCE` is normalised with a note.

    Raises:
        ValueError: a non-finite pose or twist component, or a (near-)zero quaternion.
    """
    p, o = msg.pose.pose.position, msg.pose.pose.orientation
    lin, ang = msg.twist.twist.linear, msg.twist.twist.angular
    position, orientation = (p.x, p.y, p.z), (o.x, o.y, o.z, o.w)
    linear, angular = (lin.x, lin.y, lin.z), (ang.x, ang.y, ang.z)
    # a good reading in plain floats (a node reads every state a driver sends); the
    # checks that name the problem only when these fail (NaN fails every comparison)
    if not (_within(position, ABSURD_POSITION) and all(map(math.isfinite, orientation))
            and _within(linear, ABSURD_LINEAR) and _within(angular, ABSURD_ANGULAR)):
        _refuse_odometry(position, orientation, linear, angular)
    scale = max(map(abs, orientation))  # normalise in two steps: |q|^2 may overflow
    if scale < 1e-6:
        raise ValueError(f"Odometry orientation is a zero quaternion {list(orientation)}")
    scaled = [c / scale for c in orientation]
    scaled_norm = math.sqrt(sum(c * c for c in scaled))
    unit = np.array(scaled) / scaled_norm
    norm = scale * scaled_norm
    notes = []
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        notes.append(f"Odometry orientation has norm {norm:.6g}; normalised")
    x, y = unit[0], unit[1]
    if 1.0 - 2.0 * (x * x + y * y) < 0.0:  # the base z-axis points down
        notes.append("Odometry orientation has the base upside down: the walking plan "
                     "cannot recover from that")
    return np.array(position), unit, np.array(linear), np.array(angular), notes


def _within(values: tuple[float, ...], bound: float) -> bool:
    return all(-bound <= x <= bound for x in values)


def _refuse_odometry(position: tuple, orientation: tuple, linear: tuple,
                     angular: tuple) -> None:
    """Raise the ValueError naming the first non-finite or implausible part of an odom."""
    parts = (("position", position), ("orientation", orientation),
             ("linear twist", linear), ("angular twist", angular))
    for what, values in parts:
        if not all(map(math.isfinite, values)):
            raise ValueError(f"Odometry {what} is not finite: {[float(x) for x in values]}")
    for what, values, bound in (("position", position, ABSURD_POSITION),
                                ("linear twist", linear, ABSURD_LINEAR),
                                ("angular twist", angular, ABSURD_ANGULAR)):
        if not _within(values, bound):
            raise ValueError(f"Odometry {what} {[float(x) for x in values]} is beyond the "
                             f"plausible {bound:g}")
