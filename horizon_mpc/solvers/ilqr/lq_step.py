"""The LQ step of an ILQR iteration in three compiled calls on arrays bound once
(``lq_step.c``).

:class:`CompiledLqStep` does what ``IlqrSolver._lq_step`` and ``_step`` do through
:mod:`.riccati_c`'s wrappers (the projected equality rows stacked and factorised by
:func:`.equality.project`, :func:`.riccati_c.backward_pass_c`,
:func:`.riccati_c.linear_rollout_c`, :func:`.riccati_c.step_stats_c`) with the same C
kernels and results, without the wrappers' per-call work: the pointer and stride tables
of ~30 arrays (the quadratisation's blocks are bound once: they live in the compiled
evaluation's persistent buffer) and fresh output arrays (~1 MB per go2 iteration). On
go2's walking MPC those wrappers cost ~0.5 ms per tick in the closed loop, ~13 % of it.

Outputs are persistent and overwritten by the next call of the same kind: the
:class:`.equality.Projection` of :meth:`CompiledLqStep.project`, the
:class:`.riccati.BackwardResult` of :meth:`CompiledLqStep.backward` and the step
of :meth:`CompiledLqStep.rollout`. A failed backward pass overwrites the last result (its
rollout is refused until a pass succeeds) except its gains: they rotate through three
arrays, a pass writing neither the last good pass's nor those of the last step rolled out,
so the gains of the step taken stay valid until the next rollout.
"""

from __future__ import annotations

import ctypes
import logging
from collections.abc import Mapping
from typing import Any

import numpy as np

from horizon_mpc.solvers.ilqr import riccati_c
from horizon_mpc.solvers.ilqr.equality import (
    EqualityLayout,
    Projection,
    _slots,
    fill_by_svd,
)
from horizon_mpc.solvers.ilqr.riccati import BackwardResult

__all__ = ["CompiledLqStep"]

log = logging.getLogger(__name__)

_p, _i, _d = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
_N_SR, _N_IN, _N_OUT, _N_RO = 10, 16, 7, 8  # riccati.h's argument counts
_IN_BLO, _RO_LO = 14, 6  # the box entries of the backward and rollout tables (lo, then hi)


class _LqStep(ctypes.Structure):  # lq_step of lq_step.c
    _fields_ = [("N", _i), ("ndx", _i), ("nu", _i), ("nc", _i), ("ncN", _i), ("variant", _i),
                ("rtol", _d), ("pat", _p),
                ("sr_in", _p * _N_SR), ("sr_st", ctypes.c_int64 * (3 * _N_SR)),
                ("bw_in", _p * _N_IN), ("bw_st", ctypes.c_int64 * (3 * _N_IN)),
                ("bw_out", _p * _N_OUT),
                ("ro_in", _p * _N_RO), ("ro_st", ctypes.c_int64 * (3 * _N_RO)),
                ("W", _p), ("P_e", _p), ("P_x", _p), ("Z", _p), ("fr", _p), ("pinv", _p),
                ("rows", _p), ("ok", _p), ("unmet", _p), ("con", _p),
                ("dX", _p), ("dU", _p), ("lx", _p), ("lu", _p), ("lxN", _p)]


def _bind_library() -> ctypes.CDLL:
    lib = riccati_c._load()
    if not getattr(lib, "_lq_step_bound", False):
        ptr = ctypes.POINTER(_LqStep)
        lib.lq_project.argtypes = [ptr, *[_p] * 7, *[_i] * 4, _p, _p, _p]
        lib.lq_project.restype = _i
        lib.lq_backward.argtypes = [ptr, _p, _d, _i, _p, ctypes.POINTER(_i)]
        lib.lq_backward.restype = _i
        lib.lq_rollout.argtypes = [ptr, _p, _p, _p, _i, _p]
        lib.lq_rollout.restype = _i
        lib._lq_step_bound = True
    return lib


def _table(items: list[tuple[str, np.ndarray | None, tuple[int, ...]]], ptrs: ctypes.Array,
           strides: ctypes.Array) -> None:
    """Fill a pointer table and its element strides (node, row, column) from ``(name,
    array, shape)`` items: bound arrays as they are (any strided view of aligned float64;
    ValueError when one would need a copy: the C code would read a stale one), None for a
    per-call array, whose strides are those of a C-contiguous array of that shape."""
    for j, (name, arr, shape) in enumerate(items):
        if arr is None:
            st = [*np.empty(shape, np.float64).strides]
        else:
            if arr.shape != shape or arr.dtype != np.float64 or not arr.flags.aligned:
                raise ValueError(f"{name}: {arr.dtype} {arr.shape}, expected aligned float64 "
                                 f"{shape}")
            if any(s % 8 for s in arr.strides):
                raise ValueError(f"{name}: strides {arr.strides} are not whole elements")
            st = [*arr.strides]
            ptrs[j] = arr.ctypes.data
        for d, s in enumerate([*st, 0, 0, 0][:3]):
            strides[3 * j + d] = s // 8


class CompiledLqStep:
    """The projection, backward pass, rollout and step measures of an ILQR iteration on the
    quadratisation's persistent blocks; see the module docstring.

    Args:
        q: the quadratisation's blocks as ``IlqrSolver._quadratise`` returns them (A, B, lx,
            lu, lxx, luu, lux, lxN, lxxN, cx, cu, cxN), views of a buffer that stays where
            it is (read in place by every call; lx and lu C-contiguous).
        sizes: N, ndx, nu, nc (constraint rows per node), ncN (terminal constraint rows),
            ldc (the row length of the evaluation's ``c``, whose first nc columns are the
            constraint rows).
        pattern: the structural nonzeros of [A | B] (None: dense).
        rtol: the independence threshold of :func:`.equality.project`.
    """

    def __init__(self, q: Mapping[str, np.ndarray], sizes: Mapping[str, int],
                 pattern: riccati_c.AbPattern | None = None, rtol: float = 1e-9):
        self._lib = _bind_library()
        N, ndx, nu, nc, ncN = (int(sizes[k]) for k in ("N", "ndx", "nu", "nc", "ncN"))
        self.N, self.ndx, self.nu, self.nc, self.ncN, self.ldc = N, ndx, nu, nc, ncN, int(
            sizes["ldc"])
        if nu == 0 or N == 0:
            raise ValueError("the compiled LQ step needs inputs and nodes")
        for name, shape in (("lx", (N, ndx)), ("lu", (N, nu))):
            if q[name].shape != shape or not q[name].flags.c_contiguous:
                raise ValueError(f"{name} must be C-contiguous {shape}")
        self._q = dict(q)  # kept alive: the C code reads them
        self.rtol = float(rtol)
        s = self._s = _LqStep(N=N, ndx=ndx, nu=nu, nc=nc, ncN=ncN,
                              variant=riccati_c._variant(), rtol=self.rtol)
        self._pattern = pattern  # kept alive: the C code reads its data
        if pattern is not None:
            riccati_c._check_pattern(pattern, ndx, nu)
            s.pat = pattern.data.ctypes.data
        # projection outputs, sized for the most slots a node can have
        m_max = nc + max(nc, ncN)
        w = nu + ndx + 1
        self._W = np.zeros((N * m_max + 1) * w)
        self._rows = np.zeros(N * m_max, np.uint8)
        self._pinv = np.zeros(N * nu * m_max)
        self.P_e, self.P_x = np.zeros((N, nu)), np.zeros((N, nu, ndx))
        self.Z, self.free = np.zeros((N, nu, nu)), np.zeros((N, nu))
        self._ok, self._unmet, self._con = (np.zeros(N, np.uint8) for _ in range(3))
        # backward outputs: three gain arrays (see the module docstring), then the rest
        self._K = tuple(np.zeros((N, nu, ndx)) for _ in range(3))
        self._bw = (np.zeros((N, nu)), np.zeros((N + 1, ndx, ndx)), np.zeros((N + 1, ndx)),
                    np.zeros((N, nu)), np.zeros((N, nu, nu)), np.zeros((N, nu, ndx)))
        self._results = tuple(BackwardResult(K, *self._bw) for K in self._K)
        self._cur = 0  # self._results[self._cur] is the last good pass
        self._rolled = 0  # the gains of the last rollout (not written until the next one)
        self._valid = False  # no failed pass since the last good one
        self.dX, self.dU = np.zeros((N + 1, ndx)), np.zeros((N, nu))
        # the box of du (riccati.py's), filled in place by the caller; used by a backward
        # pass and a rollout called with box=True
        self.box_lo, self.box_hi = np.full((N, nu), -np.inf), np.full((N, nu), np.inf)
        self._stats = np.zeros(4)
        for name in ("W", "rows", "pinv"):
            setattr(s, name, getattr(self, "_" + name).ctypes.data)
        s.P_e, s.P_x, s.Z, s.fr = (a.ctypes.data for a in (self.P_e, self.P_x, self.Z,
                                                            self.free))
        s.ok, s.unmet, s.con = (a.ctypes.data for a in (self._ok, self._unmet, self._con))
        s.dX, s.dU = self.dX.ctypes.data, self.dU.ctypes.data
        s.lx, s.lu = q["lx"].ctypes.data, q["lu"].ctypes.data
        lxN = np.ascontiguousarray(q["lxN"]).reshape(ndx)
        if not np.shares_memory(lxN, q["lxN"]):
            raise ValueError("lxN must be contiguous")
        s.lxN = lxN.ctypes.data
        _table([("c", None, (N, self.ldc)), ("b", None, (N, nc)),
                ("cx", q["cx"], (N, nc, ndx)), ("cu", q["cu"], (N, nc, nu)),
                ("cN", None, (max(ncN, 1),)), ("bN", None, (max(ncN, 1),)),
                ("cxN", q["cxN"], (ncN, ndx)), ("A", q["A"], (N, ndx, ndx)),
                ("B", q["B"], (N, ndx, nu)), ("gap", None, (N, ndx))], s.sr_in, s.sr_st)
        _table([("A", q["A"], (N, ndx, ndx)), ("B", q["B"], (N, ndx, nu)),
                ("lx", q["lx"], (N, ndx)), ("lu", q["lu"], (N, nu)),
                ("lxx", q["lxx"], (N, ndx, ndx)), ("luu", q["luu"], (N, nu, nu)),
                ("lux", q["lux"], (N, nu, ndx)), ("f", None, (N, ndx)),
                ("lxN", lxN, (ndx,)), ("lxxN", q["lxxN"], (ndx, ndx)),
                ("P_e", self.P_e, (N, nu)), ("P_x", self.P_x, (N, nu, ndx)),
                ("Z", self.Z, (N, nu, nu)), ("free", self.free, (N, nu)),
                ("box lo", self.box_lo, (N, nu)), ("box hi", self.box_hi, (N, nu))],
               s.bw_in, s.bw_st)
        for j, a in enumerate(self._bw):
            s.bw_out[j + 1] = a.ctypes.data
        _table([("A", q["A"], (N, ndx, ndx)), ("B", q["B"], (N, ndx, nu)),
                ("f", None, (N, ndx)), ("K", None, (N, nu, ndx)),
                ("k", self._bw[0], (N, nu)), ("dx0", None, (ndx,)),
                ("box lo", self.box_lo, (N, nu)), ("box hi", self.box_hi, (N, nu))],
               s.ro_in, s.ro_st)
        self._box_ptrs = (self.box_lo.ctypes.data, self.box_hi.ctypes.data)
        self._set_box(s.bw_in, _IN_BLO, False)  # no box until a call asks for it
        self._set_box(s.ro_in, _RO_LO, False)
        self._ptr = ctypes.pointer(s)
        self._K_ptr = tuple(K.ctypes.data for K in self._K)
        self._stats_ptr = self._stats.ctypes.data
        self._fail = ctypes.c_int(-1)
        self._views: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._no_rows = np.zeros(1)  # cN and bN without terminal rows (never read)
        self._projection: Projection | None = None

    @classmethod
    def create(cls, *args: Any, **kwargs: Any) -> CompiledLqStep | None:
        """An instance, or None when the compiled library is unavailable or the blocks cannot
        be bound in place (logged): the solver then calls the wrappers, the same numbers
        more slowly."""
        if not riccati_c.available():
            return None
        try:
            return cls(*args, **kwargs)
        except (RuntimeError, OSError, ValueError, KeyError) as err:
            log.info("ilqr: the compiled LQ step is unavailable (%s); using the wrappers", err)
            return None

    def _slot_views(self, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """W_flat (N m + 1, nu + ndx + 1), rows (N, m) bool and pinv (N, nu, m) for m slots."""
        views = self._views.get(m)
        if views is None:
            N, w = self.N, self.nu + self.ndx + 1
            views = self._views[m] = (self._W[:(N * m + 1) * w].reshape(N * m + 1, w),
                                      self._rows[:N * m].view(bool).reshape(N, m),
                                      self._pinv[:N * self.nu * m].reshape(N, self.nu, m))
        return views

    @staticmethod
    def _pointer(name: str, a: np.ndarray, shape: tuple[int, ...], dtype: type) -> int:
        if a.shape != shape or a.dtype != dtype or not a.flags.c_contiguous:
            raise ValueError(f"{name}: {a.dtype} {a.shape}, expected C-contiguous {dtype} "
                             f"{shape}")
        return a.ctypes.data

    def project(self, layout: EqualityLayout, c: np.ndarray, cN: np.ndarray,
                gap: np.ndarray) -> Projection:
        """:func:`.equality.project` (method ``'qr'``, this instance's ``rtol`` and pattern)
        of ``layout``'s rows, from the evaluation's c (N, ldc), cN (>= ncN,) and gap
        (N, ndx), C-contiguous; the quadratisation's blocks are read where they were bound.
        Nodes the QR cannot take go through the SVD, as there.

        Raises:
            ValueError: a shape or layout does not fit.
            MemoryError: no memory for the C code's workspace.
        """
        N, nc, ncN = self.N, self.nc, self.ncN
        own_cols, nxt_cols, term_cols, m = _slots(layout)
        if m == 0:
            raise ValueError("the layout has no projected row")
        cols = [riccati_c._int32(a) for a in (own_cols, nxt_cols, term_cols)]
        own = np.ascontiguousarray(layout.own, dtype=bool)
        nxt = np.ascontiguousarray(layout.next, dtype=bool)
        W_flat, rows, pinv = self._slot_views(m)
        self._s.pinv = pinv.ctypes.data
        bad = self._lib.lq_project(
            self._ptr, self._pointer("c", c, (N, self.ldc), np.float64),
            self._pointer("b", layout.b, (N, nc), np.float64),
            self._pointer("cN", cN[:ncN] if ncN else self._no_rows, (max(ncN, 1),),
                          np.float64),
            self._pointer("bN", layout.bN if ncN else self._no_rows, (max(ncN, 1),),
                          np.float64),
            self._pointer("gap", gap, (N, self.ndx), np.float64),
            self._pointer("own", own, (N, nc), bool), self._pointer("nxt", nxt, (N, nc), bool),
            m, len(cols[0]), len(cols[1]), len(cols[2]), *(a.ctypes.data for a in cols))
        if bad < 0:
            raise MemoryError("lq_project: out of memory for its workspace")
        unmet = self._unmet.view(bool)
        if bad:
            fb = np.flatnonzero(self._ok == 0)
            fill_by_svd({"P_x": self.P_x, "P_e": self.P_e, "Z": self.Z, "free": self.free,
                         "pinv": pinv, "unmet": unmet}, W_flat, rows, fb, self.nu, self.rtol)
        self._projection = Projection(self.P_e, self.P_x, self.Z, self.free, pinv, rows,
                                      self._con.view(bool), int(np.count_nonzero(unmet)))
        return self._projection

    def _set_box(self, table: ctypes.Array, first: int, box: bool) -> None:
        table[first], table[first + 1] = self._box_ptrs if box else (None, None)

    def backward(self, gap: np.ndarray, mu: float, proj: Projection | None,
                 box: bool = False) -> BackwardResult | None:
        """:func:`.riccati_c.backward_pass_c` of the bound quadratisation with the defects
        gap (N, ndx) (C-contiguous), regularisation ``mu``, ``proj`` (None, or the last
        :meth:`project`'s result) and, with ``box``, the box ``(box_lo, box_hi)``. None when
        a (reduced) Q_uu is not positive definite or a feed-forward term is not finite (the
        earlier results' gains stay as they were).

        Raises:
            ValueError: ``proj`` is not this instance's last projection, or gap's shape.
            MemoryError: no memory for the C code's workspace.
        """
        if proj is not None and proj is not self._projection:
            raise ValueError("proj must be the last projection of this CompiledLqStep")
        nxt = ({0, 1, 2} - {self._cur, self._rolled}).pop()
        self._valid = False
        self._set_box(self._s.bw_in, _IN_BLO, box)
        ret = self._lib.lq_backward(self._ptr, self._pointer("gap", gap, (self.N, self.ndx),
                                                             np.float64),
                                    float(mu), proj is not None, self._K_ptr[nxt],
                                    ctypes.byref(self._fail))
        if ret == -1:
            raise MemoryError("riccati_backward: out of memory for its workspace")
        if ret != 0:
            log.debug("backward pass failed at node %d (%s)", self._fail.value,
                      "Q_uu not positive definite" if ret == 1 else "k not finite")
            return None
        self._cur, self._valid = nxt, True
        return self._results[nxt]

    def rollout(self, gap: np.ndarray, bw: BackwardResult, dx0: np.ndarray,
                proj: Projection | None, box: bool = False,
                ) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float]]:
        """The full step ``dX (N+1, ndx), dU (N, nu)`` of the last backward pass ``bw`` from
        dx0 (ndx,) with the defects gap (N, ndx) (``box``: du clamped into the box), and
        its measures (slope, largest
        multiplier estimate, max |dX|, max |dU|) as :func:`.merit.step_stats` gives them
        (with proj's D^+). dX and dU are overwritten by the next call.

        Raises:
            ValueError: ``bw`` or ``proj`` are not this instance's last ones, or a shape.
            MemoryError: no memory for the C code's workspace.
        """
        if bw is not self._results[self._cur] or not self._valid:
            raise ValueError("bw must be the last backward pass of this CompiledLqStep, "
                             "successful")
        if proj is not None and proj is not self._projection:
            raise ValueError("proj must be the last projection of this CompiledLqStep")
        dx0 = np.ascontiguousarray(dx0, dtype=np.float64)
        m = 0 if proj is None else proj.pinv.shape[2]
        self._set_box(self._s.ro_in, _RO_LO, box)
        if self._lib.lq_rollout(self._ptr, self._pointer("gap", gap, (self.N, self.ndx),
                                                         np.float64),
                                self._K_ptr[self._cur],
                                self._pointer("dx0", dx0, (self.ndx,), np.float64), m,
                                self._stats_ptr):
            raise MemoryError("lq_rollout: out of memory for its workspace")
        self._rolled = self._cur
        slope, lam, dx, du = self._stats.tolist()
        return self.dX, self.dU, (slope, lam, dx, du)
