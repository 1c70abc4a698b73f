"""compile_function: same numbers as the VM, on-disk cache, opt-out switch."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import casadi as cs
import numpy as np
import pytest
from model_reference import evaluate, model, random_states

from horizon_mpc import codegen


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("HORIZON_MPC_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("HORIZON_MPC_NO_CODEGEN", raising=False)
    return tmp_path


def _small_function() -> cs.Function:
    x = cs.SX.sym("x", 3)
    p = cs.SX.sym("p")
    return cs.Function("small", [x, p], [cs.sin(x) * p, cs.sumsqr(x)], ["x", "p"], ["y", "n"])


def test_compiled_forward_kinematics_returns_what_the_vm_does(cache):
    m = model("go2")
    fn = m.frame_velocity("FL_foot", "WORLD")
    fast = m.compile(fn)
    s = random_states(m, n=20)
    for vm_out, c_out in zip(
        evaluate(fn, s["q"], s["v"]), evaluate(fast, s["q"], s["v"]), strict=True
    ):
        assert np.allclose(c_out, vm_out, rtol=1e-12, atol=1e-12)


@pytest.mark.slow
def test_compiled_inverse_dynamics_and_derivatives_return_what_the_vm_does(cache):
    m = model("solo12")
    feet = ["FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"]
    s = random_states(m, n=10)
    f = 30.0 * np.random.default_rng(7).normal(size=(12, 10))
    for fn in (m.inverse_dynamics(feet), m.inverse_dynamics_derivatives(feet)):
        mapped = fn.map(10, "serial")
        fast = codegen.compile_function(mapped)
        args = [s["q"], s["v"], s["a"], f]
        for vm_out, c_out in zip(mapped.call(args), fast.call(args), strict=True):
            assert np.allclose(c_out.full(), vm_out.full(), rtol=1e-12, atol=1e-12)


def test_compiled_function_keeps_name_and_signature(cache):
    fn = _small_function()
    fast = codegen.compile_function(fn)
    assert fast.name() == "small"
    assert fast.name_in() == ["x", "p"] and fast.name_out() == ["y", "n"]
    assert fast.size_out(0) == (3, 1)


def test_compiled_function_can_be_renamed(cache):
    fast = codegen.compile_function(_small_function(), name="small_renamed")
    assert fast.name() == "small_renamed"
    assert float(fast(np.ones(3), 2.0)[1]) == 3.0


def test_mapped_functions_compile(cache):
    fn = _small_function().map(7, "serial")
    fast = codegen.compile_function(fn)
    x = np.arange(21.0).reshape(3, 7)
    p = np.linspace(0, 1, 7).reshape(1, 7)
    for vm_out, c_out in zip(fn(x, p), fast(x, p), strict=True):
        assert np.allclose(c_out.full(), vm_out.full(), rtol=1e-12, atol=0)


def test_library_is_cached_on_disk_and_reused(cache):
    fn = _small_function()
    codegen.compile_function(fn)
    compiled, loaded = codegen.STATS.compiled, codegen.STATS.loaded
    codegen.forget_loaded()  # as if in a new process
    codegen.compile_function(fn)
    assert codegen.STATS.compiled == compiled  # no gcc run
    assert codegen.STATS.loaded == loaded + 1
    hits = codegen.STATS.memory_hits
    codegen.compile_function(fn)  # loaded in this process already: neither built nor read
    assert (codegen.STATS.compiled, codegen.STATS.loaded, codegen.STATS.memory_hits) == \
        (compiled, loaded + 1, hits + 1)
    assert len(list(cache.glob("small_*.so"))) == 1
    assert not list(cache.glob(".build_*"))  # temporary build folders are removed


def test_changed_function_gets_a_new_library(cache):
    codegen.compile_function(_small_function())
    x = cs.SX.sym("x", 3)
    p = cs.SX.sym("p")
    other = cs.Function("small", [x, p], [cs.cos(x) * p, cs.sumsqr(x)], ["x", "p"], ["y", "n"])
    fast = codegen.compile_function(other)
    assert np.allclose(fast(np.zeros(3), 1.0)[0].full().ravel(), 1.0)
    assert len(list(cache.glob("small_*.so"))) == 2


def test_no_codegen_switch_returns_the_vm_function(cache, monkeypatch):
    monkeypatch.setenv("HORIZON_MPC_NO_CODEGEN", "1")
    fn = _small_function()
    assert codegen.compile_function(fn) is fn
    assert not list(cache.iterdir())


def test_default_cache_dir_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("HORIZON_MPC_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert codegen.default_cache_dir() == tmp_path / "horizon_mpc"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert codegen.default_cache_dir() == Path.home() / ".cache" / "horizon_mpc"


def test_compiler_errors_are_reported(cache, monkeypatch):
    monkeypatch.setattr(codegen, "CC_ARGV", ("false",))  # a "compiler" that always fails
    with pytest.raises(RuntimeError, match="compiling broken failed"):
        codegen.build_shared_library(cache / "broken.so", lambda _work: [], "broken")


def test_a_compiler_that_fails_leaves_the_functions_uncompiled_with_one_warning(
        cache, monkeypatch, caplog):
    """A bad -march (or $CC) was a traceback out of the motion CLI; a missing compiler was
    already this. One warning for all of a model's functions."""
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "bogus")
    monkeypatch.setattr(codegen, "_UNCOMPILED_WARNED", set())
    x = cs.SX.sym("x")
    fns = [cs.Function(name, [x], [x * k]) for k, name in enumerate(("f_a", "f_b"), 2)]
    with caplog.at_level("WARNING", logger="horizon_mpc.codegen"):
        assert [codegen.compile_function(fn) for fn in fns] == fns
    assert caplog.text.count("running them uncompiled") == 1
    assert "the C compiler failed" in caplog.text and "bogus" in caplog.text


_SCRIPT = textwrap.dedent(
    """
    import logging, sys
    logging.basicConfig(level=logging.INFO, stream=sys.stdout, format="%(message)s")
    from horizon_mpc import codegen
    from horizon_mpc.model import RobotModel
    m = RobotModel.from_example("solo12")
    fast = m.compile(m.fk("FL_FOOT"))
    print("compiled", codegen.STATS.compiled, "loaded", codegen.STATS.loaded)
    """
)


@pytest.mark.slow
def test_second_process_loads_from_the_warm_cache(cache):
    env = dict(
        os.environ,
        PYTHONPATH=os.pathsep.join(
            [str(Path(__file__).parents[1]), os.environ.get("PYTHONPATH", "")]
        ),
    )
    runs = [
        subprocess.run(
            [sys.executable, "-c", _SCRIPT], capture_output=True, text=True, env=env, check=True
        ).stdout
        for _ in range(2)
    ]
    assert "compiling fk_FL_FOOT" in runs[0] and "compiled 1 loaded 0" in runs[0]
    assert "compiling" not in runs[1] and "compiled 0 loaded 1" in runs[1]


def test_buffered_function_matches_a_plain_call(cache):
    fn = codegen.compile_function(_small_function().map(4, "serial"))
    call = codegen.BufferedFunction(fn)
    x = np.arange(12.0).reshape(3, 4)
    p = np.array([[1.0, 2.0, 3.0, 4.0]])
    y, n = call(x, p)
    y_ref, n_ref = fn(x, p)
    assert np.array_equal(y, y_ref.full()) and np.array_equal(n, n_ref.full())
    x2 = x + 1.0
    y2, _ = call(x2, p)  # the same arrays, overwritten in place
    assert y2 is y and np.array_equal(y, fn(x2, p)[0].full())


def test_buffered_function_rejects_sparse_outputs():
    x = cs.SX.sym("x", 2)
    fn = cs.Function("diag", [x], [cs.diag(x)])
    with pytest.raises(ValueError, match="sparse"):
        codegen.BufferedFunction(fn)


def test_names_that_are_not_c_identifiers_are_sanitised(cache):
    x = cs.SX.sym("x")
    fast = codegen.compile_function(cs.Function("f", [x], [2 * x]), name="fk_FL-foot.0")
    assert fast.name() == "fk_FL_foot_0"
    assert float(fast(1.5)) == 3.0


@pytest.fixture
def fresh_arch(monkeypatch):
    """arch_flags() without the memo of earlier calls."""
    monkeypatch.setattr(codegen, "_ARCH_MEMO", {})
    monkeypatch.delenv("HORIZON_MPC_CODEGEN_MARCH", raising=False)


def test_arch_flags_follow_the_override_then_the_cpu(fresh_arch, monkeypatch):
    v3 = set(codegen._X86_64_V3)
    monkeypatch.setattr(codegen.platform, "machine", lambda: "x86_64")
    monkeypatch.setattr(codegen, "_compiler_accepts", lambda flag: True)
    monkeypatch.setattr(codegen, "_cpu_flags", lambda: frozenset(v3 | {"sse2"}))
    assert codegen.arch_flags() == ("-march=x86-64-v3",)
    monkeypatch.setattr(codegen, "_ARCH_MEMO", {})
    monkeypatch.setattr(codegen, "_cpu_flags", lambda: frozenset(v3 - {"fma"}))
    assert codegen.arch_flags() == ()  # a CPU without FMA gets baseline code
    monkeypatch.setattr(codegen, "_ARCH_MEMO", {})
    monkeypatch.setattr(codegen, "_cpu_flags", lambda: frozenset(v3))
    monkeypatch.setattr(codegen, "_compiler_accepts", lambda flag: False)
    assert codegen.arch_flags() == ()  # a compiler that does not know x86-64-v3
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "none")
    assert codegen.arch_flags() == ()
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "native")
    assert codegen.arch_flags() == ("-march=native",)


def test_each_target_gets_its_own_library(cache, fresh_arch, monkeypatch):
    """The -march is part of the cache key: switching it compiles again, and both builds
    return the same numbers."""
    if not codegen._compiler_accepts("-march=native"):
        pytest.skip(f"{codegen.CC} does not take -march=native")
    fn = _small_function()
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "none")
    plain = codegen.compile_function(fn)
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "native")
    native = codegen.compile_function(fn)
    assert len(list(cache.glob("small_*.so"))) == 2
    args = [np.array([0.1, -0.4, 2.0]), 1.5]
    for a, b in zip(plain.call(args), native.call(args), strict=True):
        np.testing.assert_allclose(a.full(), b.full(), rtol=1e-14)


@pytest.mark.parametrize("damage", ["empty", "truncated", "garbage", "overwritten"])
def test_a_damaged_cached_library_is_rebuilt_not_loaded(cache, damage, caplog):
    """A zero-byte or garbage file was a CasADi assertion at every later run; a truncated
    one killed the process (SIGBUS) when loaded; one overwritten inside, its headers
    intact, was loaded: SIGILL or SIGSEGV at every later run, or other numbers."""
    fn = _small_function()
    codegen.compile_function(fn)
    lib = next(cache.glob(f"{fn.name()}_*.so"))
    data = lib.read_bytes()
    lib.unlink()  # a new file: this process still maps the old one (truncating it in place
    # would crash it at its next call)
    middle = len(data) // 2
    lib.write_bytes({"empty": b"", "truncated": data[:middle],
                     "garbage": b"not a library" * 50,
                     "overwritten": data[:middle] + b"\xff" * 64 + data[middle + 64:]}[damage])
    codegen.forget_loaded()
    compiled = codegen.STATS.compiled
    with caplog.at_level("WARNING", logger="horizon_mpc.codegen"):
        again = codegen.compile_function(fn)
    assert codegen.STATS.compiled == compiled + 1 and "is damaged" in caplog.text
    x = np.linspace(0.1, 0.9, fn.size1_in(0))
    for got, want in zip(again(x, 2.0), fn(x, 2.0), strict=True):
        np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-12)
    assert lib.read_bytes() != b"" and codegen.library_damage(lib) is None



def test_a_library_of_a_cache_without_checksums_is_adopted_not_rebuilt(cache, caplog):
    """Caches of earlier versions have no checksums: rebuilding each cost minutes of a
    go2 start-up, and a read-only one ran uncompiled. Sound by the structural checks, such
    a library is loaded and its checksum written; one changed after that is rebuilt."""
    fn = _small_function()
    codegen.compile_function(fn)
    lib = next(cache.glob(f"{fn.name()}_*.so"))
    codegen.checksum_path(lib).unlink()
    codegen.forget_loaded()
    compiled = codegen.STATS.compiled
    with caplog.at_level("WARNING", logger="horizon_mpc.codegen"):
        again = codegen.compile_function(fn)
    assert codegen.STATS.compiled == compiled and not caplog.text
    assert codegen.checksum_path(lib).read_text().split()[0] == codegen._sha256(lib)
    assert float(again(np.ones(3), 2.0)[1]) == pytest.approx(3.0)
    lib.unlink()  # this process keeps its mapping of the old file
    codegen.checksum_path(lib).unlink()
    (cache / f"orphan_{_KEY}.so.sha256").write_text("0\n")
    assert codegen.prune_cache(max_bytes=0, spare_s=0.0) == []  # clear: nothing but the orphan
    assert not list(cache.glob("*.sha256"))

def test_without_a_compiler_or_a_writable_cache_the_function_runs_uncompiled(
        tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(codegen, "CC_ARGV", ("no-such-cc",))
    monkeypatch.setattr(codegen, "_UNCOMPILED_WARNED", set())
    fn = _small_function()
    with caplog.at_level("WARNING", logger="horizon_mpc.codegen"):
        assert codegen.compile_function(fn, cache_dir=tmp_path / "c") is fn
        assert codegen.compile_function(fn, cache_dir=tmp_path / "c") is fn
    assert caplog.text.count("running them uncompiled") == 1  # one warning per reason
    assert "'no-such-cc' not found" in caplog.text
    (tmp_path / "file").write_text("")
    monkeypatch.setattr(codegen, "CC_ARGV", ("gcc",))
    assert codegen.compile_function(fn, cache_dir=tmp_path / "file" / "c") is fn


def test_function_names_are_c_identifiers_that_clash_with_nothing():
    for text, expected in (("sin", "f_sin"), ("int", "f_int"), ("casadi_f0", "f_casadi_f0"),
                           ("vélo", "v_lo"), ("2d-arm", "f_2d_arm"), ("ok_name", "ok_name")):
        assert codegen.function_name(text) == expected
    for text in ("y0", "modf", "sinf", "lgamma"):
        assert codegen.function_name(text) == "f_" + text
    long = codegen.function_name("x" * 300)
    assert len(long) <= 64 and long != codegen.function_name("x" * 299)
    cut = codegen.function_name("a" * 54 + "-b" + "c" * 20)  # '_' at the cut: no '__'
    assert "__" not in cut and cs.Function(cut, [cs.SX.sym("x")], [1]).name() == cut


_BIG_COMPILE = """
import sys
import casadi as cs
from horizon_mpc import codegen
x = cs.SX.sym("x", 60)
e = x
for i in range(60):
    e = cs.sin(e * 1.0001 + i) * cs.cos(e[::-1])
codegen.compile_function(cs.Function("slow_to_compile", [x], [cs.jacobian(e, x)]),
                         cache_dir=sys.argv[1])
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG")
def test_a_killed_process_takes_its_compiler_with_it(tmp_path):
    """SIGKILL or SIGTERM of the Python process left gcc compiling (for up to minutes)."""
    import signal
    import time

    def compilers() -> list[str]:
        out = subprocess.run(["ps", "-ww", "-eo", "args"], capture_output=True, text=True).stdout
        return [line for line in out.splitlines() if str(tmp_path) in line
                and "slow_to_compile.c" in line and "cc1" in line.split(" ", 1)[0]]

    env = {**os.environ, "PYTHONPATH": str(Path(codegen.__file__).resolve().parents[1])}
    for sig in (signal.SIGKILL, signal.SIGTERM):
        proc = subprocess.Popen([sys.executable, "-c", _BIG_COMPILE, str(tmp_path)], env=env)
        end = time.monotonic() + 60
        while not compilers():
            assert time.monotonic() < end and proc.poll() is None, "no compiler ran"
            time.sleep(0.05)
        proc.send_signal(sig)
        proc.wait()
        end = time.monotonic() + 10
        while compilers():
            assert time.monotonic() < end, f"compiler left running after {sig.name}"
            time.sleep(0.05)


# --------------------------------------------------------------------------------------------
# the cache's bound: least recently used libraries go first

_KEY = "0" * 24  # a cache key, as the cache names its libraries


def _lib(name: str) -> str:
    """The file name of a cached library of function ``name``."""
    return f"{name}_{_KEY}.so"


def _short(path: Path) -> str:
    """``name.so`` for the cached library ``name_<key>.so``."""
    return path.name.replace(f"_{_KEY}", "")


def _fake_libraries(folder: Path, ages_s: dict[str, float], size: int = 1000) -> None:
    """Files named like cached libraries, last used ``ages_s`` seconds ago."""
    now = time.time()
    for name, age in ages_s.items():
        path = folder / _lib(name)
        path.write_bytes(b"\0" * size)
        os.utime(path, (now - age, now - age))


def test_prune_removes_the_least_recently_used_libraries_down_to_the_bound(cache):
    _fake_libraries(cache, {"old": 9000, "older": 9500, "recent": 3000, "fresh": 60})
    removed = codegen.prune_cache(cache, max_bytes=2500)
    assert sorted(_short(p) for p in removed) == ["old.so", "older.so"]
    assert sorted(_short(p) for p in cache.glob("*.so")) == ["fresh.so", "recent.so"]
    assert codegen.prune_cache(cache, max_bytes=2500) == []  # within the bound now


def test_prune_spares_recent_kept_and_unbounded(cache):
    _fake_libraries(cache, {"a": 9000, "b": 8000, "c": 100})  # c: used in the last 10 min
    assert codegen.prune_cache(cache, max_bytes=None) == []
    removed = codegen.prune_cache(cache, max_bytes=0, keep=(cache / _lib("a"),))
    assert [_short(p) for p in removed] == ["b.so"]
    assert sorted(_short(p) for p in cache.glob("*.so")) == ["a.so", "c.so"]


def test_loading_from_the_cache_marks_the_library_used(cache):
    fn = _small_function()
    codegen.compile_function(fn)
    (lib,) = cache.glob("small_*.so")
    os.utime(lib, (1e9, 1e9))
    codegen.forget_loaded()
    codegen.compile_function(fn)
    assert time.time() - lib.stat().st_mtime < 60


def test_a_build_prunes_the_cache_to_the_environment_bound(cache, monkeypatch):
    _fake_libraries(cache, {"stale": 9000}, size=5000)
    monkeypatch.setenv("HORIZON_MPC_CACHE_MAX_MB", "0.001")  # 1000 bytes
    codegen.compile_function(_small_function())
    # the stale library went; the new one stays although it alone exceeds the bound
    assert [p.name.split("_")[0] for p in cache.glob("*.so")] == ["small"]


@pytest.mark.parametrize("text", ["x", "-1", "inf", "nan"])
def test_a_malformed_bound_is_an_error_that_names_the_variable_but_builds_go_on(
        cache, monkeypatch, text, caplog):
    monkeypatch.setenv("HORIZON_MPC_CACHE_MAX_MB", text)
    with pytest.raises(ValueError, match="HORIZON_MPC_CACHE_MAX_MB"):
        codegen.cache_max_bytes()
    x = cs.SX.sym("x")
    fn = codegen.compile_function(cs.Function("doubled", [x], [2 * x]))
    assert float(fn(3.0)) == 6.0
    assert "the cache is not pruned" in caplog.text


def test_cache_command_line_reports_prunes_and_clears(cache):
    _fake_libraries(cache, {"a": 9000, "b": 8000}, size=2_000_000)
    cmd = [sys.executable, "-m", "horizon_mpc.codegen_cli"]
    env = {**os.environ, "HORIZON_MPC_CACHE_DIR": str(cache)}
    info = subprocess.run([*cmd, "info"], env=env, capture_output=True, text=True, timeout=120)
    assert info.returncode == 0 and "2 libraries, 4.0 MB" in info.stdout, info.stdout
    prune = subprocess.run([*cmd, "prune", "--max-mb", "3"], env=env, capture_output=True,
                           text=True, timeout=120)
    assert prune.returncode == 0 and "removed 1 libraries" in prune.stdout, prune.stdout
    assert [_short(p) for p in cache.glob("*.so")] == ["b.so"]
    clear = subprocess.run([*cmd, "clear"], env=env, capture_output=True, text=True,
                           timeout=120)
    assert clear.returncode == 0 and "0 libraries" in clear.stdout
    for bound in ("-2", "0", "inf"):  # 0 would read as "unbounded" (the variable's meaning)
        bad = subprocess.run([*cmd, "prune", "--max-mb", bound], env=env, capture_output=True,
                             text=True, timeout=120)
        assert bad.returncode == 2 and "--max-mb" in bad.stderr, bound
    # options that did nothing, accepted without a word
    for args, text in ((["clear", "--max-mb", "5"], "--max-mb is the bound of `prune`"),
                       (["info", "--max-mb", "5"], "--max-mb is the bound of `prune`"),
                       (["info", "--dir", str(cache / "missing")], "no such folder"),
                       # a file is not a folder (it said 'no such folder': session 32)
                       (["info", "--dir", str(__file__)], "not a folder")):
        bad = subprocess.run([*cmd, *args], env=env, capture_output=True, text=True,
                             timeout=120)
        assert bad.returncode == 2 and text in bad.stderr, args


def test_clear_empties_the_cache_empty_files_included(cache):
    """A zero-byte library (an interrupted copy) survived `clear`: the loop stopped once
    the total was 0."""
    _fake_libraries(cache, {"a": 9000})
    _fake_libraries(cache, {"empty": 9000}, size=0)
    removed = codegen.prune_cache(cache, max_bytes=0, spare_s=0.0)
    assert sorted(_short(p) for p in removed) == ["a.so", "empty.so"]
    assert list(cache.glob("*.so")) == []


def test_cache_command_line_says_what_it_spared_or_that_there_is_no_bound(cache):
    _fake_libraries(cache, {"a": 9000, "b": 60}, size=2_000_000)
    cmd = [sys.executable, "-m", "horizon_mpc.codegen_cli", "prune"]
    env = {**os.environ, "HORIZON_MPC_CACHE_DIR": str(cache)}
    out = subprocess.run([*cmd, "--max-mb", "1"], env=env, capture_output=True, text=True,
                         timeout=120).stdout
    assert "removed 1 libraries" in out and "1 libraries used in the last 10 minutes" in out
    env["HORIZON_MPC_CACHE_MAX_MB"] = "0"
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120).stdout
    assert "removed 0 libraries" in out and "no bound" in out


def test_cache_command_line_names_a_cache_path_that_is_no_folder(tmp_path, monkeypatch,
                                                                 capsys):
    """HORIZON_MPC_CACHE_DIR=/etc/passwd: 'info' said 0 libraries, exit 0 (--dir said
    'no such folder')."""
    from horizon_mpc import codegen_cli

    (tmp_path / "file").write_text("")
    monkeypatch.setenv("HORIZON_MPC_CACHE_DIR", str(tmp_path / "file"))
    with pytest.raises(SystemExit) as stop:
        codegen_cli.main(["info"])
    assert stop.value.code == 2 and "is not a folder" in capsys.readouterr().err
    monkeypatch.setenv("HORIZON_MPC_CACHE_DIR", str(tmp_path / "none"))
    assert codegen_cli.main(["info"]) == 0
    out = capsys.readouterr().out
    assert "0 libraries" in out and "no such folder yet" in out
    assert not (tmp_path / "none").exists()


# --------------------------------------------------------------------------------------------
# session 28 audit of the cache


def test_a_function_calling_a_compiled_function_runs_uncompiled_and_the_process_lives(cache):
    """Its library linked with the callee's symbols undefined and dlopen killed the process
    (exit 127), every later run too (the library stayed cached). Linked with every symbol
    defined, it fails to build: the uncompiled fallback, with the reason. In a child process
    (a regression would kill pytest)."""
    script = """
import logging, numpy as np, casadi as cs
from horizon_mpc import codegen
logging.basicConfig(level=logging.WARNING)
x = cs.SX.sym("x", 3)
base = codegen.compile_function(cs.Function("base", [x], [cs.sin(x) * 2 + x[0] * x[1]]))
assert codegen.compiled_library(base) is not None
mapped = codegen.compile_function(base.map(5))
out = np.array(mapped(np.tile([0.1, 0.2, 0.3], (5, 1)).T))
assert np.allclose(out[:, 0], np.sin([0.1, 0.2, 0.3]) * 2 + 0.02), out
print("alive", codegen.compiled_library(mapped))
"""
    env = {**os.environ, "HORIZON_MPC_CACHE_DIR": str(cache)}
    for _ in range(2):  # the second run finds the cache as the first left it
        res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                             text=True, timeout=300)
        assert res.returncode == 0 and "alive None" in res.stdout, res.stderr[-2000:]
        assert "undefined reference to" in res.stderr and "compile the uncompiled" in res.stderr
    assert not list(cache.glob("map5_base_*.so"))


def test_native_march_keys_the_cache_by_what_it_means_on_this_cpu(fresh_arch, monkeypatch):
    """-march=native was hashed as the text: two CPUs sharing a cache got the same file
    (AVX-512 code on this machine)."""
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "native")
    monkeypatch.setattr(codegen, "_TARGET_MEMO", {})
    outputs = iter(["  -march=  cooperlake\n  -mavx512f  [enabled]\n",
                    "  -march=  znver2\n  -mavx512f  [disabled]\n"])

    class Done:
        returncode = 0

        def __init__(self) -> None:
            self.stdout = next(outputs)

    monkeypatch.setattr(codegen.subprocess, "run", lambda *a, **k: Done())
    first = codegen._arch_key()
    assert first.startswith("-march=native ") and codegen._arch_key() == first  # memo
    monkeypatch.setattr(codegen, "_TARGET_MEMO", {})
    assert codegen._arch_key() != first
    monkeypatch.setenv("HORIZON_MPC_CODEGEN_MARCH", "x86-64-v3")
    assert codegen._arch_key() == "-march=x86-64-v3"


def test_clear_and_prune_leave_other_files_and_survive_what_they_cannot_remove(cache, caplog):
    """`clear` removed any *.so of the folder (libcasadi.so copied there went); a library
    that could not be removed (another user's, a read-only cache) made a build fall back
    to uncompiled and the command line end in a traceback."""
    (cache / "libcasadi.so").write_bytes(b"\0" * 10)
    _fake_libraries(cache, {"old": 9000})
    (cache / _lib("stuck")).mkdir()  # unlink fails: IsADirectoryError
    os.utime(cache / _lib("stuck"), (1e9, 1e9))
    removed = codegen.prune_cache(cache, max_bytes=0, spare_s=0.0)
    assert [_short(p) for p in removed] == ["old.so"]
    assert (cache / "libcasadi.so").is_file()
    assert "1 libraries could not be removed" in caplog.text
    fn = codegen.compile_function(_small_function())  # builds, then prunes: still compiled
    assert codegen.compiled_library(fn) is not None


def test_names_of_math_h_and_casadi_macros_are_made_other_symbols():
    """nextafter, isfinite, M_PI... did not compile (and the warning said to install a
    C compiler)."""
    for name in ("nextafter", "isfinite", "fpclassify", "M_PI", "INFINITY", "CASADI_PREFIX",
                 "casadi_real", "double_t"):
        assert codegen.function_name(name) == f"f_{name}"
    x = cs.SX.sym("x")
    fn = codegen.compile_function(cs.Function("nextafter", [x], [2 * x]))
    assert float(fn(3.0)) == 6.0


def test_a_cc_that_does_not_split_and_the_reasons_a_build_failed(tmp_path):
    """CC='gcc "x' was a ValueError at import; a full disk read as a C syntax error or
    'ld returned 1'."""
    assert codegen._compiler_argv('gcc "x') == ('gcc "x',)
    assert codegen._compiler_argv("ccache gcc") == ("ccache", "gcc")
    full = codegen.CompilerError("compiling f failed (gcc ...):\n/usr/bin/ld: final link "
                                 "failed: No space left on device\ncollect2: error: ld "
                                 "returned 1 exit status")
    assert codegen._uncompiled_reason(full, tmp_path) == f"{tmp_path}: no space left on the device"
    syntax = codegen.CompilerError("compiling f failed (gcc ...):\nf.c:3:1: error: expected "
                                   "expression at end of input")
    assert codegen._uncompiled_reason(syntax, tmp_path).endswith("error: expected expression "
                                                                 "at end of input")


def test_a_relative_cache_folder_loads_its_libraries(tmp_path, monkeypatch):
    """HORIZON_MPC_CACHE_DIR=. : dlopen took the bare file name of a library as one to search
    the system's library paths for (the compiled Riccati recursion never loaded and was
    rebuilt at every run)."""
    from horizon_mpc.solvers.ilqr.evaluation import GeneratedFunction

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("HORIZON_MPC_CACHE_DIR", ".")
    monkeypatch.delenv("HORIZON_MPC_NO_CODEGEN", raising=False)
    assert codegen.default_cache_dir() == tmp_path
    fn = codegen.compile_function(_small_function())
    assert codegen.compiled_library(fn).is_absolute()
    GeneratedFunction.bind(fn)  # ctypes loads it by its path


@pytest.mark.parametrize("tail, said", [('truncate -s 1000 "$out"', "truncated (1000 bytes"),
                                        ('rm -f "$out"', "is not written")])
def test_a_compiler_output_that_is_not_a_whole_library_is_never_loaded(
        cache, monkeypatch, caplog, tail, said):
    """A compiler that exits 0 with a truncated library: loaded at once (SIGBUS at every
    start; the cache's check saw it only at the next); one that wrote nothing was blamed on
    the cache folder."""
    cc = cache / "cc.sh"
    cc.write_text('#!/bin/sh\nout=""; prev=""\nfor a in "$@"; do [ "$prev" = "-o" ] && '
                  f'out="$a"; prev="$a"; done\ngcc "$@" || exit 1\n{tail}\n')
    cc.chmod(0o755)
    monkeypatch.setattr(codegen, "CC_ARGV", (str(cc),))
    monkeypatch.setattr(codegen, "_UNCOMPILED_WARNED", set())
    x = cs.SX.sym("x")
    fns = [_small_function(), cs.Function("other", [x], [2 * x])]
    def source(work: Path) -> list[str]:
        (work / "probe.c").write_text("int probe(void) { return 0; }\n")
        return [*codegen._FLAGS, str(work / "probe.c")]

    with pytest.raises(codegen.CompilerError, match=re.escape(said)):
        codegen.build_shared_library(cache / _lib("probe"), source, "probe")
    with caplog.at_level("WARNING", logger="horizon_mpc.codegen"):
        for fn in fns:
            assert codegen.compile_function(fn) is fn  # uncompiled, the process alive
    # one warning for all the functions, which does not blame the cache folder
    assert caplog.text.count("running them uncompiled") == 1, caplog.text
    assert codegen.BAD_OUTPUT in caplog.text and "HORIZON_MPC_CACHE_DIR" not in caplog.text
    assert not list(cache.glob("*.so"))


def test_cache_command_line_on_an_unreadable_folder_unremovable_files_and_builds(
        cache, monkeypatch, capsys):
    """An unreadable cache was 'empty' (clear: 'removed 0 libraries', exit 0); libraries
    clear could not remove ended in exit 0; the build folders killed processes left were
    neither counted nor cleared."""
    from horizon_mpc import codegen_cli

    _fake_libraries(cache, {"old": 9000})
    stale, running = cache / ".build_stale", cache / ".build_running"
    for folder in (stale, running):
        folder.mkdir()
        (folder / "x.c").write_bytes(b"\0" * 3000)
    os.utime(stale, (time.time() - 2 * codegen.PRUNE_SPARE_S,) * 2)
    assert codegen_cli.main(["info"]) == 0
    assert "2 unfinished build folders, 0.0 MB" in capsys.readouterr().out
    (cache / _lib("stuck")).mkdir()  # unlink fails: IsADirectoryError
    assert codegen_cli.main(["clear"]) == 1
    out, err = capsys.readouterr()
    assert "removed 1 libraries" in out and "1 libraries could not be removed" in err
    assert not stale.exists() and running.exists()  # a build running is left alone

    real = os.listdir

    def unreadable(path="."):
        if Path(path) == cache:
            raise PermissionError(13, "Permission denied", str(path))
        return real(path)

    monkeypatch.setattr(os, "listdir", unreadable)
    for command in ("info", "clear"):
        with pytest.raises(SystemExit) as exited:
            codegen_cli.main([command])
        assert exited.value.code == 1
        assert "Permission denied" in capsys.readouterr().err


def test_a_library_built_while_waiting_for_its_lock_is_not_built_again(cache, caplog):
    """Two nodes starting together on an empty cache each compiled every function (86 s
    each for go2 on 2 cores, an auditor's): a build waits for the one in progress and
    finds the library built."""
    import threading

    lib = cache / _lib("probe")
    compiles: list[str] = []

    def source(work: Path) -> list[str]:
        compiles.append(work.name)
        (work / "probe.c").write_text("int probe(void) { return 0; }\n")
        return [*codegen._FLAGS, str(work / "probe.c")]

    built: list[bool] = []
    waiter = threading.Thread(
        target=lambda: built.append(codegen.build_shared_library(lib, source, "probe")))
    with caplog.at_level("INFO", logger="horizon_mpc.codegen"):
        with codegen.build_lock(lib):  # another process is building it
            waiter.start()
            time.sleep(0.5)
            assert waiter.is_alive() and not compiles  # waiting, not compiling
            codegen._build_unlocked(lib, source, "probe")  # the other process's build
        waiter.join(timeout=30)
    assert built == [False] and len(compiles) == 1
    # the wait is said (a review: a node waiting on a suspended build said nothing)
    assert "waiting for another process building probe" in caplog.text
    assert codegen.library_damage(lib) is None
    # without a build in progress it compiles (and says so)
    lib.unlink()
    assert codegen.build_shared_library(lib, source, "probe") is True and len(compiles) == 2
    # clear removes the locks of the libraries it removed
    codegen.prune_cache(cache, max_bytes=0, spare_s=0.0)
    assert not list((cache / ".locks").glob("*.lock"))
