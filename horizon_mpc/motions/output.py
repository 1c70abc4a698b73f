"""Write a motion's outputs: solution (.npz), figures (PNG), animation (GIF), summary (JSON).

Files in the output folder::

    solution.npz           t (N+1), q, v (per node), a, f, tau (per interval), stance,
                           feet, joint_names, dt, integrator (of the transcription: what
                           the next node follows from), foot_radius (where the dynamics
                           apply the forces), and the motion's extra arrays (the walk's
                           stance_foot_radius: its stance condition's rolling ball feet)
    contact_forces.png     forces of every foot over time (paper Fig. 2 style)
    base_and_torques.png   base position and orientation, joint torques
    animation.gif          the motion rendered headless (PyBullet TinyRenderer)
    summary.json           motion, robot, solver, solver statistics, the motion's figures
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np

from horizon_mpc.config import RobotConfig
from horizon_mpc.motions.result import MotionResult

__all__ = ["OUTPUT_FILES", "load_solution", "write_outputs", "write_solution", "write_summary"]

#: what :func:`write_outputs` writes (the summary last: a folder without it is incomplete)
OUTPUT_FILES = ("solution.npz", "contact_forces.png", "base_and_torques.png", "animation.gif",
                "summary.json")

log = logging.getLogger(__name__)


def write_solution(res: MotionResult, path: str | Path) -> Path:
    """The trajectories as ``.npz`` (see the module docstring)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, t=res.t, q=res.q, v=res.v, a=res.a, f=res.f, tau=res.tau,
                        stance=res.stance, feet=np.array(res.feet),
                        joint_names=np.array(res.joint_names), dt=res.dt,
                        integrator=res.integrator, foot_radius=res.foot_radius, **res.arrays)
    return path


def load_solution(path: str | Path) -> dict[str, np.ndarray]:
    """The arrays of a ``solution.npz``."""
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return float(x) if math.isfinite(x) else str(float(x))
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    if isinstance(x, (str, int, bool)) or x is None:
        return x
    return str(x)


def write_summary(res: MotionResult, path: str | Path, extra: dict | None = None) -> Path:
    """``summary.json``: motion, robot, solver, statistics, figures (non-finite as strings)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = {"motion": res.motion, "robot": res.robot, "solver": res.solver,
           "nodes": res.n_nodes, "dt": res.dt, "duration": res.n_nodes * res.dt,
           "solver_stats": res.stats, "results": res.summary, **(extra or {})}
    path.write_text(json.dumps(_jsonable(doc), indent=2) + "\n", encoding="utf-8")
    return path


def write_outputs(res: MotionResult, cfg: RobotConfig, out: str | Path,
                  effort_limit: np.ndarray | None = None, animation: bool = True,
                  extra: dict | None = None, **render: Any) -> dict[str, Path]:
    """Write every output of ``res`` into the folder ``out``; returns name -> path.

    ``effort_limit``: (nj,) joint torque limits drawn on the torque plot; ``extra``: more
    entries for the JSON summary; ``render``: options of
    :func:`horizon_mpc.motions.animation.render_frames`.
    """
    from horizon_mpc.motions.plots import plot_base_and_torques, plot_contact_forces

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    # an earlier run's outputs go first: a run interrupted while writing left its solution
    # beside the earlier run's summary and plots, nothing telling them apart
    earlier = [p for p in (out / name for name in OUTPUT_FILES) if p.is_file()]
    for path in earlier:
        path.unlink()
    if earlier:
        log.info("%s: removed the earlier run's %s in %s", res.motion,
                 ", ".join(p.name for p in earlier), out)
    files = {"solution": write_solution(res, out / "solution.npz"),
             "contact_forces": plot_contact_forces(res, out / "contact_forces.png"),
             "base_and_torques": plot_base_and_torques(res, out / "base_and_torques.png",
                                                       effort_limit)}
    if animation:
        from horizon_mpc.motions.animation import write_animation

        files["animation"] = write_animation(res, cfg, out / "animation.gif", **render)
    files["summary"] = write_summary(
        res, out / "summary.json",
        {**(extra or {}), "files": {k: p.name for k, p in files.items()}})
    log.info("%s: outputs in %s", res.motion, out)
    return files
