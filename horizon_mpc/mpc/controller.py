"""The walking MPC as a plain-Python controller (the ROS node wraps it).

At every tick: measured state -> node-0 bounds; command -> clamped, ramped velocity
reference and a reference pose integrated along it; gait -> contact schedule on the horizon
nodes; warm start shifted by the elapsed time; real-time ILQR iteration(s); plan out.
"""

from __future__ import annotations

import logging
import math
import numbers
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from horizon_mpc.codegen import BufferedFunction
from horizon_mpc.config import RobotConfig, load_robot_config
from horizon_mpc.locomotion import MpcSettings, build_walking_problem, config_gait, make_gait
from horizon_mpc.locomotion.command import limit_command, ramp_time
from horizon_mpc.locomotion.gaits import speed_scale
from horizon_mpc.locomotion.pose_reference import (
    advance_pose,
    base_yaw,
    horizon_poses,
    wrap_angle,
)
from horizon_mpc.model import RobotModel
from horizon_mpc.mpc.schedule import GaitScheduler
from horizon_mpc.solvers import make_solver

__all__ = ["Plan", "WalkingMpc"]

log = logging.getLogger(__name__)

# s: two tick times this close are the same time (a ROS stamp's resolution); prepare(t + dt)
# in floating point is 1e-17 s off a state stamped t + dt elsewhere, and with the default
# max_extrapolation 0 an exact comparison ran 56 of 249 replayed go2 ticks whole
SAME_TIME = 1e-9
# s (wall): at most one log line per this about failed ticks (each burst of failures said
# once, and bursts closer than this counted into the next line: every other tick failing
# under hostile odometry logged 10 lines in 2 s)
FAILURE_LOG_PERIOD = 2.0


InverseDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Plan:
    """A solution of the walking problem, from the state measured at time ``t0``.

    Shapes: q (nq, N+1), v (nv, N+1), a (nv, N), f (3 n_feet, N), stance (n_feet, N+1);
    :attr:`tau` (nv, N) is the inverse dynamics of the plan (``tau[6:]`` the joint torques),
    computed on first use by ``inverse_dynamics`` (q, v, a, f of n nodes -> (nv, n)):
    a consumer of the first nodes only asks :meth:`tau_head` and pays for those nodes.
    """

    t0: float
    dt: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    f: np.ndarray
    stance: np.ndarray
    stats: dict = field(default_factory=dict)
    inverse_dynamics: InverseDynamics | None = field(default=None, repr=False, compare=False)
    _tau: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def times(self) -> np.ndarray:
        """Node times relative to ``t0``, shape (N+1,)."""
        return self.dt * np.arange(self.q.shape[1])

    @property
    def tau(self) -> np.ndarray:
        """Inverse dynamics of every stage node, shape (nv, N) (computed once, on first use)."""
        if self._tau is None:
            self._tau = self.tau_head(self.a.shape[1])
        return self._tau

    def tau_head(self, n: int) -> np.ndarray:
        """``tau[:, :n]``, shape (nv, n), without computing the other nodes (``n`` >= 1;
        more than the plan's nodes: all of them)."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"tau_head: n must be an integer >= 1, got {n!r}")
        if self._tau is not None:
            return self._tau[:, :n]
        if self.inverse_dynamics is None:
            raise ValueError("this Plan has no inverse_dynamics to compute tau with")
        n = min(int(n), self.a.shape[1])
        return self.inverse_dynamics(self.q[:, :n], self.v[:, :n], self.a[:, :n],
                                     self.f[:, :n])


class WalkingMpc:
    """Receding-horizon whole-body walking with a warm-started ILQR.

    Args:
        cfg: robot config (or its name); its ``mpc:`` section gives the settings.
        model: the symbolic model (built from the config when None).
        settings: overrides the config's ``mpc:`` section.
        iterations: ILQR iterations per tick (None: the settings' ``iterations``, 1 by
            default).
    """

    def __init__(self, cfg: RobotConfig | str, model: RobotModel | None = None,
                 settings: MpcSettings | None = None, iterations: int | None = None):
        self.cfg = load_robot_config(cfg) if isinstance(cfg, str) else cfg
        self.model = model = model if model is not None else RobotModel.from_config(self.cfg)
        self.settings = settings or MpcSettings.from_config(self.cfg)
        if iterations is None:
            iterations = self.settings.iterations
        if (isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer))
                or iterations < 1):  # 1.7 was taken as 1
            raise ValueError(f"iterations per tick must be a whole number >= 1, got "
                             f"{iterations!r}")
        self.iterations = int(iterations)
        t = time.perf_counter()
        self.wp = build_walking_problem(model, self.cfg, self.settings)
        self.solver = make_solver("ilqr", self.wp.prb, {
            "rti": True, "iterations_per_call": self.iterations,
            "rho_init": self.settings.rho_init, "inequality": self.settings.inequality,
            "barrier_mu": self.settings.barrier_mu, "barrier_delta": self.settings.barrier_delta})
        # per tick: numpy in/out through preallocated buffers (no DM conversion); one mapped
        # function per number of nodes asked for (the horizon, the node's published points)
        self._id_maps: dict[int, BufferedFunction] = {}
        self.prepare_inverse_dynamics(self.wp.n_nodes)
        self.build_time = time.perf_counter() - t
        self.scheduler = GaitScheduler(self.settings.gait.to_gait(len(self.wp.feet)),
                                       stand_when_idle=self.settings.stand_when_idle)
        # the gait the config's velocity limits are for (see velocity_limits)
        self.reference_gait = config_gait(self.cfg)
        self.cmd = np.zeros(3)  # ramped command: vx, vy, wz
        self.pose_ref = np.zeros(3)  # x, y, yaw
        self.t_last: float | None = None
        self.ground_z = np.zeros(len(self.wp.feet))
        # m: the ground (the feet's mean height at start) and the base height reference above it
        self.ground_height = 0.0
        self.base_height_above_ground = float(self.wp.base_height)
        self._stance_set: np.ndarray | None = None  # the stance last given to the problem
        self.failures = 0
        self._failure_log = (-math.inf, 0)  # (wall time of the last line, bursts not said)
        self.divergence_threshold = 1e3  # constraint violation above which a tick has failed
        # wall-clock budget of a tick's solve (s; None: none): the iterations after the first
        # are skipped when they would not end within it (real-time use; the bootstrap solve
        # ignores it)
        self.time_budget: float | None = None
        # the warm start's interpolation between nodes (ticks off the node grid): compiled
        # now (~0.3 s once, then cached; 13 against 55 us per shift on go2), not in a tick
        prb, N = self.wp.prb, self.wp.n_nodes
        self._interp = (BufferedFunction(model.compile(prb.state_difference().map(N))),
                        BufferedFunction(model.compile(prb.state_integrate().map(N))))
        # split real-time iteration (prepare() / the feedback of update()): the tick time
        # the prepared step is for
        self._prepared_for: float | None = None
        # the planned accelerations (nv) around the prepared time (see prepare, _feedback)
        self._accel_before = np.zeros(model.nv)
        self._accel_after = np.zeros(model.nv)
        self.prepare_misses = 0  # ticks too far from the prepared time: whole ticks run
        self.restarts = 0  # ticks that restarted from a state discontinuous with the plan
        self._pose_expected = (0.0, 0.0, 0.0)  # x, y, yaw of the warm start's node 0

    # ------------------------------------------------------------------ set-up
    def start(self, q: np.ndarray, v: np.ndarray, t: float = 0.0,
              max_iter: int = 50) -> Plan:
        """Bootstrap: solve the standing problem at the measured state to convergence.

        Raises:
            ValueError: a state of the wrong shape or not finite, a time not finite, or a
                ``max_iter`` < 1 (nothing changed).
        """
        wp = self.wp
        q, v = self._checked_state(t, q, v)
        if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) \
                or max_iter < 1:
            # (the solver refused it after the controller had reset its warm start and left
            # the ILQR out of its real-time mode)
            raise ValueError(f"start(): max_iter must be an integer >= 1, got {max_iter!r}")
        fk = [self.model.fk(foot) for foot in wp.feet]
        self.ground_z = np.array([float(fn(q)[0][2]) for fn in fk])
        # feet frames may sit above the ground (foot radius): keep the height above them
        lowest_nominal = min(float(fn(wp.q_nominal)[0][2]) for fn in fk)
        self.ground_height = float(np.mean(self.ground_z))
        self.base_height_above_ground = wp.base_height - lowest_nominal
        wp.height_ref.assign(self.base_height_above_ground + self.ground_height)
        self.pose_ref = np.array([q[0], q[1], base_yaw(q)])
        self.cmd[:] = 0.0
        self.scheduler.reset(t)
        wp.standing_guess(q)
        self.solver.reset_multipliers()
        self._set_state(q, v)
        self._set_references(t)
        self.solver.set_option("rti", False)
        self.solver.set_option("max_iter", max_iter)
        self.solver.set_option("time_budget", None)
        self.solver.solve()
        self.solver.set_option("rti", True)
        self.t_last = t
        self._prepared_for = None
        self._pose_expected = _pose(q)
        return self._plan(t)

    def prepare_inverse_dynamics(self, n: int) -> None:
        """Compile (or load from the cache) the ``n``-node inverse dynamics now, not in the
        first tick that asks for ``n`` nodes (see :meth:`inverse_dynamics`)."""
        n = int(n)
        if n not in self._id_maps:
            fn = self.model.inverse_dynamics(self.wp.feet).map(n)
            self._id_maps[n] = BufferedFunction(self.model.compile(fn))

    def inverse_dynamics(self, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                         f: np.ndarray) -> np.ndarray:
        """Generalised forces ``tau`` (nv, n) of n nodes: q (nq, n), v and a (nv, n), foot
        forces f (3 n_feet, n) in world axes; ``tau[:6]`` is the base wrench (zero for a
        feasible plan). One compiled mapped call (compiled on the first use of each n)."""
        n = q.shape[1]
        self.prepare_inverse_dynamics(n)
        return self._id_maps[n](q, v, a, f)[0].copy()

    # ------------------------------------------------------------------ tick
    def update(self, t: float, q: np.ndarray, v: np.ndarray,
               cmd: np.ndarray | None = None) -> Plan:
        """One MPC tick at time ``t`` (s) from the measured ``q`` (nq), ``v`` (nv).

        ``cmd``: desired base velocity ``(vx, vy, wz)`` in the base frame (None: zero).
        After :meth:`prepare` for a time within ``settings.max_extrapolation`` or
        ``settings.feedback_tolerance`` of ``t``, the tick is only the feedback step of the
        prepared iteration (``cmd`` was taken at the preparation); otherwise it is the whole
        tick.

        Raises:
            ValueError: a state of the wrong shape or not finite, a time not finite, a
                command that is not 3 numbers (checked before anything changes: a state with
                an infinite quaternion left the pose reference NaN for good).
        """
        q, v = self._checked_state(t, q, v)
        cmd = self._checked_command(cmd)
        if self.t_last is None:
            return self.start(q, v, t)
        jump = self._discontinuity(t, q)
        if jump is not None:
            # a simulator or estimator reset, an odometry glitch: a plan (and the pose
            # reference) anchored to the old pose would chase it
            self.restarts += 1
            log.warning("%s: restarting from the measured state", jump)
            return self.start(q, v, t)
        if self._prepared_for is not None:
            plan = self._feedback(t, q, v)
            if plan is not None:
                return plan
        dt_tick = max(t - self.t_last, 0.0)
        self._ramp_command(cmd, dt_tick)
        self._shift(dt_tick, q)
        self._advance_pose_ref(q, dt_tick)
        self.t_last = t
        self._pose_expected = _pose(q)
        self._command_gait(t, cmd)
        self._set_state(q, v)
        self._set_references(t)
        ok = self._solve(self.iterations)
        if not ok:
            self._restore_standing(q)
            self._set_state(q, v)
            self._set_references(t)
        return self._plan(t)

    def prepare(self, t_next: float, cmd: np.ndarray | None = None) -> bool:
        """Preparation phase of the tick at ``t_next`` (s): call it after using the plan of
        :meth:`update`, off the latency-critical path (a real-time iteration split in two).

        Moves the problem to ``t_next`` (``cmd`` ramp, reference pose, contact schedule,
        warm start shift) with the warm start's own state there as the predicted node 0,
        runs ``iterations - 1`` whole real-time iterations and prepares the last one
        (quadratisation and backward pass).
        The next :meth:`update` then only rolls the prepared feedback law out from its
        measured state: a state stamped within ``settings.feedback_tolerance`` of
        ``t_next`` takes the prepared step as measured; one up to
        ``settings.max_extrapolation`` away is first predicted to ``t_next`` with the plan's
        acceleration, and the plan starts at ``t_next``; a state further away than both
        gets a whole tick. Returns whether a step is prepared (False: the next update runs
        a whole tick).
        """
        if self.t_last is None:
            raise RuntimeError("prepare() needs a started controller (start() or update())")
        t_next = _checked_time(t_next, "prepare(): the tick time")
        if t_next < self.t_last:
            # the next tick's: one before the last moved the controller's time back, and
            # the next update took the whole gap as elapsed (solo12 ran 0.55 m/s for 0.2)
            raise ValueError(f"prepare(): the tick time {t_next:.6g} s is before the last "
                             f"tick's ({self.t_last:.6g} s): prepare the next tick")
        cmd = self._checked_command(cmd)
        dt_tick = max(t_next - self.t_last, 0.0)
        self._ramp_command(cmd, dt_tick)
        a_guess = self.wp.a
        # the planned acceleration just before t_next, of the node whose interval ends there
        # (node k-1 for a tick of k nodes): the feedback's prediction of a state measured a
        # little before t_next (the one after it: below, once the warm start is final)
        before = min(max(round(dt_tick / self.settings.dt) - 1, 0), self.wp.n_nodes - 1)
        self._accel_before = a_guess.initial_guess[:, before].copy()
        self._shift(dt_tick, self.wp.q.initial_guess[:, 0])
        # the plan's state at t_next
        q_pred, v_pred = self.wp.q.initial_guess[:, 0], self.wp.v.initial_guess[:, 0]
        self._advance_pose_ref(q_pred, dt_tick)
        self.t_last = t_next
        self._pose_expected = _pose(q_pred)
        self._command_gait(t_next, cmd)
        self._set_state(q_pred, v_pred)
        self._set_references(t_next)
        n_whole = self.iterations - 1
        # one multiplier update per tick, after its last iteration (the feedback step)
        if n_whole and not self._solve(n_whole, update_multipliers=False):
            self._restore_standing(q_pred)
            self._set_state(q_pred, v_pred)
            self._set_references(t_next)
        self._accel_after = a_guess.initial_guess[:, 0].copy()
        ok = self.solver.prepare()
        self._prepared_for = t_next if ok else None
        return ok

    @property
    def prepared_for(self) -> float | None:
        """The tick time (s) a :meth:`prepare` awaits its state for, or None."""
        return self._prepared_for

    def _feedback(self, t: float, q: np.ndarray, v: np.ndarray) -> Plan | None:
        """The feedback phase of the prepared iteration from the state measured at ``t``
        (checked: :meth:`_checked_state`); None when ``t`` is too far from the prepared time
        (the caller runs a whole tick).

        At the prepared time (``SAME_TIME``) the plan starts there; within
        ``settings.max_extrapolation`` the state is predicted to it; within
        ``settings.feedback_tolerance`` the prepared step takes the state as measured and
        the plan starts at ``t``, while the controller stays on the prepared time's grid
        (``t_last``): the next preparation from ``t`` let the tick times drift back by up
        to the tolerance each tick."""
        st = self.settings
        t_plan, self._prepared_for = self._prepared_for, None
        lead = t_plan - t
        if abs(lead) > max(st.max_extrapolation, st.feedback_tolerance) + SAME_TIME or (
                not self.solver.prepared):
            self.prepare_misses += 1
            return None
        if SAME_TIME < abs(lead) <= st.max_extrapolation + SAME_TIME:
            # the state predicted to the prepared time with the plan's acceleration over that
            # stretch (the last plan's node ending at the prepared time before it, the
            # prepared warm start's first after it); a constant-velocity prediction kept the
            # velocity measured up to 4 ms early, and solo12's legs change their velocities
            # by 0.3-0.8 rad/s in 4 ms: it fell in 4 ms early states (doc/locomotion.md)
            acc = self._accel_before if lead > 0 else self._accel_after  # set by prepare()
            q = pin.integrate(self.model.pin_model, q, (v + 0.5 * lead * acc) * lead)
            v = v + lead * acc
            t_stamp = t_plan
        else:
            t_stamp = t
        self.t_last = t_plan
        self._pose_expected = _pose(q)
        self.solver.feedback(np.concatenate((q, v)))
        if not self._healthy():
            self._restore_standing(q)
            self._set_state(q, v)
        plan = self._plan(t_stamp)
        plan.stats["iterations"] = self.iterations
        return plan

    def _discontinuity(self, t: float, q: np.ndarray) -> str | None:
        """What makes the state at ``t`` no continuation of the last tick's (time back by
        more than 0.1 s, a base pose off the plan's by more than ``settings.pose_jump`` plus
        what 2 m/s and 3 rad/s explain), or None."""
        if t < self.t_last - 0.1:
            return f"time went back {self.t_last - t:.3f} s"
        x, y = float(q[0]), float(q[1])
        if not (math.isfinite(x) and math.isfinite(y)):
            return None  # the tick's failure handling applies
        x0, y0, yaw0 = self._pose_expected
        dt = abs(t - self.t_last)
        dist = math.hypot(x - x0, y - y0)
        yaw = base_yaw(q)  # atan2 of the quaternion: no unit norm needed
        dyaw = abs(wrap_angle(yaw - yaw0)) if math.isfinite(yaw) else 0.0
        jump = self.settings.pose_jump
        if dist > jump + 2.0 * dt or dyaw > jump + 3.0 * dt:
            return (f"the measured base pose is {dist:.3f} m / {dyaw:.3f} rad off the plan's "
                    f"(pose_jump {jump:g})")
        return None

    def _shift(self, dt_tick: float, q: np.ndarray) -> None:
        """Move the warm start by ``dt_tick`` (s): whole nodes, then the fraction; past the
        horizon, back to standing at ``q``."""
        n_shift = int(round(dt_tick / self.wp.settings.dt))
        if n_shift > self.wp.n_nodes:
            self._restore_standing(q)
            return
        for _ in range(n_shift):
            self.solver.shift()
        # a tick off the node grid (real time: a timer on one clock, states on another)
        # moves the warm start by the rest too, so its nodes sit at t + k dt
        self._shift_fraction(dt_tick / self.wp.settings.dt - n_shift)

    def _command_gait(self, t: float, cmd: np.ndarray | None) -> None:
        walking = self.scheduler.walking
        self.scheduler.command(t, bool(np.any(np.abs(self.cmd) > 1e-3)) or bool(
            cmd is not None and np.any(np.abs(cmd) > 1e-3)))
        if walking and not self.scheduler.walking:
            # the stop is over (every foot down for good): stand where the robot is. The
            # pose reference may still hold the lag of the walk (up to pose_leash; go2
            # walking backwards at -0.3 m/s: 0.35 m), a pose planted feet cannot reach:
            # the costs would only lean the base toward it (_pose_expected: node 0's,
            # set before this call)
            self.pose_ref = np.array(self._pose_expected)

    def _solve(self, iterations: int, update_multipliers: bool = True) -> bool:
        self.solver.set_option("time_budget", self.time_budget)
        self.solver.set_option("iterations_per_call", iterations)
        self.solver.set_option("rti_multiplier_update", update_multipliers)
        self.solver.solve()
        return self._healthy()

    def _healthy(self) -> bool:
        """Whether the solver's last result is usable (finite, not diverged); counts and
        logs the failures (once per burst, at most once per FAILURE_LOG_PERIOD)."""
        sol = self.solver.solution
        # q, v, a, f are rows of the stacked x and u
        finite = bool(sol) and bool(np.isfinite(sol["x"]).all() and np.isfinite(sol["u"]).all())
        diverged = self.solver.stats.constraint_violation > self.divergence_threshold
        if finite and math.isfinite(self.solver.stats.cost) and not diverged:
            self.failures = 0
            return True
        self.failures += 1
        if self.failures == 1:  # a new burst
            last, unsaid = self._failure_log
            now = time.monotonic()
            if now - last < FAILURE_LOG_PERIOD:
                self._failure_log = (last, unsaid + 1)
            else:
                log.warning("ILQR failed (%s): back to the standing warm start%s",
                            self.solver.stats.status,
                            f" ({unsaid} more bursts of failures before it)" if unsaid else "")
                self._failure_log = (now, 0)
        return False

    # ------------------------------------------------------------------ pieces
    @staticmethod
    def _clean_q(q: np.ndarray) -> np.ndarray:
        """A copy of ``q`` with a unit base quaternion (identity if it has no direction: a
        zero one; a non-finite one is refused before, :meth:`_checked_state`)."""
        q = np.array(q, dtype=float)
        n = math.hypot(*q[3:7].tolist())  # four numbers: no numpy call (every tick)
        q[3:7] = q[3:7] / n if n > 1e-9 else (0.0, 0.0, 0.0, 1.0)
        return q

    def _checked_state(self, t: float, q: np.ndarray, v: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
        """``(q, v)`` as clean float arrays (:meth:`_clean_q`), or ValueError naming what is
        wrong: a time or a state entry not finite, a state of the wrong shape."""
        _checked_time(t, "the state's time")
        q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
        nq, nv = self.model.nq, self.model.nv
        if q.shape != (nq,) or v.shape != (nv,):
            raise ValueError(f"state of shapes q {q.shape}, v {v.shape}; the model has q "
                             f"({nq},), v ({nv},)")
        if not (np.isfinite(q).all() and np.isfinite(v).all()):
            bad = [f"{n}[{i}]" for n, x in (("q", q), ("v", v))
                   for i in np.flatnonzero(~np.isfinite(x))]
            raise ValueError(f"state not finite at {', '.join(bad[:6])}: not planned from")
        return self._clean_q(q), v

    @staticmethod
    def _checked_command(cmd: np.ndarray | None) -> np.ndarray | None:
        """``cmd`` as 3 floats (NaN/inf entries are zeroed later), or ValueError."""
        if cmd is None:
            return None
        try:
            arr = np.asarray(cmd, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"command must be 3 numbers (vx, vy, wz), got {cmd!r}") from None
        if arr.shape != (3,):
            raise ValueError(f"command must be 3 numbers (vx, vy, wz), got shape {arr.shape}")
        return arr

    def _set_state(self, q: np.ndarray, v: np.ndarray) -> None:
        self.wp.q.set_bounds(q, q, nodes=0)
        self.wp.v.set_bounds(v, v, nodes=0)
        # the warm start's first node is the measured state (the gap closes in one step)
        self.wp.q.set_initial_guess(q, nodes=0)
        self.wp.v.set_initial_guess(v, nodes=0)

    def _shift_fraction(self, r: float, tol: float = 0.05) -> None:
        """Move the warm start by ``r`` nodes (|r| <= 1/2): each node's state and input are
        interpolated toward the next node's (r > 0) or the previous one's (r < 0), states
        on their manifold (``x (+) |r| (x' (-) x)``). Below ``tol`` nothing moves (lockstep
        ticks sit on the grid to rounding)."""
        if abs(r) < tol:
            return
        prb, N = self.wp.prb, self.wp.n_nodes
        diff, integ = self._interp
        X, U = prb.stacked("state", copy=False), prb.stacked("input", copy=False)
        a, b = (slice(0, N), slice(1, N + 1)) if r > 0 else (slice(1, N + 1), slice(0, N))
        X_new = X.copy()
        X_new[:, a] = integ(X[:, a], abs(r) * diff(X[:, a], X[:, b])[0])[0]
        U_new = U.copy()
        ua, ub = (slice(0, N - 1), slice(1, N)) if r > 0 else (slice(1, N), slice(0, N - 1))
        U_new[:, ua] = U[:, ua] + abs(r) * (U[:, ub] - U[:, ua])
        prb.set_stacked_initial_guess("state", X_new)
        prb.set_stacked_initial_guess("input", U_new)

    def _restore_standing(self, q: np.ndarray) -> None:
        self.wp.standing_guess(q)
        self.solver.reset_multipliers()

    def _ramp_command(self, cmd: np.ndarray | None, dt: float) -> None:
        """Move the ramped command toward ``cmd`` (None: zero; NaN/inf: zero), limited per
        axis and as a whole (:func:`limit_command`), for ``dt`` along the ramp of
        :func:`~horizon_mpc.locomotion.command.ramp_time` (the axes' accelerations, each a
        share of its limit, of norm at most 1)."""
        st = self.settings
        cmd = [0.0, 0.0, 0.0] if cmd is None else np.asarray(cmd, float).tolist()
        # three numbers: plain floats (numpy's per-call overhead was ~50 us a tick here)
        target = limit_command([c if math.isfinite(c) else 0.0 for c in cmd],
                               self.velocity_limits, st.max_command_norm)
        if self.scheduler.gait.stands or self.scheduler.pending is not None:
            # a gait that never lifts a foot (stand): the command cannot be walked; moving
            # the base on planted feet slid them (34 deg of yaw, feet dragged 2 cm). A gait
            # change stops the walk first (GaitScheduler.set_gait): ramped down with it,
            # the command ramps up again with the new gait, where it held on and go2,
            # stopped by the change, lunged to 0.8 m/s to catch up a 0.3 m/s command
            target = (0.0, 0.0, 0.0)
        # along a straight line in command space, the axes' accelerations of normalised
        # norm <= 1 (locomotion/command.py: a reversal of all three axes at once, each at
        # its own limit, made go2 sink 6 cm)
        delta = [c - x for c, x in zip(target, self.cmd, strict=True)]
        need = ramp_time(delta, st.max_acceleration)
        share = 1.0 if need <= dt else dt / need
        for i, (d, amax) in enumerate(zip(delta, st.max_acceleration, strict=True)):
            self.cmd[i] += d * share if amax > 0 else 0.0

    @property
    def velocity_limits(self) -> list[float]:
        """The per-axis command limits (vx, vy, wz) of the gait walked now (and of the one
        pending, the lower): ``settings.max_velocity`` times :func:`speed_scale` of that gait
        against the config's (a walk gets a third of the trot's limits at one step duration)."""
        sch = self.scheduler
        # while a change is pending, the slower of the two (the old gait's swings go on)
        scale = min(speed_scale(g, self.reference_gait) for g in (sch.gait, sch.pending) if g)
        return [scale * float(v) for v in self.settings.max_velocity]

    def _advance_pose_ref(self, q: np.ndarray, dt: float) -> None:
        st = self.settings
        self.pose_ref = advance_pose(self.pose_ref, self.cmd, q, dt, st.pose_leash, st.yaw_leash)

    def _velocity_reference(self) -> list[float]:
        """The base velocity reference ``(vx, vy, wz)`` (base frame) of the horizon: while
        walking, the ramped command plus the pose error (reference pose minus the measured
        one, node 0) closed over the horizon, within the command limits; standing, the
        ramped command.

        The pose reference is the integral action of velocity tracking, but a velocity
        reference of the bare command fought it: a correction of the pose is a velocity
        off the command, which the velocity cost (weights 40-100 against 50 for the
        position) resisted, so a drift held the robot 0.06-0.10 m off its pose reference
        for seconds (go2: 0.036 m/s for 0.02, 0.012-0.024 m/s in x for a lateral command;
        0.07-0.13 rad short of a 1.5 rad turn; doc/locomotion.md). With the error closed over
        the horizon, velocity and pose references agree at the horizon's end."""
        vx, vy, wz = (float(c) for c in self.cmd)
        if not self.scheduler.walking:
            # feet down: the base cannot walk to a pose (moving it on planted feet slid them)
            return [vx, vy, wz]
        x, y, yaw = self._pose_expected  # node 0: the measured (or predicted) state
        ex, ey = float(self.pose_ref[0]) - x, float(self.pose_ref[1]) - y
        c, s = math.cos(yaw), math.sin(yaw)
        horizon = self.wp.n_nodes * self.settings.dt
        v = [vx + (c * ex + s * ey) / horizon, vy + (c * ey - s * ex) / horizon,
             wz + wrap_angle(float(self.pose_ref[2]) - yaw) / horizon]
        return list(limit_command(v, self.velocity_limits, self.settings.max_command_norm))

    def _set_references(self, t: float) -> None:
        wp, st = self.wp, self.settings
        N, dt = wp.n_nodes, st.dt
        vx, vy, wz = self._velocity_reference()
        wp.v_ref.assign([vx, vy, 0.0, 0.0, 0.0, wz])
        wp.pose_ref.assign(horizon_poses(self.pose_ref, self.cmd, N, dt))
        sched = self.scheduler.schedule(t, N, dt)
        self._set_stance(sched.stance)
        wp.contacts.set_swing_height(self.ground_z[:, None] + sched.swing_height())
        self._stance = sched.stance

    def _set_stance(self, stance: np.ndarray) -> None:
        # the contact terms' node sets cost ~10 us each through the Problem API (16 for four
        # feet): skip them when the stance did not change (standing). Shifts leave node sets
        # alone and this controller is the only writer of its contact terms' nodes.
        if self._stance_set is not None and np.array_equal(stance, self._stance_set):
            return
        self.wp.contacts.set_stance(stance)
        self._stance_set = stance.copy()

    def _plan(self, t: float) -> Plan:
        # tau is left to the consumer: the node needs the first few nodes only
        sol = self.solver.solution
        return Plan(t, self.settings.dt, sol["q"].copy(), sol["v"].copy(), sol["a"].copy(),
                    sol["f"].copy(), self._stance.copy(), self.solver.stats.as_dict(history=False),
                    self.inverse_dynamics)

    # ------------------------------------------------------------------ live settings
    def set_gait(self, name: str, step_duration: float | None = None,
                 step_height: float | None = None, duty_factor: float | None = None) -> None:
        """Switch gait (from the next tick): ``step_duration`` and ``step_height`` None keep
        the current ones, ``duty_factor`` None is the gait's own (walk 0.75, the others
        0.5). Checked before anything changes. While walking the contacts do not jump: a new
        step duration or height keeps the cycle's phase, another gait or duty factor starts
        once the swings in progress have ended (:meth:`GaitScheduler.set_gait`).

        Raises:
            ValueError: an unknown gait or a value out of its range (nothing changed).
        """
        g = self.settings.gait
        step_duration = g.step_duration if step_duration is None else step_duration
        step_height = g.step_height if step_height is None else step_height
        # make_gait checks every value (a stand's ignored duty factor too: 5.0 was stored
        # and the settings were then invalid)
        gait = make_gait(name, step_duration, step_height, duty_factor, len(self.wp.feet))
        step_duration, step_height = float(step_duration), float(step_height)
        old = self.scheduler.pending or self.scheduler.gait
        changed = (gait.name, gait.period, gait.duty_factor) != (old.name, old.period,
                                                                 old.duty_factor)
        g.name, g.step_duration, g.step_height = name, step_duration, step_height
        g.duty_factor = None if duty_factor is None else float(duty_factor)
        if changed and self.scheduler.walking:
            # the pose reference's lag belongs to the old gait: the walk tracks ~75 % of its
            # command, so its lag grew to pose_leash, and the trot's higher limits released
            # it at once (go2 lunged to 0.8 m/s for a 0.3 command, fell in real time). A
            # standing robot keeps its reference (a pushed one walks back to it)
            self.pose_ref = np.array(self._pose_expected)
        self.scheduler.set_gait(gait, self.t_last if self.t_last is not None else 0.0)

    def set_stand_when_idle(self, stand: bool) -> None:
        """With a zero command, keep the feet down (True) or keep the gait stepping in place
        (False); takes effect at the next tick."""
        if not isinstance(stand, (bool, np.bool_)):  # bool("false") is True
            raise TypeError(f"stand_when_idle must be True or False, got {stand!r}")
        self.settings.stand_when_idle = self.scheduler.stand_when_idle = bool(stand)


def _checked_time(t: object, what: str) -> float:
    """``t`` (s) as a float: a finite real number (numpy's, a 0-d array too), else a
    ValueError naming ``what`` (True was a time of 1 s, '0' a TypeError)."""
    if isinstance(t, (bool, np.bool_)) or not (
            isinstance(t, numbers.Real) or (isinstance(t, np.ndarray) and t.ndim == 0
                                            and np.issubdtype(t.dtype, np.number))):
        raise ValueError(f"{what} must be a finite number (s), got {t!r}")
    value = float(t)
    if not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number (s), got {t!r}")
    return value


def _pose(q: np.ndarray) -> tuple[float, float, float]:
    return float(q[0]), float(q[1]), base_yaw(q)
