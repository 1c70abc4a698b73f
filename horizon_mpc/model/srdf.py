"""Reference postures (``<group_state>``) of an SRDF file."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

__all__ = ["read_group_states"]


def read_group_states(srdf: str | Path) -> dict[str, dict[str, list[float]]]:
    """Named postures of an SRDF: ``{state name: {joint name: values}}``.

    ``values`` has one entry for single-DoF joints, several for multi-DoF ones (e.g. a root
    joint ``value="x y z qx qy qz qw"``).

    Raises:
        FileNotFoundError: the file does not exist.
        ValueError: the file is not valid XML.
    """
    path = Path(srdf)
    if not path.is_file():
        raise FileNotFoundError(f"SRDF file not found: {path}")
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"malformed SRDF {path}: {exc}") from exc
    states: dict[str, dict[str, list[float]]] = {}
    for gs in root.iter("group_state"):
        name = gs.get("name")
        if not name:
            continue
        joints = states.setdefault(name, {})
        for j in gs.iter("joint"):
            jname, value = j.get("name"), j.get("value")
            if jname is None or value is None:
                continue
            joints[jname] = [float(x) for x in value.split()]
    return states
