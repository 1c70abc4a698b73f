"""Loading a URDF into pybullet with the same physics as Pinocchio reads from it.

Three things differ between pybullet's URDF importer and Pinocchio's, and are corrected here:

* ``package://`` mesh URIs: rewritten to absolute paths (package folders are looked up in the
  given search folders, the ament prefixes, example-robot-data's share folder and the URDF's
  ancestors), so loading does not depend on pybullet's single global search path.
* Links without ``<inertial>``: pybullet gives them 1 kg and unit inertia (Pinocchio: 0 kg).
  They get :data:`MASSLESS_LINK_MASS` instead. (Not exactly 0: a zero-mass root link would
  make pybullet treat the robot as fixed-base.)
* Inertia: taken from the file (``URDF_USE_INERTIA_FROM_FILE``), not recomputed from the
  collision shapes; pybullet's default per-link linear/angular velocity damping is removed.
* An empty position range (``lower == upper``, e.g. ``lower="0" upper="0"``): pybullet locks
  the joint there (a go2 URDF written so stood up on straight legs); here, as for the model
  (:attr:`horizon_mpc.model.RobotModel.unset_limits`), it is no limit (``lower > upper`` is
  none in pybullet already).

Joint damping from ``<dynamics damping>`` is applied by pybullet itself; joint friction is
realised with pybullet's joint velocity motor (target velocity 0, max force = friction), which
is pybullet's implicit Coulomb friction. All other motors are disabled (force 0).
"""

from __future__ import annotations

import logging
import os
import re
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from horizon_mpc.c_output import c_output_captured
from horizon_mpc.sim.pybullet_import import import_pybullet

p = import_pybullet()  # the module, without its banner (pybullet_import.py)

__all__ = ["MASSLESS_LINK_MASS", "LoadedRobot", "load_robot", "resolve_mesh_uris"]

_LOG = logging.getLogger(__name__)

MASSLESS_LINK_MASS = 1e-5  # kg, given to links that have no <inertial> (Pinocchio: 0 kg)
_MASSLESS_LINK_INERTIA = 1e-9  # kg m^2, principal moments of those links

_NO_LIMIT = 1e9  # rad or m: the range given to a joint whose URDF range is empty

_FILENAME = re.compile(r'filename\s*=\s*"([^"]*)"')


@dataclass
class LoadedRobot:
    """A robot loaded in one pybullet physics client.

    Attributes:
        body: pybullet body unique id.
        root_link: name of the URDF root link (pybullet link index -1).
        link_index: URDF link name -> pybullet link index (root link -> -1).
        joint_index: name of each non-fixed joint -> pybullet joint index.
        parent_index: pybullet link index -> index of its parent link (-1 for the root).
        fixed_joint: pybullet link index -> whether the joint above the link is fixed.
        massless_links: links that had no ``<inertial>`` and were given a tiny mass.
        inertial_pos: (3,) root link's inertial frame origin in the root link frame (m).
        inertial_quat: (4,) its orientation ``(x, y, z, w)`` (principal axes, as pybullet uses).
    """

    body: int
    root_link: str
    link_index: dict[str, int]
    joint_index: dict[str, int]
    parent_index: dict[int, int]
    fixed_joint: dict[int, bool]
    massless_links: list[str]
    inertial_pos: np.ndarray
    inertial_quat: np.ndarray

    def rigid_group(self, link: str) -> set[int]:
        """pybullet indices of the links rigidly attached to ``link`` or moving with it.

        That is the subtree below the nearest non-fixed joint above ``link`` (for a foot
        frame on a fixed joint: the calf/ankle link, the foot link, a wheel on the ankle, ...).
        Used to attribute contact points to feet.
        """
        idx = self.link_index[link]
        while idx != -1 and self.fixed_joint[idx]:
            idx = self.parent_index[idx]
        group = {idx}
        changed = True
        while changed:
            changed = False
            for child, parent in self.parent_index.items():
                if parent in group and child not in group:
                    group.add(child)
                    changed = True
        return group


def _package_roots(urdf: Path, search_dirs: list[Path]) -> list[Path]:
    roots = list(search_dirs)
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            roots.append(Path(prefix) / "share")
    try:
        from horizon_mpc.robots import example_robots_dir

        roots.append(example_robots_dir().parent.parent)
    except FileNotFoundError:
        pass
    roots.extend(urdf.resolve().parents)
    return roots


def _resolve(uri: str, urdf: Path, roots: list[Path]) -> str | None:
    if uri.startswith("file://"):
        return uri[len("file://"):]
    if not uri.startswith("package://"):
        path = Path(uri)
        return str(path if path.is_absolute() else (urdf.resolve().parent / path))
    package, _, rest = uri[len("package://"):].partition("/")
    for root in roots:
        for candidate in (root / package / rest, root / rest if root.name == package else None):
            if candidate is not None and candidate.is_file():
                return str(candidate)
    return None


def resolve_mesh_uris(urdf: Path, search_dirs: list[Path] | None = None) -> str:
    """The URDF text of ``urdf`` with every ``filename="..."`` made an absolute path.

    A ``<visual>`` whose mesh cannot be found is left out, with a warning (pybullet refuses
    the whole URDF for one missing mesh: "Cannot load URDF file").

    Raises:
        FileNotFoundError: a ``<collision>`` mesh cannot be found (without it a foot would
            fall through the ground: go2's feet collide through meshes).
    """
    text = urdf.read_text(encoding="utf-8")
    roots = _package_roots(urdf, [Path(d) for d in (search_dirs or [])])
    cache: dict[str, str | None] = {}

    def substitute(match: re.Match[str]) -> str:
        uri = match.group(1)
        if uri not in cache:
            cache[uri] = _resolve(uri, urdf, roots)
            if cache[uri] is not None and not Path(cache[uri]).is_file():
                cache[uri] = None
        return f'filename="{cache[uri] or uri}"'

    text = _FILENAME.sub(substitute, text)
    missing = {uri for uri, path in cache.items() if path is None}
    return _without_meshes(text, missing, urdf) if missing else text


def _without_meshes(text: str, uris: set[str], urdf: Path) -> str:
    """``text`` without the ``<visual>`` elements whose mesh is one of ``uris`` (logged);
    FileNotFoundError when a ``<collision>`` uses one."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError:
        return text  # not XML: pybullet's own error names it
    missing_collisions, missing_visuals = [], []
    for link in root.iter("link"):
        for kind in ("visual", "collision"):
            for element in link.findall(kind):
                mesh = element.find("geometry/mesh")
                uri = mesh.get("filename") if mesh is not None else None
                if uri in uris:
                    (missing_collisions if kind == "collision" else missing_visuals).append(
                        (link, element, uri))
    if missing_collisions:
        where = "; ".join(f"{link.get('name')}: {uri}" for link, _, uri in missing_collisions)
        raise FileNotFoundError(f"{urdf}: cannot find the collision meshes of {where} "
                                "(package:// URIs are looked up in the ament prefixes, "
                                "example-robot-data and the URDF's folders)")
    for link, element, uri in missing_visuals:
        link.remove(element)
        _LOG.warning("%s: cannot find mesh %r; the <visual> of link %r is left out", urdf,
                     uri, link.get("name"))
    return ET.tostring(root, encoding="unicode")


def _link_inertias(urdf_text: str) -> dict[str, float | None]:
    """The largest ``|inertia entry|`` (kg m^2) of each link, None for a link without
    ``<inertial>`` (0 for one without ``<inertia>`` in it)."""
    out: dict[str, float | None] = {}
    for link in ET.fromstring(urdf_text).findall("link"):
        inertia = link.find("inertial/inertia")
        out[link.get("name")] = None if link.find("inertial") is None else max(
            (abs(float(v)) for v in ({} if inertia is None else inertia.attrib).values()),
            default=0.0)
    return out


_BAD_INERTIA = "Bad inertia tensor properties, setting inertia to zero for link: "
_NO_INERTIAL = "No inertial data for link"
_HEADER = re.compile(r"b3\w+(\[[^\]]*\])?:")  # pybullet's message prefix
_NEGLIGIBLE_INERTIA = 1e-5  # kg m^2: a URDF's placeholder inertia (1e-6 entries), zeroed


def _importer_messages(text: str) -> list[str]:
    """pybullet's importer output as messages (split at its ``b3Warning[file,line]:``
    prefixes, which do not always start a line), repeats removed, in order."""
    said: list[str] = []
    for message in _HEADER.split(text):
        message = " ".join((message or "").split())
        if message and not message.startswith("[") and message not in said:
            said.append(message)
    return said


def _log_importer_messages(urdf: Path, said: list[str],
                           inertias: dict[str, float | None]) -> None:
    """Log what pybullet's URDF importer printed, less what is corrected here: a link
    without ``<inertial>`` (given :data:`MASSLESS_LINK_MASS` below; the importer names it in
    a message of its own after its note) and a placeholder inertia it zeroes (entries
    <= 1e-5 kg m^2). Inertia tensors that are not positive definite, zeroed by pybullet
    (anymal_c's cameras), are named at INFO; anything else is a warning. ``inertias``:
    :func:`_link_inertias` of the URDF."""
    zeroed, other = [], []
    for message in said:
        # the note about a missing <inertial> and the link names that follow it (the repeats
        # of the note are gone: one note, then every such link's name; CENTAURO's 8 names
        # after the first were warnings)
        if message.startswith(_NO_INERTIAL) or inertias.get(message, 0.0) is None:
            continue
        if message.startswith(_BAD_INERTIA):
            link = message[len(_BAD_INERTIA):]
            if (inertias.get(link) or 0.0) > _NEGLIGIBLE_INERTIA:
                zeroed.append(link)
        else:
            other.append(message)
    if zeroed:
        _LOG.info("%s: pybullet zeroed the inertia tensors of %s (not positive definite in the "
                  "URDF; Pinocchio takes them as they are)", urdf.name, ", ".join(zeroed))
    for message in other:
        _LOG.warning("%s: pybullet: %s", urdf.name, message)


def load_robot(
    client: int,
    urdf: Path,
    search_dirs: list[Path] | None = None,
    lateral_friction: float = 0.9,
) -> LoadedRobot:
    """Load ``urdf`` into the pybullet client ``client`` with the corrections listed above.

    Args:
        client: pybullet physics client id.
        urdf: URDF file.
        search_dirs: extra folders holding ROS packages (for ``package://`` URIs).
        lateral_friction: friction coefficient of every robot link (the ground's is 1, and
            pybullet multiplies the two).
    """
    text = resolve_mesh_uris(urdf, search_dirs)
    inertias = _link_inertias(text)
    failed: p.error | None = None
    with tempfile.TemporaryDirectory(prefix="horizon_mpc_urdf_") as tmp:
        path = Path(tmp) / urdf.name
        path.write_text(text, encoding="utf-8")
        with c_output_captured(1) as importer:  # pybullet's importer prints on stdout
            try:
                body = p.loadURDF(
                    str(path),
                    flags=p.URDF_USE_INERTIA_FROM_FILE,
                    useFixedBase=False,
                    physicsClientId=client,
                )
            except p.error as exc:  # pybullet says only "Cannot load URDF file."
                failed = exc
    said = _importer_messages(importer.text)
    if failed is not None:
        raise ValueError(f"pybullet could not load the URDF {urdf} ({failed})"
                         + (f"; its parser said: {' | '.join(said)}" if said else ""))
    _log_importer_messages(urdf, said, inertias)
    if body < 0:
        raise RuntimeError(f"pybullet could not load the URDF {urdf}")
    root_link = p.getBodyInfo(body, physicsClientId=client)[0].decode()
    link_index = {root_link: -1}
    joint_index: dict[str, int] = {}
    parent_index: dict[int, int] = {}
    fixed_joint: dict[int, bool] = {}
    for j in range(p.getNumJoints(body, physicsClientId=client)):
        info = p.getJointInfo(body, j, physicsClientId=client)
        link_index[info[12].decode()] = j
        parent_index[j] = info[16]
        fixed_joint[j] = info[2] == p.JOINT_FIXED
        if not fixed_joint[j]:
            joint_index[info[1].decode()] = j
    massless = sorted(name for name, inertia in inertias.items()
                      if inertia is None and name in link_index)
    for name in massless:
        p.changeDynamics(
            body,
            link_index[name],
            mass=MASSLESS_LINK_MASS,
            localInertiaDiagonal=[_MASSLESS_LINK_INERTIA] * 3,
            physicsClientId=client,
        )
    if massless:
        _LOG.info("%s: links without <inertial> given %g kg: %s", urdf.name, MASSLESS_LINK_MASS,
                  ", ".join(massless))
    for idx in link_index.values():
        p.changeDynamics(body, idx, linearDamping=0.0, angularDamping=0.0,
                         lateralFriction=lateral_friction, physicsClientId=client)
    for j in joint_index.values():
        info = p.getJointInfo(body, j, physicsClientId=client)
        friction, lower, upper = info[7], info[8], info[9]
        if lower == upper and info[2] in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC):
            # changeDynamics cannot remove the limit: a range no motion reaches replaces it
            p.changeDynamics(body, j, jointLowerLimit=-_NO_LIMIT, jointUpperLimit=_NO_LIMIT,
                             physicsClientId=client)
        p.setJointMotorControl2(body, j, p.VELOCITY_CONTROL, targetVelocity=0.0,
                                force=max(float(friction), 0.0), physicsClientId=client)
    dyn = p.getDynamicsInfo(body, -1, physicsClientId=client)
    return LoadedRobot(
        body=body,
        root_link=root_link,
        link_index=link_index,
        joint_index=joint_index,
        parent_index=parent_index,
        fixed_joint=fixed_joint,
        massless_links=massless,
        inertial_pos=np.array(dyn[3], dtype=float),
        inertial_quat=np.array(dyn[4], dtype=float),
    )
