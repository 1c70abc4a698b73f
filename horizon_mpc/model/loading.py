"""Parse a URDF (file or XML string) into a numeric Pinocchio model, with clear errors."""

from __future__ import annotations

from pathlib import Path

import pinocchio as pin

__all__ = ["load_pin_model"]


def _looks_like_xml(text: str) -> bool:
    return "<" in text and ("<robot" in text or "<?xml" in text)


def load_pin_model(urdf: str | Path, floating_base: bool = True) -> pin.Model:
    """Pinocchio model of a URDF path or URDF XML string.

    Args:
        urdf: file path or XML text.
        floating_base: add a ``JointModelFreeFlyer`` root joint.

    Raises:
        FileNotFoundError: the path does not exist.
        ValueError: the URDF is malformed (Pinocchio's message is included).
    """
    is_xml = isinstance(urdf, str) and _looks_like_xml(urdf)
    if not is_xml:
        path = Path(urdf).expanduser()
        if not path.is_file():
            raise FileNotFoundError(f"URDF file not found: {path}")
        source = f"URDF file {path}"
    else:
        source = "URDF string"
    try:
        if is_xml and floating_base:
            return pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer())
        if is_xml:
            return pin.buildModelFromXML(urdf)
        if floating_base:
            return pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
        return pin.buildModelFromUrdf(str(path))
    except (ValueError, RuntimeError) as exc:
        raise ValueError(f"malformed {source}: {exc}") from exc
