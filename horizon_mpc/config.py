"""Per-robot configuration: ``config/<robot>.yaml``.

Everything robot-specific (foot frames, nominal posture, friction, simulator gains, gait
timings, cost weights) lives in these YAML files, never in code. A config file is looked up
by robot name in the folders of :func:`config_dirs`, in order: the ``config`` folder of the
source tree, the ament index's ``share/horizon_mpc/config``, the interpreter prefix's (a pip
install into a venv). A path to a YAML file is accepted too.

Schema (every section but ``robot``/``feet`` is optional and falls back to the defaults below)::

    robot: go2                 # example-robot-data name ...
    urdf_path: null            # ... or an explicit URDF path (takes precedence)
    base_link: base
    feet: [FL_foot, FR_foot, RL_foot, RR_foot]   # contact frames, in the order used everywhere
    nominal_posture: standing  # SRDF group_state giving the nominal joint positions
    nominal_joints: {}         # per-joint overrides (rad), applied on top of the SRDF posture
    friction: 0.6              # friction coefficient used by the controller (linearised cone)
    foot_radius: 0.0           # m, foot frame to ground contact (the foot rolls on a sphere)
    sim: {kp: 30.0, kd: 1.0, lateral_friction: 0.9, physics_rate: 1000.0}  # kp, kd: or per joint
    mpc: {...}                 # see horizon_mpc.locomotion (gait, weights, horizon)
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import math
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

__all__ = ["RobotConfig", "SimGains", "check_settings", "config_dirs", "did_you_mean",
           "field_default", "find_config_file", "finite_number", "load_robot_config", "merged",
           "nearest_name", "numeric_type", "parse_yaml", "read_yaml"]

log = logging.getLogger(__name__)


@dataclass
class SimGains:
    """Joint-space PD gains (a number for every joint, or a list of one per joint in model
    order) and contact parameters of the simulator."""

    kp: float | list[float] = 30.0
    kd: float | list[float] = 1.0
    lateral_friction: float = 0.9
    physics_rate: float = 1000.0


@dataclass
class RobotConfig:
    """A robot's configuration (see the module docstring for the YAML schema)."""

    name: str
    robot: str | None
    urdf_path: str | None
    base_link: str
    feet: list[str]
    nominal_posture: str | None = "standing"
    nominal_joints: dict[str, float] = field(default_factory=dict)
    friction: float = 0.6
    foot_radius: float = 0.0
    sim: SimGains = field(default_factory=SimGains)
    sections: dict[str, Any] = field(default_factory=dict)  # other sections, e.g. ``mpc``
    source: Path | None = None

    def section(self, name: str) -> dict[str, Any]:
        """A copy of the raw YAML section ``name`` ({} if absent)."""
        return copy.deepcopy(self.sections.get(name, {}))


def config_dirs() -> list[Path]:
    """Folders searched for ``<robot>.yaml``, in order: the source tree's ``config`` (a
    checkout or an editable install), the ament index's ``share/horizon_mpc/config`` (the
    workspace ``AMENT_PREFIX_PATH`` names first, as ``ros2 run`` resolves it), then the
    interpreter's prefix (a pip install into a venv)."""
    here = Path(__file__).resolve().parent
    dirs = [here.parent / "config"]
    try:  # a colcon/ament install
        from ament_index_python.packages import get_package_share_directory

        dirs.append(Path(get_package_share_directory("horizon_mpc")) / "config")
    except Exception:  # noqa: BLE001 - no ament index in this environment: fine
        pass
    dirs.append(Path(sys.prefix) / "share" / "horizon_mpc" / "config")
    return list(dict.fromkeys(dirs))


def find_config_file(name_or_path: str | Path, what: str = "robot config",
                     subdir: str = "") -> Path:
    """The YAML file of a config: ``name_or_path`` itself when it is a path (ends in
    ``.yaml``/``.yml``, names a folder, or is a :class:`~pathlib.Path`), else
    ``<dir>/<subdir>/<name>.yaml`` in the first of :func:`config_dirs` that has it.

    Raises:
        FileNotFoundError: no such file, or a folder (the message names ``what`` and lists the
            available names).
    """
    p = Path(name_or_path)
    # a path: a .yaml/.yml name, a name with a folder (./name too: pathlib drops the '.'),
    # or a Path (a bare name is a config's, whatever the working directory holds)
    if (p.suffix in (".yaml", ".yml") or len(p.parts) > 1 or isinstance(name_or_path, Path)
            or "/" in str(name_or_path) or os.sep in str(name_or_path)):
        if p.is_dir():
            raise FileNotFoundError(f"{what} {str(p)!r} is a folder, not a YAML file")
        if not p.is_file():
            raise FileNotFoundError(f"{what} file {str(p)!r} does not exist")
        return p
    dirs = [d / subdir if subdir else d for d in config_dirs()]
    for d in dirs:
        candidate = d / f"{name_or_path}.yaml"
        if candidate.is_file():
            return candidate
    available = sorted({c.stem for d in dirs if d.is_dir() for c in d.glob("*.yaml")})
    here = (f"; the file {str(name_or_path)!r} in the working folder is no {what} name: give "
            f"it as ./{name_or_path}") if p.is_file() else ""
    raise FileNotFoundError(f"no {what} {str(name_or_path)!r}; available: "
                            f"{', '.join(available) or 'none'}{here}")


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader refusing a key given twice in one mapping (PyYAML keeps the last
    silently: a profile with two ``segments:`` lost the first)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":  # '<<: *anchor', the base's own
                continue
            key = self.construct_object(key_node, deep=True)
            if isinstance(key, list | dict):
                continue  # unhashable: the base class says so
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} given twice in one mapping", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


# a number in exponent notation without a point or a sign in the exponent (1e-4, 1.5e3)
# is a float, as in YAML 1.2 and the ROS parameter files: PyYAML's YAML 1.1 read it as
# text, and a weight given so was "not a number"
_UniqueKeyLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9][0-9_]*)[eE][-+]?[0-9]+$"),
    list("-+.0123456789"))


def parse_yaml(text: str) -> Any:
    """The data of a YAML text (a ``--set`` value), read as :func:`read_yaml` reads files.

    Raises:
        yaml.YAMLError: not YAML; ValueError: a scalar its constructor refuses (a date
            2001-13-45), nesting too deep.
    """
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader
    except RecursionError:
        raise ValueError("nested too deeply") from None


def merged(*layers: dict[str, Any]) -> dict[str, Any]:
    """The settings of ``layers``, later ones over earlier ones key by key, mappings merged
    the same way (a ``{gait: {name: walk}}`` over a config's ``mpc`` changes the gait's
    name only, not its step duration and height too)."""
    out: dict[str, Any] = {}
    for layer in layers:
        for key, value in layer.items():
            if isinstance(value, dict) and isinstance(out.get(key), dict):
                value = merged(out[key], value)
            out[key] = value
    return out


def read_yaml(path: str | Path) -> Any:
    """The data of the YAML file at ``path``; ``ValueError`` naming the file when it is not
    text (UTF-8) or not valid YAML (a key given twice in a mapping included)."""
    with open(path, encoding="utf-8") as fh:
        try:
            return yaml.load(fh, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader
        except UnicodeDecodeError as exc:  # (a ValueError: before the next)
            raise ValueError(f"{path}: not a text file (UTF-8): {exc.reason} at byte "
                             f"{exc.start}") from None
        except (yaml.YAMLError, ValueError) as exc:  # (a scalar a constructor refuses)
            raise ValueError(f"{path}: not valid YAML ({' '.join(str(exc).split())})") from None
        except RecursionError:
            raise ValueError(f"{path}: not valid YAML (nested too deeply)") from None


def field_default(f: dataclasses.Field) -> Any:
    """The default value of a dataclass field (its factory's product), None without one."""
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


def check_settings(settings: object, positive: tuple[str, ...] = (),
                   non_negative: tuple[str, ...] = (), prefix: str = "") -> None:
    """Check a settings dataclass: every number finite, those in ``positive`` > 0, those in
    ``non_negative`` >= 0 (an optional number, None by default, is checked when given),
    every flag (a setting whose default is a bool) true or false (a quoted "false" was a
    true flag). Lists, mappings, nested settings and text are left to their owners.

    Raises:
        ValueError: naming the setting as ``prefix + name`` (the CLIs turn it into one
            line, exit code 2).
    """
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        default = field_default(f)
        name = prefix + f.name
        if isinstance(default, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"setting {name!r} must be true or false, got {value!r}")
            continue
        if (value is None or (isinstance(value, (list, tuple, dict))
                              and not numeric_type(str(f.type)))
                or dataclasses.is_dataclass(value) or isinstance(default, str)):
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"setting {name!r} must be a number, got {value!r}")
        if not finite_number(value):
            raise ValueError(f"setting {name!r} must be finite, got {value!r}")
        if f.name in positive and not value > 0:
            raise ValueError(f"setting {name!r} must be > 0, got {value!r}")
        if f.name in non_negative and value < 0:
            raise ValueError(f"setting {name!r} must be >= 0, got {value!r}")


def finite_number(value: Any) -> bool:
    """A finite int or float, not a bool (an int beyond a float's range is none: it was an
    OverflowError)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def numeric_type(kind: str) -> bool:
    """Whether a dataclass field's type (its text, ``float | None``) is a number, not a
    sequence or mapping of them."""
    return ("float" in kind or "int" in kind) and not any(
        k in kind for k in ("list", "dict", "tuple", "Sequence"))


_KNOWN = {"robot", "urdf_path", "base_link", "feet", "nominal_posture", "nominal_joints",
          "friction", "foot_radius", "sim"}
#: the sections read by other modules (``RobotConfig.section``): ``mpc`` (horizon_mpc.locomotion)
SECTIONS = ("mpc",)


def _number(path: Path, key: str, value: Any, lowest: float = -math.inf,
            strict: bool = False) -> float:
    """``value`` as a finite float >= ``lowest`` (> with ``strict``), or a ValueError naming
    the file and the key."""
    try:
        if isinstance(value, bool):  # YAML 'yes'/'true' is no number
            raise TypeError
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{path}: '{key}' must be a number, got {value!r}") from None
    except OverflowError:  # an integer beyond a float's range
        x = math.inf
    if not math.isfinite(x) or x < lowest or (strict and x == lowest):
        bound = f"{'>' if strict else '>='} {lowest:g}" if lowest > -math.inf else "finite"
        raise ValueError(f"{path}: '{key}' must be {bound}, got {value!r}")
    return x


def _non_negative(path: Path, key: str, value: Any) -> float:
    return _number(path, key, value, 0.0)


def _mapping(path: Path, key: str, value: Any) -> dict:
    """``value`` (None: empty) as a mapping, or a ValueError naming the file and the key."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ValueError(f"{path}: '{key}' must be a mapping, got {value!r}")
    return value


def _sim_gains(path: Path, sim: dict) -> SimGains:
    """The ``sim`` section: kp/kd a number >= 0 or a non-empty list of them (per joint; its
    length is checked against the robot's joints by the simulator), the others positive."""
    unknown = set(sim) - set(SimGains.__dataclass_fields__)
    if unknown:
        raise ValueError(f"{path}: unknown keys in 'sim': {sorted(map(str, unknown))} (known: "
                         f"{sorted(SimGains.__dataclass_fields__)})")
    out = {}
    for key, value in sim.items():
        if key in ("kp", "kd") and isinstance(value, list):
            if not value:
                raise ValueError(f"{path}: 'sim.{key}' is an empty list: give a number or one "
                                 "per joint")
            out[key] = [_non_negative(path, f"sim.{key}[{i}]", v) for i, v in enumerate(value)]
        elif key in ("kp", "kd"):
            out[key] = _non_negative(path, f"sim.{key}", value)
        else:
            out[key] = _number(path, f"sim.{key}", value, 0.0, strict=True)
    return SimGains(**out)


def _edits(a: str, b: str) -> int:
    """Edits (insert, delete, substitute, swap two neighbours) that turn ``a`` into ``b``."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1,
                          d[i - 1][j - 1] + (a[i - 1] != b[j - 1]))
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


def nearest_name(name: str, known: list[str]) -> str | None:
    """The first of ``known`` within a few edits of ``name`` (a typo of it: at most a
    quarter of its letters, at least one; upper and lower case alike: ``MPC`` is ``mpc``),
    else None."""
    low = name.lower()
    return next((n for n in known if _edits(low, n.lower()) <= max(1, len(n) // 4)), None)


def did_you_mean(name: object, known: list[str]) -> str:
    """`` (did you mean 'x'?)`` for the :func:`nearest_name` ``x`` of ``name`` in
    ``known``, else an empty text: the tail of an error naming an unknown name."""
    near = nearest_name(name, known) if isinstance(name, str) else None
    return f" (did you mean {near!r}?)" if near is not None else ""


def _urdf_path(path: Path, value: Any) -> str | None:
    """``urdf_path`` of the config at ``path``: ``~`` expanded, a relative path taken from
    the config file's folder (it was from the working folder: a config worked from one
    folder only)."""
    if value is None or value == "":
        return None
    if not isinstance(value, str):
        raise ValueError(f"{path}: 'urdf_path' must be a file path, got {value!r}")
    return str(path.parent / Path(value).expanduser())


def _check_top_level_keys(path: Path, data: dict) -> None:
    """A key that is neither a known setting nor a section: refused when it is close to a
    known one (a misspelt ``mcp:`` section was ignored and the defaults used without a
    word), else ignored with a warning (a user's own note, ``description:``)."""
    known = sorted(_KNOWN | set(SECTIONS))
    unknown = sorted(str(k) for k in data if k not in _KNOWN and k not in SECTIONS)
    typos = {k: near for k in unknown if (near := nearest_name(k, known))}
    if typos:
        hints = ", ".join(f"{k!r} (did you mean {v!r}?)" for k, v in typos.items())
        raise ValueError(f"{path}: unknown key(s) {hints}; known: {known}")
    if unknown:
        log.warning("%s: unknown key(s) %s ignored (known: %s)", path, unknown, known)


def load_robot_config(name_or_path: str | Path) -> RobotConfig:
    """Load ``config/<name>.yaml`` (or the YAML file at ``name_or_path``).

    Raises:
        FileNotFoundError: no such config (the message lists the available ones).
        ValueError: the file is not a mapping, lacks ``feet``/a robot source, has a key
            that is neither a setting nor a section, or a value of the wrong type (the
            message names the file and the key).
    """
    path = find_config_file(name_or_path)
    data = read_yaml(path)
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a YAML mapping at the top level")
    if not data.get("robot") and not data.get("urdf_path"):
        raise ValueError(f"{path}: needs 'robot' (example-robot-data name) or 'urdf_path'")
    for key in ("robot", "base_link", "nominal_posture"):
        # (base_link: null was taken as a base link called None)
        if key in data and (data[key] is not None or key == "base_link") and not (
                isinstance(data[key], str) and data[key]):
            raise ValueError(f"{path}: '{key}' must be a name, got {data[key]!r}")
    feet = data.get("feet")
    if not isinstance(feet, list) or not feet or not all(isinstance(f, str) and f
                                                         for f in feet):
        # (a null or a number was taken as the frame 'None' or '3')
        raise ValueError(f"{path}: 'feet' must be a non-empty list of contact frame names, "
                         f"got {feet!r}")
    twice = sorted({str(f) for f in feet if feet.count(f) > 1})
    if twice:  # was "a constraint or cost called 'FL_foot_velocity' already exists"
        raise ValueError(f"{path}: 'feet' names {twice} more than once")
    if data.get("base_link", "base") in feet:
        raise ValueError(f"{path}: 'feet' names the base link {data.get('base_link', 'base')!r}"
                         ": a foot is a contact frame of a leg")
    _check_top_level_keys(path, data)
    joints = _mapping(path, "nominal_joints", data.get("nominal_joints"))
    return RobotConfig(
        name=path.stem,
        robot=data.get("robot"),
        urdf_path=_urdf_path(path, data.get("urdf_path")),
        base_link=data.get("base_link", "base"),
        feet=[str(f) for f in feet],
        nominal_posture=data.get("nominal_posture", "standing"),
        nominal_joints={str(k): _number(path, f"nominal_joints.{k}", v)
                        for k, v in joints.items()},
        friction=_number(path, "friction", data.get("friction", 0.6), 0.0, strict=True),
        foot_radius=_non_negative(path, "foot_radius", data.get("foot_radius", 0.0)),
        sim=_sim_gains(path, _mapping(path, "sim", data.get("sim"))),
        sections={k: v for k, v in data.items() if k in SECTIONS},
        source=path,
    )
