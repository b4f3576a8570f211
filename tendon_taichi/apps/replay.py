"""Replay: rebuild a run from its recording alone and solve each recorded stage
again from rest, to check that it reproduces (the engine behind ``replay``)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.plots import plot_stages
from ..io.recording import RecordingError, read_recording
from ..objective.objective import union_tension
from ..optimizer.soft_ik import active_set, pose_errors, state_solver
from ..physics.model import Model


def replay(path: str | Path, stage: int | None = None, solver: str = "recorded", tol: float = 1e-8,
           png: str | Path | None = None) -> dict:
    """Rebuild the problem from a recording, re-solve each recorded stage's
    equilibrium from rest (with the run's solver unless ``solver`` names another)
    and compare pose error, active count and (where recorded) the equilibrium
    itself with the record, each within ``tol`` (relative; positions relative to
    L); ``png`` also draws stage 0 beside the last replayed stage."""
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
        row = {"stage": k, "k": rec["k"], "recorded_pose_error": rec["pose_error"],
               "pose_error": pe, "pose_error_rel_diff": rel,
               "recorded_active_fibers": rec["active_fibers"], "active_fibers": int(act.sum()),
               "active_length": float(problem.fibers.a0[act].sum())}
        if rs.xs is not None:
            row["x_rel_diff"] = float(np.abs(xs - rs.xs).max() / problem.size)
            ok = ok and row["x_rel_diff"] <= tol
        rows.append({**row, "reproduces": bool(ok)})
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
