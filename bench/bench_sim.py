"""Benchmark of the pybullet simulator and of ``sim_node``.

* physics steps per second at 1 kHz for go2 with the trajectory controller running
  (:meth:`Simulator.step` following a Hermite-interpolated trajectory, effort clamping) and
  with the posture hold, each against a plain Python PD loop simulating the same motion (the
  FACTS reference point: getJointStates, PD on a precomputed reference,
  setJointMotorControlArray, stepSimulation) — the ratios are what our controller costs;
* ``Simulator.state()`` time (what publishing needs besides the messages);
* the node's real-time factor when running free (``realtime_factor: 0``, alone in its
  process, ``state_rate`` 500 and 200 Hz, publishing joint_states/odom/clock).

Steps/s: best and median over ``ROUNDS`` chunks of ``CHUNK`` steps, the three loops taking
turns chunk by chunk in this one run (times on these machines vary 20-50% between runs and
other jobs share the cores: compare ratios). Run:
``python bench/bench_sim.py``; writes ``bench/results/sim.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pybullet as p

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # running from a source checkout without an install
    sys.path.insert(0, str(ROOT))

from horizon_mpc.sim import JointTrajectoryCommand, Simulator  # noqa: E402
from horizon_mpc.sim.trajectory import ReferenceGenerator  # noqa: E402

ROBOT = "go2"
CHUNK = 200
ROUNDS = 40
NODE_SECONDS = 4.0
RESULTS = ROOT / "bench" / "results" / "sim.json"


def plain_pd_loop(sim: Simulator, q_ref: np.ndarray, tau_ff: np.ndarray
                  ) -> Callable[[int], None]:
    """A plain PD loop on the simulator's pybullet body, reading its reference from tables.

    ``q_ref``, ``tau_ff``: (steps, nj) per-step reference (a table lookup: the least a
    controller can cost). No interpolation, no clamping.
    """
    body, cid, joints = sim.body, sim.client, sim._pb_joints  # noqa: SLF001 - benchmark
    kp, kd = sim.kp, sim.kd
    k = [0]

    def run(n: int) -> None:
        for _ in range(n):
            states = p.getJointStates(body, joints, physicsClientId=cid)
            q = np.array([s[0] for s in states])
            v = np.array([s[1] for s in states])
            tau = tau_ff[k[0]] + kp * (q_ref[k[0]] - q) - kd * v
            p.setJointMotorControlArray(body, joints, p.TORQUE_CONTROL, forces=tau.tolist(),
                                        physicsClientId=cid)
            p.stepSimulation(physicsClientId=cid)
            k[0] += 1

    return run


def long_trajectory(sim: Simulator) -> JointTrajectoryCommand:
    """A slowly varying trajectory, 50 points over 100 s, from t = 0."""
    times = np.linspace(0.0, 100.0, 50)
    q0 = sim.q_start[7:]
    positions = q0 + 0.05 * np.sin(times)[:, None]
    velocities = 0.05 * np.cos(times)[:, None] * np.ones_like(q0)
    efforts = np.tile(sim.tau_standing, (len(times), 1))
    return JointTrajectoryCommand(sim.joint_names, 0.0, times, positions, velocities, efforts)


def physics_rates() -> dict[str, dict[str, float]]:
    """Steps/s of each loop: best and median over ROUNDS chunks of CHUNK steps.

    The loops take turns chunk by chunk, so that load changes on the machine hit all alike;
    the best chunk is the least disturbed measurement. Each loop has its own simulator; the
    plain loops replay the same references as ours, so each pair simulates the same motion
    (a moving robot has more contact points, and pybullet's step costs more).
    """
    names = ("plain_pd_hold", "posture_hold", "plain_pd_tracking", "trajectory_controller")
    sims = {name: Simulator(ROBOT, dt=1e-3) for name in names}
    cmd = long_trajectory(sims["trajectory_controller"])
    sims["trajectory_controller"].reference.timeout = 1e9  # never stale during the benchmark
    sims["trajectory_controller"].set_trajectory(cmd)
    ref = ReferenceGenerator(len(cmd.joint_names), timeout=1e9)
    ref.set_command(cmd, now=0.0)
    n_steps = ROUNDS * CHUNK
    table = [ref.reference(k * 1e-3) for k in range(n_steps)]
    q_track = np.array([r[0] for r in table])
    tau_track = np.array([r[2] for r in table])
    hold = sims["plain_pd_hold"]
    q_hold = np.tile(hold.q_start[7:], (n_steps, 1))
    tau_hold = np.tile(hold.tau_standing, (n_steps, 1))
    loops = {
        "plain_pd_hold": plain_pd_loop(hold, q_hold, tau_hold),
        "posture_hold": sims["posture_hold"].step,
        "plain_pd_tracking": plain_pd_loop(sims["plain_pd_tracking"], q_track, tau_track),
        "trajectory_controller": sims["trajectory_controller"].step,
    }
    times: dict[str, list[float]] = {name: [] for name in loops}
    for _ in range(ROUNDS):
        for name, run in loops.items():
            start = time.perf_counter()
            run(CHUNK)
            times[name].append((time.perf_counter() - start) / CHUNK)
    assert not sims["trajectory_controller"].reference.holding
    for s in sims.values():
        s.close()
    return {name: {"best": 1.0 / min(t), "median": 1.0 / float(np.median(t))}
            for name, t in times.items()}


def node_realtime_factor(state_rate: float) -> float:
    """Sim seconds per wall second of a free-running sim_node alone in an executor."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from horizon_mpc.nodes.sim_node import SimNode

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        node = SimNode(context=ctx, parameter_overrides=[
            Parameter("robot", value=ROBOT), Parameter("realtime_factor", value=0.0),
            Parameter("state_rate", value=state_rate)])
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        for _ in range(50):  # warm up
            executor.spin_once(timeout_sec=0.01)
        wall0, sim0 = time.perf_counter(), node.sim.time
        while time.perf_counter() - wall0 < NODE_SECONDS:
            executor.spin_once(timeout_sec=0.01)
        rtf = (node.sim.time - sim0) / (time.perf_counter() - wall0)
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    return rtf


def main() -> dict:
    """Run the simulator benchmarks; returns (and writes) their results."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 101)))
    rates = physics_rates()
    with Simulator(ROBOT, dt=1e-3) as sim:
        start = time.perf_counter()
        for _ in range(1000):
            sim.state()
        state_us = (time.perf_counter() - start) * 1e3
    results = {
        "machine": {"python": platform.python_version(), "pybullet": p.getAPIVersion(),
                    "cpu": platform.machine()},
        "robot": ROBOT,
        "physics_rate_hz": 1000.0,
        "steps_per_s": {name: {k: round(v) for k, v in r.items()} for name, r in rates.items()},
        # same motion, same physics: what our controller costs over a table-lookup PD loop
        "ratio_trajectory_controller_to_plain_pd": {
            k: round(rates["trajectory_controller"][k] / rates["plain_pd_tracking"][k], 3)
            for k in ("best", "median")
        },
        "ratio_posture_hold_to_plain_pd": {
            k: round(rates["posture_hold"][k] / rates["plain_pd_hold"][k], 3)
            for k in ("best", "median")
        },
        "state_read_us": round(state_us, 1),
        "node_realtime_factor_free": {
            "state_rate_500": round(node_realtime_factor(500.0), 2),
            "state_rate_200": round(node_realtime_factor(200.0), 2),
        },
    }
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(json.dumps(results, indent=2))  # noqa: T201 - a benchmark script reports on stdout
    return results


if __name__ == "__main__":
    # no options: --help shows this docstring, anything else is refused (it ran the
    # benchmark and overwrote its results)
    argparse.ArgumentParser(description=__doc__,
                            formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
