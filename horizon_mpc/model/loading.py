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
    text = urdf if is_xml else path.read_text(errors="replace")
    tree = _parsed(text)
    if model is not None:
        # urdfdom drops an <inertial> it cannot read (mass "2kg") with a line on stderr and
        # builds the link massless: a model that weighs nothing, without a word
        unread = [_said(line) for line in said if "Could not parse inertial" in line]
        if unread:
            raise ValueError(f"malformed {source}: {'; '.join(unread)}")
        if tree is not None:
            _check_names(tree, floating_base, source)
            _check_inertials(tree, source)
        else:  # (a text Pinocchio's parser reads and ElementTree does not)
            log.warning("%s: not read as XML here, so its link names and masses are not "
                        "checked", source)
        _check_root(model, floating_base, source)
        _warn_mimic_joints(tree, source)
        return model
    # urdfdom prints the reason (a joint without limits, an unknown link) on stderr and
    # raises "does not contain a valid URDF model" only
    reason = "; ".join(_said(line) for line in said
                       if line.strip() and not line.strip().startswith("at line "))
    negative = _negative_limits(tree) if tree is not None else []
    if negative:  # Pinocchio's own words: "min_effort are greater than max_effort"
        reason = "; ".join(filter(None, (reason, "negative limits: " + ", ".join(negative))))
    raise ValueError(f"malformed {source}: {error}" + (f" ({reason})" if reason else "")) \
        from error


def _said(line: str) -> str:
    return line.strip().removeprefix("Error:").strip()


def _parsed(text: str) -> ElementTree.Element | None:
    """The URDF's XML root, or None where ElementTree cannot read what Pinocchio did. As
    lenient as that parser where it is easy: blank lines before the XML declaration, and
    anything after the ``<robot>`` element."""
    text = text.lstrip("\ufeff \t\r\n")
    try:
        return ElementTree.fromstring(text.encode())
    except ElementTree.ParseError as exc:
        if "junk after document element" not in str(exc):
            return None
        line, column = exc.position  # where the junk starts: keep the text before it
        lines = text.splitlines(keepends=True)
        head = "".join(lines[:line - 1]) + lines[line - 1][:column]
        try:
            return ElementTree.fromstring(head.encode())
        except ElementTree.ParseError:
            return None


def _negative_limits(root: ElementTree.Element) -> list[str]:
    """``joint.attribute = value`` of every negative effort or velocity limit."""
    out = []
    for joint in root.iter("joint"):
        for limit in joint.findall("limit"):
            for key in ("effort", "velocity"):
                with contextlib.suppress(TypeError, ValueError):
                    if float(limit.get(key)) < 0:
                        out.append(f"{joint.get('name', '?')}.{key} = {limit.get(key)}")
    return out


def _check_names(root: ElementTree.Element, floating_base: bool, source: str) -> None:
    """ValueError for a link or joint named as one Pinocchio adds itself: its world frame
    ``universe`` (the link could not be looked up: ``fk('universe')`` gave the world
    origin) and, with ``floating_base``, the free-flyer ``root_joint``."""
    clashes = ["link 'universe' (Pinocchio's world frame)" for link in root.iter("link")
               if link.get("name") == "universe"]
    if floating_base:
        clashes += ["joint 'root_joint' (the free-flyer floating_base adds)"
                    for joint in root.iter("joint") if joint.get("name") == "root_joint"]
    if clashes:
        raise ValueError(f"{source}: {', '.join(clashes)} has the name of a joint or frame "
                         "the model adds itself: rename it in the URDF")


def _check_inertials(root: ElementTree.Element, source: str) -> None:
    """ValueError for a link of negative mass (Pinocchio builds it: a robot of -1 kg). Its
    rotational inertia is not checked: example-robot-data's own icub, romeo and tiago have
    negative principal moments, and go1, b1, anymal and hyq break the triangle inequality."""
    bad = []
    for link in root.iter("link"):
        mass = link.find("inertial/mass")
        with contextlib.suppress(AttributeError, TypeError, ValueError):
            if float(mass.get("value")) < 0:
                bad.append(f"{link.get('name', '?')} ({mass.get('value')} kg)")
    if bad:
        raise ValueError(f"{source}: link(s) of negative mass: {', '.join(bad)}")


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


def _warn_mimic_joints(root: ElementTree.Element | None, source: str) -> None:
    """Warn about URDF mimic joints: Pinocchio's URDF parser (as used here) makes each one
    an independent, actuated degree of freedom, and nothing in the model couples it to the
    joint it mimics."""
    if root is None:  # Pinocchio read it; nothing to say about mimics here
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
