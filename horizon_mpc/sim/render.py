"""Headless rendering (pybullet's TinyRenderer, CPU only) and GIF writing."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from horizon_mpc.sim.pybullet_import import import_pybullet
from horizon_mpc.sim.rotations import quat_yaw

p = import_pybullet()  # the module, without its banner (pybullet_import.py)

__all__ = ["checker_texture", "render_following", "write_gif"]


@functools.cache
def checker_texture(folder: Path, squares: int = 200, pixels: int = 4) -> Path:
    """A grey checkerboard PNG (``squares`` x ``squares``) written into ``folder``; returns
    its path (the caller removes it once loaded: a folder left per simulator filled /tmp).

    Stretched over the ground's visual (100 m wide) it gives 0.5 m squares, so that motion
    is visible in rendered frames.
    """
    from PIL import Image

    board = (np.indices((squares, squares)).sum(axis=0) % 2).astype(np.uint8) * 40 + 150
    board = np.kron(board, np.ones((pixels, pixels), dtype=np.uint8))
    rgb = np.stack([board, board + 10, board], axis=-1)
    path = Path(folder) / "checker.png"
    Image.fromarray(rgb).save(path)
    return path


def render_following(
    client: int,
    base_position: np.ndarray,
    base_quaternion: np.ndarray,
    width: int = 320,
    height: int = 240,
    distance: float = 1.5,
    yaw: float = 45.0,
    pitch: float = -25.0,
    fov: float = 60.0,
) -> np.ndarray:
    """RGB image (height, width, 3) uint8 from a camera looking at the base.

    The camera turns with the base heading: ``yaw`` (deg) is measured from behind the robot,
    ``pitch`` (deg) is negative when looking down; ``distance`` in m.
    """
    if width <= 0 or height <= 0:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    heading = np.degrees(quat_yaw(base_quaternion))
    view = p.computeViewMatrixFromYawPitchRoll(
        cameraTargetPosition=[float(x) for x in base_position],
        distance=distance,
        yaw=heading - 90.0 + yaw,
        pitch=pitch,
        roll=0.0,
        upAxisIndex=2,
        physicsClientId=client,
    )
    proj = p.computeProjectionMatrixFOV(fov=fov, aspect=width / height, nearVal=0.05,
                                        farVal=50.0, physicsClientId=client)
    _, _, rgba, _, _ = p.getCameraImage(width, height, view, proj,
                                        renderer=p.ER_TINY_RENDERER, physicsClientId=client)
    return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()


def write_gif(path: str | Path, frames: Sequence[np.ndarray], fps: float = 25.0) -> Path:
    """Write RGB frames (each (H, W, 3) uint8) as a looping GIF at ``fps`` frames/s."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:],
                   duration=max(1, round(1000.0 / fps)), loop=0)
    return path
