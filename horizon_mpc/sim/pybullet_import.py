"""``pybullet`` imported without its banner.

Importing pybullet writes ``pybullet build time: ...`` on standard error from C, which
landed in every ``sim_node`` start (``--help`` included) and in every log of a program that
simulates. :func:`import_pybullet` imports it with file descriptor 2 captured and drops what
was written (:func:`horizon_mpc.c_output.c_output_captured`). Where descriptor 2 cannot be
redirected (closed, an unusual platform) pybullet is imported plainly.
"""

from __future__ import annotations

import sys
from types import ModuleType

from horizon_mpc.c_output import c_output_captured

__all__ = ["import_pybullet"]


def import_pybullet() -> ModuleType:
    """The ``pybullet`` module, imported (once) without its build-time banner."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    with c_output_captured(2):  # the banner, dropped
        import pybullet
    return pybullet
