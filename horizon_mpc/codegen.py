"""Compile any ``casadi.Function`` to C, with an on-disk cache shared by all processes.

``compile_function(fn)`` generates C for ``fn`` (``casadi.CodeGenerator``), builds a shared
library with ``gcc -shared -fPIC`` (optimisation by size of the C, ``-march`` from
:func:`arch_flags`) and loads it with ``casadi.external``. The result has the
same name, inputs and outputs as ``fn`` and returns the same numbers. It evaluates numerically
and on MX, not on SX (an external function has no SX graph), and it has no derivatives:
compile the derivative Function you need (e.g. a Jacobian) rather than differentiating it.

Cache: ``$HORIZON_MPC_CACHE_DIR``, else ``$XDG_CACHE_HOME/horizon_mpc``, else
``~/.cache/horizon_mpc``. A library is keyed by a hash of ``fn.serialize()``, the compiler
command and the CasADi version, so a changed function never loads a stale library. Libraries
are written under a temporary name and renamed into place, so every reader sees a complete
file; processes building the same library take turns on an advisory lock
(``.locks/<library>.lock``, :func:`build_lock`): the first compiles, the others wait (saying
so) and load its result. Where locks do not work (no ``fcntl``, a file system without them)
builds run unlocked and the last rename wins.

A cached library that is damaged (empty, not a shared object, truncated: a disk filled up,
a copy cut short; or bytes changed inside it, which its SHA-256, kept next to it in
``<library>.sha256``, tells) is rebuilt, never loaded (a truncated one killed the process
with SIGBUS, one overwritten inside with SIGILL or SIGSEGV, or returned other numbers).
Without a working compiler (none, or one that fails: a bad ``$CC`` or
``$HORIZON_MPC_CODEGEN_MARCH``) or a writable cache, ``fn`` is returned uncompiled (slower,
same numbers) with one warning that says why. A compiler whose Python process dies (SIGTERM,
SIGKILL) is killed with its whole process group, and build folders left by a killed process
are removed by later builds.

The cache is bounded: loading a library marks it used (its modification time), and after
each build the least recently used libraries are deleted while the cache holds more than
``$HORIZON_MPC_CACHE_MAX_MB`` (default 2048; 0 disables the bound), sparing those this
process loaded and any used in the last ten minutes. ``python -m horizon_mpc.codegen_cli
info`` reports the cache, ``prune [--max-mb N]`` bounds it now, ``clear`` empties it.

Set ``HORIZON_MPC_NO_CODEGEN=1`` to get ``fn`` back unchanged (debugging, or no compiler).
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import logging
import math
import os
import platform
import re
import shlex
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import casadi as cs
import numpy as np

try:  # POSIX: the build locks (elsewhere builds run unlocked, as they always could)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = [
    "STATS",
    "BufferedFunction",
    "CC_ARGV",
    "CacheInfo",
    "CompileStats",
    "CompilerError",
    "DEFAULT_CACHE_MAX_MB",
    "PRUNE_SPARE_S",
    "arch_flags",
    "build_lock",
    "build_shared_library",
    "cache_info",
    "cache_max_bytes",
    "checksum_path",
    "codegen_enabled",
    "compile_function",
    "compiled_library",
    "default_cache_dir",
    "forget_loaded",
    "function_name",
    "library_damage",
    "mark_used",
    "prune_cache",
]

_log = logging.getLogger(__name__)

CC = os.environ.get("CC", "gcc")


def _compiler_argv(cc: str) -> tuple[str, ...]:
    """``cc`` split as a shell would ("ccache gcc", "gcc -pipe"); one that does not split
    (an unbalanced quote) is kept whole: it is then no compiler on PATH, the documented
    uncompiled fallback with one warning (it was a ValueError at import)."""
    try:
        return tuple(shlex.split(cc)) or ("gcc",)
    except ValueError:
        return (cc,)


#: the compiler command: ``$CC`` split as a shell would
CC_ARGV = _compiler_argv(CC)
# Optimisation level by size of the generated C. SX code is long straight-line arithmetic:
# measured on go2's inverse-dynamics derivatives mapped over 50 nodes (423 kB of C), -O1
# compiles in 10 s against 24 s for -O3 and runs within 5% of it (doc/benchmarks.md).
_OPT_BY_SIZE = ((150_000, "-O3"),)
_OPT_LARGE = "-O1"
# Added to -O1, the passes of -O2 that pay on straight-line arithmetic (the FMA contraction
# is part of -fexpensive-optimizations): go2's walking quadratisation (1.9 MB of C) runs
# 47 % faster with them and x86-64-v3 (191 against 364 us) and compiles in ~18 s instead of
# ~12 s (-O2: ~50 s for the same speed); doc/benchmarks.md, session 8.
_OPT_LARGE_EXTRA = ("-fstrict-aliasing", "-fexpensive-optimizations", "-ftree-slp-vectorize")
_FLAGS = ("-shared", "-fPIC")
# every symbol resolved when linking (Linux): a function calling another compiled one (its
# ``<name>_incref``... are in that library) linked, then killed the process at dlopen
_LINK_FLAGS = ("-Wl,-z,defs",) if sys.platform.startswith("linux") else ()
_POLICY = f"{_OPT_BY_SIZE}|{_OPT_LARGE}|{_OPT_LARGE_EXTRA}|{_FLAGS}|{_LINK_FLAGS}|v3"
# x86-64-v3 (AVX2, FMA, BMI1/2, F16C, LZCNT, MOVBE): the CPU features /proc/cpuinfo names
_X86_64_V3 = frozenset({"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave"})
_ARCH_MEMO: dict[tuple[str, str], tuple[str, ...]] = {}


@dataclass
class CompileStats:
    """Process-wide counters (tests use them to tell a compilation, a load from the disk
    cache and a library already loaded in this process apart)."""

    compiled: int = 0  # gcc runs
    loaded: int = 0  # libraries loaded from the disk cache
    memory_hits: int = 0  # already loaded in this process


STATS = CompileStats()
_LOADED: dict[str, cs.Function] = {}


def codegen_enabled() -> bool:
    """False when ``HORIZON_MPC_NO_CODEGEN`` is set to a true value (1, true, yes)."""
    return os.environ.get("HORIZON_MPC_NO_CODEGEN", "").strip().lower() not in ("1", "true", "yes")


def default_cache_dir() -> Path:
    """The cache directory (see the module docstring); not created here."""
    env = os.environ.get("HORIZON_MPC_CACHE_DIR")
    if env:
        # absolute: dlopen (ctypes) reads a bare file name as one to search the system's
        # library paths for ('.' ran the compiled Riccati recursion never, rebuilt each run)
        return Path(env).expanduser().absolute()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return (base / "horizon_mpc").absolute()


def _cache_folder(folder: str | Path | None) -> Path:
    """``folder`` (user-expanded, absolute), or :func:`default_cache_dir` when None."""
    return Path(folder).expanduser().absolute() if folder is not None else default_cache_dir()


def function_name(text: str) -> str:
    """``text`` made a valid CasADi Function (and C) name: ``[A-Za-z](_?[A-Za-z0-9])*``, ASCII,
    at most 64 characters (a longer one keeps a hash of the rest), and never a C keyword, a
    libm function or CasADi's own ``casadi_`` prefix (``sin``, ``int``, ``casadi_f0`` did not
    compile)."""
    out = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", text)).strip("_")
    if not out:  # no ASCII letter or digit at all (a frame named '脚' or '-': 'f_' made
        out = "f"  # 'jac_f__LOCAL' of its Jacobian, which CasADi refused)
    elif not out[:1].isalpha() or out in _C_RESERVED or out.startswith("casadi_"):
        out = "f_" + out
    if len(out) > 64:
        out = f"{out[:55].rstrip('_')}_{hashlib.sha256(out.encode()).hexdigest()[:8]}"
    return out


# C keywords and libm names a generated function would clash with (its own symbol is
# the function's name)
_C_RESERVED = frozenset("""auto break case char const continue default do double else enum
extern float for goto if inline int long register restrict return short signed sizeof static
struct switch typedef union unsigned void volatile while main abs acos asin atan atan2 cbrt
ceil cos cosh erf exp expm1 fabs floor fmax fmin fmod hypot log log10 log1p log2 pow round
sin sinh sqrt tan tanh trunc sign copysign j0 j1 jn y0 y1 yn modf frexp ldexp lgamma tgamma
rint lrint llrint nearbyint remainder remquo scalbn scalbln logb ilogb exp2 fdim fma nan
erfc asinh acosh atanh lround llround isnan isinf signbit gamma drem significand isfinite
isnormal fpclassify nextafter nexttoward finite double_t float_t isgreater isless isunordered
INFINITY NAN HUGE_VAL HUGE_VALF HUGE_VALL M_PI M_E CASADI_SYMBOL_EXPORT CASADI_PREFIX
casadi_int casadi_real""".split())
_C_RESERVED = _C_RESERVED | {n + suffix for n in _C_RESERVED for suffix in ("f", "l")}


def _opt_flags(c_size: int) -> tuple[str, ...]:
    for limit, flag in _OPT_BY_SIZE:
        if c_size < limit:
            return (flag,)
    return (_OPT_LARGE, *_OPT_LARGE_EXTRA)


def _cpu_flags() -> frozenset[str]:
    """The CPU feature flags of /proc/cpuinfo (empty where there is no such file)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return frozenset()
    for line in text.splitlines():
        if line.startswith("flags"):
            return frozenset(line.partition(":")[2].split())
    return frozenset()


def _compiler_accepts(flag: str) -> bool:
    res = subprocess.run([*CC_ARGV, flag, "-x", "c", "-fsyntax-only", "-"], input="",
                         capture_output=True, text=True, check=False)
    return res.returncode == 0


def arch_flags() -> tuple[str, ...]:
    """The ``-march`` of generated code: ``$HORIZON_MPC_CODEGEN_MARCH`` when set (a gcc
    ``-march`` value such as ``native``, or ``none`` for the compiler's baseline), else
    ``x86-64-v3`` on an x86-64 CPU with all its features and a compiler that knows it,
    else none. Part of every library's cache key: a cache shared by different CPUs keeps
    one build per target, and a CPU never loads code it cannot run."""
    choice = os.environ.get("HORIZON_MPC_CODEGEN_MARCH", "auto").strip() or "auto"
    memo = _ARCH_MEMO.get((choice, CC))
    if memo is not None:
        return memo
    if choice == "none":
        flags: tuple[str, ...] = ()
    elif choice != "auto":
        flags = (f"-march={choice}",)
    elif (platform.machine() in ("x86_64", "AMD64") and _X86_64_V3 <= _cpu_flags()
          and shutil.which(CC_ARGV[0]) and _compiler_accepts("-march=x86-64-v3")):
        flags = ("-march=x86-64-v3",)
    else:
        flags = ()
    _ARCH_MEMO[(choice, CC)] = flags
    return flags


def _renamed(fn: cs.Function, name: str) -> cs.Function:
    if fn.name() == name:
        return fn
    if fn.is_a("SXFunction"):
        args = fn.sx_in()
    else:
        args = fn.mx_in()
    return cs.Function(name, args, fn.call(args), fn.name_in(), fn.name_out())


_TARGET_MEMO: dict[tuple[str, ...], str] = {}


def _arch_key() -> str:
    """:func:`arch_flags` as a cache key: ``-march=native`` with what it means on this CPU
    (the compiler's target options; a hash of /proc/cpuinfo's flags if it cannot say), so
    that a cache shared by two CPUs never gives one the other's code (AVX-512 on a CPU
    without it: SIGILL)."""
    flags = arch_flags()
    if not any(f == "-march=native" for f in flags):
        return " ".join(flags)
    if flags not in _TARGET_MEMO:
        try:
            res = subprocess.run([*CC_ARGV, *flags, "-Q", "--help=target"], capture_output=True,
                                 text=True, check=False, timeout=30)
            target = res.stdout if res.returncode == 0 and res.stdout.strip() else ""
        except (OSError, subprocess.SubprocessError):
            target = ""
        target = target or " ".join(sorted(_cpu_flags()))
        _TARGET_MEMO[flags] = hashlib.sha256(target.encode()).hexdigest()[:16]
    return " ".join(flags) + " " + _TARGET_MEMO[flags]


def _key(fn: cs.Function) -> str:
    h = hashlib.sha256()
    for part in (fn.serialize(), _POLICY, _arch_key(), CC, cs.__version__):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:24]


def compile_function(
    fn: cs.Function, name: str | None = None, cache_dir: str | Path | None = None
) -> cs.Function:
    """Compiled twin of ``fn`` (same signature), from the cache when possible.

    Args:
        fn: any CasADi Function without free variables (SX, MX, mapped, ...).
        name: name of the compiled function (a C identifier); default ``fn.name()``.
        cache_dir: where libraries are kept; default :func:`default_cache_dir`.

    Returns:
        a ``casadi.Function`` backed by the shared library, or ``fn`` itself when
        ``HORIZON_MPC_NO_CODEGEN=1``, or with a warning (once per reason) when it cannot
        be compiled: no compiler, one that fails, a cache folder that cannot be written.
    """
    if not codegen_enabled():
        return fn
    fn = _renamed(fn, function_name(name or fn.name()))  # the name is a C symbol
    folder = _cache_folder(cache_dir)
    lib = folder / f"{fn.name()}_{_key(fn)}.so"
    if str(lib) in _LOADED:
        STATS.memory_hits += 1
        return _LOADED[str(lib)]
    try:
        folder.mkdir(parents=True, exist_ok=True)
        damage = library_damage(lib) if lib.is_file() else None
        if damage:
            _log.warning("cached library %s is damaged (%s): rebuilding it", lib, damage)
            lib.unlink(missing_ok=True)
        if lib.is_file():
            _log.debug("loading %s from the cache (%s)", fn.name(), lib)
            STATS.loaded += 1
            mark_used(lib)
        else:
            _build(fn, lib)
    except (OSError, CompilerError) as exc:  # no compiler or a failing one, a cache
        # folder that cannot be written
        _warn_uncompiled(_uncompiled_reason(exc, folder))
        return fn
    try:
        compiled = cs.external(fn.name(), str(lib))
    except RuntimeError as exc:  # not loadable after all (dlopen): one rebuild
        _log.warning("cached library %s does not load (%s): rebuilding it", lib,
                     str(exc).splitlines()[-1])
        lib.unlink(missing_ok=True)
        try:
            _build(fn, lib)
        except (OSError, CompilerError) as again:
            _warn_uncompiled(_uncompiled_reason(again, folder))
            return fn
        try:
            compiled = cs.external(fn.name(), str(lib))
        except RuntimeError as again:  # e.g. a cache folder mounted noexec
            _warn_uncompiled(f"{lib.parent}: {str(again).splitlines()[-1]}")
            return fn
    _LOADED[str(lib)] = compiled
    return compiled


_UNCOMPILED_WARNED: set[str] = set()


class CompilerError(RuntimeError):
    """The C compiler ran and failed (:func:`build_shared_library`)."""


#: why a build failed when the compiler exited 0 with no whole library
BAD_OUTPUT = "the C compiler exited 0 without a whole library (truncated or not written)"


def _uncompiled_reason(exc: OSError | CompilerError, folder: Path) -> str:
    """Why a build failed, the same for every function (the warning is said once per
    reason; a path named each function's random build folder): an OSError's folder and
    reason, or the compiler's first error line, else the last line of its message."""
    if isinstance(exc, OSError):
        return f"{folder}: {exc.strerror or exc}"
    lines = [line.strip() for line in str(exc).splitlines() if line.strip()]
    # the cause before the compiler's generic lines: a full disk (a truncated source reads
    # as a syntax error, a failed link as 'ld returned 1'), a function calling another
    # compiled one (its symbols are in that library), then the first error
    def first(needle: str) -> str | None:
        return next((line for line in lines[1:] if needle in line.lower()), None)

    if first("no space left on device") or _disk_full(folder):
        return f"{folder}: no space left on the device"
    undefined = first("undefined reference to")
    if undefined:
        return (f"the C compiler failed: {undefined} (a function that calls a compiled "
                "function: compile the uncompiled one instead)")
    if lines and lines[-1] == BAD_OUTPUT:
        return BAD_OUTPUT
    return f"the C compiler failed: {first('error') or (lines or [repr(exc)])[-1]}"


def _disk_full(folder: Path) -> bool:
    """Whether ``folder``'s file system has less than 1 MB free (a generated source cut
    short there gave a C syntax error)."""
    try:
        return shutil.disk_usage(folder).free < 1_000_000
    except OSError:
        return False


def _warn_uncompiled(reason: str) -> None:
    if reason not in _UNCOMPILED_WARNED:
        _UNCOMPILED_WARNED.add(reason)
        if "not found on PATH" in reason:
            advice = f"install a C compiler (CC={CC}), or "
        elif reason.startswith(("the C compiler failed", BAD_OUTPUT)):
            advice = ""
        else:
            advice = "set HORIZON_MPC_CACHE_DIR to a writable folder, or "
        _log.warning("cannot compile CasADi functions (%s): running them uncompiled (slower); "
                     "%sset HORIZON_MPC_NO_CODEGEN=1 to silence this", reason, advice)


def library_damage(lib: Path) -> str | None:
    """Why the shared library file ``lib`` cannot be a complete one, or None. ELF (Linux):
    the magic number and the section header table, which the linker writes last, inside the
    file; elsewhere only emptiness is checked. Then its checksum (:func:`checksum_path`)."""
    return _structure_damage(lib) or _checksum_damage(lib)


def _structure_damage(lib: Path) -> str | None:
    """:func:`library_damage` without the checksum."""
    try:
        with open(lib, "rb") as fh:
            head = fh.read(64)
            size = os.fstat(fh.fileno()).st_size
    except OSError as exc:
        return f"unreadable: {exc}"
    if size == 0:
        return "empty"
    if not sys.platform.startswith("linux"):
        return None
    if len(head) < 52 or head[:4] != b"\x7fELF":
        return "not an ELF shared object"
    order = "<" if head[5] == 1 else ">"
    if head[4] == 2 and len(head) >= 64:  # ELF64
        (shoff,), (shentsize, shnum) = (struct.unpack_from(order + "Q", head, 0x28),
                                        struct.unpack_from(order + "HH", head, 0x3A))
    else:  # ELF32
        (shoff,), (shentsize, shnum) = (struct.unpack_from(order + "I", head, 0x20),
                                        struct.unpack_from(order + "HH", head, 0x2E))
    if shoff + shentsize * shnum > size:
        return f"truncated ({size} bytes, its section table ends at {shoff + shentsize * shnum})"
    return None


def checksum_path(lib: Path) -> Path:
    """The file next to ``lib`` holding its SHA-256, written by :func:`build_shared_library`."""
    return lib.with_name(lib.name + ".sha256")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _checksum_damage(lib: Path) -> str | None:
    """Whether ``lib``'s bytes are those it was built with: a library overwritten inside
    (its headers intact) was loaded and crashed every later run (SIGILL, SIGSEGV), or
    returned other numbers without a word. A library without a checksum (a cache of an
    earlier version, sound by the checks above) is adopted: its checksum is written now
    when the folder can be written (rebuilding every one cost minutes, and a read-only
    cache ran uncompiled)."""
    path = checksum_path(lib)
    try:
        got = _sha256(lib)
    except OSError as exc:
        return f"unreadable: {exc}"
    try:
        want = path.read_text().split()[0]
    except FileNotFoundError:
        with contextlib.suppress(OSError):
            _write_atomically(path, got + "\n")
        return None
    except (OSError, IndexError):
        return "its checksum file is unreadable or empty"
    return None if got == want else "its bytes changed since it was built (checksum)"


def _write_atomically(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def compiled_library(fn: cs.Function) -> Path | None:
    """The shared library behind ``fn`` when :func:`compile_function` returned it (in this
    process), else None. Its C entry points are CasADi's interface of generated code:
    ``<fn.name()>(arg, res, iw, w, mem)`` and ``<fn.name()>_work`` for the array sizes."""
    for path, loaded in _LOADED.items():
        if loaded is fn:
            return Path(path)
    return None


def forget_loaded() -> None:
    """Drop the in-process table of loaded libraries (the next call reads the disk cache)."""
    _LOADED.clear()


def _build(fn: cs.Function, lib: Path) -> None:
    started: list[float] = []

    def generate(work: Path) -> list[str]:  # called once the build's lock is taken
        started.append(time.perf_counter())
        c_name = f"{fn.name()}.c"
        gen = cs.CodeGenerator(c_name, {"with_header": False})
        gen.add(fn)
        gen.generate(str(work) + os.sep)
        size = (work / c_name).stat().st_size
        opt = (*_opt_flags(size), *arch_flags())
        _log.info("compiling %s (%d kB of C, %s)...", fn.name(), size // 1000, " ".join(opt))
        return [*opt, *_FLAGS, str(work / c_name)]

    if build_shared_library(lib, generate, fn.name()):
        STATS.compiled += 1
        _log.info("compiled %s in %.1f s -> %s", fn.name(), time.perf_counter() - started[0],
                  lib)
    else:
        STATS.loaded += 1
        _log.info("%s was compiled meanwhile by another process: loading it", fn.name())


def build_shared_library(lib: Path, compiler_args: Callable[[Path], list[str]],
                         what: str) -> bool:
    """Build the shared library ``lib`` with the C compiler (:data:`CC_ARGV`) in a
    temporary folder next to it, then rename it into place (atomic: readers never see a
    partial file). ``compiler_args(work)`` gives the arguments between the compiler and
    ``-o`` (flags, sources) and may write the sources into ``work`` first. The compiler runs
    in a process group that dies with this process; build folders that a killed process
    left behind are removed.

    Processes building the same library take turns (an advisory lock, :func:`build_lock`):
    one compiles, the others wait and find it built. Returns True when this call compiled
    it, False when another process did meanwhile (two nodes starting together on an empty
    cache each compiled every function, 86 s each for go2 on 2 cores).

    Raises:
        FileNotFoundError: no C compiler (checked before ``compiler_args`` runs).
        CompilerError: the compiler failed (the message ends with its output).
    """
    if shutil.which(CC_ARGV[0]) is None:
        raise FileNotFoundError(f"C compiler {CC_ARGV[0]!r} not found on PATH")
    lib.parent.mkdir(parents=True, exist_ok=True)
    with build_lock(lib, what):
        if lib.is_file() and library_damage(lib) is None:
            return False
        _build_unlocked(lib, compiler_args, what)
    return True


@contextlib.contextmanager
def build_lock(lib: Path, what: str = "") -> Iterator[None]:
    """Hold the exclusive advisory lock of building ``lib`` (a ``flock`` on
    ``.locks/<name>.lock`` beside it: released when the block ends or the process dies,
    so a killed build never leaves it held); a wait for another process's build is logged
    first (naming ``what``, default the library). Where locks do not work (no ``fcntl``,
    a file system without them), the block runs unlocked: concurrent builds were always
    safe, only duplicated."""
    locks = lib.parent / ".locks"
    try:
        if fcntl is None:
            raise OSError("no fcntl")
        locks.mkdir(exist_ok=True)
        fh = open(locks / f"{lib.name}.lock", "a")  # noqa: SIM115 - closed below
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            _log.info("waiting for another process building %s (%s)", what or lib.name,
                      locks / f"{lib.name}.lock")
            with contextlib.suppress(OSError):
                fcntl.flock(fh, fcntl.LOCK_EX)
        except OSError:  # a file system without locks
            pass
        yield
    finally:
        fh.close()


def _build_unlocked(lib: Path, compiler_args: Callable[[Path], list[str]],
                    what: str) -> None:
    """:func:`build_shared_library`'s work, under its lock."""
    _remove_stale_builds(lib.parent)
    work = Path(tempfile.mkdtemp(prefix=".build_", dir=lib.parent))
    try:
        tmp_lib = work / lib.name
        cmd = [*CC_ARGV, *compiler_args(work), "-o", str(tmp_lib), "-lm", *_LINK_FLAGS]
        returncode, stderr = _run_compiler(cmd)
        if returncode != 0:
            raise CompilerError(f"compiling {what} failed ({' '.join(cmd)}):\n{stderr[-2000:]}")
        # a compiler that says it succeeded: its output checked before it is ever loaded (a
        # truncated one was a SIGBUS at every start, the cache's check seeing it only later)
        damage = "not written" if not tmp_lib.is_file() else _structure_damage(tmp_lib)
        if damage:  # the last line the same for every function: one warning for them all
            raise CompilerError(f"compiling {what} ({' '.join(cmd)}): its library is {damage}"
                                f"\n{BAD_OUTPUT}")
        # the checksum first: a reader seeing a library sees its checksum or a newer one
        # (two processes building at once: a mismatch, one rebuild; never a damaged load)
        tmp_sum = work / checksum_path(lib).name
        tmp_sum.write_text(_sha256(tmp_lib) + "\n")
        os.replace(tmp_sum, checksum_path(lib))
        os.replace(tmp_lib, lib)  # atomic within one file system
    finally:
        shutil.rmtree(work, ignore_errors=True)
    try:
        prune_cache(lib.parent, keep=(lib,))
    except (ValueError, OSError) as exc:  # a malformed bound, an unreadable folder: the
        # library is built, the cache only not pruned
        if str(exc) not in _UNCOMPILED_WARNED:
            _UNCOMPILED_WARNED.add(str(exc))
            _log.warning("%s: the cache is not pruned", exc)


STALE_BUILD_S = 3600.0  # a build folder this old was left by a killed process
#: libraries used this recently are never pruned (another process may be loading them)
PRUNE_SPARE_S = 600.0
DEFAULT_CACHE_MAX_MB = 2048.0


def mark_used(lib: Path) -> None:
    """Record that ``lib`` was used now (its modification time: the pruning's order)."""
    with contextlib.suppress(OSError):
        os.utime(lib)


def cache_max_bytes() -> int | None:
    """The cache bound of ``$HORIZON_MPC_CACHE_MAX_MB`` (MB, default 2048), None when 0.

    Raises:
        ValueError: the variable is not a number >= 0.
    """
    text = os.environ.get("HORIZON_MPC_CACHE_MAX_MB", "").strip()
    try:
        mb = float(text) if text else DEFAULT_CACHE_MAX_MB
    except ValueError:
        mb = math.nan
    if not mb >= 0.0 or math.isinf(mb):
        raise ValueError(f"HORIZON_MPC_CACHE_MAX_MB must be a number of MB >= 0 (0: no "
                         f"bound), got {text!r}")
    return int(mb * 1e6) if mb > 0 else None


@dataclass
class CacheInfo:
    """What a cache folder holds: ``libraries`` (count), ``bytes``, the modification
    times (s since the epoch) of the least and most recently used library, and ``recent``,
    the libraries used in the last :data:`PRUNE_SPARE_S` seconds (never pruned);
    ``builds``, ``build_bytes``: the unfinished build folders (a build running, or one a
    killed process left: a build removes those after :data:`STALE_BUILD_S`, ``clear``
    after :data:`PRUNE_SPARE_S`)."""

    folder: Path
    libraries: int
    bytes: int
    oldest: float | None
    newest: float | None
    recent: int
    builds: int = 0
    build_bytes: int = 0


#: the cache's library names, ``<function>_<24 hex digits of the key>.so``
_LIBRARY_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*_[0-9a-f]{24}\.so")


def _libraries(folder: Path) -> list[tuple[float, int, Path]]:
    """(mtime, size, path) of the cache's libraries, least recently used first."""
    out = []
    # listed first: Path.glob skips a folder it cannot read, and an unreadable cache was
    # reported as empty (`clear`: 'removed 0 libraries', exit 0)
    for name in os.listdir(folder):
        if not _LIBRARY_NAME.fullmatch(name):  # not one of ours (libcasadi.so...)
            continue
        lib = folder / name
        with contextlib.suppress(OSError):
            st = lib.stat()
            out.append((st.st_mtime, st.st_size, lib))
    return sorted(out)


def cache_info(folder: str | Path | None = None) -> CacheInfo:
    """The libraries of the cache ``folder`` (default :func:`default_cache_dir`)."""
    folder = _cache_folder(folder)
    libs = _libraries(folder) if folder.is_dir() else []
    builds = [_tree_bytes(b) for b in folder.glob(".build_*")] if folder.is_dir() else []
    now = time.time()
    return CacheInfo(folder, len(libs), sum(size for _, size, _ in libs),
                     libs[0][0] if libs else None, libs[-1][0] if libs else None,
                     sum(now - mtime < PRUNE_SPARE_S for mtime, _, _ in libs),
                     len(builds), sum(builds))


def _tree_bytes(folder: Path) -> int:
    """The bytes of the files under ``folder`` (those it can see)."""
    total = 0
    for root, _, files in os.walk(folder):
        for name in files:
            with contextlib.suppress(OSError):
                total += os.lstat(os.path.join(root, name)).st_size
    return total


def prune_cache(folder: str | Path | None = None, max_bytes: int | None = -1,
                keep: tuple[Path, ...] = (), spare_s: float = PRUNE_SPARE_S,
                undeletable: list[str] | None = None) -> list[Path]:
    """Delete the least recently used libraries of ``folder`` (default
    :func:`default_cache_dir`) while it holds more than ``max_bytes`` (-1: the bound of
    :func:`cache_max_bytes`; None: no bound, nothing deleted). Spared: ``keep``, the
    libraries this process loaded and those used in the last ``spare_s`` seconds (a
    process that already loaded a deleted library keeps it; one about to load it rebuilds
    it). With ``max_bytes`` 0 (clear), build folders older than :data:`PRUNE_SPARE_S` go
    too. Returns the deleted paths; ``undeletable``, if given, gets the libraries that
    could not be removed (name: reason).

    Raises:
        ValueError: a malformed ``$HORIZON_MPC_CACHE_MAX_MB`` (with ``max_bytes`` -1).
    """
    folder = _cache_folder(folder)
    if max_bytes == -1:
        max_bytes = cache_max_bytes()
    if max_bytes is None or not folder.is_dir():
        return []
    libs = _libraries(folder)
    total = sum(size for _, size, _ in libs)
    spared = {str(p) for p in keep} | set(_LOADED)
    now, deleted = time.time(), []
    undeletable = [] if undeletable is None else undeletable
    for mtime, size, lib in libs:
        if total <= max_bytes and max_bytes > 0:  # 0 (clear): empty files go too
            break
        if str(lib) in spared or now - mtime < spare_s:
            continue
        try:
            lib.unlink()
        except FileNotFoundError:  # another process pruned it
            pass
        except OSError as exc:  # another user's file in a shared folder, a read-only cache
            undeletable.append(f"{lib.name}: {exc.strerror or exc}")
            continue
        else:
            deleted.append(lib)
        with contextlib.suppress(OSError):
            checksum_path(lib).unlink(missing_ok=True)
        total -= size
    if max_bytes == 0:  # clear: build folders killed processes left, orphan checksums
        _remove_stale_builds(folder, PRUNE_SPARE_S)
        for orphan in folder.glob("*.so.sha256"):
            if _LIBRARY_NAME.fullmatch(orphan.name[:-7]) and not orphan.with_suffix("").exists():
                with contextlib.suppress(OSError):
                    orphan.unlink()
    if deleted or max_bytes == 0:
        _remove_orphan_locks(folder)
    if undeletable:
        _log.warning("codegen cache %s: %d libraries could not be removed (%s)", folder,
                     len(undeletable), "; ".join(undeletable[:3]))
    if deleted:
        _log.info("codegen cache %s: removed %d least recently used libraries (bound %g MB, "
                  "HORIZON_MPC_CACHE_MAX_MB)", folder, len(deleted), max_bytes / 1e6)
    return deleted


def _remove_orphan_locks(folder: Path) -> None:
    """The build locks (:func:`build_lock`) of libraries no longer there, when no build
    holds them (one that starts meanwhile may then build beside another: a duplicate
    build, which was always safe)."""
    if fcntl is None:
        return
    for lock in (folder / ".locks").glob("*.lock"):
        if (folder / lock.name[:-5]).exists():
            continue
        with contextlib.suppress(OSError), open(lock, "a") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            lock.unlink()


def _remove_stale_builds(folder: Path, age_s: float = STALE_BUILD_S) -> None:
    now = time.time()
    for old in folder.glob(".build_*"):
        with contextlib.suppress(OSError):
            if now - old.stat().st_mtime > age_s:
                shutil.rmtree(old, ignore_errors=True)


# The compiler runs under `sh` in a process group of its own; the shell kills that group
# (the driver, cc1, as, ld) when it gets SIGTERM, which Linux sends it when this process
# dies (PR_SET_PDEATHSIG), also by SIGKILL: a killed Python left gcc compiling for minutes
_GROUP_GUARD = 'trap "kill -KILL 0" TERM; "$@" & wait $!'
_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    _PRCTL(_PR_SET_PDEATHSIG, int(signal.SIGTERM))


_PRCTL = None
if sys.platform.startswith("linux"):
    with contextlib.suppress(OSError, AttributeError):
        _PRCTL = ctypes.CDLL(None, use_errno=True).prctl  # resolved before any fork


def _run_compiler(cmd: list[str]) -> tuple[int, str]:
    """Run the compiler in a process group of its own, killed with it when this process
    dies (see ``_GROUP_GUARD``); if anything interrupts the wait (a signal handler raising,
    KeyboardInterrupt), the whole group is killed: killing the driver alone left its cc1
    compiling for tens of seconds.

    Raises:
        FileNotFoundError: no such compiler.
    """
    if shutil.which(cmd[0]) is None:
        raise FileNotFoundError(f"C compiler {cmd[0]!r} not found on PATH")
    guarded = _PRCTL is not None and shutil.which("sh") is not None
    proc = subprocess.Popen(["sh", "-c", _GROUP_GUARD, "sh", *cmd] if guarded else cmd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            preexec_fn=_die_with_parent if guarded else None)  # noqa: PLW1509
    try:
        _, stderr = proc.communicate()
    except BaseException:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
    return proc.returncode, stderr


class BufferedFunction:
    """Evaluate a Function on preallocated numpy arrays, with no DM conversion.

    Passing numpy arrays to a ``casadi.Function`` converts them to DM element by element
    (about 50 ns per number in CasADi 3.8) and every output is a freshly allocated DM: for a
    Jacobian mapped over 50 nodes that is as much time as the evaluation. This wrapper binds
    fixed input and output arrays once (``Function.buffer()``) and writes into them in place.

    Example::

        call = BufferedFunction(compile_function(fn.map(50)))
        tau, dtau_dq, *_ = call(q, v, a, f)  # numpy views, overwritten by the next call

    Only dense inputs and outputs are supported (densify the Function otherwise).
    ``output_buffer`` is one flat array holding every output, in order (e.g. one
    finiteness test of all of them: ``math.isfinite(call.output_buffer.sum())``).
    """

    def __init__(self, fn: cs.Function) -> None:
        for kind, n, sp in (
            ("input", fn.n_in(), fn.sparsity_in),
            ("output", fn.n_out(), fn.sparsity_out),
        ):
            for i in range(n):
                if not sp(i).is_dense():
                    raise ValueError(f"{fn.name()}: {kind} {i} is sparse; use a dense Function")
        self.fn = fn
        self._buffer, self._eval = fn.buffer()
        # CasADi is column-major: a Fortran-ordered array's transpose is a C-contiguous view
        self.inputs = [np.zeros(fn.size_in(i), order="F") for i in range(fn.n_in())]
        # the outputs are consecutive blocks of one array: one reduction covers them all
        sizes = [fn.numel_out(i) for i in range(fn.n_out())]
        self.output_buffer = np.zeros(sum(sizes))
        offsets = np.concatenate(([0], np.cumsum(sizes))).astype(int)
        self.outputs = [self.output_buffer[offsets[i]:offsets[i + 1]].reshape(
            fn.size_out(i), order="F") for i in range(fn.n_out())]
        for i, arr in enumerate(self.inputs):
            self._buffer.set_arg(i, memoryview(arr.T))
        for i, arr in enumerate(self.outputs):
            self._buffer.set_res(i, memoryview(arr.T))

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        """Copy ``args`` into the input buffers, evaluate, return the output arrays."""
        if len(args) != len(self.inputs):
            raise TypeError(f"{self.fn.name()} takes {len(self.inputs)} inputs, got {len(args)}")
        for dst, src in zip(self.inputs, args, strict=True):
            dst[...] = np.reshape(src, dst.shape, order="F")
        self._eval()
        if self._buffer.ret() != 0:
            raise RuntimeError(f"evaluating {self.fn.name()} failed")
        return self.outputs

