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


class _Recorder:
    """Stand-in for the launch classes: keeps its arguments."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


def _launch_description(path: Path, monkeypatch) -> list:
    """The entities of ``path``'s launch description, built with stand-ins of ``launch``
    and ``launch_ros`` (not installable from PyPI)."""
    import sys
    import types

    mods = {"launch": {"LaunchDescription": lambda entities: entities},
            "launch.actions": {"DeclareLaunchArgument": _Recorder},
            "launch.substitutions": {"LaunchConfiguration": lambda name: f"$({name})"},
            "launch_ros.actions": {"Node": _Recorder}}
    for name, attrs in mods.items():
        monkeypatch.setitem(sys.modules, name, types.SimpleNamespace(**attrs))
    monkeypatch.setitem(sys.modules, "launch_ros", types.SimpleNamespace())
    scope: dict = {}
    exec(compile(path.read_text(), str(path), "exec"), scope)  # noqa: S102 - our own file
    return scope["generate_launch_description"]()


def test_sim_mpc_gives_both_nodes_the_same_robot_as_declared_parameters(monkeypatch):
    """Each launch argument reaches both nodes as a parameter the node declares."""
    entities = _launch_description(ROOT / "launch" / "sim_mpc.launch.py", monkeypatch)
    declared = {e.args[0] for e in entities if "executable" not in e.kwargs}
    nodes = {e.kwargs["executable"]: e.kwargs for e in entities if "executable" in e.kwargs}
    assert set(nodes) == {"sim_node", "mpc_node"}
    assert {"robot", "config", "urdf_path"} <= declared
    from horizon_mpc.nodes.mpc_parameters import parameter_names
    from horizon_mpc.nodes.sim_node import SIM_PARAMETERS

    for exe, kwargs in nodes.items():
        params = {k: v for d in kwargs["parameters"] for k, v in d.items()}
        for name in declared:
            assert params[name] == f"$({name})", (exe, name)
            if exe == "mpc_node":
                assert name in parameter_names(), f"{exe} declares no {name!r}"
            else:
                assert name in {p[0] for p in SIM_PARAMETERS}, f"{exe} declares no {name!r}"
    assert nodes["mpc_node"]["parameters"][0]["use_sim_time"] is True
    # the names 'ros2 run' gives them: a params file keyed by node name works on both routes
    # (the launch file named them mpc_node / sim_node, and such a file applied nothing
    # under ros2 run)
    for exe, kwargs in nodes.items():
        source = (ROOT / "horizon_mpc" / "nodes" / f"{exe}.py").read_text()
        assert re.search(rf'DEFAULT_NAME = "{kwargs["name"]}"', source), exe
        assert "node_name: str = DEFAULT_NAME" in source, exe
    from horizon_mpc.nodes.spin import PACKAGE_NODES  # a params file shared by both

    assert set(PACKAGE_NODES) == {kwargs["name"] for kwargs in nodes.values()}
