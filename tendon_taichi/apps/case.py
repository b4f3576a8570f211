"""One case: a scene at a level, optimized (recorded), then every requested
extractor on its last stage, each followed by consolidation. ``bench``,
``sweep``, ``planted-bench`` and the workers' warm-up all run cases through
:func:`run_case`; each turns the :class:`CaseResult` into its own figures.

:func:`start_worker` is the set-up every worker process of the task engine
runs once (start Taichi, compile the kernels by a short case)."""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from ..body.scene import Scene, load_scene, with_overrides
from ..extract.settings import ConsolidationSettings
from ..physics import runtime
from .extract import Extraction, extract
from .optimize import Interrupted, RunResult, optimize

#: what stops a whole run of cases when a case raises it (Ctrl-C inside an in-process case)
STOP = (Interrupted,)


@dataclass
class CaseResult:
    """A finished case: its optimization ``run``, the ``extraction`` of its last
    stage, and the seconds each took."""

    run: RunResult
    extraction: Extraction
    optimize_s: float
    extract_s: float


def run_case(scene: Scene, level: int, record: str | Path, solver: str = "auto",
             extractors: list[str] | None = None, consolidation: ConsolidationSettings | None = None,
             log_tendons: bool = True) -> CaseResult:
    """Optimize ``scene`` at ``level`` into the recording ``record``, then run
    ``extractors`` (default: every installed one) on its last stage, each
    followed by ``consolidation`` (default settings if None); ``log_tendons``
    logs their tendons into the recording."""
    t0 = time.perf_counter()
    run = optimize(scene, level, solver, record=record)
    t1 = time.perf_counter()
    ex = extract(run.recording, extractors, record=log_tendons, consolidation=consolidation)
    return CaseResult(run, ex, t1 - t0, time.perf_counter() - t1)


def warm_up() -> float:
    """Compile the kernels a case uses, by a short case on the built-in ``t_shape``
    at level 1 in a temporary folder; returns seconds. Its extraction skips
    consolidation: the realizable robots it solves use the same kernels, and after
    three iterations per stage the pattern is still dense, which would make
    consolidating it take about a minute."""
    t0 = time.perf_counter()
    scene = with_overrides(load_scene("t_shape"), {"stage_iterations": 3, "k_min": 0.5})
    with tempfile.TemporaryDirectory(prefix="tendon-taichi-warmup-") as tmp:
        run_case(scene, 1, Path(tmp) / "warm.rrd", consolidation=ConsolidationSettings(tolerance=-1.0),
                 log_tendons=False)
    return time.perf_counter() - t0


def start_worker(threads: int | None, arch: str | None = None, warm: bool = True) -> dict:
    """A task engine's worker set-up: start Taichi (``arch``, ``threads``) and warm
    up; returns the times (``init_s``, ``warm_up_s``)."""
    t0 = time.perf_counter()
    runtime.configure(arch=arch, threads=threads)
    runtime.init()
    out = {"init_s": time.perf_counter() - t0, "warm_up_s": None}
    if warm:
        out["warm_up_s"] = warm_up()
    return out


def worker_setup(warm: bool = True):
    """The ``setup`` to hand the task engine: :func:`start_worker` on this
    process's Taichi arch."""
    return partial(start_worker, arch=runtime.info()["arch"], warm=warm)
