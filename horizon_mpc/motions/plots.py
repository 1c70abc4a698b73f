"""Figures of a motion (matplotlib, Agg backend): contact forces, base and joint torques."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from horizon_mpc.motions.analysis import roll_pitch_yaw, swing_intervals
from horizon_mpc.motions.result import MotionResult

__all__ = ["plot_base_and_torques", "plot_contact_forces"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _shade_swings(ax, res: MotionResult, foot: int) -> None:
    for a, b in swing_intervals(res.stance[foot:foot + 1])[0]:
        ax.axvspan((a - 1) * res.dt, b * res.dt, color="0.9", lw=0)


def plot_contact_forces(res: MotionResult, path: str | Path) -> Path:
    """One panel per foot: force components (world axes, N) over time, swings shaded
    (the layout of the paper's Fig. 2). Forces are held over each interval (steps)."""
    plt = _pyplot()
    nf = len(res.feet)
    fig, axs = plt.subplots(nf, 1, figsize=(9, 1.9 * nf + 0.6), sharex=True, squeeze=False)
    t = res.t[:-1]
    F = res.forces()
    for i, ax in enumerate(axs[:, 0]):
        _shade_swings(ax, res, i)
        for c, (name, color) in enumerate(zip("xyz", ("tab:blue", "tab:orange", "k"),
                                              strict=True)):
            ax.step(t, F[i, c], where="post", color=color, lw=1.2 if c == 2 else 0.9,
                    label=f"$f_{name}$")
        ax.set_ylabel(f"{res.feet[i]}\n(N)")
        ax.grid(alpha=0.3)
    axs[0, 0].legend(loc="upper right", ncol=3, fontsize=8)
    axs[0, 0].set_title(f"{res.motion} ({res.robot}, {res.solver}): contact forces, world "
                        "axes (grey: swing)")
    axs[-1, 0].set_xlabel("time (s)")
    return _save(fig, plt, path)


def plot_base_and_torques(res: MotionResult, path: str | Path,
                          effort_limit: np.ndarray | None = None) -> Path:
    """Base position (m), base roll/pitch/yaw (deg) and joint torques (N m) over time.

    ``effort_limit``: (nj,) joint torque limits; the largest ratio of torque to limit is
    given in the torque panel's title.
    """
    plt = _pyplot()
    fig, axs = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    t = res.t
    for i, name in enumerate("xyz"):
        axs[0].plot(t, res.q[i], label=name)
    axs[0].set_ylabel("base position (m)")
    rpy = np.degrees(np.unwrap(roll_pitch_yaw(res.q[3:7].T), axis=0))
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axs[1].plot(t, rpy[:, i], label=name)
    axs[1].set_ylabel("base orientation (deg)")
    tau = res.tau[6:]
    for j, name in enumerate(res.joint_names):
        axs[2].step(t[:-1], tau[j], where="post", lw=0.8, label=name)
    title = "joint torque (N m)"
    if effort_limit is not None:
        ratio = np.max(np.abs(tau) / np.asarray(effort_limit, float)[:, None], initial=0.0)
        title += f", max |tau| / URDF limit = {ratio:.2f}"
    axs[2].set_title(title, fontsize=9)
    axs[2].set_ylabel("joint torque (N m)")
    axs[2].set_xlabel("time (s)")
    for ax in axs[:2]:
        ax.legend(loc="upper right", fontsize=8)
    if len(res.joint_names) <= 16:
        axs[2].legend(loc="upper right", fontsize=6, ncol=4)
    for ax in axs:
        ax.grid(alpha=0.3)
    axs[0].set_title(f"{res.motion} ({res.robot}, {res.solver}): base and joint torques")
    return _save(fig, plt, path)


def _save(fig, plt, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
