"""``design``: the main job end to end (``docs/cli.md``): optimize the fiber
contractions (recorded), run every extractor on the last stage, turn each
one's tendons into smooth routes, consolidate and optimize them on the
as-built robot (capstan friction and clearance included), and recommend the
layout a designer should build: the fewest tendons whose as-built pose error
is within the budget, ties broken by the worst capstan factor, then by length.

Everything goes into one output folder: ``run.rrd`` (the run, the routes
logged into it), ``run.npz`` (the problem export), ``as_built.npz`` (the
as-built robot: routes, equilibria, tensions), ``design.json``,
``design.svg`` (the fabrication drawing, mm), ``design.png`` (the rest body
with the routes beside the as-built pose) and ``front.png`` (as-built error
against tendon count)."""

from __future__ import annotations

import json
import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..body.problem import build_problem
from ..body.scene import Scene
from ..errors import InputError, TendonError
from ..extract.clearance import CLEAR_TOL
from ..extract.consolidation import Layout
from ..extract.context import Context
from ..extract.converge import FineSolves, converge_front
from ..extract.front import PRECISION, Front, search_front
from ..extract.metrics import MetricSettings, tendon_metrics
from ..extract.realizable import as_built_arrays
from ..extract.settings import ConsolidationSettings, FrontSettings
from ..files import check_writable, file_stem, write_json
from ..io.export import write_as_built
from ..io.outputs import design_outputs
from ..io.plots import load as load_pictures, plot_front
from ..io.progress import Progress
from ..io.recording import RecordedRun, rewrite
from ..optimizer.soft_ik import Figures
from ..physics import runtime
from ..physics.elements import check_elements
from ..tasks.pool import Pool
from .extract import Extraction, extract, frictionless_error, log_layout
from .optimize import RunOptions, RunResult, optimize
from .priors import PriorDesign, front_prior, prior_layouts, read_prior, route_rows
from .provenance import result_provenance
from .settings import DesignSettings, ExtractSettings

#: what the output folder holds
FILES = ("run.rrd", "run.npz", "as_built.npz", "design.json", "design.png", "front.png")


def design_files(dim: int) -> tuple[str, ...]:
    """What the output folder of a ``dim``-dimensional body's design holds: :data:`FILES`
    and its fabrication export (:func:`~tendon_taichi.io.outputs.design_outputs`)."""
    return FILES + (design_outputs(dim).fabrication,)


def default_out(scene: Scene, level: int) -> Path:
    """The output folder when none is given: ``designs/<scene>-r<level>``."""
    return Path("designs") / f"{file_stem(scene.name)}-r{level}"


@dataclass
class Design:
    """A finished design: its ``summary`` (what ``design.json`` holds), the ``run``
    (the optimization), its ``extraction`` (every extractor's outcome) and the
    ``layout`` recommended."""

    summary: dict
    run: RunResult
    extraction: Extraction
    layout: Layout


def front_rows(front: Front, fine: dict | None, mu: float, kink_angle: float) -> list[dict]:
    """One entry per count: the front's layout with its figures and its ``routes``
    (:func:`~.priors.route_rows`); its ``realizable_pose_error_rel`` is the one on
    the finer mesh where ``fine`` holds it (``realizable_pose_error_rel_level`` the
    design level's)."""
    rows = []
    for k, lay in sorted(front.layouts.items()):
        row = lay.front_entry(mu, kink_angle)
        row["realizable_pose_error_rel_level"] = lay.error
        if fine is not None and fine["results"].get(k) is not None:
            row["realizable_pose_error_rel"] = fine["results"][k].pose_error_rel
            row["converged_resolution"] = fine["resolution"]
        row["routes"] = route_rows(lay)
        rows.append(row)
    return rows


def recommend(rows: list[dict], budget: float, max_tendons: int | None = None, min_capstan: float = 0.0,
              tolerance: float = 0.0) -> dict:
    """The fewest tendons (at most ``max_tendons``) whose as-built error is within
    ``budget`` (fraction of L) and whose worst capstan factor is at least
    ``min_capstan`` (the pull that reaches a tendon's far end, a fraction), the best
    worst capstan among them, then the shortest; when none keeps the capstan limit,
    the same without it; when none is within the budget, the lowest as-built error
    - the fewest tendons among those within ``tolerance`` (fraction of L,
    consolidation's: a tendon that lowers the error by less pulls no weight) or
    the soft IK's precision, the larger, of it."""
    pool = [e for e in rows if max_tendons is None or e["count"] <= max_tendons]
    if not pool:
        raise InputError(f"no layout of at most {max_tendons} tendon(s) was found (--max-tendons)")
    within = [e for e in pool if e["realizable_pose_error_rel"] <= budget]
    kept = [e for e in within if e["capstan_worst"] >= min_capstan] or within
    if kept:
        return min(kept, key=lambda e: (e["count"], -e["capstan_worst"], e["total_length"]))
    least = min(e["realizable_pose_error_rel"] for e in pool)
    return min([e for e in pool if e["realizable_pose_error_rel"] <= least + max(tolerance, PRECISION)],
               key=lambda e: (e["count"], e["realizable_pose_error_rel"]))


def tendon_rows(layout: Layout, mu: float, clearances: list[float], scene: Scene) -> list[dict]:
    """The recommended tendons as ``design.json`` lists them (``clearances``: each
    one's least distance from the walls, m, as the metrics give them): with each
    one's ``exit`` (where it leaves the body, m, or None) and ``clamp_distance``,
    the distance of its pull end from the nearest clamped box, m."""
    real = layout.realizable
    P = 1 if real.poses is None else len(real.poses)
    contraction = np.asarray(real.contraction).reshape(P, -1)
    tension = np.asarray(real.tau).reshape(P, -1)
    rows = []
    for i, t in enumerate(layout.tendons()):
        turning = float(t.turn_angles().sum())
        rows.append({"waypoints": t.waypoints.tolist(), "control_points": t.control.tolist(),
                     "anchor": t.anchor.tolist(), "pull_end": t.pull_end.tolist(), "length": t.length,
                     "contraction": contraction[:, i].tolist(), "tension": float(tension[:, i].max()),
                     "tension_per_pose": tension[:, i].tolist(), "turning": turning,
                     "capstan": float(np.exp(-mu * turning)),
                     "clearance_min": clearances[i],
                     "exit": None if t.exit is None else t.exit.tolist(),
                     "clamp_distance": float(scene.clamp_distance(t.pull_end[None])[0]),
                     "source": layout.routes[i].source or layout.source})
    return rows


#: the earliest recorded stage ``design`` reads where the later ones' patterns make no layout (stage 0
#: has every fiber free: hundreds of short tendons)
MIN_STAGE = 1
#: the most worker processes ``design`` starts by default: each holds its own copy of the problem
#: and its compiled kernels, and the front's batches are a few to a few dozen pieces
MAX_DEFAULT_WORKERS = 4


def default_workers() -> int:
    """Worker processes ``design`` starts by default: one per core it may use but
    the one it runs on, at most :data:`MAX_DEFAULT_WORKERS`."""
    return max(0, min(runtime.cores() - 1, MAX_DEFAULT_WORKERS))


def start_worker(threads: int | None, arch: str | None = None, warm: bool = True) -> dict:
    """A worker process's set-up (``design``'s pool, the task engine's Dask
    workers): start Taichi (``arch``, ``threads``) and, with ``warm``, compile the
    kernels by a short design (:func:`warm_up`) and import what the pictures use
    (:func:`~tendon_taichi.io.plots.load`); returns the times (``init_s``,
    ``warm_up_s``). Its factorizations run on one thread where the job gives none
    (:func:`~tendon_taichi.physics.runtime.factor_threads`): other processes hold
    the other cores."""
    t0 = time.perf_counter()
    runtime.configure(arch=arch, threads=threads, factor_threads=1)
    runtime.init()
    out = {"init_s": time.perf_counter() - t0, "warm_up_s": None}
    if warm:
        out["warm_up_s"] = warm_up()
        load_pictures()
    return out


#: the one extractor the warm-up runs (:func:`warm_up`), where it is installed
WARM_UP_EXTRACTOR = "strands"


def warm_up() -> float:
    """Compile the kernels a design uses, by a short one of the built-in ``t_shape``
    at level 1 in a temporary folder; returns seconds. Its extraction skips
    consolidation: the realizable robots it solves use the same kernels, and after
    three iterations per stage the pattern is still dense, which would make
    consolidating it take about a minute, and the pose it reaches is not checked
    against a budget (:func:`check_reach`). It runs one extractor
    (:data:`WARM_UP_EXTRACTOR`, else every installed one): every extractor's layout
    is solved by the same kernels, and the three built-in ones' dense layouts take
    longer to solve than one's (the worker then joins a level-2 design's
    consolidations from their start, not midway)."""
    from ..body.scene import load_scene, with_overrides
    from ..extract.plugins import available_extractors

    t0 = time.perf_counter()
    scene = with_overrides(load_scene("t_shape"), {"stage_iterations": 3, "k_min": 0.125})
    names = (WARM_UP_EXTRACTOR,) if WARM_UP_EXTRACTOR in available_extractors() else None
    with tempfile.TemporaryDirectory(prefix="tendon-taichi-warmup-") as tmp:
        quick = DesignSettings(budget=1.0, extractors=names, png=False, front=FrontSettings(converge=False),
                               consolidation=ConsolidationSettings(tolerance=-1.0, refine=0))
        design(scene, 1, tmp, quick)
    return time.perf_counter() - t0


def design(scene: Scene, level: int = 1, out: str | Path | None = None, settings: DesignSettings = DesignSettings(),
           progress: Progress | None = None, workers: int = 0) -> Design:
    """The main job (module docstring) on ``scene`` at ``level`` into the folder
    ``out`` (default :func:`default_out`), made and chosen as ``settings`` say
    (:class:`~.settings.DesignSettings`: the budget both bounds consolidation, unless
    its settings say otherwise, and picks the recommendation; ``routes_from`` is
    checked before anything is computed, :mod:`.priors`); ``workers`` processes
    (started at once, warming up while the contractions are optimized) share the
    consolidations and the front's solves and route optimizations - the same
    design, sooner where there are idle cores (from a script: under ``if __name__
    == "__main__":``, as :mod:`~tendon_taichi.tasks.pool` says). Goals out of reach
    of the budget end it after the optimization (:func:`check_reach`). Its
    factorizations run on one thread where it starts workers
    (:func:`design_threads`), theirs too."""
    t0 = time.perf_counter()
    check_elements(scene.body.dim, scene.origin)
    progress = progress or Progress(enabled=False)
    prior = None if settings.routes_from is None else read_prior(settings.routes_from, scene)
    out = Path(out) if out is not None else default_out(scene, level)
    for name in design_files(scene.body.dim):
        check_writable(out / name, "output")
    here = runtime.info()
    threads = design_threads(workers)
    with Pool(workers, start_worker, (here["threads"], here["arch"])) as pool:
        coarse = None
        if prior is None and settings.front.coarse and level > 1:
            progress.message(f"design: {scene.name} at level {level - 1} first: its front's layouts join this "
                             "design's (--no-coarse skips this)" + (f"; {workers} worker process"
                                                                    f"{'es' if workers > 1 else ''} starting"
                                                                    if workers else ""))
            prior, coarse = coarse_prior(scene, level - 1, settings, progress, pool=pool, threads=threads)
        progress.message(f"design: optimizing {scene.name} at level {level}"
                         + (f" ({workers} worker process{'es' if workers > 1 else ''} starting)"
                            if workers and coarse is None else ""))
        run = optimize(scene, level, settings.solver, record=out / "run.rrd", progress=progress,
                       options=RunOptions(export=out / "run.npz", factor_threads=threads))
        check_reach(run, settings.budget)
        for w in run.warnings:  # now, not only with the design: the search may take long
            progress.message(f"design: warning: {w}")
        ex, layout, summary = recommended(run.held, settings, progress, workers=pool, prior=prior,
                                          factor_threads=threads)
        summary["timing"]["optimize_s"] = run.summary["time_s"]
        summary["timing"]["workers"] = workers
        summary["timing"]["coarse_s"] = None if coarse is None else coarse["time_s"]
        summary["search"]["coarse"] = coarse
        summary["warnings"] = list(run.warnings) + _budget_warning(summary) + clearance_warnings(summary)
        summary["files"] = _write(out, ex, layout, summary, png=settings.png, pool=pool)
    if pool.broken:
        progress.message(f"design: {pool.broken}")
    summary["time_s"] = time.perf_counter() - t0
    write_json(summary, out / "design.json")
    return Design(summary, run, ex, layout)


def coarse_prior(scene: Scene, level: int, settings: DesignSettings, progress: Progress, *, pool: Pool,
                 threads: int) -> tuple[PriorDesign | None, dict]:
    """``scene`` designed at the coarser ``level`` as ``settings`` say - its front not
    solved again on a finer mesh (the design this one starts is that mesh), nothing
    drawn, the run recorded into a temporary folder, removed - on ``pool``, its
    factorizations on ``threads``: its front as a prior design for the level above
    (:func:`~.priors.front_prior`), and what it was (``search.coarse`` in
    ``design.json``: ``level``, ``layouts``, the ``count`` it recommended, its
    as-built ``error_rel``, ``time_s``). Where that level reaches no design (its
    goals out of the budget's reach, :func:`reach`; no extractor's tendons) the
    prior is None and ``error`` says why, the design above goes on without it."""
    t0 = time.perf_counter()
    quick = replace(settings, png=False, front=replace(settings.front, converge=False, coarse=False))
    with tempfile.TemporaryDirectory(prefix="tendon-taichi-coarse-") as tmp:
        run = optimize(scene, level, settings.solver, record=Path(tmp) / "run.rrd", progress=progress,
                       options=RunOptions(export=Path(tmp) / "run.npz", factor_threads=threads))
        nearest = reach(run).pose_error_rel
        why = (f"the optimized fibers come no closer to the goals than {100 * nearest:.2f}% of L, above the budget"
               if nearest > settings.budget else None)
        if why is None:
            try:
                _, _, summary = recommended(run.held, quick, progress, workers=pool, factor_threads=threads)
            except InputError as exc:
                why = str(exc)
    if why is not None:
        progress.message(f"design: level {level}: {why}; going on without its layouts")
        return None, {"level": level, "layouts": 0, "count": None, "error_rel": None,
                      "time_s": time.perf_counter() - t0, "error": why}
    prior = front_prior(summary["front"], scene, level)
    rec = summary["recommended"]
    progress.message(f"design: level {level}: {len(prior.layouts)} front layouts, {rec['count']} tendon(s) "
                     f"recommended, {100 * rec['metrics']['realizable_pose_error_rel']:.2f}% of L as built")
    return prior, {"level": level, "layouts": len(prior.layouts), "count": rec["count"],
                   "error_rel": rec["metrics"]["realizable_pose_error_rel"], "time_s": time.perf_counter() - t0}


def design_threads(workers: int) -> int:
    """The threads of a design's sparse factorizations, in this process and in its
    ``workers`` (they are handed them): one where there are workers, which hold
    the other cores, else this process's
    (:func:`~tendon_taichi.physics.runtime.factor_threads`)."""
    return 1 if workers > 0 else runtime.factor_threads()


def check_reach(run: RunResult, budget: float) -> None:
    """Stop before anything is extracted where the goals are out of reach of the
    budget: the optimized fibers come no closer to them than ``budget`` (fraction
    of L) at any stage, stage 0 (every fiber free, no regularizer) included. No
    tendon layout is expected to beat every fiber together, and the search for
    one over the many tendons such fibers make takes many minutes; the run stays
    in its recording, and the message names the budget that designs anyway."""
    best = reach(run)
    if best.pose_error_rel <= budget:
        return
    enough = _rounded_up(best.pose_error_rel)
    way_on = f"; a --budget of {enough:g} or more designs anyway" if enough < 1.0 else ""
    raise InputError(f"the goals are out of reach: the optimized fibers come no closer to them than "
                     f"{1e3 * best.pose_error:.2f} mm ({100 * best.pose_error_rel:.2f}% of L), above the budget of "
                     f"{100 * budget:g}% of L, so no layout was searched; the run is kept in "
                     f"{run.recording}{way_on}")


def reach(run: RunResult) -> Figures:
    """How near the optimized fibers of ``run`` come to the goals: the figures of its
    stage of least pose error (``pose_error_rel``, fraction of L; ``pose_error``, m),
    stage 0 (every fiber free) included."""
    return min(run.stages, key=lambda st: st.figures.pose_error_rel).figures


def _rounded_up(x: float) -> float:
    """``x`` > 0 rounded up to three significant digits."""
    r = float(f"{x:.3g}")
    if r < x:
        r = float(f"{r + 10.0 ** (np.floor(np.log10(r)) - 2):.3g}")
    return r


def recommended(recording: str | Path | RecordedRun, settings: DesignSettings = DesignSettings(),
                progress: Progress | None = None, workers: Pool | None = None, prior: PriorDesign | None = None,
                factor_threads: int | None = None) -> tuple[Extraction, Layout, dict]:
    """Every extractor of ``settings`` on a recorded run's last stage (where its
    pattern makes no layout - a homotopy that thinned it to a few fibers -, the stage
    before, and so on down to ``MIN_STAGE``, said in the progress; ``recording``:
    its path, or the run read or held in memory, as :func:`~.extract.extract` takes
    it), consolidated and routed, the count/error front searched from all their
    routes (:func:`search_front`), each front entry solved again on the next finer
    mesh (``settings.front.converge``), and the layout recommended
    (:func:`recommend`): the extraction, the layout and the summary ``design.json``
    holds (no file is written; ``settings.png`` and ``routes_from`` are not read).
    ``workers`` (a pool of worker processes) share the consolidations and the
    front's independent pieces; ``prior``'s front layouts
    (:func:`~.priors.read_prior`) join the front's seeds; every factorization runs
    on ``factor_threads`` (None: the process's)."""
    t0 = time.perf_counter()
    progress = progress or Progress(enabled=False)
    cons = settings.consolidating
    budget, max_tendons, min_capstan = settings.budget, settings.front.max_tendons, settings.min_capstan
    converge = settings.front.converge
    how = ExtractSettings(names=settings.extractors, consolidation=cons, factor_threads=factor_threads,
                          **({} if settings.plugin_timeout is None else {"plugin_timeout": settings.plugin_timeout}))

    def log(text: str) -> None:
        progress.message(f"design: {text}")

    stage, extract_s, ready = None, 0.0, False
    priors = finer = None
    while True:  # the last stage, or - where its pattern makes no layout - the one before, ...
        t1 = time.perf_counter()
        ex = extract(recording, replace(how, stage=stage), log=log, workers=workers)
        extract_s += time.perf_counter() - t1
        problem, solver = ex.problem, ex.solver
        done = [r.consolidation for r in ex.results if r.error is None and r.consolidation is not None]
        front = None
        if done:
            if not ready:  # the prior's layouts and the finer mesh: the same for every stage read
                if prior is not None:
                    priors = prior_layouts(prior, problem)
                    log(f"{len(priors)} of the {len(prior.layouts)} layouts of {prior.name} join the front's seeds")
                finer = FinerMesh(problem, ex.run.settings, solver, workers) if converge else None
                ready = True
            front = search_front(Context(problem, ex.state, ex.run.settings, solver, log=log, workers=workers),
                                 done, cons, settings.front, priors=priors,
                                 on_finished=None if finer is None else finer.offer)
        if (front is not None and front.layouts) or max_tendons or ex.stage <= MIN_STAGE:
            break
        kept = ex.run.stages[ex.stage].summary.get("active_fibers")
        log(f"no extractor's tendons make a layout from stage {ex.stage}"
            + ("" if kept is None else f" ({kept} active fibers)") + f"; reading stage {ex.stage - 1}")
        stage = ex.stage - 1
    if not done:
        raise InputError("no extractor produced tendons: " + "; ".join(r.error for r in ex.results if r.error))
    ms = MetricSettings(mu=problem.scene.tendons.friction)
    if not front.layouts:
        raise InputError(f"no layout of at most {max_tendons} tendon(s) was found (--max-tendons)" if max_tendons
                         else "no extractor's tendons make a layout of one tendon or more" + _pattern_said(ex))
    fine = finer_mesh_errors(ex, front, cons, log, workers=workers, finer=finer) if converge else None
    rows = front_rows(front, fine, ms.mu, ms.kink_angle)
    chosen = recommend(rows, budget, max_tendons, min_capstan, tolerance=max(cons.tolerance, 0.0))
    layout = front.layouts[chosen["count"]]
    summary = _summary(ex, layout, chosen, rows, settings, ms=ms)
    summary["search"] = {**front.as_json(), "beam": settings.front.beam, "stage": ex.stage,
                         "routes_from": None if prior is None or prior.path is None else str(prior.path),
                         "converged_resolution": None if fine is None else fine["resolution"],
                         **({"converge_error": fine["error"]} if fine and fine.get("error") else {})}
    summary["timing"].update(extract_s=extract_s, front_s=front.time_s,
                             converge_s=None if fine is None else fine["time_s"],
                             route_s=summary["timing"]["route_s"] + front.route_s)
    return ex, layout, summary


def _extractor_row(r) -> dict:
    """An extractor's entry in ``design.json``: its final figures and what became
    of the tendons it returned (:func:`unaccounted`)."""
    cons = r.consolidation
    return {"name": r.name, "count": r.metrics.get("count"),
            "realizable_pose_error_rel": r.metrics.get("realizable_pose_error_rel"),
            "capstan_worst": r.metrics.get("capstan_worst"), "time_s": r.time_s,
            "extracted_count": None if cons is None else cons.extracted_count,
            "strands": None if cons is None else (cons.extracted_count if cons.strands is None else cons.strands),
            "steps": None if cons is None else [s.as_json() for s in cons.steps],
            **({"error": r.error} if r.error else {})}


def unaccounted(row: dict) -> int | None:
    """How many of an extractor's tendons went missing without a step that says so,
    from its ``design.json`` entry alone: its ``extracted_count`` tendons make
    ``strands`` routes (pieces of one strand merged; the progress says so), each
    ``drop`` and ``join`` step takes one away, and ``count`` are left - anything
    else is a tendon lost silently, which none may be (``docs/method.md``,
    Consolidation). None for an extractor that failed."""
    if row.get("error") or row.get("steps") is None:
        return None
    removed = sum(1 for s in row["steps"] if s["action"] in ("drop", "join"))
    merged_wrongly = max(row["strands"] - row["extracted_count"], 0)  # merging never adds a route
    return abs(row["strands"] - removed - row["count"]) + merged_wrongly


def _pattern_said(ex: Extraction) -> str:
    """What the extracted stage's tension pattern holds, for a message about its tendons."""
    st = ex.run.stages[ex.stage].summary  # the completed stages, from 0 up
    if "active_fibers" not in st:
        return ""
    return (f": stage {ex.stage}, which they read, keeps {st['active_fibers']} active fiber(s) "
            f"({100 * st['active_length']:.1f} cm) at a pose error of {100 * st['pose_error_rel']:.2f}% of L "
            f"(the regularizers' weights, --sparsity first, set how much stays)")


def clearance_warnings(summary: dict) -> list[str]:
    """A warning per recommended tendon whose route keeps less than the asked
    clearance from the walls: the body is too narrow for it there, and it keeps
    the most it can (``docs/method.md``, routes)."""
    asked = summary["clearance"] * summary["body_size"]
    return [f"tendon {i + 1} keeps {1e3 * row['clearance_min']:.2f} mm from the walls, less than the "
            f"{1e3 * asked:.2f} mm clearance asked: the body is too narrow for it there"
            for i, row in enumerate(summary["recommended"]["tendons"])
            if row["clearance_min"] < asked * (1.0 - CLEAR_TOL)]


def _budget_warning(summary: dict) -> list[str]:
    """A warning, as a list, when the recommended layout is not within the budget."""
    error = summary["recommended"]["metrics"]["realizable_pose_error_rel"]
    if error <= summary["budget"]:
        return []
    return [f"no layout found is within the budget of {100 * summary['budget']:g}% of L: the recommended "
            f"one is the most accurate, {100 * error:.2f}% of L as built"]


class FinerMesh:
    """The next finer mesh (level + 1) of ``problem``'s body, built before the front
    is searched, and the solves there of the layouts the front finishes, started
    as they are (:meth:`offer`: ``workers`` run them while they have nothing else
    to do, :class:`~tendon_taichi.extract.converge.FineSolves`); ``error`` where
    that mesh could not be built (too large for this machine, or its scene file is
    gone), ``build_s`` the seconds its building took."""

    def __init__(self, problem, settings, solver: str, workers: Pool | None):
        t0 = time.perf_counter()
        self.level = problem.level + 1
        self.error: str | None = None
        self.solves: FineSolves | None = None
        try:
            self.solves = FineSolves(build_problem(problem.scene, self.level), settings, solver, workers)
        except TendonError as exc:
            self.error = str(exc)
        self.build_s = time.perf_counter() - t0

    def offer(self, layout: Layout) -> None:
        """Start solving a layout the front finished on this mesh."""
        if self.solves is not None:
            self.solves.offer(layout)


def finer_mesh_errors(ex: Extraction, front: Front, cons: ConsolidationSettings, log,
                      workers: Pool | None = None, finer: FinerMesh | None = None) -> dict:
    """The front's layouts solved, with the extraction's linear solver, on the next
    finer mesh (level + 1; ``finer``, where
    it was built before the front was searched), kept monotone there
    (:func:`converge_front`): ``resolution``, ``results`` (per count its as-built
    robot there, None where it could not be solved), ``time_s`` (from here on, and
    the mesh's building), and ``error`` when that mesh could not be built (too
    large for this machine, or its scene file is gone)."""
    t0 = time.perf_counter()
    level, solver = ex.problem.level + 1, ex.solver
    out = {"resolution": level, "results": {}, "time_s": 0.0}
    log(f"re-solving the front on the level-{level} mesh")
    finer = finer or FinerMesh(ex.problem, ex.run.settings, solver, workers)
    if finer.solves is None:
        log(f"the level-{level} mesh was not built ({finer.error}); the front's errors are at level {level - 1}")
        return {**out, "error": finer.error, "time_s": time.perf_counter() - t0 + finer.build_s}
    out["results"] = converge_front(front, Context(ex.problem, ex.state, ex.run.settings, solver, log=log,
                                                   workers=workers), finer.solves.fine, cons, finer.solves)
    out["time_s"] = time.perf_counter() - t0 + finer.build_s
    return out


def _summary(ex: Extraction, layout: Layout, chosen: dict, rows: list[dict], settings: DesignSettings,
             ms: MetricSettings) -> dict:
    budget, max_tendons, min_capstan = settings.budget, settings.front.max_tendons, settings.min_capstan
    problem, run = ex.problem, ex.run
    tendons = layout.tendons()
    real = layout.realizable
    metrics = tendon_metrics(problem, ex.state, tendons, ms)
    metrics.update(realizable_pose_error=chosen["realizable_pose_error_rel"] * problem.size,
                   realizable_pose_error_rel=chosen["realizable_pose_error_rel"],
                   realizable_pose_error_rel_level=real.pose_error_rel,
                   realizable_pose_error_rel_frictionless=frictionless_error(
                       problem, tendons, ex.state, run.settings, ex.solver, real=real),
                   idealized_pose_error_rel=ex.idealized_pose_error / problem.size)
    if real.poses is not None:
        metrics["realizable_pose_errors_rel"] = [r.pose_error_rel for r in real.poses]
    ts = problem.scene.tendons
    done = [r.consolidation for r in ex.results if r.consolidation is not None]
    return {"scene": problem.scene.name, "resolution": problem.level, "body_size": problem.size,
            "friction": ts.friction, "clearance": ts.clearance, "exit": ts.exit, "budget": budget,
            "max_tendons": max_tendons,
            "min_capstan": min_capstan,
            "recommended": {"count": layout.count, "source": layout.source,
                            "meets_min_capstan": chosen["capstan_worst"] >= min_capstan,
                            "tendons": tendon_rows(layout, ms.mu, metrics["clearances"], problem.scene),
                            "metrics": metrics},
            "front": rows,
            "extractors": [_extractor_row(r) for r in ex.results],
            "timing": {"optimize_s": None, "extract_s": None, "route_s": sum(c.route_s for c in done),
                       "route_evaluations": sum(c.route_evaluations for c in done)},
            "provenance": result_provenance()}


def _write(out: Path, ex: Extraction, layout: Layout, summary: dict, png: bool, pool: Pool) -> dict:
    """The drawing, the pictures and the routes logged into the recording. The
    pictures are drawn by a worker of ``pool`` where it has one, while this process
    writes the rest (drawing them, matplotlib's import included, which the workers
    did as they started, was the end of a design)."""
    problem = ex.problem
    tendons = layout.tendons()
    title = f"{problem.scene.name} level {problem.level}: {layout.count} tendon(s), as built " \
            f"{100 * layout.error:.2f}% of L"
    outputs = design_outputs(problem.dim)
    fabrication = outputs.fabrication
    pictures = None
    if png:
        job = (problem.dim, (out / "design.png", problem, tendons, layout.realizable, title),
               (out / "front.png", summary["front"], summary["budget"], summary["recommended"]["count"],
                problem.scene.name))
        pictures = pool.defer(_draw_pictures, job)
    paths = {"recording": str(out / "run.rrd"), "export": str(out / "run.npz"), "json": str(out / "design.json"),
             fabrication.rsplit(".")[-1]: str(outputs.write_fabrication(out / fabrication, problem, tendons, title)),
             "as_built": str(write_as_built(out / "as_built.npz", problem,
                                            as_built_arrays(problem, tendons, layout.realizable)))}
    run = ex.run
    stage = ex.stage

    def add(rr, rec) -> None:
        rec.set_time("stage", sequence=stage)
        rec.set_time("iteration", sequence=int(run.stages[stage].summary.get("step", 0)))
        log_layout(rr, rec, "/design/routes", problem, tendons, real=layout.realizable)
        rec.log("/design/summary", rr.TextDocument(json.dumps(summary), media_type="text/plain"))

    rewrite(run.path, run.meta.get("run_id"), lambda ch: not ch.entity_path.startswith("/design/"), add)
    if pictures is not None:
        paths["png"], paths["front_png"] = pool.collect([pictures])[0]
    return paths


def _draw_pictures(job: tuple[int, tuple, tuple]) -> tuple[str, str]:
    """design.png and front.png from the body's dimension, the arguments of its
    ``plot_design`` (:func:`~tendon_taichi.io.outputs.design_outputs`) and those of
    :func:`~tendon_taichi.io.plots.plot_front`; their paths."""
    dim, design_args, front_args = job
    return str(design_outputs(dim).plot_design(*design_args)), str(plot_front(*front_args))
