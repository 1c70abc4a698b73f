"""Command profiles of the closed loop (:mod:`horizon_mpc.closed_loop`): velocity segments and
scripted pushes, read from YAML (format in ``doc/closed_loop.md``)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from horizon_mpc.config import find_config_file, read_yaml
from horizon_mpc.locomotion.command import DEFAULT_MAX_NORM, limit_command, ramp_time
from horizon_mpc.nodes.mpc_inputs import ABSURD_COMMAND
from horizon_mpc.sim.simulator import PLAUSIBLE_WRENCH

__all__ = ["DEFAULT_PROFILE", "MAX_COMMAND", "MAX_PUSH", "Push", "Segment", "command_at",
           "load_profile", "load_pushes", "profile_file", "unreached_segments",
           "with_zero_tail"]

DEFAULT_PROFILE = "default"  # config/commands/default.yaml (installed under share/horizon_mpc)


def profile_file(name_or_path: str | Path) -> Path:
    """The YAML file of a command profile: a path (``.yaml``/``.yml``), or the name of one
    in ``config/commands`` (the source tree's, or the installed copy under
    ``share/horizon_mpc``: see :func:`horizon_mpc.config.config_dirs`).

    Raises:
        FileNotFoundError: no such profile (the message lists the available names).
    """
    return find_config_file(name_or_path, "command profile", subdir="commands")


@dataclass
class Segment:
    """A constant command ``(vx, vy, wz)`` (base frame) held for ``duration`` s.

    Raises:
        ValueError: a duration that is not a finite number > 0, a command that is not
            finite or beyond :data:`MAX_COMMAND` (a negative duration ran 1 tick without
            a word when given from Python).
    """

    duration: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0

    def __post_init__(self) -> None:
        for k in ("duration", "vx", "vy", "wz"):  # plain floats (numpy's, a '2' too)
            setattr(self, k, _number(getattr(self, k), k))
        if not self.duration > 0:
            raise ValueError(f"non-positive duration {self.duration}")
        fast = {k: v for k, v in (("vx", self.vx), ("vy", self.vy), ("wz", self.wz))
                if abs(v) > MAX_COMMAND}
        if fast:
            raise ValueError(f"{fast} beyond {MAX_COMMAND:g} (m/s, rad/s), which the MPC node "
                             "rejects as garbage")


@dataclass
class Push:
    """A world-frame ``force`` (N) on the base for ``duration`` s from sim time ``time``.

    Raises:
        ValueError: a time < 0, a duration <= 0, a force that is not 3 finite numbers or
            beyond :data:`MAX_PUSH`.
    """

    time: float
    force: tuple[float, float, float]
    duration: float = 0.1

    def __post_init__(self) -> None:
        try:
            three = not isinstance(self.force, (str, bytes)) and np.shape(self.force) == (3,)
        except ValueError:  # ragged
            three = False
        if not three:
            raise ValueError(f"force must be a list [fx, fy, fz], got {self.force!r}")
        self.force = tuple(_number(f, "force") for f in self.force)
        self.time, self.duration = _number(self.time, "time"), _number(self.duration, "duration")
        if self.time < 0 or not self.duration > 0:
            raise ValueError("time must be >= 0 and duration > 0")
        if max(map(abs, self.force)) > MAX_PUSH:
            raise ValueError(f"force beyond {MAX_PUSH:g} N")


#: |vx|, |vy| (m/s), |wz| (rad/s) a profile may command: the MPC node rejects faster
#: commands as garbage, so a run with one would be scored against a command the robot
#: never received
MAX_COMMAND = ABSURD_COMMAND
#: N: the simulator refuses larger pushes
MAX_PUSH = PLAUSIBLE_WRENCH


def _read(path: str | Path) -> tuple[Path, object]:
    path = profile_file(path)
    data = read_yaml(path)
    if isinstance(data, dict):
        unknown = set(data) - {"segments", "pushes"}
        if unknown:
            raise ValueError(f"{path}: unknown key(s) {sorted(map(str, unknown))}; a profile has "
                             "'segments' and optionally 'pushes'")
    return path, data


def _number(value: object, where: str) -> float:
    """A finite real number, else ValueError naming ``where``. Not a bool; a string only
    when it spells a number (YAML 1.1 reads ``1e9``, without a dot, as a string)."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise ValueError(f"{where} must be a number, got {value!r}") from None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise ValueError(f"{where} must be a number, got {value!r}")
    try:
        x = float(value)
    except OverflowError:  # an integer beyond a float's range
        x = math.inf
    if not math.isfinite(x):
        raise ValueError(f"{where} must be finite, got {value!r}")
    return x


def load_pushes(path: str | Path) -> list[Push]:
    """The optional ``pushes:`` list of a profile YAML or name (``{time, force: [fx, fy,
    fz], duration}``); empty when the profile has none.

    Raises:
        ValueError: a push that is not a mapping of those keys, a time < 0, a force that is
            not 3 finite numbers or beyond :data:`MAX_PUSH`, a duration <= 0.
    """
    path, data = _read(path)
    items = data.get("pushes") if isinstance(data, dict) else None
    if items is None:
        return []
    if not isinstance(items, list):
        raise ValueError(f"{path}: 'pushes' must be a list of {{time, force, duration}}")
    pushes = []
    for i, item in enumerate(items):
        where = f"{path}: push {i}"
        if not isinstance(item, dict) or not {"time", "force"} <= set(item) or (
                set(item) - {"time", "force", "duration"}):
            raise ValueError(f"{where} needs 'time', 'force' [fx, fy, fz] and optionally "
                             f"'duration', got {item!r}")
        try:  # (Push checks and converts its values)
            pushes.append(Push(item["time"], item["force"], item.get("duration", 0.1)))
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
    return pushes


def load_profile(path: str | Path) -> list[Segment]:
    """Segments of a command profile YAML or name (a list, or a mapping with
    ``segments:``).

    Raises:
        FileNotFoundError: no such profile.
        ValueError: not YAML, no segments, a segment that is not a mapping of ``duration``
            (finite, > 0) and ``vx``/``vy``/``wz`` (finite numbers within
            :data:`MAX_COMMAND`), unknown keys.
    """
    path, data = _read(path)
    items = data.get("segments") if isinstance(data, dict) else data
    if not isinstance(items, list) or not items:
        raise ValueError(f"{path}: expected a list of segments {{duration, vx, vy, wz}}")
    segs = []
    for i, item in enumerate(items):
        where = f"{path}: segment {i}"
        if not isinstance(item, dict):
            raise ValueError(f"{where} must be a mapping {{duration, vx, vy, wz}}, got {item!r}")
        unknown = set(item) - {"duration", "vx", "vy", "wz"}
        if unknown or "duration" not in item:
            raise ValueError(f"{where} needs 'duration' and only vx/vy/wz, got "
                             f"{sorted(map(str, item))}")
        try:  # (Segment checks and converts its values)
            segs.append(Segment(**item))
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
    return segs


def command_at(segments: Sequence[Segment], t: float) -> np.ndarray:
    """The profile's ``(vx, vy, wz)`` at time ``t`` (zero after the last segment)."""
    end = 0.0
    for seg in segments:
        end += seg.duration
        if t < end - 1e-9:
            return np.array([seg.vx, seg.vy, seg.wz])
    return np.zeros(3)


def with_zero_tail(segments: Sequence[Segment], duration: float | None) -> list[Segment]:
    """``segments`` with a zero command ``Segment`` for the time ``duration`` (s) runs past
    their end (the command after a profile is zero: a run longer than its profile stood
    there, and its summary listed no segment for that time)."""
    segments = list(segments)
    extra = (duration or 0.0) - sum(s.duration for s in segments)
    if extra > 1e-9:
        segments.append(Segment(extra))
    return segments


def unreached_segments(segments: Sequence[Segment], max_velocity: Sequence[float],
                       max_acceleration: Sequence[float],
                       max_command_norm: float = DEFAULT_MAX_NORM) -> list[tuple[int, float]]:
    """The segments (index, ramp time in s) whose command the MPC's ramp
    (:func:`~horizon_mpc.locomotion.command.ramp_time` of ``max_acceleration``, commands
    limited as the MPC does: ``max_velocity`` per axis and
    ``max_command_norm`` combined, :func:`~horizon_mpc.locomotion.command.limit_command`)
    cannot reach from the one before within the segment; the last segment is left out (no
    command follows it). An axis with a zero acceleration never moves: inf.

    The robot follows the ramped command, not the profile's: go2 under +-0.4 m/s flipped
    every 0.5 s (1 m/s^2 needs 0.8 s for a flip) ran a command between -0.1 and +0.4 and
    ended 0.97 m ahead of a profile that averages zero (session 26 audit)."""
    amax = np.asarray(max_acceleration, float)
    out = []
    before = np.zeros(3)
    for i, seg in enumerate(segments):
        cmd = np.array(limit_command((seg.vx, seg.vy, seg.wz), max_velocity, max_command_norm))
        change = np.abs(cmd - before)
        # an axis that cannot accelerate never gets there
        ramp = math.inf if np.any((change > 0.0) & (amax <= 0.0)) else ramp_time(change, amax)
        if i < len(segments) - 1 and ramp > seg.duration + 1e-9:
            out.append((i, ramp))
        before = cmd
    return out
