"""``pybullet`` imported without its banner.

Importing pybullet writes ``pybullet build time: ...`` on standard error from C, which
landed in every ``sim_node`` start (``--help`` included) and in every log of a program that
simulates. :func:`import_pybullet` imports it with file descriptor 2 pointed at the null
device (C's stderr is unbuffered: nothing is left to be written after it is restored). Where
descriptor 2 cannot be redirected (closed, an unusual platform) pybullet is imported plainly.

:func:`c_stdout_captured` catches what pybullet's C code prints on standard output (its URDF
importer's ``b3Warning`` lines) for the caller to log or report.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import ModuleType

__all__ = ["Captured", "c_stdout_captured", "import_pybullet"]


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


@dataclass
class Captured:
    """What :func:`c_stdout_captured` caught (``text``: filled when the block ends)."""

    text: str = ""


def _flush_c_stdio() -> None:
    try:
        ctypes.CDLL(None).fflush(None)  # every C stdio stream: what is buffered goes now
    except (OSError, AttributeError):
        pass


@contextmanager
def c_stdout_captured() -> Iterator[Captured]:
    """File descriptor 1 pointed at a temporary file for the block, C's buffered output
    flushed into it before it is restored; yields a :class:`Captured` whose ``text`` is
    what was written. Where descriptor 1 cannot be redirected, nothing is captured."""
    out = Captured()
    try:
        sys.stdout.flush()
        _flush_c_stdio()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # fd 1 closed, stdout replaced or closed
        yield out
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 1)
        try:
            yield out
        finally:
            _flush_c_stdio()
            os.dup2(saved, 1)
            os.close(saved)
            tmp.seek(0)
            out.text = tmp.read().decode("utf-8", "replace")
