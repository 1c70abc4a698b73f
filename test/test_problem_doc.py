"""The runnable example of doc/problem.md runs and gives what its comment says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).resolve().parents[1] / "doc" / "problem.md"


def test_cartpole_example_in_the_documentation_runs():
    text = DOC.read_text()
    section = text[text.index("## A runnable example"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, str(DOC), "exec"), namespace)  # noqa: S102 - our own documentation
    solver = namespace["solver"]
    assert solver.stats.iterations <= 12  # 9 with IPOPT 3.14 / MUMPS here
    assert solver.stats.cost == pytest.approx(67.0675, abs=1e-4)
    assert solver.solution["u"].shape == (1, 100)
    np.testing.assert_allclose(solver.solution["q"][:, -1], [0.0, np.pi], atol=1e-8)


README = DOC.parents[1] / "README.md"


@pytest.mark.parametrize("solver_call", [
    'make_solver("ilqr", prb)', 'make_solver("ipopt", prb)',
    'make_solver("gnsqp", prb)'])
def test_the_readme_example_solves_with_each_solver_its_comment_names(solver_call):
    text = README.read_text()
    section = text[text.index("## The library in a few lines"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    assert 'make_solver("ilqr", prb)' in code
    namespace: dict = {}
    exec(compile(code.replace('make_solver("ilqr", prb)', solver_call), str(README), "exec"),
         namespace)  # noqa: S102 - our own documentation
    solver = namespace["solver"]
    assert solver.stats.success, solver.stats.status
    assert solver.stats.cost == pytest.approx(73.3816, abs=1e-3)
    assert solver.solution["x"].shape == (2, 61)


def test_every_solver_option_is_in_its_docstring_table():
    """The ILQR's options were one prose paragraph that had lost some; each solver's table
    (class or module docstring) names every option it takes."""
    import sys

    from horizon_mpc.solvers.gnsqp import GnSqpSolver
    from horizon_mpc.solvers.ilqr.solver import IlqrSolver
    from horizon_mpc.solvers.ipopt import IpoptSolver

    for cls in (IlqrSolver, GnSqpSolver, IpoptSolver):
        doc = (cls.__doc__ or "") + (sys.modules[cls.__module__].__doc__ or "")
        missing = [o for o in cls.DEFAULTS if f"``{o}``" not in doc and f"``{o}*``" not in doc]
        assert not missing, (cls.name, missing)


def test_the_docstring_examples_of_the_library_run():
    """The ``>>>`` examples of the modules' docstrings (problem.py's printed two reprs it
    did not show until session 32: nothing ran them)."""
    import doctest

    import casadi as cs

    import horizon_mpc.problem.problem as problem_module

    result = doctest.testmod(problem_module, extraglobs={"cs": cs, "np": np})
    assert result.attempted >= 8 and result.failed == 0
