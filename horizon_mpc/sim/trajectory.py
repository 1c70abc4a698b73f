"""Joint trajectory commands: validation, and the reference they define at each physics step.

A :class:`JointTrajectoryCommand` is the library form of a ``trajectory_msgs/JointTrajectory``:
K points at times ``t0 + times[k]`` (sim seconds) with joint positions (rad or m), optional
velocities and optional efforts (N m or N). :class:`ReferenceGenerator` turns the latest
command into ``(q_ref, v_ref, tau_ff)`` at any time:

* between points: cubic Hermite on positions when velocities are given (``v_ref`` is its
  time derivative, so position and velocity references agree), linear otherwise; efforts
  linear;
* before the first point (its time is later than the moment the command was set): the
  reference at that moment is prepended, so the robot moves smoothly onto the trajectory;
* after the last point, or once the command is older than ``timeout`` (the sender died): hold
  the reference reached, with ``v_ref = 0`` (the D term damps) and its feed-forward torque.
  The robot is never let go.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["PLAUSIBLE", "PLAUSIBLE_SPEED", "JointTrajectoryCommand", "ReferenceGenerator"]


#: magnitudes no joint reference reaches (rad or m, rad/s or m/s, N m or N): beyond them a
#: command is garbage, and its interpolation would overflow into the physics (NaN state)
PLAUSIBLE = {"positions": 1e4, "velocities": 1e5, "efforts": 1e7}
#: rad/s or m/s: the speed between two consecutive points no joint reaches (URDF limits:
#: 20-40 rad/s); two points 1 ns apart and 0.3 rad apart asked for 3e8 rad/s, which the
#: interpolation fed to the D term: 1000 N m, the robot launched at 100 m/s
PLAUSIBLE_SPEED = 1e2
#: s: a first point this close ahead of now is now (stamps are whole ns; a stamp copied
#: from a state and read back as seconds can land an ulp or a rounding ahead of sim time)
STAMP_RESOLUTION = 1e-9


def _finite_array(name: str, value: object, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not a numeric array of shape {shape}: {exc}") from None
    if arr.shape != shape:
        raise ValueError(f"{name} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name} contains NaN/Inf (first at index {tuple(int(i) for i in bad)})")
    bound = PLAUSIBLE.get(name)
    if bound is not None and arr.size and np.max(np.abs(arr)) > bound:
        bad = np.unravel_index(int(np.argmax(np.abs(arr))), arr.shape)
        raise ValueError(f"{name} beyond the plausible {bound:g} (at index "
                         f"{tuple(int(i) for i in bad)}: {arr[bad]:g})")
    return arr


@dataclass
class JointTrajectoryCommand:
    """A joint trajectory: K points for nj named joints.

    Attributes:
        joint_names: (nj,) joint names; column j of the arrays belongs to ``joint_names[j]``.
        t0: stamp (sim s) that ``times`` count from.
        times: (K,) strictly increasing, >= 0 (s).
        positions: (K, nj) joint positions (rad / m).
        velocities: (K, nj) joint velocities (rad/s / m/s), or None.
        efforts: (K, nj) feed-forward efforts (N m / N), or None (zero feed-forward).
    """

    joint_names: Sequence[str]
    t0: float
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    efforts: np.ndarray | None = None

    def validate(
        self,
        expected_joints: Sequence[str] | None = None,
        now: float | None = None,
        max_stamp_offset: float = 1.0,
    ) -> JointTrajectoryCommand:
        """Check the command; return a copy with float arrays of the documented shapes.

        Args:
            expected_joints: if given, ``joint_names`` must be exactly these (any order).
            now: current sim time (s); if given, ``|t0 - now|`` must be ``<= max_stamp_offset``.
            max_stamp_offset: accepted stamp age / lead (s).

        Raises:
            ValueError: with a message naming the problem.
        """
        if isinstance(self.joint_names, str):  # list("LF_HAA") is its letters
            raise ValueError(f"joint_names must be a list of names, got the string "
                             f"{self.joint_names!r}")
        names = list(self.joint_names)
        if not names:
            raise ValueError("joint_names is empty")
        if not all(isinstance(n, str) for n in names):
            raise ValueError("joint_names must be strings")
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"duplicate joint names: {dup}")
        if expected_joints is not None:
            expected = set(expected_joints)
            unknown = [n for n in names if n not in expected]
            if unknown:
                raise ValueError(
                    f"unknown joint names {unknown}; the joints are: {list(expected_joints)}"
                )
            missing = [n for n in expected_joints if n not in set(names)]
            if missing:
                raise ValueError(f"missing joint names {missing} (every joint must be commanded)")
        try:
            t0 = float(self.t0)
        except (TypeError, ValueError):
            raise ValueError(f"t0 is not a number: {self.t0!r}") from None
        if not math.isfinite(t0):
            raise ValueError(f"t0 is not finite: {t0}")
        try:
            k = len(self.times)  # type: ignore[arg-type]
        except TypeError:
            raise ValueError("times is not a sequence") from None
        if k == 0:
            raise ValueError("the trajectory has no points")
        times = _finite_array("times", self.times, (k,))
        if times[0] < 0.0:
            raise ValueError(f"times[0] = {times[0]} is negative")
        steps = np.diff(times)
        if np.any(steps <= 0.0):
            i = int(np.argmax(steps <= 0.0))
            raise ValueError(
                f"times are not strictly increasing: times[{i}] = {times[i]}, "
                f"times[{i + 1}] = {times[i + 1]}"
            )
        shape = (k, len(names))
        positions = _finite_array("positions", self.positions, shape)
        if k > 1:
            speed = np.abs(np.diff(positions, axis=0)) / steps[:, None]
            if np.any(speed > PLAUSIBLE_SPEED):
                i, j = np.unravel_index(int(np.argmax(speed)), speed.shape)
                raise ValueError(
                    f"points {i} and {i + 1} ask joint {names[j]!r} to move "
                    f"{abs(positions[i + 1, j] - positions[i, j]):.3g} in {steps[i]:.3g} s "
                    f"({speed[i, j]:.3g} per s, beyond {PLAUSIBLE_SPEED:g})")
        velocities = None
        if self.velocities is not None:
            velocities = _finite_array("velocities", self.velocities, shape)
        efforts = None
        if self.efforts is not None:
            efforts = _finite_array("efforts", self.efforts, shape)
        if now is not None:
            if t0 - now > max_stamp_offset:
                raise ValueError(
                    f"stamp {t0:.6f} s is {t0 - now:.3f} s in the future (now {now:.6f} s, "
                    f"accepted: {max_stamp_offset} s)"
                )
            if now - t0 > max_stamp_offset:
                raise ValueError(
                    f"stamp {t0:.6f} s is {now - t0:.3f} s old (now {now:.6f} s, "
                    f"accepted: {max_stamp_offset} s)"
                )
        return JointTrajectoryCommand(names, t0, times, positions, velocities, efforts)

    def reordered(self, joint_names: Sequence[str]) -> JointTrajectoryCommand:
        """The same command with columns in the order of ``joint_names`` (a permutation)."""
        col = {n: j for j, n in enumerate(self.joint_names)}
        idx = [col[n] for n in joint_names]

        def pick(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else np.asarray(a, dtype=float)[:, idx]

        return JointTrajectoryCommand(
            list(joint_names), self.t0, np.asarray(self.times, dtype=float),
            pick(self.positions), pick(self.velocities), pick(self.efforts),
        )


# Cubic Hermite basis: q(s) = [1, s, s^2, s^3] @ _HERMITE @ [q0, h v0, q1, h v1], s in [0, 1].
_HERMITE = np.array([
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [-3.0, -2.0, 3.0, -1.0],
    [2.0, 1.0, -2.0, 1.0],
])


class ReferenceGenerator:
    """The joint reference ``(q_ref, v_ref, tau_ff)`` defined by the latest command.

    Arrays are (nj,) in the simulator's joint order. :meth:`reference` is called every physics
    step, so the interpolation is prepared when a command arrives: per segment, the power-basis
    coefficients of positions (cubic) and efforts (linear) in one (4, 2 nj) block; a step then
    costs one (2, 4) @ (4, 2 nj) product and the segment index moves forward incrementally.
    """

    def __init__(self, n_joints: int, timeout: float = 0.5) -> None:
        """Args: n_joints: nj; timeout: age (s, since :meth:`set_command`) of a stale command."""
        self.n_joints = n_joints
        self.timeout = timeout
        zeros = np.zeros(n_joints)
        self._hold = (zeros.copy(), zeros.copy(), zeros.copy())
        self._times: np.ndarray | None = None  # (K,) absolute sim times
        self._points: tuple[np.ndarray, np.ndarray, np.ndarray] = (zeros, zeros, zeros)
        self._coef = np.zeros((0, 4, 2 * n_joints))  # (K - 1, 4, 2 nj)
        self._segment = 0
        self._received = 0.0
        #: commands frozen as stale before their last point, and the last of them:
        #: (sim s followed, sim s it was long, both from its arrival)
        self.stale_cuts = 0
        self.last_cut: tuple[float, float] | None = None

    @property
    def holding(self) -> bool:
        """True when no trajectory is being followed (holding a posture)."""
        return self._times is None

    def hold(self, q: np.ndarray, tau_ff: np.ndarray) -> None:
        """Drop any trajectory; hold joint positions ``q`` (nj,) with feed-forward ``tau_ff``."""
        self._times = None
        self._hold = (np.array(q, dtype=float), np.zeros(self.n_joints),
                      np.array(tau_ff, dtype=float))

    def set_command(self, cmd: JointTrajectoryCommand, now: float) -> None:
        """Follow ``cmd`` (validated, columns in simulator joint order) from sim time ``now``.

        Raises:
            ValueError: its first point lies ahead of ``now`` and reaching it from the current
                reference is beyond :data:`PLAUSIBLE_SPEED`, or further ahead than the
                timeout (it would be stale before it is reached); nothing changes then.
        """
        times = cmd.t0 + np.asarray(cmd.times, dtype=float)
        if times[0] - now > self.timeout:
            # accepted, it was never reached: frozen as stale on the way (an auditor's point
            # 0.8 s ahead stayed at a quarter of its way)
            raise ValueError(f"the first point is {times[0] - now:.3f} s ahead, beyond "
                             f"trajectory_timeout ({self.timeout:g} s): the command would be "
                             "stale (held) before it is reached; send it later or raise "
                             "trajectory_timeout")
        k, nj = cmd.positions.shape
        q = np.asarray(cmd.positions, dtype=float)
        has_v = cmd.velocities is not None
        v = np.asarray(cmd.velocities, dtype=float) if has_v else np.zeros((k, nj))
        tau = np.asarray(cmd.efforts, dtype=float) if cmd.efforts is not None else np.zeros((k, nj))
        if times[0] > now + STAMP_RESOLUTION:  # start from where the reference is now
            q_now, v_now, tau_now = self.reference(now)
            # that segment too must be a plausible speed (validate() sees only cmd's own):
            # one future point 1.5 ms ahead and 0.8 rad away drove solo12 at 100 rad/s
            speed = np.abs(q[0] - q_now) / (times[0] - now)
            if np.any(speed > PLAUSIBLE_SPEED):
                j = int(np.argmax(speed))
                raise ValueError(
                    f"the first point, {times[0] - now:.3g} s ahead, asks joint {j} to move "
                    f"{abs(q[0, j] - q_now[j]):.3g} from the current reference ({speed[j]:.3g} "
                    f"per s, beyond {PLAUSIBLE_SPEED:g})")
            times = np.concatenate(([now], times))
            q, v, tau = np.vstack((q_now, q)), np.vstack((v_now, v)), np.vstack((tau_now, tau))
        h = np.diff(times)[:, None]  # (K - 1, 1)
        coef = np.zeros((len(times) - 1, 4, 2 * nj))
        if has_v:
            ends = np.stack((q[:-1], h * v[:-1], q[1:], h * v[1:]), axis=1)  # (K - 1, 4, nj)
            coef[:, :, :nj] = np.einsum("ij,sjn->sin", _HERMITE, ends)
        else:
            coef[:, 0, :nj], coef[:, 1, :nj] = q[:-1], q[1:] - q[:-1]
        coef[:, 0, nj:], coef[:, 1, nj:] = tau[:-1], tau[1:] - tau[:-1]
        self._times, self._points, self._coef = times, (q, v, tau), coef
        self._segment = 0
        self._received = now

    def reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q_ref, v_ref, tau_ff)`` at sim time ``t`` (s), each (nj,). Do not modify them."""
        times = self._times
        if times is None:
            return self._hold
        if t - self._received > self.timeout:  # stale: freeze where the reference was
            q, _, tau = self._interpolate(times, min(self._received + self.timeout, times[-1]))
            if times[-1] > self._received + self.timeout + STAMP_RESOLUTION:  # not its noise
                self.stale_cuts += 1
                self.last_cut = (self.timeout, float(times[-1] - self._received))
            self.hold(q, tau)
            return self._hold
        if t >= times[-1]:  # ran out: hold the last point
            self.hold(self._points[0][-1], self._points[2][-1])
            return self._hold
        return self._interpolate(times, t)

    def _interpolate(
        self, times: np.ndarray, t: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if t <= times[0]:
            return self._points[0][0], self._points[1][0], self._points[2][0]
        if t >= times[-1]:
            return self._points[0][-1], self._points[1][-1], self._points[2][-1]
        i = self._segment
        if t < times[i]:  # time went back (a query for the past): search
            i = int(np.searchsorted(times, t, side="right")) - 1
        while t >= times[i + 1]:
            i += 1
        self._segment = i
        h = times[i + 1] - times[i]
        s = (t - times[i]) / h
        basis = np.array([[1.0, s, s * s, s * s * s],
                          [0.0, 1.0 / h, 2.0 * s / h, 3.0 * s * s / h]])
        out = basis @ self._coef[i]  # (2, 2 nj): [q, tau] and their time derivatives
        nj = self.n_joints
        return out[0, :nj], out[1, :nj], out[0, nj:]
