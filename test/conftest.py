"""Session-wide test environment, set when pytest imports this file (before any test module
imports rclpy) and inherited by every subprocess a test starts:

* network hygiene: DDS discovery stays on 127.0.0.1 (``ROS_AUTOMATIC_DISCOVERY_RANGE``) in a
  ROS domain private to this test session (``ROS_DOMAIN_ID`` derived from the pid), so
  parallel sessions on one machine do not see each other and nothing leaves the host;
* the interpreter's prefix is an ament prefix (``AMENT_PREFIX_PATH``) and its ``bin`` comes
  first on ``PATH``, as in an activated venv, so ``ros2 run``-style lookups behave as they
  do after ``make setup``;
* matplotlib draws off-screen; hypothesis is derandomised (same examples every run).
"""

from __future__ import annotations

import os
import sys

# Domain ids whose DDS ports are valid on Linux; 0 is everybody's default, so it is left out.
VALID_DOMAIN_IDS = [*range(1, 102), *range(215, 233)]


def private_domain_id(pid: int) -> int:
    """The ``ROS_DOMAIN_ID`` for the process ``pid``: one of ``VALID_DOMAIN_IDS``."""
    return VALID_DOMAIN_IDS[pid % len(VALID_DOMAIN_IDS)]


def _prepend_path(var: str, entry: str) -> None:
    parts = [p for p in os.environ.get(var, "").split(os.pathsep) if p]
    if entry not in parts:
        os.environ[var] = os.pathsep.join([entry, *parts])


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(private_domain_id(os.getpid()))
_prepend_path("AMENT_PREFIX_PATH", sys.prefix)
_prepend_path("PATH", os.path.dirname(sys.executable))
os.environ.setdefault("MPLBACKEND", "Agg")

try:
    from hypothesis import settings
except ImportError:  # hypothesis is a test extra; tests that need it import it themselves
    pass
else:
    settings.register_profile("horizon_mpc", derandomize=True, deadline=None, database=None)
    settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "horizon_mpc"))
