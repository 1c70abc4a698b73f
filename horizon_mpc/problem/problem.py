"""The optimal-control problem on a horizon of nodes (Horizon-style API).

>>> prb = Problem(20)
>>> x = prb.create_state_variable('x', 2)
>>> u = prb.create_input_variable('u', 1)
>>> prb.set_dynamics(cs.vertcat(x[1], u))
>>> prb.set_dt(0.1)
>>> x.set_bounds([0, 0], [0, 0], nodes=0)
>>> goal = prb.create_final_constraint('goal', x - np.array([1.0, 0.0]))
>>> effort = prb.create_cost('effort', u)

Node conventions: ``n_nodes = N`` intervals; states on nodes 0..N, inputs on 0..N-1.
Per-node functions take the *node arguments* ``(x, u, s, p)``: all states stacked in
creation order, all inputs, all single variables and all parameters of that node, followed
by ``(x_o, u_o)`` for every node offset ``o`` a term uses.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Iterable

import casadi as cs
import numpy as np

from horizon_mpc.problem.integrators import Integrator, get_integrator
from horizon_mpc.problem.nodes import Expression, NodeSelection, Values
from horizon_mpc.problem.terms import Constraint, Cost, GeneralCost, Term
from horizon_mpc.problem.variables import (
    InputVariable,
    Parameter,
    SingleVariable,
    StateVariable,
    Variable,
    VariableGroup,
)

__all__ = ["Problem"]

log = logging.getLogger(__name__)

TRANSCRIPTIONS = ("multiple_shooting", "direct_collocation")


class Problem:
    """An optimal-control problem with ``n_nodes`` intervals.

    Args:
        n_nodes: number of intervals N (>= 1).
    """

    def __init__(self, n_nodes: int):
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, (int, np.integer)) \
                or n_nodes < 1:
            raise ValueError(f"n_nodes must be an int >= 1, got {n_nodes!r}")
        self.n_nodes = int(n_nodes)
        # each kind's arrays stacked (VariableGroup); the lists are the groups' own
        self._groups = {"state": VariableGroup(self.n_nodes + 1),
                        "input": VariableGroup(self.n_nodes), "single": VariableGroup(1),
                        "parameter": VariableGroup(self.n_nodes + 1)}
        self.states: list[StateVariable] = self._groups["state"].variables
        self.inputs: list[InputVariable] = self._groups["input"].variables
        self.singles: list[SingleVariable] = self._groups["single"].variables
        self.parameters: list[Parameter] = self._groups["parameter"].variables
        self.constraints: dict[str, Constraint] = {}
        self.costs: dict[str, Cost | GeneralCost] = {}
        self._xdot: cs.SX | None = None
        self._dt: cs.SX | float | None = None
        self.transcription = "multiple_shooting"
        self.integrator_name: str = "rk4"
        self._integrator: Integrator = get_integrator("rk4")
        self.collocation_degree = 3
        self._finalized = False
        self._revision = 0  # see structure_revision

    # ------------------------------------------------------------------ variables
    def _check_new(self, name: str, dim: int, what: str) -> None:
        if self._finalized:
            raise RuntimeError(f"cannot create {what} {name!r}: the problem is already "
                               "built into a solver; create every variable first")
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"{what} name must be an identifier, got {name!r}")
        if name in self.variables:
            raise ValueError(f"a variable called {name!r} already exists")
        if not isinstance(dim, (int, np.integer)) or dim < 1:
            raise ValueError(f"{what} {name!r}: dimension must be an int >= 1, got {dim!r}")

    def create_state_variable(self, name: str, dim: int) -> StateVariable:
        """A state variable of dimension ``dim`` living on nodes 0..N."""
        self._check_new(name, dim, "state variable")
        if self._xdot is not None:
            raise RuntimeError(f"cannot create state variable {name!r} after set_dynamics(): "
                               "create all states and inputs before the dynamics")
        var = StateVariable(name, int(dim), self.n_nodes)
        self._groups["state"].add(var)
        return var

    def create_input_variable(self, name: str, dim: int) -> InputVariable:
        """An input variable of dimension ``dim`` living on nodes 0..N-1."""
        self._check_new(name, dim, "input variable")
        if self._xdot is not None:
            raise RuntimeError(f"cannot create input variable {name!r} after set_dynamics(): "
                               "create all states and inputs before the dynamics")
        var = InputVariable(name, int(dim), self.n_nodes)
        self._groups["input"].add(var)
        return var

    def create_single_variable(self, name: str, dim: int) -> SingleVariable:
        """A decision variable with one value for the whole horizon."""
        self._check_new(name, dim, "single variable")
        var = SingleVariable(name, int(dim))
        self._groups["single"].add(var)
        return var

    def create_parameter(self, name: str, dim: int) -> Parameter:
        """A parameter (one value per node, set with ``assign``), not optimised."""
        self._check_new(name, dim, "parameter")
        var = Parameter(name, int(dim), self.n_nodes)
        self._groups["parameter"].add(var)
        return var

    @property
    def variables(self) -> dict[str, Variable]:
        """Every variable and parameter by name."""
        return {v.name: v for v in [*self.states, *self.inputs, *self.singles, *self.parameters]}

    def get_variable(self, name: str) -> Variable:
        """A variable or parameter by name (clear error if unknown)."""
        try:
            return self.variables[name]
        except KeyError:
            raise KeyError(f"unknown variable {name!r}; variables are: "
                           f"{', '.join(self.variables)}") from None

    # ------------------------------------------------------------------ stacked layout
    @property
    def x(self) -> cs.SX:
        """All states stacked (nx)."""
        return cs.vertcat(*self.states) if self.states else cs.SX(0, 1)

    @property
    def u(self) -> cs.SX:
        """All inputs stacked (nu)."""
        return cs.vertcat(*self.inputs) if self.inputs else cs.SX(0, 1)

    @property
    def s(self) -> cs.SX:
        """All single variables stacked (ns)."""
        return cs.vertcat(*self.singles) if self.singles else cs.SX(0, 1)

    @property
    def p(self) -> cs.SX:
        """All parameters stacked (np)."""
        return cs.vertcat(*self.parameters) if self.parameters else cs.SX(0, 1)

    def x_offset(self, k: int) -> cs.SX:
        """All states at node offset ``k`` stacked."""
        return cs.vertcat(*[v.offset(k) for v in self.states]) if self.states else cs.SX(0, 1)

    def u_offset(self, k: int) -> cs.SX:
        """All inputs at node offset ``k`` stacked."""
        return cs.vertcat(*[v.offset(k) for v in self.inputs]) if self.inputs else cs.SX(0, 1)

    @property
    def nx(self) -> int:
        """State dimension."""
        return sum(v.dim for v in self.states)

    @property
    def ndx(self) -> int:
        """State tangent-space dimension."""
        return sum(v.tangent_dim for v in self.states)

    @property
    def nu(self) -> int:
        """Input dimension."""
        return sum(v.dim for v in self.inputs)

    @property
    def ns(self) -> int:
        """Single-variable dimension."""
        return sum(v.dim for v in self.singles)

    @property
    def np_(self) -> int:
        """Parameter dimension."""
        return sum(v.dim for v in self.parameters)

    # ------------------------------------------------------------------ dynamics
    def set_dynamics(self, xdot: cs.SX) -> None:
        """Set the dynamics: ``xdot``, the time derivative of the stacked states.

        On a manifold state (see ``StateVariable.set_manifold``), ``xdot`` is the tangent
        velocity (e.g. ``v`` for a configuration ``q``), so ``xdot`` has ``ndx`` rows.
        """
        if not self.states:
            raise RuntimeError("create the state variables before setting the dynamics")
        xdot = self._as_sx(xdot, "dynamics")
        if xdot.shape != (self.ndx, 1):
            raise ValueError(f"dynamics: expected an expression of shape ({self.ndx}, 1) "
                             f"(tangent of the stacked states), got {xdot.shape}")
        self._check_symbols(xdot, "dynamics", allow_offsets=False)
        self._xdot = xdot
        self._revision += 1

    @property
    def dynamics(self) -> cs.SX | None:
        """The state derivative expression (None until set)."""
        return self._xdot

    def set_dt(self, dt: float | SingleVariable | Parameter | cs.SX) -> None:
        """Set the interval duration: a number, a single variable or a parameter (or an
        expression of those).

        Raises:
            TypeError: a bool, or something that is not a number or an expression.
            ValueError: a constant that is not a finite number > 0 (also one given as a
                one-element array, list or DM), or a non-scalar expression.
        """
        if isinstance(dt, (bool, np.bool_)):
            raise TypeError(f"dt must be a number or an expression, got the bool {dt}")
        if not isinstance(dt, (int, float, np.floating, np.integer)):
            dt = self._as_sx(dt, "dt")
            if dt.shape != (1, 1):
                raise ValueError(f"dt must be a scalar, got an expression of shape {dt.shape}")
            if dt.is_constant():  # a number in an array, list or DM
                dt = float(cs.evalf(dt))
        if isinstance(dt, (int, float, np.floating, np.integer)):
            if not (dt > 0 and math.isfinite(dt)):
                raise ValueError(f"dt must be a finite number > 0, got {dt}")
            self._dt = float(dt)
            self._revision += 1
            return
        if cs.depends_on(dt, self.x) or cs.depends_on(dt, self.u):
            raise ValueError("dt may depend on single variables and parameters only")
        self._check_symbols(dt, "dt", allow_offsets=False)
        self._dt = dt
        self._revision += 1

    @property
    def dt(self) -> float | cs.SX:
        """The interval duration (float or expression)."""
        if self._dt is None:
            raise RuntimeError("dt is not set: call set_dt()")
        return self._dt

    def transcribe(self, method: str = "multiple_shooting",
                   integrator: str | Integrator | None = None, degree: int | None = None) -> None:
        """Choose the transcription: ``multiple_shooting`` with ``integrator`` (default
        ``rk4``), or ``direct_collocation`` with Legendre polynomials of ``degree`` (1..9,
        default 3). The argument the method does not use is warned about when given (an
        Euler collocation asked for was a Legendre one without a word)."""
        if method not in TRANSCRIPTIONS:
            raise ValueError(f"unknown transcription {method!r}; choose one of {TRANSCRIPTIONS}")
        collocation = method == "direct_collocation"
        if collocation:
            degree = 3 if degree is None else degree
            if not isinstance(degree, (int, np.integer)) or not 1 <= degree <= 9:
                raise ValueError(f"collocation degree must be an int in 1..9, got {degree!r}")
            self.check_transcription(method)
        unused = (f"integrator {integrator if isinstance(integrator, str) else 'custom'!r}"
                  if collocation and integrator is not None else
                  f"degree {degree!r}" if not collocation and degree is not None else None)
        if unused:
            warnings.warn(f"{method}: {unused} is not used ("
                          + ("the collocation polynomial integrates the dynamics"
                             if collocation else "the degree is direct collocation's") + ")",
                          UserWarning, stacklevel=2)
        integrator = "rk4" if integrator is None or collocation else integrator
        self._integrator = get_integrator(integrator)
        self.integrator_name = integrator if isinstance(integrator, str) else "custom"
        self.transcription = method
        self.collocation_degree = int(degree) if collocation else 3
        self._revision += 1

    @property
    def structure_revision(self) -> int:
        """A count that grows with every change a solver built earlier cannot follow: the
        dynamics, dt, the transcription or integrator, a state's manifold. Solvers refuse
        to solve once it moved (build a new one); bounds, guesses, parameters, weights and
        node sets are read at every solve and do not count."""
        return self._revision + sum(v.manifold_revision for v in self.states)

    # ------------------------------------------------------------------ manifold helpers
    def _state_blocks(self):
        i = j = 0
        for v in self.states:
            yield v, i, j
            i += v.dim
            j += v.tangent_dim

    def integrate_expr(self, x: cs.SX, dx: cs.SX) -> cs.SX:
        """``x (+) dx`` on the stacked state manifold."""
        parts = []
        for v, i, j in self._state_blocks():
            xi, dxi = x[i:i + v.dim], dx[j:j + v.tangent_dim]
            parts.append(v.manifold.integrate(xi, dxi) if v.manifold else xi + dxi)
        return cs.vertcat(*parts)

    def difference_expr(self, x0: cs.SX, x1: cs.SX) -> cs.SX:
        """``x1 (-) x0`` on the stacked state manifold."""
        parts = []
        for v, i, _ in self._state_blocks():
            a, b = x0[i:i + v.dim], x1[i:i + v.dim]
            parts.append(v.manifold.difference(a, b) if v.manifold else b - a)
        return cs.vertcat(*parts)

    def state_integrate(self) -> cs.Function:
        """``(x, dx) -> x (+) dx`` as a Function."""
        x, dx = cs.SX.sym("x", self.nx), cs.SX.sym("dx", self.ndx)
        return cs.Function("state_integrate", [x, dx], [self.integrate_expr(x, dx)],
                           ["x", "dx"], ["x_next"])

    def state_difference(self) -> cs.Function:
        """``(x0, x1) -> x1 (-) x0`` as a Function."""
        x0, x1 = cs.SX.sym("x0", self.nx), cs.SX.sym("x1", self.nx)
        return cs.Function("state_difference", [x0, x1], [self.difference_expr(x0, x1)],
                           ["x0", "x1"], ["dx"])

    def continuous_dynamics(self) -> cs.Function:
        """``(x, u, s, p) -> xdot`` (tangent)."""
        self._require_dynamics()
        return cs.Function("xdot", [self.x, self.u, self.s, self.p], [self._xdot],
                           ["x", "u", "s", "p"], ["xdot"])

    def discrete_dynamics(self, integrator: str | Integrator | None = None) -> cs.Function:
        """``(x, u, s, p) -> x_next`` over one interval with the chosen integrator."""
        self._require_dynamics()
        step = self._integrator if integrator is None else get_integrator(integrator)
        f = self.continuous_dynamics()
        x, u, s, p = (cs.SX.sym(n, d) for n, d in
                      (("x", self.nx), ("u", self.nu), ("s", self.ns), ("p", self.np_)))
        dt = self.dt if isinstance(self.dt, float) else cs.substitute(
            self.dt, cs.vertcat(self.s, self.p), cs.vertcat(s, p))
        x_next = step(lambda xx: f(xx, u, s, p), self.integrate_expr, x, dt)
        return cs.Function("F", [x, u, s, p], [x_next], ["x", "u", "s", "p"], ["x_next"])

    def dt_function(self) -> cs.Function:
        """``(s, p) -> dt`` for one node."""
        dt = self.dt
        return cs.Function("dt", [self.s, self.p], [cs.SX(dt) if isinstance(dt, float) else dt],
                           ["s", "p"], ["dt"])

    def check_transcription(self, method: str | None = None) -> None:
        """ValueError when the transcription (``method``, default the problem's) cannot take
        the states: direct collocation sums states as vectors, so none may be on a manifold
        (checked by :meth:`transcribe` and again when a solver is built: a manifold declared
        after ``transcribe`` crashed inside CasADi, or was silently ignored)."""
        method = self.transcription if method is None else method
        if method == "direct_collocation" and any(v.manifold for v in self.states):
            names = [v.name for v in self.states if v.manifold]
            raise ValueError(f"direct_collocation supports vector-space states only; {names} "
                             "on a manifold: use multiple_shooting")

    def check_dt_values(self) -> None:
        """ValueError when dt, an expression of parameters, is not a finite number > 0 on
        some node with the parameters' current values (``set_dt`` checks a constant). With
        single variables in it, not a finite number >= 0 at their initial guess (within
        their bounds), where the solver starts (``T * frac`` with a negative ``frac`` on a
        node solved a time-reversed interval and called it a success; 0 is a time ``T >= 0``
        guessed 0, which solves; keeping dt positive as they move is for their bounds).
        Solvers call it at every solve: a parameter assigned -0.1 solved a time-reversed
        problem and called it a success."""
        dt = self._dt
        if dt is None or isinstance(dt, float):
            return
        singles = np.zeros(self.ns)
        where, least = "with the parameters' values", "> 0"
        if cs.depends_on(dt, self.s):
            singles = np.clip(self.stacked("single").ravel(),
                              self.stacked("single", "lower_bounds").ravel(),
                              self.stacked("single", "upper_bounds").ravel())
            # 0 there is a start on a bound (a time T >= 0 guessed 0), not a reversed interval
            where, least = where + " and the single variables' initial guess", ">= 0"
        # interval k takes dt of node k: node N's value is never used
        values = np.asarray(self.dt_function()(singles, self.parameter_values()[:, :-1]))
        good = np.isfinite(values) & ((values > 0) if least == "> 0" else (values >= 0))
        bad = np.flatnonzero(~good.ravel())
        if bad.size:
            k = int(bad[0])
            raise ValueError(f"dt must be a finite number {least}; {where} it is "
                             f"{float(values.ravel()[k])!r} at node {k}"
                             + (f" (and {bad.size - 1} other node(s))" if bad.size > 1 else ""))

    def _require_dynamics(self) -> None:
        if self._xdot is None:
            raise RuntimeError("the dynamics are not set: call set_dynamics()")
        if self._xdot.shape != (self.ndx, 1):  # a manifold declared after set_dynamics
            raise ValueError(f"dynamics: {self._xdot.shape[0]} rows but the states' tangent "
                             f"space has {self.ndx} (a manifold set after set_dynamics()?): "
                             "set the dynamics again")

    # ------------------------------------------------------------------ terms
    def _known_symbols(self, allow_offsets: bool) -> dict[int, str]:
        """The problem's scalar symbols by identity (``element_hash``), not by name: a
        variable of another problem with the same name is another symbol (it passed here
        and failed later inside CasADi, naming no term)."""
        known = {}
        groups: Iterable = [*self.states, *self.inputs, *self.singles, *self.parameters]
        for v in groups:
            for i in range(v.dim):
                known[v[i].element_hash()] = v.name
            if allow_offsets and isinstance(v, (StateVariable, InputVariable)):
                for k, off in v._offsets.items():
                    for i in range(v.dim):
                        known[off[i].element_hash()] = f"{v.name}.offset({k})"
        return known

    @staticmethod
    def _as_sx(expr, what: str) -> cs.SX:
        """``expr`` as an SX column source: SX, numbers, numpy/DM arrays, or a list/tuple
        of those (stacked); anything else (MX, strings) is a TypeError naming ``what``."""
        if isinstance(expr, cs.SX):
            return expr
        if isinstance(expr, cs.MX):
            raise TypeError(f"{what}: got a CasADi MX expression; build it from the "
                            "problem's variables, which are SX")
        if isinstance(expr, (list, tuple)) and any(isinstance(e, (cs.SX, cs.MX)) for e in expr):
            return cs.vertcat(*(Problem._as_sx(e, what) for e in expr))
        if isinstance(expr, str):
            raise TypeError(f"{what}: got the string {expr!r}, not an expression")
        try:
            return cs.SX(expr)
        except (NotImplementedError, TypeError, ValueError, RuntimeError):
            raise TypeError(f"{what}: expected a CasADi SX expression of the problem's "
                            f"variables or numbers, got {type(expr).__name__}") from None

    def _check_symbols(self, expr: cs.SX, what: str, allow_offsets: bool = True) -> None:
        known = self._known_symbols(allow_offsets)
        unknown = [s.name() for s in cs.symvar(expr) if s.element_hash() not in known]
        if unknown:
            raise ValueError(f"{what}: the expression uses symbols that are not variables of "
                             f"this problem (another problem's, or free symbols; a name "
                             f"is not enough): {unknown[:5]}")

    def _term_layout(self, expr: cs.SX) -> tuple[bool, list[int], np.ndarray]:
        uses_input = bool(self.inputs) and cs.depends_on(expr, self.u)
        offsets: set[int] = set()
        lo, hi = 0, self.n_nodes - (1 if uses_input else 0)
        for v in [*self.states, *self.inputs]:
            for k, off in v._offsets.items():
                if cs.depends_on(expr, off):
                    offsets.add(k)
                    top = self.n_nodes - (1 if isinstance(v, InputVariable) else 0)
                    lo, hi = max(lo, -k), min(hi, top - k)
        return uses_input, sorted(offsets), np.arange(lo, hi + 1)

    def _add_term(self, cls, store: dict, name: str, expr, nodes: NodeSelection, **kw) -> Term:
        if self._finalized:
            raise RuntimeError(f"cannot add {name!r}: the problem is already built into a "
                               "solver; add every constraint and cost first")
        if not isinstance(name, str) or not cs.Function.check_name(name):
            # the name becomes a CasADi Function's, which rejected it only when a solver
            # was built, with its own message
            raise ValueError(f"term name {name!r} is not valid: a letter, then letters, "
                             "digits and single underscores (ASCII), not 'jac', 'hess' or "
                             "'null'")
        if name in self.constraints or name in self.costs:
            raise ValueError(f"a constraint or cost called {name!r} already exists")
        expr = self._as_sx(expr, f"{cls.kind} {name!r}")
        if expr.is_empty() or expr.shape[1] != 1:
            if expr.shape[0] == 1 and expr.shape[1] > 1:
                expr = expr.T
            else:
                raise ValueError(f"{cls.kind} {name!r}: expected a column expression, "
                                 f"got shape {expr.shape}")
        self._check_symbols(expr, f"{cls.kind} {name!r}")
        if cls is Constraint and expr.is_constant():
            raise ValueError(f"constraint {name!r} is a constant ({expr}): it depends on no "
                             "variable, so it always holds or makes the problem infeasible")
        uses_input, offsets, valid = self._term_layout(expr)
        if valid.size == 0:
            raise ValueError(f"{cls.kind} {name!r} is valid on no node of the horizon")
        term = cls(name, expr, None, uses_input, offsets, valid, self.n_nodes, nodes, **kw)
        store[name] = term
        return term

    def create_constraint(self, name: str, expr: Expression, nodes: NodeSelection = None,
                          bounds: tuple[Values, Values] | None = None) -> Constraint:
        """``lb <= expr <= ub`` on ``nodes`` (None: all valid nodes); default ``expr == 0``."""
        return self._add_term(Constraint, self.constraints, name, expr, nodes, bounds=bounds)

    def create_final_constraint(self, name: str, expr: Expression,
                                bounds: tuple[Values, Values] | None = None) -> Constraint:
        """A constraint on the final node N only."""
        return self.create_constraint(name, expr, nodes=self.n_nodes, bounds=bounds)

    def create_cost(self, name: str, residual: Expression, nodes: NodeSelection = None,
                    weight: Values = 1.0) -> Cost:
        """Residual cost ``sum_k weight * ||residual_k||^2`` on ``nodes``."""
        return self._add_term(Cost, self.costs, name, residual, nodes, weight=weight)

    def create_final_cost(self, name: str, residual: Expression,
                          weight: Values = 1.0) -> Cost:
        """A residual cost on the final node N only."""
        return self.create_cost(name, residual, nodes=self.n_nodes, weight=weight)

    def create_general_cost(self, name: str, expr: Expression,
                            nodes: NodeSelection = None) -> GeneralCost:
        """A general scalar cost ``sum_k expr_k`` (IPOPT only; GN solvers refuse it)."""
        expr = self._as_sx(expr, f"general cost {name!r}")
        if expr.shape != (1, 1):
            raise ValueError(f"general cost {name!r} must be scalar, got shape {expr.shape}")
        return self._add_term(GeneralCost, self.costs, name, expr, nodes)

    def remove(self, name: str) -> None:
        """Remove a constraint or cost (before the problem is built into a solver)."""
        if self._finalized:
            raise RuntimeError("cannot remove terms after the problem is built into a solver")
        if self.constraints.pop(name, None) is None and self.costs.pop(name, None) is None:
            raise KeyError(f"no constraint or cost called {name!r}")

    def get_term(self, name: str) -> Term:
        """A constraint or cost by name (clear error if unknown)."""
        if name in self.constraints:
            return self.constraints[name]
        if name in self.costs:
            return self.costs[name]
        raise KeyError(f"unknown constraint or cost {name!r}; known: "
                       f"{', '.join([*self.constraints, *self.costs])}")

    # ------------------------------------------------------------------ building
    def node_arguments(self, offsets: list[int]) -> list[cs.SX]:
        """Symbolic node arguments ``[x, u, s, p, x_o, u_o, ...]`` for ``offsets``."""
        args = [self.x, self.u, self.s, self.p]
        for k in offsets:
            args += [self.x_offset(k), self.u_offset(k)]
        return args

    def finalize(self) -> None:
        """Freeze the layout and build each term's node Function (done by solvers)."""
        if self._finalized:
            return
        self._require_dynamics()
        self.dt  # noqa: B018 - raises when unset
        for term in [*self.constraints.values(), *self.costs.values()]:
            names = ["x", "u", "s", "p"]
            for k in term.offsets:
                names += [f"x_{k:+d}", f"u_{k:+d}"]
            term.function = cs.Function(term.name, self.node_arguments(term.offsets),
                                        [term.expr], names, ["value"])
        self._finalized = True
        log.debug("problem finalized: nx=%d ndx=%d nu=%d ns=%d np=%d N=%d, %d constraints, "
                  "%d costs", self.nx, self.ndx, self.nu, self.ns, self.np_, self.n_nodes,
                  len(self.constraints), len(self.costs))

    @property
    def finalized(self) -> bool:
        """Whether the problem is frozen (built into a solver)."""
        return self._finalized

    def _release(self) -> None:
        """Undo :meth:`finalize`: a solver that failed to build calls it on the problem it
        had frozen (the user can then change the problem and build again)."""
        self._finalized = False

    # ------------------------------------------------------------------ receding horizon
    def shift(self) -> None:
        """Shift every variable's initial guess and every parameter's values one node back.

        The last node keeps its value. Node sets of constraints and costs are not changed;
        update them (``term.set_nodes``) or their parameters for a moving schedule.
        """
        for kind in ("state", "input", "parameter"):
            self._groups[kind].shift()

    def initial_guess(self) -> dict[str, np.ndarray]:
        """Initial guesses of all variables by name (shapes (dim, n_values))."""
        return {v.name: v.initial_guess for v in [*self.states, *self.inputs, *self.singles]}

    def parameter_values(self) -> np.ndarray:
        """Stacked parameter values, shape (np, N+1)."""
        return self.stacked("parameter")

    def stacked(self, kind: str, what: str = "initial_guess", copy: bool = True) -> np.ndarray:
        """Stack ``what`` (initial_guess, lower_bounds, upper_bounds) of a variable kind.

        Returns an array of shape (dim, n_values) for 'state' (N+1), 'input' (N),
        'single' (1) or 'parameter' (N+1, the values). ``copy=False``: the problem's own
        stacked array, read-only and valid until the next change (no copy: the solvers'
        per-solve reading).
        """
        try:
            group = self._groups[kind]
        except KeyError:
            raise KeyError(f"unknown variable kind {kind!r}; kinds are: "
                           f"{', '.join(self._groups)}") from None
        out = group.stacked(what)
        return out.copy() if copy else out

    def set_stacked_initial_guess(self, kind: str, values: np.ndarray) -> None:
        """Write a stacked array (as from :meth:`stacked`, shape (dim, n_values)) back into
        the variables of ``kind``."""
        if kind not in self._groups:
            raise KeyError(f"unknown variable kind {kind!r}; kinds are: "
                           f"{', '.join(self._groups)}")
        self._groups[kind].set_initial_guess(values)
