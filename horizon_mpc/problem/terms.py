"""Constraints and costs: expressions evaluated on a set of nodes.

A term is built from a CasADi expression of the problem's variables. Its *valid* nodes are
those where every variable it uses exists (a term that uses an input cannot live on node N;
one that uses ``x.offset(-1)`` cannot live on node 0); its *active* nodes are a subset the
user chooses and may change between solves without rebuilding anything.

Per-node arrays have shape ``(dim, N + 1)``; columns of nodes where a term is not valid
are ignored.
"""

from __future__ import annotations

import itertools

import casadi as cs
import numpy as np

from horizon_mpc.codegen import function_name
from horizon_mpc.problem.nodes import (
    NodeSelection,
    Values,
    bound_values,
    check_bounds,
    float_array,
    select_nodes,
)

__all__ = ["Constraint", "Cost", "GeneralCost", "Term", "revisions", "stacked_active",
           "stacked_bounds", "stacked_weights", "term_name"]

def term_name(*parts: str) -> str:
    """A valid term name (:meth:`Problem.create_constraint`) from ``parts`` joined by ``_``,
    e.g. a URDF frame name and a role: :func:`horizon_mpc.codegen.function_name` of it
    (``term_name("leg-1.foot", "velocity")`` is ``leg_1_foot_velocity``)."""
    return function_name("_".join(parts))


# one counter for every term: a term's revision is unique, so a tuple of revisions names
# the state of a list of terms (what the solvers cache their per-solve reading on)
_REVISIONS = itertools.count(1)


class Term:
    """Common part of constraints and costs.

    Attributes:
        name: unique name in the problem.
        expr: the expression (SX column).
        dim: its number of rows.
        function: ``casadi.Function`` of the node arguments (see ``Problem.node_arguments``).
        uses_input: whether the expression depends on the inputs of its node.
        offsets: sorted node offsets of the offset variables it uses.
        valid_nodes: nodes where the term can be evaluated.
        revision: changes whenever the term's nodes, bounds or weight do (see
            :func:`revisions`).
    """

    kind = "term"

    def __init__(self, name: str, expr: cs.SX, function: cs.Function, uses_input: bool,
                 offsets: list[int], valid_nodes: np.ndarray, n_nodes: int,
                 nodes: NodeSelection):
        self.name = name
        self.expr = expr
        self.dim = int(expr.shape[0])
        self.function = function
        self.uses_input = uses_input
        self.offsets = offsets
        self.valid_nodes = valid_nodes
        self.n_nodes = n_nodes
        self._active = np.zeros(n_nodes + 1, dtype=bool)
        self._valid_mask = np.zeros(n_nodes + 1, dtype=bool)
        self._valid_mask[valid_nodes] = True
        self._invalid_nodes = np.flatnonzero(~self._valid_mask)
        self.revision = next(_REVISIONS)
        self.set_nodes(nodes)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, dim={self.dim}, nodes={self.nodes.tolist()})"

    def _select_mask(self, nodes: NodeSelection) -> np.ndarray:
        """The (N+1,) boolean mask of ``nodes``, validated against the term's valid nodes.

        A boolean mask of one entry per node is taken as it is (the per-tick schedules pass
        those: no index arrays built); every other selection goes through ``select_nodes``.
        """
        if nodes is None:
            return self._valid_mask.copy()
        if (isinstance(nodes, np.ndarray) and nodes.dtype == bool
                and nodes.shape == self._active.shape):
            mask = nodes
        else:
            mask = np.zeros_like(self._active)
            mask[select_nodes(nodes, self.n_nodes + 1, f"{self.kind} {self.name!r}")] = True
        # the nodes a term cannot live on are few (node N for an input term): test those
        if self._invalid_nodes.size and mask[self._invalid_nodes].any():
            invalid = np.flatnonzero(mask & ~self._valid_mask)
            raise IndexError(
                f"{self.kind} {self.name!r} cannot be evaluated on nodes {invalid.tolist()} "
                f"(it uses {'inputs or ' if self.uses_input else ''}offset variables); "
                f"valid nodes: {_ranges(self.valid_nodes)}")
        return mask

    def set_nodes(self, nodes: NodeSelection) -> None:
        """Make the term active exactly on ``nodes`` (None: every valid node)."""
        np.copyto(self._active, self._select_mask(nodes))
        self.revision = next(_REVISIONS)

    @property
    def nodes(self) -> np.ndarray:
        """The active nodes (sorted)."""
        return np.flatnonzero(self._active)

    @property
    def active(self) -> np.ndarray:
        """Boolean mask of the active nodes, shape (N+1,)."""
        return self._active.copy()


class Constraint(Term):
    """``lb <= expr <= ub`` on its active nodes (default: ``expr == 0``)."""

    kind = "constraint"

    def __init__(self, name: str, expr: cs.SX, function: cs.Function, uses_input: bool,
                 offsets: list[int], valid_nodes: np.ndarray, n_nodes: int,
                 nodes: NodeSelection, bounds=None):
        super().__init__(name, expr, function, uses_input, offsets, valid_nodes, n_nodes,
                         nodes)
        self._lb = np.zeros((self.dim, self.n_nodes + 1))
        self._ub = np.zeros((self.dim, self.n_nodes + 1))
        self.bounds_revision = self.revision  # changes with the bounds only
        if bounds is not None:
            if not (isinstance(bounds, (tuple, list)) and len(bounds) == 2):
                raise TypeError(f"constraint {self.name!r}: bounds must be a pair (lb, ub), "
                                f"got {bounds!r}")
            # per-node bounds: (dim, N+1), or one column per active node, in the order the
            # nodes were given (as set_bounds takes them with those nodes)
            cols = {np.shape(b)[1] for b in bounds if np.ndim(b) == 2} - {1}
            per_active = bool(cols - {self.n_nodes + 1})
            if per_active and cols != {self.nodes.size}:
                raise ValueError(f"constraint {self.name!r}: per-node bounds have "
                                 f"{sorted(cols)} columns; give one per node 0..N "
                                 f"({self.n_nodes + 1}) or one per active node "
                                 f"({self.nodes.size})")
            chosen = self.nodes if nodes is None else nodes
            self.set_bounds(*bounds, nodes=chosen if per_active else None)

    def set_bounds(self, lb: Values, ub: Values, nodes: NodeSelection = None) -> None:
        """Set the bounds on ``nodes`` (None: all nodes); scalar, (dim,) or (dim, n_sel), None
        for no bound on that side."""
        idx = (np.arange(self.n_nodes + 1) if nodes is None
               else select_nodes(nodes, self.n_nodes + 1, f"constraint {self.name!r}",
                                 ordered=True))
        lo = bound_values(lb, -np.inf, self.dim, idx.size, f"lower bound of {self.name!r}")
        hi = bound_values(ub, np.inf, self.dim, idx.size, f"upper bound of {self.name!r}")
        check_bounds(lo, hi, f"constraint {self.name!r}")
        self._lb[:, idx], self._ub[:, idx] = lo, hi
        self.revision = self.bounds_revision = next(_REVISIONS)

    @property
    def lower_bounds(self) -> np.ndarray:
        """Lower bounds, shape (dim, N+1)."""
        return self._lb.copy()

    @property
    def upper_bounds(self) -> np.ndarray:
        """Upper bounds, shape (dim, N+1)."""
        return self._ub.copy()

    @property
    def is_equality(self) -> bool:
        """True when lb == ub on every active node."""
        a = self._active
        return bool(np.all(self._lb[:, a] == self._ub[:, a]))


class Cost(Term):
    """Residual cost ``sum_k sum_i w_i r_i(k)^2`` over its active nodes (Gauss-Newton form)."""

    kind = "cost"

    def __init__(self, *args, weight=1.0, **kwargs):
        super().__init__(*args, **kwargs)
        self._weight = np.ones(self.dim)
        self.set_weight(weight)

    def set_weight(self, weight: Values) -> None:
        """Set the weight: a scalar or one non-negative value per residual row."""
        w = float_array(weight, f"weight of cost {self.name!r}")
        w = np.full(self.dim, float(w)) if w.ndim == 0 else w.reshape(-1)
        if w.shape != (self.dim,):
            raise ValueError(f"weight of cost {self.name!r}: expected a scalar or "
                             f"{self.dim} values, got shape {np.shape(weight)}")
        if np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError(f"weight of cost {self.name!r} must be finite and >= 0")
        self._weight = w
        self.revision = self.weight_revision = next(_REVISIONS)

    @property
    def weight(self) -> np.ndarray:
        """Per-row weights, shape (dim,)."""
        return self._weight.copy()


class GeneralCost(Term):
    """A general scalar cost ``sum_k l(k)`` (only for solvers that take a Hessian: IPOPT)."""

    kind = "general cost"


def stacked_bounds(constraints: list[Constraint]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows of ``constraints`` stacked in order: ``(lb, ub, active)``, each
    (sum of dims, N+1); ``active`` repeats each term's node mask over its rows. Bounds are
    returned as they are set, inactive nodes included (one copy of each, no per-term
    copies: the solvers read this every solve)."""
    if not constraints:
        return np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0), bool)
    return (np.concatenate([c._lb for c in constraints]),
            np.concatenate([c._ub for c in constraints]), stacked_active(constraints))


def stacked_weights(costs: list[Cost], weights: np.ndarray | None = None) -> np.ndarray:
    """Weight of each residual row of ``costs`` (stacked in order) per node,
    (sum of dims, N+1): the cost's weight where it is active, 0 elsewhere. ``weights``:
    the rows' weights when the caller has them stacked already (sum of dims,)."""
    if not costs:
        return np.zeros((0, 0))
    if weights is None:
        weights = np.concatenate([c._weight for c in costs])
    return stacked_active(costs) * weights[:, None]


def revisions(terms: list[Term], which: str = "revision") -> tuple[int, ...]:
    """The revisions of ``terms``: equal tuples mean nothing in them changed in between.
    ``which``: ``revision`` (anything), ``bounds_revision`` (constraints' bounds) or
    ``weight_revision`` (costs' weights)."""
    return tuple(getattr(t, which) for t in terms)


def stacked_active(terms: list[Term]) -> np.ndarray:
    """Each term's (N+1,) node mask repeated over its rows: (sum of dims, N+1)."""
    return np.repeat(np.array([t._active for t in terms]), [t.dim for t in terms], axis=0)


def _ranges(idx: np.ndarray) -> str:
    if idx.size == 0:
        return "none"
    parts, start = [], idx[0]
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if b != a + 1:
            parts.append(f"{start}..{a}" if a != start else f"{start}")
            start = b
    parts.append(f"{start}..{idx[-1]}" if idx[-1] != start else f"{start}")
    return ", ".join(parts)
