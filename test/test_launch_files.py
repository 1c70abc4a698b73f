"""Launch files: valid Python that declares its arguments and starts declared executables.

``launch``/``launch_ros`` are not on PyPI, so the files are checked statically here; a ROS 2
installation runs them with ``ros2 launch horizon_mpc <file>``.
"""

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
LAUNCH = sorted((ROOT / "launch").glob("*.launch.py"))


def _executables() -> set[str]:
    text = (ROOT / "setup.py").read_text()
    block = text[text.index("EXECUTABLES"):]
    block = block[:block.index("}") + 1]
    return set(re.findall(r'"(\w+)":', block))


def test_there_are_launch_files():
    assert {p.name for p in LAUNCH} >= {"closed_loop.launch.py", "sim_mpc.launch.py"}


@pytest.mark.parametrize("path", LAUNCH, ids=lambda p: p.name)
def test_launch_file_defines_the_entry_point_and_uses_declared_executables(path):
    tree = ast.parse(path.read_text(), filename=str(path))
    names = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in names
    used = {kw.value.value for node in ast.walk(tree) if isinstance(node, ast.Call)
            for kw in node.keywords
            if kw.arg == "executable" and isinstance(kw.value, ast.Constant)}
    assert used and used <= _executables(), used - _executables()
    text = path.read_text()
    assert '"robot"' in text and "DeclareLaunchArgument" in text  # robot is an argument


def test_closed_loop_arguments_exist_on_the_cli():
    """Every flag the launch file passes is one the closed_loop CLI accepts."""
    from horizon_mpc.closed_loop import main  # noqa: F401  (import check)

    text = (ROOT / "launch" / "closed_loop.launch.py").read_text()
    flags = set(re.findall(r'"(--[a-z-]+)"', text))
    cli = (ROOT / "horizon_mpc" / "closed_loop.py").read_text()
    assert flags and all(f'"{flag}"' in cli for flag in flags)
