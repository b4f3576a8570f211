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

from functools import partial
from pathlib import Path

from ..body.scene import Scene
from ..extract.settings import BEAM, BUDGET, ConsolidationSettings
from ..physics import runtime
from .design import Design, design, start_worker
from .optimize import Interrupted

#: what stops a whole run of cases when a case raises it (Ctrl-C inside an in-process case)
STOP = (Interrupted,)


def run_case(scene: Scene, level: int, out: str | Path, solver: str = "auto",
             extractors: list[str] | None = None, consolidation: ConsolidationSettings | None = None,
             budget: float = BUDGET, png: bool = False, beam: int = BEAM, converge: bool = True,
             routes_from: str | Path | None = None) -> Design:
    """The design of ``scene`` at ``level`` into the folder ``out`` (``run.rrd``,
    ``run.npz``, ``design.json``, ``design.svg``; the pictures with ``png``), with
    ``extractors`` (default: every installed one), each followed by
    ``consolidation`` (default settings, with ``budget``, if None); ``beam``: the
    front's beam width; ``converge`` re-solves the front on the next finer mesh;
    ``routes_from``: a prior design whose front the front searches from too."""
    return design(scene, level, out, solver, budget, extractors=extractors,
                  consolidation=consolidation or ConsolidationSettings(budget=budget), png=png, beam=beam,
                  converge=converge, routes_from=routes_from)


def worker_setup(warm: bool = True):
    """The ``setup`` to hand the task engine: :func:`start_worker` on this
    process's Taichi arch."""
    return partial(start_worker, arch=runtime.info()["arch"], warm=warm)
