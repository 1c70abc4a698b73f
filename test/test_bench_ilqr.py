"""The ILQR-vs-Crocoddyl benchmark (``bench/bench_ilqr.py``) runs and writes well-formed JSON.

Tiny configuration (N = 8, CasADi VM instead of compiled code, a few iterations and ticks):
what is checked is the plumbing, not the figures. The peer part needs ``.venv-peer``
(``make peer-venv``); without it that test is skipped, saying why.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TINY = ["--nodes", "8", "--no-codegen", "--ticks", "3", "--repeats", "1", "--rounds", "1",
        "--max-iter", "4"]


def _load_bench():
    spec = importlib.util.spec_from_file_location("bench_ilqr", ROOT / "bench" / "bench_ilqr.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


bench = _load_bench()


def _finite_positive(x) -> bool:
    return isinstance(x, int | float) and math.isfinite(x) and x > 0


def _read(out: Path) -> dict:
    text = (out / "ilqr.json").read_text()
    return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))


def _check_ours(ours: dict) -> None:
    conv, ticks = ours["converging"], ours["ticks"]
    assert ours["problem"]["nodes"] == 8
    assert ours["missing_timing_keys"] == []
    assert _finite_positive(conv["ms_per_iteration"]["median"])
    assert set(conv["common_ms_per_iteration"]) == {"linearise", "backward",
                                                    "forward_line_search", "other"}
    assert ticks["n"] == 3
    assert all(it == 1 for r in ticks["rounds"] for it in r["iterations"])  # rti: 1 per tick
    assert _finite_positive(ticks["tick_ms"]["median"])
    assert ticks["tick_ms"]["median"] >= ticks["solve_ms"]["median"]
    assert _finite_positive(ticks["common_ms_per_tick"]["linearise"])


def test_without_the_peer_ours_is_reported_and_the_ratios_are_null(tmp_path):
    code = bench.main([*TINY, "--peer-python", str(tmp_path / "no-python"), "--out",
                       str(tmp_path)])
    assert code == 0
    res = _read(tmp_path)
    _check_ours(res["ours"]["8"])
    assert res["peer"]["available"] is False
    assert "make peer-venv" in res["peer"]["reason"]
    assert {v for clock in res["ratios"]["8"].values() for v in clock.values()} == {None}
    assert (tmp_path / "ilqr.png").stat().st_size > 0


def test_with_the_peer_both_are_measured_and_the_ratios_computed(tmp_path):
    python, reason = bench.find_peer_python()
    if python is None:
        pytest.skip(reason)
    code = bench.main([*TINY, "--out", str(tmp_path), "--no-plot"])
    assert code == 0
    res = _read(tmp_path)
    _check_ours(res["ours"]["8"])
    peer = res["peer"]
    assert peer["available"] is True, peer.get("reason")
    assert peer["problem"]["nodes"] == 56 and peer["problem"]["nthreads"] == 1
    assert peer["ticks"]["n"] == 3
    assert _finite_positive(peer["converging"]["ms_per_iteration"]["median"])
    assert _finite_positive(peer["profile"]["common_ms_per_iteration"]["linearise"])
    ratios = [v for clock in res["ratios"]["8"].values() for v in clock.values()]
    assert len(ratios) == 12 and all(_finite_positive(r) for r in ratios)


def test_the_peer_paces_its_warm_ticks_when_asked():
    """``pace`` adds warm ticks each after that much sleep, pooled by summarise_peer."""
    python, reason = bench.find_peer_python()
    if python is None:
        pytest.skip(reason)
    out = bench.run_peer(python, ticks=3, repeats=1, max_iter=4, profile=False, pace=0.02)
    assert out["paced_ticks"]["pace_s"] == 0.02 and len(out["paced_ticks"]["tick_ms"]) == 3
    assert "paced_ticks" not in bench.run_peer(python, ticks=2, repeats=1, max_iter=4,
                                               profile=False)
    pooled = bench.summarise_peer([out, out])["paced_ticks"]
    assert pooled["n"] == 6 and _finite_positive(pooled["tick_ms"]["median"])


@pytest.mark.parametrize("argv, message", [
    (["--repeats", "0"], "--repeats: '0' is not an integer >= 1"),
    (["--rounds", "0"], "--rounds: '0' is not an integer >= 1"),
    (["--ticks", "-3"], "--ticks: '-3' is not an integer >= 1"),
    (["--nodes", "24", "0"], "--nodes: '0' is not an integer >= 1"),
    (["--v-forward", "nan"], "--v-forward: 'nan' is not a finite number"),
])
def test_bad_arguments_are_refused_before_anything_is_measured(argv, message, capsys):
    """--repeats 0 crashed after the warm ticks were measured, --ticks 0 printed a nan tick
    and exited 0, --v-forward nan solved a problem of NaN parameters."""
    with pytest.raises(SystemExit) as exc:
        bench.parse_args(argv)
    assert exc.value.code == 2 and message in capsys.readouterr().err


def test_an_out_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "f").write_text("")
    with pytest.raises(SystemExit):
        bench.parse_args(["--out", str(tmp_path / "f")])
    assert "is not a folder" in capsys.readouterr().err
