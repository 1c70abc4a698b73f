"""The backward Riccati recursion and linear rollout of :mod:`.riccati`, compiled from C.

``backward_pass_c`` and ``linear_rollout_c`` take the same arguments and return the same
results as :func:`.riccati.backward_pass` and :func:`.riccati.linear_rollout` (to rounding:
~1e-15 relative on well-conditioned problems; on go2's, with cond(Q_uu) ~ 1e8, within what
numpy itself moves when its inputs change by one ulp), with no Python loop over the nodes:
at go2 sizes (ndx 36, nu 30, 40 nodes) the backward pass takes about 1 ms against 4-8 ms
for numpy. The C source, ``riccati.c`` next to this file, is compiled once with
``gcc -O3 -fPIC -shared`` into the cache directory of :mod:`horizon_mpc.codegen` (keyed by a
hash of the source, the compiler and its flags) and loaded with ctypes. No ``-march``: the
cache may be shared between machines, so the library carries a baseline and an AVX2+FMA
version of the recursion and picks one from the CPU at run time (override with
``HORIZON_MPC_RICCATI_ISA=generic``).

Use :func:`available` first: it is False, with the reason logged once, when
``HORIZON_MPC_NO_CODEGEN=1``, when there is no C compiler (``$CC``, default gcc) or when the
build fails; the caller then keeps the numpy functions::

    from horizon_mpc.solvers.ilqr import riccati, riccati_c
    backward = riccati_c.backward_pass_c if riccati_c.available() else riccati.backward_pass

Inputs may be any float64 numpy views (e.g. the transposed CasADi buffers of the solver):
they are read through their strides, without a copy.
"""

from __future__ import annotations

import _ctypes
import ctypes
import hashlib
import logging
import math
import os
import platform
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from horizon_mpc import codegen
from horizon_mpc.solvers.ilqr.equality import EqualityLayout, Projection, _slots
from horizon_mpc.solvers.ilqr.riccati import BackwardResult

__all__ = ["AbPattern", "AlRowsKernel", "available", "backward_pass_c", "library_path",
           "linear_rollout_c", "project_rows_c", "stack_rows_c", "step_stats_c", "uses_avx2"]

_log = logging.getLogger(__name__)

SOURCE = Path(__file__).with_name("riccati.c")
# compiled into the same library: one evaluation of the problem (evaluation.py binds it) and
# the LQ step on bound arrays (lq_step.py); riccati.h declares what they call of riccati.c
SOURCES = (SOURCE, *(Path(__file__).with_name(name) for name in ("evaluation.c", "lq_step.c")))
HEADERS = (Path(__file__).with_name("riccati.h"),)
# Plain optimisation only: no -march/-mavx2 (the cache may be shared by different CPUs; the
# source dispatches to AVX2 itself) and no -ffast-math (NaN and inf must propagate as in
# numpy, the caller's regularisation loop depends on it).
FLAGS = ("-O3", "-fPIC", "-shared")
# riccati_backward's `variant`: 0 automatic, 1 baseline ISA (HORIZON_MPC_RICCATI_ISA=generic)
_VARIANTS = {"": 0, "auto": 0, "generic": 1}

_lib: ctypes.CDLL | None = None
_failure: str | None = None  # why the library could not be built or loaded (not retried)
_reported: set[str] = set()


def _variant() -> int:
    name = os.environ.get("HORIZON_MPC_RICCATI_ISA", "").strip().lower()
    if name not in _VARIANTS:
        raise ValueError(f"HORIZON_MPC_RICCATI_ISA={name!r}; expected one of 'auto', 'generic'")
    return _VARIANTS[name]


def _key(source: bytes) -> str:
    h = hashlib.sha256()
    # the machine too: a cache directory shared by x86-64 and aarch64 hosts keeps one of each
    for part in (source, " ".join(FLAGS).encode(), " ".join(codegen.CC_ARGV).encode(),
                 platform.machine().encode(), b"riccati-v2"):
        h.update(part)
        h.update(b"\0")
    return h.hexdigest()[:24]


def library_path() -> Path:
    """Where the compiled library of the current source lives (it may not exist yet)."""
    text = b"\0".join(path.read_bytes() for path in (*SOURCES, *HEADERS))
    return codegen.default_cache_dir() / f"riccati_{_key(text)}.so"


def _build(lib: Path) -> None:
    """Compile the sources to ``lib`` (:func:`horizon_mpc.codegen.build_shared_library`)."""
    started: list[float] = []

    def sources(_work: Path) -> list[str]:  # called once the build's lock is taken
        _log.info("compiling %s ...", ", ".join(path.name for path in SOURCES))
        started.append(time.perf_counter())
        return [*FLAGS, *map(str, SOURCES)]

    if codegen.build_shared_library(lib, sources, "the Riccati library"):
        _log.info("compiled the Riccati library in %.1f s -> %s",
                  time.perf_counter() - started[0], lib)
    else:
        _log.info("the Riccati library was compiled meanwhile by another process: loading it")


def _report(reason: str, level: int) -> None:
    """Log why the compiled recursion is unavailable, once per reason."""
    if reason not in _reported:
        _reported.add(reason)
        _log.log(level, "compiled Riccati recursion unavailable (use riccati.py's): %s", reason)


def _load() -> ctypes.CDLL:
    """The loaded library (compiled on first use); raises RuntimeError when unavailable."""
    global _lib, _failure
    if _lib is not None:
        return _lib
    if not codegen.codegen_enabled():
        _report("HORIZON_MPC_NO_CODEGEN is set", logging.INFO)
        raise RuntimeError("compiled Riccati recursion unavailable: HORIZON_MPC_NO_CODEGEN is set")
    if _failure is None:
        try:
            if shutil.which(codegen.CC_ARGV[0]) is None:
                raise RuntimeError(f"no C compiler: {codegen.CC_ARGV[0]!r} is not on PATH "
                                   "(set $CC)")
            lib = library_path()
            damage = codegen.library_damage(lib) if lib.is_file() else None
            if damage:  # loading a truncated library is a SIGBUS, not an OSError
                _log.warning("cached library %s is damaged (%s): rebuilding it", lib, damage)
                lib.unlink(missing_ok=True)
            if not lib.is_file():
                _build(lib)
            codegen.mark_used(lib)
            try:
                _lib = _open(lib)
            except (OSError, AttributeError) as err:  # a damaged cache entry (another
                # library under its name: a missing symbol): build it again, once
                _log.warning("could not load %s (%s); rebuilding it", lib, err)
                lib.unlink(missing_ok=True)  # else the build finds it there and keeps it
                _build(lib)
                _lib = _open(lib)
            return _lib
        except (OSError, RuntimeError, AttributeError) as err:
            _failure = str(err)
            _report(_failure, logging.WARNING)
    raise RuntimeError(f"compiled Riccati recursion unavailable: {_failure}")


def _open(path: Path) -> ctypes.CDLL:
    """The library at ``path``, its functions typed. A library without them (another one
    under its name) is closed again, so that a rebuilt one at the same path gets loaded
    (dlopen would hand back the open one).

    Raises:
        OSError: it does not load. AttributeError: a function is missing.
    """
    lib = ctypes.CDLL(str(path))
    try:
        return _bind(lib)
    except AttributeError:
        _ctypes.dlclose(lib._handle)
        raise


def _bind(lib: ctypes.CDLL) -> ctypes.CDLL:
    p, i, d = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
    lib.riccati_backward.argtypes = [i, i, i, ctypes.POINTER(p), p, d, p, p, ctypes.POINTER(p), i,
                                     p]
    lib.riccati_backward.restype = i
    lib.riccati_rollout.argtypes = [i, i, i, ctypes.POINTER(p), p, p, p, i]
    lib.riccati_rollout.restype = i
    lib.riccati_project.argtypes = [i, i, i, i, p, p, d, p, p, p, p, p, p, p, i]
    lib.riccati_project.restype = i
    lib.riccati_stack_rows.argtypes = [i, i, i, i, i, i, i, i, p, p, p, ctypes.POINTER(p), p, p,
                                       p, p, p, p]
    lib.riccati_stack_rows.restype = i
    lib.riccati_al_rows.argtypes = [i, p, p, p, p, p, p, p, i, d, d, p, p, p, p]
    lib.riccati_al_rows.restype = None
    lib.riccati_step_stats.argtypes = [i] * 4 + [p] * 12
    lib.riccati_step_stats.restype = i
    lib.riccati_has_avx2.argtypes = []
    lib.riccati_has_avx2.restype = i
    return lib


def available() -> bool:
    """True if the compiled recursion can be used (compiling it now if needed).

    False when ``HORIZON_MPC_NO_CODEGEN=1`` (checked at every call), when the C compiler is
    missing or fails (the reason is logged once, as a warning, and remembered for the process).
    """
    if not codegen.codegen_enabled():
        _report("HORIZON_MPC_NO_CODEGEN is set", logging.INFO)
        return False
    try:
        _load()
    except RuntimeError:
        return False
    return True


def uses_avx2() -> bool:
    """True if calls run the AVX2+FMA kernels: the CPU has both and
    ``HORIZON_MPC_RICCATI_ISA`` is not ``generic``. Raises RuntimeError when unavailable."""
    return bool(_load().riccati_has_avx2()) and _variant() != 1


def _forget() -> None:
    """Forget the loaded library and any failure (tests: change the environment, retry)."""
    global _lib, _failure
    _lib = None
    _failure = None
    _reported.clear()


def _strided(items: list[tuple[str, object, tuple[int, ...]]],
             n: int) -> tuple[ctypes.Array, np.ndarray, list[np.ndarray]]:
    """Pointers, element strides (n, 3) and the arrays of ``(name, array, shape)`` items.

    Arrays are passed as they are when they hold aligned float64 (any view, transposed or
    not); anything else is converted first. None items and entries past ``len(items)`` (up
    to ``n``) are null. Raises ValueError on a wrong shape: the C code trusts the shapes.
    """
    ptrs, strides, keep = [], [], []
    for name, arr, shape in items:
        if arr is None:
            keep.append(np.zeros(1))
            ptrs.append(None)
            strides += [0, 0, 0]
            continue
        a = arr if type(arr) is np.ndarray and arr.dtype == np.float64 else np.asarray(
            arr, dtype=np.float64)
        if a.shape != shape:
            raise ValueError(f"{name} has shape {a.shape}; expected {shape}")
        if not a.flags.aligned:  # e.g. a view into packed bytes
            a = np.ascontiguousarray(a)
        keep.append(a)
        ptrs.append(a.ctypes.data)
        strides += [*a.strides, 0, 0, 0][:3]
    strides += [0] * (3 * (n - len(items)))
    st = np.array(strides, np.int64).reshape(n, 3)
    for j in np.flatnonzero((st % 8).any(axis=1)):  # strides of partial elements: copy
        keep[j] = np.ascontiguousarray(keep[j])
        ptrs[j] = keep[j].ctypes.data
        st[j] = [*keep[j].strides, 0, 0, 0][:3]
    return (ctypes.c_void_p * n)(*ptrs), st // 8, keep


@dataclass(frozen=True)
class AbPattern:
    """The structural nonzeros of ``[A | B]`` (the same at every node), for
    :func:`backward_pass_c`: its products with A and B then cost O(nnz ndx) instead of
    O(ndx^3). Entries of A and B outside the pattern are never read (taken as zero).

    Build it with :meth:`from_mask`; ``data`` is the compressed-column form the C code reads
    (int32: ``ndx + nu + 1`` column pointers, then the row of each nonzero).
    """

    mask: np.ndarray  # (ndx, ndx + nu) bool
    data: np.ndarray

    @classmethod
    def from_mask(cls, mask: np.ndarray) -> AbPattern:
        """From a boolean (ndx, ndx + nu) mask of the entries that may be nonzero."""
        mask = np.array(mask, dtype=bool)
        if mask.ndim != 2 or mask.shape[1] < mask.shape[0]:
            raise ValueError(f"the pattern of [A | B] has shape {mask.shape}; expected "
                             "(ndx, ndx + nu)")
        col, row = np.nonzero(mask.T)  # by column, rows ascending within each
        pointers = np.concatenate([[0], np.cumsum(np.bincount(col, minlength=mask.shape[1]))])
        mask.setflags(write=False)
        return cls(mask, np.concatenate([pointers, row]).astype(np.int32))

    @property
    def density(self) -> float:
        """Fraction of the entries of [A | B] in the pattern."""
        return float(self.mask.mean()) if self.mask.size else 1.0


def _check_pattern(pattern: AbPattern | None, ndx: int, nu: int) -> None:
    if pattern is not None and pattern.mask.shape != (ndx, ndx + nu):
        raise ValueError(f"pattern has shape {pattern.mask.shape}; expected {(ndx, ndx + nu)}")


def _sizes(B) -> tuple[int, int, int]:
    """(N, ndx, nu) from the shape of B."""
    shape = np.shape(B)
    if len(shape) != 3:
        raise ValueError(f"B has shape {shape}; expected (N, ndx, nu)")
    return shape


def backward_pass_c(A: np.ndarray, B: np.ndarray, lx: np.ndarray, lu: np.ndarray, lxx: np.ndarray,
                    luu: np.ndarray, lux: np.ndarray, f: np.ndarray, lxN: np.ndarray,
                    lxxN: np.ndarray, mu: float, proj: Projection | None = None,
                    pattern: AbPattern | None = None,
                    box: tuple[np.ndarray, np.ndarray] | None = None) -> BackwardResult | None:
    """Riccati recursion with regularisation ``mu`` on Q_uu, in C; see
    :func:`.riccati.backward_pass` for the maths.

    Args:
        A (N, ndx, ndx), B (N, ndx, nu): linearised dynamics; f (N, ndx): defects.
        lx (N, ndx), lu (N, nu), lxx (N, ndx, ndx), luu (N, nu, nu), lux (N, nu, ndx):
            stage cost models; lxN (ndx,), lxxN (ndx, ndx): terminal ones.
        mu: Levenberg-Marquardt term added to the diagonal of every Q_uu.
        proj: null-space projection of the equality rows (:func:`.equality.project`).
        pattern: the structural nonzeros of [A | B] (None: dense); entries outside it must
            be zero, they are not read. Worth it when sparse: go2's walking dynamics fill
            5 % of it, and a go2 pass (30 nodes) takes 0.68 ms instead of 0.87.
        box: ``(lo, hi)`` (N, nu) bounds of ``du`` at the nodes without projected rows
            (:func:`.riccati.box_qp`), or None.

    Returns:
        :class:`.riccati.BackwardResult` (K, k, S, s, Qu, Quu, Qux), or None when a (reduced)
        Q_uu is not positive definite or a feed-forward term is not finite.

    Raises:
        RuntimeError: the compiled library is not available (see :func:`available`).
        ValueError: an array has the wrong shape.
    """
    lib = _load()
    N, ndx, nu = _sizes(B)
    _check_pattern(pattern, ndx, nu)
    items = [("A", A, (N, ndx, ndx)), ("B", B, (N, ndx, nu)), ("lx", lx, (N, ndx)),
             ("lu", lu, (N, nu)), ("lxx", lxx, (N, ndx, ndx)), ("luu", luu, (N, nu, nu)),
             ("lux", lux, (N, nu, ndx)), ("f", f, (N, ndx)), ("lxN", lxN, (ndx,)),
             ("lxxN", lxxN, (ndx, ndx))]
    con = None
    if proj is not None:
        con = np.ascontiguousarray(proj.constrained, dtype=np.uint8)
        if con.shape != (N,):
            raise ValueError(f"proj.constrained has shape {con.shape}; expected {(N,)}")
        items += [("proj.P_e", proj.P_e, (N, nu)), ("proj.P_x", proj.P_x, (N, nu, ndx)),
                  ("proj.Z", proj.Z, (N, nu, nu)), ("proj.free", proj.free, (N, nu))]
    else:
        items += [("proj.P_e", None, ()), ("proj.P_x", None, ()), ("proj.Z", None, ()),
                  ("proj.free", None, ())]
    if box is not None:
        items += [("box lo", box[0], (N, nu)), ("box hi", box[1], (N, nu))]
    ptrs, strides, _keep = _strided(items, 16)  # without proj or box: their entries are null
    # all outputs in one buffer: one allocation, one pointer per block
    shapes = ((N, nu, ndx), (N, nu), (N + 1, ndx, ndx), (N + 1, ndx), (N, nu), (N, nu, nu),
              (N, nu, ndx))
    sizes = [math.prod(sh) for sh in shapes]
    buf = np.empty(sum(sizes))
    out, out_ptrs, pos = [], (ctypes.c_void_p * 7)(), 0
    base = buf.ctypes.data
    for j, (sh, n) in enumerate(zip(shapes, sizes, strict=True)):
        out.append(buf[pos:pos + n].reshape(sh))
        out_ptrs[j] = base + 8 * pos
        pos += n
    fail = ctypes.c_int(-1)
    ret = lib.riccati_backward(N, ndx, nu, ptrs, strides.ctypes.data, float(mu),
                               None if con is None else con.ctypes.data,
                               None if pattern is None else pattern.data.ctypes.data, out_ptrs,
                               _variant(), ctypes.byref(fail))
    if ret == -1:
        raise MemoryError("riccati_backward: out of memory for its workspace")
    if ret != 0:
        _log.debug("backward pass failed at node %d (%s)", fail.value,
                   "Q_uu not positive definite" if ret == 1 else "k not finite")
        return None
    return BackwardResult(*out)


def linear_rollout_c(A: np.ndarray, B: np.ndarray, f: np.ndarray, bw: BackwardResult,
                     dx0: np.ndarray,
                     box: tuple[np.ndarray, np.ndarray] | None = None,
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The full step (dX (N+1, ndx), dU (N, nu)) of the LQ sub-problem, in C; see
    :func:`.riccati.linear_rollout` (``box``: (lo, hi) (N, nu) that du is clamped into).

    Raises:
        RuntimeError: the compiled library is not available (see :func:`available`).
        ValueError: an array has the wrong shape.
    """
    lib = _load()
    N, ndx, nu = _sizes(B)
    ptrs, strides, _keep = _strided([
        ("A", A, (N, ndx, ndx)), ("B", B, (N, ndx, nu)), ("f", f, (N, ndx)),
        ("bw.K", bw.K, (N, nu, ndx)), ("bw.k", bw.k, (N, nu)), ("dx0", dx0, (ndx,)),
        *([] if box is None else [("box lo", box[0], (N, nu)), ("box hi", box[1], (N, nu))])],
        8)
    dX = np.empty((N + 1, ndx))
    dU = np.empty((N, nu))
    if lib.riccati_rollout(N, ndx, nu, ptrs, strides.ctypes.data, dX.ctypes.data,
                           dU.ctypes.data, _variant()) != 0:
        raise MemoryError("riccati_rollout: out of memory for its workspace")
    return dX, dU


def _int32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int32)


def stack_rows_c(layout: EqualityLayout, c: np.ndarray, cx: np.ndarray, cu: np.ndarray,
                 cN: np.ndarray, cxN: np.ndarray, A: np.ndarray, B: np.ndarray, gap: np.ndarray,
                 pattern: AbPattern | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``equality._stack_rows`` in C: the rows ``[D | C | e]`` of every node and their mask.

    Same arguments and results (to rounding: the products with A and B sum in another
    order); ``pattern``: the structural nonzeros of [A | B] (None: dense), whose other
    entries are not read. The inputs are read through their strides (no copies).

    Raises:
        RuntimeError: the compiled library is not available (see :func:`available`).
        ValueError: an array has the wrong shape.
    """
    lib = _load()
    N, ndx, nu = _sizes(B)
    nc = layout.own.shape[1]
    ncN = layout.term.shape[0]
    *cols, m = _slots(layout)
    own_cols, nxt_cols, term_cols = map(_int32, cols)
    if m == 0 or nu == 0:
        return np.zeros((N * m + 1, nu + ndx + 1)), np.zeros((N, m), bool)
    _check_pattern(pattern, ndx, nu)
    W_flat = np.empty((N * m + 1, nu + ndx + 1))
    rows = np.empty((N, m), bool)
    ptrs, strides, _keep = _strided([
        ("c", c, (N, nc)), ("layout.b", layout.b, (N, nc)), ("cx", cx, (N, nc, ndx)),
        ("cu", cu, (N, nc, nu)), ("cN", cN, (ncN,)), ("layout.bN", layout.bN, (ncN,)),
        ("cxN", cxN, (ncN, ndx)), ("A", A, (N, ndx, ndx)), ("B", B, (N, ndx, nu)),
        ("gap", gap, (N, ndx))], 10)
    # bool masks as bytes, without a copy when they are contiguous already
    own = np.ascontiguousarray(layout.own, dtype=bool).view(np.uint8)
    nxt = np.ascontiguousarray(layout.next, dtype=bool).view(np.uint8)
    if own.shape != (N, nc) or nxt.shape != (N, nc):
        raise ValueError(f"layout.own/next have shapes {own.shape}/{nxt.shape}; expected "
                         f"{(N, nc)}")
    k, j, jt = len(own_cols), len(nxt_cols), len(term_cols)
    if lib.riccati_stack_rows(N, nu, ndx, nc, m, k, j, jt, own_cols.ctypes.data,
                              nxt_cols.ctypes.data, term_cols.ctypes.data, ptrs,
                              strides.ctypes.data, own.ctypes.data, nxt.ctypes.data,
                              None if pattern is None else pattern.data.ctypes.data,
                              W_flat.ctypes.data, rows.view(np.uint8).ctypes.data) != 0:
        raise MemoryError("riccati_stack_rows: out of memory for its workspace")
    return W_flat, rows


def project_rows_c(W_flat: np.ndarray, rows: np.ndarray, nu: int,
                   rtol: float) -> tuple[np.ndarray, ...]:
    """The per-node QR projection of :func:`.equality.project`, in C, for every node.

    Args:
        W_flat (N m + 1, nu + ndx + 1), rows (N, m): as ``equality._stack_rows`` returns them.
        nu: inputs per node; rtol: the independence threshold of ``equality.project``.

    Returns:
        ``(P_e (N, nu), P_x (N, nu, ndx), Z (N, nu, nu), free (N, nu), pinv (N, nu, m),
        ok (N,), unmet (N,))``; where ``ok`` is False (more rows than ``nu``, rows (nearly)
        dependent or not finite) the node's other outputs are meaningless: take the SVD.

    Raises:
        RuntimeError: the compiled library is not available (see :func:`available`).
        ValueError: the shapes do not fit.
    """
    lib = _load()
    n, m = rows.shape
    W = np.ascontiguousarray(W_flat, dtype=np.float64)
    if W.ndim != 2 or W.shape[0] != n * m + 1 or W.shape[1] < nu + 1:
        raise ValueError(f"W_flat has shape {W.shape}; expected ({n * m + 1}, nu + ndx + 1)")
    ndx = W.shape[1] - nu - 1
    mask = np.ascontiguousarray(rows, dtype=np.uint8)
    P_e, P_x = np.empty((n, nu)), np.empty((n, nu, ndx))
    Z, free, pinv = np.empty((n, nu, nu)), np.empty((n, nu)), np.empty((n, nu, m))
    ok, unmet = np.empty(n, np.uint8), np.empty(n, np.uint8)
    ret = lib.riccati_project(n, m, nu, ndx, W.ctypes.data, mask.ctypes.data, float(rtol),
                              P_e.ctypes.data, P_x.ctypes.data, Z.ctypes.data,
                              free.ctypes.data, pinv.ctypes.data, ok.ctypes.data,
                              unmet.ctypes.data, _variant())
    if ret != 0:
        raise MemoryError("riccati_project: out of memory for its workspace")
    return P_e, P_x, Z, free, pinv, ok.astype(bool), unmet.astype(bool)


def _contiguous(name: str, a, shape: tuple[int, ...]) -> np.ndarray:
    """``a`` as a C-contiguous float64 array (no copy when it is one); ValueError on a wrong
    shape: the C code trusts the shapes."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"{name} has shape {a.shape}; expected {shape}")
    return a


def step_stats_c(lx: np.ndarray, lu: np.ndarray, lxN: np.ndarray, s: np.ndarray, S: np.ndarray,
                 Qu: np.ndarray, Quu: np.ndarray, Qux: np.ndarray, dX: np.ndarray, dU: np.ndarray,
                 pinv: np.ndarray) -> tuple[float, float, float, float]:
    """:func:`.merit.step_stats` in one compiled pass: the same arguments (any array layout;
    non-contiguous ones are copied) and results.

    Raises:
        RuntimeError: the compiled library is not available (see :func:`available`).
        ValueError: an array has the wrong shape.
    """
    lib = _load()
    N, nu = np.shape(dU)
    ndx = np.shape(dX)[1]
    m = 0 if pinv is None else np.shape(pinv)[2]
    arrays = [_contiguous("lx", lx, (N, ndx)), _contiguous("lu", lu, (N, nu)),
              _contiguous("lxN", lxN, (ndx,)), _contiguous("s", s, (N + 1, ndx)),
              _contiguous("S", S, (N + 1, ndx, ndx)), _contiguous("Qu", Qu, (N, nu)),
              _contiguous("Quu", Quu, (N, nu, nu)), _contiguous("Qux", Qux, (N, nu, ndx)),
              _contiguous("dX", dX, (N + 1, ndx)), _contiguous("dU", dU, (N, nu))]
    if m:  # kept alive until the call
        pinv = _contiguous("pinv", pinv, (N, nu, m))
    out = np.empty(4)
    if lib.riccati_step_stats(N, ndx, nu, m, *(a.ctypes.data for a in arrays),
                              pinv.ctypes.data if m else None, out.ctypes.data):
        raise MemoryError("riccati_step_stats: out of memory for its workspace")
    return tuple(out.tolist())


class AlRowsKernel:
    """The augmented-Lagrangian / relaxed-barrier terms of a block of constraint rows in one
    compiled pass (``riccati_al_rows``): what :class:`.lagrangian.AugmentedLagrangian`
    computes with numpy, without its ~20 numpy calls per evaluation.

    Bound to the arrays of the rows (``lb``, ``ub``, ``lam``, ``lam_lo``, ``lam_up``,
    ``rho``: C-contiguous float64 of one shape); they are read in place at every call, so
    they must stay the same objects (update them in place); new bounds through
    :meth:`set_bounds`.

    Raises:
        RuntimeError: the compiled library is not available (see :func:`available`).
        ValueError: the arrays are not C-contiguous float64 of one shape.
    """

    def __init__(self, lb: np.ndarray, ub: np.ndarray, lam: np.ndarray, lam_lo: np.ndarray,
                 lam_up: np.ndarray, rho: np.ndarray):
        self._lib = _load()
        self.shape = lb.shape
        self.n = int(lb.size)
        self._multipliers = self._checked(lam, lam_lo, lam_up, rho)  # kept alive: pointers
        self._multiplier_ptrs = tuple(a.ctypes.data for a in self._multipliers)
        self._sums = np.zeros(2)
        self._sums_ptr = self._sums.ctypes.data
        self.set_bounds(lb, ub)

    def _checked(self, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
        for a in arrays:
            if (type(a) is not np.ndarray or a.dtype != np.float64 or a.shape != self.shape
                    or not a.flags.c_contiguous):
                raise ValueError("AlRowsKernel: the row arrays must be C-contiguous float64 of "
                                 f"one shape ({self.shape})")
        return arrays

    def set_bounds(self, lb: np.ndarray, ub: np.ndarray) -> None:
        """Read these bounds from now on (same rules as the constructor's arrays)."""
        self._bounds = self._checked(lb, ub)  # kept alive: pointers
        self._ptrs = (lb.ctypes.data, ub.ctypes.data, *self._multiplier_ptrs)

    def __call__(self, c: np.ndarray, barrier: bool, mu: float, delta: float,
                 weights: bool = False) -> tuple[float, float, np.ndarray | None,
                                                 np.ndarray | None]:
        """``(value, max violation, w, t)`` at constraint values ``c`` (the rows' shape);
        ``w``, ``t`` (Gauss-Newton weights and targets) only with ``weights``, else None."""
        c = np.ascontiguousarray(c, dtype=np.float64)
        if c.shape != self.shape:
            raise ValueError(f"c has shape {c.shape}; expected {self.shape}")
        w = t = None
        wp = tp = None
        if weights:
            w, t = np.empty(self.shape), np.empty(self.shape)
            wp, tp = w.ctypes.data, t.ctypes.data
        self._lib.riccati_al_rows(self.n, c.ctypes.data, *self._ptrs, int(barrier), mu, delta,
                                  wp, tp, None, self._sums_ptr)
        return float(self._sums[0]), float(self._sums[1]), w, t
