"""``ros2 run horizon_mpc mpc_node``: the walking MPC (:class:`WalkingMpc`) as a ROS 2 node.

Topics, parameters, timing and the bad-input policy are documented in ``doc/mpc_node.md``.
In short: subscribes ``joint_states``, ``odom`` (twist in the base frame, REP 105) and
``cmd_vel``; publishes ``joint_trajectory`` stamped with the stamp of the state the plan was
computed from, ``/diagnostics`` and ``~/predicted_base_path``. ``trigger: state`` ticks once
per new (joint_states, odom) pair with equal stamps, which is what the simulator's lockstep
mode needs; ``trigger: timer`` ticks at ``control_rate`` on the node's clock.
"""

from __future__ import annotations

import copy
import functools
import gc
import math
import sys
import textwrap
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path as FilePath

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry, Path
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory

from horizon_mpc.closed_loop_report import FALL_HEIGHT, FALL_TILT
from horizon_mpc.codegen import codegen_enabled, default_cache_dir
from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.locomotion import MpcSettings
from horizon_mpc.model import RobotModel
from horizon_mpc.model.loading import refuse_second_free_flyer
from horizon_mpc.mpc.controller import Plan, WalkingMpc
from horizon_mpc.nodes.conversions import NS_PER_S, time_to_ns
from horizon_mpc.nodes.declare import accept_integers_for_floats, parameter_overrides
from horizon_mpc.nodes.mpc_inputs import (
    LayoutNote,
    base_from_odometry,
    clipped,
    command_from_twist,
    joints_from_joint_state,
)
from horizon_mpc.nodes.mpc_outputs import (
    DiagnosticsMessage,
    due,
    fill_path,
    fill_trajectory,
    period_ns,
)
from horizon_mpc.nodes.mpc_parameters import (
    LIVE_LIMITS,
    MODEL_PARAMETER_DECLARATIONS,
    MpcParameters,
    gait_duty_factor,
    gait_warnings,
    limit_warnings,
    parameter_table,
    timing_warnings,
    weight_warnings,
)
from horizon_mpc.nodes.robot_description import check_urdf_text
from horizon_mpc.nodes.spin import spin_until_signal
from horizon_mpc.nodes.throttling import problem_kind

__all__ = ["MpcNode", "main", "robot_model"]

_WARN_PERIOD = 2.0  # s (wall) between two warnings of the same kind
#: different texts of one kind said once each (a publisher's layout) before the rest of that
#: kind is throttled instead (a layout that changes per message)
ONCE_KEYS = 8
_WATCH_PERIOD = 2.0  # s (wall): states arriving this long without a tick get explained
#: a plan's constraint violation (its rows are mostly N and N m: the base wrench, friction)
#: beyond which its diagnostics say WARN, as a fraction of the robot's weight (m g): walking
#: at the combined limits, go2 (157 N) stayed below 6, b1 below 82 and hyq below 28 N; a
#: collapsing experimental gait of go2 reached 100-140 N. Not a failure: the plan is sent
INFEASIBLE_PLAN = 0.3
#: s of node clock the violation must stay beyond INFEASIBLE_PLAN before it is WARN: a
#: falling robot's plans stay there; at 100 Hz single ticks of a walking go2 reached 81-140
INFEASIBLE_FOR = 0.1
# a measured base below FALL_HEIGHT of its nominal height above the ground, or tilted more
# than FALL_TILT (rad), is a fallen robot: ERROR diagnostics, the closed loop's thresholds
# (the status said OK while go2 lay on its side in some falls, its plans' violation small)
MISS_WARN_SHARE = 0.2  # prepare misses among the recent ticks beyond which the node warns
_RECENT_STATES = 8  # joint_states / odom messages kept to pair them by stamp
STATE_QUEUE_DEPTH = 1  # of the joint_states and odom subscriptions


class MpcNode(MpcParameters, Node):
    """The MPC node. Construct after ``rclpy.init()``; spin it with any executor.

    ``mpc``: an already built controller to wrap (tests reuse one); its robot must match the
    ``robot``/``config`` parameter. Otherwise the node builds one (seconds, logged).
    """

    DEFAULT_NAME = "mpc"  # spin.PACKAGE_NODES

    def __init__(
        self,
        node_name: str = DEFAULT_NAME,
        *,
        parameter_overrides: Sequence[Parameter] | None = None,
        mpc: WalkingMpc | None = None,
        sim_time_default: bool = False,
        **kwargs: object,
    ) -> None:
        super().__init__(node_name, parameter_overrides=list(parameter_overrides or []),
                         **kwargs)
        if sim_time_default:
            self._default_to_sim_time()
        for name, default, description in MODEL_PARAMETER_DECLARATIONS:
            self._declare(name, default, description, ro=True)
        cfg = load_robot_config(self._p("config") or self._p("robot"))
        settings = self._settings_from_parameters(cfg, mpc)
        mpc = self.mpc = self._controller(cfg, settings, mpc)
        self.joint_names = list(mpc.model.joint_names)
        # readings far outside these are refused (a wrong joint offset, a garbled message);
        # an empty range (centauro's wheels at [0, 0]) is none (RobotModel.unset_limits)
        self._joint_limits = (mpc.model.q_lower[7:].copy(), mpc.model.q_upper[7:].copy())
        self.period = 1.0 / self._p("control_rate")
        self.state_timeout = self._p("state_timeout")
        self.cmd_timeout = self._p("cmd_timeout")
        self.publish_points = min(self._p("publish_points"), settings.n_nodes)
        if self._p("publish_points") > settings.n_nodes:
            self.get_logger().warning(
                f"publish_points {self._p('publish_points')} is more than the horizon's "
                f"{settings.n_nodes} nodes: publishing {settings.n_nodes}")
        mpc.prepare_inverse_dynamics(self.publish_points)  # compiled now, not in a tick
        self.trigger = self._p("trigger")
        budget = self._p("solve_budget")
        # lockstep (trigger 'state') stays deterministic: no wall-clock budget there
        mpc.time_budget = (budget * self.period if self.trigger == "timer" and budget > 0
                           else None)
        # the predicted path and the diagnostics may go out at lower rates than the ticks
        self._path_period_ns = period_ns(self._p("path_rate"))
        self._diag_period_ns = period_ns(self._p("diagnostics_rate"))
        self._last_path_ns: int | None = None
        self._last_diag: tuple[int, bytes] | None = None  # (node clock ns, level) last sent
        self._solve_time_max = 0.0  # s, over the ticks since the last diagnostics
        self._path = Path()  # reused: its poses are overwritten in place (see path_msg)
        self._world_frame = "odom"  # the odometry pose's frame: the predicted path's
        self._trajectory = JointTrajectory()  # reused likewise (see trajectory_msg)
        # the fully qualified name: two robots in two namespaces tell their statuses apart
        self._diag = DiagnosticsMessage(f"{self.get_fully_qualified_name()}: walking MPC",
                                        mpc.cfg.name)

        # latest accepted inputs: (stamp ns, arrays...) / (receipt time s, cmd)
        # the last few of each, (stamp ns, arrays...), to plan from a joints/base pair of one
        # stamp when there is one
        self._joints_recent: deque[tuple] = deque(maxlen=_RECENT_STATES)
        self._base_recent: deque[tuple] = deque(maxlen=_RECENT_STATES)
        self._cmd: tuple[float, np.ndarray] | None = None
        self._cmd_timed_out = True
        self._cmd_rejected = 0  # cmd_vel messages rejected since the last valid one
        self._last_tick_stamp: int | None = None
        self._clock_seen_ns: int | None = None  # the node clock at the last tick
        self._clock_back = False  # it went back since (until states of before are dropped)
        self._clock_publishers_since: float | None = None  # several on the clock topic
        self.plan: Plan | None = None
        self.measured_base: np.ndarray | None = None  # (7,) base pose of the last tick's state
        self.ticks = 0
        self.deadline_misses = 0  # trigger 'timer': work longer than the control period
        self.overruns = 0  # trigger 'state' (lockstep): the same, but the simulator waits
        self.stale_skips = 0
        self.solver_errors = 0
        self.rejected = {"joint_states": 0, "odom": 0, "cmd_vel": 0}
        self.last_solve_time = math.nan  # s: state in -> plan out (the tick's latency)
        self.last_prepare_time = math.nan  # s: the next tick's preparation after it
        self._period_ns = round(self.period * NS_PER_S)
        self._prepared_ns = 0  # the tick time (node clock, ns) the preparation is for
        # a state skipped since the preparation (stale, out of order, ...): the prepared
        # time is then behind the states, and the next tick plans from the newest (_state_pair)
        self._skipped_since_prepare = False
        self._recent_misses: deque[bool] = deque(maxlen=50)  # prepare misses of recent ticks
        # N: a plan's constraint violation beyond which its status is WARN (INFEASIBLE_PLAN)
        self._infeasible_violation = INFEASIBLE_PLAN * mpc.model.mass * 9.81
        self._infeasible_since_ns: int | None = None  # plan stamp the violation went beyond
        self.last_state_age = math.nan
        self._last_warn: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._said_once: dict[str, set[str]] = {}  # keys said once, per kind
        # odometry twists are in child_frame_id (REP 105): the base link's, or its root
        # body's when the config names a link fixed to it (a1: trunk on base)
        self._base_frames = {mpc.cfg.base_link, mpc.model.root_link}

        self._create_interfaces()

    def _settings_from_parameters(self, cfg: RobotConfig, mpc: WalkingMpc | None
                                  ) -> MpcSettings:
        """Declare the parameters (defaults from ``cfg``'s ``mpc:`` section, or the given
        controller's settings) and return the settings they choose, warning about values
        outside where the robot was seen to walk."""
        # the config's own: what the gait and limits were tuned with (warnings)
        self._config_settings = MpcSettings.from_config(cfg)
        settings = mpc.settings if mpc is not None else copy.deepcopy(self._config_settings)
        self._declare_parameters(settings, rate_sets_horizon=mpc is None)
        horizon = (int(self._p("n_nodes")), float(self._p("dt")))
        if mpc is not None and horizon != (settings.n_nodes, settings.dt):
            raise ValueError(f"n_nodes/dt {horizon} differ from those of the given MPC "
                             f"({settings.n_nodes}, {settings.dt}): build it with them")
        duty = gait_duty_factor(self._p("duty_factor"))
        settings.n_nodes, settings.dt = horizon
        g = settings.gait
        g.name, g.step_duration = self._p("gait"), self._p("step_duration")
        g.step_height, g.duty_factor = self._p("step_height"), duty
        settings.max_velocity = [self._p(n) for n in LIVE_LIMITS]
        settings.max_command_norm = float(self._p("max_command_norm"))
        settings.stand_when_idle = bool(self._p("stand_when_idle"))
        settings.prepare_ahead = bool(self._p("prepare_ahead"))
        nodes_per_tick = settings.dt * float(self._p("control_rate"))
        nodes_per_tick = 1.0 / nodes_per_tick if nodes_per_tick > 0 else math.nan
        # with trigger 'state' too: a lockstep simulator steps by the control period
        if settings.prepare_ahead and not (
                round(nodes_per_tick) >= 1 and abs(nodes_per_tick - round(nodes_per_tick))
                <= 0.05):
            # a tick of a fraction of a node: each preparation predicted node 0 from a warm
            # start blended between two nodes, and go2 fell at 2.3-2.5 s at 100 Hz
            # (dt 0.02 s) in real time; whole ticks walked
            settings.prepare_ahead = False
            self.get_logger().warning(
                f"prepare_ahead is off (the parameter keeps its value): control_rate "
                f"{self._p('control_rate'):g} Hz moves the horizon {nodes_per_tick:.3g} nodes a "
                f"tick (dt {settings.dt:g} s); it needs whole nodes (control_rate = 1/dt, or "
                "1/(k dt)). Fractional ticks blend the warm start between nodes: go2 fell at "
                "100 Hz in 3 of 5 real-time runs even without it, and at 2.9 s in the "
                "lockstep closed loop")
        settings.max_extrapolation = float(self._p("max_extrapolation"))
        settings.feedback_tolerance = float(self._p("feedback_tolerance"))
        settings.weights = self._weights_from_parameters(settings.weights)

        for note in (*gait_warnings(g.name, g.step_duration, g.duty_factor,
                                    self._config_settings.gait.step_duration),
                     *limit_warnings(settings.max_velocity, self._config_settings.max_velocity),
                     *weight_warnings(settings.weights)):
            self.get_logger().warning(note)
        for note in timing_warnings(settings.dt, settings.n_nodes,
                                    1.0 / self._p("control_rate"),
                                    min(self._p("publish_points"), settings.n_nodes)):
            self.get_logger().warning(note)
        return settings

    def _controller(self, cfg: RobotConfig, settings: MpcSettings,
                    mpc: WalkingMpc | None) -> WalkingMpc:
        """The walking MPC: built from the parameters' model (seconds, logged), or the given
        one set to the parameters' gait, idle stance and weights."""
        g = settings.gait
        t = time.perf_counter()
        if mpc is None:
            model = robot_model(cfg, str(self._p("urdf_path")),
                                str(self._p("robot_description")))
            model = model if model is not None else RobotModel.from_config(cfg)
            _check_joints(model)  # before the build (tens of seconds)
            if codegen_enabled():
                self.get_logger().info(
                    f"building the {cfg.name} walking MPC: its compiled functions load from "
                    f"the cache ({default_cache_dir()}) or, on a first start, are compiled "
                    "(tens of seconds to minutes)")
            mpc = WalkingMpc(cfg, model, settings=settings, iterations=self._p("iterations"))
        else:
            _check_joints(mpc.model)
            mpc.set_gait(g.name, g.step_duration, g.step_height, g.duty_factor)
            mpc.set_stand_when_idle(settings.stand_when_idle)
            mpc.wp.set_weights(settings.weights)
        if len(cfg.feet) != 4:
            self.get_logger().warning(
                f"{len(cfg.feet)} feet: the gaits and the contact model are a quadruped's "
                "(point feet; the gaits' phases go over the feet in order); talos on its two "
                "soles trotted the default profile and fell at 12.7 s (doc/mpc_node.md)")
        source = model_source(cfg, str(self._p("urdf_path")), str(self._p("robot_description")))
        self.get_logger().info(
            f"built the {cfg.name} walking MPC (model from {source}) in "
            f"{time.perf_counter() - t:.2f} s "
            f"({settings.n_nodes} nodes x {settings.dt:g} s, {mpc.iterations} "
            f"iteration(s)/tick, gait {g.name})")
        return mpc

    def _create_interfaces(self) -> None:
        """Publishers, subscriptions, the parameter callback and the timers."""
        self._pub_traj = self.create_publisher(JointTrajectory, "joint_trajectory", 10)
        self._pub_diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._pub_path = self.create_publisher(Path, "~/predicted_base_path", 10)
        # depth 1: a tick plans from the newest state, never from a backlog of stale ones
        # (at depth 5 the executor took the queued states one per wait and the node planned
        # from states 20 ms old in one of two real-time runs, session 30). The price: another
        # driver's JointState on the topic (a gripper's) displaces the robot's (JointState
        # has no key), which the rejection's warning names
        state_qos = QoSProfile(depth=STATE_QUEUE_DEPTH,
                               reliability=_RELIABILITY[self._p("state_reliability")])
        # best effort by default: it also hears best-effort publishers (a reliable
        # subscription never received a joystick driver's sensor-data cmd_vel; the robot
        # stood with diagnostics OK)
        cmd_qos = QoSProfile(depth=10, reliability=_RELIABILITY[self._p("cmd_reliability")])
        # each input with the parameter that sets its reliability (_check_input_types)
        self._inputs = (
            (self.create_subscription(JointState, "joint_states", self._on_joint_state,
                                      state_qos), "state_reliability"),
            (self.create_subscription(Odometry, "odom", self._on_odom, state_qos),
             "state_reliability"),
            (self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, cmd_qos),
             "cmd_reliability"))
        self._input_topics = dict(zip(("joint_states", "odom", "cmd_vel"),
                                      (sub.topic_name for sub, _ in self._inputs), strict=True))
        accept_integers_for_floats(self)  # ros2 param set /mpc max_vx 1
        self.add_on_set_parameters_callback(self._on_set_parameters)
        if self.trigger == "timer":
            self._timer = self.create_timer(self.period, self.tick)
        # on the wall clock: says why states arrive and no tick comes (a node clock that
        # stands still, stamps that never pair); silent otherwise
        self._states_in = 0  # accepted joint_states and odom messages
        self._watch = (0, 0, self.get_clock().now().nanoseconds)
        self.create_timer(_WATCH_PERIOD, self._check_progress,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.get_logger().info(f"waiting for {self._input('joint_states')} and "
                               f"{self._input('odom')} (trigger: {self.trigger})")

    # ------------------------------------------------------------------ helpers
    def _input(self, name: str) -> str:
        """An input's name for the log: ``name``, with the topic it was remapped to
        (``-r joint_states:=/foo``: the node said it waited for joint_states)."""
        topic = self._input_topics[name]
        unmapped = self.resolve_topic_name(name, only_expand=True)  # in the node's namespace
        return name if topic == unmapped else f"{name} (remapped to {topic})"

    def _default_to_sim_time(self) -> None:
        """``use_sim_time`` true unless it was set for this node (a ``-p``, a params-file
        section matching it, an override): rcl has resolved those into the node's
        overrides. (Guessing from the command line took another node's section or
        ``-p sim:use_sim_time:=...`` for this node's: it stayed on the wall clock and never
        planned from the simulator's states.)"""
        if "use_sim_time" not in parameter_overrides(self):
            self.set_parameters([Parameter("use_sim_time", value=True)])

    def now(self) -> float:
        """Node clock (s): ROS time, i.e. sim time when ``use_sim_time`` is set."""
        return self.get_clock().now().nanoseconds / NS_PER_S

    def _warn(self, kind: str, text: str) -> None:
        """A warning throttled per ``kind``; says how many were suppressed meanwhile."""
        wall = time.monotonic()
        # (less a little: the 2 s watchdog's own warnings were dropped every other time)
        if wall - self._last_warn.get(kind, -math.inf) < 0.95 * _WARN_PERIOD:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        n = self._suppressed.pop(kind, 0)
        self._last_warn[kind] = wall
        self.get_logger().warning(text + (f" ({n} similar warnings suppressed)" if n else ""))

    def _warn_once(self, kind: str, text: str, key: str | None = None) -> None:
        """A warning said once per distinct ``key`` (default: the text) of its ``kind``; past
        :data:`ONCE_KEYS` different keys of one kind (a layout that changes from message
        to message) throttled per kind like :meth:`_warn` (each was a line, and a key
        kept, per message)."""
        key = text if key is None else key
        seen = self._said_once.setdefault(kind, set())
        if key in seen:
            return
        if len(seen) < ONCE_KEYS:
            seen.add(key)
            self.get_logger().warning(text + " (said once)")
        else:
            self._warn(kind, text + f" (more than {ONCE_KEYS} different ones: throttled)")

    def _note(self, topic: str, note: str) -> None:
        if isinstance(note, LayoutNote):
            self._warn_once(f"{topic}_layout", note)
        else:
            self._warn(problem_kind(f"{topic}_note", note), note)

    def _skip_stale(self, age: float, kind: str, text: str, stamp_ns: int,
                    now_ns: int, force: bool = False) -> bool:
        """Not planning from a state ``age`` s old (negative: stamped ahead of the clock):
        counted in ``stale_skips``, warned about (``kind``, throttled), WARN diagnostics
        (``force``: whatever the node clock says). Returns False (no trajectory published)."""
        self.last_state_age = age
        self.stale_skips += 1
        self._skipped_since_prepare = True
        self._warn(kind, text)
        self._publish_diagnostics(None, stamp_ns, now_ns, force=force)
        return False

    def _check_progress(self) -> None:
        """Explain (throttled) why states keep arriving while no tick happens, or say that
        they stopped (wall clock: a stopped simulator stops the sim clock as well)."""
        self._check_input_types()
        ticks, clock_ns = self.ticks + self.stale_skips, self.get_clock().now().nanoseconds
        if self._joints is None or self._base is None:
            # a node waiting for its inputs says so on /diagnostics too: an aggregator saw
            # nothing of it, as of a node that is not running
            missing = [self._input(n) for n, x in (("joint_states", self._joints),
                                                   ("odom", self._base)) if x is None]
            self._publish_diagnostics(None, clock_ns, clock_ns, force=True, waiting=(
                f"waiting for {' and '.join(missing)}: not planning"))
            # and in the log (a tick says it, but no tick comes on a sim clock that stands
            # or, with trigger 'state', without states: the log said nothing)
            since = "since the clock went back" if self.plan is not None else "received yet"
            self._warn("no_state", f"no {' and no '.join(missing)} {since}; not planning")
        prev_states, prev_ticks, prev_clock = self._watch
        self._watch = (self._states_in, ticks, clock_ns)
        if self._states_in == prev_states and self.plan is not None:
            # no state for a whole watch period, on the wall clock: with a simulator that
            # stopped, the sim clock stopped too and no timer tick can see the states age
            self._skip_stale(math.inf, "stale", f"no {self._input('joint_states')} / "
                             f"{self._input('odom')} for {_WATCH_PERIOD:g} s (wall clock): not "
                             "planning; the last trajectory sent is the robot's last plan",
                             self._last_tick_stamp or 0, clock_ns, force=True)
            return
        if self._states_in == prev_states or ticks > prev_ticks:
            return
        if self.trigger == "timer" and clock_ns == prev_clock:
            self._warn("no_clock", "states arrive but the node's clock stands still: "
                       "use_sim_time is true and nothing publishes /clock; on a robot run "
                       "with -p use_sim_time:=false")
        elif self.trigger == "state" and self._joints is not None and self._base is not None \
                and self._joints[0] != self._base[0]:
            self._warn("unpaired", "trigger 'state' ticks when joint_states and odom of one "
                       "stamp have arrived, and theirs never match (the last ones "
                       f"{(self._joints[0] - self._base[0]) / 1e6:+.1f} ms apart): with "
                       "separate drivers use trigger:=timer")

    def _check_input_types(self) -> None:
        """Say (once each) which publishers on an input topic send another message type, a
        TwistStamped cmd_vel above all (Jazzy's teleop and nav2 can publish those): DDS
        never connects the two and nothing else says so; the robot just stands."""
        for sub, parameter in self._inputs:
            ours = message_type_name(sub.msg_type)
            for info in self.get_publishers_info_by_topic(sub.topic_name):
                # a publisher's node is named once discovery has caught up
                who = ("a node" if "_UNKNOWN_" in info.node_name else
                       f"{info.node_namespace.rstrip('/')}/{info.node_name}")
                if info.topic_type != ours:
                    self._warn_once("input_type",
                                    f"{sub.topic_name}: {who} publishes {info.topic_type}, "
                                    f"this node subscribes {ours}: none of its messages "
                                    "arrive (different types never connect)",
                                    key=f"{sub.topic_name} {info.topic_type}")
                elif (info.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
                      and self._p(parameter) == "reliable"):
                    self._warn_once("input_qos",
                                    f"{sub.topic_name}: {who} publishes best effort, this "
                                    "node subscribes reliable: none of its messages arrive; "
                                    f"start the node with -p {parameter}:=best_effort",
                                    key=f"{sub.topic_name} best effort")
        if self.get_parameter("use_sim_time").value:
            self._check_clock_publishers()

    def _check_clock_publishers(self) -> None:
        """Say (once per set of names) that the clock topic has several publishers: two
        simulators on one /clock (two robots in one graph) make the sim time jump between
        them, and the warnings blamed a simulator reset or use_sim_time. Publishers of one
        name are a restarted simulator whose dead participant DDS still lists (up to ~20 s,
        its lease): said only if that lasts :data:`CLOCK_PUBLISHERS_FOR` s."""
        clock = self.resolve_topic_name("/clock")
        publishers = self.get_publishers_info_by_topic(clock)
        now = time.monotonic()
        if len(publishers) < 2:
            self._clock_publishers_since = None
            return
        who = sorted("a node" if "_UNKNOWN_" in p.node_name
                     else f"{p.node_namespace.rstrip('/')}/{p.node_name}" for p in publishers)
        if self._clock_publishers_since is None:
            self._clock_publishers_since = now
        if len(set(who)) > 1 or now - self._clock_publishers_since >= CLOCK_PUBLISHERS_FOR:
            self._warn_once("clock_publishers",
                            f"{clock} has {len(publishers)} publishers ({', '.join(who)}): "
                            "this node's sim time jumps between their clocks and its states "
                            "look old, new or reset; with a simulator per robot, remap "
                            "/clock per robot (-r /clock:=/<namespace>/clock on both of its "
                            "nodes)", key=", ".join(who))

    def current_command(self) -> np.ndarray:
        """The command to use now: the last cmd_vel, or zero once it is older than
        cmd_timeout (which is said once) or stamped on a clock that has gone back since
        (then dropped)."""
        age = None if self._cmd is None else self.now() - self._cmd[0]
        if age is not None and age < 0.0:
            # the clock went back (a restarted simulator) since it came: no command of this
            # clock's (it was followed for as long as the clock went back), and dropped, or
            # it would come back to life when the new clock reaches its time
            self._cmd = None
            self._warn("cmd_timeout", f"the clock went back {-age:.3f} s since the last "
                       "cmd_vel: dropped it; commanding zero velocity")
        if self._cmd is None or age > self.cmd_timeout:
            if self._cmd is not None and not self._cmd_timed_out:
                rejected = (f" ({self._cmd_rejected} rejected since)" if self._cmd_rejected
                            else "")
                self._warn("cmd_timeout", f"no valid {self._input('cmd_vel')} for more than "
                           f"{self.cmd_timeout:g} s{rejected}; commanding zero velocity")
            self._cmd_timed_out = True
            return np.zeros(3)
        self._cmd_timed_out = False
        return self._cmd[1]

    # ------------------------------------------------------------------ inputs
    def _on_joint_state(self, msg: JointState) -> None:
        try:
            qj, vj, notes = joints_from_joint_state(msg, self.joint_names, self._joint_limits)
        except ValueError as exc:
            self.rejected["joint_states"] += 1
            self._warn(problem_kind("joint_states", str(exc)),
                       f"rejected {self._input('joint_states')}: {exc}")
            return
        for note in notes:
            self._note("joint_states", note)
        self._joints_recent.append((time_to_ns(msg.header.stamp), qj, vj))
        self._states_in += 1
        self._maybe_tick_on_state()

    def _on_odom(self, msg: Odometry) -> None:
        try:
            pos, quat, lin, ang, notes = base_from_odometry(msg)
        except ValueError as exc:
            self.rejected["odom"] += 1
            self._warn(problem_kind("odom", str(exc)), f"rejected {self._input('odom')}: {exc}")
            return
        for note in notes:
            self._note("odom", note)
        if msg.child_frame_id and msg.child_frame_id not in self._base_frames:
            child = clipped(msg.child_frame_id)
            self._warn_once("odom_child_frame",
                            f"odom child_frame_id {child!r} is not the base link "
                            f"({' or '.join(sorted(self._base_frames))}): its twist is taken as "
                            "the base's (REP 105: the twist is in child_frame_id)")
        self._base_recent.append((time_to_ns(msg.header.stamp), pos, quat, lin, ang))
        self._world_frame = msg.header.frame_id or "odom"
        self._states_in += 1
        self._maybe_tick_on_state()

    def _on_cmd_vel(self, msg: Twist) -> None:
        try:
            st = self.mpc.settings
            cmd, notes = command_from_twist(msg, self.mpc.velocity_limits,
                                            st.max_command_norm)
        except ValueError as exc:
            self.rejected["cmd_vel"] += 1
            self._cmd_rejected += 1
            self._warn(problem_kind("cmd_vel", str(exc)),
                       f"rejected {self._input('cmd_vel')}: {exc}; the last valid one "
                       "stands until "
                       f"cmd_timeout ({self.cmd_timeout:g} s) after it came, then zero")
            return
        if self.mpc.scheduler.gait.stands and np.any(cmd != 0.0):
            notes.append(f"gait {self.mpc.settings.gait.name!r} never lifts a foot: cmd_vel "
                         "is not followed (the robot stands)")
        for note in notes:
            self._note("cmd_vel", note)
        self._cmd = (self.now(), cmd)
        self._cmd_rejected = 0

    def _maybe_tick_on_state(self) -> None:
        if self.trigger == "state" and self._joints is not None and self._base is not None \
                and self._joints[0] == self._base[0]:
            self.tick()

    @property
    def _joints(self) -> tuple | None:
        """The newest accepted joint state (stamp ns, q, v), or None."""
        return self._joints_recent[-1] if self._joints_recent else None

    @property
    def _base(self) -> tuple | None:
        """The newest accepted base state (stamp ns, position, quaternion, linear, angular)."""
        return self._base_recent[-1] if self._base_recent else None

    def _state_pair(self) -> tuple[tuple, tuple]:
        """The joints and base states to plan from: the newest pair with one stamp among the
        last few received (a simulator publishes both per step, not always in the same
        order before a tick), else the newest of each (separate drivers, unsynchronised
        stamps: the plan's stamp is then the older of the two).

        With a prepared tick, the pair stamped at the prepared time when one came, even if a
        newer one came too: a timer tick sees the state of its own time or the one before,
        as the simulator's and the node's callbacks fall, and a plan from the newer one is
        a prepare miss (a whole tick, ~2x the work; 12 % of go2's ticks with a 250 Hz
        simulator) or a prediction of the state (solo12 fell at 0.4 m/s, 2 of 2 real-time
        runs). The plan is stamped with its state's time, and a simulator follows it by
        that stamp.

        Without one at the prepared time (a robot's driver stamps its states when it
        measures them), the pair nearest to it within the MPC's ``feedback_tolerance``
        (and ``max_extrapolation``), whose feedback step the preparation serves; with
        separate drivers (no stamp shared), the joint state and the base state nearest to
        it, each within that window (the plan's stamp is the older).

        Never an older pair than the newest: with trigger 'state' (the pair that triggered
        the tick; a lockstep simulator waits for its answer), or after a state was skipped
        since the preparation (its prepared time stays behind: a lockstep node answered
        every state with the one before, and the simulator waited out each step)."""
        if self.trigger == "state" and self._joints[0] == self._base[0]:
            return self._joints, self._base
        base_stamps = {b[0]: b for b in self._base_recent}
        pairs = [(j, base_stamps[j[0]]) for j in self._joints_recent if j[0] in base_stamps]
        prepared = self._prepared_ns if (self.mpc.prepared_for is not None
                                         and not self._skipped_since_prepare) else None
        if prepared is not None and self._joints_recent and self._base_recent:
            st = self.mpc.settings
            window = max(st.max_extrapolation, st.feedback_tolerance) * NS_PER_S
            if pairs:
                nearest = min(pairs, key=lambda pair: abs(pair[0][0] - prepared))
                if abs(nearest[0][0] - prepared) <= window:
                    return nearest
            # else the nearest of each stream (separate drivers, whose stamps meet now and
            # then or never: until session 25 their newest of each)
            nearest = tuple(min(recent, key=lambda x: abs(x[0] - prepared))
                            for recent in (self._joints_recent, self._base_recent))
            if max(abs(x[0] - prepared) for x in nearest) <= window:
                return nearest
        if pairs:
            return pairs[-1]
        return self._joints, self._base

    # ------------------------------------------------------------------ the tick
    def tick(self) -> bool:
        """One MPC tick on the latest state; returns whether a trajectory was published.

        Ticks never queue: a tick on a state already used does nothing, and a tick longer
        than the control period only counts a deadline miss (an overrun with trigger
        'state', whose lockstep simulator waits).
        """
        if self._joints is None or self._base is None:
            missing = [self._input(n) for n, x in (("joint_states", self._joints),
                                                   ("odom", self._base)) if x is None]
            since = "since the clock went back" if self.plan is not None else "received yet"
            self._warn("no_state", f"no {' and no '.join(missing)} {since}; not planning")
            return False
        joints, base = self._state_pair()
        stamp_ns = min(joints[0], base[0])
        now_ns = self.get_clock().now().nanoseconds
        if self._clock_seen_ns is not None and now_ns < self._clock_seen_ns:
            self._clock_back = True
        self._clock_seen_ns = now_ns
        if stamp_ns == self._last_tick_stamp:
            # no new state since the last plan: nothing to do, unless the states stopped
            # (a timer tick): then say so, as for a stale state that arrives
            age = (now_ns - stamp_ns) / NS_PER_S
            if age > self.state_timeout:
                self._skip_stale(age, "stale", f"no new state for {age:.3f} s (state_timeout "
                                 f"{self.state_timeout:g} s): not planning; the last "
                                 "trajectory sent is the robot's last plan", stamp_ns, now_ns)
            return False
        t = stamp_ns / NS_PER_S
        if self._last_tick_stamp is not None and stamp_ns < self._last_tick_stamp \
                and now_ns >= self._last_tick_stamp:
            # out of order (the node's clock did not go back, as at a simulator reset)
            self.stale_skips += 1
            self._skipped_since_prepare = True
            self._warn("order", f"a state stamped {(self._last_tick_stamp - stamp_ns) / 1e6:.1f}"
                       " ms before the one the last plan was made from: not planning from it"
                       + _unset_hint(joints[0], base[0]))
            return False
        age = now_ns / NS_PER_S - t
        self.last_state_age = age
        if age > self.state_timeout:
            return self._skip_stale(age, "stale", f"the state is {age:.3f} s old "
                                    f"(state_timeout {self.state_timeout:g} s); not planning"
                                    + _unset_hint(joints[0], base[0], age), stamp_ns, now_ns)
        # stamped ahead of the node's clock: clocks differ. Either stream: the plan's stamp
        # is the older one's, and a joint_states stream 1 s ahead of a correct odom was
        # planned from without a word
        ahead_ns, stream = max((joints[0], "joint_states"), (base[0], "odom"))
        ahead = (ahead_ns - now_ns) / NS_PER_S
        if ahead > self.state_timeout and self._clock_back:
            return self._after_clock_went_back(now_ns, stamp_ns)
        if ahead > self.state_timeout:
            # (both ahead: both named; the later one only was, and a user debugged one
            # driver of two)
            both = min(joints[0], base[0]) - now_ns > self.state_timeout * NS_PER_S
            stream = (f"{self._input('joint_states')} and {self._input('odom')} are"
                      if both else f"{self._input(stream)} is")
            return self._skip_stale(-ahead, "future", f"{stream} stamped {ahead:.3f} s "
                                    "ahead of the node's clock (more than state_timeout "
                                    f"{self.state_timeout:g} s): not planning; do the "
                                    "publisher and this node use the same clock "
                                    "(use_sim_time)?", stamp_ns, now_ns)
        _, qj, vj = joints
        _, pos, quat, lin, ang = base
        q = np.concatenate((pos, quat, qj))
        self.measured_base = q[:7]
        v = np.concatenate((lin, ang, vj))
        cmd = self.current_command()
        previous_ns, self._last_tick_stamp = self._last_tick_stamp, stamp_ns
        self._clock_back = False  # planning from states of the clock as it is
        bootstrap = self.plan is None
        prepared = False  # a preparation awaited this tick
        wall = time.perf_counter()
        try:
            if bootstrap:
                plan = self.mpc.start(q, v, t)
                self.get_logger().info(f"bootstrapped at t = {t:.3f} s in "
                                       f"{time.perf_counter() - wall:.2f} s; ticking")
            else:
                misses, restarts = self.mpc.prepare_misses, self.mpc.restarts
                prepared = self.mpc.prepared_for is not None
                plan = self.mpc.update(t, q, v, cmd)
                # a restart (a reset simulator) is a bootstrap solve: no deadline to miss
                bootstrap = self.mpc.restarts > restarts
                self._recent_misses.append(self.mpc.prepare_misses > misses)
                # a late state now and then (a loaded simulator) costs one whole tick and is
                # counted (diagnostics prepare_misses); warned about when it is the rule
                if self._recent_misses[-1] and self._misses_are_the_rule():
                    self._warn("prepare_miss", self._miss_text(t, stamp_ns, previous_ns))
        except Exception as exc:  # noqa: BLE001 - the node must outlive any solver error
            self.solver_errors += 1
            self._warn("solver", f"MPC tick failed ({type(exc).__name__}: {exc}); "
                       "keeping the last trajectory")
            return False
        self.last_solve_time = time.perf_counter() - wall
        # the plan starts at the state's stamp, or at the prepared tick time when the state
        # was predicted to it (WalkingMpc.update)
        plan_ns = stamp_ns if plan.t0 == t else self._prepared_ns
        # the next tick is one period after this one's time on the node's grid: the prepared
        # time when the preparation served (a state within feedback_tolerance plans from
        # its own stamp; one period after that let the ticks drift back by up to the
        # tolerance each: 32 ms behind at 100 Hz with 250 Hz states), else the plan's
        served = not bootstrap and prepared and not self._recent_misses[-1]
        grid_ns = self._prepared_ns if served else plan_ns
        self.plan = plan
        self.ticks += 1
        self._pub_traj.publish(self.trajectory_msg(plan, plan_ns))
        if due(self._last_path_ns, self._path_period_ns, now_ns):
            self._last_path_ns = now_ns
            self._pub_path.publish(self.path_msg(plan, plan_ns))
        self.last_prepare_time = 0.0
        if self.mpc.settings.prepare_ahead:
            try:
                self._prepared_ns = grid_ns + self._period_ns
                self._skipped_since_prepare = False
                self.mpc.prepare(self._prepared_ns / NS_PER_S, cmd)
            except Exception as exc:  # noqa: BLE001 - as above; the next tick runs whole
                self.solver_errors += 1
                self._warn("solver", f"MPC preparation failed ({type(exc).__name__}: {exc})")
            self.last_prepare_time = time.perf_counter() - wall - self.last_solve_time
        # a tick's work (its latency and the next tick's preparation) must fit its period
        work = self.last_solve_time + self.last_prepare_time
        if work > self.period and not bootstrap:
            took = f"tick took {work * 1e3:.1f} ms > period {self.period * 1e3:.1f} ms"
            if self.trigger == "state":
                # a lockstep simulator waits for the answer: the loop runs slower than real
                # time, no deadline is missed (these were counted as misses until session 32)
                self.overruns += 1
                self._warn("overrun", f"{took}: the lockstep loop runs slower than real time "
                           f"({self.overruns} such ticks; trigger 'state' misses no deadline)")
            else:
                self.deadline_misses += 1
                self._warn("deadline", f"{took} ({self.deadline_misses} misses)")
        self._publish_diagnostics(plan, plan_ns, now_ns)
        return True

    def _after_clock_went_back(self, now_ns: int, stamp_ns: int) -> bool:
        """The node's clock went back since the last tick (a simulator reset) and the states
        are far ahead of it: they came before the reset, and are dropped with a note rather
        than blamed on clocks that differ (one stream's new state and the other's old one
        made a pair 'stamped ahead of the clock'); the next pair of the new clock restarts
        the MPC. Counted as a stale skip (WARN diagnostics). Returns False."""
        self._clock_back = False
        limit = now_ns + self.state_timeout * NS_PER_S
        for recent in (self._joints_recent, self._base_recent):
            kept = [x for x in recent if x[0] <= limit]
            recent.clear()
            recent.extend(kept)
        gone = (self._last_tick_stamp or stamp_ns) - now_ns
        return self._skip_stale((now_ns - stamp_ns) / NS_PER_S, "clock_back",
                                f"the clock went back {gone / 1e9:.3f} s (a simulator reset?): "
                                "states stamped before it dropped", stamp_ns, now_ns)

    def _misses_are_the_rule(self) -> bool:
        """More than MISS_WARN_SHARE of the recent ticks were prepare misses."""
        return sum(self._recent_misses) > MISS_WARN_SHARE * self._recent_misses.maxlen

    def _misses_text(self) -> str:
        return f"{sum(self._recent_misses)} of the last {len(self._recent_misses)} ticks"

    def _miss_text(self, t: float, stamp_ns: int, previous_ns: int | None) -> str:
        """The warning of prepare misses that are the rule, with their likely cause."""
        tol = self.mpc.settings.feedback_tolerance
        text = (f"state stamped {t:.4f} s, {abs(self._prepared_ns - stamp_ns) / 1e6:.3f} ms "
                f"from the prepared tick time (feedback_tolerance {tol * 1e3:g} ms): ran a "
                f"whole tick ({self._misses_text()}): ")
        if self.trigger == "state":
            # a lockstep simulator stepping at another period than the node's
            spacing = "" if previous_ns is None else (
                f"the states come {(stamp_ns - previous_ns) / 1e6:g} ms apart, ")
            return text + (f"trigger 'state' ticks on every state, {spacing}and the "
                           f"preparation is for one control period ({self.period * 1e3:g} ms, "
                           "1 / control_rate) later. trigger 'state' is for a lockstep "
                           "simulator that steps one control period per plan: there make "
                           "them equal (sim_node's control_period), a whole number of dt "
                           f"({self.mpc.settings.dt:g} s); a free-running state stream "
                           "(a robot, sim_node without lockstep) needs trigger 'timer'")
        return text + ("no state comes near the tick times (a loaded machine delays them, "
                       "control_rate is not their rate, or their stamps are further apart "
                       "than feedback_tolerance)")

    # ------------------------------------------------------------------ outputs
    def trajectory_msg(self, plan: Plan, stamp_ns: int) -> JointTrajectory:
        """The first ``publish_points`` nodes of ``plan`` (joints in model order); efforts
        from the inverse dynamics of those nodes only. The node's one JointTrajectory,
        refilled in place (:func:`fill_trajectory`): copy it to keep it past the next call."""
        return fill_trajectory(self._trajectory, plan, self.joint_names, self.publish_points,
                               stamp_ns)

    def path_msg(self, plan: Plan, stamp_ns: int) -> Path:
        """The planned base poses of every node, in the frame of the odometry's pose
        (``odom`` until one arrives): the node's one Path message, refilled in place
        (:func:`fill_path`), so copy it to keep it past the next call."""
        return fill_path(self._path, plan, stamp_ns, self._world_frame)

    def gait_phase(self, t: float) -> float:
        """Phase in [0, 1) of the gait cycle at ``t`` (NaN while standing)."""
        sch = self.mpc.scheduler
        period = sch.gait.period
        if sch.t_start is None or not math.isfinite(period):
            return math.nan
        return ((t - sch.t_start) / period) % 1.0

    def _publish_diagnostics(self, plan: Plan | None, stamp_ns: int,
                             now_ns: int | None = None, force: bool = False,
                             waiting: str | None = None) -> None:
        """The node's status, when ``diagnostics_rate`` says so, its level rose or ``force``
        (the wall-clock watchdog: a stopped simulator stops the node clock the rate is
        counted on, and the stale status went out once, then never again). Without a plan:
        WARN, ``waiting`` (no state yet) or the stale state's message."""
        if plan is None:
            age = "stale" if self.last_state_age > 0 else "future-stamped"
            level, stats = DiagnosticStatus.WARN, {}
            message = waiting or f"{age} state: not planning"
        else:
            # WARN on a failure (the plan is the standing fallback), not on a real-time
            # iteration that leaves some violation: one iteration per tick rarely reaches
            # the solver's own tolerance, and the plan is still the one to follow
            stats = plan.stats
            ok = self.mpc.failures == 0
            level = DiagnosticStatus.OK if ok else DiagnosticStatus.WARN
            message = "ok" if ok else (f"solver failure ({stats.get('status')}): "
                                       "standing fallback")
            violation = stats.get("constraint_violation", 0.0)
            limit = self._infeasible_violation
            beyond = ok and violation > limit
            since = self._infeasible_since_ns = (
                (stamp_ns if self._infeasible_since_ns is None else self._infeasible_since_ns)
                if beyond else None)
            if beyond and stamp_ns - since >= INFEASIBLE_FOR * NS_PER_S:
                level = DiagnosticStatus.WARN
                message = (f"plan far from feasible (constraint violation {violation:.3g} > "
                           f"{limit:.3g}, {INFEASIBLE_PLAN:g} of the weight, for "
                           f"{(stamp_ns - since) / 1e6:.0f} ms): the robot may be falling")
                self._warn("infeasible", message)
            elif ok and self._misses_are_the_rule():
                level = DiagnosticStatus.WARN
                message = (f"prepare misses in {self._misses_text()}: whole ticks, no "
                           "state within feedback_tolerance of the tick times")
            # the measured base: a prepared plan's node 0 closes on a measured state over
            # ticks (a 1 rad roll was OK for 21 ticks, upside down for 8)
            fallen = self._fallen(plan.q[:7, 0] if self.measured_base is None
                                  else self.measured_base)
            if fallen:
                level, message = DiagnosticStatus.ERROR, fallen
                self._warn("fallen", fallen)
            self._solve_time_max = max(self._solve_time_max, self.last_solve_time)
        now_ns = self.get_clock().now().nanoseconds if now_ns is None else now_ns
        last = self._last_diag  # a rising level (OK -> WARN) goes out at once
        if not force and last is not None and level <= last[1] and not due(
                last[0], self._diag_period_ns, now_ns):
            return
        self._last_diag = (now_ns, level)
        values = {
            "solve_time_ms": self.last_solve_time * 1e3,
            "solve_time_max_ms": self._solve_time_max * 1e3,
            "prepare_time_ms": self.last_prepare_time * 1e3,
            "prepare_misses": self.mpc.prepare_misses,
            "iterations": stats.get("iterations", math.nan),
            "cost": stats.get("cost", math.nan),
            "constraint_violation": stats.get("constraint_violation", math.nan),
            "solver_status": stats.get("status", ""),
            "deadline_misses": self.deadline_misses,
            "overruns": self.overruns,
            "solver_errors": self.solver_errors,
            "state_age_ms": self.last_state_age * 1e3,
            # the gait walked (gait_phase is its), and the one set, taken once the
            # swings in progress end (it said the one set at once)
            "gait": self.mpc.scheduler.gait.name,
            "gait_pending": getattr(self.mpc.scheduler.pending, "name", ""),
            "gait_phase": self.gait_phase(stamp_ns / NS_PER_S),
            "command": np.round(self.mpc.cmd, 4).tolist(),
            "ticks": self.ticks,
            "stale_skips": self.stale_skips,
            "rejected": self.rejected,
        }
        self._solve_time_max = 0.0
        self._pub_diag.publish(self._diag.filled(stamp_ns, level, message, values))

    def _fallen(self, base: np.ndarray) -> str:
        """Why the measured base pose ``base`` (x, y, z, quaternion x, y, z, w) is a fallen
        robot's (below FALL_HEIGHT of its nominal height above the
        ground, or tilted more than FALL_TILT), or '' if it is not."""
        _, _, z, qx, qy = base[:5].tolist()
        # the controller's ground is the feet frames' height: a sphere foot's sits its radius
        # above the ground (go2's nominal was 0.312 m here, 0.336 in the closed loop's test)
        radius = self.mpc.cfg.foot_radius
        height = z - (self.mpc.ground_height - radius)
        nominal = self.mpc.base_height_above_ground + radius
        cos_tilt = 1.0 - 2.0 * (qx * qx + qy * qy)
        if cos_tilt < math.cos(FALL_TILT) or height < FALL_HEIGHT * nominal:
            tilt = math.acos(max(-1.0, min(1.0, cos_tilt)))
            return (f"the robot seems to have fallen: base {height:.3f} m above the ground "
                    f"(nominal {nominal:.3f} m), tilted {tilt:.2f} rad")
        return ""


_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE,
                "best_effort": ReliabilityPolicy.BEST_EFFORT}


#: s: a state this much older than the node's clock is on another clock (sim time against
#: wall time: ~1.8e9 s), not late
OTHER_CLOCK_AGE = 3600.0
#: s that several publishers of one name on the clock topic last before they are said (a
#: restarted simulator's dead participant stays listed until its DDS lease ends, ~20 s)
CLOCK_PUBLISHERS_FOR = 30.0


def _unset_hint(joints_ns: int, base_ns: int, age: float = 0.0) -> str:
    """What to say of states stamped 0 (a driver that leaves header.stamp unset) when the
    node's clock is far past them (sim time starts at 0), or of states on another clock
    (``age`` s old: a simulator's sim time read on wall time); empty otherwise."""
    unset = [name for name, ns in (("joint_states", joints_ns), ("odom", base_ns)) if ns == 0]
    if unset and age > OTHER_CLOCK_AGE:
        # on wall time, a simulator's legitimate first state (sim time 0) looks the same
        return (f" ({' and '.join(unset)} stamped 0: header.stamp unset, or a simulator's "
                "first state read on another clock? a driver must stamp each message with "
                "the time of its measurement; against a simulator publishing /clock, set "
                "use_sim_time)")
    if unset:
        return (f" ({' and '.join(unset)} stamped 0: header.stamp unset? the driver must "
                "stamp each message with the time of its measurement)")
    if age > OTHER_CLOCK_AGE:  # sim_node's states read by a node on wall time said only "old"
        return (" (more than an hour old: do the publisher and this node use the same clock "
                "(use_sim_time)?)")
    return ""


def message_type_name(msg_type: type) -> str:
    """The ROS name of a message class, as the graph gives it: ``geometry_msgs/msg/Twist``."""
    return f"{msg_type.__module__.split('.')[0]}/msg/{msg_type.__name__}"


def model_source(cfg: RobotConfig, urdf_path: str = "", robot_description: str = "") -> str:
    """Where the robot model comes from, for the log: the parameters' description or
    file, else the config's ``urdf_path`` (a user's robot: it said example-robot-data),
    else example-robot-data."""
    if robot_description.strip():
        return "robot_description"
    return urdf_path or str(cfg.urdf_path or "") or "example-robot-data"


def robot_model(cfg: RobotConfig, urdf_path: str = "",
                robot_description: str = "") -> RobotModel | None:
    """The robot model the parameters ask for: from ``robot_description`` (URDF XML) if
    given, else from the file ``urdf_path``, else None (the config's own model).

    Raises:
        ValueError: ``robot_description`` is not URDF XML, or a URDF cannot be parsed.
        FileNotFoundError: ``urdf_path`` does not exist.
    """
    if robot_description.strip():
        # RobotModel.from_urdf would take a path here for a file: say where files go
        check_urdf_text(robot_description)
        return RobotModel.from_urdf(robot_description, name=cfg.robot or None)
    if urdf_path.strip():
        return RobotModel.from_urdf(FilePath(urdf_path), name=cfg.robot or None)
    return None


def _check_joints(model: RobotModel) -> None:
    """ValueError unless the walking MPC can take ``model``: a floating base (a legged
    robot; an arm was refused as having continuous joints) and one q entry per joint."""
    if not model.floating_base:
        raise ValueError(f"robot {model.name!r} has a fixed base: the walking MPC needs a "
                         "legged robot on a floating base")
    pin_model = model.pin_model
    refuse_second_free_flyer(pin_model, f"robot {model.name!r}")
    continuous = [pin_model.names[j] for j in range(2, pin_model.njoints)
                  if pin_model.joints[j].nq == 2 and pin_model.joints[j].nv == 1]
    if continuous or model.nq != 7 + len(model.joint_names):
        raise ValueError(f"the walking MPC needs one q entry per joint; continuous joints "
                         f"{continuous} have two (cos, sin): make them revolute with limits "
                         "in the URDF")


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run horizon_mpc mpc_node``; exit code 0 on SIGINT/SIGTERM.

    ``use_sim_time`` defaults to true here, unless it is set for this node (``sim_node``
    stamps states with the simulated clock it publishes on ``/clock``, so ``mpc_node``
    started with no arguments follows that clock; on a robot, pass ``--ros-args -p
    use_sim_time:=false``).
    """
    return spin_until_signal(_node_with_frozen_startup,
                             list(sys.argv if args is None else args), usage,
                             process_exits=True)


def usage() -> str:
    """The ``--help`` text: what the node does, its topics and its parameters."""
    wrap = functools.partial(textwrap.fill, width=92)
    lines = ["usage: ros2 run horizon_mpc mpc_node [--ros-args -p NAME:=VALUE ... "
             "--params-file FILE -r FROM:=TO]", "",
             wrap(" ".join(__doc__.split("\n\n")[1].split()).replace("``", "'")), "",
             wrap("Parameters (library defaults; a robot config's mpc: section overrides "
                  "them). [live]: also changed while running (ros2 param set); the others "
                  "at start-up only. use_sim_time defaults to true. Details: "
                  "doc/mpc_node.md (installed in share/horizon_mpc/doc)."), ""]
    for name, default, description, read_only in parameter_table():
        lines.append(f"  {name} (default {default!r}){'' if read_only else ' [live]'}")
        lines.append(textwrap.fill(description, width=92, initial_indent=" " * 6,
                                   subsequent_indent=" " * 6))
    return "\n".join(lines)


def _node_with_frozen_startup() -> MpcNode:
    """The node, with what its startup allocated frozen out of the garbage collector: the
    model, compiled functions and ROS entities live as long as the process, and a full
    collection over them (~11 ms with go2) would land in some tick; frozen, it scans only
    what the ticks allocate (doc/mpc_node.md, Real time)."""
    node = MpcNode(sim_time_default=True)
    gc.collect()
    gc.freeze()
    return node


if __name__ == "__main__":
    raise SystemExit(main())
