"""The idle-gap benchmark (``bench/bench_idle_gap.py``) runs and writes well-formed JSON.

A tiny configuration without the peer: the plumbing is checked, not the figures."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load_bench():
    path = ROOT / "bench" / "bench_idle_gap.py"
    spec = importlib.util.spec_from_file_location("bench_idle_gap", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_a_tiny_run_times_our_ticks_after_each_gap(tmp_path):
    bench = _load_bench()
    out = tmp_path / "idle"
    # the gaps in any order: the ratios are against the shortest (the first row was taken)
    assert bench.main(["--gaps", "0.002", "0", "--ticks", "3", "--no-peer", "--out",
                       str(out)]) == 0
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["robot"] == "go2" and doc["peer"].startswith("not run")
    assert [r["gap_s"] for r in doc["rows"]] == [0.002, 0.0] and doc["shortest_gap_s"] == 0.0
    for row in doc["rows"]:
        assert math.isfinite(row["ours_ms"]) and row["ours_ms"] > 0
        assert row["ours_p90_ms"] >= row["ours_ms"] and "crocoddyl_ms" not in row
    assert doc["rows"][1]["ours_over_shortest_gap"] == 1.0
    assert doc["rows"][0]["ours_over_shortest_gap"] == pytest.approx(
        doc["rows"][0]["ours_ms"] / doc["rows"][1]["ours_ms"])
    assert out.with_suffix(".png").stat().st_size > 0


@pytest.mark.parametrize("argv, message", [
    (["--ticks", "0"], "--ticks: '0' is not an integer >= 1"),
    (["--gaps", "-0.01"], "--gaps: '-0.01' is not a finite number >= 0"),
])
def test_bad_arguments_are_refused_before_anything_runs(argv, message, capsys):
    bench = _load_bench()
    with pytest.raises(SystemExit) as exc:
        bench.main([*argv, "--no-peer"])
    assert exc.value.code == 2 and message in capsys.readouterr().err


def test_the_replay_sleeps_the_gap_before_each_tick(monkeypatch):
    """Each replayed tick follows a sleep of the gap (none for a zero gap)."""
    bench = _load_bench()
    states = bench.record(4 * 0.02 + 1e-9)
    slept = []
    monkeypatch.setattr(bench.time, "sleep", slept.append)
    assert len(bench.replay(states, 0.03)) == len(states) - 1 == len(slept)
    assert set(slept) == {0.03}
    slept.clear()
    bench.replay(states, 0.0)
    assert slept == []
