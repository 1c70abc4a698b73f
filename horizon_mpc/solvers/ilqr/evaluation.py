"""The ILQR's evaluation and quadratisation of its problem, each in one compiled call
(``evaluation.c``).

:class:`CompiledEvaluation` does what ``IlqrSolver._evaluate`` does with numpy (the value
functions of the stage model, the state difference at node 0, ``merit.evaluation_stats``
and ``AugmentedLagrangian.value_and_violation`` of both row blocks) and what
``IlqrSolver._quadratise`` does (the rows' Gauss-Newton weights and targets, the
quadratisation functions, the finiteness test of their outputs), with the C code calling
the CasADi-generated functions directly through their C entry points: one ctypes call
instead of ~40 numpy and CasADi calls (~0.2 ms of Python per evaluation on go2's walking
problem, two to three evaluations per MPC tick).

It needs the value functions compiled by :func:`horizon_mpc.codegen.compile_function`
(their libraries are where the entry points come from) and the compiled Riccati library;
:func:`CompiledEvaluation.create` returns None otherwise and the solver keeps numpy.
"""

from __future__ import annotations

import ctypes
import logging
from typing import Any

import casadi as cs
import numpy as np

from horizon_mpc import codegen
from horizon_mpc.solvers.ilqr import riccati_c
from horizon_mpc.solvers.ilqr.lagrangian import AugmentedLagrangian

__all__ = ["CompiledEvaluation", "GeneratedFunction"]

log = logging.getLogger(__name__)

_p, _i, _d = ctypes.c_void_p, ctypes.c_int, ctypes.c_double


class GeneratedFunction(ctypes.Structure):
    """A CasADi-generated function's C entry point with its argument, result and work
    arrays (``generated_fn`` of evaluation.c). Build it with :meth:`bind`."""

    _fields_ = [("f", _p), ("arg", ctypes.POINTER(_p)), ("res", ctypes.POINTER(_p)),
                ("iw", _p), ("w", _p)]

    @classmethod
    def bind(cls, fn: cs.Function) -> GeneratedFunction:
        """The entry point of ``fn``, a Function from ``codegen.compile_function``.

        Raises:
            RuntimeError: ``fn`` is not backed by a library of ``compile_function`` (e.g.
                ``HORIZON_MPC_NO_CODEGEN``) or the library's integer or real types are
                not 64-bit.
        """
        path = codegen.compiled_library(fn)
        if path is None:
            raise RuntimeError(f"{fn.name()} is not a compiled function (compile_function)")
        lib = ctypes.CDLL(str(path))
        name = fn.name()
        for kind in ("int", "real"):
            size_fn = getattr(lib, f"{name}_casadi_{kind}_size")
            size_fn.restype = _i
            if size_fn() != 8:
                raise RuntimeError(f"{path.name}: casadi_{kind} is not 64-bit")
        sizes = (ctypes.c_longlong * 4)()
        work = getattr(lib, f"{name}_work")
        work.restype = _i
        if work(*(ctypes.byref(sizes, 8 * i) for i in range(4))) != 0:
            raise RuntimeError(f"{name}_work failed")
        n_arg = max(int(sizes[0]), fn.n_in())
        n_res = max(int(sizes[1]), fn.n_out())
        arg, res = (_p * n_arg)(), (_p * n_res)()
        iw = np.zeros(max(int(sizes[2]), 1), np.int64)
        w = np.zeros(max(int(sizes[3]), 1))
        out = cls(ctypes.cast(getattr(lib, name), _p), ctypes.cast(arg, ctypes.POINTER(_p)),
                  ctypes.cast(res, ctypes.POINTER(_p)), iw.ctypes.data, w.ctypes.data)
        out._keep = (lib, arg, res, iw, w)  # the arrays the pointers point into
        return out


class _AlBlock(ctypes.Structure):
    _fields_ = [("n", _i), ("lb", _p), ("ub", _p), ("lam", _p), ("lam_lo", _p),
                ("lam_up", _p), ("rho", _p)]


class _Data(ctypes.Structure):  # evaluation_data of evaluation.c
    _fields_ = [*((name, _i) for name in ("N", "nx", "ndx", "nr", "nc", "ncon", "nrN", "ncN",
                                          "ncNcon", "npar", "barrier")),
                ("mu", _d), ("delta", _d), ("values", GeneratedFunction),
                ("values_term", GeneratedFunction), ("difference", GeneratedFunction),
                *((name, _p) for name in ("S", "P", "x_init", "W", "WN", "b", "bN", "eq",
                                          "eqN")),
                ("al", _AlBlock), ("alN", _AlBlock)]


class _Out(ctypes.Structure):  # evaluation_out of evaluation.c
    _fields_ = [(name, _p) for name in ("gap", "r", "c", "rN", "cN", "d0")]


class _Quadratise(ctypes.Structure):  # quadratise_data of evaluation.c
    _fields_ = [("stage", GeneratedFunction), ("term", GeneratedFunction), ("w", _p),
                ("t", _p), ("wN", _p), ("tN", _p), ("out", _p * 9), ("out_term", _p * 3),
                ("buffer", _p), ("n_buffer", ctypes.c_size_t)]


def _output_views(buffer: np.ndarray, fns: tuple[cs.Function, ...]) -> list[list[np.ndarray]]:
    """The outputs of ``fns`` as consecutive blocks of ``buffer``, each shaped as the
    Function's output (column-major, as ``BufferedFunction.outputs``)."""
    views, pos = [], 0
    for fn in fns:
        out = []
        for i in range(fn.n_out()):
            n = fn.numel_out(i)
            out.append(buffer[pos:pos + n].reshape(fn.size_out(i), order="F"))
            pos += n
        views.append(out)
    if pos != buffer.size:
        raise ValueError("output buffer of the wrong size")
    return views


def _bind_library() -> ctypes.CDLL:
    lib = riccati_c._load()
    if not getattr(lib, "_evaluation_bound", False):
        lib.ilqr_evaluate.argtypes = [ctypes.POINTER(_Data), _p, _p, ctypes.POINTER(_Out), _p]
        lib.ilqr_evaluate.restype = _i
        lib.ilqr_quadratise.argtypes = [ctypes.POINTER(_Data), ctypes.POINTER(_Quadratise),
                                        _p, _p, _p, _p]
        lib.ilqr_quadratise.restype = _i
        lib._evaluation_bound = True
    return lib


class CompiledEvaluation:
    """``IlqrSolver._evaluate`` and ``_quadratise`` in one compiled call each; see the
    module docstring.

    Evaluation outputs (row-major, overwritten by each call): ``gap`` (N, ndx), ``r``
    (N, nr), ``c`` (N, nc), ``rN`` (nrN,), ``cN`` (ncN,), ``d0`` (ndx,); quadratisation
    outputs: ``quadratisation`` and ``quadratisation_term``, the outputs of the stage and
    terminal functions shaped as theirs (as ``BufferedFunction.outputs``), in one flat
    ``quadratisation_buffer``. The problem data are set with :meth:`set_problem` (after the
    solver reads the problem) and :meth:`set_initial_state`.
    """

    def __init__(self, values: cs.Function, values_term: cs.Function,
                 difference: cs.Function, quadratise: cs.Function,
                 quadratise_term: cs.Function, sizes: dict[str, int],
                 al: AugmentedLagrangian, alN: AugmentedLagrangian):
        self._lib = _bind_library()
        self._fns = tuple(GeneratedFunction.bind(f) for f in (values, values_term, difference))
        s = sizes
        self.N, self.nx, self.nu = s["N"], s["nx"], s["nu"]
        d = self._data = _Data()
        for name in ("N", "nx", "ndx", "nr", "nc", "ncon", "nrN", "ncN", "ncNcon", "npar"):
            setattr(d, name, int(s[name]))
        d.values, d.values_term, d.difference = self._fns
        self.gap, self.r = np.zeros((s["N"], s["ndx"])), np.zeros((s["N"], s["nr"]))
        self.c = np.zeros((s["N"], s["nc"]))
        self.rN, self.cN, self.d0 = np.zeros(s["nrN"]), np.zeros(s["ncN"]), np.zeros(s["ndx"])
        self._out = _Out(*(a.ctypes.data for a in (self.gap, self.r, self.c, self.rN, self.cN,
                                                    self.d0)))
        self._stats = np.zeros(7)
        self._x_init = np.zeros(s["nx"])
        self._x_init_set: np.ndarray | None = None
        # the problem's data: set_problem copies into these, the C code points at them
        # the singles once per stage node (the mapped functions take one column per node;
        # the terminal one reads the first)
        self._S, self._P = np.zeros((s["N"], s["ns"])), np.zeros((s["N"] + 1, s["npar"]))
        self._W, self._WN = np.zeros((s["N"], s["nr"])), np.zeros(s["nrN"])
        self._weights_set = False  # set_problem copies the weights when they change only
        self._b, self._eq = np.zeros((s["N"], s["ncon"])), np.zeros((s["N"], s["ncon"]), bool)
        self._bN, self._eqN = np.zeros(s["ncNcon"]), np.zeros(s["ncNcon"], bool)
        d.S, d.P, d.W, d.WN, d.b, d.eq, d.bN, d.eqN = (
            a.ctypes.data if a.size else None
            for a in (self._S, self._P, self._W, self._WN, self._b, self._eq, self._bN,
                      self._eqN))
        self._al = (al, alN)
        self._bind_multipliers()
        self._data_ptr, self._out_ptr = ctypes.pointer(d), ctypes.pointer(self._out)
        self._stats_ptr = self._stats.ctypes.data
        # the quadratisation: AL weights and targets, one buffer for every output
        q = self._quad = _Quadratise()
        self._wt = (np.zeros((s["N"], s["nc"])), np.zeros((s["N"], s["nc"])),
                    np.zeros(s["ncN"]), np.zeros(s["ncN"]))
        q.w, q.t, q.wN, q.tN = (a.ctypes.data for a in self._wt)
        n_out = sum(f.numel_out(i) for f in (quadratise, quadratise_term)
                    for i in range(f.n_out()))
        self.quadratisation_buffer = np.zeros(n_out)
        self.quadratisation, self.quadratisation_term = _output_views(
            self.quadratisation_buffer, (quadratise, quadratise_term))
        if len(self.quadratisation) != 9 or len(self.quadratisation_term) != 3:
            raise ValueError("the quadratisation functions have 9 and 3 outputs")
        for j, a in enumerate(self.quadratisation):
            q.out[j] = a.ctypes.data
        for j, a in enumerate(self.quadratisation_term):
            q.out_term[j] = a.ctypes.data
        q.buffer, q.n_buffer = self.quadratisation_buffer.ctypes.data, n_out
        q.term = GeneratedFunction.bind(quadratise_term)
        self._stage_fns: dict[int, tuple[cs.Function, GeneratedFunction]] = {}
        self._stage_shapes = [quadratise.size_out(i) for i in range(9)]
        self.set_stage_quadratisation(quadratise)
        self._quad_ptr = ctypes.pointer(q)

    @classmethod
    def create(cls, *args: Any, **kwargs: Any) -> CompiledEvaluation | None:
        """An instance, or None when the compiled library is unavailable (riccati_c logs
        why) or the functions cannot be bound (logged here): the solver then evaluates
        with numpy, the same numbers more slowly."""
        if not riccati_c.available():
            return None
        try:
            return cls(*args, **kwargs)
        except (RuntimeError, OSError, AttributeError) as err:
            log.info("ilqr: evaluating with numpy, the compiled evaluation is unavailable: %s",
                     err)
            return None

    def set_stage_quadratisation(self, fn: cs.Function) -> None:
        """Quadratise with this stage function from now on (the solver's lean or full one:
        the same inputs and output shapes)."""
        entry = self._stage_fns.get(id(fn))  # (fn, its entry): the key stays valid
        if entry is None:
            if [fn.size_out(i) for i in range(fn.n_out())] != self._stage_shapes:
                raise ValueError(f"{fn.name()}: outputs unlike the bound quadratisation's")
            entry = self._stage_fns[id(fn)] = (fn, GeneratedFunction.bind(fn))
        self._quad.stage = entry[1]

    def set_problem(self, S: np.ndarray, P: np.ndarray, b: np.ndarray, eq: np.ndarray,
                    bN: np.ndarray, eqN: np.ndarray,
                    weights: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """The data of the next evaluations: S (ns,) singles, P (npar, N+1) parameters,
        b and eq (N, ncon) the projected rows' targets and mask, bN and eqN (ncNcon,) the
        terminal ones, ``weights`` W (N, nr) and WN (nrN,) the residual weights (None: the
        last ones given; they must have been given once). Copied into arrays the C code
        holds pointers to (set once); the augmented Lagrangians' bounds, multipliers and
        penalties are read in place."""
        arrays = [("S", self._S, np.broadcast_to(np.reshape(S, -1), self._S.shape)),
                  ("P", self._P, P.T), ("b", self._b, b),
                  ("eq", self._eq, eq), ("bN", self._bN, bN), ("eqN", self._eqN, eqN)]
        if weights is not None:
            arrays += [("W", self._W, weights[0]), ("WN", self._WN, weights[1])]
        elif not self._weights_set:
            raise ValueError("set_problem needs the residual weights the first time")
        for name, dst, src in arrays:
            if np.shape(src) != dst.shape:
                raise ValueError(f"{name} has shape {np.shape(src)}; expected {dst.shape}")
            np.copyto(dst, src)
        self._weights_set |= weights is not None
        if any(a.lb is not arrays[0] for a, arrays in zip(self._al, self._al_arrays,
                                                          strict=True)):
            self._bind_multipliers()

    def _bind_multipliers(self) -> None:
        """Point the C data at the augmented Lagrangians' arrays (which they update in
        place: ``AugmentedLagrangian`` keeps the same arrays throughout)."""
        d = self._data
        al = self._al[0]
        d.barrier, d.mu, d.delta = int(al.barrier), al.mu, al.delta
        for block, a in ((d.al, self._al[0]), (d.alN, self._al[1])):
            arrays = (a.lb, a.ub, a.lam, a.lam_lo, a.lam_up, a.rho)
            if any(not x.flags.c_contiguous or x.dtype != np.float64 for x in arrays):
                raise ValueError("the augmented Lagrangian's arrays must be C-contiguous float64")
            block.n = a.lam.size
            block.lb, block.ub, block.lam, block.lam_lo, block.lam_up, block.rho = (
                x.ctypes.data for x in arrays)
        self._al_arrays = tuple((a.lb, a.ub, a.lam, a.lam_lo, a.lam_up, a.rho)
                                for a in self._al)  # kept alive: the C code's pointers

    def set_initial_state(self, x_init: np.ndarray | None) -> None:
        """Node 0's fixed state (nx,), or None (free: d0 is zero)."""
        if x_init is self._x_init_set:
            return
        self._x_init_set = x_init
        if x_init is None:
            self._data.x_init = None
            return
        self._x_init[:] = x_init
        self._data.x_init = self._x_init.ctypes.data

    def __call__(self, X: np.ndarray, U: np.ndarray) -> tuple[float, ...] | None:
        """Evaluate at X (N+1, nx), U (N, nu) (C-contiguous float64): ``(cost, gap_l1,
        gap_max, eq_l1, eq_max, al, al_viol)``, or None when a value is not finite.

        Raises:
            RuntimeError: a generated function reported a failure.
            ValueError: X or U has the wrong shape or layout.
        """
        if (X.shape != (self.N + 1, self.nx) or U.shape != (self.N, self.nu)
                or not (X.flags.c_contiguous and U.flags.c_contiguous)
                or X.dtype != np.float64 or U.dtype != np.float64):
            raise ValueError(f"X {X.shape} and U {U.shape} must be C-contiguous float64 of "
                             f"shapes {(self.N + 1, self.nx)}, {(self.N, self.nu)}")
        ret = self._lib.ilqr_evaluate(self._data_ptr, X.ctypes.data, U.ctypes.data,
                                      self._out_ptr, self._stats_ptr)
        if ret == 1:
            return None
        if ret != 0:
            raise RuntimeError("ilqr_evaluate: a generated value function failed")
        return tuple(self._stats.tolist())

    def quadratise(self, X: np.ndarray, U: np.ndarray, c: np.ndarray, cN: np.ndarray) -> bool:
        """Quadratise at X (N+1, nx), U (N, nu) (as :meth:`__call__` takes them) whose
        evaluation gave the constraint rows c (N, nc), cN (ncN,) (C-contiguous float64):
        fills ``quadratisation`` and ``quadratisation_term``; False when an output is not
        finite.

        Raises:
            RuntimeError: a generated function reported a failure.
            ValueError: an array has the wrong shape or layout.
        """
        d = self._data
        for name, a, shape in (("X", X, (self.N + 1, self.nx)), ("U", U, (self.N, self.nu)),
                               ("c", c, (self.N, d.nc)), ("cN", cN, (d.ncN,))):
            if a.shape != shape or not a.flags.c_contiguous or a.dtype != np.float64:
                raise ValueError(f"{name} {a.shape} must be C-contiguous float64 of shape "
                                 f"{shape}")
        ret = self._lib.ilqr_quadratise(self._data_ptr, self._quad_ptr, X.ctypes.data,
                                        U.ctypes.data, c.ctypes.data, cN.ctypes.data)
        if ret == 2:
            raise RuntimeError("ilqr_quadratise: a generated quadratisation function failed")
        return ret == 0
