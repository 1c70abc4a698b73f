"""Parameters of :class:`~horizon_mpc.nodes.mpc_node.MpcNode`: declaration (with
descriptions and ranges, defaults from the robot config's ``mpc:`` section) and live
updates of the gait, command limits and cost weights (``ros2 param set``).

A mixin: the methods run on the node itself (an ``rclpy`` ``Node`` with an ``mpc``
attribute, the :class:`~horizon_mpc.mpc.controller.WalkingMpc`, once built).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    SetParametersResult,
)
from rclpy.parameter import Parameter

from horizon_mpc.locomotion import MpcSettings
from horizon_mpc.locomotion.gaits import EXPERIMENTAL_GAITS, GAITS
from horizon_mpc.locomotion.settings import (
    DT_RANGE,
    ITERATIONS_RANGE,
    MAX_COMMAND_NORM,
    MAX_VELOCITY,
    MAX_WEIGHT,
    MIN_COMMAND_NORM,
    MIN_DUTY_FACTOR,
    N_NODES_RANGE,
    STEP_DURATION_RANGE,
    STEP_HEIGHT_RANGE,
    Weights,
)
from horizon_mpc.nodes.declare import declare, float_range, int_range, parameter_overrides

__all__ = ["DIAGNOSTICS_RATE", "LIVE_GAIT", "LIVE_LIMITS", "MIN_DUTY_FACTOR",
           "MODEL_PARAMETERS", "MODEL_PARAMETER_DECLARATIONS", "WEIGHT_FIELDS", "MpcParameters",
           "gait_duty_factor", "gait_warnings", "parameter_names", "parameter_table",
           "horizon_for_rate", "limit_warnings", "timing_warnings", "weight_warnings"]

WEIGHT_FIELDS = [f.name for f in dataclasses.fields(Weights)]
LIVE_GAIT = ("gait", "step_duration", "step_height", "duty_factor")
LIVE_LIMITS = ("max_vx", "max_vy", "max_wz")
# declared by MpcNode itself, before the settings they choose are read: name, default,
# description (all read-only)
MODEL_PARAMETER_DECLARATIONS = (
    ("robot", "go2", "robot config name (config/<robot>.yaml) or YAML path"),
    ("config", "", "path of a robot config YAML (overrides 'robot')"),
    ("urdf_path", "", "URDF file of the robot model (overrides the config's URDF; the config "
     "still gives feet, posture, gains, weights)"),
    ("robot_description", "", "URDF XML text of the robot model, as robot_state_publisher's "
     "parameter (overrides urdf_path)"),
)
MODEL_PARAMETERS = tuple(d[0] for d in MODEL_PARAMETER_DECLARATIONS)
# Hz of the node clock: a status every fifth 50 Hz tick (diagnostic tools poll at ~1 Hz);
# its values summarise the ticks in between (solve_time_max_ms, ticks, deadline_misses)
DIAGNOSTICS_RATE = 10.0


# where the walking MPC was seen to walk and to fall (go2, lockstep, forward 0.3 m/s and a
# turn; doc/mpc_node.md): the accepted ranges are wider, the node warns outside these
# s: 0.008 (60 nodes, 125 Hz, session 24) to 0.025 walked for every robot tried; go2 and
# anymal_c walked at 0.03 and 0.035, solo12 fell at 0.03 (session 28 audit), go2 at 0.04
WALKED_DT = (0.008, 0.025)
# 20 and 24 walked; 16 walked in lockstep but fell in real time (3.4-3.8 s, 3 of 3 runs,
# session 20); 12 fell
WALKED_MIN_NODES = 20
# 25 Hz at dt 0.02 (2 nodes a tick) walked the default profile (go2, a1, solo12); 10 Hz (5)
# fell: go2 at 12.4 s (2 of 2), a1 at 4.2 s, anymal_c at 2.6 s (solo12 walked); 5 Hz (10)
# fell (session 28 audit; 10 Hz had walked go2's shorter forward-and-turn run)
WALKED_MAX_NODES_PER_TICK = 2
# the trot, direct lockstep loop at 0.3 m/s for 5 s (session 23): step durations 0.15-0.7 s
# walked (0.1 fell at 4.3 s, 0.8 at 2.6 s), duty factors 0.15-0.9 (0.1 fell at 2.6 s);
# weights up to ~1000x their library defaults (base_position at 1000x, posture at 1e4x,
# base_orientation at 1e4x), and it fell with base_position at 2e4x, posture and
# base_orientation at 1e6x and more
WALKED_STEP_DURATION = (0.15, 0.7)
WALKED_DUTY_FACTOR = (0.15, 0.9)
# other robots, default profile, lockstep (session 26 audit): a step of 2x their config's
# walked (solo12 0.4 s for its 0.2), longer ones fell (solo12 0.6 and 0.7 s, anymal_c 0.7
# s for its 0.3); solo12 fell with duty factor 0.2
WALKED_STEP_RATIO = 2.0
WALKED_MIN_DUTY_FACTOR_ALL = 0.25
WALKED_WEIGHT_RATIO = 1000.0


def gait_duty_factor(value: float) -> float | None:
    """The ``duty_factor`` parameter as a gait's duty factor: 0 is None (the gait's own).

    Raises:
        ValueError: a value in (0, MIN_DUTY_FACTOR).
    """
    if value and value < MIN_DUTY_FACTOR:
        raise ValueError(f"duty_factor {value} is below {MIN_DUTY_FACTOR} (0: the gait's own)")
    return float(value) or None


def gait_warnings(gait: str, step_duration: float | None = None,
                  duty_factor: float | None = None,
                  config_step: float | None = None) -> list[str]:
    """What is known to go wrong with ``gait`` and, when given, its step duration (s) and
    duty factor (None or 0: the gait's own) outside where the trot walked, also relative to
    ``config_step``, the robot config's own step duration (empty when nothing is)."""
    out = []
    if gait in EXPERIMENTAL_GAITS:
        out.append(f"gait {gait!r} is experimental: it does not walk in the lockstep closed "
                   f"loop ({EXPERIMENTAL_GAITS[gait]}; doc/locomotion.md); trot and walk do")
    if gait == "stand":
        return ["gait 'stand': the feet stay down and cmd_vel is not followed"]
    if duty_factor is not None and duty_factor >= 1.0:
        return [f"duty_factor {duty_factor:g}: gait {gait!r} never lifts a foot (it stands, "
                "like gait 'stand') and cmd_vel is not followed"]
    lo, hi = WALKED_STEP_DURATION
    if step_duration is not None and not lo <= step_duration <= hi:
        out.append(f"step_duration {step_duration:g} s is outside {lo:g}-{hi:g} s, where the "
                   "go2 trot walked (0.1 and 0.8 s fell in the lockstep loop)")
    elif step_duration is not None and config_step and not (
            config_step / WALKED_STEP_RATIO <= step_duration
            <= WALKED_STEP_RATIO * config_step + 1e-12):
        out.append(f"step_duration {step_duration:g} s is {step_duration / config_step:.3g}x the "
                   f"robot config's {config_step:g} s: robots walked within "
                   f"{1 / WALKED_STEP_RATIO:g}-{WALKED_STEP_RATIO:g}x theirs (solo12 fell at 3x, "
                   "anymal_c at 2.3x in the lockstep loop)")
    lo, hi = WALKED_DUTY_FACTOR
    if duty_factor and not lo <= duty_factor <= hi:
        out.append(f"duty_factor {duty_factor:g} is outside {lo:g}-{hi:g}, where the go2 trot "
                   "walked (0.1 fell in the lockstep loop)")
    elif duty_factor and duty_factor < WALKED_MIN_DUTY_FACTOR_ALL:
        out.append(f"duty_factor {duty_factor:g} is below {WALKED_MIN_DUTY_FACTOR_ALL:g}: the "
                   "go2 trot walked down to 0.15, solo12 fell at 0.2 in the lockstep loop")
    return out


def limit_warnings(limits: list[float], config_limits: list[float]) -> list[str]:
    """The command limits (max_vx, max_vy, max_wz) above the robot config's
    (``mpc.max_velocity``), the speeds its gait was tuned and seen to walk at (empty when
    none is): go2 fell at 0.7 m/s forward (its config: 0.6) and at 1.0 with no warning."""
    out = []
    for name, value, nominal, unit in zip(LIVE_LIMITS, limits, config_limits,
                                          ("m/s", "m/s", "rad/s"), strict=True):
        if value > nominal + 1e-9:
            out.append(f"{name} {value:g} {unit} is above the robot config's {nominal:g} "
                       "(mpc.max_velocity, where its gait was seen to walk): go2 fell at 0.7 "
                       "m/s forward in the lockstep loop (doc/locomotion.md)")
    return out


def weight_warnings(weights: Weights, names: list[str] | None = None) -> list[str]:
    """The weights (of ``names``, default all; without the ``w_`` prefix) more than
    WALKED_WEIGHT_RATIO times their library defaults (empty when none is). Entries whose
    default is 0 (a term off by default) have no walked scale and are not compared (a
    new term's weight 5 was called 5e+300x its default)."""
    defaults = Weights()
    out = []
    for n in WEIGHT_FIELDS if names is None else names:
        value = np.atleast_1d(np.asarray(getattr(weights, n), dtype=float))
        default = np.atleast_1d(np.asarray(getattr(defaults, n), dtype=float))
        value, default = np.broadcast_arrays(value, default)
        on = default != 0.0
        if not on.any():
            continue
        ratio = np.max(np.abs(value[on]) / np.abs(default[on]))
        if ratio > WALKED_WEIGHT_RATIO:
            shown = f"{float(value[0]):g}" if value.size == 1 else str(value.tolist())
            out.append(f"w_{n} {shown} is up to {ratio:.3g}x its library default: the go2 "
                       f"trot walked with weights up to ~{WALKED_WEIGHT_RATIO:g}x theirs and "
                       "fell at 2e4x and more (doc/mpc_node.md)")
    return out


def horizon_for_rate(dt: float, n_nodes: int, control_rate: float) -> tuple[float, int] | None:
    """``(dt, n_nodes)`` for a control rate faster than one node of ``dt`` per tick: the
    control period as the node interval and as many nodes as keep the horizon's duration,
    when that period is one the walking MPC was seen to walk with (``WALKED_DT``); else
    None. A tick of a fraction of a node made go2 fall (100 Hz at dt 0.02 s); at dt 0.01 s
    and 48 nodes it walked, and at 0.008 s and 60 nodes (125 Hz), in lockstep and in real
    time (doc/mpc_node.md)."""
    period = 1.0 / control_rate
    if not (period < dt - 1e-12 and period >= WALKED_DT[0] - 1e-12):
        return None
    return period, max(2, round(n_nodes * dt / period))


def timing_warnings(dt: float, n_nodes: int, period: float, publish_points: int
                    ) -> list[str]:
    """What in these timing settings is outside where the walking MPC was seen to walk, or
    cannot work: a trajectory that ends before the next tick (its last point, at
    ``(publish_points - 1) dt``, before the control period: the robot has no plan until
    then). ``period``: the control period (s), with trigger 'state' too (the preparation is
    for one period later, and a lockstep simulator steps by it); empty when all is well.
    Until session 28 the first two were said with trigger 'timer' only, and a trajectory
    of 5 points at 10 Hz (4 intervals, 0.08 s) passed."""
    out = []
    if (publish_points - 1) * dt < period - 1e-9:
        need = math.ceil(period / dt - 1e-9) + 1
        out.append(f"the published trajectory ({publish_points} points, dt {dt:g} s apart) "
                   f"ends before the next tick ({period:g} s later): the robot has no plan in "
                   f"between; set publish_points >= {need}")
    if period > WALKED_MAX_NODES_PER_TICK * dt + 1e-9:
        out.append(f"control_rate {1 / period:g} Hz moves the horizon {period / dt:.3g} nodes a "
                   f"tick: robots walked with up to {WALKED_MAX_NODES_PER_TICK} (25 Hz at dt "
                   "0.02 s); with 5 (10 Hz) go2, a1 and anymal_c fell, with 10 (5 Hz) go2 "
                   "flipped over")
    if not WALKED_DT[0] - 1e-12 <= dt <= WALKED_DT[1] + 1e-12:
        out.append(f"dt {dt:g} s: every robot tried walked with {WALKED_DT[0]:g}-"
                   f"{WALKED_DT[1]:g} s (solo12 fell with 0.03 s, go2 with 0.04 s)")
    if n_nodes < WALKED_MIN_NODES:
        out.append(f"n_nodes {n_nodes}: go2 walked with {WALKED_MIN_NODES}-24 nodes (dt "
                   "0.02 s); with 16 it fell in real time (it walked in lockstep), with 12 "
                   "in both")
    return out


def weight_problem(name: str, values: np.ndarray, size: int) -> str | None:
    """Why the weight parameter ``name`` cannot take ``values`` (size ``size`` needed:
    finite, within [0, MAX_WEIGHT]), or None."""
    if values.size != size or not np.all(np.isfinite(values)) or np.any(values < 0) \
            or np.any(values > MAX_WEIGHT):
        return (f"{name} needs {size} finite value(s) in [0, {MAX_WEIGHT:g}], got "
                f"{values.tolist()}")
    return None


class MpcParameters:
    """Declaration and live update of the MPC node's parameters (mixin of ``MpcNode``)."""

    def _declare(self, name: str, default: object, description: str,
                 rng: list[FloatingPointRange] | None = None,
                 irng: list[IntegerRange] | None = None, ro: bool = False) -> None:
        declare(self, name, default, description, rng, irng, read_only=ro)

    def _declare_parameters(self, st: MpcSettings, rate_sets_horizon: bool = True) -> None:
        """Declare every parameter, defaults from ``st`` (the config's MPC settings); with
        ``rate_sets_horizon``, a ``control_rate`` given faster than one node per tick sets
        the defaults of ``dt`` and ``n_nodes`` (:func:`horizon_for_rate`)."""
        d = self._declare
        n_nodes, dt = int(st.n_nodes), float(st.dt)
        given = parameter_overrides(self)
        rate = given["control_rate"].value if "control_rate" in given else None
        chosen = None
        # (a rate of the wrong type or range is refused by its own declaration below)
        if rate_sets_horizon and "dt" not in given and isinstance(rate, (int, float)) \
                and not isinstance(rate, bool) and rate > 0:
            chosen = horizon_for_rate(dt, n_nodes, float(rate))
        if chosen is not None:
            dt, n_nodes = chosen[0], (n_nodes if "n_nodes" in given else chosen[1])
            self.get_logger().info(
                f"control_rate {rate:g} Hz is faster than the config's nodes of {st.dt:g} s: "
                f"dt {dt:g} s and {n_nodes} nodes ({n_nodes * dt:g} s of horizon; -p dt and "
                "-p n_nodes choose others)")
        d("n_nodes", n_nodes, "horizon nodes (intervals) of the walking problem "
          "(default: the config's mpc.n_nodes, scaled with dt when a faster control_rate "
          "sets it)", irng=int_range(*N_NODES_RANGE), ro=True)
        d("dt", dt, "duration of one horizon node (s; default: the config's mpc.dt, or the "
          "control period of a control_rate faster than that, down to "
          f"{WALKED_DT[0]:g} s)", float_range(*DT_RANGE), ro=True)
        d("control_rate", 1.0 / float(self._p("dt")), "MPC ticks per second of the node "
          "clock (trigger timer; default: 1 / dt)", float_range(1, 1000), ro=True)
        d("iterations", int(st.iterations), "ILQR iterations per tick (default: the config's "
          "mpc.iterations)", irng=int_range(*ITERATIONS_RANGE), ro=True)
        d("solve_budget", 0.85, "with trigger 'timer': the ILQR iterations after the first "
          "are skipped when they would end later than this fraction of the control period "
          "after the solve started (0: always run them all)", float_range(0, 10), ro=True)
        d("prepare_ahead", bool(st.prepare_ahead), "after publishing a plan, prepare the next "
          "tick's last iteration (quadratisation, backward pass): a tick is then only its "
          "feedback step from the new state (low latency); false: whole ticks", ro=True)
        d("max_extrapolation", float(st.max_extrapolation), "a state stamped up to this far "
          "(s) from the prepared tick time is predicted to it with the plan's acceleration; "
          "further: a whole tick (0: no prediction; a timer tick takes the state of the "
          "prepared time when one came)", float_range(0, 1), ro=True)
        d("feedback_tolerance", float(st.feedback_tolerance), "a state stamped up to this "
          "far (s) from the prepared tick time, and not predicted (max_extrapolation), gets "
          "the prepared feedback step as measured, the plan starting at its stamp; further: "
          "a whole tick (a robot's driver never stamps on the tick times)",
          float_range(0, 1), ro=True)
        d("trigger", "timer", "'timer': tick at control_rate; 'state': tick on each new "
          "(joint_states, odom) pair with equal stamps (simulator lockstep)", ro=True)
        d("state_reliability", "reliable", "QoS reliability of the joint_states and odom "
          "subscriptions: 'reliable' (matches reliable publishers: ros2 topic pub, sim_node) "
          "or 'best_effort' (matches both, e.g. a driver publishing with the sensor-data "
          "profile, which a reliable subscription never receives)", ro=True)
        d("cmd_reliability", "best_effort", "QoS reliability of the cmd_vel subscription: "
          "'best_effort' (matches reliable and best-effort publishers: teleop, nav2, a "
          "joystick driver's sensor-data profile) or 'reliable' (reliable publishers only)",
          ro=True)
        d("gait", st.gait.name, f"gait ({', '.join(GAITS)}); live")
        d("step_duration", float(st.gait.step_duration), "swing duration (s); live",
          float_range(*STEP_DURATION_RANGE))
        d("step_height", float(st.gait.step_height), "swing apex height (m); live",
          float_range(*STEP_HEIGHT_RANGE))
        d("duty_factor", float(st.gait.duty_factor or 0.0), "stance fraction of a cycle (0: "
          "the gait's own, walk 0.75, the others 0.5); live", float_range(0.0, 1.0))
        for name, vmax, unit in zip(LIVE_LIMITS, st.max_velocity, ("m/s", "m/s", "rad/s"),
                                    strict=True):
            d(name, float(vmax), f"|{name[4:]}| command limit ({unit}) of the config's gait "
              "(a gait with a longer stance, e.g. walk, gets a share of it); live",
              float_range(0, MAX_VELOCITY))
        d("max_command_norm", float(st.max_command_norm), "combined command limit: the "
          "command's norm with each axis divided by its limit (max_vx, max_vy, max_wz) is at "
          "most this, a command beyond is scaled down along its direction (1.414: two axes at "
          "their limits together; >= 1.733: per-axis limits only); live",
          float_range(MIN_COMMAND_NORM, MAX_COMMAND_NORM))
        for name in WEIGHT_FIELDS:
            value = getattr(st.weights, name)
            value = [float(x) for x in value] if isinstance(value, list) else float(value)
            d(f"w_{name}", value, f"cost weight '{name}' (see MpcSettings.weights); live")
        d("stand_when_idle", bool(st.stand_when_idle), "zero command: the feet stay down "
          "(true) or the gait keeps stepping in place (false); live")
        d("cmd_timeout", 0.5, "a cmd_vel older than this (s, node clock) means zero command",
          float_range(0.01, 60))
        d("state_timeout", 0.2, "no plan from a state older than this (s, node clock)",
          float_range(0.001, 60))
        d("publish_points", 6, "trajectory points published per plan (nodes 0..n-1)",
          irng=int_range(1, 1000), ro=True)
        d("path_rate", 10.0, "~/predicted_base_path messages per second of the node clock "
          "(at most one per tick; 0: every tick)", float_range(0, 1000), ro=True)
        d("diagnostics_rate", DIAGNOSTICS_RATE, "/diagnostics messages per second of the "
          "node clock (at most one per tick, and at once when the level rises; 0: every tick)",
          float_range(0, 1000), ro=True)
        self._check_trigger(self._p("trigger"))
        for name in ("state_reliability", "cmd_reliability"):
            if self._p(name) not in ("reliable", "best_effort"):
                raise ValueError(f"{name} must be 'reliable' or 'best_effort', got "
                                 f"{self._p(name)!r}")

    @staticmethod
    def _check_trigger(trigger: str) -> None:
        if trigger not in ("timer", "state"):
            raise ValueError(f"trigger must be 'timer' or 'state', got {trigger!r}")

    def _p(self, name: str) -> object:
        return self.get_parameter(name).value

    def _weights_from_parameters(self, base: Weights, changed: dict | None = None) -> Weights:
        values = {n: (changed or {}).get(f"w_{n}", self._p(f"w_{n}")) for n in WEIGHT_FIELDS}
        out = {}
        for n, v in values.items():
            # rclpy hands array parameters over as array.array (a live set crashed on it)
            arr = np.atleast_1d(np.asarray(v, dtype=float))
            problem = weight_problem(f"w_{n}", arr, np.size(getattr(base, n)))
            if problem:
                raise ValueError(f"parameter {problem}")
            out[n] = arr.tolist() if np.ndim(v) else float(v)
        return dataclasses.replace(base, **out)

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """Validate and apply live changes (gait, limits, weights, idle stance, time-outs)
        between two ticks."""
        new = {p.name: p.value for p in params}
        for name, value in new.items():
            if name == "use_sim_time" and value != self._p("use_sim_time"):
                # every state would be stale, or stamped ahead, until it was set back
                return SetParametersResult(successful=False, reason=(
                    "use_sim_time is read at start-up (the node's clock, the states' stamps "
                    "and the time-outs follow it): restart the node to change it"))
            if name == "gait" and value not in GAITS:
                return SetParametersResult(successful=False,
                                           reason=f"unknown gait {value!r}; gaits: {list(GAITS)}")
            if name.startswith("w_"):
                problem = weight_problem(name, np.atleast_1d(np.asarray(value, dtype=float)),
                                         np.atleast_1d(self._p(name)).size)
                if problem:
                    return SetParametersResult(successful=False, reason=problem)
        st = self.mpc.settings
        if any(n in new for n in LIVE_GAIT):
            g = {n: new.get(n, self._p(n)) for n in LIVE_GAIT}
            try:
                self.mpc.set_gait(g["gait"], g["step_duration"], g["step_height"],
                                  gait_duty_factor(g["duty_factor"]))
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        if any(n in new for n in LIVE_LIMITS):
            st.max_velocity = [float(new.get(n, self._p(n))) for n in LIVE_LIMITS]
        if "max_command_norm" in new:
            st.max_command_norm = float(new["max_command_norm"])
        if "stand_when_idle" in new:
            self.mpc.set_stand_when_idle(new["stand_when_idle"])
        # read by the node at every tick / command
        self.cmd_timeout = float(new.get("cmd_timeout", self.cmd_timeout))
        self.state_timeout = float(new.get("state_timeout", self.state_timeout))
        if any(n.startswith("w_") for n in new):
            st.weights = self._weights_from_parameters(st.weights, new)
            self.mpc.wp.set_weights(st.weights)
        if new:
            self.get_logger().info(f"parameters updated live: {sorted(new)}")
        if any(n in new for n in LIVE_GAIT):
            g = st.gait
            for note in gait_warnings(g.name, g.step_duration, g.duty_factor,
                                      self._config_settings.gait.step_duration):
                self.get_logger().warning(note)
        if any(n in new for n in LIVE_LIMITS):
            for note in limit_warnings(st.max_velocity, self._config_settings.max_velocity):
                self.get_logger().warning(note)
        changed = [n[2:] for n in new if n.startswith("w_")]
        if changed:
            for note in weight_warnings(st.weights, changed):
                self.get_logger().warning(note)
        return SetParametersResult(successful=True)


def parameter_table(settings: MpcSettings | None = None
                    ) -> list[tuple[str, object, str, bool]]:
    """``(name, default, description, read_only)`` of every parameter the MPC node declares
    (``use_sim_time``, rclpy's own, aside), in declaration order, without building a node;
    defaults from ``settings`` (None: the library's, not a robot config's)."""
    rows = {name: (default, text, True) for name, default, text in MODEL_PARAMETER_DECLARATIONS}

    class _Table(MpcParameters):
        def _declare(self, name: str, default: object, description: str, *args: object,
                     ro: bool = False, **kwargs: object) -> None:
            rows[name] = (default, description, ro)

        def _p(self, name: str) -> object:
            return rows[name][0]

    _Table()._declare_parameters(settings or MpcSettings())
    return [(name, *row) for name, row in rows.items()]


def parameter_names() -> tuple[str, ...]:
    """The names of every parameter the MPC node declares (``use_sim_time``, rclpy's own,
    aside), without building a node: what a launcher checks ``-p NAME=VALUE`` against."""
    return tuple(row[0] for row in parameter_table())
