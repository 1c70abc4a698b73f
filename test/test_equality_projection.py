"""The QR null-space projection of equality rows gives what the SVD one does.

``project(..., method='qr')`` (the default) factorises each node's rows with a QR (the
compiled kernel of ``riccati.c``, or batched numpy: every test runs with both) and hands
only the nodes whose rows are (nearly) dependent, or more than the inputs, to the batched
SVD of ``method='svd'``. Both must return the same ``P_e``, ``P_x``, ``pinv``, ``free``
and ``rank_deficient``, and orthonormal bases ``Z`` of the same null spaces (not the same
bases), so that the backward pass computes the same gains.

Problems are random: D rows are Gaussian, so full-rank nodes have condition numbers of a
few tens; 1e-9 relative to each output's largest entry leaves five orders of magnitude
over the rounding actually seen (~1e-14).
"""

from __future__ import annotations

import numpy as np
import pytest

from horizon_mpc.solvers.ilqr import equality, riccati_c
from horizon_mpc.solvers.ilqr.equality import EqualityLayout, Projection, project
from horizon_mpc.solvers.ilqr.riccati import backward_pass

RTOL = 1e-9


def _close(a: np.ndarray, b: np.ndarray, rtol: float = RTOL) -> bool:
    """|a - b| <= rtol times the largest |b| (an absolute 1e-300 floor for all-zero b)."""
    scale = max(float(np.max(np.abs(b), initial=0.0)), 1e-300)
    return float(np.max(np.abs(a - b), initial=0.0)) <= rtol * scale


def _problem(N: int = 12, ndx: int = 7, nu: int = 5, n_in: int = 3, n_state: int = 2,
             n_term: int = 2, seed: int = 0, p_in: float = 0.6, p_state: float = 0.6):
    """Random linearised rows and dynamics, and a layout using some of them.

    Columns ``:n_in`` of the stage constraints are input rows (``own``, each used with
    probability ``p_in``), the next ``n_state`` state rows of node k+1 (``next``); the
    ``n_term`` terminal rows are handled at node N-1; every third node has no row.
    Returns ``(layout, args)`` with ``args`` the arrays :func:`project` takes after it.
    """
    rng = np.random.default_rng(seed)
    nc = n_in + n_state
    own = np.zeros((N, nc), bool)
    nxt = np.zeros((N, nc), bool)
    own[:, :n_in] = rng.random((N, n_in)) < p_in
    nxt[:-1, n_in:] = rng.random((N - 1, n_state)) < p_state
    own[:-1:3] = nxt[:-1:3] = False
    layout = EqualityLayout(own, nxt, np.ones(n_term, bool),
                            rng.standard_normal((N, nc)), rng.standard_normal(n_term))
    args = [rng.standard_normal((N, nc)), rng.standard_normal((N, nc, ndx)),
            rng.standard_normal((N, nc, nu)), rng.standard_normal(n_term),
            rng.standard_normal((n_term, ndx)),
            np.eye(ndx) + 0.1 * rng.standard_normal((N, ndx, ndx)),
            rng.standard_normal((N, ndx, nu)), 0.1 * rng.standard_normal((N, ndx))]
    return layout, args


def _rows(layout: EqualityLayout, args: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each node's rows ``D du + C dx + e = 0``, (N, m, nu), (N, m, ndx), (N, m), built
    node by node from their definition (zero in unused slots): the used input columns of
    the layout, then its state columns of node k+1 through the dynamics (at N-1: the
    terminal rows)."""
    c, cx, cu, cN, cxN, A, B, gap = args
    N, ndx, nu = B.shape
    own_cols = np.flatnonzero(layout.own.any(axis=0))
    nxt_cols = np.flatnonzero(layout.next.any(axis=0))
    term_cols = np.flatnonzero(layout.term)
    k = len(own_cols)
    m = k + max(len(nxt_cols), len(term_cols))
    D, C, e = np.zeros((N, m, nu)), np.zeros((N, m, ndx)), np.zeros((N, m))
    for i in range(N):
        for s, col in enumerate(own_cols):
            if layout.own[i, col]:
                D[i, s], C[i, s], e[i, s] = cu[i, col], cx[i, col], c[i, col] - layout.b[i, col]
        if i < N - 1:
            for s, col in enumerate(nxt_cols, start=k):
                if layout.next[i, col]:
                    J = cx[i + 1, col]
                    D[i, s], C[i, s] = J @ B[i], J @ A[i]
                    e[i, s] = c[i + 1, col] - layout.b[i + 1, col] + J @ gap[i]
        else:
            for s, col in enumerate(term_cols, start=k):
                J = cxN[col]
                D[i, s], C[i, s] = J @ B[i], J @ A[i]
                e[i, s] = cN[col] - layout.bN[col] + J @ gap[i]
    return D, C, e


@pytest.fixture
def svd_batches(monkeypatch) -> list[int]:
    """The sizes of the node batches the QR path hands to the SVD, in order."""
    sizes: list[int] = []
    svd_solve = equality._svd_solve

    def spy(W, nu, rtol):
        sizes.append(len(W))
        return svd_solve(W, nu, rtol)

    monkeypatch.setattr(equality, "_svd_solve", spy)
    return sizes


@pytest.fixture(autouse=True, params=["compiled", "numpy"])
def qr_kernel(request, monkeypatch) -> str:
    """Every test with the compiled QR kernel and with the batched numpy one."""
    if request.param == "compiled":
        if not riccati_c.available():
            pytest.skip("no compiled Riccati library (no C compiler or codegen disabled)")
    else:
        monkeypatch.setattr(equality, "_compiled", lambda: False)
    return request.param


def _both(layout: EqualityLayout, args: list) -> tuple[Projection, Projection]:
    return project(layout, *args, method="qr"), project(layout, *args, method="svd")


def _assert_same_projection(qr: Projection, svd: Projection) -> None:
    """Same affine part, pseudo-inverse, free columns and null spaces (bases may differ)."""
    for name in ("rows", "constrained", "free"):
        np.testing.assert_array_equal(getattr(qr, name), getattr(svd, name), err_msg=name)
    assert qr.rank_deficient == svd.rank_deficient
    for name in ("P_e", "P_x", "pinv"):
        assert _close(getattr(qr, name), getattr(svd, name)), name
    # the same null space: the same orthogonal projector Z Z^T
    assert _close(qr.Z @ np.swapaxes(qr.Z, 1, 2), svd.Z @ np.swapaxes(svd.Z, 1, 2))


def _assert_valid_basis(proj: Projection, D: np.ndarray) -> None:
    """Z: exactly zero range columns (free = 0), orthonormal null columns with D Z = 0."""
    free = proj.free.astype(bool)
    assert np.all(proj.Z[~free[:, None, :].repeat(proj.Z.shape[1], axis=1)] == 0.0)
    for k in range(len(free)):
        Zk = proj.Z[k][:, free[k]]
        np.testing.assert_allclose(Zk.T @ Zk, np.eye(Zk.shape[1]), atol=1e-12)
    assert np.max(np.abs(D @ proj.Z), initial=0.0) <= 1e-12 * max(1.0, np.max(np.abs(D)))


def test_full_rank_nodes_match_the_svd_and_meet_their_rows(svd_batches):
    layout, args = _problem(N=15, seed=1)
    qr = project(layout, *args)
    assert svd_batches == []  # no node needed the SVD
    svd = project(layout, *args, method="svd")
    D, C, e = _rows(layout, args)
    np.testing.assert_array_equal(qr.rows, np.any(D != 0.0, axis=2))
    assert qr.constrained.any() and not qr.constrained.all()  # some nodes have no row
    assert qr.rank_deficient == 0
    _assert_same_projection(qr, svd)
    _assert_valid_basis(qr, D)
    # D du = -(C dx + e) for every dx: D P_e + e = 0 and D P_x + C = 0
    assert np.max(np.abs(np.einsum("kmu,ku->km", D, qr.P_e) + e)) <= 1e-12
    assert np.max(np.abs(D @ qr.P_x + C)) <= 1e-12


def test_nodes_without_rows_leave_the_input_free():
    layout, args = _problem(N=10, seed=2)
    qr, _ = _both(layout, args)
    idle = ~qr.constrained
    assert idle.any()
    np.testing.assert_array_equal(qr.Z[idle], np.broadcast_to(np.eye(5), qr.Z[idle].shape))
    assert np.all(qr.free[idle] == 1.0)
    assert np.all(qr.P_e[idle] == 0.0) and np.all(qr.P_x[idle] == 0.0)
    assert np.all(qr.pinv[idle] == 0.0)


def test_pseudo_inverse_reproduces_d_at_every_node():
    """D D^+ D = D: the multiplier estimate's pseudo-inverse, dependent rows included."""
    layout, args = _problem(N=12, nu=4, seed=3)
    args[2][4, 1] = args[2][4, 0]  # node 4: two input rows equal in D
    layout.own[4, :2] = True
    layout.own[[5, 8], :3] = True  # nodes 5, 8: five rows, four inputs
    layout.next[[5, 8], 3:] = True
    proj = project(layout, *args)
    D, _, _ = _rows(layout, args)
    assert np.max(np.abs(D @ proj.pinv @ D - D)) <= 1e-12 * np.max(np.abs(D))


@pytest.mark.parametrize("consistent", [True, False])
def test_dependent_rows_fall_back_to_the_svd(consistent, svd_batches):
    """Duplicated rows: met if their targets agree (not rank deficient), in least squares
    if not; only those two nodes go through the SVD."""
    layout, args = _problem(N=12, seed=4, p_in=1.0, p_state=0.0, n_term=0)
    c, cu = args[0], args[2]
    for k in (2, 7):
        cu[k, 1] = cu[k, 0]
        c[k, 1] = c[k, 0] + layout.b[k, 1] - layout.b[k, 0] + (0.0 if consistent else 1.0)
    qr = project(layout, *args)
    assert svd_batches == [2]
    svd = project(layout, *args, method="svd")
    _assert_same_projection(qr, svd)
    _assert_valid_basis(qr, _rows(layout, args)[0])
    assert qr.rank_deficient == (0 if consistent else 2)
    assert np.all(qr.free[[2, 7]].sum(axis=1) == 5 - 2)  # 3 rows of rank 2


def test_more_rows_than_inputs_go_through_the_svd(svd_batches):
    """m > nu at some nodes: the rows cannot all be met; the others still use the QR."""
    layout, args = _problem(N=8, nu=3, n_in=4, n_state=2, seed=5, p_in=0.3, p_state=0.3)
    layout.own[[1, 5], :4] = True
    qr = project(layout, *args)
    assert svd_batches == [int(np.sum(qr.rows.sum(axis=1) > 3))]
    assert qr.rank_deficient == svd_batches[0] > 0
    svd = project(layout, *args, method="svd")
    _assert_same_projection(qr, svd)
    _assert_valid_basis(qr, _rows(layout, args)[0])


def test_fully_constrained_node_has_no_free_column():
    layout, args = _problem(N=6, nu=4, n_in=4, n_state=0, n_term=0, seed=6, p_in=0.0)
    layout.own[3] = True
    qr, svd = _both(layout, args)
    assert np.all(qr.Z[3] == 0.0) and np.all(qr.free[3] == 0.0)
    _assert_same_projection(qr, svd)


def test_go2_like_trot_matches_the_svd(svd_batches):
    """The go2 walking sizes and pattern: N 40, nu 30 (18 accelerations, 12 forces), ndx 36;
    per node 6 dynamics rows, a zero force (a row fixing one input) per swing-foot
    component and the velocity of each stance foot at k+1: 18 of 30 row slots."""
    layout, args = _problem(N=40, ndx=36, nu=30, n_in=18, n_state=12, n_term=6, seed=7)
    cu = args[2]
    cu[:, 6:18] = 0.0
    cu[:, 6:18, 18:30] = np.eye(12)
    swing = np.zeros((40, 4), bool)
    swing[:, [0, 3]] = (np.arange(40) // 5 % 2 == 0)[:, None]  # diagonal pairs, 5 nodes
    swing[:, [1, 2]] = ~swing[:, [0, 3]]
    layout.own[:] = False
    layout.own[:, :6] = True
    layout.own[:, 6:18] = np.repeat(swing, 3, axis=1)
    layout.next[:] = False
    layout.next[:-1, 18:30] = np.repeat(~swing[1:], 3, axis=1)
    qr = project(layout, *args)
    assert svd_batches == [] and np.all(qr.rows.sum(axis=1) == 18)
    svd = project(layout, *args, method="svd")
    _assert_same_projection(qr, svd)
    _assert_valid_basis(qr, _rows(layout, args)[0])


@pytest.mark.parametrize("gap, by_svd", [(1e-5, False), (1e-12, True)])
def test_nearly_dependent_rows_are_decided_as_the_svd_decides(gap, by_svd, svd_batches):
    """Two rows 1e-5 apart (condition ~1e5) stay with the QR, 1e-12 apart (beyond
    1 / rtol) go to the SVD, which drops the smallest singular value."""
    layout, args = _problem(N=6, seed=11, p_in=1.0, p_state=0.0, n_term=0)
    cu = args[2]
    cu[4, 1] = cu[4, 0] + gap * np.random.default_rng(12).standard_normal(5)
    qr = project(layout, *args)
    assert svd_batches == ([1] if by_svd else [])
    svd = project(layout, *args, method="svd")
    assert qr.free[4].sum() == (3 if by_svd else 2)
    for name in ("free", "rows"):
        np.testing.assert_array_equal(getattr(qr, name), getattr(svd, name))
    assert qr.rank_deficient == svd.rank_deficient
    # conditioning ~1/gap: the affine part agrees to ~1e-16 / gap relative
    for name in ("P_e", "P_x"):
        assert _close(getattr(qr, name), getattr(svd, name), 1e-9 if by_svd else 1e-7), name


def test_backward_pass_gains_are_the_same_with_either_basis():
    layout, args = _problem(N=15, seed=8)
    N, ndx, nu = args[6].shape
    A, B, gap = args[5], args[6], args[7]
    rng = np.random.default_rng(9)
    M = rng.standard_normal((N + 2, ndx + nu, ndx + nu)) / np.sqrt(ndx + nu)
    H = M @ np.swapaxes(M, 1, 2) + np.eye(ndx + nu)  # [[lxx, lux^T], [lux, luu]], SPD
    lq = (A, B, rng.standard_normal((N, ndx)), rng.standard_normal((N, nu)),
          H[:N, :ndx, :ndx], H[:N, ndx:, ndx:], H[:N, ndx:, :ndx], gap,
          rng.standard_normal(ndx), H[N, :ndx, :ndx])
    qr, svd = _both(layout, args)
    a, b = backward_pass(*lq, 1e-6, qr), backward_pass(*lq, 1e-6, svd)
    assert a is not None and b is not None
    for name in ("K", "k", "S", "s"):
        assert _close(getattr(a, name), getattr(b, name)), name


def test_no_projected_row_gives_free_inputs_with_either_method():
    layout, args = _problem(N=5, seed=10, p_in=0.0, p_state=0.0, n_term=0)
    for method in ("qr", "svd"):
        proj = project(layout, *args, method=method)
        assert not proj.constrained.any() and proj.pinv.shape == (5, 5, 0)
        assert np.all(proj.free == 1.0)


def test_non_finite_rows_are_refused_as_by_the_svd(svd_batches):
    """A NaN in a used row: the QR hands the node to the SVD, which refuses it."""
    layout, args = _problem(N=6, seed=13, p_in=1.0)
    args[2][4, 0, 2] = np.nan
    for method in ("qr", "svd"):
        with pytest.raises(np.linalg.LinAlgError):
            project(layout, *args, method=method)
    assert svd_batches[0] == 1


def test_triangular_inverse_not_done_in_place_is_copied_back(monkeypatch):
    """If LAPACK's wrapper ever returns a copy rather than inverting in place."""
    layout, args = _problem(N=9, seed=14)
    ref = project(layout, *args)
    trtri = equality._trtri
    monkeypatch.setattr(equality, "_trtri",
                        lambda c, *flags: trtri(np.array(c, order="F"), *flags))
    _assert_same_projection(project(layout, *args), ref)


def test_unknown_method_is_refused():
    layout, args = _problem(N=3)
    with pytest.raises(ValueError, match="'lu'.*'qr', 'qr-numpy', 'svd'"):
        project(layout, *args, method="lu")


def test_a_row_the_input_moves_only_by_round_off_is_dropped():
    """An input row scaled to round-off (1e-19, state Jacobian 1e-16: a unit-quaternion row
    under a norm-preserving integrator) is not projected (its P_x would be C / D ~ 1e3):
    the node's projection is the one without that row. Its only row: no other row to
    compare it with (a relative rank test keeps it)."""
    layout, args = _problem(N=9, seed=4)
    node = int(np.flatnonzero(layout.own.sum(axis=1) >= 1)[0])
    layout.own[node] = False
    col = 0
    layout.own[node, col] = True
    layout.next[node] = False
    args[2][node, col] *= 1e-19
    args[1][node, col] *= 1e-16
    args[0][node, col] = layout.b[node, col]  # the row holds (as the unit norm does)
    qr = project(layout, *args)
    layout.own[node, col] = False
    without = project(layout, *args)
    for name in ("P_e", "P_x", "free"):
        assert _close(getattr(qr, name)[node], getattr(without, name)[node]), name
    assert qr.rank_deficient == 0  # the dropped row is met: its target holds
