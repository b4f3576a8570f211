"""Extract tendons from a recorded run, turn them into smooth routes, prove them
on the as-built realizable robot (capstan friction included), consolidate them
(fewer tendons for almost the same pose), optimize the routes and score them
(the engine behind the ``extract``, ``compare`` and ``design`` commands)."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from ..body.problem import Problem
from ..errors import ConvergenceError, InputError
from ..extract.checks import call_plugin, check_tendons, read_only_copy
from ..extract.consolidation import Consolidation, ConsolidationSettings, consolidate
from ..extract.context import Context
from ..extract.metrics import MetricSettings, tendon_metrics
from ..extract.plugins import available_extractors, load_extractor
from ..extract.protocol import IdealizedState, PluginError, Tendon
from ..extract.realizable import RealizableResult, deformed_waypoints, solve_realizable_poses
from ..files import check_writable
from ..io.recording import (TENDONS_OF, RecordedRun, RecordingError, chunk_at_stage, mesh_edges, read_recording,
                            rewrite, tendons_owner)
from ..optimizer.soft_ik import state_solver
from ..physics.model import Model
from ..solve.linear import LinearSettings
from ..tasks.pool import Pool
from .settings import ExtractSettings


@dataclass
class ExtractorResult:
    """One extractor's outcome on one stage; ``error`` is set when it failed."""

    name: str
    tendons: list[Tendon] = field(default_factory=list)
    metrics: dict = field(default_factory=dict)
    realizable: RealizableResult | None = None
    time_s: float = 0.0
    error: str | None = None
    pose_names: list[str] = field(default_factory=list)
    consolidation: Consolidation | None = None

    def as_json(self) -> dict:
        out = {"name": self.name, "tendons": [t.as_json() for t in self.tendons],
               "metrics": self.metrics, "time_s": self.time_s}
        if self.consolidation is not None:
            out["consolidation"] = self.consolidation.as_json()
        if self.realizable is not None:
            out["realizable"] = {"contraction": self.realizable.contraction.tolist(),
                                 "ratios": self.realizable.ratios.tolist(),
                                 "tension": self.realizable.tau.tolist(),
                                 "iterations": self.realizable.iterations}
            if self.realizable.poses is not None:
                out["realizable"]["poses"] = [
                    {"name": name, "pose_error": r.pose_error, "pose_error_rel": r.pose_error_rel,
                     "pose_error_max": r.pose_error_max, "contraction": r.contraction.tolist()}
                    for name, r in zip(self.pose_names, self.realizable.poses)]
        if self.error is not None:
            out["error"] = self.error
        return out


@dataclass
class Extraction:
    """All extractors run on one recorded stage."""

    run: RecordedRun
    problem: Problem
    stage: int
    state: IdealizedState
    idealized_pose_error: float
    results: list[ExtractorResult]
    record: str | None = None  # the file the tendons were logged into
    record_error: str | None = None  # why the tendons could not be logged
    solver: LinearSettings | None = None  # the linear backend the extractors' robots were solved with

    def as_json(self) -> dict:
        out = {"recording": str(self.run.path), "scene": self.run.meta.get("scene"),
               "resolution": self.problem.level, "truncated": self.run.truncated,
               "stage": self.stage, "k": self.state.k,
               "body_size": self.problem.size, "idealized_pose_error": self.idealized_pose_error,
               "idealized_pose_error_rel": self.idealized_pose_error / self.problem.size,
               "extractors": [r.as_json() for r in self.results]}
        if self.record is not None:
            out["record"] = self.record
        if self.record_error is not None:
            out["record_error"] = self.record_error
        return out


def idealized_state(run: RecordedRun, problem: Problem, stage: int, solver: str) -> IdealizedState:
    """The recorded stage as an extractor sees it: recorded tensions and contractions,
    and each pose's recorded equilibrium with its tensions (a format-1 recording's
    equilibria are solved again from rest, exactly as the run solved them)."""
    rs = run.stages[stage]
    s = run.settings
    thr, k = s.active_threshold * s.tension_scale, rs.summary["k"]
    model = Model.from_problem(problem)
    acs = rs.ac.reshape(problem.n_poses, -1)
    poses = []
    if rs.xs is None:
        newton = state_solver(model, solver)
        for ac in acs:
            eq = newton.solve(ac=ac, x0=problem.mesh.nodes)
            poses.append(IdealizedState(eq.tau, ac, eq.x, thr, stage, k=k))
    else:
        for ac, x in zip(acs, rs.xs):
            poses.append(IdealizedState(model.tensions_at(ac, x), ac, np.array(x), thr, stage, k=k))
    return IdealizedState(rs.tau, acs.max(axis=0), poses[0].x, thr, stage, k=k,
                          poses=poses if len(poses) > 1 else None)


def run_extractor(name: str, context: Context, run: RecordedRun, settings: ExtractSettings,
                  done: dict | None = None) -> ExtractorResult:
    """Run one extractor on read-only copies of the context's problem and state
    (with its options in ``settings``, for at most ``settings.plugin_timeout`` s),
    check its tendons (:mod:`~tendon_taichi.extract.checks`), turn them into
    routes, consolidate and optimize them on the as-built robot with the context's
    solver (:mod:`~tendon_taichi.extract.consolidation`, ``settings.consolidation``)
    and score them (``settings.metric_settings``, given); a failing plugin gives a
    result with ``error`` instead of raising. The context's log hears when the
    plugin starts, of consolidation's steps and of the result. ``done`` maps the
    tendons of extractors run before (their waypoints) to their consolidation:
    the same tendons are not consolidated twice."""
    t0 = time.perf_counter()
    problem, state, solver, log = context.problem, context.state, context.solver, context.log
    options, timeout = (settings.options or {}).get(name), settings.plugin_timeout
    consolidation, metric_settings = settings.consolidation, settings.metric_settings
    say = log or (lambda text: None)
    found = _plugin_tendons(name, problem, state, options, timeout, say=say)
    if isinstance(found, ExtractorResult):
        return replace(found, time_s=time.perf_counter() - t0)
    key = _key(found)
    if done is not None and key in done:
        cons = done[key].relabel(name)
        say(f"{name}: the same tendons as {done[key].layout.source}")
    else:
        cons = _consolidated(problem, found, state, run.settings, consolidation, solver=solver, name=name,
                             log=log)
    if done is not None and not isinstance(cons, str):
        done.setdefault(key, cons)
    return _scored(name, problem, state, cons, run, solver=solver, metric_settings=metric_settings, t0=t0, say=say)


def _key(tendons: list[Tendon]) -> tuple:
    """Which tendons an extractor found (their waypoints): equal keys, equal tendons."""
    return tuple(t.waypoints.tobytes() for t in tendons)


def _plugin_tendons(name: str, problem: Problem, state: IdealizedState, options: dict | None, timeout: float,
                    say) -> list[Tendon] | ExtractorResult:
    """Extractor ``name``'s checked tendons, or its result with the ``error`` that
    stopped it."""
    try:
        ext = load_extractor(name)
        opts = ext.make_options(options) if hasattr(ext, "make_options") else options
        say(f"{name}: extracting")
        view, seen = read_only_copy(problem), read_only_copy(state)
        found = call_plugin(name, lambda: ext.extract(view, seen, opts), timeout)
        return check_tendons(name, found, problem)
    except PluginError as exc:
        return ExtractorResult(name, error=str(exc))
    except Exception as exc:  # noqa: BLE001 - a plugin's bug must not stop the others
        msg = str(exc).splitlines()[0] if str(exc) else ""
        return ExtractorResult(name, error=f"extractor '{name}' raised {type(exc).__name__}: {msg}")


def _consolidated(problem: Problem, tendons: list[Tendon], state: IdealizedState, settings,
                  consolidation: ConsolidationSettings | None, solver: str, name: str,
                  log=None) -> Consolidation | str:
    """The tendons consolidated (:func:`consolidate`), or why their robot cannot be
    solved (the equilibrium's error)."""
    try:
        return consolidate(Context(problem, state, settings, solver, log=log), tendons,
                           consolidation or ConsolidationSettings(), source=name)
    except ConvergenceError as exc:
        return str(exc)


def _consolidate_task(spec: tuple, job: tuple[str, list[Tendon]]) -> tuple[Consolidation | str, float]:
    """:func:`_consolidated` as a worker process runs it (``spec``: the problem,
    state, optimize settings, consolidation settings and solver; ``job``: the
    extractor's name and tendons), with the seconds it took."""
    t0 = time.perf_counter()
    problem, state, settings, consolidation, solver = spec
    cons = _consolidated(problem, job[1], state, settings, consolidation, solver=solver, name=job[0])
    return cons, time.perf_counter() - t0


def _scored(name: str, problem: Problem, state: IdealizedState, cons: Consolidation | str, run: RecordedRun,
            solver: str, metric_settings: MetricSettings, t0: float, say) -> ExtractorResult:
    """Extractor ``name``'s result from its consolidation (or why its robot could not be solved)."""
    if isinstance(cons, str):
        return ExtractorResult(name, time_s=time.perf_counter() - t0,
                               error=f"extractor '{name}': its tendons' robot cannot be solved ({cons})")
    real = cons.realizable
    tendons = cons.tendons
    metrics = tendon_metrics(problem, state, tendons, metric_settings)
    L = problem.size
    ideal = run.stages[state.stage].summary["pose_error"]
    metrics.update(realizable_pose_error=real.pose_error, realizable_pose_error_rel=real.pose_error_rel,
                   realizable_pose_error_rel_frictionless=frictionless_error(problem, tendons, state, run.settings,
                                                                             solver, real=real),
                   idealized_pose_error_rel=ideal / L,
                   realizable_ratio=real.pose_error / ideal if ideal > 0 else float("inf"))
    metrics["extracted_count"] = cons.extracted_count
    if real.poses is not None:
        metrics["realizable_pose_errors_rel"] = [r.pose_error_rel for r in real.poses]
    dt = time.perf_counter() - t0
    # said here too: a worker process that merged them has no log
    if cons.strands is not None and cons.strands < cons.extracted_count:
        say(f"{name}: its {cons.extracted_count} tendons are {cons.strands} strands (pieces in line merged)")
    say(f"{name}: {len(tendons)} tendon(s), as built {100 * real.pose_error_rel:.2f}% of L ({dt:.1f} s)")
    return ExtractorResult(name, tendons, metrics, real, dt, pose_names=problem.pose_names, consolidation=cons)


def _run_shared(names: list[str], problem: Problem, state: IdealizedState, options: dict, run: RecordedRun,
                solver: str, ms: MetricSettings, consolidation: ConsolidationSettings | None, timeout: float, log,
                workers: Pool) -> list[ExtractorResult]:
    """:func:`run_extractor` for every extractor, their distinct tendons consolidated
    on ``workers`` and here at once: the plugins run here one after the other,
    then every distinct set of tendons is consolidated (the same results)."""
    say = log or (lambda text: None)
    found, plugin_s = {}, {}
    for n in names:
        t0 = time.perf_counter()
        found[n] = _plugin_tendons(n, problem, state, options.get(n), timeout, say=say)
        plugin_s[n] = time.perf_counter() - t0
    first: dict[tuple, str] = {}
    for n in names:
        if not isinstance(found[n], ExtractorResult):
            first.setdefault(_key(found[n]), n)
    jobs = [(n, found[n]) for n in first.values()]
    shared = min(len(jobs), workers.active + 1)
    say(f"consolidating the tendons of {len(jobs)} extractor(s) in {shared} process{'es' if shared > 1 else ''}")
    spec = (problem, state, run.settings, consolidation, solver)
    made = dict(zip(first.values(), workers.map(partial(_consolidate_task, spec), jobs)))
    results = []
    for n in names:
        if isinstance(found[n], ExtractorResult):
            results.append(replace(found[n], time_s=plugin_s[n]))
            continue
        source = first[_key(found[n])]
        cons, took = made[source]
        if source != n and not isinstance(cons, str):
            cons = cons.relabel(n)
            say(f"{n}: the same tendons as {source}")
        start = time.perf_counter() - plugin_s[n] - (took if source == n else 0.0)
        results.append(_scored(n, problem, state, cons, run, solver=solver, metric_settings=ms, t0=start, say=say))
    return results


def frictionless_error(problem: Problem, tendons: list[Tendon], state: IdealizedState, settings, solver: str,
                       real: RealizableResult) -> float:
    """The realizable pose error (fraction of L) of ``tendons`` without friction, their
    contractions solved again (from the as-built ones); the as-built one if there is
    no friction to remove."""
    if problem.scene.tendons.friction == 0.0 or not tendons:
        return real.pose_error_rel
    bare = problem.with_tendons(friction=0.0)
    return solve_realizable_poses(Context(bare, state, settings, solver), tendons, real.ratios).pose_error_rel


def extract(path: str | Path | RecordedRun, settings: ExtractSettings = ExtractSettings(),
            record: bool | str | Path = False, on_wait=None, log=None, workers: Pool | None = None) -> Extraction:
    """Run the extractors of ``settings`` (:class:`~.settings.ExtractSettings`;
    default: every installed one, each for at most ``plugin_timeout`` s) on a
    recorded stage (default: the last completed), each followed by consolidation;
    its ``friction`` and ``clearance`` replace the scene's [tendons] settings where
    given. The recording is only read, unless ``record`` asks to log the
    tendons: True into the recording itself, a path into a file of their own that
    the viewer shows with the run (:func:`log_tendons`; ``on_wait`` is called if
    another process is writing; when that fails, the results are kept and
    ``record_error`` says why). ``workers`` (a pool of worker processes) share the
    consolidations (the same results); every factorization, theirs too, runs on
    ``settings.factor_threads`` (None: each process's own). ``path`` is the recording's
    path, or the run already read
    (:func:`~tendon_taichi.io.recording.read_recording`) or handed on in memory
    (:class:`~tendon_taichi.io.recording.HeldRun`: the file is not read again)."""
    s = settings
    stage, names, options = s.stage, s.names, s.options
    consolidation, plugin_timeout = s.consolidation, s.plugin_timeout
    run = path if isinstance(path, RecordedRun) else read_recording(path)
    target = record_target(run, record)
    if not run.stages:
        raise InputError(f"'{run.path}' has no completed stage to extract from")
    if stage is None:
        stage = len(run.stages) - 1
    if not 0 <= stage < len(run.stages):
        raise InputError(f"--stage {stage} is not in the recording (stages 0..{len(run.stages) - 1})")
    names = list(names) if names else sorted(available_extractors())
    options = options or {}
    unknown_opts = set(options) - set(names)
    if unknown_opts:
        raise InputError(f"options given for extractor(s) not run: {', '.join(sorted(unknown_opts))}")
    solver = LinearSettings(run.meta.get("solver", "auto") if s.solver == "recorded" else s.solver, s.factor_threads)
    problem = run.problem().with_tendons(friction=s.friction, clearance=s.clearance, exit=s.exit)
    state = idealized_state(run, problem, stage, solver)
    ms = s.metric_settings or MetricSettings(mu=problem.scene.tendons.friction)
    if workers is not None and workers.active and len(names) > 1:
        results = _run_shared(names, problem, state, options, run, solver=solver, ms=ms, consolidation=consolidation,
                              timeout=plugin_timeout, log=log, workers=workers)
    else:
        done: dict = {}
        context, how = Context(problem, state, run.settings, solver, log=log), replace(s, metric_settings=ms)
        results = [run_extractor(n, context, run, how, done) for n in names]
    out = Extraction(run, problem, stage, state, run.stages[stage].summary["pose_error"], results=results,
                     solver=solver)
    if target is not None and any(r.error is None for r in results):
        try:
            log_tendons(out, on_wait, target)
            out.record = str(target)
        except (OSError, RecordingError) as exc:
            why = exc.strerror or exc if isinstance(exc, OSError) else exc
            out.record_error = f"the tendons were not logged into '{target}' ({why}); the results above are complete"
    return out


def record_target(run: RecordedRun, record: bool | str | Path) -> Path | None:
    """Where ``record`` asks the tendons to be logged (None: nowhere), checked before
    any work: a ``.rrd`` path that can be written and, if it exists, is the run's
    recording or a tendons file of this run."""
    if record is False or record is None:
        return None
    if record is True:
        return Path(run.path)
    target = Path(record)
    if target.suffix != ".rrd":
        raise InputError(f"--record must name an .rrd file (got '{target}')")
    check_writable(target, "tendons recording")
    if target.exists() and not target.samefile(run.path):
        owner = tendons_owner(target)
        if owner is None or owner != run.meta.get("run_id"):
            raise InputError(f"--record '{target}' exists and does not hold tendons of '{run.path}'; "
                             f"name a new file or one an earlier --record of this run wrote")
    return target


def log_tendons(ex: Extraction, on_wait=None, target: str | Path | None = None) -> None:
    """Add each extractor's tendons (rest and realizable) and summary under
    ``/tendons/<extractor>`` at the stage they came from, to the run's recording or
    to ``target``, a file of their own with the run's recording id (rerun shows
    the two together; :data:`TENDONS_OF` names the run). An earlier extraction by
    the same extractor at the same stage is replaced
    (:func:`~tendon_taichi.io.recording.rewrite`: atomic, under a lock on the run's
    recording, so concurrent extractions all keep their tendons). Raises OSError
    when it cannot be written (the file is then unchanged)."""
    names = {r.name for r in ex.results if r.error is None}
    target = Path(ex.run.path if target is None else target)
    own_file = not (target.exists() and target.samefile(ex.run.path))

    def keep(ch) -> bool:
        parts = ch.entity_path.split("/")
        if ch.entity_path == TENDONS_OF:
            return False
        return not (len(parts) > 2 and parts[1] == "tendons" and parts[2] in names and chunk_at_stage(ch, ex.stage))

    def add(rr, rec) -> None:
        if own_file:
            rec.log(TENDONS_OF, rr.TextDocument(json.dumps({"recording": Path(ex.run.path).name,
                                                            "run_id": ex.run.meta.get("run_id")}),
                                                media_type="text/plain"), static=True)
        rec.set_time("stage", sequence=ex.stage)
        rec.set_time("iteration", sequence=int(ex.run.stages[ex.stage].summary.get("step", 0)))
        for r in ex.results:
            if r.error is None:
                log_layout(rr, rec, f"/tendons/{r.name}", ex.problem, r.tendons, real=r.realizable)
                rec.log(f"/tendons/{r.name}/summary", rr.TextDocument(json.dumps(r.as_json()),
                                                                      media_type="text/plain"))

    rewrite(target, ex.run.meta.get("run_id"), keep, add, on_wait, lock=ex.run.path)


def log_layout(rr, rec, base: str, problem: Problem, tendons: list[Tendon], real: RealizableResult | None) -> None:
    """Log tendons at rest (``base/rest``) and on their realizable robot's first pose
    (``base/realizable/mesh``, ``base/realizable/tendons``)."""
    rest = [t.waypoints.astype(np.float32) for t in tendons]
    rec.log(f"{base}/rest", rr.LineStrips2D(rest, radii=-2.0) if rest else rr.Clear(recursive=False))
    if real is None:
        return
    x = real.x
    edges = mesh_edges(problem.mesh.triangles)
    rec.log(f"{base}/realizable/mesh", rr.LineStrips2D(x[edges].astype(np.float32),
                                                        colors=[(120, 140, 170, 90)], radii=-0.5))
    if tendons:
        rec.log(f"{base}/realizable/tendons",
                rr.LineStrips2D([w.astype(np.float32) for w in deformed_waypoints(problem, tendons, x)],
                                radii=-2.0))
