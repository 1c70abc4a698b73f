"""The comparison peer of ``bench/bench_ilqr.py``: Crocoddyl's FDDP on its own go2 trot.

Runs with the peer interpreter (``.venv-peer``: crocoddyl 3.2.1, pin 4.0.0; see
``make peer-venv``), never with ``.venv`` (crocoddyl crashes with pin 4.1). It imports
nothing from ``horizon_mpc``; ``bench_ilqr.py`` starts it in a subprocess and reads the one
JSON document it prints on stdout.

Problem: ``crocoddyl.utils.quadruped.SimpleQuadrupedalGaitProblem`` for go2
(example-robot-data, feet ``FL_foot FR_foot RL_foot RR_foot``), ``createTrottingProblem``
with Crocoddyl's example settings (step length 0.15 m, height 0.1 m, dt 0.01 s, 25 step
knots, 2 support knots: 56 running nodes), forward dynamics, ``problem.nthreads = 1``.

Measured, single thread:

* converging solves: ``SolverFDDP.solve(xs, us, max_iter)`` from the standing state and the
  quasi-static inputs (Crocoddyl's example initialisation); time per iteration = time of
  ``solve`` / ``solver.iter`` (wall, and CPU time of the process);
* warm MPC ticks of a perfect-model receding horizon: the horizon advances by one node
  (``problem.circularAppend`` of the next node of the following trot cycle, built from the
  end of the solved cycle so that its footholds continue the walk), node 0 becomes the
  previous solution's node 1, and one FDDP iteration runs from the shifted solution;
* with ``--pace S``, the same warm ticks again with S seconds of sleep before each
  (``paced_ticks``): a real-time loop at 1/S Hz idles between its ticks, and the tick after
  an idle period runs slower than one right after the last (cold caches);
* Crocoddyl's own profiler (``crocoddyl.enable_profiler``) in separate runs (it adds its
  own overhead): calcDiff / backwardPass / tryStep (nonlinear rollout + line search).

Run: ``.venv-peer/bin/python bench/peer_crocoddyl.py [--ticks N] [--repeats R] [--pace S]``.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):  # before numpy: single thread
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import crocoddyl  # noqa: E402
import example_robot_data  # noqa: E402
import numpy as np  # noqa: E402
import pinocchio  # noqa: E402
from crocoddyl.utils.quadruped import SimpleQuadrupedalGaitProblem  # noqa: E402

ROBOT = "go2"
FEET = ("FL_foot", "FR_foot", "RL_foot", "RR_foot")
TROT = {"stepLength": 0.15, "stepHeight": 0.1, "timeStep": 1e-2, "stepKnots": 25,
        "supportKnots": 2}
# Crocoddyl's profiler names -> our phase names (see bench_ilqr.COMMON_PHASES)
PROFILE = {"linearise": "SolverDDP::calcDiff", "backward": "SolverDDP::backwardPass",
           "forward_line_search": "SolverDDP::tryStep"}
PROFILE_TOTAL = "SolverFDDP::solve"


def build(step_knots: int = TROT["stepKnots"]) -> tuple:
    """The trotting problem, its FDDP solver and the cold initial guess.

    Returns ``(gait, problem, solver, xs0, us0)``; ``gait`` is the
    ``SimpleQuadrupedalGaitProblem`` (it remembers that the first step was made).
    """
    robot = example_robot_data.load(ROBOT)
    q0 = robot.model.referenceConfigurations["standing"].copy()
    x0 = np.concatenate([q0, np.zeros(robot.model.nv)])
    gait = SimpleQuadrupedalGaitProblem(robot.model, *FEET)
    problem = _trot(gait, x0, step_knots)
    solver = crocoddyl.SolverFDDP(problem)
    xs0 = [x0] * (problem.T + 1)
    us0 = problem.quasiStatic([x0] * problem.T)
    return gait, problem, solver, xs0, us0


def _trot(gait, x0: np.ndarray, step_knots: int):
    t = dict(TROT, stepKnots=step_knots)
    problem = gait.createTrottingProblem(x0, t["stepLength"], t["stepHeight"], t["timeStep"],
                                         t["stepKnots"], t["supportKnots"])
    problem.nthreads = 1  # Crocoddyl's default is 2
    return problem


def measure_converging(solver: crocoddyl.SolverFDDP, xs0: list, us0: list, repeats: int,
                       max_iter: int) -> dict:
    """Cold converging solves: wall time, iterations, time per iteration (ms)."""
    solves = []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        converged = solver.solve(xs0, us0, max_iter, False)
        ms, cpu = 1e3 * (time.perf_counter() - t0), 1e3 * (time.process_time() - c0)
        iters = max(int(solver.iter), 1)
        solves.append({"ms": ms, "cpu_ms": cpu, "iterations": int(solver.iter),
                       "ms_per_iteration": ms / iters, "cpu_ms_per_iteration": cpu / iters,
                       "cost": float(solver.cost), "converged": bool(converged)})
    return {"solves": solves}


def _future_models(gait, solver, xs0, us0, n: int, step_knots: int, max_iter: int):
    """The running models (with data) of the trot cycles that follow the solved one.

    Each cycle is built from the end state of the previous cycle solved to convergence, so
    its footholds continue the walk; untimed set-up of the receding horizon.
    """
    models = []
    xs, us = xs0, us0
    sol = solver
    while len(models) < n:
        sol.solve(xs, us, max_iter, False)
        x_end = np.array(sol.xs[-1])
        nxt = _trot(gait, x_end, step_knots)
        models += [(m, m.createData()) for m in nxt.runningModels]
        sol = crocoddyl.SolverFDDP(nxt)
        xs = [x_end] * (nxt.T + 1)
        us = nxt.quasiStatic([x_end] * nxt.T)
    return models[:n]


def measure_ticks(gait: object, solver: crocoddyl.SolverFDDP, xs0: list, us0: list, ticks: int,
                  step_knots: int,
                  max_iter: int, profile: bool = False, pace: float = 0.0) -> dict:
    """Warm MPC ticks: shift the horizon by one node, then one FDDP iteration (ms).

    The receding horizon starts from the converged cycle (re-solved here, untimed).
    ``profile``: run under Crocoddyl's profiler and return its per-tick phase times instead.
    ``pace``: seconds of sleep before each tick, as a real-time loop idles between its
    ticks (0: back to back). On this machine a tick after 20 ms of idling takes ~1.5x the
    back-to-back one, whatever the solver (doc/benchmarks.md, Session 16).
    """
    future = _future_models(gait, solver, xs0, us0, ticks, step_knots, max_iter)
    # the horizon's own problem object is modified by circularAppend: work on a copy
    horizon = _trot(SimpleQuadrupedalGaitProblem(gait.rmodel, *FEET), xs0[0], step_knots)
    mpc = crocoddyl.SolverFDDP(horizon)
    mpc.solve(xs0, us0, max_iter, False)
    if profile:
        crocoddyl.stop_watch_reset_all()
        crocoddyl.enable_profiler()
    tick_ms, solve_ms, tick_cpu_ms, steps = [], [], [], []
    for model, data in future:
        if pace > 0:
            time.sleep(pace)
        t0, c0 = time.perf_counter(), time.process_time()
        xs = list(mpc.xs[1:]) + [mpc.xs[-1]]
        us = list(mpc.us[1:])
        # the appended node may be an impulse (nu = 0): repeat the last input only if it fits
        us.append(us[-1] if model.nu == us[-1].size else np.zeros(model.nu))
        horizon.circularAppend(model, data)
        horizon.x0 = xs[0]  # perfect model: the measured state is the planned node 1
        t1 = time.perf_counter()
        mpc.solve(xs, us, 1, False)
        t2, c2 = time.perf_counter(), time.process_time()
        tick_ms.append(1e3 * (t2 - t0))
        solve_ms.append(1e3 * (t2 - t1))
        tick_cpu_ms.append(1e3 * (c2 - c0))
        steps.append(float(mpc.stepLength))
    out = {"tick_ms": tick_ms, "solve_ms": solve_ms, "tick_cpu_ms": tick_cpu_ms,
           "pace_s": pace,
           "step_length": steps,
           "final_cost": float(mpc.cost)}
    if profile:
        crocoddyl.disable_profiler()
        out = {"per_tick_ms": _profile_per(len(future)), "ticks": len(future)}
    return out


def profile_converging(solver: crocoddyl.SolverFDDP, xs0: list, us0: list, max_iter: int
                       ) -> dict:
    """One converging solve under Crocoddyl's profiler: phase times per iteration (ms)."""
    crocoddyl.stop_watch_reset_all()
    crocoddyl.enable_profiler()
    solver.solve(xs0, us0, max_iter, False)
    crocoddyl.disable_profiler()
    iters = max(int(solver.iter), 1)
    return {"per_iteration_ms": _profile_per(iters), "iterations": int(solver.iter),
            "calcDiff_calls": _calls(PROFILE["linearise"])}


def _calls(name: str) -> int:
    """Number of timed calls of a profiler section (0 when absent)."""
    try:
        total, avg = crocoddyl.stop_watch_get_total_time(name), \
            crocoddyl.stop_watch_get_average_time(name)
    except Exception:  # noqa: BLE001 - a profiler section that never ran
        return 0
    return int(round(total / avg)) if avg > 0 else 0


def _profile_per(n: int) -> dict:
    """Profiler totals divided by ``n``, ms; ``other`` = solve total minus the phases."""
    def total_ms(name: str) -> float:
        try:
            return 1e3 * float(crocoddyl.stop_watch_get_total_time(name))  # seconds
        except Exception:  # noqa: BLE001 - a profiler section that never ran
            return 0.0
    phases = {key: total_ms(name) / n for key, name in PROFILE.items()}
    total = total_ms(PROFILE_TOTAL) / n
    phases["other"] = max(total - sum(phases.values()), 0.0)
    phases["total"] = total
    return phases


def main(argv: list[str] | None = None) -> dict:
    """Measure and print one JSON document on stdout; returns it."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ticks", type=int, default=50, help="warm MPC ticks (default 50)")
    ap.add_argument("--repeats", type=int, default=3, help="converging solves (default 3)")
    ap.add_argument("--max-iter", type=int, default=100, help="FDDP iteration limit")
    ap.add_argument("--step-knots", type=int, default=TROT["stepKnots"],
                    help="knots per step (default 25: 56 nodes)")
    ap.add_argument("--no-profile", action="store_true", help="skip the profiled runs")
    ap.add_argument("--pace", type=float, default=0.0,
                    help="also measure warm ticks with this many seconds of sleep before "
                         "each (a real-time loop's idling; e.g. 0.02 for 50 Hz)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    gait, problem, solver, xs0, us0 = build(args.step_knots)
    build_s = time.perf_counter() - t0
    conv = measure_converging(solver, xs0, us0, args.repeats, args.max_iter)
    ticks = measure_ticks(gait, solver, xs0, us0, args.ticks, args.step_knots, args.max_iter)
    out = {
        "versions": {"crocoddyl": crocoddyl.__version__, "pinocchio": pinocchio.__version__,
                     "numpy": np.__version__, "python": platform.python_version()},
        "problem": {"robot": ROBOT, "builder": "SimpleQuadrupedalGaitProblem."
                    "createTrottingProblem", **dict(TROT, stepKnots=args.step_knots),
                    "nodes": int(problem.T), "nx": int(problem.nx), "ndx": int(problem.ndx),
                    "nu": int(problem.runningModels[0].nu), "nthreads": int(problem.nthreads),
                    "solver": "SolverFDDP", "build_s": build_s},
        "converging": conv,
        "ticks": ticks,
    }
    if args.pace > 0:
        out["paced_ticks"] = measure_ticks(gait, solver, xs0, us0, args.ticks, args.step_knots,
                                           args.max_iter, pace=args.pace)
    if not args.no_profile:
        out["profile"] = {
            "converging": profile_converging(solver, xs0, us0, args.max_iter),
            "tick": measure_ticks(gait, solver, xs0, us0, args.ticks, args.step_knots,
                                  args.max_iter, profile=True),
        }
    json.dump(out, sys.stdout, allow_nan=True)
    sys.stdout.write("\n")
    return out


if __name__ == "__main__":
    main()
