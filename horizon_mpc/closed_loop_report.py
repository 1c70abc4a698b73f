"""Metrics, plots and GIF of a closed-loop run (:mod:`horizon_mpc.closed_loop`).

Velocities are compared in the BASE frame (the frame of ``cmd_vel``): ``v[0:2]`` of the
Pinocchio velocity and the base-frame yaw rate ``v[5]``. Metrics are defined in
``doc/closed_loop.md``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from horizon_mpc.locomotion.command import limit_command

if TYPE_CHECKING:
    from horizon_mpc.closed_loop import Recording, Segment

__all__ = ["REPORT_FILES", "fallen", "render_replay", "roll_pitch_yaw", "summarise",
           "write_report"]

SETTLING = 1.0  # s after a segment starts before its tracking error counts
FALL_HEIGHT = 0.6  # fraction of the nominal base height below which the robot has fallen
FALL_TILT = 0.5  # rad of |roll| or |pitch| beyond which the robot has fallen
FALL_EPISODE = 2.0  # s: fallen-condition onsets closer than this to the last are one fall
FRAME_PERIOD = 0.05  # s of sim time between two GIF frames (real-time playback)
#: frames a run's GIF holds at most (~90 MB of raw frames: kept until the GIF is written, a
#: 40 s run held 400 MB more than without its GIF, 10 MB per sim second)
MAX_GIF_FRAMES = 400


def gif_frame_period(duration: float) -> float:
    """Sim s between two GIF frames of a run of ``duration`` s (frames at both ends):
    :data:`FRAME_PERIOD`, longer for runs of more than :data:`MAX_GIF_FRAMES` frames (the
    GIF still plays in real time, at fewer frames per second): a whole number of
    centiseconds, as a GIF stores its frame times (95.2 ms stored as 90 played a 38 s run
    5 % fast)."""
    if not math.isfinite(duration):
        return FRAME_PERIOD
    return max(FRAME_PERIOD, math.ceil(100.0 * duration / (MAX_GIF_FRAMES - 1) - 1e-9) / 100.0)
AXES = ("vx", "vy", "wz")


def roll_pitch_yaw(quat: np.ndarray) -> np.ndarray:
    """(..., 3) roll, pitch, yaw (rad, ZYX) of (..., 4) quaternions ``(x, y, z, w)``."""
    x, y, z, w = np.moveaxis(np.asarray(quat, dtype=float), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def fallen(q: np.ndarray, nominal_height: float) -> bool:
    """Base below ``FALL_HEIGHT`` x nominal height, or |roll| or |pitch| above ``FALL_TILT``."""
    roll, pitch, _ = roll_pitch_yaw(q[3:7])
    return bool(q[2] < FALL_HEIGHT * nominal_height or abs(roll) > FALL_TILT
                or abs(pitch) > FALL_TILT)


def _percentiles(x: np.ndarray) -> dict[str, float]:
    """median, p95, p99 and max of ``x`` (s) in ms (NaN when empty)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return dict.fromkeys(("median", "p95", "p99", "max"), math.nan)
    return {"median": float(np.median(x) * 1e3), "p95": float(np.percentile(x, 95) * 1e3),
            "p99": float(np.percentile(x, 99) * 1e3), "max": float(np.max(x) * 1e3)}


def _ticks(d: dict[str, np.ndarray], t0: float, t1: float, period: float,
           deadline_misses: int) -> dict:
    """Tick figures over the recorded span [t0, t1] (s of sim time): ticks per sim second
    and control periods without a tick (from the plans' stamps: every tick publishes one
    plan), solve time percentiles over the ticks whose solve time was heard (every tick
    with the MPC's diagnostics at every tick, a sample of them at a lower
    ``diagnostics_rate``; the first tick, the bootstrap solve, apart), deadline misses,
    plan age."""
    tick_t, tick = d["tick_t"], d["tick_time"]
    plan_t = d["plan_t"] if d["plan_t"].size else tick_t
    prepare = d["prepare_time"] if d["prepare_time"].size == tick.size else np.zeros(tick.size)
    span = t1 - t0 + period  # the control periods recorded, both ends included
    inside = int(np.count_nonzero((plan_t >= t0 - 1e-9) & (plan_t <= t1 + 1e-9)))
    # periods are counted, not measured: 2.1e-12 % without a tick after 102 s was the sum's
    expected = round(span / period, 6) if period > 0 else math.nan
    solves = max(plan_t.size - 1, 0)
    return {
        "ticks": int(plan_t.size),
        "ticks_per_sim_second": inside / span if span > 0 else math.nan,
        "periods_without_tick_percent": 100.0 * max(expected - inside, 0.0) / expected
        if expected > 0 else math.nan,
        "tick_time_samples": max(int(tick.size) - 1, 0),
        "tick_time_ms": _percentiles(tick[1:]),
        # a tick's latency plus the preparation of the next after it: what must fit a period
        "tick_work_ms": _percentiles(tick[1:] + np.nan_to_num(prepare[1:tick.size])),
        "bootstrap_ms": float(tick[0] * 1e3) if tick.size else math.nan,
        "deadline_misses": deadline_misses,
        "deadline_miss_percent": 100.0 * deadline_misses / solves if solves else math.nan,
        "plan_age_ms": _percentiles(d["plan_age"]),
    }


def summarise(rec: Recording, segments: Sequence[Segment], mode: str = "lockstep",
              robot: str = "") -> dict:
    """The metrics of ``rec`` as a JSON-ready dict (times s, speeds m/s and rad/s)."""
    d = rec.arrays()
    t, q, v = d["t"], d["q"], d["v"]
    actual = np.column_stack([v[:, 0], v[:, 1], v[:, 5]])
    segs, start = [], 0.0
    run_end = float(t[-1]) if len(t) else 0.0
    for i, seg in enumerate(segments):
        end = round(start + seg.duration, 9)  # no 40.39999999999996 after many segments
        mask = (t >= start + SETTLING - 1e-9) & (t < end - 1e-9)
        cmd = np.array([seg.vx, seg.vy, seg.wz])
        entry = {"index": i, "start": start, "end": end, "command": dict(zip(AXES, cmd.tolist(),
                                                                             strict=True)),
                 "samples": int(mask.sum())}
        if end > run_end + 0.05:  # --duration ended the run before this segment's end
            entry.update(end=max(start, run_end), planned_end=end, cut_short=True)
            if start >= run_end:  # never played: no end of its own
                entry.update(end=None, reached=False)
        if rec.max_velocity is not None:
            clamped = np.array(limit_command(cmd, rec.max_velocity, rec.max_command_norm))
            if not np.array_equal(clamped, cmd):
                # the node limits such a command: the robot is scored against what it got
                entry["command_clamped"] = dict(zip(AXES, clamped.tolist(), strict=True))
                cmd = clamped
        if mask.sum() >= 2:  # one sample (a segment cut at its settling second) is no mean
            err = actual[mask] - cmd
            entry["rmse"] = dict(zip(AXES, np.sqrt(np.mean(err**2, axis=0)).tolist(),
                                     strict=True))
            entry["mean"] = dict(zip(AXES, actual[mask].mean(axis=0).tolist(), strict=True))
        segs.append(entry)
        start = end
    fall_flags = np.array([fallen(qi, rec.nominal_height) for qi in q]) if len(q) else \
        np.zeros(0, bool)
    # a fall = an onset of the fallen condition more than FALL_EPISODE after the previous
    # onset (a robot on its side crosses the tilt threshold back and forth as it tumbles)
    onsets = np.flatnonzero(fall_flags & ~np.concatenate(([False], fall_flags[:-1])))
    onsets = onsets[np.diff(t[onsets], prepend=-np.inf) > FALL_EPISODE]
    xy = q[:, :2] if len(q) else np.zeros((0, 2))
    sim_time = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    period = float(np.median(np.diff(t))) if len(t) > 1 else math.nan
    rpy = roll_pitch_yaw(q[:, 3:7]) if len(q) else np.zeros((0, 3))
    ticks = _ticks(d, float(t[0]) if len(t) else 0.0, float(t[-1]) if len(t) else 0.0,
                   period, rec.deadline_misses)
    return {
        "robot": robot,
        "mode": mode,
        "sim_time": sim_time,
        "wall_time": rec.wall_time,
        "real_time_factor": sim_time / rec.wall_time if rec.wall_time > 0 else math.nan,
        "mpc_build_time": rec.build_time,
        "segments": segs,
        "distance_travelled": float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))),
        "net_displacement": (xy[-1] - xy[0]).tolist() if len(xy) else [0.0, 0.0],
        "yaw_change": float(np.unwrap(rpy[:, 2])[-1] - rpy[0, 2]) if len(rpy) else 0.0,
        "falls": {"count": int(onsets.size), "times": t[onsets].tolist(),
                  "criteria": f"base height < {FALL_HEIGHT} x {rec.nominal_height:.3f} m or "
                              f"|roll|, |pitch| > {FALL_TILT} rad"},
        "min_base_height": float(q[:, 2].min()) if len(q) else math.nan,
        "max_abs_roll_pitch": float(np.abs(rpy[:, :2]).max()) if len(rpy) else math.nan,
        **ticks,
        "overruns": rec.overruns,
        "stale_skips": rec.stale_skips,
        "prepare_misses": rec.prepare_misses,
        "mpc_process": rec.mpc_process,
        "domain_id": rec.domain_id,
        "foreign_publishers": list(rec.foreign_publishers),
        "interrupted": bool(getattr(rec, "interrupted", False)),
        "gif_frames": len(rec.frames),
        "gif_frame_period": rec.frame_period if rec.frames else None,  # no GIF: none
    }


def render_replay(robot: str, t: Sequence[float], q: Sequence[np.ndarray],
                  period: float = FRAME_PERIOD) -> list[np.ndarray]:
    """GIF frames of a finished run: the recorded configurations ``q`` (Pinocchio, one per
    time in ``t``, s) set into a fresh headless simulator and rendered every ``period`` s of
    sim time (the nearest recorded state to each frame time)."""
    from horizon_mpc.sim import Simulator

    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return []
    frames = []
    with Simulator(robot) as sim:
        for tf in np.arange(t[0], t[-1] + 1e-9, period):
            sim.set_state(q[int(np.argmin(np.abs(t - tf)))])
            frames.append(sim.render())
    return frames


#: what :func:`write_report` writes into a run's folder
REPORT_FILES = ("summary.json", "mpc_node.log", "velocity_tracking.png", "base_pose.png",
                "contacts.png", "solve_time.png", "run.gif")


def write_report(rec: Recording, summary: dict, out: str | Path,
                 written: list[Path] | None = None) -> list[Path]:
    """Write summary.json, the PNG plots, (if frames were rendered) run.gif and (real time)
    mpc_node.log into ``out``; an earlier run's files of those names there are removed
    first (:data:`REPORT_FILES`: a Ctrl-C while writing left the earlier run's plots and GIF
    beside this run's summary). Returns the paths written, appended to ``written`` as they
    are (an interrupted call leaves the ones it finished there). The summary goes first:
    matplotlib's import and the plots take seconds, in which a Ctrl-C left no output."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for name in REPORT_FILES:
        (out / name).unlink(missing_ok=True)
    written = [] if written is None else written
    # strict JSON: a figure with no samples (NaN) is null, not the NaN parsers refuse
    (out / "summary.json").write_text(json.dumps(_finite_or_null(summary), indent=2,
                                                 allow_nan=False) + "\n", encoding="utf-8")
    written.append(out / "summary.json")
    if rec.mpc_log:
        (out / "mpc_node.log").write_text(rec.mpc_log + "\n", encoding="utf-8")
        written.append(out / "mpc_node.log")
    d = rec.arrays()
    t = d["t"]
    if len(t) == 0:
        return written
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q, v = d["q"], d["v"]

    # which run a figure is of, when several are compared side by side
    run = f"{summary.get('robot', '')}, {summary.get('mode', '')}".strip(", ")

    def save(fig, name: str) -> None:
        if run:
            fig.suptitle(run, fontsize=9, x=0.01, ha="left")
        fig.tight_layout()
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
        written.append(out / name)

    fig, axs = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    actual = np.column_stack([v[:, 0], v[:, 1], v[:, 5]])
    for i, (ax, name, unit) in enumerate(zip(axs, AXES, ("m/s", "m/s", "rad/s"), strict=True)):
        ax.plot(t, d["cmd"][:, i], "k--", label="commanded")
        ax.plot(t, d["cmd_mpc"][:, i], color="0.6", label="MPC reference (ramped)")
        ax.plot(t, actual[:, i], label="actual (base frame)")
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    axs[0].legend(loc="upper right", fontsize=8)
    axs[-1].set_xlabel("sim time (s)")
    save(fig, "velocity_tracking.png")

    rpy = roll_pitch_yaw(q[:, 3:7])
    fig, axs = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    axs[0].plot(t, q[:, 2], label="base height")
    axs[0].axhline(FALL_HEIGHT * rec.nominal_height, color="r", ls=":", label="fall threshold")
    axs[0].set_ylabel("z (m)")
    axs[0].legend(fontsize=8)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        axs[1].plot(t, rpy[:, i], label=name)
    axs[1].set_ylabel("rad")
    axs[1].set_xlabel("sim time (s)")
    axs[1].legend(fontsize=8)
    for ax in axs:
        ax.grid(alpha=0.3)
    save(fig, "base_pose.png")

    contact = d["contact"].astype(float)
    fig, ax = plt.subplots(figsize=(9, 2.5))
    ax.imshow(contact.T, aspect="auto", interpolation="nearest", cmap="Greys",
              extent=(t[0], t[-1], contact.shape[1] - 0.5, -0.5))
    ax.set_yticks(range(contact.shape[1]), rec.feet or range(contact.shape[1]))
    ax.set_xlabel("sim time (s)")
    ax.set_title("foot contacts (black = contact)")
    save(fig, "contacts.png")

    fig, ax = plt.subplots(figsize=(9, 3))
    tick = d["tick_time"]
    prepare = d["prepare_time"] if d["prepare_time"].size == tick.size else np.zeros(tick.size)
    if np.nansum(prepare) > 0:  # prepared ticks: the latency alone hides half the work
        ax.plot(d["tick_t"], (tick + prepare) * 1e3, ".", ms=3, color="0.55",
                label="work per tick (latency + next tick's preparation)")
    ax.plot(d["tick_t"], tick * 1e3, ".", ms=3, label="latency (state to plan)")
    ax.axhline(1e3 * (t[1] - t[0]) if len(t) > 1 else 20.0, color="r", ls=":",
               label="control period")
    ax.set_xlabel("sim time (s)")
    ax.set_ylabel("time (ms)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    save(fig, "solve_time.png")

    if rec.frames:
        from horizon_mpc.sim.render import write_gif

        written.append(write_gif(out / "run.gif", rec.frames, fps=1.0 / rec.frame_period))
    return written


def _finite_or_null(x: object) -> object:
    """``x`` with every non-finite float (at any depth of dicts and lists) replaced by None."""
    if isinstance(x, dict):
        return {k: _finite_or_null(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite_or_null(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x
