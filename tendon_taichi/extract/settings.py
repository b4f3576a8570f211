"""The settings of consolidation, with their defaults (data only: the command
line reads them without loading the solvers)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

#: defaults (fractions of the body size L)
TOLERANCE = 1.0e-3
BUDGET = 5.0e-3
GAP = 0.2
#: rounds of route optimization (each at most RouteSettings.iterations SLSQP iterations)
REFINE = 2
#: drop and join candidates solved in full per round (the best screened; 0: all, unscreened)
SCREEN = 4
#: layouts kept per tendon count by the count/error front's beam search
BEAM = 3
#: the count/error front's settings as ``design`` takes them: ``beam`` (above),
#: ``converge``, whether each entry is re-solved on the next finer mesh, and ``coarse``,
#: whether a design above level 1 searches from the next coarser level's front too
FRONT_DEFAULTS = {"beam": BEAM, "converge": True, "coarse": True}


def front_id(front: dict) -> dict:
    """What of the front's settings ``front`` goes into a case's id: those that
    differ from :data:`FRONT_DEFAULTS`, as ``{"front": {...}}``, or nothing, so that
    cases run before these settings existed keep their ids."""
    changed = {k: v for k, v in front.items() if v != FRONT_DEFAULTS[k]}
    return {"front": changed} if changed else {}


@dataclass(frozen=True)
class ConsolidationSettings:
    """``tolerance``: allowed cumulative rise of the as-built pose error, as a
    fraction of L (negative: keep the extracted tendons' routes as they are);
    ``gap``: farthest two route ends may be apart to be joined, as a fraction of
    L; ``budget``: an as-built pose error (fraction of L) the designer accepts
    anyway - a candidate within it is kept even when the error rises by more
    than ``tolerance`` (0: no budget); ``refine``: the most rounds of route
    optimization (0: the fitted routes as they are); ``screen``: how many of a
    round's drop and join candidates, the best by the Gauss-Newton screen, are
    solved in full (0: every one, unscreened)."""

    tolerance: float = TOLERANCE
    gap: float = GAP
    budget: float = BUDGET
    refine: int = REFINE
    screen: int = SCREEN

    @property
    def enabled(self) -> bool:
        return self.tolerance >= 0.0


@dataclass(frozen=True)
class FrontSettings:
    """The count/error front's search: ``beam``, the layouts its beam search keeps
    per tendon count; ``converge``, whether each entry is solved again on the next
    finer mesh; ``max_tendons``, the most tendons a layout may have (None: no limit);
    ``coarse``, whether a design above level 1 first designs at the level below and
    searches from that front's layouts too (where no prior design is given)."""

    beam: int = BEAM
    converge: bool = True
    max_tendons: int | None = None
    coarse: bool = True

    def table(self) -> dict:
        """The ``[front]`` table's settings (:data:`FRONT_DEFAULTS`' keys) as a dict."""
        return {k: v for k, v in asdict(self).items() if k in FRONT_DEFAULTS}
