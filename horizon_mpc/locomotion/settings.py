"""Settings of the walking problem: the ``mpc:`` section of ``config/<robot>.yaml``.

Every field has a default that suits a ~15 kg quadruped; robot configs override what
they need. Weights multiply squared residuals (SI units: m, rad, m/s, rad/s, N).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from horizon_mpc.config import (
    RobotConfig,
    check_settings,
    did_you_mean,
    field_default,
    finite_number,
    merged,
)
from horizon_mpc.locomotion.command import DEFAULT_MAX_NORM
from horizon_mpc.locomotion.gaits import GAITS, Gait, make_gait

__all__ = ["DT_RANGE", "ITERATIONS_RANGE", "MAX_COMMAND_NORM", "MAX_VELOCITY", "MAX_WEIGHT",
           "MIN_COMMAND_NORM", "MIN_DUTY_FACTOR", "N_NODES_RANGE", "STEP_DURATION_RANGE",
           "STEP_HEIGHT_RANGE", "GaitSettings", "MpcSettings", "Weights", "config_gait"]

#: the largest max_command_norm (>= sqrt(3) already leaves the per-axis limits alone)
MAX_COMMAND_NORM = 10.0
# The ranges of the settings the MPC node also takes as parameters (it declares them with
# these): a config value outside one was refused by the node only, as a parameter the user
# never set, while the library and the motion CLI ran it (a walk of 1 node 'solved')
N_NODES_RANGE = (2, 500)
DT_RANGE = (0.001, 0.5)  # s
ITERATIONS_RANGE = (1, 50)
STEP_DURATION_RANGE = (0.05, 2.0)  # s
STEP_HEIGHT_RANGE = (0.0, 0.3)  # m
MIN_DUTY_FACTOR = 0.05
MAX_VELOCITY = 5.0  # m/s or rad/s, each command limit
MIN_COMMAND_NORM = 0.01
#: a cost weight above this is refused: w_posture 1e30 made the cost 1e32, the solver fail
#: every tick and go2 sink to the ground (1e8 was harmless; the configs use up to ~1e4)
MAX_WEIGHT = 1e9


def _within(name: str, value: float, bounds: tuple[float, float]) -> None:
    lo, hi = bounds
    if not lo <= value <= hi:
        raise ValueError(f"setting {name!r} must be in [{lo:g}, {hi:g}], got {value!r}")


#: the walking problem's swing clearance and inequality treatments
CLEARANCES = ("cost", "constraint", "none")
INEQUALITIES = ("barrier", "lagrangian")


@dataclass
class GaitSettings:
    """Gait of the walking MPC (see :mod:`horizon_mpc.locomotion.gaits`)."""

    name: str = "trot"
    step_duration: float = 0.3
    # stance fraction of a cycle; None: the gait's own (gaits.GAITS: walk 0.75, the others
    # 0.5; a fixed 0.5 made the 'walk' gait a two-foot gait)
    duty_factor: float | None = None
    step_height: float = 0.07

    def __post_init__(self) -> None:
        check_settings(self, positive=("step_duration",), non_negative=("step_height",),
                       prefix="mpc.gait.")
        if not isinstance(self.name, str) or self.name not in GAITS:
            raise ValueError(f"'mpc.gait.name' must be one of {list(GAITS)}, got {self.name!r}"
                             f"{did_you_mean(self.name, list(GAITS))}")
        _within("mpc.gait.step_duration", self.step_duration, STEP_DURATION_RANGE)
        _within("mpc.gait.step_height", self.step_height, STEP_HEIGHT_RANGE)
        if self.duty_factor is not None and not (
                isinstance(self.duty_factor, (int, float)) and not isinstance(
                    self.duty_factor, bool) and MIN_DUTY_FACTOR <= self.duty_factor <= 1):
            raise ValueError(f"'mpc.gait.duty_factor' must be in [{MIN_DUTY_FACTOR:g}, 1] (or "
                             f"null: the gait's own), got {self.duty_factor!r}")

    def to_gait(self, n_feet: int) -> Gait:
        """The :class:`~horizon_mpc.locomotion.gaits.Gait` of these settings for ``n_feet``
        feet (ValueError: an unknown gait name)."""
        return make_gait(self.name, self.step_duration, self.step_height, self.duty_factor,
                         n_feet)


@dataclass
class Weights:
    """Cost weights (per residual row where a list is given)."""

    # lateral stepping needs a stronger pull than forward trotting to reach the command
    base_linear_velocity: list[float] = field(default_factory=lambda: [40.0, 100.0, 10.0])
    base_angular_velocity: list[float] = field(default_factory=lambda: [2.0, 2.0, 10.0])
    # the barrier of the joint limits and friction cones pulls the base down (at 100 go2
    # stood 11 % low, solo12 8 %); 1000 holds it within 3 % (doc/locomotion.md)
    base_height: float = 1000.0
    base_orientation: float = 100.0
    # the position reference integrates the command: a strong pull on it is the integral
    # action that removes the steady-state velocity error of the real robot
    base_position: float = 50.0
    base_yaw: float = 5.0
    posture: float = 0.3
    # each foot's lateral offset from the base (base frame) against its standing one: keeps
    # the support polygon wide. Without it the walk (three feet down, the CoM on the edge of
    # their triangle) landed its swing feet under the body rather than sway it: go2's hind
    # feet crossed (stance width -0.25 of the standing one, walking or stepping in place)
    # and robots tipped over once stopped on them (go2, solo12, anymal_b). At 100 the walk's
    # sideways speed dropped (go2 0.20 of 0.25 m/s, 0.22 at 30)
    foot_lateral: float = 30.0
    joint_velocity: float = 0.01
    acceleration: float = 3e-4
    force: float = 1e-5
    swing_height: float = 500.0
    final_posture: float = 5.0

    def __post_init__(self) -> None:
        """Each weight a finite number >= 0, a per-row one as many as its default has
        (they were checked when the problem was built, naming a cost and not the key:
        ``force: "x"`` was 'could not convert string to float')."""
        for f in fields(self):
            value, default = getattr(self, f.name), field_default(f)
            name = f"mpc.weights.{f.name}"
            if isinstance(default, list):
                if not (isinstance(value, (list, tuple, np.ndarray)) and _flat(value)
                        and len(value) == len(default)
                        and all(finite_number(x) and 0 <= x <= MAX_WEIGHT for x in value)):
                    raise ValueError(f"setting {name!r} must be {len(default)} numbers in "
                                     f"[0, {MAX_WEIGHT:g}] (one per row), got {value!r}")
            elif not (finite_number(value) and 0 <= value <= MAX_WEIGHT):
                raise ValueError(f"setting {name!r} must be a number in [0, {MAX_WEIGHT:g}], "
                                 f"got {value!r}")


@dataclass
class MpcSettings:
    """Horizon, gait, weights and limits of the walking MPC."""

    # 0.48 s, a little over one trot step pair (Crocoddyl's go2 MPC example plans 0.56 s):
    # go2, solo12 and anymal_c walk every command of the lockstep sweep of
    # doc/locomotion.md with 24 nodes as with 30 or 40, at 0.8x the work of 30
    n_nodes: int = 24
    dt: float = 0.02
    friction: float | None = None  # None: the robot config's friction
    base_height: float | None = None  # None: the nominal standing height
    gait: GaitSettings = field(default_factory=GaitSettings)
    weights: Weights = field(default_factory=Weights)
    clearance: str = "cost"  # 'cost', 'constraint' or 'none'
    torque_limits: bool = True
    # command limits vx, vy (m/s), wz (rad/s): what the go2 trot sustains in the lockstep
    # sweep of doc/locomotion.md (0.8-1.0 m/s forward and 1.0 rad/s while walking fell)
    max_velocity: list[float] = field(default_factory=lambda: [0.6, 0.5, 0.8])
    # the combined limit: the command's norm, each axis divided by its max_velocity, is at
    # most this (locomotion/command.py; sqrt(2): two axes at their limits, not three)
    max_command_norm: float = DEFAULT_MAX_NORM
    max_acceleration: list[float] = field(default_factory=lambda: [1.0, 1.0, 2.0])
    # m, rad: the pose reference (integrated from the command, the integral action of the
    # velocity tracking) is kept this close to the measured pose, so it never winds up;
    # at 0.15 m it saturated walking backwards (go2 -0.22 m/s for -0.3, -0.28 at 0.4 m)
    pose_leash: float = 0.4
    yaw_leash: float = 0.3
    stand_when_idle: bool = True
    # m (and rad): a measured base pose this far from the plan's (beyond 2 m/s and 3 rad/s
    # of motion since the last tick) is a reset or a glitch of the state estimate, not
    # motion: the controller restarts from it rather than chase the old pose (0.3 until
    # session 26: a reset 0.13-0.27 m from the start pose was walked again; pushes of 30 %
    # of the weight move the base by millimetres a tick)
    pose_jump: float = 0.1
    rho_init: float = 100.0
    # inequality rows (friction cones, torque and joint limits) in the ILQR: 'barrier' (a
    # relaxed log barrier, smooth: one iteration per tick walks every command of the lockstep
    # sweep of doc/locomotion.md) or 'lagrangian' (the augmented Lagrangian: exact at
    # convergence, but its active set switches between ticks; with one iteration per tick
    # the go2 fell on 9 of 13 sweep commands; two iterations walked all 13)
    inequality: str = "barrier"
    barrier_mu: float = 1.0  # weight of the barrier terms
    barrier_delta: float = 1.0  # slack (units of each row: N, N m, rad) where it turns quadratic
    # ILQR iterations per tick: one walks the 13 commands of the lockstep sweep of
    # doc/locomotion.md with the barrier (with the augmented Lagrangian it took two)
    iterations: int = 1
    # split the last iteration of a tick (real-time iteration, WalkingMpc.prepare): its
    # quadratisation and backward pass run after the previous plan went out, so a tick's
    # latency is one rollout and line search from the measured state (~1 ms against ~5).
    # The lockstep sweep walks 13 of 13 commands this way (go2, solo12, anymal_c)
    prepare_ahead: bool = True
    # s: a state stamped this far from the prepared tick time is predicted to it with the
    # plan's acceleration; further away, the tick runs whole on the state's own time. 0 by
    # default: the node plans from the state stamped at the prepared time when it has one
    # (mpc_node._state_pair), and a prediction (5 ms allowed until session 21) made solo12
    # fall at its 0.4 m/s limit in real time (2 of 2; 0 of 2 without) and in delayed
    # lockstep loops at the limits and in the walk gait (solo12, anymal_c, go2, go1, hyq)
    max_extrapolation: float = 0.0
    # s: a state stamped this close to the prepared tick time (and not predicted, above)
    # gets the prepared step as it is: the plan starts at the state's own time, with the
    # references and contacts prepared for the tick time, |offset| away (a tenth of a node
    # at 2 ms). A robot's driver stamps its states when it measures them, never on the
    # node's tick times: without it every tick ran whole (2x the work) and the node warned
    # of prepare misses forever (a 500 Hz driver: 96 of 97 ticks)
    feedback_tolerance: float = 0.002

    def __post_init__(self) -> None:
        check_settings(self, positive=("dt", "friction", "base_height", "barrier_mu",
                                       "barrier_delta", "rho_init", "pose_jump",
                                       "max_command_norm"),
                       non_negative=("pose_leash", "yaw_leash", "max_extrapolation",
                                     "feedback_tolerance"),
                       prefix="mpc.")
        if not MIN_COMMAND_NORM <= self.max_command_norm <= MAX_COMMAND_NORM:
            raise ValueError(f"'mpc.max_command_norm' must be in [{MIN_COMMAND_NORM:g}, "
                             f"{MAX_COMMAND_NORM:g}] (>= 1.733 keeps the per-axis limits "
                             f"only), got {self.max_command_norm!r}")
        _within("mpc.dt", self.dt, DT_RANGE)
        for name, (lo, hi) in (("n_nodes", N_NODES_RANGE), ("iterations", ITERATIONS_RANGE)):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi):
                raise ValueError(f"'mpc.{name}' must be an integer in [{lo}, {hi}], got "
                                 f"{value!r}")
        for name, top in (("max_velocity", MAX_VELOCITY), ("max_acceleration", math.inf)):
            value = getattr(self, name)
            if not (isinstance(value, (list, tuple)) and len(value) == 3 and all(
                    finite_number(x) and 0 <= x <= top for x in value)):
                within = ">= 0" if top == math.inf else f"in [0, {top:g}]"
                raise ValueError(f"'mpc.{name}' must be 3 numbers {within} (vx, vy, wz), got "
                                 f"{value!r}")
        # choices ('bogus' failed at the build; flags: check_settings)
        for name, choices in (("clearance", CLEARANCES), ("inequality", INEQUALITIES)):
            if getattr(self, name) not in choices:
                raise ValueError(f"'mpc.{name}' must be one of {list(choices)}, got "
                                 f"{getattr(self, name)!r}")

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> MpcSettings:
        """Settings from a YAML mapping; unknown keys raise ``ValueError`` naming them."""
        data = _checked(data, cls, "mpc")
        gait = GaitSettings(**_checked(data.pop("gait", {}), GaitSettings, "mpc.gait"))
        weights = Weights(**_checked(data.pop("weights", {}), Weights, "mpc.weights"))
        return cls(gait=gait, weights=weights, **data)

    @classmethod
    def from_config(cls, cfg: RobotConfig, overrides: dict[str, Any] | None = None
                    ) -> MpcSettings:
        """The settings of a robot config's ``mpc:`` section with ``overrides`` merged in
        key by key (``{gait: {name: walk}}`` changes the gait's name only); a ``ValueError``
        names the config file (it named the key only)."""
        section = cfg.section("mpc")
        if section is None:  # 'mpc:' with nothing under it (it dropped the overrides)
            section = {}
        try:  # (a section that is no mapping: from_dict says so)
            return cls.from_dict(merged(section, overrides or {})
                                 if isinstance(section, dict) else section)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{cfg.source or f'robot config {cfg.name!r}'}: {exc}") from None


def _check(data: dict, cls: type, where: str) -> None:
    names = {f.name for f in fields(cls)}
    unknown = set(data) - names
    if unknown:
        shown = ", ".join(f"{str(k)!r}{did_you_mean(k, sorted(names))}"
                          for k in sorted(unknown, key=str))
        raise ValueError(f"unknown key(s) [{shown}] in '{where}'; known: {sorted(names)}")


def _flat(value: Any) -> bool:
    """A flat sequence (a ragged one was numpy's 'setting an array element' error)."""
    return all(not isinstance(x, (list, tuple, dict, np.ndarray)) for x in value)


def _checked(data: Any, cls: type, where: str) -> dict:
    if data is not None and not isinstance(data, dict):
        raise ValueError(f"'{where}' must be a mapping of {sorted(f.name for f in fields(cls))}"
                         f", got {data!r}")
    data = dict(data or {})
    _check(data, cls, where)
    return data


def config_gait(cfg: RobotConfig) -> Gait:
    """The gait of a robot config's ``mpc.gait`` section: the one its ``mpc.max_velocity``
    was tuned with (:func:`horizon_mpc.locomotion.gaits.speed_scale`)."""
    return MpcSettings.from_config(cfg).gait.to_gait(len(cfg.feet))
