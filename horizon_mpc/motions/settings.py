"""Motion settings: ``config/motions/<motion>.yaml``.

Each motion declares its settings as a dataclass with defaults; the YAML file gives the
values, with per-robot overrides::

    robot: go2          # default robot of the motion
    solver: ipopt       # default solver
    settings: {...}     # overrides of the dataclass defaults
    robots:             # per-robot overrides, applied on top of ``settings``
      solo12: {...}

The file is looked up like the robot configs (:func:`horizon_mpc.config.config_dirs`, in a
``motions`` sub-folder); a path to a YAML file is accepted too. Unknown keys are errors.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, TypeVar

import yaml

from horizon_mpc.config import find_config_file

__all__ = ["MotionConfig", "load_motion_config"]

T = TypeVar("T")


@dataclasses.dataclass
class MotionConfig:
    """The parsed ``config/motions/<motion>.yaml``."""

    motion: str
    robot: str
    solver: str
    settings: dict[str, Any]
    robots: dict[str, dict[str, Any]]
    source: Path | None = None

    def settings_for(self, cls: type[T], robot: str | None = None,
                     overrides: dict[str, Any] | None = None) -> T:
        """``cls`` (a dataclass) filled from the file for ``robot``, then ``overrides``.

        Raises:
            ValueError: a key that ``cls`` does not have (the message lists the known ones).
        """
        values = {**self.settings, **self.robots.get(robot or self.robot, {}),
                  **(overrides or {})}
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise ValueError(f"{self.source or self.motion}: unknown setting(s) {unknown} for "
                             f"motion {self.motion!r}; known: {sorted(names)}")
        return cls(**values)


def load_motion_config(motion: str | Path) -> MotionConfig:
    """Load ``config/motions/<motion>.yaml`` (or the YAML file at ``motion``).

    Raises:
        FileNotFoundError: no such file (the message lists the available motions).
        ValueError: not a mapping, or unknown top-level keys.
    """
    path = find_config_file(motion, "motion config", subdir="motions")
    with open(path, encoding="utf-8") as fh:
        data = yaml.safe_load(fh) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a YAML mapping at the top level")
    known = {"robot", "solver", "settings", "robots"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; known: {sorted(known)}")
    return MotionConfig(
        motion=path.stem,
        robot=str(data.get("robot", "go2")),
        solver=str(data.get("solver", "ipopt")),
        settings=dict(data.get("settings") or {}),
        robots={str(k): dict(v or {}) for k, v in (data.get("robots") or {}).items()},
        source=path,
    )
