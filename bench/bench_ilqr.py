"""Benchmark of our ILQR against Crocoddyl's FDDP (issue 5: the figure that matters).

Ours: the go2 whole-body walking problem of the MPC (``build_walking_problem`` with the
robot config's ``mpc:`` settings: dt 0.02 s, N nodes, four point contacts, under-actuation,
friction cones, torque and joint limits), trotting at ``V_FORWARD`` m/s, solved by
``make_solver('ilqr', ...)`` with the options the MPC gives it (plus ``--ilqr-opt``):

* converging solves from the standing guess (``rti`` False): time per iteration =
  ``stats.time / stats.iterations``, and the solver's per-phase ``timings``
  (quadratise / backward / rollout / line_search) per iteration;
* warm MPC ticks of a perfect-model receding horizon (``rti`` True, one iteration per
  call): ``shift()``, node 0 pinned to the previous solution's node 1, velocity/pose
  references and the trot's contact schedule sampled at the tick's time, ``solve()``.
  The tick time is all of that; ``solve_ms`` is ``stats.time`` alone.

Peer: ``bench/peer_crocoddyl.py`` (Crocoddyl's own go2 trot, 56 nodes at dt 0.01, FDDP,
one thread), run in a subprocess with the peer interpreter (``$HORIZON_MPC_PEER_PYTHON``,
else ``.venv-peer/bin/python``; ``make peer-venv`` creates it). The same quantities, plus
Crocoddyl's own profiler (calcDiff / backwardPass / tryStep) in separate runs.

Ours and the peer take turns for ``--rounds`` rounds in this one run (times on these
machines vary 20-50% between runs and other jobs share the 2 cores: compare the ratios).
Every time is taken on the wall clock and as CPU time of the process (``process_time``:
what a single-threaded solve costs, without the time other jobs hold the core; the
solver's phase breakdown is wall time only). Figures are medians over every solve/tick of
all rounds; the breakdowns are means. The problems differ (ours: N = 40 at dt 0.02 with
constraints; Crocoddyl: 56 nodes at dt 0.01, contacts in the dynamics, soft costs):
per-node ratios are given next to the raw ones, and ours also runs at N = 56.

Run: ``python bench/bench_ilqr.py [--ticks N] [--nodes N ...] [--out DIR]`` (``--help``
for the rest); writes ``DIR/ilqr.json`` and ``DIR/ilqr.png`` (default ``bench/results``).
Without the peer interpreter, ours is still measured and the ratios are null; a peer
that fails is reported the same way and the exit status is 1.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):  # before numpy: single thread
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # running from a source checkout without an install
    sys.path.insert(0, str(ROOT))

sys.path.insert(0, str(Path(__file__).resolve().parent))  # cli_checks, beside this script
from cli_checks import finite_float, output_folder, positive_int  # noqa: E402

from horizon_mpc.config import load_robot_config  # noqa: E402
from horizon_mpc.locomotion import MpcSettings, build_walking_problem, make_gait  # noqa: E402
from horizon_mpc.model import RobotModel  # noqa: E402
from horizon_mpc.solvers import make_solver  # noqa: E402

ROBOT = "go2"
V_FORWARD = 0.3  # m/s, the trot's forward velocity reference
RESULTS = ROOT / "bench" / "results"
PEER_SCRIPT = ROOT / "bench" / "peer_crocoddyl.py"
PEER_ENV = "HORIZON_MPC_PEER_PYTHON"
PEER_DEFAULT = ROOT / ".venv-peer" / "bin" / "python"
PEER_TIMEOUT = 900.0  # s
# the ILQR's solver.timings keys, and how they map onto the phases both solvers share
TIMING_KEYS = ("quadratise", "backward", "rollout", "line_search")
COMMON_PHASES = {"linearise": ("quadratise",), "backward": ("backward",),
                 "forward_line_search": ("rollout", "line_search")}
PHASE_LABELS = {"linearise": "linearise (quadratise / calcDiff)",
                "backward": "backward pass",
                "forward_line_search": "rollout + line search (/ tryStep)",
                "other": "rest of the solve",
                "shift": "shift + references (tick only)"}


# ---------------------------------------------------------------------- ours
@dataclass
class Trot:
    """The go2 walking problem, its ILQR, and the trot it is asked to walk.

    ``ground_z``: world height of each foot frame standing at the nominal posture (m);
    ``vx``: forward velocity reference (m/s).
    """

    wp: object  # horizon_mpc.locomotion.WalkingProblem
    solver: object  # the ILQR
    gait: object  # horizon_mpc.locomotion.Gait
    ground_z: np.ndarray
    vx: float
    build_s: float

    @property
    def n_nodes(self) -> int:
        """Number of intervals N."""
        return self.wp.n_nodes

    def set_references(self, t: float, q: np.ndarray) -> None:
        """Velocity and pose references and the trot's contact schedule from time ``t`` (s).

        The pose reference moves at ``vx`` from the base position ``q[:2]`` (the MPC's
        reference never winds up far from the measured pose either).
        """
        wp, dt, n = self.wp, self.wp.settings.dt, self.n_nodes
        wp.v_ref.assign([self.vx, 0.0, 0.0, 0.0, 0.0, 0.0])
        k = dt * np.arange(n + 1)
        wp.pose_ref.assign(np.vstack([q[0] + self.vx * k, np.full(n + 1, q[1]),
                                      np.ones(n + 1), np.zeros(n + 1)]))
        sched = self.gait.schedule(t, n, dt)
        wp.contacts.set_schedule(sched.stance, self.ground_z[:, None] + sched.swing_height())

    def pin_initial_state(self, q: np.ndarray, v: np.ndarray) -> None:
        """Node 0 fixed to the measured state (bounds) and the warm start's node 0 on it."""
        self.wp.q.set_bounds(q, q, nodes=0)
        self.wp.v.set_bounds(v, v, nodes=0)
        self.wp.q.set_initial_guess(q, nodes=0)
        self.wp.v.set_initial_guess(v, nodes=0)

    def stand(self) -> None:
        """Cold start: standing guess at the nominal posture, trot references from t = 0."""
        q0 = self.wp.q_nominal.copy()
        self.wp.standing_guess(q0)
        self.solver.reset_multipliers()
        self.pin_initial_state(q0, np.zeros(self.wp.model.nv))
        self.set_references(0.0, q0)


def build_trot(n_nodes: int | None = None, vx: float = V_FORWARD, codegen: bool = True,
               opts: dict | None = None) -> Trot:
    """Build the go2 walking problem (``n_nodes`` None: the config's horizon) and its ILQR.

    The ILQR gets the options ``WalkingMpc`` gives it (``rho_init`` from the settings) plus
    ``opts``. ``codegen`` False evaluates with CasADi's VM (no compilation: tests only).
    """
    t0 = time.perf_counter()
    cfg = load_robot_config(ROBOT)
    model = RobotModel.from_example(ROBOT)
    settings = MpcSettings.from_config(cfg)
    if n_nodes is not None:
        settings.n_nodes = int(n_nodes)
    wp = build_walking_problem(model, cfg, settings)
    solver = make_solver("ilqr", wp.prb, {"rho_init": settings.rho_init, "codegen": codegen,
                                          **(opts or {})})
    g = settings.gait
    gait = make_gait("trot", g.step_duration, g.step_height, g.duty_factor, len(wp.feet))
    ground_z = np.array([float(model.fk(foot)(wp.q_nominal)[0][2]) for foot in wp.feet])
    return Trot(wp, solver, gait, ground_z, float(vx), time.perf_counter() - t0)


def _phases(solver) -> tuple[dict[str, float], list[str]]:
    """The solver's per-phase times of the last solve (ms) and the missing timing keys."""
    timings = dict(getattr(solver, "timings", None) or {})
    missing = [k for k in TIMING_KEYS if k not in timings]
    return {k: 1e3 * float(v) for k, v in timings.items()}, missing


def measure_converging(trot: Trot, repeats: int, max_iter: int = 100) -> dict:
    """Cold converging solves of the trot from the standing guess (``rti`` False).

    Returns ``{"solves": [...]}``, one record per solve: wall ms, stats.time ms, iterations,
    status, cost, violation and the solver's phase times (ms, summed over the iterations).
    """
    s = trot.solver
    s.set_option("rti", False)
    s.set_option("max_iter", int(max_iter))
    solves = []
    for _ in range(repeats):
        trot.stand()  # untimed: the cold initial guess
        t0, c0 = time.perf_counter(), time.process_time()
        s.solve()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        phases, missing = _phases(s)
        st = s.stats
        iters = max(st.iterations, 1)
        solves.append({"wall_ms": 1e3 * wall, "ms": 1e3 * st.time, "cpu_ms": 1e3 * cpu,
                       "iterations": st.iterations, "ms_per_iteration": 1e3 * st.time / iters,
                       "cpu_ms_per_iteration": 1e3 * cpu / iters,
                       "status": st.status, "converged": bool(st.success),
                       "cost": float(st.cost), "violation": float(st.constraint_violation),
                       "phases_ms": phases, "missing_timing_keys": missing})
    return {"solves": solves}


def measure_ticks(trot: Trot, ticks: int, max_iter: int = 100) -> dict:
    """Warm MPC ticks of a perfect-model receding horizon, one ILQR iteration each.

    Starts from a converged trot (untimed). Per tick: ``shift()``, node 0 pinned to the
    previous solution's node 1, references/schedule at ``t = k dt``, ``solve()``; the tick
    time covers all of it. Returns per-tick lists (ms; violations, costs) and phase times.
    """
    s, wp = trot.solver, trot.wp
    dt = wp.settings.dt
    s.set_option("rti", False)
    s.set_option("max_iter", int(max_iter))
    trot.stand()
    s.solve()
    start = {"iterations": s.stats.iterations, "status": s.stats.status}
    s.set_option("rti", True)
    s.set_option("iterations_per_call", 1)
    out = {"start": start, "tick_ms": [], "solve_ms": [], "tick_cpu_ms": [], "iterations": [],
           "violation": [],
           "cost": [], "status": [], "phases_ms": [], "missing_timing_keys": []}
    try:
        for k in range(1, ticks + 1):
            sol = s.solution
            q1, v1 = sol["q"][:, 1].copy(), sol["v"][:, 1].copy()  # the perfect model
            t0, c0 = time.perf_counter(), time.process_time()
            s.shift()
            trot.pin_initial_state(q1, v1)
            trot.set_references(k * dt, q1)
            s.solve()
            tick, cpu = time.perf_counter() - t0, time.process_time() - c0
            phases, missing = _phases(s)
            st = s.stats
            out["tick_ms"].append(1e3 * tick)
            out["solve_ms"].append(1e3 * st.time)
            out["tick_cpu_ms"].append(1e3 * cpu)
            out["iterations"].append(st.iterations)
            out["violation"].append(float(st.constraint_violation))
            out["cost"].append(float(st.cost))
            out["status"].append(st.status)
            out["phases_ms"].append(phases)
            out["missing_timing_keys"] = sorted(set(out["missing_timing_keys"]) | set(missing))
    finally:
        s.set_option("rti", False)
    out["base_x_final"] = float(s.solution["q"][0, 0])
    return out


# ---------------------------------------------------------------------- peer
def find_peer_python(explicit: str | None = None) -> tuple[str | None, str]:
    """The peer interpreter and a reason when there is none.

    Order: ``explicit`` (``--peer-python``), ``$HORIZON_MPC_PEER_PYTHON``, ``.venv-peer``.
    """
    if explicit:
        where, path = "--peer-python", explicit
    elif os.environ.get(PEER_ENV):
        where, path = f"${PEER_ENV}", os.environ[PEER_ENV]
    else:
        where, path = "default", str(PEER_DEFAULT)
    if path and Path(path).is_file() and os.access(path, os.X_OK):
        return path, ""
    return None, (f"peer interpreter not found ({where}: {path}); run `make peer-venv` "
                  f"(crocoddyl 3.2.1 + pin 4.0.0 in .venv-peer) or set {PEER_ENV}")


def run_peer(python: str, ticks: int, repeats: int, max_iter: int = 100,
             profile: bool = True, timeout: float = PEER_TIMEOUT, pace: float = 0.0) -> dict:
    """Run ``peer_crocoddyl.py`` with ``python``; its JSON (raises RuntimeError on failure).

    ``pace`` > 0 adds its ``paced_ticks`` (ticks after ``pace`` s of sleep each)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}  # nothing of ours
    env.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    cmd = [python, str(PEER_SCRIPT), "--ticks", str(ticks), "--repeats", str(repeats),
           "--max-iter", str(max_iter)] + ([] if profile else ["--no-profile"])
    if pace > 0:
        cmd += ["--pace", repr(float(pace))]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout,
                          check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"peer run failed (exit {proc.returncode}): {' '.join(cmd)}\n"
                           f"{proc.stderr.strip()[-2000:]}")
    try:
        return json.loads(proc.stdout.strip().splitlines()[-1])
    except (IndexError, json.JSONDecodeError) as exc:
        raise RuntimeError(f"peer printed no JSON: {proc.stdout[-500:]!r}") from exc


# ---------------------------------------------------------------------- summaries
def jsonable(obj: object) -> object:
    """``obj`` with every non-finite float replaced by None (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _stats(xs: list[float]) -> dict[str, float]:
    """Median, min, 90th percentile, max of a sample (NaN when empty)."""
    if not xs:
        return {"median": math.nan, "min": math.nan, "p90": math.nan, "max": math.nan}
    return {"median": statistics.median(xs), "min": min(xs),
            "p90": float(np.percentile(xs, 90)), "max": max(xs)}


def _common(phases: dict[str, float], total: float) -> dict[str, float]:
    """Our timing keys -> the shared phases; ``other`` = ``total`` minus them."""
    out = {name: sum(phases.get(k, 0.0) for k in keys) for name, keys in COMMON_PHASES.items()}
    out["other"] = total - sum(out.values())
    return out


def summarise_ours(rounds: list[dict], n_nodes: int, trot: Trot) -> dict:
    """Pool the rounds of ours at one horizon length."""
    solves = [s for r in rounds for s in r["converging"]["solves"]]
    iters = sum(s["iterations"] for s in solves)
    phase_sum = {k: sum(s["phases_ms"].get(k, 0.0) for s in solves) for k in TIMING_KEYS}
    per_it = {k: v / max(iters, 1) for k, v in phase_sum.items()}
    total_per_it = sum(s["ms"] for s in solves) / max(iters, 1)
    ticks = [r["ticks"] for r in rounds]
    tick_ms = [x for t in ticks for x in t["tick_ms"]]
    solve_ms = [x for t in ticks for x in t["solve_ms"]]
    tick_cpu_ms = [x for t in ticks for x in t["tick_cpu_ms"]]
    n_ticks = max(len(tick_ms), 1)
    tick_phases = {k: sum(p.get(k, 0.0) for t in ticks for p in t["phases_ms"]) / n_ticks
                   for k in TIMING_KEYS}
    tick_common = _common(tick_phases, sum(solve_ms) / n_ticks)
    tick_common["shift"] = (sum(tick_ms) - sum(solve_ms)) / n_ticks
    viol = [x for t in ticks for x in t["violation"]]
    prb = trot.wp.prb
    missing = sorted({k for s in solves for k in s["missing_timing_keys"]}
                     | {k for t in ticks for k in t["missing_timing_keys"]})
    return {
        "solver_options": {k: v for k, v in trot.solver.opts.items()
                           if isinstance(v, bool | int | float | str | None)},
        "problem": {"robot": ROBOT, "nodes": n_nodes, "dt": trot.wp.settings.dt,
                    "nx": int(prb.nx), "ndx": int(prb.ndx), "nu": int(prb.nu),
                    "constraints": sorted(prb.constraints), "gait": "trot",
                    "step_duration": trot.gait.step_duration, "v_forward": trot.vx,
                    "build_s": trot.build_s},
        "converging": {
            "ms_per_iteration": _stats([s["ms_per_iteration"] for s in solves]),
            "cpu_ms_per_iteration": _stats([s["cpu_ms_per_iteration"] for s in solves]),
            "iterations": [s["iterations"] for s in solves],
            "status": sorted({s["status"] for s in solves}),
            "violation_max": max(s["violation"] for s in solves),
            "solve_ms": _stats([s["ms"] for s in solves]),
            "breakdown_ms_per_iteration": {**per_it, "total": total_per_it},
            "common_ms_per_iteration": _common(per_it, total_per_it),
            "solves": solves,
        },
        "ticks": {
            "n": len(tick_ms),
            "tick_ms": _stats(tick_ms),
            "tick_cpu_ms": _stats(tick_cpu_ms),
            "solve_ms": _stats(solve_ms),
            "breakdown_ms_per_tick": {**tick_phases, "solve": sum(solve_ms) / n_ticks,
                                      "tick": sum(tick_ms) / n_ticks},
            "common_ms_per_tick": tick_common,
            "violation": {**_stats(viol), "last": viol[-1] if viol else math.nan},
            "start_iterations": [t["start"]["iterations"] for t in ticks],
            "rounds": ticks,
        },
        "missing_timing_keys": missing,
    }


def summarise_peer(rounds: list[dict]) -> dict:
    """Pool the rounds of the peer."""
    solves = [s for r in rounds for s in r["converging"]["solves"]]
    tick_ms = [x for r in rounds for x in r["ticks"]["tick_ms"]]
    solve_ms = [x for r in rounds for x in r["ticks"]["solve_ms"]]
    tick_cpu_ms = [x for r in rounds for x in r["ticks"]["tick_cpu_ms"]]
    n_ticks = max(len(tick_ms), 1)
    out = {
        "versions": rounds[0]["versions"],
        "problem": rounds[0]["problem"],
        "converging": {
            "ms_per_iteration": _stats([s["ms_per_iteration"] for s in solves]),
            "cpu_ms_per_iteration": _stats([s["cpu_ms_per_iteration"] for s in solves]),
            "iterations": [s["iterations"] for s in solves],
            "converged": all(s["converged"] for s in solves),
            "solve_ms": _stats([s["ms"] for s in solves]),
            "solves": solves,
        },
        "ticks": {"n": len(tick_ms), "tick_ms": _stats(tick_ms),
                  "tick_cpu_ms": _stats(tick_cpu_ms), "solve_ms": _stats(solve_ms),
                  "shift_ms_mean": (sum(tick_ms) - sum(solve_ms)) / n_ticks,
                  "step_length": [x for r in rounds for x in r["ticks"]["step_length"]]},
    }
    paced = [r["paced_ticks"] for r in rounds if "paced_ticks" in r]
    if paced:
        out["paced_ticks"] = {"n": sum(len(p["tick_ms"]) for p in paced),
                              "pace_s": paced[0]["pace_s"],
                              "tick_ms": _stats([x for p in paced for x in p["tick_ms"]]),
                              "tick_cpu_ms": _stats([x for p in paced
                                                     for x in p["tick_cpu_ms"]])}
    profiles = [r["profile"] for r in rounds if "profile" in r]
    if profiles:
        def mean(path: tuple[str, str]) -> dict[str, float]:
            keys = profiles[0][path[0]][path[1]].keys()
            return {k: statistics.fmean(p[path[0]][path[1]][k] for p in profiles) for k in keys}
        tick_prof = mean(("tick", "per_tick_ms"))
        out["profile"] = {
            "note": "crocoddyl's profiler, separate runs (it adds its own overhead)",
            "common_ms_per_iteration": mean(("converging", "per_iteration_ms")),
            "common_ms_per_tick": {**tick_prof, "shift": out["ticks"]["shift_ms_mean"]},
            "calcDiff_calls_per_converging_solve": profiles[0]["converging"]["calcDiff_calls"],
            "iterations_per_converging_solve": profiles[0]["converging"]["iterations"],
        }
    return out


def ratios(ours: dict, peer: dict | None) -> dict:
    """Ours / Crocoddyl, per iteration and per warm tick, on wall and on CPU time.

    Medians (and minima); ``per_node``: each side divided by its number of nodes first.
    None everywhere without the peer.
    """
    keys = ("per_iteration", "per_tick", "per_iteration_min", "per_tick_min",
            "per_iteration_per_node", "per_tick_per_node")
    if peer is None:
        return {clock: dict.fromkeys(keys) for clock in ("wall", "cpu")}
    nodes = ours["problem"]["nodes"] / peer["problem"]["nodes"]
    out = {}
    for clock, it_key, tick_key in (("wall", "ms_per_iteration", "tick_ms"),
                                    ("cpu", "cpu_ms_per_iteration", "tick_cpu_ms")):
        o_it, p_it = ours["converging"][it_key], peer["converging"][it_key]
        o_t, p_t = ours["ticks"][tick_key], peer["ticks"][tick_key]
        out[clock] = {"per_iteration": o_it["median"] / p_it["median"],
                      "per_tick": o_t["median"] / p_t["median"],
                      "per_iteration_min": o_it["min"] / p_it["min"],
                      "per_tick_min": o_t["min"] / p_t["min"],
                      "per_iteration_per_node": o_it["median"] / p_it["median"] / nodes,
                      "per_tick_per_node": o_t["median"] / p_t["median"] / nodes}
    return out


# ---------------------------------------------------------------------- plot
def plot(results: dict, path: Path) -> None:
    """Stacked bars of the phase breakdown, ours vs Crocoddyl, per iteration and per tick.

    Bars: phase means (wall time; Crocoddyl's from its profiler runs). On each bar a solid
    black line marks the median wall time, a dashed one the median CPU time.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8))
    colors = dict(zip(PHASE_LABELS, ("#4c72b0", "#dd8452", "#55a868", "#8c8c8c", "#c9b3e0"),
                      strict=True))
    peer = results["peer"]
    for ax, (title, key, wall, cpu) in zip(axes, (
            ("converging solve: ms per iteration", "iteration", "ms_per_iteration",
             "cpu_ms_per_iteration"),
            ("warm MPC tick (shift + 1 iteration): ms", "tick", "tick_ms", "tick_cpu_ms")),
            strict=True):
        bars = []  # (label, phases, median wall, median cpu)
        for n, o in results["ours"].items():
            src = o["converging"] if key == "iteration" else o["ticks"]
            bars.append((f"ours\nN={n}", src[f"common_ms_per_{key}"], src[wall]["median"],
                         src[cpu]["median"]))
        if peer.get("available") and "profile" in peer:
            src = peer["converging"] if key == "iteration" else peer["ticks"]
            bars.append((f"Crocoddyl\nFDDP {peer['problem']['nodes']} nodes",
                         peer["profile"][f"common_ms_per_{key}"], src[wall]["median"],
                         src[cpu]["median"]))
        for i, (_label, phases, median, median_cpu) in enumerate(bars):
            bottom = 0.0
            for name, color in colors.items():
                h = max(phases.get(name, 0.0), 0.0)
                if h > 0:
                    ax.bar(i, h, bottom=bottom, color=color, width=0.6,
                           label=PHASE_LABELS[name])
                    bottom += h
            ax.plot([i - 0.35, i + 0.35], [median, median], color="k", lw=2,
                    label="median wall time")
            ax.plot([i - 0.35, i + 0.35], [median_cpu, median_cpu], color="k", lw=1.2,
                    ls="--", label="median CPU time")
            ax.text(i, max(bottom, median) * 1.02, f"{median:.1f}", ha="center", va="bottom")
        ax.set_xticks(range(len(bars)), [b[0] for b in bars])
        ax.set_title(title)
        ax.set_ylabel("ms")
        ax.margins(y=0.12)
    handles, labels = {}, []
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in handles:
                handles[lab] = h
                labels.append(lab)
    fig.legend([handles[lab] for lab in labels], labels, loc="lower center", ncol=3,
               fontsize=8, frameon=False)
    n0 = next(iter(results["ours"]))
    r = results["ratios"][n0]
    sub = ("peer not measured: " + peer.get("reason", "")) if not peer.get("available") else (
        f"ours (N={n0}) / Crocoddyl: {r['wall']['per_iteration']:.2f} per iteration, "
        f"{r['wall']['per_tick']:.2f} per tick (CPU time: {r['cpu']['per_iteration']:.2f}, "
        f"{r['cpu']['per_tick']:.2f})")
    fig.suptitle(f"ILQR vs Crocoddyl FDDP, go2 trot, 1 thread\n{sub}", fontsize=10)
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------- main
def run(args: argparse.Namespace) -> tuple[dict, int]:
    """Measure everything; returns the results and the exit code."""
    load0 = os.getloadavg()
    peer_python, reason = find_peer_python(args.peer_python)
    trots = {}
    for n in args.nodes:
        print(f"building the go2 walking problem, N={n}", flush=True)
        trots[n] = build_trot(n, args.v_forward, codegen=not args.no_codegen,
                              opts=dict(args.ilqr_opt))
    ours_rounds = {n: [] for n in args.nodes}
    peer_rounds, peer_error = [], None
    for r in range(args.rounds):
        for n, trot in trots.items():
            print(f"round {r + 1}/{args.rounds}: ours N={n}", flush=True)
            ours_rounds[n].append({
                "converging": measure_converging(trot, args.repeats, args.max_iter),
                "ticks": measure_ticks(trot, args.ticks, args.max_iter)})
        if peer_python and peer_error is None:
            print(f"round {r + 1}/{args.rounds}: Crocoddyl ({peer_python})", flush=True)
            try:
                peer_rounds.append(run_peer(peer_python, args.ticks, args.repeats,
                                            args.max_iter))
            except (RuntimeError, subprocess.TimeoutExpired) as exc:
                peer_error = str(exc)
    ours = {str(n): summarise_ours(ours_rounds[n], n, trots[n]) for n in args.nodes}
    if peer_rounds and peer_error is None:
        peer = {"available": True, "python": peer_python, **summarise_peer(peer_rounds)}
    else:
        peer = {"available": False, "python": peer_python,
                "reason": peer_error or reason}
    results = {
        "code": git_state(),
        "machine": {"python": platform.python_version(), "numpy": np.__version__,
                    "cpu": platform.processor() or platform.machine(),
                    "loadavg_start": load0, "loadavg_end": os.getloadavg(),
                    "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS")},
        "settings": {"ticks": args.ticks, "repeats": args.repeats, "rounds": args.rounds,
                     "max_iter": args.max_iter, "nodes": args.nodes,
                     "codegen": not args.no_codegen, "ilqr_opt": dict(args.ilqr_opt)},
        "ours": ours,
        "peer": peer,
        "ratios": {n: ratios(o, peer if peer["available"] else None) for n, o in ours.items()},
    }
    return results, (1 if peer_error else 0)


def git_state() -> dict:
    """Commit of the checkout and the tracked files of ``horizon_mpc/`` that differ from it
    (figures are only comparable between runs of known code)."""
    def git(*cmd: str) -> str | None:
        try:
            proc = subprocess.run(["git", *cmd], cwd=ROOT, capture_output=True, text=True,
                                  timeout=30, check=False)
        except (OSError, subprocess.TimeoutExpired):
            return None
        return proc.stdout.strip() if proc.returncode == 0 else None
    status = git("status", "--porcelain", "--untracked-files=no", "--", "horizon_mpc")
    return {"commit": git("rev-parse", "HEAD"),
            "horizon_mpc_modified": None if status is None else status.splitlines()}


def report(results: dict) -> str:
    """Human-readable summary lines."""
    lines = []
    for n, o in results["ours"].items():
        c, t = o["converging"], o["ticks"]
        b = c["common_ms_per_iteration"]
        bt = t["common_ms_per_tick"]
        lines.append(
            f"ours N={n}: {c['ms_per_iteration']['median']:.1f} ms/iteration (min "
            f"{c['ms_per_iteration']['min']:.1f}, CPU {c['cpu_ms_per_iteration']['median']:.1f};"
            f" {c['iterations']} it, {c['status']}); "
            f"per iteration: linearise {b['linearise']:.1f}, backward {b['backward']:.1f}, "
            f"rollout+line search {b['forward_line_search']:.1f}, other {b['other']:.1f}")
        lines.append(
            f"ours N={n}: warm tick {t['tick_ms']['median']:.1f} ms median (min "
            f"{t['tick_ms']['min']:.1f}, CPU {t['tick_cpu_ms']['median']:.1f}, solve "
            f"{t['solve_ms']['median']:.1f}) over {t['n']}; "
            f"per tick: linearise {bt['linearise']:.1f}, backward {bt['backward']:.1f}, "
            f"rollout+line search {bt['forward_line_search']:.1f}, other {bt['other']:.1f}, "
            f"shift+references {bt['shift']:.1f}; violation median "
            f"{t['violation']['median']:.1e} max {t['violation']['max']:.1e}")
        if o["missing_timing_keys"]:
            lines.append(f"ours N={n}: solver.timings lacks {o['missing_timing_keys']}")
    p = results["peer"]
    if p["available"]:
        c, t = p["converging"], p["ticks"]
        lines.append(f"Crocoddyl {p['versions']['crocoddyl']} FDDP, {p['problem']['nodes']} "
                     f"nodes: {c['ms_per_iteration']['median']:.1f} ms/iteration (min "
                     f"{c['ms_per_iteration']['min']:.1f}, CPU "
                     f"{c['cpu_ms_per_iteration']['median']:.1f}; {c['iterations']} it); warm "
                     f"tick {t['tick_ms']['median']:.1f} ms median (min {t['tick_ms']['min']:.1f},"
                     f" CPU {t['tick_cpu_ms']['median']:.1f})")
        if "profile" in p:
            b, bt = p["profile"]["common_ms_per_iteration"], p["profile"]["common_ms_per_tick"]
            lines.append(
                f"Crocoddyl profile per iteration: calcDiff {b['linearise']:.1f}, backward "
                f"{b['backward']:.1f}, tryStep {b['forward_line_search']:.1f}, other "
                f"{b['other']:.1f}; per tick: calcDiff {bt['linearise']:.1f}, backward "
                f"{bt['backward']:.1f}, tryStep {bt['forward_line_search']:.1f}, shift "
                f"{bt['shift']:.1f}")
        for n, rr in results["ratios"].items():
            for clock, r in rr.items():
                lines.append(
                    f"ratio ours(N={n})/Crocoddyl, {clock:4s}: {r['per_iteration']:.2f} per "
                    f"iteration, {r['per_tick']:.2f} per warm tick (per node: "
                    f"{r['per_iteration_per_node']:.2f}, {r['per_tick_per_node']:.2f}; "
                    f"target <= 0.33)")
    else:
        lines.append(f"PEER NOT MEASURED: {p['reason']}")
        lines.append("ratios: null")
    return "\n".join(lines)


def _option(text: str) -> tuple[str, object]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command line (see the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ticks", type=positive_int, default=50, help="warm MPC ticks per round (50)")
    ap.add_argument("--repeats", type=positive_int, default=3,
                    help="converging solves per round (3)")
    ap.add_argument("--rounds", type=positive_int, default=3,
                    help="rounds, ours and the peer taking turns (3)")
    ap.add_argument("--nodes", type=positive_int, nargs="+", default=[40, 56],
                    help="horizon lengths N of ours (default: 40, the MPC config's, and 56, the "
                         "peer's node count); the first is the headline")
    ap.add_argument("--max-iter", type=positive_int, default=100, help="iteration limit of a solve")
    ap.add_argument("--v-forward", type=finite_float, default=V_FORWARD, help="trot velocity, m/s")
    ap.add_argument("--out", type=Path, default=RESULTS, help="output directory")
    ap.add_argument("--peer-python", default=None,
                    help=f"peer interpreter (default ${PEER_ENV}, else .venv-peer)")
    ap.add_argument("--ilqr-opt", type=_option, action="append", default=[],
                    metavar="KEY=VALUE", help="extra ILQR option (repeatable; VALUE in JSON, "
                    "else a string), e.g. --ilqr-opt line_search=false")
    ap.add_argument("--no-codegen", action="store_true",
                    help="CasADi VM instead of compiled node functions (tests only)")
    ap.add_argument("--no-plot", action="store_true", help="skip ilqr.png")
    args = ap.parse_args(argv)
    args.out = output_folder(ap, args.out)  # checked before the minutes of measuring
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, write ``ilqr.json`` (and ``ilqr.png``), print the summary."""
    args = parse_args(argv)
    results, code = run(args)
    args.out.mkdir(parents=True, exist_ok=True)
    out = args.out / "ilqr.json"
    out.write_text(json.dumps(jsonable(results), indent=1, allow_nan=False) + "\n")
    written = [out]
    if not args.no_plot:
        plot(results, args.out / "ilqr.png")
        written.append(args.out / "ilqr.png")
    sys.stdout.write(report(results) + "\nwritten " + ", ".join(map(str, written)) + "\n")
    return code


if __name__ == "__main__":
    sys.exit(main())
