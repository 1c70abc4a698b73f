"""Node selections and per-node value arrays.

Nodes are numbered 0..N (``N = n_nodes``, the number of intervals). States live on nodes
0..N, inputs on 0..N-1. Every ``nodes=`` argument of the Problem API accepts an int, a list
or integer array, a ``range``, a ``slice`` (of the nodes the object lives on, negative
bounds counting from the end as in Python; a bound beyond them is refused), a boolean
mask (array or list) with one entry per node the object lives on, or None (= every node
the object lives on). A bool alone or a non-integer number is refused. Per-node values
(a ``(dim, n_sel)`` array) go to the nodes in the order they are listed (``nodes=[8, 3]``:
column 0 to node 8); a list naming a node twice is the sorted set of its nodes (a scalar
or ``(dim,)`` value then fills them).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import casadi as cs
import numpy as np

NodeSelection = int | Iterable[int] | slice | range | None
#: per-node values (bounds, guesses, weights): a scalar, ``(dim,)`` for every selected node,
#: or ``(dim, n_sel)`` one column per selected node
Values = float | Sequence[float] | np.ndarray
#: what a term takes: an SX expression of the problem's variables (variables are SX), a
#: number or array, or a list of those (stacked)
Expression = cs.SX | float | np.ndarray | Sequence

__all__ = ["Expression", "NodeSelection", "Values", "bound_values", "broadcast_values",
           "check_bounds", "holds_none", "select_nodes"]


def select_nodes(nodes: NodeSelection, n_valid: int, what: str = "",
                 ordered: bool = False) -> np.ndarray:
    """Node indices of a selection, validated against ``0..n_valid-1``: sorted and unique,
    or with ``ordered`` (a selection that per-node values are written to: column j of a
    ``(dim, n_sel)`` value goes to the j-th node listed) in the caller's order; a selection
    that names a node twice is its sorted set either way.

    Raises:
        IndexError: a node is out of range (the message names ``what`` and the valid range).
        TypeError: the selection has an unsupported type.
    """
    if nodes is None:
        return np.arange(n_valid)
    if isinstance(nodes, slice):
        # a Python slice of the nodes (negative bounds count from the end), but a bound
        # past them is a mistake, not an empty or clipped selection (slice(20, 30) of 11
        # nodes set nothing without a word)
        for end in (nodes.start, nodes.stop):
            if end is not None and not -n_valid <= _node_index(end, what) <= n_valid:
                raise IndexError(f"nodes {nodes} out of range for {what}: valid nodes are "
                                 f"0..{n_valid - 1}")
        return np.arange(n_valid)[nodes]
    if isinstance(nodes, (bool, np.bool_)):
        raise TypeError(f"nodes of {what}: a bool is not a node (give a mask with one entry "
                        f"per node 0..{n_valid - 1}, or None for all)")
    if isinstance(nodes, (list, tuple)) and nodes and all(
            isinstance(n, (bool, np.bool_)) for n in nodes):
        nodes = np.array(nodes, dtype=bool)  # a mask written as a list
    if isinstance(nodes, (int, np.integer)):
        idx = np.array([int(nodes)])
    elif isinstance(nodes, np.ndarray) and nodes.dtype == bool:
        if nodes.shape != (n_valid,):
            raise IndexError(f"boolean node mask of shape {nodes.shape} for {what}: expected "
                             f"({n_valid},), one entry per node 0..{n_valid - 1}")
        return np.flatnonzero(nodes)
    elif isinstance(nodes, np.ndarray) and nodes.dtype.kind in "iu" and nodes.ndim == 1:
        idx = nodes.astype(int)  # the fast path of per-tick schedules (np.flatnonzero)
    else:
        try:
            items = list(nodes)
        except TypeError as exc:
            raise TypeError(f"nodes of {what}: expected int, list, range, slice or None, "
                            f"got {type(nodes).__name__}") from exc
        idx = np.array([_node_index(n, what) for n in items], dtype=int)
    if idx.size and (idx.min() < 0 or idx.max() >= n_valid):
        bad = idx[(idx < 0) | (idx >= n_valid)]
        raise IndexError(f"nodes {bad.tolist()} out of range for {what}: valid nodes are "
                         f"0..{n_valid - 1}")
    if idx.size > 1 and np.any(idx[1:] <= idx[:-1]):
        unique = np.unique(idx)
        if not ordered or unique.size < idx.size:
            # a node listed twice: the set of nodes (a per-node value must then have a column
            # per node of the set, and the shape check says so)
            return unique
    return idx


def _node_index(n: object, what: str) -> int:
    """One node of a list: an int, or a float holding one (2.0); 2.7 or True is refused."""
    if isinstance(n, (bool, np.bool_)):
        raise TypeError(f"nodes of {what}: {n!r} mixed with node numbers")
    if isinstance(n, (float, np.floating)) and float(n).is_integer():
        return int(n)
    if not isinstance(n, (int, np.integer)):
        raise TypeError(f"nodes of {what}: {n!r} is not a node number")
    return int(n)


def float_array(value: object, what: str = "") -> np.ndarray:
    """``value`` as a float array; a ``ValueError`` naming ``what`` when it is not numbers
    (text, a ragged list: numpy's own message named neither the variable nor the bound)."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        shown = repr(value)
        shown = shown if len(shown) <= 80 else shown[:77] + "..."
        raise ValueError(f"{what}: {shown} is not a number or an array of numbers "
                         f"({exc})") from None


def broadcast_values(value: object, dim: int, n_sel: int, what: str = "") -> np.ndarray:
    """Broadcast a scalar, a (dim,) vector or a (dim, n_sel) array to shape (dim, n_sel).

    Raises:
        ValueError: the shape fits none of those, or not numbers (the message names
            ``what``).
    """
    arr = float_array(value, what)
    if arr.ndim == 0:
        return np.full((dim, n_sel), float(arr))
    if arr.ndim == 1 and arr.shape[0] == dim:
        return np.repeat(arr[:, None], n_sel, axis=1)
    if arr.ndim == 2 and arr.shape == (dim, 1):
        return np.repeat(arr, n_sel, axis=1)
    if arr.ndim == 2 and arr.shape == (dim, n_sel):
        return arr.copy()
    raise ValueError(f"{what}: value of shape {arr.shape} does not fit dimension {dim} on "
                     f"{n_sel} node(s); give a scalar, ({dim},) or ({dim}, {n_sel})")


def bound_values(value: object, side: float, dim: int, n_sel: int, what: str = ""
                 ) -> np.ndarray:
    """:func:`broadcast_values` of a bound, None being no bound (``side``: -inf for a lower
    bound, inf for an upper one; it was taken as a NaN bound and refused), as a whole or as
    an element of a list (``[None, 0]``: no bound on the first component)."""
    if isinstance(value, np.ndarray) and value.dtype == object:  # np.array([None, 0])
        value = value.tolist()
    if value is None:
        value = side
    elif isinstance(value, (list, tuple)) and holds_none(value):
        value = _none_to(value, side)
    return broadcast_values(value, dim, n_sel, what)


def holds_none(value: object) -> bool:
    """Whether ``value`` is None or a (nested) list or tuple with a None in it."""
    return value is None or (isinstance(value, (list, tuple))
                             and any(holds_none(v) for v in value))


def _none_to(value, side: float):
    """``value`` (nested lists/tuples) with every None replaced by ``side``."""
    if value is None:
        return side
    if isinstance(value, (list, tuple)):
        return [_none_to(v, side) for v in value]
    return value


def check_bounds(lo: np.ndarray, hi: np.ndarray, what: str) -> None:
    """Raise ValueError when a bound is NaN (no bound is -inf/inf; a NaN bound would be
    ignored by some solvers and enforced by others), a lower bound is +inf or an upper
    one -inf (no value meets them: IPOPT raised, the others failed later with misleading
    statuses), or a lower bound is above its upper."""
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise ValueError(f"{what}: NaN bound (use -inf/inf for no bound)")
    if np.isposinf(lo).any() or np.isneginf(hi).any():
        raise ValueError(f"{what}: a lower bound of +inf or an upper bound of -inf (no value "
                         "meets it; -inf/inf on the other side is no bound)")
    if np.any(lo > hi):
        raise ValueError(f"{what}: lower bound above upper bound")
