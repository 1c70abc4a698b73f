"""``pybullet`` imported without its banner.

Importing pybullet writes ``pybullet build time: ...`` on standard error from C, which
landed in every ``sim_node`` start (``--help`` included) and in every log of a program that
simulates. :func:`import_pybullet` imports it with file descriptor 2 pointed at the null
device (C's stderr is unbuffered: nothing is left to be written after it is restored). Where
descriptor 2 cannot be redirected (closed, an unusual platform) pybullet is imported plainly.
"""

from __future__ import annotations

import os
import sys
from types import ModuleType

__all__ = ["import_pybullet"]


def import_pybullet() -> ModuleType:
    """The ``pybullet`` module, imported (once) without its build-time banner."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # fd 2 closed, stderr replaced or closed
        import pybullet

        return pybullet
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 2)
        finally:
            os.close(devnull)
        import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    return pybullet
