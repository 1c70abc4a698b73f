"""``motion``: solve one of the paper's three motions offline and write its outputs.

    ros2 run horizon_mpc motion leap [--robot go2] [--solver ipopt] [--out out/motions/leap]
    python -m horizon_mpc.motions turn --robot centauro
    motion walk --solver gnsqp --set duration=1.0

Settings come from ``config/motions/<motion>.yaml`` (per robot), ``--set KEY=VALUE``
overrides one (the value is read as YAML: ``--set velocity=[0.2,0,0]``).
"""

from __future__ import annotations

import _thread
import argparse
import dataclasses
import logging
import os
import signal
import socket
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

if TYPE_CHECKING:  # the heavy modules are imported when a motion runs
    from horizon_mpc.config import RobotConfig
    from horizon_mpc.model import RobotModel
    from horizon_mpc.motions.result import MotionResult

__all__ = ["MOTIONS", "main"]

MOTIONS = ("leap", "turn", "walk")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="motion", description="Solve a motion of the Horizon paper offline (leap, turn, "
        "walk) and write its solution, plots, animation and summary.")
    p.add_argument("motion", choices=MOTIONS)
    p.add_argument("--robot", help="robot config name or YAML path (default: the motion's)")
    p.add_argument("--solver", choices=("ipopt", "gnsqp", "ilqr"),
                   help="solver (default: the motion's: ipopt for leap/turn, ilqr for walk)")
    p.add_argument("--out", help="output folder (default: out/motions/<motion>)")
    p.add_argument("--config", help="motion config YAML (default: config/motions/<motion>.yaml)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting (repeatable)")
    p.add_argument("--no-animation", action="store_true", help="skip the GIF")
    p.add_argument("--no-replay", action="store_true",
                   help="leap: skip the open-loop PyBullet replay")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="debug logging and the solver's iterations as they go")
    return p


def _overrides(items: Sequence[str]) -> dict:
    from horizon_mpc.config import parse_yaml  # read as the config files are (1e-4 a number)

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ValueError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            out[key.strip()] = parse_yaml(value)
        except yaml.YAMLError as exc:  # six lines of PyYAML's, naming no item
            mark = getattr(exc, "problem_mark", None)
            where = f" at column {mark.column + 1}" if mark is not None else ""
            raise ValueError(f"--set {item!r}: not a YAML value ({getattr(exc, 'problem', '')}"
                             f"{where})") from None
        except ValueError as exc:  # a date 2001-13-45, nesting too deep
            raise ValueError(f"--set {item!r}: not a YAML value ({exc})") from None
    return out


def _first_missing(folder: Path) -> Path | None:
    """The outermost of ``folder`` and its parents that does not exist yet (None: it does)."""
    missing = None
    for d in (folder, *folder.parents):
        if d.exists():
            return missing
        missing = d
    return missing


def _remove_empty(folder: Path, made: Path | None) -> None:
    """Remove ``folder`` and its parents up to ``made`` (the first this run made), while
    they are empty: a run that wrote nothing leaves no folder behind (a walk too short to
    build left an empty one)."""
    if made is None:
        return
    for d in (folder, *folder.parents):
        try:
            d.rmdir()
        except OSError:  # not empty (or gone): keep it and what holds it
            return
        if d == made:
            return


# exit code of an interrupted run (SIGINT, SIGTERM), as a shell gives a process ended by SIGINT
INTERRUPTED = 130


_signals: list[int] = []  # the SIGINT/SIGTERM received (see _checkpoint)
_ending: list[bool] = []  # main is ending the run: a signal's exception is not wanted now
#: s after a signal when its KeyboardInterrupt is raised again, if the run still goes on
RAISE_AGAIN = 0.5


def _interrupt(signum: int, *_: object) -> None:
    _signals.append(signum)
    if _ending:
        return
    if len(_signals) == 1:
        # raised while Python compiles a module it imports (no .pyc files), the exception
        # vanishes: a leap interrupted in its first second was solved and written. The
        # same signal again a moment later, unless main is ending the run by then
        again = threading.Timer(RAISE_AGAIN, _thread.interrupt_main, (signal.SIGTERM,))
        again.daemon = True
        again.start()
    raise KeyboardInterrupt


def _checkpoint() -> None:
    """KeyboardInterrupt if a signal came and its exception was lost on the way."""
    if _signals:
        raise KeyboardInterrupt


#: s a run has, after SIGINT/SIGTERM, to end by itself before the process ends at once
FORCE_EXIT_AFTER = 3.0
_INTERRUPT_MESSAGE = "motion: interrupted (the outputs are not written, or not all of them)"


class _SignalWatch:
    """Ends the process :data:`FORCE_EXIT_AFTER` s after a SIGINT/SIGTERM the run has not
    ended by itself in. Python runs a signal's handler (the KeyboardInterrupt) only between
    bytecodes, and a long CasADi call never gets there: building IPOPT's derivatives for a
    go2 turn is a minute in C, and the turn ended 69 s after SIGTERM. The interpreter's
    C-level handler writes each signal number to a socket at once (``signal.set_wakeup_fd``),
    which a thread of this class reads; ``cleanup`` callables run before the exit (the
    empty output folders' removal). Main thread only."""

    def __init__(self) -> None:
        self.cleanup: list[Callable[[], None]] = []
        self._done = threading.Event()
        self._read, self._write = socket.socketpair()
        self._write.setblocking(False)
        self._previous = signal.set_wakeup_fd(self._write.fileno(), warn_on_full_buffer=False)
        threading.Thread(target=self._watch, name="motion-signals", daemon=True).start()

    def _watch(self) -> None:
        while True:
            try:
                got = self._read.recv(1)
            except OSError:
                return
            if not got or self._done.is_set():
                return  # closed: the run is over
            if got[0] in (signal.SIGINT, signal.SIGTERM):
                break
        if self._done.wait(FORCE_EXIT_AFTER):
            return
        for clean in self.cleanup:
            try:
                clean()
            except Exception:  # noqa: BLE001 - exiting anyway
                pass
        sys.stderr.write(_INTERRUPT_MESSAGE.replace(
            "interrupted", f"interrupted inside a long solver call, ended after "
            f"{FORCE_EXIT_AFTER:g} s") + "\n")
        sys.stderr.flush()
        os._exit(INTERRUPTED)

    def close(self) -> None:
        """The run is over: no forced exit from now on; the wakeup socket as it was."""
        self._done.set()
        signal.set_wakeup_fd(self._previous)
        self._read.shutdown(socket.SHUT_RDWR)  # wakes the thread's recv
        self._write.close()


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``motion`` executable; returns the process exit code
    (0: solved and written; 1: the solver did not succeed, outputs written anyway; 2: bad
    arguments or settings; 130: interrupted by SIGINT or SIGTERM, one line and no
    traceback; the outputs not written, or not all of them)."""
    _signals.clear()
    _ending.clear()
    previous = {}
    watch = None
    if threading.current_thread() is threading.main_thread():
        # also when started with SIGINT ignored (a background job of a non-interactive
        # shell); SIGTERM (a supervisor, `timeout`) as Ctrl-C; the caller's handlers back
        # on return (main called in a process of its own making, e.g. a test)
        previous = {sig: signal.signal(sig, _interrupt) for sig in (signal.SIGINT,
                                                                     signal.SIGTERM)}
        watch = _SignalWatch()
    try:
        return _main(argv, watch)
    except KeyboardInterrupt:
        _ending.append(True)
        print(_INTERRUPT_MESSAGE, file=sys.stderr)
        return INTERRUPTED
    finally:
        _ending.append(True)
        if watch is not None:
            watch.close()
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _main(argv: Sequence[str] | None, watch: _SignalWatch | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if args.verbose:  # ours only: matplotlib's font search was 2343 of 2402 lines
        logging.getLogger("horizon_mpc").setLevel(logging.DEBUG)
    from horizon_mpc.config import load_robot_config
    from horizon_mpc.motions import leap, turn, walk
    from horizon_mpc.motions.settings import load_motion_config
    from horizon_mpc.motions.wholebody import robot_model

    cls, run = {
        "leap": (leap.LeapSettings, leap.run_leap),
        "turn": (turn.TurnSettings, turn.run_turn),
        "walk": (walk.WalkSettings, walk.run_walk),
    }[args.motion]
    out: Path | None = None
    made: Path | None = None  # the first folder made for the outputs
    try:  # whatever ends the run (an error, an interrupt) before anything is written in
        # the folders made for the outputs removes them again (they were left empty)
        try:  # the configs and settings: one line naming the problem, exit code 2
            mc = load_motion_config(args.config or args.motion)
            robot = args.robot or mc.robot
            solver = args.solver or mc.solver
            cfg = load_robot_config(robot)
            settings = mc.settings_for(cls, cfg.name, _overrides(args.set))
            out = Path(args.out or f"out/motions/{args.motion}")
            if out.exists() and not out.is_dir():  # found before the solve, not after it
                raise ValueError(f"--out {out} exists and is not a folder")
            # before the folder is made: a bad locked_joints left an empty one
            model = robot_model(cfg, getattr(settings, "locked_joints", ()))
            made = _first_missing(out)
            if watch is not None:
                watch.cleanup.append(lambda: _remove_empty(out, made))
            try:
                out.mkdir(parents=True, exist_ok=True)
            except OSError as exc:  # under a file, no permission: a traceback after the solve
                raise ValueError(f"--out {out}: cannot make that folder ({exc.strerror})") \
                    from None
            try:  # an existing folder that cannot be written: found after the solve too
                tempfile.TemporaryFile(dir=out).close()
            except OSError as exc:
                raise ValueError(f"--out {out}: cannot write in that folder ({exc.strerror})") \
                    from None
        except (ValueError, KeyError, FileNotFoundError, yaml.YAMLError) as exc:
            print(f"motion: error: {exc}", file=sys.stderr)
            return 2
        return _solve_and_write(args, run, cfg, model, solver, settings, out)
    finally:
        if out is not None:
            _remove_empty(out, made)


def _solve_and_write(args: argparse.Namespace, run: Callable[..., MotionResult],
                     cfg: RobotConfig, model: RobotModel, solver: str, settings: object,
                     out: Path) -> int:
    """Solve the motion, replay a leap, write and print the outputs; the exit code."""
    from horizon_mpc.motions.output import write_outputs

    print(f"{args.motion}: {cfg.name} ({model.nv} dof), solver {solver}")
    t0 = time.perf_counter()
    try:
        # -v: the solver's iterations as they go (a GN-SQP turn takes minutes)
        res = run(cfg, solver, settings, opts={"verbose": True} if args.verbose else None,
                  model=model)
    except ValueError as exc:  # settings the problem cannot be built with (n_nodes 0, ...)
        print(f"motion: error: cannot build the {args.motion}: {exc}", file=sys.stderr)
        return 2
    _checkpoint()
    wall = time.perf_counter() - t0
    extra = {"settings": dataclasses.asdict(settings), "wall_time": wall}
    if args.motion == "leap" and not args.no_replay:
        from horizon_mpc.motions.leap import replay_gains
        from horizon_mpc.motions.replay import replay, replay_summary

        kp, kd = replay_gains(settings, cfg)
        try:
            rep = replay(res, cfg, model.pin_model, kp, kd)
        except ValueError as exc:  # a plan the simulator refuses (an unsolved one: a joint
            # jumping at 110 rad/s), which was a traceback with nothing written
            extra["pybullet_replay"] = {"kp": kp, "kd": kd, "not_replayed": str(exc)}
        else:
            extra["pybullet_replay"] = {
                "kp": kp, "kd": kd,
                **replay_summary(rep, res, float(res.summary["target"][0] - res.q[0, 0]))}
    render = {"yaw": 90.0} if args.motion == "leap" else {}
    _checkpoint()
    files = write_outputs(res, cfg, out, effort_limit=model.joint_effort_limit,
                          animation=not args.no_animation, extra=extra, **render)
    _checkpoint()
    ok = bool(res.stats.get("success", True))
    solver_time = res.stats.get("time")
    inner = (f" (the solver's own {solver_time:.1f} s, the rest building the problem)"
             if isinstance(solver_time, float) and solver_time < wall else "")
    # a failure says why (the solver's status, also in summary.json)
    status = "" if ok else f" ({solver} status: {res.stats.get('status', 'unknown')})"
    print(f"{args.motion}: {'solved' if ok else 'NOT solved'}{status} in {wall:.1f} s{inner}; "
          f"outputs in {out}: {', '.join(p.name for p in files.values())}")
    if not ok:  # a GN-SQP leap's untouched guess read as a leap (an auditor's)
        print("  (the figures below are of the plan the solver stopped at, not of a solved "
              f"{args.motion}: max_dynamics_defect and the status say how far from one)")
    for key, value in res.summary.items():
        if not isinstance(value, list) or len(value) <= 4:
            print(f"  {key}: {value}")
    for warning in motion_warnings(args.motion, res.summary, settings):
        print(f"  WARNING: {warning}")
    if "pybullet_replay" in extra:
        print(f"  pybullet_replay: {extra['pybullet_replay']}")
        if "not_replayed" in extra["pybullet_replay"]:
            print(f"  WARNING: not replayed in PyBullet: "
                  f"{extra['pybullet_replay']['not_replayed']}")
        elif not ok:
            print("  (the replay is of a plan the solver did not solve: no guide to how a "
                  "solved leap lands)")
        elif not extra["pybullet_replay"]["within_tolerance"]:
            print(f"  WARNING: {_replay_warning(extra['pybullet_replay'])}: the plan is not one "
                  "this simulated robot follows without feedback (replay_kp/replay_kd, or a "
                  "shorter leap)")
    return 0 if ok else 1


#: share beyond 1 of the largest torque / URDF effort limit that is said (a plan at its
#: bounds reaches them within the solver's tolerance)
TORQUE_RATIO_TOLERANCE = 1e-3
#: a walk's ``velocity_error`` (relative; m/s for a zero reference) that is warned about:
#: the shipped walks are within 0.6-3.9 % (doc/motions.md)
VELOCITY_ERROR_WARNING = 0.2
#: the share of the gait's step height under which a walk's highest swing apex is warned
#: about (the clearance is a cost: go2's walk lifts its feet 1.9-3.5 cm for its 7 cm,
#: doc/motions.md)
SWING_APEX_WARNING = 0.2


def motion_warnings(motion: str, summary: dict, settings: object) -> list[str]:
    """What to say beside "solved" of a motion's ``summary``: torques beyond the URDF's effort
    limits (naming ``torque_limit_scale`` where the motion has one), and for a walk
    :func:`walk_warnings` (until session 31 asked of every motion: each CLI turn, whose
    summary has per-foot swing apexes, ended in a TypeError after its outputs were written)."""
    out = []
    ratio = summary.get("max_torque_ratio")
    if isinstance(ratio, float) and ratio > 1.0 + TORQUE_RATIO_TOLERANCE:
        scale = getattr(settings, "torque_limit_scale", None)
        out.append(f"the plan's torques reach {ratio:.3g} times the URDF effort limits"
                   + (f" (torque_limit_scale {scale:g})" if scale is not None else "")
                   + ": more than the robot's motors are rated for")
    return out + (walk_warnings(summary) if motion == "walk" else [])


def walk_warnings(summary: dict) -> list[str]:
    """What to say of a walk (its summary only) whose success is the problem's (converged,
    physically consistent) but not what was asked: a mean velocity more than
    :data:`VELOCITY_ERROR_WARNING` off its reference, swing feet that rise less
    than :data:`SWING_APEX_WARNING` of the gait's step height (they skim the ground), or a
    gait that swings feet with a step height of 0."""
    out = []
    error = summary.get("velocity_error")
    if isinstance(error, float) and error > VELOCITY_ERROR_WARNING:
        reference = summary["velocity_reference"]
        mean = [round(x, 3) for x in summary["mean_velocity"]]
        off = (f"{error:.0%} off its reference" if any(reference) else
               f"{error:.3f} m/s for a zero reference")
        if summary.get("window_includes_start_up"):  # it blamed the command (an auditor's)
            out.append(f"the walk's mean velocity (vx, vy, wz) {mean} is {off} {reference}, "
                       "averaged over the whole walk, its start from standing included: walk "
                       "longer than average_cycles gait cycles to measure the gait's own")
        else:
            out.append(f"the walk's mean velocity (vx, vy, wz) {mean} is {off} {reference}: "
                       "the motion is consistent, but does not follow the command")
    apex, height = summary.get("swing_apex"), summary.get("step_height")
    if apex and isinstance(height, float) and height > 0 \
            and apex[1] < SWING_APEX_WARNING * height:
        out.append(f"the swing feet rise at most {apex[1] * 100:.2f} cm for a step_height of "
                   f"{height * 100:.2f} cm: they skim the ground (the clearance is a cost: "
                   "mpc.weights.swing_height against the others)")
    elif apex and height == 0.0:
        out.append(f"step_height is 0: the swing feet are not lifted (they rise at most "
                   f"{apex[1] * 100:.2f} cm, sliding or skimming the ground)")
    return out


def _replay_warning(rep: dict) -> str:
    """What went wrong in a leap's replay (``replay_summary``'s figures), in words."""
    from horizon_mpc.motions.replay import REPLAY_TOLERANCE

    text = "replayed open loop in PyBullet (joint PD on the plan), the leap "
    if not rep["ended_standing"]:
        roll, pitch = rep["final_roll_pitch_yaw"][:2]
        return (text + f"did not end standing: its base {abs(rep['height_error']) * 100:.1f} "
                f"cm {'below' if rep['height_error'] < 0 else 'above'} the plan's final height, "
                f"roll {roll:.2f} rad, pitch {pitch:.2f} rad (landed "
                f"{rep['landing_error']:.3f} m from its target)")
    return (text + f"lands {rep['landing_error']:.3f} m from its target (> {REPLAY_TOLERANCE} "
            "m)")


if __name__ == "__main__":
    sys.exit(main())
