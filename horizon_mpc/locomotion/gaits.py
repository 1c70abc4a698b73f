"""Gaits and contact schedules.

A gait is periodic: foot ``i`` is in stance while its phase ``(t / period + offset_i) mod 1``
is below the duty factor. ``period = step_duration / (1 - duty_factor)`` so that
``step_duration`` is the duration of one swing. Offsets are given per foot position in
the order ``[front-left, front-right, hind-left, hind-right]`` (the order of ``feet`` in
every robot config). Sampling a gait at ``t0 + k dt`` gives the schedule of a receding
horizon that starts at ``t0``; shifting the horizon is sampling at a later ``t0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from horizon_mpc.config import did_you_mean

__all__ = ["EXPERIMENTAL_GAITS", "GAITS", "ContactSchedule", "Gait", "feet_order_error",
           "make_gait", "speed_scale", "swing_height_profile"]

#: the foot each gait offset is for, in order (front/hind, left/right)
FOOT_SLOTS = ("front left", "front right", "hind left", "hind right")
# m: standing feet closer than this to the feet's centre along x or y have no side to check
SIDE_MARGIN = 0.01


@dataclass(frozen=True)
class Gait:
    """A periodic gait (see the module docstring)."""

    name: str
    offsets: tuple[float, ...]
    duty_factor: float
    step_duration: float
    step_height: float

    @property
    def stands(self) -> bool:
        """Whether the gait never lifts a foot (``stand``, or a duty factor of 1)."""
        return self.duty_factor >= 1.0

    @property
    def period(self) -> float:
        """Duration of one gait cycle (s)."""
        return np.inf if self.stands else self.step_duration / (1.0 - self.duty_factor)

    def phases(self, t: np.ndarray) -> np.ndarray:
        """Phase in [0, 1) of each foot at times ``t``: shape (n_feet, len(t)), rounded to
        :data:`PHASE_DECIMALS` decimals: a node on a lift-off or a touch-down is on the same
        side of it whatever rounding its time came with (1.30 s gave 0.49999999999999972 at
        one tick and 0.5 at the next: the contact flipped between ticks on 64 of 949)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if not np.isfinite(self.period):
            return np.zeros((len(self.offsets), t.size))
        phase = t[None, :] / self.period + np.asarray(self.offsets)[:, None]
        return np.mod(np.round(phase, PHASE_DECIMALS), 1.0)

    def schedule(self, t0: float, n_nodes: int, dt: float) -> ContactSchedule:
        """Contacts and swing progress on nodes ``t0 + k dt``, k = 0..n_nodes."""
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, (int, np.integer)) \
                or n_nodes < 0 or not (math.isfinite(dt) and dt > 0) or not math.isfinite(t0):
            # (2.5 nodes gave 4, a NaN dt every foot in swing)
            raise ValueError(f"schedule: n_nodes must be an integer >= 0, dt > 0 and t0 "
                             f"finite, got {n_nodes!r}, {dt!r}, {t0!r}")
        t = t0 + dt * np.arange(n_nodes + 1)
        ph = self.phases(t)
        stance = np.ones_like(ph, bool) if self.stands else ph < self.duty_factor
        swing_progress = np.where(stance, 0.0,
                                  (ph - self.duty_factor) / max(1.0 - self.duty_factor, 1e-9))
        return ContactSchedule(stance, swing_progress, self.step_height)


#: decimals a gait phase is rounded to (1e-9 of a cycle: far below a node, far above the
#: rounding of node times)
PHASE_DECIMALS = 9


@dataclass
class ContactSchedule:
    """Per foot and node: stance flags (n_feet, N+1) and swing progress in [0, 1)."""

    stance: np.ndarray
    swing_progress: np.ndarray
    step_height: float

    def swing_height(self) -> np.ndarray:
        """Foot height above the ground on each node (0 in stance), shape (n_feet, N+1)."""
        return np.where(self.stance, 0.0,
                        swing_height_profile(self.swing_progress, self.step_height))

    def count_swings(self) -> np.ndarray:
        """Number of swing phases per foot in the schedule, shape (n_feet,)."""
        sw = ~self.stance
        starts = sw[:, 1:] & ~sw[:, :-1]
        return starts.sum(axis=1) + sw[:, 0]


def swing_height_profile(s: np.ndarray, height: float) -> np.ndarray:
    """Height ``16 h s^2 (1 - s)^2``: 0 with zero slope at lift-off and touch-down, h at 1/2."""
    s = np.clip(s, 0.0, 1.0)
    return 16.0 * height * s * s * (1.0 - s) ** 2


# name -> (offsets [FL, FR, HL, HR], duty factor)
GAITS: dict[str, tuple[tuple[float, ...], float]] = {
    "stand": ((0.0, 0.0, 0.0, 0.0), 1.0),
    "trot": ((0.0, 0.5, 0.5, 0.0), 0.5),
    "walk": ((0.0, 0.5, 0.75, 0.25), 0.75),
    "pace": ((0.0, 0.5, 0.0, 0.5), 0.5),
    "bound": ((0.0, 0.0, 0.5, 0.5), 0.5),
    "pronk": ((0.0, 0.0, 0.0, 0.0), 0.5),
}


#: gaits the walking MPC offers but which do not walk (session 20, lockstep closed loop, 0.25
#: m/s forward): what was seen, for the warnings of the node and the docs
EXPERIMENTAL_GAITS: dict[str, str] = {
    "pace": "go2 and a1 fell at 1.2 s, anymal_c at 3.0 s (solo12 paced)",
    "bound": "go2, a1, solo12 and anymal_c fell within 0.4 s",
    "pronk": "go2 fell at 1.6 s, solo12 at 3.5 s (anymal_c pronked)",
}


def make_gait(name: str, step_duration: float = 0.3, step_height: float = 0.08,
              duty_factor: float | None = None, n_feet: int = 4) -> Gait:
    """A gait from the library (``stand``, ``trot``, ``walk``, ``pace``, ``bound``, ``pronk``);
    ``duty_factor`` None: the gait's own (:data:`GAITS`: walk 0.75, the others 0.5).

    The offsets are those of four feet in the order front left, front right, hind left,
    hind right; another number of feet repeats them every four (foot ``i`` gets foot
    ``i % 4``'s).

    Raises:
        ValueError: unknown name, a duration that is not a finite number > 0, a step height
            that is not a finite number >= 0, a duty factor outside (0, 1] (also for
            ``stand``, which ignores it), fewer than one foot.
    """
    if not isinstance(name, str) or name not in GAITS:
        raise ValueError(f"unknown gait {name!r}{did_you_mean(name, list(GAITS))}; gaits are: "
                         f"{', '.join(GAITS)}")
    for what, value in (("step_duration", step_duration), ("step_height", step_height),
                        ("duty factor", duty_factor)):
        if value is not None and (isinstance(value, bool)
                                  or not isinstance(value, (int, float, np.number))):
            raise ValueError(f"{what} must be a number, got {value!r}")
    if duty_factor is not None and not 0.0 < duty_factor <= 1.0:
        raise ValueError(f"duty factor must be in (0, 1], got {duty_factor}")
    offsets, beta = GAITS[name]
    beta = beta if duty_factor is None or name == "stand" else float(duty_factor)
    if not (np.isfinite(step_duration) and step_duration > 0):
        raise ValueError(f"step_duration must be a finite number > 0, got {step_duration}")
    if not (np.isfinite(step_height) and step_height >= 0):
        raise ValueError(f"step_height must be a finite number >= 0, got {step_height}")
    if isinstance(n_feet, bool) or not isinstance(n_feet, (int, np.integer)) or n_feet < 1:
        raise ValueError(f"a gait needs at least one foot, got n_feet {n_feet!r}")
    if n_feet != 4:
        offsets = tuple(offsets[i % 4] for i in range(n_feet))
    return Gait(name, tuple(offsets), beta, float(step_duration), float(step_height))


def speed_scale(gait: Gait, reference: Gait) -> float:
    """The share of velocity limits set for ``reference`` (a robot config's gait) that
    ``gait`` may be commanded: ``min(1, reference stance / gait stance)``, a stance being
    ``duty_factor * period``, the time a foot stays down per cycle. A foot's stride is bounded
    by its reach, about the same in any gait, and the body travels it while the foot is down,
    so a longer stance walks slower: the walk (duty 0.75, a cycle twice the trot's at one
    step duration: 0.9 s of stance against 0.3 s) gets a third of the trot's limits. At the
    trot's limits it fell (anymal_c at 0.4-0.5 m/s forward, a1 at 0.4 m/s sideways; go2
    reached 60-70 % of them). 1 for a gait that stands (it walks no command) or a reference
    that stands."""
    if gait.stands or reference.stands:
        return 1.0
    stance = gait.duty_factor * gait.period
    return min(1.0, reference.duty_factor * reference.period / stance)


def feet_order_error(feet: list[str], xy: np.ndarray) -> str | None:
    """Why four ``feet`` standing at ``xy`` (n_feet, 2; base frame, x forward, y left) are
    not in the gait order of :data:`FOOT_SLOTS`, naming the order that is; None when they
    are, or when the order cannot be told (not four feet, a foot within ``SIDE_MARGIN`` of
    the feet's centre along x or y). The offsets of every gait are given in that order: a
    config listing go2's feet as FL, RR, FR, RL made its trot a pace, and it fell."""
    xy = np.asarray(xy, dtype=float)
    if len(feet) != 4 or xy.shape != (4, 2):
        return None
    d = xy - xy.mean(axis=0)
    if np.any(np.abs(d) < SIDE_MARGIN):
        return None
    slots = [2 * int(dx < 0) + int(dy < 0) for dx, dy in d]  # index into FOOT_SLOTS
    if slots == [0, 1, 2, 3]:
        return None
    where = ", ".join(f"{foot} {FOOT_SLOTS[k]}" for foot, k in zip(feet, slots, strict=True))
    text = (f"feet {list(feet)} are not in the gait order {', '.join(FOOT_SLOTS)} (standing, "
            f"in the base frame, x forward and y left as REP 103 has it: {where}); the gaits' "
            "offsets are given in that order")
    if sorted(slots) == [0, 1, 2, 3]:
        text += f": list them as {[feet[slots.index(k)] for k in range(4)]}"
    return text
