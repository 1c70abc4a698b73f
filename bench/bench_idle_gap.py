"""How a tick's time depends on the idle time before it: ours and Crocoddyl's.

A real-time MPC ticks once per control period and idles in between; on this machine a
tick after ~20 ms of idling runs ~1.5x slower than the same tick right after the previous
one, whatever fills the gap (sleep, a busy loop, other work) and for any solver. This
script measures it so that tick times taken in different regimes are not compared as if
they were alike (doc/benchmarks.md, Session 16).

Ours: the walking MPC's tick (``update`` + ``tau_head`` + ``prepare``, no ROS, no
simulator) replayed on states recorded from a lockstep closed loop, after each gap.
Crocoddyl: its warm MPC tick (``peer_crocoddyl.py --pace``), after the same gaps.
Output: ``bench/results/idle_gap.json`` and ``idle_gap.png``; a table on stdout.

Run: ``python bench/bench_idle_gap.py [--gaps 0 0.005 0.02 0.05] [--ticks 150] [--no-peer]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT))

import bench_ilqr  # noqa: E402
from cli_checks import non_negative_float, output_stem, positive_int, sibling  # noqa: E402

from horizon_mpc.config import load_robot_config  # noqa: E402
from horizon_mpc.mpc import WalkingMpc  # noqa: E402
from horizon_mpc.sim.simulator import Simulator  # noqa: E402
from horizon_mpc.sim.trajectory import JointTrajectoryCommand  # noqa: E402

ROBOT = "go2"  # the peer's robot
PUBLISHED = 6  # plan nodes sent to the simulator (the node's default publish_points)


def record(seconds: float) -> list[tuple]:
    """(t, q, v, cmd) of every tick of a lockstep closed loop (stand, then walk and turn)."""
    cfg = load_robot_config(ROBOT)
    sim, mpc = Simulator(cfg), WalkingMpc(cfg)
    dt = mpc.settings.dt
    steps = round(dt / sim.dt)
    plan, out = None, []
    while (st := sim.state()).time < seconds:
        t = st.time
        cmd = np.array([0.3 * (t > 1), 0.1 * (t > 3), 0.3 * (t > 4.5)])
        out.append((t, st.q.copy(), st.v.copy(), cmd))
        plan = mpc.start(st.q, st.v, t) if plan is None else mpc.update(t, st.q, st.v, cmd)
        mpc.prepare(t + dt, cmd)
        k = np.arange(PUBLISHED)
        sim.set_trajectory(JointTrajectoryCommand(
            sim.joint_names, t, dt * k, plan.q[7:, :PUBLISHED].T, plan.v[6:, :PUBLISHED].T,
            plan.tau_head(PUBLISHED)[6:].T))
        sim.step(steps)
    return out


def replay(states: list[tuple], gap: float) -> list[float]:
    """Tick times (ms) of a fresh MPC replaying ``states``, sleeping ``gap`` s before each."""
    mpc = WalkingMpc(ROBOT)
    dt = mpc.settings.dt
    t, q, v, c = states[0]
    mpc.start(q, v, t)
    mpc.prepare(t + dt, c)
    ticks = []
    for t, q, v, c in states[1:]:
        if gap > 0:
            time.sleep(gap)
        t0 = time.perf_counter()
        mpc.update(t, q, v, c).tau_head(PUBLISHED)
        mpc.prepare(t + dt, c)
        ticks.append(1e3 * (time.perf_counter() - t0))
    return ticks


def main(argv: list[str] | None = None) -> int:
    """Measure both ticks after each gap, write the JSON and the plot, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gaps", type=non_negative_float, nargs="+",
                    default=[0.0, 0.005, 0.02, 0.05],
                    help="idle seconds before each tick (ratios are against the smallest)")
    ap.add_argument("--ticks", type=positive_int, default=150,
                    help="ticks per gap (ours and peer)")
    ap.add_argument("--no-peer", action="store_true", help="ours only")
    ap.add_argument("--peer-python", default=None,
                    help=f"peer interpreter (default ${bench_ilqr.PEER_ENV}, else .venv-peer)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "idle_gap",
                    help="output stem: <out>.json and <out>.png")
    args = ap.parse_args(argv)
    args.out = output_stem(ap, args.out)
    dt = WalkingMpc(ROBOT).settings.dt
    states = record((args.ticks + 1) * dt)
    python, reason = ((None, "--no-peer") if args.no_peer else
                      bench_ilqr.find_peer_python(args.peer_python))
    rows = []
    for gap in args.gaps:
        ours = replay(states, gap)
        row = {"gap_s": gap, "ours_ms": float(np.median(ours)),
               "ours_p90_ms": float(np.percentile(ours, 90))}
        if python:
            try:
                peer = bench_ilqr.run_peer(python, ticks=args.ticks, repeats=1, max_iter=100,
                                           profile=False, pace=gap if gap > 0 else 0.0)
            except RuntimeError as exc:  # ours is still measured, the peer's said not run
                python, reason = None, str(exc)
                print(f"peer failed, ours only from here: {exc}", flush=True)  # noqa: T201
            else:
                ticks = (peer["paced_ticks"]["tick_ms"] if gap > 0
                         else peer["ticks"]["tick_ms"])
                row["crocoddyl_ms"] = float(np.median(ticks))
                row["ratio"] = row["ours_ms"] / row["crocoddyl_ms"]
        rows.append(row)
        print(" | ".join(f"{k} {v:.3f}" for k, v in row.items()), flush=True)  # noqa: T201
    base = min(rows, key=lambda r: r["gap_s"])  # the shortest gap (0: back to back)
    for row in rows:
        row["ours_over_shortest_gap"] = row["ours_ms"] / base["ours_ms"]
        if "crocoddyl_ms" in row and "crocoddyl_ms" in base:
            row["crocoddyl_over_shortest_gap"] = row["crocoddyl_ms"] / base["crocoddyl_ms"]
    doc = {"code": bench_ilqr.git_state(), "robot": ROBOT, "ticks": args.ticks,
           "shortest_gap_s": base["gap_s"],
           "peer": python or f"not run: {reason}", "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    json_path, png = sibling(args.out, ".json"), sibling(args.out, ".png")
    json_path.write_text(json.dumps(bench_ilqr.jsonable(doc), indent=1) + "\n")
    plot(rows, png)
    print(f"written {json_path}, {png}")  # noqa: T201
    return 0


def plot(rows: list[dict], path: Path) -> None:
    """Median tick against the idle gap, ours and Crocoddyl's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gaps = [1e3 * r["gap_s"] for r in rows]
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(gaps, [r["ours_ms"] for r in rows], "o-", label="horizon_mpc tick (1 ILQR it.)")
    if all("crocoddyl_ms" in r for r in rows):
        ax.plot(gaps, [r["crocoddyl_ms"] for r in rows], "s-",
                label="Crocoddyl warm tick (1 FDDP it.)")
    ax.set_xlabel("idle time before each tick (ms)")
    ax.set_ylabel("median tick (ms)")
    ax.set_title(f"{ROBOT}: tick time after an idle gap")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
