"""The ``robot_description`` parameter of the nodes: a robot's URDF as XML text (what
robot_state_publisher holds), given in place of a URDF file."""

from __future__ import annotations

import os
import tempfile

__all__ = ["check_urdf_text", "description_file"]


def check_urdf_text(text: str) -> None:
    """Raise ValueError unless ``text`` looks like URDF XML (a ``<robot`` element): a path
    given here by mistake gets a message pointing to ``urdf_path``."""
    if "<robot" not in text:
        raise ValueError("robot_description must be the URDF XML text (no <robot> element in "
                         f"{text[:60]!r}); for a file, set urdf_path")


def description_file(text: str) -> str | None:
    """A temporary ``.urdf`` file holding ``text`` (the caller removes it), or None when
    ``text`` is blank. Its mesh URIs must be ``package://`` or absolute: the file's folder is
    not the one the URDF came from.

    Raises:
        ValueError: ``text`` is not URDF XML (see :func:`check_urdf_text`).
    """
    if not text.strip():
        return None
    check_urdf_text(text)
    fd, path = tempfile.mkstemp(prefix="robot_description_", suffix=".urdf")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    return path
