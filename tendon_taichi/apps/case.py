"""One case: a scene at a level through the ``design`` pipeline - optimized
(recorded), every requested extractor on its last stage, each followed by
consolidation and route optimization, and the recommended design - in a
folder of its own. ``bench``, ``sweep``, ``planted-bench`` and the workers'
warm-up all run cases through :func:`run_case`; each turns the
:class:`~tendon_taichi.apps.design.Design` into its own figures.

:func:`start_worker` (:func:`tendon_taichi.apps.design.start_worker`, here too)
is the set-up every worker process of the task engine runs once (start
Taichi, compile the kernels by a short case)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

from ..body.scene import Scene
from ..extract.settings import BUDGET, ConsolidationSettings, FrontSettings
from ..physics import runtime
from .design import Design, design, start_worker
from .settings import DesignSettings
from .optimize import Interrupted

#: what stops a whole run of cases when a case raises it (Ctrl-C inside an in-process case)
STOP = (Interrupted,)


@dataclass(frozen=True)
class CaseSettings:
    """How a case is designed: with the linear ``solver`` and the ``extractors``
    (None: every installed one), each followed by ``consolidation`` (None: the
    defaults with ``budget``); ``budget`` (fraction of L) also picks the
    recommendation; ``front``, the count/error front's search; ``png`` draws the
    pictures; ``routes_from``, a prior design whose front the front searches from
    too. Pickled whole to the task that runs the case."""

    solver: str = "auto"
    extractors: tuple[str, ...] | None = None
    consolidation: ConsolidationSettings | None = None
    budget: float = BUDGET
    front: FrontSettings = FrontSettings()
    png: bool = False
    routes_from: str | None = None


def run_case(scene: Scene, level: int, out: str | Path, settings: CaseSettings = CaseSettings()) -> Design:
    """The design of ``scene`` at ``level`` into the folder ``out`` (``run.rrd``,
    ``run.npz``, ``design.json``, ``design.svg``; the pictures with ``settings.png``),
    designed as ``settings`` says."""
    s = settings
    return design(scene, level, out, DesignSettings(s.solver, s.extractors, s.consolidation, s.budget, s.front,
                                                    png=s.png, routes_from=s.routes_from))


def worker_setup(warm: bool = True):
    """The ``setup`` to hand the task engine: :func:`start_worker` on this
    process's Taichi arch."""
    return partial(start_worker, arch=runtime.info()["arch"], warm=warm)
