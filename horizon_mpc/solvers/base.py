"""The interface every solver implements (``make_solver(name, prb, opts)``).

Life cycle::

    solver = make_solver('ipopt', prb, {'max_iter': 100})
    ok = solver.solve()                 # starts from the variables' initial guesses
    solver.solution['q']                # (dim, N+1) for states, (dim, N) for inputs
    solver.stats                        # see SolverStats
    solver.shift()                      # receding horizon: shift guesses (and multipliers)
    ok = solver.solve()                 # warm re-solve, nothing rebuilt

After every solve the solution is written back into the variables' initial guesses
(option ``warm_start``, default True), so ``shift()`` + ``solve()`` is a warm start.
"""

from __future__ import annotations

import logging
import math
import numbers
import sys
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from horizon_mpc.problem import Problem

log = logging.getLogger(__name__)
#: the ``verbose`` option's per-iteration lines: INFO records that reach stdout through a
#: handler of their own (INFO is silent unless the caller configured logging, and
#: ``verbose`` then showed nothing); not propagated, so a configured root does not repeat
#: them
progress_log = logging.getLogger("horizon_mpc.solvers.progress")

__all__ = ["Solver", "SolverStats"]


@dataclass
class SolverStats:
    """What a solve did. ``constraint_violation`` is the max over dynamics defects,
    constraints and variable bounds (inf-norm)."""

    success: bool = False
    status: str = "not solved"
    iterations: int = 0
    time: float = 0.0
    cost: float = math.nan
    constraint_violation: float = math.nan
    history: list[dict[str, float]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def __getitem__(self, key: str) -> Any:  # dict-style access: stats['iterations']
        return asdict(self)[key] if key != "extra" else self.extra

    def as_dict(self, history: bool = True) -> dict[str, Any]:
        """A JSON-friendly dict, ``extra`` merged in; without the iteration ``history``
        when asked (cheap enough for every tick of an MPC: no deep copy)."""
        if history:
            d = asdict(self)
            d.update(d.pop("extra"))
            return d
        out = {f.name: getattr(self, f.name) for f in fields(self)
               if f.name not in ("history", "extra")}
        out.update({k: dict(x) if isinstance(x, dict) else x for k, x in self.extra.items()})
        return out


class _StdoutHandler(logging.StreamHandler):
    """A stream handler on whatever ``sys.stdout`` is when a record is emitted (a handler
    bound once would keep writing to a stream replaced since, e.g. by a capture)."""

    @property
    def stream(self):  # noqa: D102
        return sys.stdout

    @stream.setter
    def stream(self, _value) -> None:
        pass


class Solver:
    """Base class: holds the problem, options and the last solution.

    Subclasses implement :meth:`_solve` and declare ``DEFAULTS`` (option name -> default).
    Unknown option names raise ``ValueError`` listing the known ones.
    """

    name = "solver"
    DEFAULTS: dict[str, Any] = {}
    COMMON = {"warm_start": True, "verbose": False}
    #: option -> the values it takes: '>0', '>=0', '>=1' (a number; None passes where the
    #: default is None), '(0,1)' or '[lo,hi]'; checked with the type, ValueError naming
    #: the option
    RANGES: dict[str, str] = {}
    #: option -> the values it may take (a choice among names), checked as RANGES are
    CHOICES: dict[str, tuple[str, ...]] = {}
    #: options read when the solver is built: set_option refuses to change them (the change
    #: would be accepted and have no effect)
    BUILD_ONLY: tuple[str, ...] = ()

    def __init__(self, prb: Problem, opts: dict[str, Any] | None = None):
        self.prb = prb
        if opts is not None and not isinstance(opts, Mapping):
            raise TypeError(f"options of solver {self.name!r} must be a dict (name -> value), "
                            f"got {type(opts).__name__}")
        self.opts = self._merge_options(dict(opts or {}))
        self._check_together(self.opts)
        # before finalize(): a problem refused here can still be changed and solved
        self._check_problem(prb)
        prb.finalize()
        self._structure_revision = prb.structure_revision
        self.solution: dict[str, np.ndarray] = {}
        self.stats = SolverStats()
        for key, kind, group in (("x", "states", prb.states), ("u", "inputs", prb.inputs)):
            named = [v for v in (*prb.states, *prb.inputs, *prb.singles) if v.name == key]
            if named and not (len(group) == 1 and group[0] is named[0]):
                # a state 'x' beside other states (the bundled double integrator's position)
                log.warning("solution[%r] will be the variable %r, not the stacked %s: "
                            "those are in solver.stacked_solution", key, key, kind)

    def _progress(self, line: str) -> None:
        """One line of progress for the ``verbose`` option (:data:`progress_log`)."""
        if not progress_log.handlers:
            handler = _StdoutHandler()
            handler.setFormatter(logging.Formatter("%(message)s"))
            progress_log.addHandler(handler)
            progress_log.setLevel(logging.INFO)
            progress_log.propagate = False
        progress_log.info("%s: %s", self.name, line)

    @property
    def stacked_solution(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The last solution stacked: states (nx, N+1), inputs (nu, N), singles (ns, 1)
        (``solution['x']`` and ``solution['u']`` too, unless a variable has that name), or
        None before a solve."""
        return getattr(self, "_stacked_solution", None)

    def check_problem_unchanged(self) -> None:
        """Raise RuntimeError when the problem's structure (dynamics, dt, transcription, a
        manifold: ``Problem.structure_revision``) changed after this solver was built: it
        would go on solving the old one."""
        if self.prb.structure_revision != self._structure_revision:
            raise RuntimeError(f"{self.name}: the problem's dynamics, dt, transcription or a "
                               "state manifold changed after this solver was built, and it "
                               "would solve the old problem: build a new solver (make_solver)")

    def _merge_options(self, opts: dict[str, Any]) -> dict[str, Any]:
        known = {**self.COMMON, **self.DEFAULTS}
        unknown = set(opts) - set(known) - set(self._passthrough_keys(opts))
        if unknown:
            raise ValueError(f"unknown option(s) {sorted(unknown)} for solver {self.name!r}; "
                             f"options are: {sorted(known)}")
        for key, value in opts.items():
            if key in known:
                self._check_option_type(key, value, known[key])
                self._check_option_range(key, value)
                choices = self.CHOICES.get(key)
                if choices is not None and value not in choices:
                    raise ValueError(f"option {key!r} of solver {self.name!r} must be one of "
                                     f"{list(choices)}, got {value!r}")
        return {**known, **opts}

    def _check_together(self, opts: dict[str, Any]) -> None:
        """ValueError/TypeError when options are inconsistent with each other (e.g. a
        minimum above its maximum): a hook, run on every change with all the options."""

    def _check_problem(self, prb: Problem) -> None:
        """ValueError when this solver cannot solve ``prb`` (a hook, run before the problem
        is finalized, so that the user can still change it)."""

    def _check_option_range(self, key: str, value: Any) -> None:
        """ValueError unless a number option is within its :attr:`RANGES` (NaN never is)."""
        rule = self.RANGES.get(key)
        if rule is None or value is None:
            return
        if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
            raise TypeError(f"option {key!r} of solver {self.name!r} must be a number, got "
                            f"{value!r} ({type(value).__name__})")
        x = float(value)
        if rule.startswith("["):  # a closed interval "[lo,hi]"
            lo, hi = (float(b) for b in rule[1:-1].split(","))
            ok = lo <= x <= hi
        else:
            ok = {">0": x > 0, ">=0": x >= 0, ">=1": x >= 1, "(0,1)": 0 < x < 1}[rule]
        if not ok:
            raise ValueError(f"option {key!r} of solver {self.name!r} must be {rule}, got "
                             f"{value!r}")

    def _check_option_type(self, key: str, value: Any, default: Any) -> None:
        """TypeError unless ``value`` is of the default's kind (bool, int, real number,
        string, mapping); options whose default is None take anything."""
        if isinstance(default, bool):
            ok, kind = isinstance(value, (bool, np.bool_)), "a bool"
        elif isinstance(default, int):
            ok, kind = isinstance(value, numbers.Integral) and not isinstance(
                value, (bool, np.bool_)), "an int"
        elif isinstance(default, float):
            ok, kind = isinstance(value, numbers.Real) and not isinstance(
                value, (bool, np.bool_)), "a number"
        elif isinstance(default, str):
            ok, kind = isinstance(value, str), "a string"
        elif isinstance(default, dict):
            ok, kind = isinstance(value, dict), "a dict"
        else:
            return
        if not ok:
            raise TypeError(f"option {key!r} of solver {self.name!r} must be {kind}, got "
                            f"{value!r} ({type(value).__name__})")

    def _passthrough_keys(self, opts: dict[str, Any]) -> list[str]:
        """Option keys handed to a backend unchecked (e.g. ``ipopt.*``)."""
        return []

    def set_option(self, key: str, value: Any) -> None:
        """Change one option between solves (not one of :attr:`BUILD_ONLY`)."""
        self._merge_options({key: value})  # validates the name and the value
        if key in self.BUILD_ONLY and value != self.opts[key]:
            raise ValueError(f"option {key!r} of solver {self.name!r} is read when the solver "
                             "is built: set it in make_solver's options")
        self._check_together({**self.opts, key: value})
        self.opts[key] = value

    def solve(self) -> bool:
        """Solve from the current initial guesses; returns success.

        Raises:
            RuntimeError: the problem's structure changed since the solver was built
                (see :meth:`check_problem_unchanged`).
            ValueError: dt, an expression of parameters, is not > 0 with their values
                (:meth:`.Problem.check_dt_values`).
        """
        self.check_problem_unchanged()
        self.prb.check_dt_values()
        try:
            ok = self._solve()
        except BaseException as exc:  # an exception in a solve (a callback's, Ctrl-C): the
            # stats said the previous solve's success
            self.stats.success = False
            self.stats.status = f"interrupted ({type(exc).__name__})"
            raise
        if self.solution and self.opts["warm_start"]:
            self._write_back()
        return ok

    def _solve(self) -> bool:
        raise NotImplementedError

    def shift(self) -> None:
        """Receding horizon: shift the problem's guesses/parameters and solver state."""
        self.prb.shift()

    def reset(self) -> None:
        """Forget what the solver carries from one solve to the next (its multipliers): the
        next solve starts cold from the problem's initial guesses."""

    def _write_back(self) -> None:
        """The solution becomes the problem's initial guess (one write per kind)."""
        for kind, values in zip(("state", "input", "single"), self._stacked_solution,
                                strict=True):
            self.prb.set_stacked_initial_guess(kind, values)

    def _split_solution(self, X: np.ndarray, U: np.ndarray, S: np.ndarray) -> None:
        """Fill ``self.solution`` from stacked arrays X (nx, N+1), U (nu, N), S (ns, 1)."""
        self._stacked_solution = (X, U, S)
        sol: dict[str, np.ndarray] = {"x": X, "u": U}
        for group, arr in ((self.prb.states, X), (self.prb.inputs, U), (self.prb.singles, S)):
            i = 0
            for v in group:
                sol[v.name] = arr[i:i + v.dim].copy()
                i += v.dim
        self.solution = sol
