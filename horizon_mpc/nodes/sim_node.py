"""``ros2 run horizon_mpc sim_node``: the pybullet simulator as a ROS 2 node.

Topics, parameters, the lockstep protocol and the bad-input policy are documented in
``doc/simulator.md``. In short:

* publishes ``joint_states`` (sensor_msgs/JointState), ``odom`` (nav_msgs/Odometry, twist in
  the base frame) and ``/clock``, stamped with sim time, every ``1 / state_rate`` sim seconds
  (every ``control_period`` in lockstep mode);
* follows ``joint_trajectory`` (trajectory_msgs/JointTrajectory), applies
  ``external_wrench`` (geometry_msgs/WrenchStamped) pushes, offers ``~/reset``
  (std_srvs/Trigger).

The physics runs in chunks of whole state periods inside one callback (no rclpy call per
physics step). :meth:`SimNode.step_once` advances one lockstep period on demand, so a test can
drive the simulator and a controller deterministically in one process and one executor.
"""

from __future__ import annotations

import math
import os
import random
import textwrap
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from geometry_msgs.msg import WrenchStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.locomotion.settings import MpcSettings
from horizon_mpc.nodes.conversions import (
    NS_PER_S,
    joint_state_to_msg,
    joint_trajectory_from_msg,
    odometry_to_msg,
    time_from_ns,
    time_to_ns,
    vector3_from_msg,
)
from horizon_mpc.nodes.declare import declare as declare_parameter
from horizon_mpc.nodes.declare import float_range
from horizon_mpc.nodes.declare import parameter_overrides as start_up_values
from horizon_mpc.nodes.robot_description import description_file
from horizon_mpc.nodes.spin import spin_until_signal
from horizon_mpc.nodes.throttling import problem_kind
from horizon_mpc.sim.simulator import Simulator

__all__ = ["SimNode", "main"]

_WARN_PERIOD = 2.0  # s (wall) between two warnings of the same kind
_MAX_LAG = 0.25  # s (wall): further behind the wall clock than this, the pacing re-anchors
_FREE_RUN_SLICE = 0.002  # s (wall) of stepping per callback when running as fast as possible
#: s (wall): a lockstep controller of joint_states and joint_trajectory gets the first state
#: this long after it was seen without an odom subscriber (one of the joints only)
ODOM_GRACE = 0.5
#: s (wall): the least a lockstep simulator waits for its controller before the first state
#: (lockstep_timeout if longer; never with lockstep_timeout 0): DDS discovery between two
#: processes started together took 1.3-3.6 s on a loaded machine, and 3 of 5 lockstep runs
#: started without their controller with the 1 s of lockstep_timeout alone
START_WAIT = 10.0
#: s (wall): an unanswered lockstep state is published again this often while the simulator
#: waits (the same stamp: a controller that has it already ignores it). The first state went
#: to another node's odom subscription matched before the controller's (a recorder, rviz),
#: the controller never had it, and with lockstep_timeout 0 both waited for good
LOCKSTEP_RESEND = 0.5


#: the lockstep emulation of a real-time loop's delays (doc/simulator.md), sim s
LOCKSTEP_DELAYS = ("lockstep_latency", "lockstep_latency_jitter", "lockstep_state_offset")


@dataclass(frozen=True)
class FromConfig:
    """A parameter default read from the robot config (``what`` names it in --help)."""

    what: str
    read: Callable[[RobotConfig], float]


def mpc_period(cfg: RobotConfig) -> float:
    """The MPC node's default control period (s) for ``cfg``: its ``mpc.dt`` (the node
    ticks every dt unless given a control_rate; a section the MPC would refuse is refused
    here too, naming the file)."""
    return float(MpcSettings.from_config(cfg).dt)


#: sim_node's parameters: (name, default, description[, range]); a :class:`FromConfig`
#: default is the robot config's value
SIM_PARAMETERS = [
    ("robot", "go2", "robot config name (config/<robot>.yaml) or YAML path"),
    ("config", "", "path of a robot config YAML (overrides 'robot')"),
    ("urdf_path", "", "URDF to simulate instead of the config's"),
    ("robot_description", "", "URDF XML text to simulate, as robot_state_publisher's "
     "parameter (overrides urdf_path)"),
    ("physics_rate", FromConfig("sim.physics_rate", lambda cfg: cfg.sim.physics_rate),
     "physics steps per sim second (Hz)",
     float_range(50, 20000)),
    ("state_rate", 500.0, "joint_states/odom/clock publish rate (Hz, sim time)",
     float_range(1, 20000)),
    ("realtime_factor", 1.0,
     "sim seconds per wall second; 0 = as fast as possible", float_range(0, 1000)),
    ("lockstep", False,
     "advance one control_period per answered state (see doc/simulator.md)"),
    ("lockstep_timeout", 1.0,
     "wall seconds to wait for the answer to a state; 0 = wait forever",
     float_range(0, 3600)),
    ("control_period", FromConfig("mpc.dt", mpc_period),
     "sim seconds advanced per lockstep step: the MPC's control period (with trigger "
     "'state' it ticks on every state; a period that is not a whole number of its dt "
     "makes the robot fall)", float_range(1e-4, 10)),
    ("lockstep_latency", 0.0,
     "lockstep: sim s from an answer's stamp until it takes effect (the previous "
     "command runs meanwhile): a real-time loop's plan delay", float_range(0, 10)),
    ("lockstep_latency_jitter", 0.0,
     "lockstep: plus a uniform random delay in [0, this] (sim s, seeded)",
     float_range(0, 10)),
    ("lockstep_seed", 0, "lockstep: seed of the latency jitter"),
    ("lockstep_state_offset", 0.0,
     "lockstep: states are published this long (sim s) before the control grid "
     "times k control_period (a state sampled before a timer tick); an answer "
     "stamped up to this much after the state also releases the step",
     float_range(0, 10)),
    ("kp", FromConfig("sim.kp", lambda cfg: cfg.sim.kp), "joint P gain (N m/rad)",
     float_range(0, 1e6)),
    ("kd", FromConfig("sim.kd", lambda cfg: cfg.sim.kd), "joint D gain (N m s/rad)",
     float_range(0, 1e5)),
    ("friction", FromConfig("sim.lateral_friction", lambda cfg: cfg.sim.lateral_friction),
     "foot-ground friction coefficient", float_range(0, 10)),
    ("initial_x", 0.0, "start base x (m)", float_range(-1e3, 1e3)),
    ("initial_y", 0.0, "start base y (m)", float_range(-1e3, 1e3)),
    ("initial_yaw", 0.0, "start base yaw (rad)", float_range(-math.pi, math.pi)),
    ("push_duration", 0.1, "duration of an external_wrench push (s)",
     float_range(1e-3, 60)),
    ("trajectory_timeout", 0.5,
     "a trajectory older than this (sim s) is stale: the robot holds (a longer one is cut "
     "there, with a warning)",
     float_range(1e-3, 1e3)),
    ("max_stamp_offset", 1.0,
     "trajectories stamped further than this from now (sim s) are rejected",
     float_range(1e-3, 1e3)),
]


class SimNode(Node):
    """The simulator node. Construct after ``rclpy.init()``; spin it with any executor."""

    DEFAULT_NAME = "sim"  # spin.PACKAGE_NODES

    def __init__(
        self,
        node_name: str = DEFAULT_NAME,
        *,
        parameter_overrides: Sequence[Parameter] | None = None,
        **kwargs: object,
    ) -> None:
        super().__init__(node_name, parameter_overrides=list(parameter_overrides or []),
                         **kwargs)
        self._keep_system_clock()
        cfg = self._declare_parameters()
        par = self._param
        physics_rate = par("physics_rate")
        # lockstep with the delays of a real-time loop (doc/simulator.md, Lockstep protocol):
        # physics steps from an answer's stamp until it takes effect (plus a seeded uniform
        # jitter), and from a state to the next control grid time (checked before the
        # simulator is built)
        self._steps_per_control = max(1, round(par("control_period") * physics_rate))
        # (real time has delays of its own: there they are 0)
        delays = {name: par(name) if par("lockstep") else 0.0 for name in LOCKSTEP_DELAYS}
        delay_steps = {name: math.floor(d * physics_rate + 0.5) for name, d in delays.items()}
        self._latency_steps, self._jitter_steps, self._offset_steps = delay_steps.values()
        self._rng = random.Random(par("lockstep_seed"))
        total = sum(delay_steps.values())
        if total and total >= self._steps_per_control:
            raise ValueError(
                "lockstep_latency + lockstep_latency_jitter + lockstep_state_offset must be "
                f"shorter than control_period: {total} against {self._steps_per_control} "
                f"physics steps of {1 / physics_rate:g} s (each delay is rounded to whole "
                "steps)")
        # robot_description (URDF text): pybullet and Pinocchio load files, so the text goes
        # to a temporary file for the node's lifetime
        self._description_file = description_file(par("robot_description"))
        try:
            self.sim = Simulator(
                cfg,
                dt=1.0 / physics_rate,
                urdf_path=self._description_file or par("urdf_path") or None,
                kp=par("kp"),
                kd=par("kd"),
                friction=par("friction"),
                base_pose=(par("initial_x"), par("initial_y"), par("initial_yaw")),
                trajectory_timeout=par("trajectory_timeout"),
                max_stamp_offset=par("max_stamp_offset"),
            )
        except (ValueError, RuntimeError, OSError) as exc:
            path = self._description_file
            self._remove_description_file()
            if path is None:
                raise
            # name the parameter, not the temporary file the text was written to (and is
            # gone: 'The file /tmp/robot_description_j0a93tq3.urdf does not contain...')
            said = str(exc).replace(f"The file {path}", "The text").replace(path, "the text")
            raise ValueError(f"robot_description: {said}") from None
        except BaseException:
            self._remove_description_file()
            raise
        self.base_link = cfg.base_link if cfg.base_link in self.sim.robot.link_index \
            else self.sim.robot.root_link
        self._dt_ns = round(NS_PER_S / physics_rate)
        self.realtime_factor = par("realtime_factor")
        self.lockstep = par("lockstep")
        self.lockstep_timeout = par("lockstep_timeout")
        self.push_duration = par("push_duration")
        self._steps_per_state = max(1, round(physics_rate / par("state_rate")))
        # (lockstep publishes a state per control period, free running every state_rate)
        for name, steps, period in (*(() if par("lockstep") else
                                      (("state_rate", self._steps_per_state,
                                        1 / par("state_rate")),)),
                                    ("control_period", self._steps_per_control,
                                     par("control_period")),
                                    *((name, delay_steps[name], delays[name])
                                      for name in LOCKSTEP_DELAYS)):
            if abs(steps * self.sim.dt - period) > 1e-9:
                self.get_logger().warning(
                    f"{name}: {period:g} s is not a whole number of physics steps; "
                    f"using {steps} steps = {steps * self.sim.dt:g} s")
        ignored = [name for name in (*LOCKSTEP_DELAYS, "lockstep_seed") if par(name)]
        if not self.lockstep and ignored:
            self.get_logger().warning(f"{', '.join(ignored)}: lockstep only; ignored")

        self.rejected_trajectories = 0
        self.rejected_wrenches = 0
        self._last_warn: dict[str, float] = {}
        self._stale_cuts_seen = 0
        self._suppressed: dict[str, int] = {}

        self._pub_joints = self.create_publisher(JointState, "joint_states", 10)
        self._pub_odom = self.create_publisher(Odometry, "odom", 10)
        self._pub_clock = self.create_publisher(Clock, "/clock", 10)
        self._sub_trajectory = self.create_subscription(
            JointTrajectory, "joint_trajectory", self._on_trajectory, 10)
        self.create_subscription(WrenchStamped, "external_wrench", self._on_wrench, 10)
        self.create_service(Trigger, "~/reset", self._on_reset)

        # lockstep bookkeeping: the stamp (ns) of the state awaiting an answer
        self.awaiting_stamp_ns: int | None = None
        # trajectories that came stamped otherwise while a state awaited its answer: their
        # count and the last one's stamp minus the awaited one (ns)
        self._off_stamp_answers = (0, 0)
        self._started = not self.lockstep
        self._deadline = self._wall_deadline(START_WAIT)
        self._controller_seen: float | None = None  # wall time, see peers_ready
        self._awaited: tuple[float, tuple] = (math.inf, ())  # resend time, awaited messages
        self.resends = 0  # lockstep states published again (LOCKSTEP_RESEND)
        # free-running pacing anchors (wall ns, sim ns)
        self._anchor: tuple[int, int] | None = None
        if self.lockstep:
            self._timer = self.create_timer(0.005, self._on_lockstep_timer)
        else:
            period = 0.0 if self.realtime_factor <= 0 else \
                self._steps_per_state * self.sim.dt / self.realtime_factor
            self._timer = self.create_timer(period, self._on_free_timer)
        self.get_logger().info(
            f"simulating {cfg.name} ({self.sim.n_joints} joints, {self.sim.total_mass():.2f} kg) "
            f"at {physics_rate:g} Hz, "
            + ("lockstep" if self.lockstep else f"realtime factor {self.realtime_factor:g}")
        )

    # ------------------------------------------------------------------ parameters
    def _keep_system_clock(self) -> None:
        """This node publishes /clock: on ``use_sim_time`` (a shared params file's
        ``/**: use_sim_time: true``) its timers waited for its own clock and it froze
        without a word. Set at start-up it is turned off with a warning; set live, refused."""
        if self.get_parameter("use_sim_time").value:
            self.get_logger().warning("use_sim_time is true, but this node is the clock (it "
                                      "publishes /clock): it runs on the system clock, "
                                      "use_sim_time set to false")
            self.set_parameters([Parameter("use_sim_time", value=False)])

        def refuse(params: list[Parameter]) -> SetParametersResult:
            if any(p.name == "use_sim_time" and p.value for p in params):
                return SetParametersResult(successful=False, reason="sim_node publishes "
                                           "/clock itself: it cannot run on /clock")
            return SetParametersResult(successful=True)

        self.add_on_set_parameters_callback(refuse)

    def _declare_parameters(self) -> RobotConfig:
        """Declare every parameter (all read at start-up: read-only, so a live set is
        refused, not accepted and ignored); the robot config, loaded once ``robot`` and
        ``config`` are, gives the defaults marked :class:`FromConfig` (a value, not an
        unset type: ``ros2 param get/dump`` fail on a parameter without one)."""
        cfg: RobotConfig | None = None
        for name, default, description, *rng in SIM_PARAMETERS:
            if isinstance(default, FromConfig):
                if cfg is None:
                    cfg = load_robot_config(self._param("config") or self._param("robot"))
                default = default.read(cfg)
                if isinstance(default, list):  # per-joint gains: a number given is every joint's
                    default = [float(x) for x in default]
                    self._broadcast_number(name, len(default))
                else:
                    default = float(default)
            declare_parameter(self, name, default, description, *rng, read_only=True)
        return cfg if cfg is not None else load_robot_config(
            self._param("config") or self._param("robot"))

    def _broadcast_number(self, name: str, n: int) -> None:
        """A number given for the list parameter ``name`` (``-p kp:=40`` with per-joint gains
        in the config) becomes that number for each of its ``n`` entries."""
        overrides = start_up_values(self)
        given = overrides.get(name)
        if given is not None and given.type_ in (Parameter.Type.DOUBLE, Parameter.Type.INTEGER):
            overrides[name] = Parameter(name, Parameter.Type.DOUBLE_ARRAY,
                                        [float(given.value)] * n)

    def _param(self, name: str) -> object:
        try:
            return self.get_parameter(name).value
        except ParameterUninitializedException:
            return None

    # ------------------------------------------------------------------ time, publishing
    @property
    def now_ns(self) -> int:
        """Sim time (integer ns, the simulator's own time rounded): the stamp of a state
        published now. (Steps of a rounded length drifted off it where 1e9 / physics_rate
        is no whole number: at 1500 Hz each copied stamp came 10 ns a period ahead of the
        simulator's time and 19 of 20 lockstep answers were rejected.)"""
        return round(self.sim.time * NS_PER_S)

    def _publish_state(self, awaiting: bool = False) -> int:
        cuts = self.sim.reference.stale_cuts
        if cuts != self._stale_cuts_seen:
            self._stale_cuts_seen = cuts
            followed, length = self.sim.reference.last_cut
            self._warn("stale", f"joint_trajectory went stale {followed:g} s after it came, "
                       f"{length - followed:.3f} s before its last point "
                       f"(trajectory_timeout {followed:g} s): the robot holds where its "
                       "reference was; send the next one sooner, or raise trajectory_timeout")
        stamp_ns = self.now_ns
        stamp = time_from_ns(stamp_ns)
        st = self.sim.state()
        msgs = (Clock(clock=stamp),
                joint_state_to_msg(stamp, self.sim.joint_names, st.joint_positions,
                                   st.joint_velocities, st.tau),
                odometry_to_msg(stamp, st.base_position, st.base_quaternion,
                                st.base_linear_velocity, st.base_angular_velocity,
                                frame_id="odom", child_frame_id=self.base_link))
        self._send(msgs)
        if awaiting:
            self.awaiting_stamp_ns = stamp_ns
            self._off_stamp_answers = (0, 0)
            self._deadline = self._wall_deadline()
            self._awaited = (time.monotonic() + LOCKSTEP_RESEND, msgs)
        return stamp_ns

    def _send(self, msgs: tuple[Clock, JointState, Odometry]) -> None:
        """Publish a state's /clock, joint_states and odom messages, in that order."""
        self._pub_clock.publish(msgs[0])
        self._pub_joints.publish(msgs[1])
        self._pub_odom.publish(msgs[2])

    def _wall_deadline(self, at_least: float = 0.0) -> float:
        """lockstep_timeout (or ``at_least`` s, if longer) from now; never with 0."""
        if self.lockstep_timeout <= 0:
            return math.inf
        return time.monotonic() + max(self.lockstep_timeout, at_least)

    def _warn(self, kind: str, text: str) -> None:
        """A warning throttled per ``kind``; says how many were suppressed meanwhile."""
        now = time.monotonic()
        if now - self._last_warn.get(kind, -math.inf) < _WARN_PERIOD:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        n = self._suppressed.pop(kind, 0)
        self._last_warn[kind] = now
        more = f" ({n} similar warnings suppressed)" if n else ""
        self.get_logger().warning(text + more)

    # ------------------------------------------------------------------ stepping
    def step_once(self) -> int:
        """Advance one ``control_period`` of sim time and publish the state (lockstep step).

        Returns the stamp (ns) of the published state; in lockstep mode the next step waits
        for the answer to it.
        """
        self._started = True
        self.sim.step(self._steps_to_next_state())
        return self._publish_state(awaiting=self.lockstep)

    def _steps_to_next_state(self) -> int:
        """Physics steps from now to the next state: one control period; with the lockstep
        delays, to the next grid time ``k control_period - lockstep_state_offset`` (after a
        delayed answer the sim stands between two grid times)."""
        n = self._steps_per_control
        if not (self._offset_steps or self._latency_steps or self._jitter_steps):
            return n
        k = (self.sim.steps + self._offset_steps) // n + 1  # the next grid time k n
        return max(1, k * n - self._offset_steps - self.sim.steps)

    def _answer_releases(self, stamp_ns: int) -> bool:
        """Whether a trajectory stamped ``stamp_ns`` answers the awaited state."""
        awaited = self.awaiting_stamp_ns
        if awaited is None:
            return False
        if stamp_ns == awaited or stamp_ns == 0:
            return True
        return awaited < stamp_ns <= awaited + self._offset_steps * self._dt_ns

    @property
    def peers_ready(self) -> bool:
        """Whether a controller is connected: a ``joint_states`` subscriber and a
        ``joint_trajectory`` publisher, and an ``odom`` subscriber or, for a controller of
        the joints only, :data:`ODOM_GRACE` s (wall) since the other two were seen (one
        whose odom subscription discovery had not matched yet missed the first lockstep
        state, and the simulator waited lockstep_timeout)."""
        if not (self._pub_joints.get_subscription_count() > 0
                and self._sub_trajectory.get_publisher_count() > 0):
            self._controller_seen = None
            return False
        if self._pub_odom.get_subscription_count() > 0:
            return True
        now = time.monotonic()
        if self._controller_seen is None:
            self._controller_seen = now
        return now - self._controller_seen >= ODOM_GRACE

    def _on_lockstep_timer(self) -> None:
        if not self._started:  # the first state goes out once the controller is connected
            if self.peers_ready or time.monotonic() > self._deadline:
                if not self.peers_ready:
                    self.get_logger().warning(
                        "lockstep: no controller connected (joint_states and odom "
                        f"subscribers, joint_trajectory publisher) after "
                        f"{max(self.lockstep_timeout, START_WAIT):g} s; starting anyway")
                self._started = True
                self._publish_state(awaiting=True)
            return
        if self.awaiting_stamp_ns is not None and time.monotonic() > self._deadline:
            self._warn("lockstep", f"no joint_trajectory answered the state stamped "
                       f"{self.awaiting_stamp_ns / NS_PER_S:.3f} s within "
                       f"{self.lockstep_timeout:g} s (wall); continuing with the last command"
                       + self._off_stamp_text())
            self.step_once()
        elif self.awaiting_stamp_ns is not None and time.monotonic() >= self._awaited[0]:
            msgs = self._awaited[1]  # the awaited state again, as it was
            self._awaited = (time.monotonic() + LOCKSTEP_RESEND, msgs)
            self._send(msgs)
            self.resends += 1

    def _off_stamp_text(self) -> str:
        """Why an awaited state went unanswered when trajectories did come, stamped otherwise
        (mpc_node left on trigger 'timer' plans from the state before the awaited one:
        every step waited out lockstep_timeout, 8 s of sim time took 409 s, and nothing
        said why)."""
        n, offset_ns = self._off_stamp_answers
        if not n:
            return ""
        when = (f"{-offset_ns / NS_PER_S:.3f} s before" if offset_ns < 0
                else f"{offset_ns / NS_PER_S:.3f} s after")
        return (f"; {n} joint_trajectory message(s) came meanwhile, the last stamped {when} "
                "it: a lockstep answer carries the stamp of the state it answers (mpc_node: "
                "trigger 'state'; with trigger 'timer' it plans from the state before)")

    def _on_free_timer(self) -> None:
        chunk = self._steps_per_state
        if self.realtime_factor <= 0:  # as fast as possible, the executor's overhead amortised
            budget = time.monotonic() + _FREE_RUN_SLICE
            while True:
                self.sim.step(chunk)
                self._publish_state()
                if time.monotonic() > budget:
                    return
        wall = time.monotonic_ns()
        if self._anchor is None:
            self._anchor = (wall, self.now_ns)
        target = self._anchor[1] + (wall - self._anchor[0]) * self.realtime_factor
        behind = (target - self.now_ns) / NS_PER_S
        if behind > _MAX_LAG * max(1.0, self.realtime_factor):
            self._warn("lag", f"the simulation runs {behind:.2f} s behind realtime factor "
                       f"{self.realtime_factor:g}; dropping the backlog")
            self._anchor = (wall, self.now_ns)
            target = self.now_ns + chunk * self._dt_ns
        while self.now_ns + chunk * self._dt_ns <= target:
            self.sim.step(chunk)
            self._publish_state()

    # ------------------------------------------------------------------ inputs
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        stamp_ns = time_to_ns(msg.header.stamp)
        release = self.lockstep and self._answer_releases(stamp_ns)
        try:
            cmd = joint_trajectory_from_msg(msg, self.sim.time)
            if release and (self._latency_steps or self._jitter_steps or self._offset_steps):
                # the answer reaches the robot d (lockstep_latency + jitter) after its stamp,
                # which may lie after the state it answers (a prepared tick time; a real-time
                # plan cannot arrive before its tick): the previous command runs until then
                d = self._latency_steps + (self._rng.randint(0, self._jitter_steps)
                                           if self._jitter_steps else 0)
                start_ns = stamp_ns if stamp_ns else self.awaiting_stamp_ns
                self.sim.step(max(0, (start_ns - self.now_ns) // self._dt_ns + d))
            note = self.sim.set_trajectory(cmd)
            if note:
                self._warn("effort", f"joint_trajectory: {note}")
        except ValueError as exc:
            self.rejected_trajectories += 1
            self._warn(problem_kind("trajectory", str(exc)),
                       f"rejected joint_trajectory: {exc}; keeping the last good command")
        if release:
            self.awaiting_stamp_ns = None
            self.step_once()
        elif self.lockstep and self.awaiting_stamp_ns is not None and stamp_ns:
            self._off_stamp_answers = (self._off_stamp_answers[0] + 1,
                                       stamp_ns - self.awaiting_stamp_ns)

    def _on_wrench(self, msg: WrenchStamped) -> None:
        link = msg.header.frame_id or self.base_link
        try:
            self.sim.push(link, vector3_from_msg(msg.wrench.force),
                          vector3_from_msg(msg.wrench.torque), self.push_duration)
        except ValueError as exc:
            self.rejected_wrenches += 1
            self._warn(problem_kind("wrench", str(exc)), f"rejected external_wrench: {exc}")

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.sim.reset(reset_time=False)
        response.success = True
        response.message = f"reset to the standing start at t = {self.sim.time:.3f} s"
        self.get_logger().info(response.message)
        return response

    def destroy_node(self) -> None:
        """Destroy the node, close the physics client and remove the robot_description's
        temporary file."""
        self.sim.close()
        self._remove_description_file()
        super().destroy_node()

    def _remove_description_file(self) -> None:
        if self._description_file:
            try:
                os.remove(self._description_file)
            except OSError:
                pass
            self._description_file = None


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``ros2 run horizon_mpc sim_node``; exit code 0 on SIGINT/SIGTERM."""
    return spin_until_signal(SimNode, args, usage, process_exits=True)


def usage() -> str:
    """The ``--help`` text: what the node does and every parameter (all read at start-up)."""
    short = __doc__.split("In short:")[1].split("\n\nThe physics")[0]
    text = " ".join(short.replace("*", "").split()).replace("``", "'")
    lines = ["usage: ros2 run horizon_mpc sim_node [--ros-args -p NAME:=VALUE ... "
             "--params-file FILE]", "",
             textwrap.fill(f"The PyBullet simulator of a robot config as a ROS 2 node: {text}",
                           width=92), "",
             textwrap.fill("Parameters, all read at start-up (details: doc/simulator.md, "
                           "installed in share/horizon_mpc/doc):", width=92), ""]
    for name, default, description, *_ in SIM_PARAMETERS:
        shown = (f"the robot config's {default.what}" if isinstance(default, FromConfig)
                 else repr(default))
        lines.append(f"  {name} (default {shown})")
        lines.append(textwrap.fill(description, width=92, initial_indent=" " * 6,
                                   subsequent_indent=" " * 6))
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
