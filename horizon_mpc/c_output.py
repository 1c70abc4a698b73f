"""What C code writes on a standard file descriptor, captured (no ROS, no numpy).

Libraries written in C (Pinocchio's URDF parser on stderr, pybullet's importer on stdout)
print straight to file descriptors 1 and 2, past Python's ``sys.stdout``/``sys.stderr``: the
only way to read it, or to keep it off a program's output, is to point the descriptor
elsewhere for a while.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

__all__ = ["Captured", "c_output_captured"]


@dataclass
class Captured:
    """What :func:`c_output_captured` caught (``text``: filled when its block ends)."""

    text: str = ""


def _flush_c_stdio() -> None:
    try:
        ctypes.CDLL(None).fflush(None)  # every C stdio stream: what is buffered goes now
    except (OSError, AttributeError):
        pass


@contextmanager
def c_output_captured(fd: int) -> Iterator[Captured]:
    """File descriptor ``fd`` (1 or 2) pointed at a temporary file for the block, C's
    buffered output flushed into it before it is restored (also when the block raises);
    yields a :class:`Captured` whose ``text`` is what was written. Where the descriptor
    cannot be redirected (closed, an embedded interpreter), nothing is captured."""
    out = Captured()
    stream = sys.stdout if fd == 1 else sys.stderr
    try:
        stream.flush()
        _flush_c_stdio()
        saved = os.dup(fd)
    except (OSError, ValueError, AttributeError):  # fd closed, stream replaced or closed
        yield out
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), fd)
        try:
            yield out
        finally:
            _flush_c_stdio()
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            out.text = tmp.read().decode("utf-8", "replace")
