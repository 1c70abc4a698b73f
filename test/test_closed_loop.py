"""The closed loop: sim_node + mpc_node in one process, lockstep, through the ROS topics."""

from __future__ import annotations

import json

import numpy as np
import pytest

from horizon_mpc.closed_loop import DEFAULT_PROFILE, Segment, command_at, load_profile, run
from horizon_mpc.closed_loop_report import fallen, summarise, write_report

STAND = 1.5  # s standing before walking
FORWARD = 0.3  # m/s commanded in the walking segment


def test_the_default_profile_is_the_documented_one():
    segs = load_profile(DEFAULT_PROFILE)
    assert [(s.duration, s.vx, s.vy, s.wz) for s in segs] == [
        (1.0, 0.0, 0.0, 0.0), (4.0, 0.3, 0.0, 0.0), (3.0, 0.0, 0.2, 0.0),
        (3.0, 0.0, 0.0, 0.5), (2.0, 0.0, 0.0, 0.0)]


def test_command_at_follows_the_segments_then_stops():
    segs = [Segment(1.0), Segment(2.0, vx=0.3)]
    np.testing.assert_array_equal(command_at(segs, 0.5), [0, 0, 0])
    np.testing.assert_array_equal(command_at(segs, 1.0), [0.3, 0, 0])
    np.testing.assert_array_equal(command_at(segs, 3.5), [0, 0, 0])


def test_a_bad_profile_names_the_problem(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("- {duration: 1.0, vz: 2.0}\n")
    with pytest.raises(ValueError, match="segment 0"):
        load_profile(path)


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """1.5 s standing then 2.5 s at 0.3 m/s forward, lockstep, with a GIF."""
    segs = [Segment(STAND), Segment(2.5, vx=FORWARD)]
    rec = run("go2", segs, mode="lockstep", gif=True, iterations=2, stop_after_fall=0.5)
    summary = summarise(rec, segs, robot="go2")
    out = tmp_path_factory.mktemp("closed_loop")
    return rec, summary, write_report(rec, summary, out), out


@pytest.mark.slow
def test_the_run_writes_summary_plots_and_gif(short_run):
    rec, summary, written, out = short_run
    names = {p.name for p in written}
    assert {"summary.json", "velocity_tracking.png", "base_pose.png", "contacts.png",
            "solve_time.png", "run.gif"} <= names
    assert all((out / n).stat().st_size > 0 for n in names)
    data = json.loads((out / "summary.json").read_text())
    for key in ("segments", "distance_travelled", "falls", "tick_time_ms", "deadline_misses",
                "real_time_factor"):
        assert key in data
    # lockstep: one MPC tick per control period (20 ms), each on a state published by the sim
    assert summary["ticks"] >= len(rec.t) - 2


@pytest.mark.slow
def test_the_robot_stands_without_falling(short_run):
    rec, _, _, _ = short_run
    t, q = np.asarray(rec.t), np.asarray(rec.q)
    standing = t < STAND
    assert standing.sum() >= STAND / 0.02 - 1
    assert not any(fallen(qi, rec.nominal_height) for qi in q[standing])
    # and it stays put: less than 2 cm drift while standing
    assert np.linalg.norm(q[standing][-1, :2] - q[0, :2]) < 0.02


@pytest.mark.slow
@pytest.mark.xfail(reason="walking quality is still being tuned (lead engineer); the go2 "
                          "falls within ~1.5 s of walking at 0.3 m/s as of this commit",
                   strict=False)
def test_forward_walking_tracks_the_command_within_15_percent(short_run):
    _, summary, _, _ = short_run
    assert summary["falls"]["count"] == 0
    walk = summary["segments"][1]
    assert walk["samples"] >= 50  # 1.5 s of walking after the 1 s settling time
    assert walk["mean"]["vx"] == pytest.approx(FORWARD, rel=0.15)
    assert walk["rmse"]["vy"] < 0.1 and walk["rmse"]["wz"] < 0.2
