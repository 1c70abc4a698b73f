"""Entry points of the package's executables (``mpc_node``, ``sim_node``, ``closed_loop``,
``motion``).

Python needs ~0.5 s to import their modules (rclpy, CasADi, Pinocchio, PyBullet); a SIGINT
or SIGTERM in that time ended the process the default way (exit code 143, or a
KeyboardInterrupt traceback). The entry points take both signals before those imports (this
module imports nothing heavy, and ``horizon_mpc`` imports its API lazily) and end the
process quietly, with the exit code the executable gives a signal once it runs, until its
own handlers take over: 0 for the nodes (a ROS node stopped is no error;
:func:`horizon_mpc.nodes.spin.spin_until_signal`), 130 for the command-line tools
(interrupted: ``closed_loop``, ``motion``).
"""

from __future__ import annotations

import contextlib
import importlib
import signal
import sys
import types
from collections.abc import Iterator

__all__ = ["closed_loop", "motion", "mpc_node", "sim_node"]

INTERRUPTED = 130  # the command-line tools' exit code for a SIGINT or SIGTERM


def _run(module: str, code: int = 0) -> int:
    """``module.main()``, a SIGINT or SIGTERM before it takes them ending with ``code``."""
    received: list[int] = []

    def exit_quietly(signum: int, frame: types.FrameType | None) -> None:
        received.append(signum)
        raise SystemExit(code)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, exit_quietly)
    try:
        with quiet_unraisable_exit(received):
            mod = importlib.import_module(module)
    except Exception:
        if received:  # numpy's C extension turns the SystemExit into an ImportError
            return code
        raise
    # the SystemExit can also be lost: raised while the import system compiles a module's
    # source (no .pyc: PYTHONDONTWRITEBYTECODE, a read-only install) it vanished, and
    # closed_loop ran its whole walk after a SIGTERM 10 ms after the launcher took it
    if received:
        return code
    return mod.main()


@contextlib.contextmanager
def quiet_unraisable_exit(received: list[int]) -> Iterator[None]:
    """Within the block, a SystemExit that Python cannot raise (the handler ran inside a
    callback of the import system's module locks) is not printed once a signal was
    ``received``: it printed "Exception ignored ... Traceback ... SystemExit: 130" (1 in
    ~100 signals during the imports); the caller returns the signal's code all the same."""
    previous = sys.unraisablehook

    def hook(unraisable: object) -> None:
        if not (received and isinstance(getattr(unraisable, "exc_value", None), SystemExit)):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous


def mpc_node() -> int:
    """``ros2 run horizon_mpc mpc_node``: :func:`horizon_mpc.nodes.mpc_node.main`."""
    return _run("horizon_mpc.nodes.mpc_node")


def sim_node() -> int:
    """``ros2 run horizon_mpc sim_node``: :func:`horizon_mpc.nodes.sim_node.main`."""
    return _run("horizon_mpc.nodes.sim_node")


def closed_loop() -> int:
    """``ros2 run horizon_mpc closed_loop``: :func:`horizon_mpc.closed_loop.main`."""
    return _run("horizon_mpc.closed_loop", INTERRUPTED)


def motion() -> int:
    """``ros2 run horizon_mpc motion``: :func:`horizon_mpc.motions.cli.main`."""
    return _run("horizon_mpc.motions.cli", INTERRUPTED)
