"""Decision variables and parameters of a :class:`~horizon_mpc.problem.Problem`.

A variable *is* a CasADi ``SX`` column symbol, so it composes into expressions directly
(``q[7:] - q_nominal``); it also carries per-node bounds, an initial guess (warm start)
and, for states, an optional manifold (e.g. a configuration with a quaternion).

Arrays of per-node values have shape ``(dim, n)`` with ``n = N + 1`` for states and
parameters, ``N`` for inputs and 1 for single variables.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as cs
import numpy as np

from horizon_mpc.problem.nodes import (
    NodeSelection,
    Values,
    bound_values,
    broadcast_values,
    check_bounds,
    float_array,
    holds_none,
    select_nodes,
)

__all__ = [
    "InputVariable",
    "Manifold",
    "OffsetVariable",
    "Parameter",
    "SingleVariable",
    "StateVariable",
    "Variable",
    "VariableGroup",
]


@dataclass(frozen=True)
class Manifold:
    """A state variable's configuration space: ``integrate(x, dx)`` and ``difference(x0, x1)``.

    ``integrate`` maps (x (dim), dx (tangent_dim)) -> x; ``difference`` maps
    (x0, x1) -> dx such that ``integrate(x0, difference(x0, x1)) == x1``.
    """

    integrate: cs.Function
    difference: cs.Function
    tangent_dim: int


class Variable(cs.SX):
    """Base of all variables: an SX symbol with per-node values.

    Attributes:
        name: the variable's name (unique in its problem).
        dim: its dimension.
        kind: 'state', 'input', 'single' or 'parameter'.
    """

    kind = "variable"

    def __init__(self, name: str, dim: int, n_values: int):
        super().__init__(cs.SX.sym(name, dim))
        self.name = name
        self.dim = dim
        self.n_values = n_values
        self._lb = np.full((dim, n_values), -np.inf)
        self._ub = np.full((dim, n_values), np.inf)
        self._init = np.zeros((dim, n_values))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, dim={self.dim})"

    def _columns(self, nodes: NodeSelection) -> tuple[slice | np.ndarray, int]:
        """The columns of ``nodes`` and their number: a slice for every node or one node
        (the per-tick calls: no index arrays), else the node indices in the caller's order
        (column j of a per-node value goes to the j-th node listed)."""
        if nodes is None:
            return slice(None), self.n_values
        if type(nodes) is int and 0 <= nodes < self.n_values:
            return slice(nodes, nodes + 1), 1
        idx = select_nodes(nodes, self.n_values, f"{self.kind} variable {self.name!r}",
                           ordered=True)
        return idx, idx.size

    def _bound_values(self, value, side: float, n: int, what: str) -> np.ndarray:
        return bound_values(value, side, self.dim, n, f"{what} of {self.name!r}")

    def _write(self, target: np.ndarray, cols: slice | np.ndarray, n: int, value,
               what: str) -> None:
        """``target[:, cols] = value`` for the shapes :func:`broadcast_values` takes, by
        numpy's broadcasting (no intermediate array: these run every MPC tick)."""
        # numpy takes None as NaN: caught only at the solve (a bound's None is no bound)
        if value is None or (isinstance(value, (list, tuple)) and holds_none(value)):
            raise TypeError(f"{what} of {self.name!r} is or holds None; give numbers")
        arr = float_array(value, f"{what} of {self.name!r}")
        if arr.ndim == 1 and arr.shape[0] == self.dim:
            arr = arr[:, None]
        elif not (arr.ndim == 0 or (arr.ndim == 2 and arr.shape[0] == self.dim
                                    and arr.shape[1] in (1, n))):
            broadcast_values(value, self.dim, n, f"{what} of {self.name!r}")  # shape error
        target[:, cols] = arr

    def set_bounds(self, lb: Values, ub: Values, nodes: NodeSelection = None) -> None:
        """Set lower and upper bounds on ``nodes`` (scalar, (dim,) or (dim, n_sel); None: no
        bound on that side).

        Raises:
            ValueError: a bound is NaN (no bound is -inf/inf), or a lower bound is above
                its upper bound, or a shape does not fit.
        """
        cols, n = self._columns(nodes)
        lo = self._bound_values(lb, -np.inf, n, "lower bound")
        hi = self._bound_values(ub, np.inf, n, "upper bound")
        check_bounds(lo, hi, f"bounds of {self.name!r}")
        self._lb[:, cols], self._ub[:, cols] = lo, hi

    def set_lower_bounds(self, lb: Values, nodes: NodeSelection = None) -> None:
        """Set the lower bounds only (checked as :meth:`set_bounds` against the upper
        bounds in place)."""
        cols, n = self._columns(nodes)
        lo = self._bound_values(lb, -np.inf, n, "lower bound")
        check_bounds(lo, self._ub[:, cols], f"bounds of {self.name!r}")
        self._lb[:, cols] = lo

    def set_upper_bounds(self, ub: Values, nodes: NodeSelection = None) -> None:
        """Set the upper bounds only (checked as :meth:`set_bounds` against the lower
        bounds in place)."""
        cols, n = self._columns(nodes)
        hi = self._bound_values(ub, np.inf, n, "upper bound")
        check_bounds(self._lb[:, cols], hi, f"bounds of {self.name!r}")
        self._ub[:, cols] = hi

    def set_initial_guess(self, value: Values, nodes: NodeSelection = None) -> None:
        """Set the initial guess (warm start) on ``nodes``."""
        cols, n = self._columns(nodes)
        self._write(self._init, cols, n, value, "initial guess")

    @property
    def lower_bounds(self) -> np.ndarray:
        """Lower bounds, shape (dim, n_values) (a copy)."""
        return self._lb.copy()

    @property
    def upper_bounds(self) -> np.ndarray:
        """Upper bounds, shape (dim, n_values) (a copy)."""
        return self._ub.copy()

    @property
    def initial_guess(self) -> np.ndarray:
        """Initial guess, shape (dim, n_values) (a copy)."""
        return self._init.copy()

    def shift(self) -> None:
        """Shift the initial guess one node back (receding horizon); the last node repeats."""
        if self.n_values > 1:
            self._init[:, :-1] = self._init[:, 1:]


class OffsetVariable(cs.SX):
    """The value of a state/input variable at node ``k + offset`` (for rate terms)."""

    def __init__(self, parent: Variable, offset: int):
        super().__init__(cs.SX.sym(f"{parent.name}_{'m' if offset < 0 else 'p'}{abs(offset)}",
                                   parent.dim))
        self.parent = parent
        self.offset = offset
        self.name = f"{parent.name}.offset({offset})"
        self.dim = parent.dim


class _NodeVariable(Variable):
    def __init__(self, name: str, dim: int, n_values: int):
        super().__init__(name, dim, n_values)
        self._offsets: dict[int, OffsetVariable] = {}

    def offset(self, k: int) -> OffsetVariable:
        """The variable at node ``i + k`` when a term is evaluated at node ``i``."""
        if not isinstance(k, (int, np.integer)) or k == 0:
            raise ValueError(f"offset of {self.name!r} must be a non-zero int, got {k!r}")
        k = int(k)
        if k not in self._offsets:
            self._offsets[k] = OffsetVariable(self, k)
        return self._offsets[k]


class StateVariable(_NodeVariable):
    """A state: one value per node 0..N."""

    kind = "state"

    def __init__(self, name: str, dim: int, n_nodes: int):
        super().__init__(name, dim, n_nodes + 1)
        self.manifold: Manifold | None = None
        self.manifold_revision = 0  # counts set_manifold calls (Problem.structure_revision)

    @property
    def tangent_dim(self) -> int:
        """Dimension of the tangent space (``dim`` unless on a manifold)."""
        return self.manifold.tangent_dim if self.manifold else self.dim

    def set_manifold(self, integrate: cs.Function, difference: cs.Function,
                     tangent_dim: int) -> None:
        """Declare that this state lives on a manifold (see :class:`Manifold`)."""
        if integrate.size1_in(0) != self.dim or integrate.size1_in(1) != tangent_dim:
            raise ValueError(f"manifold of {self.name!r}: integrate must map "
                             f"({self.dim}, {tangent_dim}) -> {self.dim}")
        self.manifold = Manifold(integrate, difference, int(tangent_dim))
        self.manifold_revision += 1


class InputVariable(_NodeVariable):
    """An input (control): one value per interval, nodes 0..N-1."""

    kind = "input"

    def __init__(self, name: str, dim: int, n_nodes: int):
        super().__init__(name, dim, n_nodes)


class SingleVariable(Variable):
    """A variable with one value for the whole horizon (e.g. a duration)."""

    kind = "single"

    def __init__(self, name: str, dim: int):
        super().__init__(name, dim, 1)

    def _columns(self, nodes: NodeSelection) -> tuple[slice, int]:
        if nodes is not None:  # one value for every node: a node set would be ignored
            raise ValueError(f"single variable {self.name!r} has one value for the whole "
                             f"horizon: call without nodes (got nodes={nodes!r})")
        return slice(0, 1), 1


class Parameter(Variable):
    """A value that is not optimised, one value per node 0..N; change it between solves."""

    kind = "parameter"

    def __init__(self, name: str, dim: int, n_nodes: int):
        super().__init__(name, dim, n_nodes + 1)

    def assign(self, value: Values, nodes: NodeSelection = None) -> None:
        """Assign the parameter's value on ``nodes`` (scalar, (dim,) or (dim, n_sel))."""
        cols, n = self._columns(nodes)
        self._write(self._init, cols, n, value, "value")

    @property
    def values(self) -> np.ndarray:
        """The assigned values, shape (dim, N+1) (a copy)."""
        return self._init.copy()

    def set_bounds(self, lb: Values, ub: Values, nodes: NodeSelection = None) -> None:  # noqa: D102
        raise TypeError(f"parameter {self.name!r} has no bounds: use assign()")


_GROUP_ARRAYS = {"lower_bounds": "_lb", "upper_bounds": "_ub", "initial_guess": "_init"}


class VariableGroup:
    """The variables of one kind (states, inputs, singles or parameters), their per-node
    arrays stacked in creation order.

    Each variable's bounds and initial guess (or values) are views of rows of the group's
    arrays, so reading or writing a whole kind is one array operation: the solvers read
    every kind once per solve, and a receding horizon shifts them every tick.
    """

    def __init__(self, n_values: int):
        self.n_values = n_values
        self.variables: list[Variable] = []
        self._arrays = {what: np.zeros((0, n_values)) for what in _GROUP_ARRAYS}

    def add(self, var: Variable) -> None:
        """Append ``var``: its arrays move into the group's (their values kept)."""
        if var.n_values != self.n_values:
            raise ValueError(f"{var.kind} variable {var.name!r} has {var.n_values} values per "
                             f"row; its group has {self.n_values}")
        self.variables.append(var)
        for what, attr in _GROUP_ARRAYS.items():
            self._arrays[what] = np.vstack([self._arrays[what], getattr(var, attr)])
        row = 0
        for v in self.variables:
            for what, attr in _GROUP_ARRAYS.items():
                setattr(v, attr, self._arrays[what][row:row + v.dim])
            row += v.dim

    @property
    def dim(self) -> int:
        """Rows of the stacked arrays (the sum of the variables' dimensions)."""
        return self._arrays["initial_guess"].shape[0]

    def stacked(self, what: str = "initial_guess") -> np.ndarray:
        """The stacked ``what`` (``initial_guess``, ``lower_bounds``, ``upper_bounds``),
        shape (dim, n_values): the group's own array, read-only (copy it to keep or change
        it; the variables' setters write it)."""
        if what not in self._arrays:
            raise KeyError(f"unknown stacked array {what!r}; arrays are: "
                           f"{', '.join(self._arrays)}")
        out = self._arrays[what].view()
        out.flags.writeable = False
        return out

    def set_initial_guess(self, values: np.ndarray) -> None:
        """Write the stacked initial guess (dim, n_values) of every variable at once."""
        values = np.asarray(values, dtype=float)
        if values.size == 0 and self.dim == 0:
            return
        if values.shape != (self.dim, self.n_values):
            raise ValueError(f"stacked initial guess of shape {values.shape}; expected "
                             f"{(self.dim, self.n_values)}")
        np.copyto(self._arrays["initial_guess"], values)

    def shift(self) -> None:
        """Every variable's initial guess one node back; the last node repeats."""
        init = self._arrays["initial_guess"]
        if self.n_values > 1:
            init[:, :-1] = init[:, 1:]
