"""The compiled Riccati recursion returns what the numpy one does (riccati_c vs riccati).

Problems are random and well conditioned (Q_uu, H eigenvalues in [1, ~5], |A| ~ 1), so both
implementations agree to rounding: 1e-10 relative to each output's largest entry leaves
three orders of magnitude of room over the ~1e-15 actually seen. Every parity test runs on
both compiled kernels (AVX2+FMA where the CPU has it, and the baseline ISA).
"""

from __future__ import annotations

from pathlib import Path

import casadi as cs
import numpy as np
import pytest

from horizon_mpc.solvers.ilqr import merit, riccati_c
from horizon_mpc.solvers.ilqr.equality import EqualityLayout, Projection, project
from horizon_mpc.solvers.ilqr.riccati import backward_pass, linear_rollout

RTOL = 1e-10
FIELDS = ("K", "k", "S", "s", "Qu", "Quu", "Qux")


@pytest.fixture(scope="module")
def compiled(tmp_path_factory):
    """The library, compiled once into a private cache directory for this module."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("HORIZON_MPC_CACHE_DIR", str(tmp_path_factory.mktemp("riccati_cache")))
        mp.delenv("HORIZON_MPC_NO_CODEGEN", raising=False)
        mp.delenv("HORIZON_MPC_RICCATI_ISA", raising=False)
        riccati_c._forget()
        if not riccati_c.available():
            pytest.skip("no C compiler: the compiled recursion is unavailable")
        yield riccati_c.library_path()
    riccati_c._forget()


@pytest.fixture(params=["auto", "generic"])
def isa(request, compiled, monkeypatch):
    """Run the test on the automatic (AVX2 here if supported) and on the baseline kernels."""
    monkeypatch.setenv("HORIZON_MPC_RICCATI_ISA", request.param)
    return request.param


def _spd(rng, k, n):
    M = rng.standard_normal((k, n, n)) / np.sqrt(max(n, 1))
    return M @ np.swapaxes(M, 1, 2) + np.eye(n)


def _lq(N=12, ndx=7, nu=5, seed=0):
    """Random well-conditioned LQ data (A, B, lx, lu, lxx, luu, lux, f, lxN, lxxN)."""
    rng = np.random.default_rng(seed)
    return [np.eye(ndx) + 0.1 * rng.standard_normal((N, ndx, ndx)),
            0.3 * rng.standard_normal((N, ndx, nu)),
            rng.standard_normal((N, ndx)), rng.standard_normal((N, nu)),
            _spd(rng, N, ndx), _spd(rng, N, nu), 0.1 * rng.standard_normal((N, nu, ndx)),
            0.1 * rng.standard_normal((N, ndx)), rng.standard_normal(ndx), _spd(rng, 1, ndx)[0]]


def _projection(args, n_rows=4, seed=1):
    """Projection of random equality rows: input rows at some nodes, state rows of k+1 at
    others, the terminal rows at N-1; every third node has none."""
    A, B, f = args[0], args[1], args[7]
    N, ndx, nu = B.shape
    rng = np.random.default_rng(seed)
    own = rng.random((N, n_rows)) < 0.5
    nxt = (rng.random((N, n_rows)) < 0.3) & ~own
    own[::3] = nxt[::3] = False
    nxt[-1] = False
    layout = EqualityLayout(own, nxt, np.ones(2, bool), np.zeros((N, n_rows)), np.zeros(2))
    return project(layout, rng.standard_normal((N, n_rows)),
                   rng.standard_normal((N, n_rows, ndx)), rng.standard_normal((N, n_rows, nu)),
                   rng.standard_normal(2), rng.standard_normal((2, ndx)), A, B, f)


def _column_major_views(args):
    """The solver's layout: each node's block column-major (a transposed view), no copy."""
    return [np.ascontiguousarray(np.swapaxes(a, -1, -2)).swapaxes(-1, -2) if a.ndim == 3
            else np.asfortranarray(a) for a in args]


def _assert_same(c, ref):
    assert c is not None and ref is not None
    for name in FIELDS:
        a, b = getattr(c, name), getattr(ref, name)
        assert a.shape == b.shape, name
        scale = max(float(np.max(np.abs(b), initial=0.0)), 1e-300)
        err = float(np.max(np.abs(a - b), initial=0.0))
        assert err <= RTOL * scale, f"{name}: {err:.2e} vs {scale:.2e}"


def test_backward_pass_without_projection_matches_numpy(isa):
    args = _lq()
    _assert_same(riccati_c.backward_pass_c(*args, 1e-3), backward_pass(*args, 1e-3))


def test_backward_pass_with_projection_matches_numpy(isa):
    args = _lq(N=15)
    proj = _projection(args)
    assert proj.constrained.any() and not proj.constrained.all()
    _assert_same(riccati_c.backward_pass_c(*args, 1e-6, proj),
                 backward_pass(*args, 1e-6, proj))


@pytest.mark.parametrize("with_projection", [False, True])
def test_go2_sizes_match_numpy(isa, with_projection):
    """ndx 36, nu 30: the 4x2-vector tiles, their remainders and blocked Cholesky all run."""
    args = _lq(N=6, ndx=36, nu=30, seed=3)
    proj = _projection(args, n_rows=18) if with_projection else None
    _assert_same(riccati_c.backward_pass_c(*args, 1e-6, proj), backward_pass(*args, 1e-6, proj))



@pytest.mark.parametrize("N, ndx, nu, n_general", [(8, 7, 6, 1), (5, 36, 30, 12)])
def test_inputs_pinned_by_their_rows_are_left_out_exactly(isa, N, ndx, nu, n_general):
    """Rows on one input with no state part (a swing foot's zero force, here with nonzero
    targets) leave that input dead: zero rows in Z and P_x. The compiled pass skips it in
    its products; K's row is zero, k is P_e's, and all else matches numpy's full products."""
    args = _lq(N=N, ndx=ndx, nu=nu, seed=5)
    rng = np.random.default_rng(9)
    pinned = [1, 4] if nu < 10 else list(range(12, 30, 3))
    nc = len(pinned) + n_general
    cu = np.zeros((N, nc, nu))
    cx = np.zeros((N, nc, ndx))
    for j, a in enumerate(pinned):
        cu[:, j, a] = 1.0 + j
    cu[:, len(pinned):] = rng.standard_normal((N, n_general, nu))
    cx[:, len(pinned):] = rng.standard_normal((N, n_general, ndx))
    own = np.ones((N, nc), bool)
    own[::4] = False  # unconstrained nodes too
    layout = EqualityLayout(own, np.zeros((N, nc), bool), np.zeros(0, bool),
                            np.zeros((N, nc)), np.zeros(0))
    proj = project(layout, rng.standard_normal((N, nc)), cx, cu, np.zeros(0),
                   np.zeros((0, ndx)), args[0], args[1], args[7])
    con = proj.constrained
    assert con.any() and not con.all()
    assert np.all(proj.Z[con][:, pinned] == 0.0) and np.all(proj.P_x[con][:, pinned] == 0.0)
    assert np.all(np.abs(proj.P_e[con][:, pinned]) > 0.0)
    got = riccati_c.backward_pass_c(*args, 1e-6, proj)
    _assert_same(got, backward_pass(*args, 1e-6, proj))
    assert np.all(got.K[con][:, pinned] == 0.0)
    np.testing.assert_array_equal(got.k[con][:, pinned], proj.P_e[con][:, pinned])

def _sparse_dynamics(args, seed=7):
    """``args`` with A = I + a few couplings, B nonzero on a band (a legged robot's Euler
    step), and its pattern with one extra structural entry that is numerically zero."""
    A, B = args[0], args[1]
    N, ndx, nu = B.shape
    rng = np.random.default_rng(seed)
    mask = np.zeros((ndx, ndx + nu), bool)
    mask[:, :ndx] = np.eye(ndx, dtype=bool) | (rng.random((ndx, ndx)) < 0.1)
    mask[:, ndx:] = rng.random((ndx, nu)) < 0.15
    mask[0, ndx] = True
    out = list(args)
    out[0] = np.where(mask[:, :ndx], A, 0.0)
    out[1] = np.where(mask[:, ndx:], B, 0.0)
    out[1][:, 0, 0] = 0.0
    return out, riccati_c.AbPattern.from_mask(mask)


@pytest.mark.parametrize("with_projection", [False, True])
@pytest.mark.parametrize("ndx, nu", [(7, 5), (36, 30)])
def test_sparse_dynamics_pattern_matches_numpy(isa, with_projection, ndx, nu):
    """The recursion reading A and B by their pattern gives the dense result."""
    args, pattern = _sparse_dynamics(_lq(N=8, ndx=ndx, nu=nu, seed=2))
    proj = _projection(args, n_rows=min(nu - 1, 12)) if with_projection else None
    want = backward_pass(*args, 1e-6, proj)
    _assert_same(riccati_c.backward_pass_c(*args, 1e-6, proj, pattern=pattern), want)
    views = _column_major_views(args)  # the solver's layout
    _assert_same(riccati_c.backward_pass_c(*views, 1e-6, proj, pattern=pattern), want)


def test_entries_outside_the_pattern_are_not_read(isa):
    args, pattern = _sparse_dynamics(_lq(N=6, ndx=6, nu=4))
    want = riccati_c.backward_pass_c(*args, 1e-6, pattern=pattern)
    noisy = list(args)
    noisy[0] = np.where(pattern.mask[:, :6], args[0], 1e3)
    noisy[1] = np.where(pattern.mask[:, 6:], args[1], np.nan)
    _assert_same(riccati_c.backward_pass_c(*noisy, 1e-6, pattern=pattern), want)


def test_pattern_of_the_wrong_shape_is_refused(compiled):
    args = _lq(N=2, ndx=3, nu=2)
    with pytest.raises(ValueError, match=r"pattern has shape \(3, 4\); expected \(3, 5\)"):
        riccati_c.backward_pass_c(*args, 0.0, pattern=riccati_c.AbPattern.from_mask(
            np.ones((3, 4), bool)))
    with pytest.raises(ValueError, match="expected \\(ndx, ndx \\+ nu\\)"):
        riccati_c.AbPattern.from_mask(np.ones((3, 2), bool))


def test_transposed_views_are_read_through_their_strides(isa):
    args = _lq(N=9, ndx=6, nu=4)
    proj = _projection(args)
    views = _column_major_views(args)
    assert not views[0].flags.c_contiguous
    _assert_same(riccati_c.backward_pass_c(*views, 0.0, proj), backward_pass(*args, 0.0, proj))


def _unaligned(a):
    """A copy of ``a`` in a buffer shifted by 4 bytes (not a valid double pointer for C)."""
    raw = np.zeros(a.nbytes + 4, np.uint8)
    out = raw[4:4 + a.nbytes].view(np.float64).reshape(a.shape)
    out[...] = a
    return out


def test_reversed_unaligned_and_integer_inputs_give_the_same_result(isa):
    """Negative strides are followed, unaligned or non-float64 arrays are converted."""
    args = _lq(N=5, ndx=4, nu=3)
    odd = list(args)
    odd[0] = np.ascontiguousarray(args[0][:, ::-1])[:, ::-1]  # negative row stride
    odd[2] = np.ascontiguousarray(args[2][::-1])[::-1]  # nodes backwards
    odd[4] = _unaligned(args[4])
    assert not odd[4].flags.aligned
    odd[9] = np.rint(args[9] * 8).astype(int)  # an integer terminal Hessian
    ref = list(args)
    ref[9] = odd[9].astype(float)
    _assert_same(riccati_c.backward_pass_c(*odd, 1e-6), backward_pass(*ref, 1e-6))


def test_fully_constrained_and_dense_null_space_nodes_match_numpy(isa):
    """A node whose Z is all zero (du = P_e + P_x dx) and one whose Z is a dense rotation
    with every column free (no zero column to skip)."""
    args = _lq(N=3, ndx=5, nu=4)
    rng = np.random.default_rng(5)
    Z = np.zeros((3, 4, 4))
    free = np.zeros((3, 4))
    Z[1] = np.linalg.qr(rng.standard_normal((4, 4)))[0]
    free[1] = 1.0
    proj = Projection(rng.standard_normal((3, 4)), rng.standard_normal((3, 4, 5)), Z, free,
                      np.zeros((3, 4, 0)), np.zeros((3, 0), bool), np.array([True, True, False]),
                      0)
    _assert_same(riccati_c.backward_pass_c(*args, 0.0, proj), backward_pass(*args, 0.0, proj))


@pytest.mark.parametrize("N, ndx, nu", [(1, 1, 1), (4, 3, 9), (5, 4, 0), (0, 3, 2)])
def test_edge_sizes_match_numpy(isa, N, ndx, nu):
    """One state, more inputs than states, no input at all, no node."""
    args = _lq(N, ndx, nu)
    _assert_same(riccati_c.backward_pass_c(*args, 1e-6), backward_pass(*args, 1e-6))


def test_indefinite_q_uu_returns_none_and_a_larger_mu_succeeds(isa):
    args = _lq()
    args[5][4] = -5.0 * np.eye(args[5].shape[1])
    assert backward_pass(*args, 1e-6) is None
    assert riccati_c.backward_pass_c(*args, 1e-6) is None
    _assert_same(riccati_c.backward_pass_c(*args, 1e3), backward_pass(*args, 1e3))


def test_indefinite_reduced_hessian_returns_none(isa):
    args = _lq(N=15)
    proj = _projection(args)
    node = int(np.flatnonzero(proj.constrained)[0])
    args[5][node] = -5.0 * np.eye(args[5].shape[1])
    assert backward_pass(*args, 1e-6, proj) is None
    assert riccati_c.backward_pass_c(*args, 1e-6, proj) is None


def test_zero_null_space_column_marked_free_is_a_singular_hessian(isa):
    """diag(1 - free) gives such a column a zero pivot: numpy's Cholesky fails, so does C."""
    args = _lq(N=3, ndx=5, nu=4)
    proj = Projection(np.zeros((3, 4)), np.zeros((3, 4, 5)), np.zeros((3, 4, 4)),
                      np.ones((3, 4)), np.zeros((3, 4, 0)), np.zeros((3, 0), bool),
                      np.ones(3, bool), 0)
    assert backward_pass(*args, 0.0, proj) is None
    assert riccati_c.backward_pass_c(*args, 0.0, proj) is None


@pytest.mark.parametrize("with_projection", [False, True])
def test_nan_input_returns_none(isa, with_projection):
    args = _lq(N=15)
    proj = _projection(args) if with_projection else None
    args[7][8, 2] = np.nan  # a defect: k of node 8 is NaN
    assert backward_pass(*args, 1e-6, proj) is None
    assert riccati_c.backward_pass_c(*args, 1e-6, proj) is None


def test_linear_rollout_matches_numpy(isa):
    args = _lq(N=10, ndx=6, nu=4)
    bw = backward_pass(*args, 1e-6)
    dx0 = np.linspace(-1.0, 1.0, 6)
    A, B, f = args[0], args[1], args[7]
    dX, dU = linear_rollout(A, B, f, bw, dx0)
    for a, b, fv in ((A, B, f), _column_major_views([A, B, f])):
        cX, cU = riccati_c.linear_rollout_c(a, b, fv, bw, dx0)
        assert cX.shape == dX.shape and cU.shape == dU.shape
        assert np.max(np.abs(cX - dX)) <= RTOL * np.max(np.abs(dX))
        assert np.max(np.abs(cU - dU)) <= RTOL * np.max(np.abs(dU))


def test_wrong_shape_is_refused_before_reaching_c(compiled):
    args = _lq(N=4, ndx=3, nu=2)
    args[4] = args[4][:, :2]
    with pytest.raises(ValueError, match=r"lxx has shape \(4, 2, 3\); expected \(4, 3, 3\)"):
        riccati_c.backward_pass_c(*args, 0.0)


def test_the_cached_library_is_loaded_not_rebuilt(compiled, monkeypatch):
    assert compiled.is_file()

    def no_build(lib):
        raise AssertionError("rebuilt a cached library")

    monkeypatch.setattr(riccati_c, "_build", no_build)
    riccati_c._forget()
    assert riccati_c.available()



def test_another_library_under_its_name_is_rebuilt_not_a_traceback(compiled, monkeypatch,
                                                                   tmp_path, caplog):
    """A valid shared object without the recursion's symbols (another library copied
    over it, with a matching checksum) raised AttributeError out of every run."""
    from horizon_mpc import codegen

    x = cs.SX.sym("x")
    other = codegen.compile_function(cs.Function("not_riccati", [x], [2 * x]),
                                     cache_dir=tmp_path)
    lib = tmp_path / "riccati_copy.so"
    lib.write_bytes(codegen.compiled_library(other).read_bytes())
    codegen.checksum_path(lib).write_text(codegen._sha256(lib) + "\n")
    built: list = []
    monkeypatch.setattr(riccati_c, "library_path", lambda: lib)

    def build(path: Path) -> None:
        # the wrong library is gone first: a build that finds a whole library in place
        # keeps it (another process's, since the build locks of session 32), and one
        # review found the rebuild keeping this one
        built.append((path, path.exists()))
        path.write_bytes(compiled.read_bytes())

    monkeypatch.setattr(riccati_c, "_build", build)
    riccati_c._forget()
    with caplog.at_level("WARNING", logger=riccati_c.__name__):
        assert riccati_c.available()
    assert built == [(lib, False)] and "undefined symbol" in caplog.text
    riccati_c._forget()

def test_unavailable_with_no_codegen_says_why(compiled, monkeypatch, caplog):
    monkeypatch.setenv("HORIZON_MPC_NO_CODEGEN", "1")
    with caplog.at_level("INFO", logger=riccati_c.__name__):
        assert not riccati_c.available()
    assert "HORIZON_MPC_NO_CODEGEN" in caplog.text


def test_unavailable_without_a_compiler_says_why(compiled, monkeypatch, caplog):
    riccati_c._forget()
    monkeypatch.setattr(riccati_c.codegen, "CC_ARGV", ("no-such-compiler-xyz",))
    with caplog.at_level("WARNING", logger=riccati_c.__name__):
        assert not riccati_c.available()
    assert "no-such-compiler-xyz" in caplog.text
    with pytest.raises(RuntimeError, match="unavailable"):
        riccati_c.backward_pass_c(*_lq(N=2, ndx=2, nu=1), 0.0)
    riccati_c._forget()


def test_projection_kernel_matches_the_numpy_qr(isa):
    """``project_rows_c`` (each ISA) = the batched numpy QR; dependent, too many and
    non-finite rows are flagged (not ok) for the caller's SVD."""
    from horizon_mpc.solvers.ilqr import equality

    rng = np.random.default_rng(4)
    N, m, nu, ndx = 9, 7, 5, 6
    W = rng.standard_normal((N * m + 1, nu + ndx + 1))
    W[-1] = 0.0
    rows = rng.random((N, m)) < 0.6
    rows[0] = False  # no row: free input
    rows[1, :3], rows[1, 3:] = True, False
    W[m + 2] = 2.0 * W[m]  # node 1: dependent rows
    rows[2] = True  # node 2: more rows than inputs
    rows[3, :2], rows[3, 2:] = True, False
    W[3 * m, 0] = np.nan  # node 3: not finite
    rows[4:, :] = rows[4:, :] & (np.arange(m) < 5)  # the rest: at most nu rows
    P_e, P_x, Z, free, pinv, ok, unmet = riccati_c.project_rows_c(W, rows, nu, 1e-9)
    ref, fallback = equality._qr_solve_numpy(W, rows, nu, 1e-9)
    np.testing.assert_array_equal(np.flatnonzero(~ok), fallback)
    good = ok.copy()
    assert good[0] and good[4:].all() and not good[1:4].any()
    for got, want in ((P_e, ref.P_e), (P_x, ref.P_x), (pinv, ref.pinv), (free, ref.free)):
        np.testing.assert_allclose(got[good], want[good], rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(unmet[good], ref.unmet[good])
    # orthonormal null-space bases of the same spaces (signs may differ)
    proj = Z @ np.swapaxes(Z, 1, 2)
    np.testing.assert_allclose(proj[good], (ref.Z @ np.swapaxes(ref.Z, 1, 2))[good], atol=1e-12)
    np.testing.assert_array_equal(Z[0], np.eye(nu))


def test_rows_on_one_input_are_eliminated_exactly(isa):
    """Rows with one nonzero in D (a swing foot's zero force) fix their input and are
    eliminated from the other rows before the QR: the same D^+, P_e, P_x and null space as
    the whole QR, with the pinned column also in the other rows, scaled pinned rows, only
    pinned rows, and two rows on one input (dependent: left to the SVD)."""
    from horizon_mpc.solvers.ilqr import equality

    rng = np.random.default_rng(11)
    N, m, nu, ndx = 6, 8, 7, 5
    W = rng.standard_normal((N * m + 1, nu + ndx + 1))
    W[-1] = 0.0
    rows = np.zeros((N, m), bool)
    rows[:, :5] = True  # 5 rows on 7 inputs

    def pin(node, slot, col, scale=1.0, zero_rest=True):
        r = W[node * m + slot]
        r[:nu] = 0.0
        r[col] = scale
        if zero_rest:
            r[nu:-1] = 0.0  # a zero-force row: f_col = 0 (C = 0, e = the force)

    pin(0, 0, 2)  # node 0: one pinned row, column 2 also in the general rows
    pin(1, 1, 0, -2.5, zero_rest=False)
    pin(1, 3, 6, 0.3)  # node 1: two scaled pinned rows, one with a state part
    for j in range(5):  # node 2: only pinned rows
        pin(2, j, (2 * j + 1) % nu, 1.0 + j)
    pin(3, 0, 4)
    pin(3, 2, 4, 2.0)  # node 3: two rows on input 4: dependent
    rows[4, 2:] = False  # node 4: general rows only (the whole QR)
    pin(5, 4, 1)
    W[5 * m + 4, -1] = 3.0  # node 5: a nonzero target on the pinned input
    P_e, P_x, Z, free, pinv, ok, unmet = riccati_c.project_rows_c(W, rows, nu, 1e-9)
    assert ok.tolist() == [True, True, True, False, True, True]
    good = ok
    Wm = W[:-1].reshape(N, m, -1) * rows[..., None]
    ref = equality._svd_solve(Wm, nu, 1e-9)
    for got, want in ((P_e, ref.P_e), (P_x, ref.P_x), (pinv, ref.pinv), (free, ref.free)):
        np.testing.assert_allclose(got[good], want[good], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P_e[5, 1], -3.0)  # d f = -e
    proj = Z @ np.swapaxes(Z, 1, 2)
    np.testing.assert_allclose(proj[good], (ref.Z @ np.swapaxes(ref.Z, 1, 2))[good],
                               atol=1e-12)
    D = Wm[..., :nu]
    assert np.max(np.abs(D[good] @ Z[good])) <= 1e-12
    # Z: zero range columns, orthonormal null columns; pinned inputs are not in the null space
    for k in np.flatnonzero(good):
        Zk = Z[k][:, free[k] > 0]
        np.testing.assert_allclose(Zk.T @ Zk, np.eye(Zk.shape[1]), atol=1e-12)
        assert np.all(Z[k][:, free[k] == 0] == 0.0)
    assert np.all(Z[0][2] == 0.0) and np.all(Z[1][[0, 6]] == 0.0)
    assert not unmet[good].any()


def _stack_problem(N, ndx, nu, n_in, n_state, n_term, seed):
    """Random rows for ``equality._stack_rows``: input rows at some nodes, state rows of
    node k+1 at others (none at every third node), ``n_term`` terminal rows."""
    rng = np.random.default_rng(seed)
    nc = n_in + n_state
    own = np.zeros((N, nc), bool)
    nxt = np.zeros((N, nc), bool)
    own[:, :n_in] = rng.random((N, n_in)) < 0.6
    nxt[:-1, n_in:] = rng.random((N - 1, n_state)) < 0.6
    own[:-1:3] = nxt[:-1:3] = False
    layout = EqualityLayout(own, nxt, rng.random(n_term) < 0.7,
                            rng.standard_normal((N, nc)), rng.standard_normal(n_term))
    args = [rng.standard_normal((N, nc)), rng.standard_normal((N, nc, ndx)),
            rng.standard_normal((N, nc, nu)), rng.standard_normal(n_term),
            rng.standard_normal((n_term, ndx)), rng.standard_normal((N, ndx, ndx)),
            rng.standard_normal((N, ndx, nu)), rng.standard_normal((N, ndx))]
    return layout, args


@pytest.mark.parametrize("N, ndx, nu, n_in, n_state, n_term", [
    (12, 7, 5, 3, 2, 2), (1, 4, 3, 2, 1, 2), (5, 6, 4, 0, 3, 1), (5, 6, 4, 3, 0, 0),
    (6, 36, 30, 18, 12, 6)])
@pytest.mark.parametrize("sparse", [False, True])
def test_row_stacking_matches_numpy(compiled, N, ndx, nu, n_in, n_state, n_term, sparse):
    """``stack_rows_c`` = ``equality._stack_rows`` (the rows, their mask, the scratch row),
    from C-ordered arrays and from the solver's column-major views, with A and B read
    densely or by a pattern whose other entries are NaN (so never read)."""
    from horizon_mpc.solvers.ilqr import equality

    layout, args = _stack_problem(N, ndx, nu, n_in, n_state, n_term, seed=N + ndx)
    pattern = None
    if sparse:
        rng = np.random.default_rng(5)
        mask = rng.random((ndx, ndx + nu)) < 0.2
        pattern = riccati_c.AbPattern.from_mask(mask)
        args[5] = np.where(mask[:, :ndx], args[5], 0.0)
        args[6] = np.where(mask[:, ndx:], args[6], 0.0)
    W_ref, rows_ref = equality._stack_rows(layout, *args)
    if sparse:  # entries outside the pattern must not be read
        args[5] = np.where(mask[:, :ndx], args[5], np.nan)
        args[6] = np.where(mask[:, ndx:], args[6], np.nan)
    for views in (args, _column_major_views(args)):
        W, rows = riccati_c.stack_rows_c(layout, *views, pattern=pattern)
        np.testing.assert_array_equal(rows, rows_ref)
        assert W.shape == W_ref.shape and np.all(W[-1] == 0.0)
        # slots without a row: zero in C, what the unused row evaluates to in numpy
        used = np.append(rows.ravel(), True)
        scale = max(float(np.max(np.abs(W_ref))), 1.0)
        assert np.max(np.abs(W[used] - W_ref[used]), initial=0.0) <= 1e-13 * scale


def test_projection_with_compiled_stacking_matches_the_numpy_path(compiled, monkeypatch):
    """``project`` through the compiled stacking and QR = the all-numpy path."""
    from horizon_mpc.solvers.ilqr import equality

    layout, args = _stack_problem(10, 8, 6, 3, 2, 2, seed=3)
    got = project(layout, *args)
    monkeypatch.setattr(equality, "_compiled", lambda: False)
    want = project(layout, *args)
    np.testing.assert_array_equal(got.rows, want.rows)
    assert got.rank_deficient == want.rank_deficient
    for name in ("P_e", "P_x", "pinv", "free"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-9,
                                   atol=1e-11, err_msg=name)


# ------------------------------------------------------------------ merit terms

def _step(rng, N=6, ndx=5, nu=4, m=3):
    return dict(lx=rng.standard_normal((N, ndx)), lu=rng.standard_normal((N, nu)),
                lxN=rng.standard_normal(ndx), s=rng.standard_normal((N + 1, ndx)),
                S=rng.standard_normal((N + 1, ndx, ndx)), Qu=rng.standard_normal((N, nu)),
                Quu=rng.standard_normal((N, nu, nu)), Qux=rng.standard_normal((N, nu, ndx)),
                dX=rng.standard_normal((N + 1, ndx)), dU=rng.standard_normal((N, nu)),
                pinv=None if m is None else rng.standard_normal((N, nu, m)))


@pytest.mark.parametrize("sizes", [{}, dict(m=None), dict(m=0), dict(nu=0, m=None),
                                   dict(N=1, ndx=1, nu=1, m=1)])
def test_step_stats_match_numpy(compiled, sizes):
    data = _step(np.random.default_rng(6), **sizes)
    ref = merit.step_stats(**data)
    got = riccati_c.step_stats_c(**data)
    assert np.allclose(got, ref, rtol=1e-12, atol=1e-12)
    costates = data["s"] + np.einsum("kij,kj->ki", data["S"], data["dX"])
    assert got[1] >= np.abs(costates).max() - 1e-12  # the costates bound it from below


def test_step_stats_multipliers_of_the_projected_rows_count(compiled):
    data = _step(np.random.default_rng(7))
    small = merit.step_stats(**dict(data, pinv=None))[1]
    data["pinv"] *= 1e3  # the projected rows' multipliers now dominate
    big = riccati_c.step_stats_c(**data)[1]
    assert big > 10 * small
    assert big == pytest.approx(merit.step_stats(**data)[1], rel=1e-12)


@pytest.mark.parametrize("field, index", [("dX", 1), ("dX", 2), ("dU", 3)])
def test_step_stats_propagate_nan_into_the_maxima(compiled, field, index):
    data = _step(np.random.default_rng(8))
    data[field][2, 0] = np.nan
    got, ref = riccati_c.step_stats_c(**data), merit.step_stats(**data)
    assert np.isnan(got[index]) and np.isnan(ref[index])
