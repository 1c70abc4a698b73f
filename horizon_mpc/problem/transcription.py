"""Transcription of a :class:`~horizon_mpc.problem.Problem` into one sparse NLP.

The NLP is built **once** per problem structure; everything a receding-horizon controller
changes between solves (variable and constraint bounds, parameter values, cost weights,
active node sets) is numeric data fed at solve time, so nothing is ever rebuilt.

Layout (column-major, one column per node, N = ``n_nodes``)::

    w = [vec(X) (nx, N+1), vec(U) (nu, N), S (ns), vec(Xc) (nx*d, N)]
    P = [vec(Pv) (np, N+1), sqrt cost weights (dim, n_valid) per cost, masks (n_valid)
         per general cost]
    g = [dynamics (per interval), constraint c on all its valid nodes (dim_c, n_valid_c), ...]
    f = ||R(w, P)||^2 + sum_general mask . l(w, P)

``Xc`` holds the collocation states (``direct_collocation`` only, d = degree). Dynamics
rows are the multiple-shooting defects ``x_{k+1} (-) F(x_k, u_k, s, p_k)`` (ndx rows) or the
collocation equations ``dt f(X_kj) - sum_i C_ij X_ki`` (nx*d rows) followed by the continuity
``x_{k+1} - sum_i D_i X_ki`` (nx rows). A constraint is evaluated on every node where it is
*valid* (option ``constraint_rows='active'``: only where it is active when built); nodes
where it is not *active* get the bounds (-inf, +inf). A cost's residual is
multiplied by ``sqrt(weight)`` per row and node, 0 on inactive nodes, so ``R`` is the
Gauss-Newton residual vector and ``f = ||R||^2`` without general costs.

Per-node functions are evaluated with ``Function.map`` over contiguous node ranges (offset
terms get shifted column slices); there is no Python loop over nodes in the graph.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import casadi as cs
import numpy as np

from horizon_mpc.problem.problem import Problem
from horizon_mpc.problem.terms import Cost, GeneralCost

__all__ = ["Block", "Transcription", "collocation_coefficients"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Block:
    """A (rows, cols) column-major block of a stacked vector, starting at ``start``.

    ``cols`` counts nodes or intervals; ``shiftable`` blocks move one column back on
    :meth:`Transcription.shift_vector` (single variables do not).
    """

    name: str
    start: int
    rows: int
    cols: int
    shiftable: bool = True

    @property
    def stop(self) -> int:
        """One past the last index."""
        return self.start + self.rows * self.cols


def collocation_coefficients(degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Legendre collocation on [0, 1]: points ``tau`` (d+1,) with tau_0 = 0, derivative
    matrix ``C`` (d+1, d+1) with ``C[i, j] = l_i'(tau_j)`` and continuity ``D`` (d+1,) with
    ``D[i] = l_i(1)`` for the Lagrange basis ``l_i`` on ``tau``."""
    tau = np.append(0.0, cs.collocation_points(degree, "legendre"))
    C = np.zeros((degree + 1, degree + 1))
    D = np.zeros(degree + 1)
    for i in range(degree + 1):
        basis = np.poly1d([1.0])
        for r in range(degree + 1):
            if r != i:
                basis *= np.poly1d([1.0, -tau[r]]) / (tau[i] - tau[r])
        D[i] = basis(1.0)
        C[i] = np.polyder(basis)(tau)
    return tau, C, D


class Transcription:
    """The NLP of a problem (see the module docstring for the layout).

    Args:
        prb: the problem (finalized here).
        sym: ``'SX'`` (scalar graph, fastest evaluation for small and medium problems) or
            ``'MX'`` (mapped SX node functions in a matrix graph: smaller memory, faster
            construction for large problems).
        constraint_rows: ``'valid'`` (default): a constraint has rows on every node where
            it is valid, so its node set can change freely between solves; ``'active'``:
            rows only on the nodes active now (a smaller NLP: IPOPT keeps a slack for every
            row, bounded or not), and activating another node later raises ``ValueError``.

    Attributes:
        nlp: ``{'x': w, 'p': P, 'f': f, 'g': g}`` for ``casadi.nlpsol``.
        residual: the weighted residual vector ``R(w, P)`` (column).
        general: the general-cost part of ``f`` (scalar, 0 without general costs).
        w_blocks, g_blocks: :class:`Block` layouts of ``w`` and ``g``.
    """

    def __init__(self, prb: Problem, sym: str = "SX", constraint_rows: str = "valid"):
        if sym not in ("SX", "MX"):
            raise ValueError(f"sym must be 'SX' or 'MX', got {sym!r}")
        if constraint_rows not in ("valid", "active"):
            raise ValueError(f"constraint_rows must be 'valid' or 'active', got "
                             f"{constraint_rows!r}")
        prb.finalize()
        prb.check_transcription()
        self.prb = prb
        self.sym = sym
        self.method = prb.transcription
        self.degree = prb.collocation_degree if self.method == "direct_collocation" else 0
        N, nx, nu, ns, npar = prb.n_nodes, prb.nx, prb.nu, prb.ns, prb.np_
        d = self.degree
        T = getattr(cs, sym)

        self.w_blocks = [Block("X", 0, nx, N + 1), Block("U", nx * (N + 1), nu, N),
                         Block("S", nx * (N + 1) + nu * N, ns, 1, shiftable=False)]
        self.w_blocks.append(Block("Xc", self.w_blocks[-1].stop, nx * d, N))
        self.nw = self.w_blocks[-1].stop
        w = T.sym("w", self.nw)
        X, U, S, Xc = (cs.reshape(w[b.start:b.stop], b.rows, b.cols) for b in self.w_blocks)
        Upad = cs.horzcat(U, T.zeros(nu, 1))  # inputs on node N never matter (see terms.py)

        # parameters: values, then sqrt weights per cost, then masks per general cost
        self.costs = [c for c in prb.costs.values() if isinstance(c, Cost)]
        self.general_costs = [c for c in prb.costs.values() if isinstance(c, GeneralCost)]
        self.p_blocks = [Block("parameters", 0, npar, N + 1)]
        for c in self.costs:
            self.p_blocks.append(Block(c.name, self.p_blocks[-1].stop, c.dim,
                                       c.valid_nodes.size))
        for c in self.general_costs:
            self.p_blocks.append(Block(c.name, self.p_blocks[-1].stop, 1, c.valid_nodes.size))
        self.npar = self.p_blocks[-1].stop
        P = T.sym("p", self.npar)
        Pv = cs.reshape(P[:npar * (N + 1)], npar, N + 1)

        def node_args(term):
            lo, hi = int(term.valid_nodes[0]), int(term.valid_nodes[-1]) + 1
            args = [X[:, lo:hi], Upad[:, lo:hi], S, Pv[:, lo:hi]]
            for o in term.offsets:
                args += [X[:, lo + o:hi + o], Upad[:, lo + o:hi + o]]
            return term.function.map(hi - lo)(*args)

        # dynamics
        g, self.g_blocks = [], []
        dyn = self._dynamics_function()
        if self.method == "multiple_shooting":
            defects = dyn.map(N)(X[:, :-1], U, S, Pv[:, :-1], X[:, 1:])
        else:
            defects = dyn.map(N)(X[:, :-1], Xc, U, S, Pv[:, :-1], X[:, 1:])
        self.g_blocks.append(Block("dynamics", 0, defects.shape[0], N))
        g.append(cs.vec(defects))
        # constraints on all valid nodes (or on the nodes active now)
        self.constraints = list(prb.constraints.values())
        self.constraint_rows = constraint_rows
        self.row_nodes: dict[str, np.ndarray] = {}
        for c in self.constraints:
            rows = c.valid_nodes if constraint_rows == "valid" else c.nodes
            self.row_nodes[c.name] = rows
            val = node_args(c)[:, (rows - c.valid_nodes[0]).tolist()]
            self.g_blocks.append(Block(c.name, self.g_blocks[-1].stop, c.dim, rows.size))
            g.append(cs.vec(val))
        self.ng = self.g_blocks[-1].stop
        # costs
        R = [cs.vec(node_args(c) * cs.reshape(P[b.start:b.stop], b.rows, b.cols))
             for c, b in zip(self.costs, self.p_blocks[1:], strict=False)]
        self.residual = cs.vertcat(T(0, 1), *R)
        general = T(0)
        for c, b in zip(self.general_costs, self.p_blocks[1 + len(self.costs):], strict=True):
            general += cs.dot(node_args(c), P[b.start:b.stop].T)
        self.general = general
        self.nlp = {"x": w, "p": P, "f": cs.sumsqr(self.residual) + general,
                    "g": cs.vertcat(T(0, 1), *g)}
        self._tau = collocation_coefficients(d)[0] if d else None
        log.debug("transcription %s (%s): %d variables, %d constraints, %d residuals, "
                  "%d parameters", self.method, sym, self.nw, self.ng, self.residual.numel(),
                  self.npar)

    # ------------------------------------------------------------------ dynamics rows
    def _dynamics_function(self) -> cs.Function:
        """Per-interval dynamics rows as an SX Function (see the module docstring)."""
        prb = self.prb
        nx, nu, ns, npar = prb.nx, prb.nu, prb.ns, prb.np_
        x, x1 = cs.SX.sym("x", nx), cs.SX.sym("x_next", nx)
        u, s, p = cs.SX.sym("u", nu), cs.SX.sym("s", ns), cs.SX.sym("p", npar)
        if self.method == "multiple_shooting":
            F = prb.discrete_dynamics()
            return cs.Function("defect", [x, u, s, p, x1],
                               [prb.difference_expr(F(x, u, s, p), x1)])
        d = self.degree
        _, C, D = collocation_coefficients(d)
        xc = cs.SX.sym("xc", nx * d)
        pts = [x] + [xc[j * nx:(j + 1) * nx] for j in range(d)]
        f = prb.continuous_dynamics()
        dt = prb.dt_function()(s, p)
        rows = []
        for j in range(1, d + 1):
            slope = sum(C[i, j] * pts[i] for i in range(d + 1))
            rows.append(dt * f(pts[j], u, s, p) - slope)
        rows.append(x1 - sum(D[i] * pts[i] for i in range(d + 1)))
        return cs.Function("collocation", [x, xc, u, s, p, x1], [cs.vertcat(*rows)])

    # ------------------------------------------------------------------ numeric data
    def initial_w(self, previous: np.ndarray | None = None) -> np.ndarray:
        """``w`` from the variables' initial guesses, shape (nw,).

        Collocation states: those of ``previous`` (a ``w`` of this transcription, the last
        solution) on the intervals whose two node guesses are exactly its node states (a
        re-solve, or a solve after a shift, starts from the solution it carries: a solved
        problem solved again broke its collocation equations by 0.24 and took GN-SQP 64
        iterations to come back); elsewhere, and where ``previous`` is NaN, interpolated
        linearly between the node guesses.
        """
        prb = self.prb
        X = prb.stacked("state")
        parts = [X.ravel("F"), prb.stacked("input").ravel("F"), prb.stacked("single").ravel()]
        if self.degree:
            tau = self._tau[1:]
            Xc = X[:, :-1, None] + (X[:, 1:, None] - X[:, :-1, None]) * tau  # (nx, N, d)
            Xc = Xc.transpose(0, 2, 1).reshape(-1, prb.n_nodes, order="F")  # (nx d, N)
            if previous is not None:
                bx, bc = self.w_blocks[0], self.w_blocks[3]
                Xp = previous[bx.start:bx.stop].reshape(bx.rows, bx.cols, order="F")
                Xcp = previous[bc.start:bc.stop].reshape(bc.rows, bc.cols, order="F")
                same = ((X[:, :-1] == Xp[:, :-1]).all(axis=0) & (X[:, 1:] == Xp[:, 1:]).all(axis=0)
                        & np.isfinite(Xcp).all(axis=0))
                Xc[:, same] = Xcp[:, same]
            parts.append(Xc.ravel("F"))
        return np.concatenate(parts)

    def bounds_w(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lbx, ubx)`` from the variables' bounds (collocation states are free)."""
        prb, free = self.prb, np.full(self.w_blocks[3].rows * self.prb.n_nodes, np.inf)
        out = []
        for what, inf in (("lower_bounds", -free), ("upper_bounds", free)):
            out.append(np.concatenate([prb.stacked("state", what).ravel("F"),
                                       prb.stacked("input", what).ravel("F"),
                                       prb.stacked("single", what).ravel(), inf]))
        return out[0], out[1]

    def bounds_g(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lbg, ubg)``: 0 on the dynamics, the constraint bounds on active nodes and
        (-inf, inf) on inactive ones."""
        lbg, ubg = np.zeros(self.ng), np.zeros(self.ng)
        for c, b in zip(self.constraints, self.g_blocks[1:], strict=True):
            v = self.row_nodes[c.name]
            act = c.active[v]
            if act.sum() != c.nodes.size:
                raise ValueError(
                    f"constraint {c.name!r} is active on nodes "
                    f"{np.setdiff1d(c.nodes, v).tolist()} that have no rows in this NLP "
                    "(built with constraint_rows='active'); build the solver with "
                    "constraint_rows='valid' to move constraints freely")
            lo, hi = c.lower_bounds[:, v], c.upper_bounds[:, v]
            lbg[b.start:b.stop] = np.where(act, lo, -np.inf).ravel("F")
            ubg[b.start:b.stop] = np.where(act, hi, np.inf).ravel("F")
        return lbg, ubg

    def parameters(self) -> np.ndarray:
        """``P``: parameter values, sqrt weights (0 off the active nodes), general masks."""
        parts = [self.prb.parameter_values().ravel("F")]
        for c in self.costs:
            v = c.valid_nodes
            parts.append((np.sqrt(c.weight)[:, None] * c.active[v][None, :]).ravel("F"))
        for c in self.general_costs:
            parts.append(c.active[c.valid_nodes].astype(float))
        return np.concatenate(parts)

    def node_order(self) -> tuple[np.ndarray, np.ndarray]:
        """Permutations ``(pw, pg)`` that sort ``w`` and ``g`` by node (stage-wise order,
        single variables last): ``w[pw]`` is ``[x_0, u_0, xc_0, x_1, ...,  x_N, S]``.

        Banded KKT matrices factorise with little fill-in in this order; QP solvers without
        their own fill-reducing ordering need it (see the gnsqp solver).
        """
        N = self.prb.n_nodes
        wn = np.empty(self.nw)
        for b in self.w_blocks:
            cols = np.arange(b.cols) + {"X": 0.0, "U": 0.1, "S": N + 1.0, "Xc": 0.2}[b.name]
            wn[b.start:b.stop] = np.repeat(cols, b.rows)
        gn = np.empty(self.ng)
        b = self.g_blocks[0]
        gn[b.start:b.stop] = np.repeat(np.arange(b.cols) + 0.5, b.rows)
        for c, b in zip(self.constraints, self.g_blocks[1:], strict=True):
            gn[b.start:b.stop] = np.repeat(self.row_nodes[c.name].astype(float), b.rows)
        return np.argsort(wn, kind="stable"), np.argsort(gn, kind="stable")

    def unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``w`` -> X (nx, N+1), U (nu, N), S (ns, 1)."""
        w = np.asarray(w, dtype=float).ravel()
        return tuple(w[b.start:b.stop].reshape(b.rows, b.cols, order="F")
                     for b in self.w_blocks[:3])

    def violation(self, w: np.ndarray, g: np.ndarray, lbx: np.ndarray, ubx: np.ndarray,
                  lbg: np.ndarray, ubg: np.ndarray) -> float:
        """Max violation (inf-norm) of the dynamics, constraints and variable bounds; NaN
        when a value is NaN (a NaN is no evidence of feasibility)."""
        w, g = np.ravel(w), np.ravel(g)
        viol = [0.0]
        for val, lo, hi in ((w, lbx, ubx), (g, lbg, ubg)):
            if val.size:
                viol.append(float(np.max(np.maximum(lo - val, val - hi))))
        return math.nan if any(map(math.isnan, viol)) else max(viol)

    # ------------------------------------------------------------------ receding horizon
    @staticmethod
    def shift_vector(vec: np.ndarray, blocks: list[Block]) -> np.ndarray:
        """Shift every shiftable block of ``vec`` one column back (last column repeated).

        Used for warm-starting multipliers after ``Problem.shift()``.
        """
        out = np.array(vec, dtype=float).ravel().copy()
        for b in blocks:
            if b.shiftable and b.cols > 1 and b.rows:
                m = out[b.start:b.stop].reshape(b.rows, b.cols, order="F")
                m[:, :-1] = m[:, 1:].copy()
                out[b.start:b.stop] = m.ravel("F")
        return out
