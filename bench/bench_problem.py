"""Benchmark of the problem core: our IPOPT wrapper against hand-written CasADi, and gnsqp.

* Cart-pole swing-up, N = 100, RK4 multiple shooting (``horizon_mpc.examples.cartpole``):
  ``IpoptSolver.solve()`` (wall time of the whole call: numeric bounds/guesses/parameters
  built from the problem, the IPOPT call, stats and write-back) against the same NLP written
  directly with ``casadi.nlpsol`` (SX, a Python loop over nodes at build time, identical
  options, cost, constraints and initial guess). Overhead ratio target: <= 1.1.
* Build times (problem -> solver ready, including the IPOPT instance) of both.
* The SX and MX graphs of our transcription (``sym`` option).
* A warm re-solve after ``shift()`` (receding horizon) against the cold solve.
* ``gnsqp`` against ``ipopt``: time and iterations on the cart-pole (free, and with input
  bounds and a cart limit) and on the minimum-time pendulum; gnsqp's QP solvers.

Times are minima (and medians) over ``REPEATS`` interleaved repeats, single thread (times on
these machines vary 20-50% between runs: compare ratios within one run). Run:
``python bench/bench_problem.py``; writes ``bench/results/problem.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import casadi as cs
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # running from a source checkout without an install
    sys.path.insert(0, str(ROOT))

from horizon_mpc.examples import (  # noqa: E402
    build_cartpole,
    build_pendulum_min_time,
    cartpole_dynamics,
)
from horizon_mpc.problem.integrators import rk4  # noqa: E402
from horizon_mpc.solvers import make_solver  # noqa: E402

N = 100
DURATION = 2.0
REPEATS = 15
RESULTS = ROOT / "bench" / "results" / "problem.json"
IPOPT_OPTS = {"ipopt": {"tol": 1e-8, "constr_viol_tol": 1e-8, "max_iter": 3000,
                        "print_level": 0, "sb": "yes", "linear_solver": "mumps"},
              "print_time": False}


def plain_cartpole() -> tuple[cs.Function, dict]:
    """The cart-pole NLP written directly: w = [x_0, u_0, x_1, u_1, ..., x_N]."""
    dt = DURATION / N
    x, u = cs.SX.sym("x", 4), cs.SX.sym("u", 1)
    xdot = cs.vertcat(x[2:], cartpole_dynamics(x[:2], x[2:], u))
    f = cs.Function("f", [x, u], [xdot])
    F = cs.Function("F", [x, u], [rk4(lambda xx: f(xx, u), lambda a, b: a + b, x, dt)])
    w, lbw, ubw, w0, g, J = [], [], [], [], [], 0
    xk = cs.SX.sym("x0", 4)
    w += [xk]
    lbw += [0.0] * 4
    ubw += [0.0] * 4
    w0 += [0.0] * 4
    theta = np.linspace(0.0, np.pi, N + 1)
    for k in range(N):
        uk = cs.SX.sym(f"u{k}", 1)
        w += [uk]
        lbw += [-np.inf]
        ubw += [np.inf]
        w0 += [0.0]
        J += dt * uk**2 + 1e-2 * dt * cs.sumsqr(xk[2:])
        x_end = F(xk, uk)
        xk = cs.SX.sym(f"x{k + 1}", 4)
        w += [xk]
        lbw += [-np.inf] * 4
        ubw += [np.inf] * 4
        w0 += [0.0, theta[k + 1], 0.0, 0.0]
        g += [xk - x_end]
    J += 1e-2 * dt * cs.sumsqr(xk[2:])
    g += [xk - cs.DM([0.0, np.pi, 0.0, 0.0])]
    nlp = {"x": cs.vertcat(*w), "f": J, "g": cs.vertcat(*g)}
    solver = cs.nlpsol("plain", "ipopt", nlp, IPOPT_OPTS)
    ng = nlp["g"].numel()
    return solver, {"x0": w0, "lbx": lbw, "ubx": ubw, "lbg": [0.0] * ng, "ubg": [0.0] * ng}


def timed(fn: Callable[[], object]) -> float:
    """Wall time (s) of one call of ``fn``."""
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def summary(times: list[float]) -> dict[str, float]:
    """Minimum and median (ms) of wall times in s."""
    return {"min_ms": 1e3 * min(times), "median_ms": 1e3 * statistics.median(times)}


VARIANTS = {"SX": {"sym": "SX"}, "SX_active_rows": {"sym": "SX", "constraint_rows": "active"},
            "MX": {"sym": "MX"}}


def bench_overhead() -> dict:
    """Our wrapper vs plain nlpsol, cold solves from the same guess, interleaved."""
    t0 = time.perf_counter()
    plain, args = plain_cartpole()
    build_plain = time.perf_counter() - t0
    ours = {}
    for name, opts in VARIANTS.items():
        t0 = time.perf_counter()
        prb, v = build_cartpole(N, duration=DURATION)
        solver = make_solver("ipopt", prb, opts)
        solver._nlpsol(warm=False)  # build the IPOPT instance now, as nlpsol does
        build = time.perf_counter() - t0
        guess = {k: var.initial_guess for k, var in v.items()}
        ours[name] = (solver, v, guess, build)

    def ours_cold(name):
        solver, v, guess, _ = ours[name]
        for k, var in v.items():  # untimed: restore the cold guess
            var.set_initial_guess(guess[k])
        solver.reset()
        return timed(solver.solve)

    times = {"plain": [], **{name: [] for name in VARIANTS}}
    res_plain = None
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        res_plain = plain(**args)
        times["plain"].append(time.perf_counter() - t0)
        for name in VARIANTS:
            times[name].append(ours_cold(name))
    out = {
        "plain": {**summary(times["plain"]), "iterations": plain.stats()["iter_count"],
                  "cost": float(res_plain["f"]), "build_s": build_plain,
                  "n_constraints": int(args["lbg"].__len__())},
    }
    for name in VARIANTS:
        s = ours[name][0]
        assert abs(s.stats.cost - float(res_plain["f"])) < 1e-6 * abs(s.stats.cost)
        out[f"ours_{name}"] = {**summary(times[name]), "iterations": s.stats.iterations,
                               "cost": s.stats.cost, "build_s": ours[name][3],
                               "n_constraints": s.transcription.ng}
        out[f"ratio_{name}_min"] = out[f"ours_{name}"]["min_ms"] / out["plain"]["min_ms"]
        out[f"ratio_{name}_median"] = (out[f"ours_{name}"]["median_ms"]
                                       / out["plain"]["median_ms"])
    return out


def bench_warm() -> dict:
    """Cold solve, then shift + warm re-solve (initial state pinned to the shifted guess)."""
    prb, v = build_cartpole(N, duration=DURATION)
    solver = make_solver("ipopt", prb)
    solver._nlpsol(warm=False)  # not timed: building the (cold) IPOPT instance
    cold = timed(solver.solve)
    cold_it = solver.stats.iterations
    warm, warm_it = [], []
    for _ in range(5):
        solver.shift()
        for name in ("q", "v"):
            x0 = v[name].initial_guess[:, 0]
            v[name].set_bounds(x0, x0, nodes=0)
        warm.append(timed(solver.solve))
        warm_it.append(solver.stats.iterations)
    return {"cold_ms": 1e3 * cold, "cold_iterations": cold_it,
            "warm_ms_median": 1e3 * statistics.median(warm), "warm_iterations": warm_it}


def bench_gnsqp() -> dict:
    """gnsqp vs ipopt on the reference problems (fresh problems, same initial guesses)."""
    cases = {
        "cartpole": lambda: build_cartpole(N, duration=DURATION),
        "cartpole_bounded": lambda: build_cartpole(N, duration=DURATION, u_max=12.0,
                                                   cart_limit=0.5),
        "pendulum_min_time": lambda: build_pendulum_min_time(50),
    }
    out = {}
    for name, build in cases.items():
        row = {}
        for solver_name, opts in (("ipopt", {}), ("gnsqp", {"max_iter": 500})):
            prb, v = build()
            s = make_solver(solver_name, prb, opts)
            guess = {k: var.initial_guess for k, var in v.items()}
            times = []
            for _ in range(4):  # the first solve builds the IPOPT / QP instances: dropped
                for k, var in v.items():
                    var.set_initial_guess(guess[k])
                s.reset()
                times.append(timed(s.solve))
            times = times[1:]
            row[solver_name] = {"ms": 1e3 * min(times), "iterations": s.stats.iterations,
                                "cost": s.stats.cost, "success": s.stats.success,
                                "violation": s.stats.constraint_violation}
            if solver_name == "gnsqp":
                row[solver_name].update({k: 1e3 * v for k, v in s.stats.extra.items()
                                         if k.startswith("t_")})
        row["time_ratio_gnsqp_over_ipopt"] = row["gnsqp"]["ms"] / row["ipopt"]["ms"]
        row["cost_rel_diff"] = abs(row["gnsqp"]["cost"] / row["ipopt"]["cost"] - 1)
        out[name] = row
    qp = {}
    for qp_solver in ("qrqp", "proxqp", "osqp"):
        prb, _ = build_cartpole(N, duration=DURATION)
        s = make_solver("gnsqp", prb, {"max_iter": 500, "qp_solver": qp_solver})
        s._qp_solver()  # build the QP instance first
        t = timed(s.solve)
        qp[qp_solver] = {"ms": 1e3 * t, "iterations": s.stats.iterations,
                         "success": s.stats.success, "qp_ms": 1e3 * s.stats.extra["t_qp"]}
    out["cartpole_qp_solvers"] = qp
    return out


def main() -> None:
    """Run the problem benchmarks and write their JSON."""
    results = {
        "machine": {"python": platform.python_version(), "casadi": cs.__version__,
                    "cpu": platform.processor() or platform.machine()},
        "problem": f"cart-pole swing-up, N={N}, {DURATION} s, RK4 multiple shooting",
        "overhead": bench_overhead(),
        "receding": bench_warm(),
        "gnsqp": bench_gnsqp(),
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    o, r, g = results["overhead"], results["receding"], results["gnsqp"]
    lines = [f"plain nlpsol: {o['plain']['min_ms']:.1f} ms (min), {o['plain']['iterations']} it, "
             f"{o['plain']['n_constraints']} constraints, build {o['plain']['build_s']:.2f} s"]
    for name in VARIANTS:
        row = o[f"ours_{name}"]
        lines.append(f"ipopt wrapper ({name}): {row['min_ms']:.1f} ms, ratio "
                     f"{o[f'ratio_{name}_min']:.2f} (median {o[f'ratio_{name}_median']:.2f}), "
                     f"{row['iterations']} it, {row['n_constraints']} constraints, build "
                     f"{row['build_s']:.2f} s")
    lines.append(f"receding: cold {r['cold_iterations']} it {r['cold_ms']:.1f} ms, warm "
                 f"{r['warm_iterations']} it, {r['warm_ms_median']:.1f} ms median")
    for name in ("cartpole", "cartpole_bounded", "pendulum_min_time"):
        row = g[name]
        lines.append(f"{name}: gnsqp {row['gnsqp']['ms']:.0f} ms / {row['gnsqp']['iterations']}"
                     f" it vs ipopt {row['ipopt']['ms']:.0f} ms / {row['ipopt']['iterations']} it"
                     f" (time ratio {row['time_ratio_gnsqp_over_ipopt']:.1f}, cost rel diff "
                     f"{row['cost_rel_diff']:.1e})")
    for qp_solver, row in g["cartpole_qp_solvers"].items():
        lines.append(f"gnsqp qp_solver={qp_solver}: {row['ms']:.0f} ms, {row['iterations']} it,"
                     f" QP {row['qp_ms']:.0f} ms, success {row['success']}")
    sys.stdout.write("\n".join(lines) + f"\nwritten {RESULTS.relative_to(ROOT)}\n")


if __name__ == "__main__":
    # no options: --help shows this docstring, anything else is refused (it ran the
    # benchmark and overwrote its results)
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
