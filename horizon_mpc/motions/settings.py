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
import logging
from pathlib import Path
from typing import Any, TypeVar

from horizon_mpc.config import (
    check_settings,
    field_default,
    find_config_file,
    finite_number,
    merged,
    nearest_name,
    numeric_type,
    read_yaml,
)

__all__ = ["MotionConfig", "check_settings", "load_motion_config", "motion_settings"]

log = logging.getLogger(__name__)

T = TypeVar("T")
SOLVERS = ("ipopt", "gnsqp", "ilqr")


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
            ValueError: a key that ``cls`` does not have (the message lists the known ones),
                or a value of another kind than the setting's default (a number where a
                whole number is due, text for a number, ...: named with the key).
        """
        robot = robot or self.robot
        if robot not in self.robots:
            self._warn_misspelt(robot)
        values = merged(self.settings, self.robots.get(robot, {}), overrides or {})
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(str(k) for k in set(values) - set(fields))
        if unknown:
            given = sorted(set(unknown) & set(map(str, overrides or {})))  # --set's
            where = "--set" if given else (self.source or self.motion)
            # the motion run is the settings class's (`walk --config leap`: the walk)
            motion = cls.__name__.removesuffix("Settings").lower()
            hint = ("" if given or self.motion == motion else
                    f" (a config of the {self.motion!r} motion?)")
            raise ValueError(f"{where}: unknown setting(s) {given or unknown} for motion "
                             f"{motion!r}{hint}; known: {sorted(fields)}")
        return cls(**{k: _checked_value(k, v, field_default(fields[k]), str(fields[k].type))
                      for k, v in values.items()})

    def _warn_misspelt(self, robot: str) -> None:
        """Warn when an entry under ``robots:`` that names no robot config is a typo of
        ``robot`` (``sol12`` for solo12: its settings were dropped without a word). Not an
        error: a robot config given by path may have a name of its own."""
        for key in self.robots:
            if nearest_name(key, [robot]) is not None:
                try:
                    find_config_file(key)
                except FileNotFoundError:
                    log.warning("%s: robots: %r is no robot config and not %r, the robot run: "
                                "a misspelling? Its settings are not used",
                                self.source or self.motion, key, robot)


def _checked_value(key: str, value: Any, default: Any, kind: str = "") -> Any:
    """``value`` as the kind of ``default`` (an int for an int setting, a float for a float
    one, a list for a list one); ValueError naming ``key`` otherwise. Settings without a
    default (or a None one) are passed as given; so is None for a setting whose type
    (``kind``, its text) allows it (the leap's ``trunk_clearance``, None for no clearance);
    a nullable number must be one."""
    def bad(kind: str) -> ValueError:
        return ValueError(f"setting {key!r} must be {kind}, got {value!r}")

    if value is None and "None" in kind:
        return None
    is_number = finite_number(value)
    if default is None and numeric_type(kind) and not is_number:
        raise bad("a number (or null)")  # (a list, a mapping were taken)
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
    elif isinstance(default, int):
        if not (is_number and float(value).is_integer()):
            raise bad("a whole number")
        return int(value)
    elif isinstance(default, float):
        if not is_number:
            raise bad("a number")
        return float(value)
    elif isinstance(default, (list, tuple)):
        if not isinstance(value, (list, tuple)):
            raise bad(f"a list like {list(default)!r}")
    elif isinstance(default, str) and not isinstance(value, str):
        raise bad("text")
    return value


def load_motion_config(motion: str | Path) -> MotionConfig:
    """Load ``config/motions/<motion>.yaml`` (or the YAML file at ``motion``).

    Raises:
        FileNotFoundError: no such file (the message lists the available motions).
        ValueError: not a mapping, or unknown top-level keys.
    """
    path = find_config_file(motion, "motion config", subdir="motions")
    data = read_yaml(path) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a YAML mapping at the top level")
    known = {"robot", "solver", "settings", "robots"}
    unknown = sorted(str(k) for k in set(data) - known)
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; known: {sorted(known)}")
    settings = {} if data.get("settings") is None else data["settings"]
    robots = {} if data.get("robots") is None else data["robots"]
    if not isinstance(settings, dict):
        raise ValueError(f"{path}: 'settings' must be a mapping of setting: value")
    if not isinstance(robots, dict) or not all(isinstance(v, dict) or v is None
                                               for v in robots.values()):
        raise ValueError(f"{path}: 'robots' must map robot names to mappings of settings")
    for key in ("robot", "solver"):
        if key in data and not (isinstance(data[key], str) and data[key]):
            raise ValueError(f"{path}: {key!r} must be a {key} name, got {data[key]!r}")
    solver = data.get("solver", "ipopt")
    if solver not in SOLVERS:
        raise ValueError(f"{path}: unknown solver {solver!r}; solvers: {list(SOLVERS)}")
    return MotionConfig(
        motion=path.stem,
        robot=data.get("robot", "go2"),
        solver=solver,
        settings=dict(settings),
        robots={str(k): dict(v or {}) for k, v in robots.items()},
        source=path,
    )


def motion_settings(motion: str, cls: type[T], robot: str) -> T:
    """The settings ``motion <motion> --robot <robot>`` runs with: ``cls`` filled from
    ``config/motions/<motion>.yaml`` for ``robot`` (the Python API's default: ``run_turn()``
    built the whole 39-joint CENTAURO, ``run_walk()`` 24 nodes, ``run_leap('solo12')`` leapt
    0.4 m where the file says 0.25)."""
    return load_motion_config(motion).settings_for(cls, robot)
