"""GIF of a motion: the kinematic solution replayed frame by frame, rendered headless.

Each frame sets the simulated robot's state (PyBullet, ``p.DIRECT``) to the solution at
that instant and renders it with the TinyRenderer (CPU, no display). No physics is run.
The plan's ground is the plane of the standing foot frames; the simulator's robot stands
with its collision shapes on its ground, so the plan is shifted up by the difference.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from horizon_mpc.config import RobotConfig
from horizon_mpc.motions.result import MotionResult

__all__ = ["render_frames", "write_animation"]

log = logging.getLogger(__name__)


def render_frames(res: MotionResult, cfg: RobotConfig, fps: float = 20.0, width: int = 320,
                  height: int = 240, distance: float | None = None, yaw: float = 60.0,
                  pitch: float = -20.0) -> tuple[list[np.ndarray], float]:
    """RGB frames (H, W, 3) uint8 of ``res`` at about ``fps`` frames per second of motion.

    The camera looks at the base from a fixed world direction (``yaw``, ``pitch`` in deg;
    ``distance`` in m, default scaled to the robot's height). Returns the frames and their
    exact rate (a whole number of nodes between frames).
    """
    from horizon_mpc.sim.render import render_following
    from horizon_mpc.sim.simulator import Simulator

    stride = max(1, int(round(1.0 / (fps * res.dt))))
    frames = []
    with Simulator(cfg) as sim:
        dz = sim.q_start[2] - res.q[2, 0]
        index = {n: 7 + i for i, n in enumerate(sim.joint_names)}
        cols = [index[n] for n in res.joint_names]
        dist = distance if distance is not None else 3.5 * float(sim.q_start[2])
        identity = np.array([0.0, 0.0, 0.0, 1.0])
        for k in range(0, res.q.shape[1], stride):
            q = sim.q_start.copy()
            q[:7] = res.q[:7, k]
            q[2] += dz
            q[cols] = res.q[7:, k]
            sim.set_state(q)
            # world-fixed camera direction (a camera turning with the base hides a turn)
            frames.append(render_following(sim.client, q[:3], identity, width, height, dist,
                                           yaw, pitch))
    return frames, 1.0 / (stride * res.dt)


def write_animation(res: MotionResult, cfg: RobotConfig, path: str | Path,
                    **kwargs: Any) -> Path:
    """Render ``res`` (see :func:`render_frames`) and write it as a looping GIF."""
    from horizon_mpc.sim.render import write_gif

    frames, rate = render_frames(res, cfg, **kwargs)
    log.info("%s: %d frames at %.1f fps -> %s", res.motion, len(frames), rate, path)
    return write_gif(path, frames, fps=rate)
