"""Whole runs: optimize a scene with a recording, or resume an interrupted run
(the engine behind the ``optimize`` command)."""

from __future__ import annotations

import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..body.problem import Problem, build_problem
from ..body.scene import Scene
from ..errors import InputError, Stopped
from ..files import check_writable, file_stem
from ..io.export import pose_arrays, write_export
from ..io.plots import plot_stages
from ..io.progress import Progress, active
from ..io.recording import (HeldRun, RecordedRun, Recorder, RecordingError, as_read, completed_chunks, held_stage,
                            problem_tensors, read_recording)
from ..objective.settings import settings_dict
from ..optimizer.homotopy import RunCallbacks, StageResult, run_schedule
from ..optimizer.soft_ik import Figures, Iterate, SoftIK, active_set
from ..physics.elements import check_elements
from ..solve.cholesky import cholesky_library
from ..solve.linear import LinearSettings
from ..version import __version__

#: a final pose error above this share of L draws a warning (the goals were not reached)
UNREACHED = 0.05


class Interrupted(Stopped):
    """Ctrl-C during a run; ``completed`` stages are in the recording."""

    def __init__(self, completed: int, recording: Path, summary: dict):
        super().__init__(f"interrupted after {completed} completed stage(s); the recording "
                         f"'{recording}' keeps them (continue with --resume {recording})")
        self.completed, self.recording, self.summary = completed, recording, summary


@dataclass
class RunResult:
    """A finished (or resumed) optimization; ``held``, the run as its recording
    holds it, kept in memory (what ``design`` extracts from)."""

    problem: Problem
    stages: list[StageResult]
    summary: dict
    recording: Path
    export: Path | None
    warnings: list[str] = field(default_factory=list)
    held: HeldRun | None = None


def _summary(problem: Problem, solver: str, stages: list, recording: Path, export: Path | None,
             t0: float, ik: SoftIK | None, extra: dict) -> dict:
    counts = problem.counts()
    st = [s if isinstance(s, dict) else s.summary() for s in stages]
    out = {"scene": problem.scene.name, "resolution": problem.level, **counts,
           "body_size": problem.size, "solver": solver,
           "settings": settings_dict(problem.scene.optimize), "stages": st,
           "final": st[-1] if st else None, "recording": str(recording),
           "export": str(export) if export else None, "time_s": time.perf_counter() - t0}
    if ik is not None:
        out["evaluations"] = ik.evaluations
        out["linear_iterations"] = sum(ps.linear.stats.iterations for ps in ik.poses)
    out.update(extra)
    return out


def _recorded_stage(rs, problem: Problem) -> StageResult:
    """A StageResult from a recorded stage (for resuming); its per-pose tensions
    are found when needed (:func:`_complete`)."""
    s = rs.summary
    fig = Figures(s["pose_error"], s["pose_error_rel"], s["pose_error_max"], s["active_fibers"],
                  s["active_length"], tau_max=s["tau_max"], objective=s["objective"], poses=s.get("poses"))
    return StageResult(s["stage"], s["k"], s["iterations"], s["evaluations"], s["time_s"], figures=fig,
                       r=rs.r, ac=rs.ac, tau=rs.tau, xs=rs.xs, message=s.get("message", ""))


def _complete(ik: SoftIK, st: StageResult) -> None:
    """Give a stage read back from a recording its per-pose equilibria and tensions:
    the recorded equilibria, or (format-1 recordings) solved again from rest."""
    if st.xs is None:
        ik.configure(st.k)
        eqs = ik.restart(st.r)
        st.xs, st.taus = np.array([eq.x for eq in eqs]), np.array([eq.tau for eq in eqs])
    elif st.taus is None:
        acs = ik.split(st.ac)
        st.taus = np.array([ps.model.tensions_at(ac, x) for ps, ac, x in zip(ik.poses, acs, st.xs)])


@dataclass(frozen=True)
class RunOptions:
    """What else :func:`optimize` does: continue the run recorded in ``resume``;
    write the final problem export to ``export`` (None: beside the recording); log
    the geometry every ``log_every`` iterations (0: at each stage's end only); draw
    stage 0 beside the final stage into ``png`` ("-": beside the recording); run
    the factorizations on ``factor_threads`` (None: the process's)."""

    resume: str | Path | None = None
    export: str | Path | None = None
    log_every: int = 0
    png: str | Path | None = None
    factor_threads: int | None = None


def optimize(scene: Scene, level: int | None = None, solver: str | None = None, record: str | Path | None = None,
             progress: Progress | None = None, options: RunOptions = RunOptions()) -> RunResult:
    """Run the regularized soft IK on ``scene`` at resolution ``level`` (default
    1) with the linear ``solver`` (default "auto"), or continue the run recorded
    in ``options.resume`` at its own level and solver and on its own scene
    (``scene`` may be None; a different level, solver or scene given is refused),
    recording every stage to ``record``, and the rest ``options`` say."""
    t0 = time.perf_counter()
    resume, export, log_every, png = options.resume, options.export, options.log_every, options.png
    factor_threads = options.factor_threads
    progress = progress or active() or Progress(enabled=False)
    completed: list[StageResult] = []
    held, header = [], None  # the completed stages and the run's metadata as the recording holds them
    if resume is not None:
        run = read_recording(resume)
        if not run.stages:
            raise RecordingError(f"'{resume}' has no completed stage to resume from")
        _check_resumable(run, level, solver, scene)
        problem = run.problem()
        solver = run.meta.get("solver") or solver or "auto"
        completed = [_recorded_stage(rs, problem) for rs in run.stages]
        held, header = list(run.stages), run.meta
        record = Path(record) if record is not None else Path(resume)
        meta = dict(run.meta)
    else:
        check_elements(scene.body.dim, scene.origin)
        problem = build_problem(scene, 1 if level is None else level)
        solver = solver or "auto"
        default = Path("recordings") / f"{file_stem(scene.name)}-r{problem.level}.rrd"
        record = Path(record) if record is not None else default
        meta = {"version": __version__, "run_id": uuid.uuid4().hex, "scene": scene.name,
                "resolution": problem.level, "solver": solver, "log_every": log_every, "cholesky": cholesky_library()}
    if record.suffix != ".rrd":
        raise InputError(f"the recording must be an .rrd file (got '{record}')")
    export = Path(export) if export is not None else record.with_suffix(".npz")
    check_writable(record, "recording")
    check_writable(export, "export")
    settings = problem.scene.optimize
    ik = SoftIK(problem, settings, LinearSettings(solver, factor_threads))
    solver = ik.linear.name
    meta["solver"] = solver

    recorder, tmp = _open_recorder(record, problem, settings, meta, log_every, resume=resume, n_done=len(completed))
    step = [sum(s.iterations for s in completed)]
    finished = list(completed)  # what the recording holds

    def on_iteration(it: Iterate):
        step[0] += 1
        recorder.iteration(step[0], it, local=it.iteration)
        progress.iteration(it)

    def on_stage_start(stage, k):
        progress.stage_start(stage, k, settings.stage_iterations)

    def on_stage(st: StageResult):
        recorder.iteration(step[0], st, force=True)
        recorder.stage(st, step[0])
        held.append(held_stage(st, step[0]))
        if tmp is not None:
            _promote(tmp)
        finished.append(st)
        progress.stage_done(st)

    callbacks = RunCallbacks([on_iteration], [on_stage_start], [on_stage])
    stages = completed
    try:
        stages = run_schedule(ik, callbacks, completed=completed)
    except KeyboardInterrupt:
        recorder.close()
        raise Interrupted(len(finished), record, _summary(problem, solver, finished, record, None, t0=t0, ik=ik,
                                                          extra={"interrupted": True})) from None
    recorder.close()
    if tmp is not None:
        _promote(tmp)
    final, s0 = stages[-1], stages[0]
    for st in (s0, final):
        _complete(ik, st)
    acs = ik.split(final.ac)
    write_export(export, problem, final.x, acs[0], final.taus[0], ac_stage0=s0.ac, tau_stage0=s0.tau,
                 r_final=final.r, **pose_arrays(problem, final.xs, acs, final.taus))
    warnings = []
    if s0.figures.pose_error_rel > UNREACHED:
        warnings.append(f"the goals are out of reach: even unregularized soft IK leaves a pose "
                        f"error of {1e3 * s0.figures.pose_error:.2f} mm ({100 * s0.figures.pose_error_rel:.1f}% "
                        f"of the body size); this is a best-effort result")
    elif final.figures.pose_error_rel > UNREACHED:
        warnings.append(f"the final pose error is {100 * final.figures.pose_error_rel:.1f}% of the body "
                        f"size: the regularizers gave up the pose (lower --sparsity or --continuity)")
    extra = {"warnings": warnings, "interrupted": False}
    if resume is not None:
        extra["resumed_from"] = str(resume)
    if png is not None:
        png = record.with_suffix(".png") if str(png) == "-" else Path(png)
        panels = [(f"stage 0 (unregularized): {s0.figures.active_fibers} active", s0.x, s0.tau)]
        names = problem.pose_names
        for i in range(problem.n_poses):
            what = f"final stage {final.stage}" + (f", pose '{names[i]}'" if len(names) > 1 else "")
            panels.append((f"{what}: {int(active_set(final.taus[i], settings).sum())} active",
                           final.xs[i], final.taus[i], i))
        plot_stages(png, problem, panels, settings.active_threshold * settings.tension_scale,
                    settings.tension_scale)
        extra["png"] = str(png)
    summary = _summary(problem, solver, stages, record, export, t0=t0, ik=ik, extra=extra)
    kept = HeldRun(record, header or as_read(recorder.meta), problem.scene.source, problem_tensors(problem), held,
                   built=problem)
    return RunResult(problem, stages, summary, record, export, warnings=warnings, held=kept)


def _check_resumable(run: RecordedRun, level: int | None, solver: str | None, scene: Scene | None) -> None:
    """Refuse a resolution, linear solver or scene that differs from the recorded
    run's (a scene: its name or its TOML text)."""
    meta = run.meta
    if scene is not None and scene.name != meta.get("scene"):
        raise InputError(f"'{run.path}' is a run of scene '{meta.get('scene')}', not '{scene.name}' "
                         f"(leave SCENE out to resume the recorded one)")
    if scene is not None and scene.source != run.scene_toml:
        raise InputError(f"scene '{scene.name}' is not the one '{run.path}' ran: its TOML text differs "
                         f"(leave SCENE out to resume the recorded one)")
    if level is not None and meta.get("resolution") is not None and level != meta["resolution"]:
        raise InputError(f"--level {level} cannot be changed when resuming "
                         f"(the run is at level {meta['resolution']})")
    if solver not in (None, "auto") and meta.get("solver") not in (None, solver):
        raise InputError(f"--solver {solver} cannot be changed when resuming (the run used {meta['solver']})")


def _open_recorder(record: Path, problem, settings, meta, log_every, resume, n_done):
    """A recorder on ``record``; when resuming into the same file, it writes to a
    temporary file first (seeded with the completed stages) that replaces the
    original once it holds at least as much."""
    tmp = None
    target = record
    if resume is not None and Path(resume).resolve() == record.resolve():
        tmp = record.with_name(f".{record.stem}.resume.rrd")
        target = tmp
    recorder = Recorder(target, problem, settings, meta, log_every)
    if resume is not None:
        recorder.copy_from(completed_chunks(resume, n_done))
    else:
        recorder.write_header()
    return recorder, (tmp, record) if tmp is not None else None


def _promote(tmp) -> None:
    """Move a resumed recording over the original (the sink keeps writing to it)."""
    src, dst = tmp
    if src.exists():
        src.replace(dst)


