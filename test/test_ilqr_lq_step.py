"""The compiled LQ step (lq_step.c: projection, backward pass, rollout and step measures on
arrays bound once) returns what riccati_c's wrappers return for the same data, keeps its
last good backward pass through a failed one, and refuses data it was not bound to."""

from __future__ import annotations

import numpy as np
import pytest
from ocps import trotting_go2_mpc

from horizon_mpc.solvers.ilqr import riccati_c
from horizon_mpc.solvers.ilqr.equality import EqualityLayout, project
from horizon_mpc.solvers.ilqr.lq_step import CompiledLqStep

pytestmark = pytest.mark.skipif(not riccati_c.available(),
                                reason="needs the compiled Riccati library")

N, NDX, NU, NC, NCN = 9, 6, 5, 5, 2


def _column_major(rng, shape):
    """A (N, rows, cols) array laid out as the solver's quadratisation views are: each
    node's block column-major."""
    n, r, c = shape
    return np.ascontiguousarray(rng.standard_normal((n, c, r))).transpose(0, 2, 1)


def _data(seed: int, dependent_node: int | None = None):
    """A random quadratisation (strided blocks, sparse [A | B]), an evaluation and a layout
    of projected rows: columns 0-2 input rows at their own node, 3-4 state rows of the next
    node, both terminal rows at node N-1. ``dependent_node``: its two own rows made equal
    (the QR refuses them, the SVD takes the node)."""
    rng = np.random.default_rng(seed)
    mask = rng.random((NDX, NDX + NU)) < 0.4
    mask[:, :NDX] |= np.eye(NDX, dtype=bool)
    A = _column_major(rng, (N, NDX, NDX)) * mask[:, :NDX] + np.eye(NDX)
    B = _column_major(rng, (N, NDX, NU)) * mask[:, NDX:]
    M = rng.standard_normal((N, NDX + NU, NDX + NU))
    H = M @ M.transpose(0, 2, 1) + 0.1 * np.eye(NDX + NU)
    lxx = np.ascontiguousarray(H[:, :NDX, :NDX]).transpose(0, 2, 1)  # symmetric
    q = {"A": A, "B": B, "lx": rng.standard_normal((N, NDX)),
         "lu": rng.standard_normal((N, NU)), "lxx": lxx,
         "luu": np.ascontiguousarray(H[:, NDX:, NDX:]),
         "lux": np.ascontiguousarray(H[:, NDX:, :NDX]),
         "lxN": rng.standard_normal(NDX), "lxxN": np.eye(NDX) * 2.0,
         "cx": _column_major(rng, (N, NC, NDX)), "cu": _column_major(rng, (N, NC, NU)),
         "cxN": rng.standard_normal((NCN, NDX))}
    q["cu"][:, 3:] = 0.0  # state rows
    own = np.zeros((N, NC), bool)
    own[:, :3] = rng.random((N, 3)) < 0.7
    nxt = np.zeros((N, NC), bool)
    nxt[:-1, 3:] = rng.random((N - 1, 2)) < 0.6
    own[4] = nxt[4] = False  # a node without rows
    if dependent_node is not None:
        own[dependent_node, :2] = True
        q["cu"][dependent_node, 1] = q["cu"][dependent_node, 0]
        q["cx"][dependent_node, 1] = q["cx"][dependent_node, 0]
    layout = EqualityLayout(own, nxt, np.ones(NCN, bool), rng.standard_normal((N, NC)),
                            rng.standard_normal(NCN))
    ev = {"c": rng.standard_normal((N, NC + 3)),  # constraint rows, then other AL rows
          "cN": rng.standard_normal((1, NCN + 1)), "gap": 0.1 * rng.standard_normal((N, NDX))}
    pattern = riccati_c.AbPattern.from_mask(mask | np.hstack([np.eye(NDX, dtype=bool),
                                                              np.zeros((NDX, NU), bool)]))
    return q, ev, layout, pattern


def _wrappers(q, ev, layout, pattern, mu, dx0):
    """The solver's path through riccati_c's wrappers: projection, backward, rollout, stats."""
    proj = project(layout, ev["c"][:, :NC], q["cx"], q["cu"], ev["cN"][0, :NCN], q["cxN"],
                   q["A"], q["B"], ev["gap"], pattern=pattern)
    bw = riccati_c.backward_pass_c(q["A"], q["B"], q["lx"], q["lu"], q["lxx"], q["luu"],
                                   q["lux"], ev["gap"], q["lxN"], q["lxxN"], mu, proj,
                                   pattern=pattern)
    dX, dU = riccati_c.linear_rollout_c(q["A"], q["B"], ev["gap"], bw, dx0)
    stats = riccati_c.step_stats_c(q["lx"], q["lu"], q["lxN"], bw.s, bw.S, bw.Qu, bw.Quu,
                                   bw.Qux, dX, dU, proj.pinv)
    return proj, bw, dX, dU, stats


def _close(a, b, name):
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("dependent_node", [None, 2])
@pytest.mark.parametrize("sparse", [False, True])
def test_the_compiled_lq_step_matches_the_wrappers(dependent_node, sparse):
    q, ev, layout, pattern = _data(seed=3, dependent_node=dependent_node)
    pattern = pattern if sparse else None
    dx0 = np.random.default_rng(9).standard_normal(NDX)
    ref_proj, ref_bw, ref_dX, ref_dU, ref_stats = _wrappers(q, ev, layout, pattern, 1e-6, dx0)
    lq = CompiledLqStep(q, {"N": N, "ndx": NDX, "nu": NU, "nc": NC, "ncN": NCN,
                            "ldc": NC + 3}, pattern)
    proj = lq.project(layout, ev["c"], ev["cN"][0], ev["gap"])
    for name in ("P_e", "P_x", "Z", "free", "pinv", "rows", "constrained"):
        _close(getattr(proj, name), getattr(ref_proj, name), name)
    assert proj.rank_deficient == ref_proj.rank_deficient
    assert proj.constrained.sum() < N  # node 4 has no row
    bw = lq.backward(ev["gap"], 1e-6, proj)
    assert bw is not None
    for name in ("K", "k", "S", "s", "Qu", "Quu", "Qux"):
        _close(getattr(bw, name), getattr(ref_bw, name), name)
    dX, dU, stats = lq.rollout(ev["gap"], bw, dx0, proj)
    _close(dX, ref_dX, "dX")
    _close(dU, ref_dU, "dU")
    _close(np.array(stats), np.array(ref_stats), "stats")
    # two equal rows with different targets: the SVD's least squares at that node
    assert proj.rank_deficient == (0 if dependent_node is None else 1)


def test_a_failed_backward_pass_keeps_the_gains_of_the_steps_taken():
    q, ev, layout, pattern = _data(seed=5)
    lq = CompiledLqStep(q, {"N": N, "ndx": NDX, "nu": NU, "nc": NC, "ncN": NCN,
                            "ldc": NC + 3}, pattern)
    proj = lq.project(layout, ev["c"], ev["cN"][0], ev["gap"])
    taken = lq.backward(ev["gap"], 1e-6, proj)
    lq.rollout(ev["gap"], taken, np.zeros(NDX), proj)
    K_taken = taken.K.copy()
    good = lq.backward(ev["gap"], 1e-3, proj)  # a later pass, not rolled out
    K_good = good.K.copy()
    q["luu"][4] = -1e6 * np.eye(NU)  # indefinite at node 4, which has no row (read in place)
    assert lq.backward(ev["gap"], 1e-6, proj) is None
    np.testing.assert_array_equal(taken.K, K_taken)  # the failed pass wrote a third array
    np.testing.assert_array_equal(good.K, K_good)
    with pytest.raises(ValueError, match="successful"):  # its k, S, ... were overwritten
        lq.rollout(ev["gap"], good, np.zeros(NDX), proj)
    q["luu"][4] = np.eye(NU)
    again = lq.backward(ev["gap"], 1e-6, proj)
    dX, dU, _ = lq.rollout(ev["gap"], again, np.zeros(NDX), proj)
    assert np.all(np.isfinite(dX)) and np.all(np.isfinite(dU))


def test_the_compiled_lq_step_refuses_what_it_was_not_bound_to():
    q, ev, layout, pattern = _data(seed=7)
    sizes = {"N": N, "ndx": NDX, "nu": NU, "nc": NC, "ncN": NCN, "ldc": NC + 3}
    lq = CompiledLqStep(q, sizes, pattern)
    proj = lq.project(layout, ev["c"], ev["cN"][0], ev["gap"])
    other = project(layout, ev["c"][:, :NC], q["cx"], q["cu"], ev["cN"][0, :NCN], q["cxN"],
                    q["A"], q["B"], ev["gap"])
    with pytest.raises(ValueError, match="last projection"):
        lq.backward(ev["gap"], 1e-6, other)
    with pytest.raises(ValueError, match="gap"):
        lq.backward(ev["gap"][:-1], 1e-6, proj)
    with pytest.raises(ValueError, match="c:"):
        lq.project(layout, ev["c"][:, :NC], ev["cN"][0], ev["gap"])  # not (N, ldc)
    bw = lq.backward(ev["gap"], 1e-6, proj)
    stale = lq.backward(ev["gap"], 1e-3, proj)
    with pytest.raises(ValueError, match="last backward"):
        lq.rollout(ev["gap"], bw, np.zeros(NDX), proj)
    lq.rollout(ev["gap"], stale, np.zeros(NDX), proj)
    # blocks that would need a copy to be read cannot be bound (the solver keeps the wrappers)
    bad = dict(q, lx=np.asfortranarray(q["lx"]))
    assert CompiledLqStep.create(bad, sizes, pattern) is None


def test_the_solver_steps_the_same_with_and_without_it_on_the_walking_problem():
    from horizon_mpc.codegen import codegen_enabled

    if not codegen_enabled():
        pytest.skip("needs code generation (the compiled evaluation's buffer)")
    solver = trotting_go2_mpc(11).solver
    assert solver._lq is not None and solver._layout.any
    rng = np.random.default_rng(4)
    X = solver.X + 0.02 * rng.standard_normal(solver.X.shape)
    U = solver.U + 0.2 * rng.standard_normal(solver.U.shape)
    ev = solver._evaluate(X, U)
    results = []
    lq = solver._lq
    for use in (lq, None):
        solver._lq, solver.mu = use, 1e-4
        try:
            q_, proj, bw = solver._lq_step(ev, solver._new_info())
            dX, dU = riccati_c.linear_rollout_c(q_["A"], q_["B"], ev["gap"], bw, ev["d0"])
            results.append({"P_x": proj.P_x.copy(), "pinv": proj.pinv.copy(),
                            "K": bw.K.copy(), "k": bw.k.copy(), "S": bw.S.copy(),
                            "dX": dX, "dU": dU})
        finally:
            solver._lq = lq
    assert results[0]["pinv"].shape == results[1]["pinv"].shape
    for name in results[0]:
        _close(results[0][name], results[1][name], name)
