"""The settings of consolidation, with their defaults (data only: the command
line reads them without loading the solvers)."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: defaults (fractions of the body size L)
TOLERANCE = 1.0e-3
BUDGET = 5.0e-3
GAP = 0.2
REFINE = 12
#: a refinement step must lower the realizable pose error by this fraction of it ...
REFINE_GAIN = 0.02
#: ... and by this fraction of L
REFINE_FLOOR = 1.0e-5
#: the sharpest turn (radians) an extension may make at a tendon end
MAX_TURN = math.pi / 4
#: refinement candidates solved in full per round (the best screened; 0: all, unscreened)
SCREEN = 3
#: ... of those, only the ones whose predicted error is within this fraction of the error a step needs
SCREEN_MARGIN = 0.1


@dataclass(frozen=True)
class ConsolidationSettings:
    """``tolerance``: allowed cumulative rise of the realizable pose error, as a
    fraction of L (negative: keep the extracted tendons as they are); ``gap``:
    farthest two tendon ends may be apart to be joined, as a fraction of L;
    ``budget``: a realizable pose error (fraction of L) the designer accepts
    anyway - a candidate within it is kept even when the error rises by more
    than ``tolerance`` (0: no budget); ``refine``: the most trim / extend rounds
    in a row (0: no refinement); ``screen``: how many of a refinement round's
    candidates, the best by the Gauss-Newton screen, are solved in full (0: every
    one, unscreened)."""

    tolerance: float = TOLERANCE
    gap: float = GAP
    budget: float = BUDGET
    refine: int = REFINE
    screen: int = SCREEN

    @property
    def enabled(self) -> bool:
        return self.tolerance >= 0.0
