"""Entry points of the ``mpc_node`` and ``sim_node`` executables.

Python needs ~0.5 s to import a node's modules (rclpy, CasADi, Pinocchio, PyBullet); a
SIGINT or SIGTERM in that time ended the process the default way (exit code 143, or a
KeyboardInterrupt traceback), where a signal to a running node exits with 0. The entry
points take both signals before those imports (this module imports nothing heavy, and
``horizon_mpc`` imports its API lazily) and end the process with exit code 0 until the
node's own handlers take over (:func:`horizon_mpc.nodes.spin.spin_until_signal`).
"""

from __future__ import annotations

import importlib
import signal
import types

__all__ = ["mpc_node", "sim_node"]


def _exit_quietly(signum: int, frame: types.FrameType | None) -> None:
    raise SystemExit(0)


def _run(module: str) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _exit_quietly)
    return importlib.import_module(module).main()


def mpc_node() -> int:
    """``ros2 run horizon_mpc mpc_node``: :func:`horizon_mpc.nodes.mpc_node.main`."""
    return _run("horizon_mpc.nodes.mpc_node")


def sim_node() -> int:
    """``ros2 run horizon_mpc sim_node``: :func:`horizon_mpc.nodes.sim_node.main`."""
    return _run("horizon_mpc.nodes.sim_node")
