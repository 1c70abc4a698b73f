"""Finite contact timelines for the offline motions (leap, turn).

A timeline gives, per contact frame, the time intervals ``(t_lift, t_touch)`` (s) it is in
the air. Sampled on nodes ``k dt`` it becomes a
:class:`~horizon_mpc.locomotion.gaits.ContactSchedule`: node ``k`` is a swing node when
``t_lift < k dt < t_touch``; the lift-off node (``round(t_lift / dt)``) and the touch-down
node (``round(t_touch / dt)``) are stance nodes, and the swing progress is
``s = (k - k_lift) / (k_touch - k_lift)``, except over an odd number of intervals, where
the two nodes around mid-swing both get ``s = 1/2``: the apex is on the nodes (over 3
intervals it was 0.79 of the step height, over 5 0.92). The receding-horizon walk uses the
periodic gaits of :mod:`horizon_mpc.locomotion.gaits` instead.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from horizon_mpc.locomotion.gaits import GAITS, ContactSchedule

__all__ = ["crawl_order", "lift_off_nodes", "timeline_schedule", "touchdown_nodes"]

log = logging.getLogger(__name__)


def timeline_schedule(swings: Sequence[Sequence[tuple[float, float]]], n_nodes: int, dt: float,
                      step_height: float = 0.0) -> ContactSchedule:
    """Sample per-foot swing intervals on nodes ``0..n_nodes`` (a time between two nodes is
    taken at the nearest one, ties to the even node, with a warning).

    Args:
        swings: per foot, a list of ``(t_lift, t_touch)`` intervals (s), in time order.
        n_nodes: number of intervals N of the horizon.
        dt: node spacing (s).
        step_height: swing apex height (m) of the schedule's swing profile.

    Returns:
        The schedule: ``stance`` (n_feet, N+1) booleans, ``swing_progress`` in [0, 1).

    Raises:
        ValueError: an interval shorter than two nodes, overlapping intervals, or an
            interval outside the horizon.
    """
    off_grid = sorted({t for intervals in swings for pair in intervals for t in pair
                       if abs(t / dt - round(t / dt)) > 1e-6})
    if off_grid:  # the leap's push of 0.25 s was 0.24, its flight 0.16, without a word
        log.warning("contact times %s s are not on the %g s node grid: taken as %s s", off_grid,
                    dt, [round(round(t / dt) * dt, 9) for t in off_grid])
    n_feet = len(swings)
    stance = np.ones((n_feet, n_nodes + 1), bool)
    progress = np.zeros((n_feet, n_nodes + 1))
    for i, intervals in enumerate(swings):
        last_touch = -1
        for t_lift, t_touch in intervals:
            k0, k1 = int(round(t_lift / dt)), int(round(t_touch / dt))
            if k1 - k0 < 2:
                raise ValueError(f"foot {i}: swing ({t_lift}, {t_touch}) s spans fewer than "
                                 f"two intervals of {dt} s")
            if k0 < 0 or k1 > n_nodes:
                raise ValueError(f"foot {i}: swing ({t_lift}, {t_touch}) s leaves the horizon "
                                 f"[0, {n_nodes * dt:.3f}] s")
            if k0 < last_touch:
                raise ValueError(f"foot {i}: swing ({t_lift}, {t_touch}) s overlaps the "
                                 "previous one")
            k = np.arange(k0 + 1, k1)
            stance[i, k] = False
            progress[i, k] = (k - k0) / (k1 - k0)
            if (k1 - k0) % 2:  # no node at mid-swing: the two middle nodes reach the apex
                mid = (k0 + k1) // 2
                progress[i, mid:mid + 2] = 0.5
            last_touch = k1
    return ContactSchedule(stance, progress, float(step_height))


def touchdown_nodes(stance: np.ndarray) -> list[np.ndarray]:
    """Per foot, the stance nodes that follow a swing node (the foot lands there)."""
    st = np.asarray(stance, bool)
    return [np.flatnonzero(row[1:] & ~row[:-1]) + 1 for row in st]


def lift_off_nodes(stance: np.ndarray) -> list[np.ndarray]:
    """Per foot, the last stance node before each swing (the foot leaves the ground there)."""
    st = np.asarray(stance, bool)
    return [np.flatnonzero(row[:-1] & ~row[1:]) for row in st]


def crawl_order(n_feet: int = 4) -> list[int]:
    """Feet in the order the library's ``walk`` gait lifts them (one at a time).

    Foot ``i`` lifts when its phase reaches the duty factor, at ``(beta - offset_i) mod 1``
    of the cycle; for ``[FL, FR, HL, HR]`` that is HL, FR, HR, FL.
    """
    offsets, beta = GAITS["walk"]
    lift = [((beta - offsets[i % 4]) % 1.0) for i in range(n_feet)]
    return [int(i) for i in np.argsort(lift, kind="stable")]
