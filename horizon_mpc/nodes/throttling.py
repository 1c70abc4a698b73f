"""What the nodes' throttled warnings are keyed by (no ROS needed)."""

from __future__ import annotations

import re

__all__ = ["problem_kind"]

# numbers, quoted names and bracketed lists: the values of a message, not its kind
_VALUES = re.compile(r"'[^']*'|\"[^\"]*\"|\[[^\]]*\]|[-+]?\d+(\.\d*)?([eE][-+]?\d+)?")


def problem_kind(topic: str, text: str) -> str:
    """The throttling key of a warning about ``topic``: the topic and the text without its
    values, so that one problem does not hide another of the same topic within a throttle
    period (a NaN position after a missing joint), while the same problem with other values
    (other joints, other numbers) stays throttled as one."""
    return f"{topic}:" + _VALUES.sub("#", text)
