"""Whole runs: optimize a scene with a recording, resume an interrupted run, and
replay a recording (the engine behind the ``optimize`` and ``replay`` commands)."""

from __future__ import annotations

import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import __version__
from .errors import InputError, Stopped
from .export import pose_arrays, write_export
from .plots import plot_stages
from .model import Model
from .objectives import union_tension
from .optimizer import (Iterate, RunCallbacks, SoftIK, StageResult, active_set, pose_errors,
                        run_schedule, state_solver)
from .problem import Problem, build_problem
from .recording import Recorder, RecordingError, completed_chunks, read_recording, settings_dict
from .scene import Scene

#: a final pose error above this share of L draws a warning (the goals were not reached)
UNREACHED = 0.05


class Interrupted(Stopped):
    """Ctrl-C during a run; ``completed`` stages are in the recording."""

    def __init__(self, completed: int, recording: Path, summary: dict):
        super().__init__(f"interrupted after {completed} completed stage(s); the recording "
                         f"'{recording}' keeps them (continue with --resume {recording})")
        self.completed, self.recording, self.summary = completed, recording, summary


class Progress:
    """Stage-by-stage progress on stderr: a live bar on a terminal, one line per
    stage otherwise."""

    def __init__(self, stream=None, enabled: bool = True):
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = enabled and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.cap = 1

    def stage_start(self, stage: int, k: float | None, cap: int) -> None:
        self.cap = cap
        if self.enabled and not self.tty:
            print(f"stage {stage} ({_k_text(k)}) ...", file=self.stream, flush=True)

    def iteration(self, it: Iterate) -> None:
        if not self.tty:
            return
        n = min(it.iteration, self.cap)
        bar = "#" * (20 * n // self.cap) + "-" * (20 - 20 * n // self.cap)
        f = it.figures
        print(f"\rstage {it.stage} {_k_text(it.k):>10} [{bar}] {it.iteration:4d}/{self.cap} "
              f"pose {100 * f.pose_error_rel:6.3f}%  active {f.active_fibers:4d}", end="",
              file=self.stream, flush=True)

    def stage_done(self, st: StageResult) -> None:
        if not self.enabled:
            return
        f = st.figures
        end = "\n" if self.tty else ""
        print(f"{chr(13) if self.tty else ''}stage {st.stage} done: {_k_text(st.k)}, "
              f"{st.iterations} iterations, pose error {100 * f.pose_error_rel:.3f}% of L, "
              f"{f.active_fibers} active fibers ({100 * f.active_length:.1f} cm), "
              f"{st.time_s:.1f} s{end}", file=self.stream, flush=True)


def _k_text(k: float | None) -> str:
    return "k = -" if k is None else f"k = {k:.4g}"


@dataclass
class RunResult:
    """A finished (or resumed) optimization."""

    problem: Problem
    stages: list[StageResult]
    summary: dict
    recording: Path
    export: Path | None
    warnings: list[str] = field(default_factory=list)


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
    """A StageResult from a recorded stage (for resuming)."""
    from .optimizer import Figures
    s = rs.summary
    fig = Figures(s["pose_error"], s["pose_error_rel"], s["pose_error_max"], s["active_fibers"],
                  s["active_length"], s["tau_max"], s["objective"], s.get("poses"))
    return StageResult(s["stage"], s["k"], s["iterations"], s["evaluations"], s["time_s"], fig,
                       rs.r, rs.ac, rs.tau, None, message=s.get("message", ""))


def optimize(scene: Scene, level: int = 1, solver: str = "auto", record: str | Path | None = None,
             export: str | Path | None = None, log_every: int = 1, progress: Progress | None = None,
             resume: str | Path | None = None, png: str | Path | None = None) -> RunResult:
    """Run the regularized soft IK on ``scene`` (or continue the run recorded in
    ``resume``), recording every stage to ``record`` and writing the final
    problem export to ``export`` (default: beside the recording); ``png``
    draws stage 0 beside the final stage ("-": beside the recording)."""
    t0 = time.perf_counter()
    progress = progress or Progress(enabled=False)
    completed: list[StageResult] = []
    if resume is not None:
        run = read_recording(resume)
        if not run.stages:
            raise RecordingError(f"'{resume}' has no completed stage to resume from")
        problem = run.problem()
        solver = run.meta.get("solver", solver)
        completed = [_recorded_stage(rs, problem) for rs in run.stages]
        record = Path(record) if record is not None else Path(resume)
        meta = dict(run.meta)
    else:
        problem = build_problem(scene, level)
        record = Path(record) if record is not None else Path(f"recordings/{scene.name}-r{problem.level}.rrd")
        meta = {"version": __version__, "run_id": uuid.uuid4().hex, "scene": scene.name,
                "resolution": problem.level, "solver": solver, "log_every": log_every}
    if record.suffix != ".rrd":
        raise InputError(f"the recording must be an .rrd file (got '{record}')")
    export = Path(export) if export is not None else record.with_suffix(".npz")
    settings = problem.scene.optimize
    ik = SoftIK(problem, settings, solver)
    solver = ik.linear.name
    meta["solver"] = solver

    recorder, tmp = _open_recorder(record, problem, settings, meta, log_every, resume, len(completed))
    step = [sum(s.iterations for s in completed)]
    finished = list(completed)  # what the recording holds

    def on_iteration(it: Iterate):
        step[0] += 1
        recorder.iteration(step[0], it.stage, it.k, it.figures, it.xs, it.taus)
        progress.iteration(it)

    def on_stage_start(stage, k):
        progress.stage_start(stage, k, settings.stage_iterations)

    def on_stage(st: StageResult):
        recorder.iteration(step[0], st.stage, st.k, st.figures, st.xs, st.taus, force=True)
        recorder.stage(st, step[0])
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
        raise Interrupted(len(finished), record, _summary(problem, solver, finished, record, None, t0, ik,
                                                          {"interrupted": True})) from None
    recorder.close()
    if tmp is not None:
        _promote(tmp)
    final, s0 = stages[-1], stages[0]
    for st in (s0, final):  # stages read back from a recording carry no positions
        if st.xs is None:
            ik.configure(st.k)
            eqs = ik.restart(st.r)
            st.xs, st.taus = np.array([eq.x for eq in eqs]), np.array([eq.tau for eq in eqs])
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
    summary = _summary(problem, solver, stages, record, export, t0, ik, extra)
    return RunResult(problem, stages, summary, record, export, warnings)


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


# ---------------------------------------------------------------- replay
def replay(path: str | Path, stage: int | None = None, solver: str = "recorded", tol: float = 1e-8,
           png: str | Path | None = None) -> dict:
    """Rebuild the problem from a recording, re-solve each recorded stage's
    equilibrium from rest (with the run's solver unless ``solver`` names another)
    and compare pose error and active count with the record; ``png`` also draws
    stage 0 beside the last replayed stage."""
    t0 = time.perf_counter()
    run = read_recording(path)
    if not run.stages:
        raise RecordingError(f"'{path}' has no completed stage")
    if stage is not None and not 0 <= stage < len(run.stages):
        raise InputError(f"--stage {stage} is not in the recording (stages 0..{len(run.stages) - 1})")
    problem = run.problem()
    settings = run.settings
    model = Model.from_problem(problem)
    newton = state_solver(model, run.meta.get("solver", "auto") if solver == "recorded" else solver)
    rows, states = [], {}

    def solve(rs):
        """Each pose's equilibrium from rest: positions (P, n, 2), union tension (f,)."""
        eqs = [newton.solve(ac=ac, x0=problem.mesh.nodes) for ac in rs.ac.reshape(problem.n_poses, -1)]
        return np.array([eq.x for eq in eqs]), union_tension([eq.tau for eq in eqs])[0]

    for k, rs in enumerate(run.stages):
        if stage is not None and k != stage:
            continue
        xs, tau = solve(rs)
        states[k] = (xs[0], tau)
        pe = pose_errors(problem, xs)[0]
        act = active_set(tau, settings)
        rec = rs.summary
        rel = abs(pe - rec["pose_error"]) / max(abs(rec["pose_error"]), 1e-300)
        ok = rel <= tol and int(act.sum()) == rec["active_fibers"]
        rows.append({"stage": k, "k": rec["k"], "recorded_pose_error": rec["pose_error"],
                     "pose_error": pe, "pose_error_rel_diff": rel,
                     "recorded_active_fibers": rec["active_fibers"], "active_fibers": int(act.sum()),
                     "active_length": float(problem.fibers.a0[act].sum()), "reproduces": bool(ok)})
    out = {"recording": str(path), "scene": run.meta.get("scene"), "resolution": problem.level,
           **problem.counts(), "truncated": run.truncated, "stages": rows,
           "reproduces": all(r["reproduces"] for r in rows), "time_s": time.perf_counter() - t0}
    if png is not None:
        first = 0 if stage is None else stage
        last = max(states)
        if 0 not in states:
            xs, tau = solve(run.stages[0])
            states[0] = (xs[0], tau)
        panels = [(f"stage {k}{' (unregularized)' if k == 0 else ''}: "
                   f"{int(active_set(states[k][1], settings).sum())} active", *states[k])
                  for k in sorted({0, first, last})]
        plot_stages(png, problem, panels, settings.active_threshold * settings.tension_scale,
                    settings.tension_scale)
        out["png"] = str(png)
    return out
