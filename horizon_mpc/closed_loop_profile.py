"""Command profiles of the closed loop (:mod:`horizon_mpc.closed_loop`): velocity segments and
scripted pushes, read from YAML (format in ``doc/closed_loop.md``)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from horizon_mpc.config import find_config_file

__all__ = ["DEFAULT_PROFILE", "Push", "Segment", "command_at", "load_profile", "load_pushes",
           "profile_file"]

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
    """A constant command ``(vx, vy, wz)`` (base frame) held for ``duration`` s."""

    duration: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0


@dataclass
class Push:
    """A world-frame ``force`` (N) on the base for ``duration`` s from sim time ``time``."""

    time: float
    force: tuple[float, float, float]
    duration: float = 0.1


def load_pushes(path: str | Path) -> list[Push]:
    """The optional ``pushes:`` list of a profile YAML or name (``{time, force: [fx, fy,
    fz], duration}``); empty when the profile has none."""
    path = profile_file(path)
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    items = data.get("pushes", []) if isinstance(data, dict) else []
    pushes = []
    for i, item in enumerate(items or []):
        try:
            force = tuple(float(f) for f in item["force"])
            push = Push(float(item["time"]), force, float(item.get("duration", 0.1)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: push {i} needs time, force [fx, fy, fz] and an optional "
                             f"duration ({exc})") from None
        if len(force) != 3 or not push.duration > 0 or not all(map(math.isfinite, force)):
            raise ValueError(f"{path}: push {i}: force must be 3 finite numbers and the "
                             "duration positive")
        pushes.append(push)
    return pushes


def load_profile(path: str | Path) -> list[Segment]:
    """Segments of a command profile YAML or name (a list, or a mapping with
    ``segments:``)."""
    path = profile_file(path)
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh)
    items = data.get("segments") if isinstance(data, dict) else data
    if not isinstance(items, list) or not items:
        raise ValueError(f"{path}: expected a list of segments {{duration, vx, vy, wz}}")
    segs = []
    for i, item in enumerate(items):
        unknown = set(item) - {"duration", "vx", "vy", "wz"}
        if unknown or "duration" not in item:
            raise ValueError(f"{path}: segment {i} needs 'duration' and only vx/vy/wz, got "
                             f"{sorted(item)}")
        seg = Segment(**{k: float(v) for k, v in item.items()})
        if not seg.duration > 0:
            raise ValueError(f"{path}: segment {i} has non-positive duration {seg.duration}")
        segs.append(seg)
    return segs


def command_at(segments: Sequence[Segment], t: float) -> np.ndarray:
    """The profile's ``(vx, vy, wz)`` at time ``t`` (zero after the last segment)."""
    end = 0.0
    for seg in segments:
        end += seg.duration
        if t < end - 1e-9:
            return np.array([seg.vx, seg.vy, seg.wz])
    return np.zeros(3)
