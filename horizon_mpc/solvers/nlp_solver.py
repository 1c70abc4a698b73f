"""Common part of the solvers that work on the transcribed NLP (``ipopt``, ``gnsqp``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from horizon_mpc.problem import Problem
from horizon_mpc.problem.transcription import Transcription
from horizon_mpc.solvers.base import Solver

__all__ = ["NlpSolver"]


class NlpSolver(Solver):
    """A solver on a :class:`Transcription` that keeps bound and constraint multipliers.

    Builds ``self.transcription`` with the options ``sym`` and ``constraint_rows`` (which
    subclasses declare in their DEFAULTS); subclasses fill ``w`` (nw), ``lam_x`` (nw) and
    ``lam_g`` (ng) after a solve; ``shift()`` moves the multipliers one node back with the
    guesses, ``reset()`` forgets them.
    """

    CHOICES = {"sym": ("SX", "MX"), "constraint_rows": ("valid", "active")}
    BUILD_ONLY = ("sym", "constraint_rows")  # they fix the NLP

    def __init__(self, prb: Problem, opts: dict[str, Any] | None = None):
        super().__init__(prb, opts)
        self.transcription = Transcription(
            prb, sym=self.opts["sym"], constraint_rows=self.opts["constraint_rows"])
        self.w: np.ndarray | None = None
        self.lam_x: np.ndarray | None = None
        self.lam_g: np.ndarray | None = None

    def shift(self) -> None:
        """Shift the guesses and parameters (``Problem.shift``), the multipliers and the
        last solution (whose collocation states warm-start the next solve)."""
        super().shift()
        tr = self.transcription
        if self.lam_x is not None:
            self.lam_x = tr.shift_vector(self.lam_x, tr.w_blocks)
            self.lam_g = tr.shift_vector(self.lam_g, tr.g_blocks)
        if self.w is not None:
            self.w = tr.shift_vector(self.w, tr.w_blocks)
            if tr.degree:  # the last interval's, repeated, belong to no interval now
                b = tr.w_blocks[3]
                self.w[b.stop - b.rows:b.stop] = np.nan

    def reset(self) -> None:
        """Forget the multipliers and the last solution: the next solve starts from zero
        multipliers and the problem's initial guesses (cold)."""
        self.lam_x = self.lam_g = self.w = None

    def _initial_w(self) -> np.ndarray:
        """The problem's initial guesses as ``w``, collocation states from the last
        solution (:meth:`Transcription.initial_w`)."""
        return self.transcription.initial_w(self.w)
