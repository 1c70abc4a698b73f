"""The merit terms of the ILQR (merit.py): an evaluation's cost, defects and projected
equality residuals, checked against sums written out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from horizon_mpc.solvers.ilqr import merit


def _evaluation(rng, N=6, ndx=5, nr=4, nc=7, ncon=3, nrN=3, ncN=4, ncNcon=2):
    """Random evaluation data for merit.evaluation_stats (some rows projected)."""
    return dict(gap=rng.standard_normal((N, ndx)), r=rng.standard_normal((N, nr)),
                W=rng.uniform(0.0, 2.0, (N, nr)), c=rng.standard_normal((N, nc)),
                b=rng.standard_normal((N, ncon)), eq=rng.random((N, ncon)) < 0.5,
                d0=rng.standard_normal(ndx), rN=rng.standard_normal(nrN),
                WN=rng.uniform(0.0, 2.0, nrN), cN=rng.standard_normal(ncN),
                bN=rng.standard_normal(ncNcon), eqN=np.array([True, False][:ncNcon], bool))


@pytest.mark.parametrize("sizes", [{}, dict(ncon=0, ncNcon=0), dict(nr=0, nrN=0),
                                   dict(N=1, ndx=1, nc=1, ncon=1, ncN=1, ncNcon=1)])
def test_evaluation_stats_sum_and_bound_the_masked_rows(sizes):
    data = _evaluation(np.random.default_rng(3), **sizes)
    got = merit.evaluation_stats(**data)
    assert got is not None
    # the sums and maxima by hand, on the masked rows only
    e = np.abs(data["c"][:, :data["b"].shape[1]] - data["b"])[data["eq"]]
    eN = np.abs(data["cN"][:data["bN"].size] - data["bN"])[data["eqN"]]
    assert got[3] == pytest.approx(e.sum() + eN.sum())
    assert got[4] == pytest.approx(max(e.max(initial=0.0), eN.max(initial=0.0)))
    assert got[0] == pytest.approx(np.sum(data["W"] * data["r"] ** 2)
                                   + np.sum(data["WN"] * data["rN"] ** 2))
    assert got[1] == pytest.approx(np.abs(data["gap"]).sum() + np.abs(data["d0"]).sum())
    assert got[2] == pytest.approx(max(np.abs(data["gap"]).max(), np.abs(data["d0"]).max()))


@pytest.mark.parametrize("field", ["gap", "r", "c", "d0", "rN", "cN"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_evaluation_stats_are_none_for_a_non_finite_value(field, bad):
    data = _evaluation(np.random.default_rng(4))
    data[field].flat[-1] = bad
    assert merit.evaluation_stats(**data) is None
