"""Running one node as a process: spin until SIGINT/SIGTERM, then exit cleanly with 0."""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Sequence

import rclpy
import rclpy.logging
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

__all__ = ["spin_until_signal"]


def spin_until_signal(make_node: Callable[[], Node], args: Sequence[str] | None = None) -> int:
    """Create the node with ``make_node`` and spin it until SIGINT/SIGTERM; returns 0.

    A node that cannot be built from its parameters (``make_node`` raises ValueError,
    KeyError or OSError: unknown robot, missing URDF, a foot the URDF lacks, ...) is
    reported in one fatal log line that names the problem, and the exit code is 1.
    The signals only set a flag that the spin loop checks (rclpy's own handlers would shut
    the context down under a running executor, which can surface as an RCLError).
    """
    stop = threading.Event()
    previous = {sig: signal.signal(sig, lambda *_: stop.set())
                for sig in (signal.SIGINT, signal.SIGTERM)}
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node: Node | None = None
    executor = SingleThreadedExecutor()
    try:
        try:
            node = make_node()
        except (ValueError, KeyError, OSError) as exc:
            message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            rclpy.logging.get_logger("horizon_mpc").fatal(
                f"cannot start: {message} ({type(exc).__name__})")
            return 1
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0
