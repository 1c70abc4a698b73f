"""The package foundation: what `ros2 run`, colcon, pip and the Makefile rely on.

The ament tests inspect the interpreter running pytest: ``make setup`` installs horizon_mpc
into ``.venv`` (editable) and copies the data files (ament index marker, package.xml,
configs, launchers) into the venv prefix. The install tests build from a copy of the source
tree into temporary prefixes, offline.
"""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from xml.etree import ElementTree

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "horizon_mpc"
SOURCE_ITEMS = ["setup.py", "setup.cfg", "pyproject.toml", "package.xml", "Makefile",
                "LICENSE", "resource", "scripts", "config", "launch", "doc", PACKAGE]


def _setup_py_constant(name: str):
    """The literal value assigned to ``name`` at the top level of setup.py (not executed)."""
    tree = ast.parse((ROOT / "setup.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == name for t in node.targets
        ):
            return ast.literal_eval(node.value)
    raise AssertionError(f"setup.py assigns no literal {name}")


EXECUTABLES: dict[str, str] = _setup_py_constant("EXECUTABLES")


def _copy_source(dest: Path) -> Path:
    """Copy the files a build needs into ``dest`` (builds write build/ and egg-info there)."""
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    dest.mkdir(parents=True)
    for item in SOURCE_ITEMS:
        src = ROOT / item
        if src.is_dir():
            shutil.copytree(src, dest / item, ignore=ignore)
        else:
            shutil.copy2(src, dest / item)
    return dest


def _get_package_prefix(prefixes: list[str]) -> Path:
    from ament_index_python.packages import get_package_prefix

    old = os.environ.get("AMENT_PREFIX_PATH")
    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(prefixes)
    try:
        return Path(get_package_prefix(PACKAGE))
    finally:
        if old is None:
            del os.environ["AMENT_PREFIX_PATH"]
        else:
            os.environ["AMENT_PREFIX_PATH"] = old


# --------------------------------------------------------------------------------------------
# The library stays ROS-free

_IMPORT_PROBE = """
import importlib, json, pkgutil, sys

EXCLUDED = ("horizon_mpc.nodes", "horizon_mpc.closed_loop")  # these bring ROS in on purpose
report = {"imported": [], "errors": {}, "rclpy_first_seen_after": None}


def visit(name):
    try:
        module = importlib.import_module(name)
    except Exception as exc:  # report every broken module, keep walking
        report["errors"][name] = f"{type(exc).__name__}: {exc}"
        return
    report["imported"].append(name)
    if "rclpy" in sys.modules and report["rclpy_first_seen_after"] is None:
        report["rclpy_first_seen_after"] = name
    for info in pkgutil.iter_modules(getattr(module, "__path__", []), name + "."):
        if not any(info.name == e or info.name.startswith(e + ".") for e in EXCLUDED):
            visit(info.name)


visit("horizon_mpc")
with open(sys.argv[1], "w") as fh:
    json.dump(report, fh)
"""


@pytest.fixture(scope="module")
def import_report(tmp_path_factory) -> dict:
    """Import every library module in a fresh interpreter and report what happened."""
    out = tmp_path_factory.mktemp("imports") / "report.json"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]))
    proc = subprocess.run([sys.executable, "-c", _IMPORT_PROBE, str(out)], env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(out.read_text())


def test_walk_covers_the_library_modules(import_report):
    imported = set(import_report["imported"]) | set(import_report["errors"])
    assert {"horizon_mpc", "horizon_mpc.config", "horizon_mpc.robots"} <= imported
    assert not any(name.startswith("horizon_mpc.nodes") for name in imported)


def test_every_library_module_imports(import_report):
    assert import_report["errors"] == {}


def test_importing_the_library_does_not_import_rclpy(import_report):
    culprit = import_report["rclpy_first_seen_after"]
    assert culprit is None, f"rclpy was imported while importing {culprit}"


def test_the_package_imports_its_api_on_first_use():
    """`import horizon_mpc` alone no longer imports CasADi (a node's entry point takes the
    signals first); its API and subpackages are there as before."""
    code = ("import sys, horizon_mpc as h\n"
            "assert 'casadi' not in sys.modules\n"
            "assert h.Problem.__name__ == 'Problem' and callable(h.make_solver)\n"
            "assert h.solvers.make_solver is h.make_solver and h.problem.Problem is h.Problem\n"
            "assert 'rclpy' not in sys.modules\n"
            "try:\n    h.no_such_thing\nexcept AttributeError:\n    print('ok')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and proc.stdout == "ok\n", proc.stderr


# --------------------------------------------------------------------------------------------
# Executables: one dict in setup.py, one launcher file each

def test_the_license_declared_is_the_license_shipped():
    """package.xml and setup.py declare Apache-2.0; no license text was in the repository
    (nor in the sdist or wheel, which take LICENSE by setuptools' default)."""
    root = ElementTree.parse(ROOT / "package.xml").getroot()
    assert root.findtext("license").strip() == "Apache-2.0"
    assert 'license="Apache-2.0"' in (ROOT / "setup.py").read_text()
    text = (ROOT / "LICENSE").read_text(encoding="utf-8")
    assert "Apache License" in text and "Version 2.0, January 2004" in text


def test_scripts_folder_holds_exactly_one_launcher_per_executable():
    assert sorted(p.name for p in (ROOT / "scripts").iterdir()) == sorted(EXECUTABLES)


@pytest.mark.parametrize("exe", sorted(EXECUTABLES))
def test_launcher_imports_and_calls_the_declared_main(exe):
    script = ROOT / "scripts" / exe
    text = script.read_text(encoding="utf-8")
    module, func = EXECUTABLES[exe].split(":")
    assert text.startswith("#!/bin/sh\n")  # its shell part picks the interpreter
    imports = [(n.module, [a.name for a in n.names])
               for n in ast.walk(ast.parse(text)) if isinstance(n, ast.ImportFrom)]
    assert imports == [(module, [func])]
    assert f"sys.exit({func}())" in text  # the exit code of main() is the process's


@pytest.mark.parametrize("exe", sorted(EXECUTABLES))
def test_launcher_is_executable_in_the_tree_and_in_git(exe):
    script = ROOT / "scripts" / exe
    assert os.access(script, os.X_OK)
    if (ROOT / ".git").exists() and shutil.which("git"):
        staged = subprocess.run(["git", "ls-files", "-s", f"scripts/{exe}"], cwd=ROOT,
                                capture_output=True, text=True).stdout
        if staged:  # a fresh clone gets its mode from git
            assert staged.startswith("100755"), staged


_CONSOLE_SCRIPTS_PROBE = """
import importlib.metadata, json
dist = importlib.metadata.distribution("horizon_mpc")
print(json.dumps({ep.name: ep.value for ep in dist.entry_points
                  if ep.group == "console_scripts"}))
"""


def test_installed_distribution_declares_the_console_scripts(tmp_path):
    # run outside the source tree: there, its horizon_mpc.egg-info would stand in for an install
    proc = subprocess.run([sys.executable, "-c", _CONSOLE_SCRIPTS_PROBE], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"horizon_mpc is not installed (`make setup`): {proc.stderr}"
    assert json.loads(proc.stdout.splitlines()[-1]) == EXECUTABLES


# --------------------------------------------------------------------------------------------
# `ros2 run horizon_mpc <exe>` from the venv: ament index lookup, then exec of the file

@pytest.fixture(scope="module")
def venv_package_prefix() -> Path:
    from ament_index_python.packages import PackageNotFoundError

    try:
        return _get_package_prefix([sys.prefix])
    except PackageNotFoundError:
        pytest.fail(f"{PACKAGE} is not in the ament index of {sys.prefix}: run `make setup` "
                    "(or, after `pip install -e .`, `python setup.py install_data -d "
                    "\"$VIRTUAL_ENV\"`)")


def test_ament_index_finds_the_package_in_the_venv_prefix(venv_package_prefix):
    assert venv_package_prefix.resolve() == Path(sys.prefix).resolve()
    assert (venv_package_prefix / "share" / PACKAGE / "package.xml").is_file()


@pytest.mark.parametrize("exe", sorted(EXECUTABLES))
def test_ros2_run_starts_the_executable_without_an_activated_venv(exe, venv_package_prefix,
                                                                  tmp_path):
    """What `ros2 run` does: execute <prefix>/lib/horizon_mpc/<exe>, here from a neutral
    cwd with nothing of the venv in the environment (the first python3 on PATH, the
    system's, has no horizon_mpc): the launcher finds the venv's interpreter itself."""
    path = venv_package_prefix / "lib" / PACKAGE / exe
    assert path.is_file(), f"{path} missing: run `make setup`"
    assert os.access(path, os.X_OK)
    env = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", str(tmp_path)),
           **{k: v for k, v in os.environ.items() if k.startswith("ROS_")}}
    proc = subprocess.run([str(path), "--help"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, f"{exe}: {proc.stderr.strip()[-2000:]}"
    assert "usage" in proc.stdout.lower(), proc.stdout[-2000:]


def _catches(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler for ``sig`` (its SigCgt mask in /proc)."""
    status = Path(f"/proc/{pid}/status").read_text()
    caught = int(next(ln for ln in status.splitlines() if ln.startswith("SigCgt:")).split()[1],
                 16)
    return bool(caught >> (sig - 1) & 1)


@pytest.mark.parametrize("delay", [0.0, 0.01, 0.02, 0.04])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
@pytest.mark.parametrize(("exe", "args", "code"), [
    ("mpc_node", [], 0), ("sim_node", [], 0),
    ("closed_loop", ["--out", "out"], 130), ("motion", ["leap", "--out", "out"], 130)])
def test_a_signal_while_the_executable_imports_its_modules_exits_quietly(
        exe, args, code, sig, delay, venv_package_prefix, tmp_path):
    """The ~0.5 s of imports before an executable takes the signals ended a SIGTERM there
    with exit code 143 (SIGINT: a KeyboardInterrupt traceback), as `ros2 launch` stopping a
    node it just started would see; the launcher takes them first (nodes/launcher.py) and
    exits as the running executable does: 0 for a node, 130 (interrupted) for the tools.
    The signal goes ``delay`` s after the process catches SIGTERM (its /proc status; Python
    itself only catches SIGINT), before the imports end: there, numpy's C extension turned
    the handler's SystemExit into an ImportError traceback (exit 1), and the import system
    compiling a module's source (no .pyc) lost it (closed_loop walked on)."""
    path = venv_package_prefix / "lib" / PACKAGE / exe
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    proc = subprocess.Popen([str(path), *args], cwd=tmp_path, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        while not _catches(proc.pid, signal.SIGTERM):
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.001)
        time.sleep(delay)
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == code, out[-2000:]
        assert "Traceback" not in out, out[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()


def test_launcher_falls_back_to_the_python3_on_path_outside_a_venv(tmp_path):
    """A colcon or ROS install prefix has no bin/python3: the launcher runs the python3 of
    PATH (here a stub that echoes its arguments)."""
    lib = tmp_path / "install" / "lib" / PACKAGE
    lib.mkdir(parents=True)
    launcher = lib / "mpc_node"
    shutil.copy2(ROOT / "scripts" / "mpc_node", launcher)
    stub = tmp_path / "stubbin" / "python3"
    stub.parent.mkdir()
    stub.write_text('#!/bin/sh\necho "stub $*"\n')
    stub.chmod(0o755)
    proc = subprocess.run([str(launcher), "--x", "a b"], capture_output=True, text=True,
                          env={"PATH": f"{stub.parent}:/usr/bin:/bin"}, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"stub {launcher} --x a b"


# --------------------------------------------------------------------------------------------
# Installs into a fresh prefix, offline: colcon's command line and pip's

def test_colcon_style_install_puts_executables_in_lib_and_registers_the_package(tmp_path):
    src = _copy_source(tmp_path / "src")
    build, prefix = tmp_path / "build", tmp_path / "install"
    build.mkdir()
    # the command colcon runs for an ament_python package (colcon-core's python build task)
    cmd = [sys.executable, "setup.py", "egg_info", "--egg-base", str(build),
           "build", "--build-base", str(build / "build"),
           "install", "--prefix", str(prefix), "--record", str(build / "install.log"),
           "--single-version-externally-managed"]
    proc = subprocess.run(cmd, cwd=src, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for exe in EXECUTABLES:
        assert os.access(prefix / "lib" / PACKAGE / exe, os.X_OK), exe
    share = prefix / "share" / PACKAGE
    assert (share / "package.xml").is_file()
    # every config, also those of subfolders (motions, command profiles)
    assert sorted(str(p.relative_to(share / "config")) for p in (share / "config").rglob(
        "*.yaml")) == sorted(str(p.relative_to(ROOT / "config"))
                             for p in (ROOT / "config").rglob("*.yaml"))
    assert _get_package_prefix([str(prefix)]) == prefix
    # the design notes the --help texts refer to
    assert sorted(p.name for p in (share / "doc").glob("*.md")) == sorted(
        p.name for p in (ROOT / "doc").glob("*.md"))
    # the installed code finds its data through the ament index, not the source tree
    site = next(prefix.glob("lib/python3*/site-packages"))
    probe = ("import horizon_mpc, sys; from horizon_mpc.closed_loop_profile import "
             "load_profile, profile_file; from horizon_mpc.config import find_config_file; "
             "print(horizon_mpc.__file__); print(profile_file('default')); "
             "print(find_config_file('go2')); print(len(load_profile('default')))")
    env = {**os.environ, "PYTHONPATH": str(site), "AMENT_PREFIX_PATH": str(prefix)}
    out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    module, profile, config, n_segments = out.stdout.split()
    assert module.startswith(str(site))
    assert Path(profile) == share / "config" / "commands" / "default.yaml"
    assert Path(config) == share / "config" / "go2.yaml" and int(n_segments) > 0


def _venv_distributions() -> list[str]:
    """horizon_mpc's metadata folders in the running interpreter's site-packages."""
    return sorted(p.name for p in Path(sys.prefix).glob("lib/python3*/site-packages/horizon_mpc*"))


def test_pip_install_puts_launchers_in_lib_and_console_scripts_in_bin(tmp_path):
    src = _copy_source(tmp_path / "src")
    prefix = tmp_path / "prefix"
    # --ignore-installed: without it, pip uninstalls the venv's own horizon_mpc first
    cmd = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index",
           "--no-build-isolation", "--ignore-installed", "--prefix", str(prefix), str(src)]
    installed_before = _venv_distributions()
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert _venv_distributions() == installed_before
    for exe in EXECUTABLES:
        launcher = prefix / "lib" / PACKAGE / exe
        assert os.access(launcher, os.X_OK), exe  # pip keeps the data file's exec bit
        assert launcher.read_text() == (ROOT / "scripts" / exe).read_text()
        assert os.access(prefix / "bin" / exe, os.X_OK), exe
    assert _get_package_prefix([str(prefix)]) == prefix


# --------------------------------------------------------------------------------------------
# package.xml and the pip requirements

REQUIRED_ROSDEP_KEYS = {
    "rclpy", "std_msgs", "std_srvs", "sensor_msgs", "nav_msgs", "geometry_msgs",
    "trajectory_msgs", "rosgraph_msgs", "diagnostic_msgs", "rcl_interfaces",
    "builtin_interfaces", "launch", "launch_ros",
    "pinocchio", "example-robot-data", "casadi-pip", "python3-pybullet-pip",
    "python3-numpy", "python3-scipy", "python3-matplotlib", "python3-yaml", "python3-pil",
}
REQUIRED_PIP_PACKAGES = {
    "casadi", "pin", "example-robot-data", "pybullet", "numpy", "scipy", "matplotlib",
    "pyyaml", "pillow", "ros-jazzy-rclpy", "ros-jazzy-common-interfaces",
}


@pytest.fixture(scope="module")
def package_xml() -> ElementTree.Element:
    return ElementTree.parse(ROOT / "package.xml").getroot()


def test_package_xml_is_an_ament_python_package_in_format_3(package_xml):
    assert package_xml.tag == "package"
    assert package_xml.get("format") == "3"
    assert package_xml.findtext("name") == PACKAGE
    assert package_xml.findtext("export/build_type") == "ament_python"
    assert (ROOT / "resource" / PACKAGE).is_file()  # the ament index marker's source


def test_package_xml_declares_the_runtime_and_test_dependencies(package_xml):
    runtime = {e.text for tag in ("depend", "exec_depend") for e in package_xml.iter(tag)}
    assert REQUIRED_ROSDEP_KEYS <= runtime, sorted(REQUIRED_ROSDEP_KEYS - runtime)
    assert "python3-pytest" in {e.text for e in package_xml.iter("test_depend")}


def test_package_xml_has_a_real_looking_maintainer_email(package_xml):
    email = package_xml.find("maintainer").get("email")
    assert re.fullmatch(r"[\w.+-]+@[\w-]+(\.[\w-]+)+", email), email
    assert not re.search(r"\.(todo|example|invalid|test)$|@(example|todo)\.", email), email


def test_version_is_the_same_in_package_xml_and_the_python_package(package_xml):
    import horizon_mpc

    assert horizon_mpc.__version__ == package_xml.findtext("version")


def test_pip_requirements_are_declared_once_with_lower_bounds():
    requirements = _setup_py_constant("INSTALL_REQUIRES")
    names = {re.match(r"[A-Za-z0-9_.-]+", r).group(0).lower() for r in requirements}
    assert names == REQUIRED_PIP_PACKAGES
    assert all(">=" in r for r in requirements), requirements
    assert not (ROOT / "requirements.txt").exists()  # setup.py is the single source


# --------------------------------------------------------------------------------------------
# Makefile setup: pip only when its inputs change, data files only when they change

@pytest.fixture
def make_tree(tmp_path):
    if not shutil.which("make"):
        pytest.skip("make is not installed")
    tree = _copy_source(tmp_path / "tree")
    old = time.time() - 1000
    for path in tree.rglob("*"):
        os.utime(path, (old, old))
    return tree


def _make(tree: Path, *args: str) -> str:
    proc = subprocess.run(["make", "--no-print-directory", *args, f"PYTHON={sys.executable}"],
                          cwd=tree, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def _stamped_venv(tree: Path) -> Path:
    """A fake, fully set-up venv: an interpreter file and both stamps, newer than the sources."""
    venv = tree / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "python").touch()
    (venv / "lib" / "python3.11" / "site-packages" / "horizon_mpc-0.1.0.dist-info").mkdir(
        parents=True)
    now = time.time()
    for offset, var in ((-500, "DEPS_STAMP"), (-400, "DATA_STAMP")):
        stamp = tree / _make(tree, "-s", f"print-{var}", f"VENV={venv}").strip()
        stamp.touch()
        os.utime(stamp, (now + offset, now + offset))
    return venv


def test_make_setup_creates_the_venv_and_installs_on_a_fresh_clone(make_tree):
    dry_run = _make(make_tree, "-n", "setup", f"VENV={make_tree / 'venv'}")
    assert "-m venv" in dry_run
    assert "-m pip install" in dry_run
    assert "install_data" in dry_run


def test_make_setup_does_nothing_once_set_up(make_tree):
    venv = _stamped_venv(make_tree)
    dry_run = _make(make_tree, "-n", "setup", f"VENV={venv}")
    assert "pip" not in dry_run and "install_data" not in dry_run, dry_run


def test_make_setup_reinstalls_when_the_package_was_uninstalled(make_tree):
    venv = _stamped_venv(make_tree)
    shutil.rmtree(venv / "lib")
    assert "-m pip install" in _make(make_tree, "-n", "setup", f"VENV={venv}")


def test_make_setup_reruns_pip_when_setup_py_changes(make_tree):
    venv = _stamped_venv(make_tree)
    with open(make_tree / "setup.py", "a", encoding="utf-8") as fh:
        fh.write("# a new dependency would go here\n")
    assert "-m pip install" in _make(make_tree, "-n", "setup", f"VENV={venv}")


def test_make_setup_only_recopies_data_files_when_a_config_changes(make_tree):
    venv = _stamped_venv(make_tree)
    (make_tree / "config" / "go2.yaml").touch()
    dry_run = _make(make_tree, "-n", "setup", f"VENV={venv}")
    assert "install_data" in dry_run
    assert "pip install" not in dry_run


# --------------------------------------------------------------------------------------------
# Network hygiene and CI

def test_test_session_uses_a_private_ros_domain_on_localhost():
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    domain = int(os.environ["ROS_DOMAIN_ID"])
    assert domain != 0 and (1 <= domain <= 101 or 215 <= domain <= 232)


def test_makefile_keeps_dds_on_localhost_in_a_private_domain():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert "export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST" in makefile
    assert "export ROS_DOMAIN_ID" in makefile
    assert "export AMENT_PREFIX_PATH" in makefile


def test_ci_runs_the_readme_test_command():
    ci = ROOT / ".ci" / "run"
    text = ci.read_text(encoding="utf-8")
    assert os.access(ci, os.X_OK)
    assert "set -euo pipefail" in text
    assert "export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST" in text
    assert text.rstrip().splitlines()[-1] == "exec make test"
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "make test" in readme and "make demo" in readme


def test_a_signal_in_an_import_lock_callback_is_not_printed():
    """The launcher's SystemExit raised inside a callback of the import system's module
    locks cannot propagate: Python printed "Exception ignored ... SystemExit: 130" (a CI run
    of session 28). Silent once a signal was received; other unraisables still print."""
    import gc
    import weakref

    from horizon_mpc.nodes.launcher import quiet_unraisable_exit

    class Referent:
        pass

    def exiting(_ref):
        raise SystemExit(130)

    seen = []
    previous = sys.unraisablehook
    sys.unraisablehook = seen.append
    try:
        for received in ([], [2]):
            obj = Referent()
            with quiet_unraisable_exit(received):
                ref = weakref.ref(obj, exiting)
                del obj
                gc.collect()
            assert ref() is None
        assert len(seen) == 1 and isinstance(seen[0].exc_value, SystemExit)  # the [] case
    finally:
        sys.unraisablehook = previous
