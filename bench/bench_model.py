"""Benchmark of the symbolic robot model against numeric Pinocchio.

Per node, for go2 and solo12 with four foot contacts:

* compiled inverse dynamics ``(q, v, a, f) -> tau`` vs ``pinocchio.rnea``;
* compiled inverse dynamics + its full Jacobian (w.r.t. the q tangent, v, a, f) vs
  ``pinocchio.computeRNEADerivatives`` (which gives dtau/dq, dtau/dv and M = dtau/da).

Pinocchio is timed with the contact forces as ``fext`` and without them (no list
conversion in the binding); ratios use the faster of the two.
* cold compile time (empty cache) and warm load time (library already on disk).

Compiled functions are timed twice: called on DM inputs (outputs are new DMs) and through
``codegen.BufferedFunction`` (numpy arrays bound once: the evaluation alone).

CasADi is timed per node inside one call over a batch of ``N_BATCH`` states (``map``), since
each Python -> CasADi call costs tens of microseconds; Pinocchio is timed per Python call.
Times are the minimum over interleaved repeats (single thread; see doc/benchmarks.md).

Run: ``python bench/bench_model.py``; writes ``bench/results/model.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import platform
import sys
import tempfile
import time
from pathlib import Path

import casadi as cs
import numpy as np
import pinocchio as pin

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # running from a source checkout without an install
    sys.path.insert(0, str(ROOT))

from horizon_mpc import codegen  # noqa: E402
from horizon_mpc.model import RobotModel  # noqa: E402

ROBOTS = {
    "go2": ["FL_foot", "FR_foot", "RL_foot", "RR_foot"],
    "solo12": ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"],
}
N_BATCH = 50
REPEATS = 15
RESULTS = ROOT / "bench" / "results" / "model.json"

_log = logging.getLogger("bench_model")


def _mean_time(func, inner: int) -> float:
    """Mean time of ``inner`` calls (s), after one warm-up call."""
    func()
    start = time.perf_counter()
    for _ in range(inner):
        func()
    return (time.perf_counter() - start) / inner


def _states(m: RobotModel, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    pm = m.pin_model
    lower = np.where(np.isfinite(m.q_lower), m.q_lower, -1.0)
    upper = np.where(np.isfinite(m.q_upper), m.q_upper, 1.0)
    q = np.column_stack([pin.randomConfiguration(pm, lower, upper) for _ in range(n)])
    return {
        "q": q,
        "v": rng.normal(size=(m.nv, n)),
        "a": rng.normal(size=(m.nv, n)),
        "f": 50.0 * rng.normal(size=(12, n)),
    }


def _compile_timed(fn: cs.Function, cache_dir: Path) -> tuple[cs.Function, float, float, int]:
    """(compiled fn, cold compile s, warm load s, C size in bytes)."""
    gen = cs.CodeGenerator("probe.c", {"with_header": False})
    gen.add(fn)
    c_size = len(gen.dump())
    start = time.perf_counter()
    codegen.compile_function(fn, cache_dir=cache_dir)
    cold = time.perf_counter() - start
    codegen.forget_loaded()
    start = time.perf_counter()
    fast = codegen.compile_function(fn, cache_dir=cache_dir)
    warm = time.perf_counter() - start
    return fast, cold, warm, c_size


def bench_robot(name: str, contacts: list[str], cache_dir: Path) -> dict:
    """Build, compile and time one robot's model functions against numeric Pinocchio."""
    start = time.perf_counter()
    m = RobotModel.from_example(name)
    id_fn = m.inverse_dynamics(contacts)
    idd_fn = m.inverse_dynamics_derivatives(contacts)
    build = time.perf_counter() - start
    s = _states(m, N_BATCH)
    # Inputs converted to DM once: numpy -> DM conversion in CasADi 3.8 costs ~50 ns per
    # element, as much as the evaluation itself; a solver keeps its data in DM (or buffers).
    args = tuple(cs.DM(s[k]) for k in ("q", "v", "a", "f"))
    np_args = tuple(s[k] for k in ("q", "v", "a", "f"))
    out: dict = {
        "nq": m.nq,
        "nv": m.nv,
        "symbolic_build_s": build,
        "instructions": {"id": id_fn.n_instructions(), "id_jac": idd_fn.n_instructions()},
    }
    per_node = {}
    timed = {}
    for key, fn in (("id", id_fn), ("id_jac", idd_fn)):
        mapped = fn.map(N_BATCH, "serial")
        fast, cold, warm, c_size = _compile_timed(mapped, cache_dir)
        timed[f"{key}_compiled"] = (lambda f=fast: f(*args), 20, N_BATCH)
        buffered = codegen.BufferedFunction(fast)
        timed[f"{key}_compiled_buffer"] = (lambda f=buffered: f(*np_args), 20, N_BATCH)
        timed[f"{key}_vm"] = (lambda f=mapped: f(*args), 2, N_BATCH)
        out[f"{key}_compile"] = {"cold_s": cold, "warm_load_s": warm, "c_kB": c_size / 1000}
    pm = m.pin_model
    data = pm.createData()
    cols = [tuple(x[:, i] for x in (s["q"], s["v"], s["a"])) for i in range(N_BATCH)]
    fexts = []
    for i in range(N_BATCH):
        pin.framesForwardKinematics(pm, data, cols[i][0])
        fext = [pin.Force.Zero() for _ in range(pm.njoints)]
        for k, c in enumerate(contacts):
            frame = pm.frames[m.frame_id(c)]
            lin = data.oMi[frame.parentJoint].rotation.T @ s["f"][3 * k : 3 * k + 3, i]
            fext[frame.parentJoint] += pin.Force(lin, np.cross(frame.placement.translation, lin))
        fexts.append(fext)

    def pin_rnea() -> None:
        for (q, v, a), fext in zip(cols, fexts, strict=True):
            pin.rnea(pm, data, q, v, a, fext)

    def pin_derivatives() -> None:
        for (q, v, a), fext in zip(cols, fexts, strict=True):
            pin.computeRNEADerivatives(pm, data, q, v, a, fext)

    def pin_rnea_no_contacts() -> None:
        for q, v, a in cols:
            pin.rnea(pm, data, q, v, a)

    def pin_derivatives_no_contacts() -> None:
        for q, v, a in cols:
            pin.computeRNEADerivatives(pm, data, q, v, a)

    timed["pin_rnea"] = (pin_rnea, 10, N_BATCH)
    timed["pin_rnea_derivatives"] = (pin_derivatives, 10, N_BATCH)
    # Without fext: no Python list -> std::vector<Force> conversion; the stricter reference.
    timed["pin_rnea_no_contacts"] = (pin_rnea_no_contacts, 10, N_BATCH)
    timed["pin_rnea_derivatives_no_contacts"] = (pin_derivatives_no_contacts, 10, N_BATCH)
    # Interleaved repeats: a load spike from another process hits every candidate alike.
    best = dict.fromkeys(timed, np.inf)
    for _ in range(REPEATS):
        for key, (func, inner, per) in timed.items():
            best[key] = min(best[key], _mean_time(func, inner) / per)
    per_node.update(best)
    out["per_node_us"] = {k: v * 1e6 for k, v in per_node.items()}
    ref_id = min(per_node["pin_rnea"], per_node["pin_rnea_no_contacts"])
    ref_jac = min(per_node["pin_rnea_derivatives"], per_node["pin_rnea_derivatives_no_contacts"])
    # Ratios against the faster Pinocchio variant (usually the one without contacts), named
    # "..._best" (the labels named the variant with contacts while dividing by the other)
    out["ratios"] = {
        "id_compiled / pin_rnea_best": per_node["id_compiled"] / ref_id,
        "id_jac_compiled / pin_rnea_derivatives_best": per_node["id_jac_compiled"] / ref_jac,
        "id_jac_compiled_buffer / pin_rnea_derivatives_best": (
            per_node["id_jac_compiled_buffer"] / ref_jac
        ),
    }
    return out


def main() -> None:
    """Run every robot of the benchmark and write its JSON."""
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    results = {
        "machine": {
            "python": platform.python_version(),
            "casadi": cs.__version__,
            "pinocchio": pin.__version__,
            "cpu": platform.processor() or platform.machine(),
        },
        "batch": N_BATCH,
        "robots": {},
    }
    with tempfile.TemporaryDirectory(prefix="bench_model_cache_") as tmp:
        for name, contacts in ROBOTS.items():
            _log.info("== %s", name)
            results["robots"][name] = bench_robot(name, contacts, Path(tmp))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n")
    print(f"{'robot':8} {'quantity':40} {'us/node':>9}")
    for name, r in results["robots"].items():
        for key, val in r["per_node_us"].items():
            print(f"{name:8} {key:40} {val:9.2f}")
        for key, val in r["ratios"].items():
            print(f"{name:8} ratio {key:34} {val:9.2f}")
        for key in ("id_compile", "id_jac_compile"):
            c = r[key]
            print(
                f"{name:8} {key:40} cold {c['cold_s']:.1f} s, warm {c['warm_load_s'] * 1e3:.1f}"
                f" ms, {c['c_kB']:.0f} kB of C"
            )
    print(f"wrote {RESULTS.relative_to(ROOT)}")


if __name__ == "__main__":
    # no options: --help shows this docstring, anything else is refused (it ran the
    # benchmark and overwrote its results)
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
