"""Common part of the solvers that work on the transcribed NLP (``ipopt``, ``gnsqp``)."""

from __future__ import annotations

import numpy as np

from horizon_mpc.problem.transcription import Transcription
from horizon_mpc.solvers.base import Solver

__all__ = ["NlpSolver"]


class NlpSolver(Solver):
    """A solver on a :class:`Transcription` that keeps bound and constraint multipliers.

    Subclasses set ``self.transcription`` and fill ``lam_x`` (nw) / ``lam_g`` (ng) after a
    solve; ``shift()`` moves them one node back with the guesses, ``reset()`` forgets them.
    """

    transcription: Transcription
    lam_x: np.ndarray | None = None
    lam_g: np.ndarray | None = None

    def shift(self) -> None:
        """Shift the guesses and parameters (``Problem.shift``) and the multipliers."""
        super().shift()
        tr = self.transcription
        if self.lam_x is not None:
            self.lam_x = tr.shift_vector(self.lam_x, tr.w_blocks)
            self.lam_g = tr.shift_vector(self.lam_g, tr.g_blocks)

    def reset(self) -> None:
        """Forget the multipliers: the next solve starts from zero multipliers (cold)."""
        self.lam_x = self.lam_g = None
