"""What ``design`` and ``extract`` are asked for beside what they work on: one
settings object each, passed whole (:class:`DesignSettings`, :class:`ExtractSettings`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..extract.checks import PLUGIN_TIMEOUT
from ..extract.metrics import MetricSettings
from ..extract.settings import BUDGET, ConsolidationSettings, FrontSettings


@dataclass(frozen=True)
class DesignSettings:
    """How a design is made and chosen.

    Args:
        solver: the linear backend ("auto", "direct", "cg", ...).
        extractors: the extractors to run (None: every installed one).
        consolidation: consolidation's settings (None: the defaults, bounded by ``budget``).
        budget: the as-built pose error accepted, a fraction of L: it picks the recommendation.
        front: the count/error front's search (beam, the finer mesh's check, the most tendons).
        min_capstan: the least worst capstan factor the recommendation accepts, a fraction.
        plugin_timeout: seconds an extractor may run (None: the default).
        png: whether design.png and front.png are drawn.
        routes_from: a prior design of the same body (its folder or design.json) whose
            front's layouts the front searches from too.
    """

    solver: str = "auto"
    extractors: tuple[str, ...] | None = None
    consolidation: ConsolidationSettings | None = None
    budget: float = BUDGET
    front: FrontSettings = FrontSettings()
    min_capstan: float = 0.0
    plugin_timeout: float | None = None
    png: bool = True
    routes_from: str | Path | None = None

    @property
    def consolidating(self) -> ConsolidationSettings:
        """Consolidation's settings: the given ones, else the defaults bounded by the budget."""
        return self.consolidation or ConsolidationSettings(budget=self.budget)


@dataclass(frozen=True)
class ExtractSettings:
    """Which extractors run on which recorded stage, and how their tendons become
    routes (``extract`` and ``compare``).

    Args:
        names: the extractors to run (None: every installed one).
        stage: the recorded stage to read (None: the last completed).
        options: per extractor name, its options as the command line gives them.
        solver: the linear backend ("recorded": the one the run used).
        metric_settings: the metrics' settings (None: the scene's friction).
        consolidation: consolidation's settings (None: the defaults).
        plugin_timeout: seconds an extractor may run.
        friction: the channels' capstan friction, in place of the scene's (None: the scene's).
        clearance: the routes' clearance, x L, in place of the scene's (None: the scene's).
        exit: where the routes leave the body, in place of the scene's (None: the scene's).
        factor_threads: the threads of every factorization, the workers' too (None: each process's).
    """

    names: tuple[str, ...] | None = None
    stage: int | None = None
    options: dict[str, dict] | None = None
    solver: str = "recorded"
    metric_settings: MetricSettings | None = None
    consolidation: ConsolidationSettings | None = None
    plugin_timeout: float = PLUGIN_TIMEOUT
    friction: float | None = None
    clearance: float | None = None
    exit: str | None = None
    factor_threads: int | None = None
