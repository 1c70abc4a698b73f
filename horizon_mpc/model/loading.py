"""Parse a URDF (file or XML string) into a numeric Pinocchio model, with clear errors."""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator
from pathlib import Path
from xml.etree import ElementTree

import pinocchio as pin

from horizon_mpc.c_output import Captured, c_output_captured

__all__ = ["floating_joints", "load_pin_model", "refuse_second_free_flyer"]

log = logging.getLogger(__name__)


def _looks_like_xml(text: str) -> bool:
    return "<" in text and ("<robot" in text or "<?xml" in text)


def load_pin_model(urdf: str | Path, floating_base: bool = True) -> pin.Model:
    """Pinocchio model of a URDF path or URDF XML string.

    Args:
        urdf: file path or XML text.
        floating_base: add a ``JointModelFreeFlyer`` root joint.

    Raises:
        FileNotFoundError: the path does not exist.
        ValueError: the URDF is malformed (Pinocchio's message is included), or empty.
    """
    if isinstance(urdf, str) and not urdf.strip():
        raise ValueError("no URDF: an empty string is neither a file path nor URDF text")
    is_xml = isinstance(urdf, str) and _looks_like_xml(urdf)
    if not is_xml:
        path = Path(urdf).expanduser()
        if not path.is_file():
            raise FileNotFoundError(f"URDF file not found: {path}")
        source = f"URDF file {path}"
    else:
        source = "URDF string"
    root = (pin.JointModelFreeFlyer(),) if floating_base else ()
    build = ((lambda: pin.buildModelFromXML(urdf, *root)) if is_xml
             else (lambda: pin.buildModelFromUrdf(str(path), *root)))
    model = None
    with _stderr_captured() as said:
        try:
            model = build()
        except (ValueError, RuntimeError) as exc:
            error = exc
    if model is not None:
        _check_root(model, floating_base, source)
        _warn_mimic_joints(urdf if is_xml else path.read_text(errors="replace"), source)
        return model
    # urdfdom prints the reason (a joint without limits, an unknown link) on stderr and
    # raises "does not contain a valid URDF model" only
    reason = "; ".join(line.strip().removeprefix("Error:").strip() for line in said
                       if line.strip() and not line.strip().startswith("at line "))
    raise ValueError(f"malformed {source}: {error}" + (f" ({reason})" if reason else "")) \
        from error


@contextlib.contextmanager
def _stderr_captured() -> Iterator[list[str]]:
    """What C code writes to file descriptor 2 inside the block, as lines in the yielded
    list once the block has ended; it is also passed on to stderr (nothing is lost)."""
    lines: list[str] = []
    out = Captured()
    try:
        with c_output_captured(2) as out:
            yield lines
    finally:
        if out.text:
            sys.stderr.write(out.text)
        lines.extend(out.text.splitlines())


def _warn_mimic_joints(text: str, source: str) -> None:
    """Warn about URDF mimic joints: Pinocchio's URDF parser (as used here) makes each one
    an independent, actuated degree of freedom, and nothing in the model couples it to the
    joint it mimics."""
    try:
        root = ElementTree.fromstring(text.lstrip("\ufeff").encode())
    except ElementTree.ParseError:  # Pinocchio read it; nothing to say about mimics here
        return
    # a fixed joint's mimic moves nothing (talos' gripper has six: the warning named joints
    # the model does not have)
    pairs = [(joint.get("name", "?"), mimic.get("joint", "?"))
             for joint in root.iter("joint") if joint.get("type") != "fixed"
             for mimic in joint.findall("mimic")]
    if pairs:
        log.warning("%s: mimic joints become independent joints of the model (%s); couple "
                    "them in your problem if they must move together", source,
                    ", ".join(f"{j} mimics {m}" for j, m in pairs))


def floating_joints(model: pin.Model, floating_base: bool = True) -> list[str]:
    """The URDF's own ``floating`` joints of ``model`` (free-flyers below the root one that
    ``floating_base`` added)."""
    first = 2 if floating_base else 1
    return [model.names[j] for j in range(first, model.njoints)
            if model.joints[j].shortname() == "JointModelFreeFlyer"]


def refuse_second_free_flyer(model: pin.Model, source: str) -> None:
    """ValueError for a URDF ``floating`` joint below the free-flyer of a legged robot's
    model (a config's: a base above a 'world' link was refused as 'base_link is not the root
    link', or as having continuous joints [])."""
    floating = floating_joints(model)
    if floating:
        raise ValueError(f"{source}: joint(s) {floating} are 'floating' joints, and a legged "
                         "robot's model adds its free-flyer above the root link itself: remove "
                         "the floating joint and the link above it (e.g. 'world') from the URDF")


def _check_root(model: pin.Model, floating_base: bool, source: str) -> None:
    """Warn about a free-flyer added above a root link called ``world``: by the ROS
    convention that URDF describes a robot fixed to the world (an arm), and the model
    gets 7 configuration and 6 velocity entries it should not have."""
    root = next((f.name for f in model.frames if f.type == pin.FrameType.BODY), None)
    floating = floating_joints(model) if floating_base else []
    if floating:  # (a valid model, two free-flyers: said so, not 'fixed to the world')
        log.warning("%s: joint(s) %s are 'floating' joints below the free-flyer "
                    "floating_base=True adds (nq %d, nv %d): for a legged robot remove them "
                    "and the link above them from the URDF, or pass floating_base=False to keep "
                    "the URDF's own", source, floating, model.nq, model.nv)
    elif floating_base and root == "world":
        log.warning("%s: the root link is 'world' (a robot fixed to the world) and "
                    "floating_base=True adds a free-flyer joint above it (nq %d, nv %d); "
                    "pass floating_base=False for a fixed base", source, model.nq, model.nv)
