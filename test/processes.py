"""Process helpers shared by the tests that start child processes."""

import os


def process_exists(pid: int) -> bool:
    """Whether a process ``pid`` exists (a zombie counts: it is not reaped yet)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True
