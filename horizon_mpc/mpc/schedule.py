"""When to walk: the gait scheduler of the walking MPC.

Walking starts when a non-zero command arrives; when the command returns to zero, every
swing that has begun is finished and the feet then stay down (``stand_when_idle``).
Times are absolute (s); the gait's phase is counted from the moment walking started.

A new gait while walking (:meth:`GaitScheduler.set_gait`) never makes the contacts jump: a
new step duration or height keeps the cycle's phase (same feet in the air, at the same
fraction of their swing); another gait or duty factor, ``stand``, or any change while a
stop is in progress is taken once the swings in progress have ended (a stop), and walking
resumes with it. Swapping the gait under a running phase
put feet that were 5 cm up into stance and lifted the standing ones (go2 fell).
"""

from __future__ import annotations

import numpy as np

from horizon_mpc.locomotion.gaits import ContactSchedule, Gait

__all__ = ["GaitScheduler"]


class GaitScheduler:
    """Contact schedules of a gait that starts and stops on command."""

    def __init__(self, gait: Gait, stand_when_idle: bool = True):
        self.gait = gait
        self.stand_when_idle = stand_when_idle
        self.pending: Gait | None = None  # the gait to take once the current swings end
        self.reset(0.0)

    def reset(self, t: float) -> None:
        """Standing, no walk in progress (a pending gait is taken now)."""
        if self.pending is not None:
            self.gait, self.pending = self.pending, None
        self.t_start: float | None = None if self.stand_when_idle or self.gait.stands else t
        self.t_stop: float | None = None

    def set_gait(self, gait: Gait, t: float) -> None:
        """Walk with ``gait`` from time ``t`` on, without a jump of the contacts (see the
        module docstring)."""
        if not self.walking:
            self.gait, self.pending = gait, None
            if gait.stands:
                self.t_start = self.t_stop = None
            return
        if (self.pending is None and self.t_stop is None and not gait.stands
                and (gait.offsets, gait.duty_factor) == (self.gait.offsets,
                                                         self.gait.duty_factor)):
            # the same pattern at another pace: keep the phase of the cycle
            phase = ((t - self.t_start) / self.gait.period) % 1.0
            self.t_start = t - phase * gait.period
            self.gait = gait
            return
        # another pattern (stand included), or a stop in progress: after the swings
        self.pending = gait
        if self.t_stop is None:
            self.t_stop = t

    @property
    def walking(self) -> bool:
        """True between a start and the end of the last swing after a stop."""
        return self.t_start is not None and not self.gait.stands

    def _swings_ended(self, t: float) -> bool:
        """Whether the swings in progress at the stop (``t_stop``) have ended by ``t``."""
        return t - self.t_stop > self.gait.step_duration + 1e-9

    def command(self, t: float, moving: bool) -> None:
        """Tell the scheduler whether the robot is commanded to move at time ``t``."""
        if self.pending is not None:
            if self.t_start is not None and not self._swings_ended(t):
                return  # the old gait's swings are ending
            self.gait, self.pending = self.pending, None
            self.t_start = self.t_stop = None
        if self.gait.stands:
            return
        if not self.stand_when_idle:
            if self.t_stop is not None:
                # stepping in place asked during a stop: the stop ends first, then the
                # gait starts afresh (t_stop was never cleared: every swing stayed stance
                # for good, while walking; go2 pushed along on planted feet, then fell)
                if not self._swings_ended(t):
                    return
                self.t_start = self.t_stop = None
            if self.t_start is None:
                self.t_start = t
            return
        if moving:
            if self.t_start is None:
                self.t_start = t
            self.t_stop = None
        elif self.t_start is not None and self.t_stop is None:
            self.t_stop = t
        if self.t_stop is not None and self._swings_ended(t):
            self.t_start = self.t_stop = None

    def schedule(self, t0: float, n_nodes: int, dt: float) -> ContactSchedule:
        """The contact schedule on nodes ``t0 + k dt``, k = 0..n_nodes."""
        g = self.gait
        n_feet = len(g.offsets)
        if self.t_start is None or g.stands:
            return ContactSchedule(np.ones((n_feet, n_nodes + 1), bool),
                                   np.zeros((n_feet, n_nodes + 1)), g.step_height)
        sched = g.schedule(t0 - self.t_start, n_nodes, dt)
        if self.t_stop is not None:
            t = t0 + dt * np.arange(n_nodes + 1)
            lift_off = t[None, :] - sched.swing_progress * g.step_duration
            late = (~sched.stance) & (lift_off > self.t_stop + 1e-9)
            sched.stance = sched.stance | late
            sched.swing_progress = np.where(late, 0.0, sched.swing_progress)
        return sched
