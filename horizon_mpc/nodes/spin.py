"""Running one node as a process: spin until SIGINT/SIGTERM, then exit cleanly with 0."""

from __future__ import annotations

import contextlib
import faulthandler
import itertools
import logging
import os
import re
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Sequence

import rclpy
import rclpy.logging
import yaml
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from horizon_mpc.nodes.declare import parameter_overrides

__all__ = ["forward_library_warnings", "spin_until_signal", "split_arguments",
           "undeclared_overrides", "unmatched_parameter_rules",
           "unmatched_params_file_sections"]


# what a node's construction raises on bad parameters or files: one line, no traceback
_USER_ERRORS = (ValueError, KeyError, OSError, ParameterException, yaml.YAMLError)


def spin_until_signal(make_node: Callable[[], Node], args: Sequence[str] | None = None,
                      usage: str | Callable[[], str] | None = None,
                      process_exits: bool = False) -> int:
    """Create the node with ``make_node`` and spin it until SIGINT/SIGTERM; returns 0.

    ``process_exits``: the caller ends the process with the returned code (an executable's
    ``main``): SIGINT and SIGTERM are then ignored from the return on, not given back to
    their previous handlers. Ctrl-C under ``ros2 launch`` signals the process group, and
    launch forwards its own SIGINT a few ms later: that second signal killed the
    interpreter's teardown, exit code -2 or -15 instead of 0.

    ``args``: the process's arguments (``sys.argv`` when None; the first is the program).
    ``-h``/``--help`` before ``--ros-args`` prints ``usage`` (a text, or a function that
    makes it) and returns 0 without building the node; other arguments outside
    ``--ros-args`` are not ROS arguments: the node ignores them, with a warning naming them.

    A node that cannot be built from its parameters (``make_node`` raises ValueError,
    KeyError, OSError, an rclpy ParameterException or a YAML error: unknown robot, missing
    URDF, a foot the URDF lacks, a value out of its range, ...) is reported in one fatal
    log line that names the problem, and the exit code is 1; any other error at start-up
    is reported with its traceback, exit code 1. ROS arguments rcl cannot parse: one line
    on stderr, exit code 2. SIGINT/SIGTERM during the start-up (e.g. while the problem
    compiles; the compiler is stopped): the build is interrupted at once, exit code 0, no
    traceback.
    The signals only set a flag that the spin loop checks (rclpy's own handlers would shut
    the context down under a running executor, which can surface as an RCLError).
    """
    argv = list(sys.argv if args is None else args)
    plain = split_arguments(argv)[0]
    if usage is not None and ({"-h", "--help"} & set(plain)):
        sys.stdout.write((usage() if callable(usage) else usage).rstrip("\n") + "\n")
        return 0
    stop = threading.Event()
    starting = True
    exit_code = [0]  # what a hung teardown exits with (the watchdog's)
    failure: list[str] = []  # the traceback of an error in the spin, said by the watchdog

    def on_signal(*_: object) -> None:
        stop.set()
        if starting:  # interrupt the build (a compiler run of ~15 s) instead of waiting
            raise _StartupInterrupted

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except RuntimeError as exc:  # rclpy's RCLError: e.g. a dangling '-p'
        sys.stderr.write(f"cannot start: bad ROS arguments: {exc}\n")
        _release(previous, process_exits)
        return 2
    except _StartupInterrupted:
        rclpy.try_shutdown()
        _release(previous, process_exits)
        return 0
    node: Node | None = None
    executor = SingleThreadedExecutor()
    log = rclpy.logging.get_logger("horizon_mpc")
    forward_library_warnings()
    if plain:
        log.warning(f"ignoring arguments that are not ROS arguments: {' '.join(plain)} "
                    "(parameters go after --ros-args: --ros-args -p name:=value)")
    try:
        try:
            node = make_node()
            starting = False
        except _StartupInterrupted:
            log.info("interrupted during start-up")
            return 0
        except Exception as exc:  # noqa: BLE001 - start-up errors end the process here
            if stop.is_set():
                log.info("interrupted during start-up")
                return 0
            message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            if isinstance(exc, _USER_ERRORS):
                log.fatal(f"cannot start: {message} ({type(exc).__name__})")
            else:
                log.fatal(f"cannot start: {type(exc).__name__}: {message}\n"
                          + traceback.format_exc())
            exit_code[0] = 1
            return 1
        if stop.is_set():  # a signal while the node was being built
            return 0
        fqn = node.get_fully_qualified_name()
        for note in (*unmatched_params_file_sections(argv, fqn,
                                                     getattr(node, "DEFAULT_NAME", None)),
                     *unmatched_parameter_rules(argv, fqn)):
            log.warning(note)
        unknown = undeclared_overrides(node)
        if unknown:
            log.warning(f"parameter(s) {unknown} set for {node.get_fully_qualified_name()} "
                        "are not parameters of this node (misspelt, or another node's, e.g. from a "
                        "/** section, which applies to every node): ignored; --help lists its "
                        "parameters")
        executor.add_node(node)
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException, _StartupInterrupted):
        pass
    except Exception:  # a bug: its exit code and traceback, even if the teardown hangs
        exit_code[0] = 1
        failure.append(traceback.format_exc())
        raise
    finally:
        starting = False
        with _teardown_watchdog(process_exits, exit_code, failure):
            executor.shutdown()
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        _release(previous, process_exits)
    return 0


#: wall s the DDS teardown may take before an executable's process ends without it
TEARDOWN_TIMEOUT = 5.0
#: s more before faulthandler ends it (stacks on stderr, exit code 1) when even that cannot
#: run (a C call that keeps the GIL)
TEARDOWN_BACKSTOP = 5.0


@contextlib.contextmanager
def _teardown_watchdog(process_exits: bool, exit_code: list[int], failure: list[str],
                       timeout: float | None = None):
    """End the process (one line on stderr, exit code ``exit_code[0]``: 0 after a signal,
    1 after a start-up error or an error in the spin, whose traceback, ``failure``, is
    written first) when the teardown inside takes longer than ``timeout``
    (default :data:`TEARDOWN_TIMEOUT`); only for an executable (``process_exits``). An
    auditor's mpc_node hung in Fast DDS's participant teardown (a lock taken by its
    discovery thread as the simulator left at the same moment; 1 stop in ~14) and never
    exited, not even on SIGTERM. Without a usable stderr (``2>&-``) there is no faulthandler
    backstop; the teardown runs all the same."""
    if not process_exits:
        yield
        return
    timeout = TEARDOWN_TIMEOUT if timeout is None else timeout

    def give_up() -> None:
        with contextlib.suppress(Exception):  # (no stderr: exit all the same)
            sys.stderr.write("".join(failure))
            sys.stderr.write(f"[horizon_mpc] shutdown: the ROS/DDS teardown did not finish "
                             f"within {timeout:g} s (a middleware deadlock); exiting without "
                             "it\n")
            sys.stderr.flush()
        os._exit(exit_code[0])

    timer = threading.Timer(timeout, give_up)
    timer.daemon = True
    timer.start()
    try:  # faulthandler needs a stderr with a file descriptor
        faulthandler.dump_traceback_later(timeout + TEARDOWN_BACKSTOP, exit=True)
        backstop = True
    except (RuntimeError, ValueError, AttributeError, OSError):
        backstop = False
    try:
        yield
    finally:
        timer.cancel()
        if backstop:
            faulthandler.cancel_dump_traceback_later()


#: default names of this package's nodes (mpc_node, sim_node)
PACKAGE_NODES = ("mpc", "sim")


def unmatched_params_file_sections(argv: Sequence[str], fqn: str,
                                   default_name: str | None = None) -> list[str]:
    """Notes on the sections of the ``--params-file`` files in ``argv`` that set parameters
    of no node named ``fqn`` (fully qualified): rcl ignores them without a word
    (a file keyed ``mpc_node:`` for the node ``mpc``). Sections of this package's other
    nodes (:data:`PACKAGE_NODES` but the node's own ``default_name``) in the same namespace
    are not named: a file shared by ``mpc_node`` and ``sim_node`` (a node renamed from
    ``mpc`` still hears of an ``mpc:`` section). Wildcards (``/**``, ``*``) match as in
    rcl; an unreadable file is rcl's to report."""
    notes = []
    for flag, path in itertools.pairwise(argv):
        if flag != "--params-file":
            continue
        try:
            with open(path, encoding="utf-8") as fh:
                data = yaml.safe_load(fh)
        except (OSError, yaml.YAMLError, ValueError, RecursionError):
            continue  # (rcl reads the file; this check only adds a warning)
        # a file shared by this package's nodes (README: one file for both) holds the
        # other node's section: that one is no mistake
        namespace = fqn.rsplit("/", 1)[0]
        siblings = [f"{namespace}/{name}" for name in PACKAGE_NODES if name != default_name]
        keys = [k for k in _node_keys(data, [])
                if not any(_matches(k, name) for name in (fqn, *siblings))]
        if keys:
            notes.append(f"--params-file {path}: section(s) {keys} match no node here (this "
                         f"node is {fqn}): their parameters are not applied")
    return notes


def unmatched_parameter_rules(argv: Sequence[str], fqn: str) -> list[str]:
    """Notes on the ``-p node:name:=value`` rules in ``argv``'s ``--ros-args`` whose node
    matches no node named ``fqn``: rcl ignores them without a word (``-p mpc:gait:=walk``
    for the node renamed ``-r __node:=other``)."""
    _, ros = split_arguments(argv)
    notes = []
    for flag, rule in itertools.pairwise(ros):
        if flag not in ("-p", "--param") or ":=" not in rule:
            continue
        target, _, name = rule.split(":=", 1)[0].rpartition(":")
        if target and not _matches(target, fqn):
            notes.append(f"-p {rule}: for the node {target!r}, and this node is {fqn}: "
                         f"{name!r} is not applied")
    return notes


def undeclared_overrides(node: Node) -> list[str]:
    """The parameters set for ``node`` (``-p``, params-file sections matching it, resolved
    by rcl) that it never declared, sorted: rclpy ignores them without a word (``max_xv``
    for ``max_vx`` left the default limit)."""
    return sorted(n for n in parameter_overrides(node) if not node.has_parameter(n))


def _node_keys(data: object, prefix: list[str]) -> list[str]:
    """The node keys of an rcl parameters file: the paths down to ``ros__parameters``."""
    if not isinstance(data, dict):
        return []
    if "ros__parameters" in data:
        return ["/".join(prefix)]
    return [k for key, value in data.items() for k in _node_keys(value, [*prefix, str(key)])]


def _matches(key: str, fqn: str) -> bool:
    """Whether an rcl parameters-file node key matches the node's fully qualified name (a
    key without a leading slash is taken from the root, as rcl does): ``**`` stands for any
    namespaces (none included), ``*`` for one name or part of one."""
    regex = "".join("(?:/[^/]+)*" if part == "**" else "/" + re.escape(part).replace(
        r"\*", "[^/]*") for part in key.split("/") if part)
    return bool(re.fullmatch(regex, fqn))


def split_arguments(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """``(plain, ros)``: the arguments of ``argv`` (the program first, left out) outside and
    inside its ``--ros-args ... [--]`` blocks (the flags themselves in neither)."""
    plain, ros, in_ros = [], [], False
    for a in list(argv)[1:]:
        if a == "--ros-args":
            in_ros = True
        elif in_ros and a == "--":
            in_ros = False
        else:
            (ros if in_ros else plain).append(a)
    return plain, ros


class _StartupInterrupted(BaseException):
    """SIGINT/SIGTERM while the node is being built (not an Exception: the build's own
    error handling must not swallow it)."""


def _release(previous: dict, process_exits: bool) -> None:
    """The signals' previous handlers back, or (``process_exits``) ignore them: the process
    ends next, and a second signal must not kill its teardown."""
    for sig, handler in previous.items():
        signal.signal(sig, signal.SIG_IGN if process_exits else handler)


class _RosLogHandler(logging.Handler):
    """Python log records -> the ROS logger of the same name (console and /rosout)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            logger = rclpy.logging.get_logger(record.name)
            text = self.format(record)
            if record.levelno >= logging.CRITICAL:
                logger.fatal(text)
            elif record.levelno >= logging.ERROR:
                logger.error(text)
            elif record.levelno >= logging.WARNING:
                logger.warning(text)
            else:
                logger.info(text)
        except Exception:  # noqa: BLE001 - logging must never raise into the caller
            self.handleError(record)


#: library loggers whose INFO lines reach the ROS loggers too: the compilation's progress
#: (a first start compiles for tens of seconds to minutes, and the node said nothing)
PROGRESS_LOGGERS = ("horizon_mpc.codegen", "horizon_mpc.solvers.ilqr.riccati_c")


def forward_library_warnings() -> None:
    """Send the library's warnings (Python ``logging`` under ``horizon_mpc``, e.g. "ILQR
    failed ...: back to the standing warm start") and the compilation's progress (the INFO
    lines of :data:`PROGRESS_LOGGERS`: "compiling NAME ...") to the ROS loggers, so they
    reach the console and /rosout like the node's own. Idempotent."""
    lib = logging.getLogger("horizon_mpc")
    if not any(isinstance(h, _RosLogHandler) for h in lib.handlers):
        lib.addHandler(_RosLogHandler(logging.WARNING))
    for name in PROGRESS_LOGGERS:
        logger = logging.getLogger(name)
        if not any(isinstance(h, _RosLogHandler) for h in logger.handlers):
            handler = _RosLogHandler(logging.INFO)
            # below WARNING only: the warnings propagate to the library's handler
            handler.addFilter(lambda record: record.levelno < logging.WARNING)
            logger.addHandler(handler)
            if logger.getEffectiveLevel() > logging.INFO:
                logger.setLevel(logging.INFO)
