"""Where the robots shipped by ``example-robot-data`` live on disk.

The ``example-robot-data`` wheel installs its URDF/SRDF files under
``<prefix>/share/example-robot-data/robots`` (pip: ``site-packages/cmeel.prefix``; a ROS
install: any prefix of ``AMENT_PREFIX_PATH``). This module maps the short robot names used
throughout horizon_mpc (``go2``, ``solo12``, ...) to those files.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

__all__ = ["RobotFiles", "example_robot_files", "example_robots_dir", "known_robots"]


@dataclass(frozen=True)
class RobotFiles:
    """Files of one example robot: its URDF, its SRDF (or None) and the package share dir."""

    name: str
    urdf: Path
    srdf: Path | None
    share_dir: Path  # the folder that contains ``example-robot-data`` (for package:// URIs)


# name -> (description folder, urdf relative path, srdf relative path or None)
_ROBOTS: dict[str, tuple[str, str, str | None]] = {
    "go2": ("go2_description", "urdf/go2.urdf", "srdf/go2.srdf"),
    "go1": ("go1_description", "urdf/go1.urdf", "srdf/go1.srdf"),
    "a1": ("a1_description", "urdf/a1.urdf", "srdf/a1.srdf"),
    "b1": ("b1_description", "urdf/b1.urdf", "srdf/b1.srdf"),
    "laikago": ("laikago_description", "urdf/laikago.urdf", None),
    "solo12": ("solo_description", "robots/solo12.urdf", "srdf/solo.srdf"),
    "solo": ("solo_description", "robots/solo.urdf", "srdf/solo.srdf"),
    "anymal_c": ("anymal_c_simple_description", "urdf/anymal.urdf", "srdf/anymal.srdf"),
    "anymal_b": ("anymal_b_simple_description", "robots/anymal.urdf", "srdf/anymal.srdf"),
    "hyq": ("hyq_description", "robots/hyq_no_sensors.urdf", "srdf/hyq.srdf"),
    "centauro": ("centauro_description", "urdf/centauro.urdf", "srdf/centauro.srdf"),
    "talos": ("talos_data", "robots/talos_reduced.urdf", "srdf/talos.srdf"),
    "ur5": ("ur_description", "urdf/ur5_robot.urdf", None),
    "panda": ("panda_description", "urdf/panda.urdf", "srdf/panda.srdf"),
}


def known_robots() -> list[str]:
    """Names accepted by :func:`example_robot_files`."""
    return sorted(_ROBOTS)


def _candidate_share_dirs() -> list[Path]:
    dirs: list[Path] = []
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share")
    for entry in sys.path:
        if entry:
            dirs.append(Path(entry) / "cmeel.prefix" / "share")
    dirs.append(Path(sys.prefix) / "share")
    return dirs


def example_robots_dir() -> Path:
    """The ``robots`` folder of the installed ``example-robot-data``.

    Raises:
        FileNotFoundError: if the package is not installed in any known prefix.
    """
    tried = []
    for share in _candidate_share_dirs():
        robots = share / "example-robot-data" / "robots"
        tried.append(str(robots))
        if robots.is_dir():
            return robots
    raise FileNotFoundError(
        "example-robot-data is not installed (pip install 'example-robot-data>=6.0'); "
        f"looked in: {', '.join(tried[:6])}"
    )


def example_robot_files(name: str) -> RobotFiles:
    """URDF and SRDF of the example-robot-data robot called ``name``.

    Raises:
        KeyError: unknown robot name (the message lists the known ones).
    """
    if name not in _ROBOTS:
        raise KeyError(f"unknown robot {name!r}; known robots are: {', '.join(known_robots())}")
    folder, urdf, srdf = _ROBOTS[name]
    robots = example_robots_dir()
    return RobotFiles(
        name=name,
        urdf=robots / folder / urdf,
        srdf=(robots / folder / srdf) if srdf else None,
        share_dir=robots.parent.parent,
    )
