"""Build script of the horizon_mpc ament_python package (colcon, ``setup.py install`` and pip).

Three install routes must all give ``ros2 run horizon_mpc <exe>`` an executable file at
``<prefix>/lib/horizon_mpc/<exe>`` and the ament index marker
``<prefix>/share/ament_index/resource_index/packages/horizon_mpc``:

* colcon / ``setup.py install``: setup.cfg sends the console scripts to ``lib/horizon_mpc``;
* ``pip install .``: pip ignores setup.cfg script dirs (console scripts go to ``<venv>/bin``),
  so the launcher files in ``scripts/`` are also installed there as data files;
* ``pip install -e .``: pip installs no data files at all; run
  ``python setup.py install_data -d "$VIRTUAL_ENV"`` afterwards (``make setup`` does).

The Python dependencies are declared here and nowhere else (the Makefile installs
``.[test]``); package.xml carries the matching rosdep keys for colcon users.
"""

from glob import glob
from pathlib import Path
from xml.etree import ElementTree

from setuptools import find_packages, setup

PACKAGE = "horizon_mpc"

# Executable name -> "module:function". Used for the console scripts and, through the
# launcher files scripts/<name> (checked against this dict by test/test_package.py),
# for the data files installed into lib/horizon_mpc.
EXECUTABLES = {
    "mpc_node": "horizon_mpc.nodes.launcher:mpc_node",
    "sim_node": "horizon_mpc.nodes.launcher:sim_node",
    "closed_loop": "horizon_mpc.nodes.launcher:closed_loop",
    "motion": "horizon_mpc.nodes.launcher:motion",
}

INSTALL_REQUIRES = [
    "casadi>=3.8",
    "pin>=4.1",
    "example-robot-data>=6.0",
    "pybullet>=3.2.7",
    "numpy>=1.26",
    "scipy>=1.11",
    "matplotlib>=3.8",
    "pyyaml>=6.0",
    "pillow>=10.0",
    # ROS 2 Jazzy from PyPI wheels (rclpy + the message packages). A colcon build does not
    # install these: there, package.xml and rosdep provide the ROS packages.
    "ros-jazzy-rclpy[fastrtps]>=7.1",
    "ros-jazzy-common-interfaces>=5.3",
]

EXTRAS_REQUIRE = {
    # setuptools: `setup.py install_data` in the editable dev flow, and the install tests
    # (bdist_wheel is part of setuptools since 70.1).
    "test": ["pytest>=8.0", "hypothesis>=6.100", "ruff>=0.6", "setuptools>=70.1"],
}


def _version() -> str:
    """The version written in package.xml (the one source of the version number)."""
    root = ElementTree.parse(Path(__file__).resolve().parent / "package.xml").getroot()
    return root.findtext("version").strip()


setup(
    name=PACKAGE,
    version=_version(),
    description="Receding-horizon MPC for legged robots (CasADi, Pinocchio, ROS 2 Jazzy)",
    license="Apache-2.0",
    maintainer="horizon_mpc maintainers",
    maintainer_email="maintainers@horizon-mpc.dev",
    python_requires=">=3.11",
    packages=find_packages(exclude=["test", "test.*", "bench", "bench.*"]),
    # C source compiled at run time (horizon_mpc.solvers.ilqr.riccati_c)
    package_data={"horizon_mpc.solvers.ilqr": ["riccati.c", "riccati.h", "evaluation.c",
                                               "lq_step.c"]},
    # Paths are relative to this file's folder (colcon and pip run setup.py from there).
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", sorted(glob("config/*.yaml"))),
        (f"share/{PACKAGE}/config/motions", sorted(glob("config/motions/*.yaml"))),
        (f"share/{PACKAGE}/config/commands", sorted(glob("config/commands/*.yaml"))),
        (f"share/{PACKAGE}/launch", sorted(glob("launch/*.py") + glob("launch/*.xml")
                                           + glob("launch/*.yaml"))),
        (f"share/{PACKAGE}/doc", sorted(glob("doc/*.md"))),  # what --help texts refer to
        (f"lib/{PACKAGE}", [f"scripts/{name}" for name in EXECUTABLES]),
    ],
    install_requires=INSTALL_REQUIRES,
    extras_require=EXTRAS_REQUIRE,
    entry_points={
        "console_scripts": [f"{name} = {target}" for name, target in EXECUTABLES.items()],
    },
    zip_safe=False,
)
