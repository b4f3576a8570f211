"""The L0 homotopy: stages of L-BFGS-B on the soft IK (``docs/method.md``).

Stage 0 is the paper's plain soft IK (the terms that are on in every stage:
pose and the small contraction regularizer); stage s >= 1 turns every term on,
those that read ``k`` (sparsity; strand ends with the ``count`` measure) at
``k = k0 factor^(s-1)``, and re-optimizes
from the previous stage's ``r``. The schedule stops when the active set has
not changed over two stages or ``k < k_min``. Every stage starts from the
equilibrium solved from rest, so a stage depends only on its starting ``r``:
a resumed run repeats an uninterrupted one exactly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize as so

from ..objective.objective import union_tension
from ..objective.settings import OptimizeSettings
from .soft_ik import Figures, Iterate, SoftIK, active_set


@dataclass
class StageResult:
    """One completed stage: its ``k`` (None for stage 0), L-BFGS-B iterations and
    evaluations, wall time, figures, and the final state: ``r`` and ``ac`` (m),
    (P C,) - the contractions of pose 0, then pose 1, ... -, the union tension
    ``tau`` (C,) N, and the per-pose equilibria ``xs`` (P, n, 2) m and tensions
    ``taus`` (P, C) N (``xs`` None for a stage read back from a recording)."""

    stage: int
    k: float | None
    iterations: int
    evaluations: int
    time_s: float
    figures: Figures
    r: np.ndarray
    ac: np.ndarray
    tau: np.ndarray
    xs: np.ndarray | None
    taus: np.ndarray | None = None
    message: str = ""

    @property
    def x(self) -> np.ndarray | None:
        """The equilibrium of the first pose (the only one, for most scenes), (n, 2) m."""
        return None if self.xs is None else self.xs[0]

    def summary(self) -> dict:
        return {"stage": self.stage, "k": self.k, "iterations": self.iterations,
                "evaluations": self.evaluations, **self.figures.as_dict(), "time_s": self.time_s}


def settled(history: list[tuple[float, bytes]], stage: int, settings: OptimizeSettings) -> bool:
    """Whether a stage has settled: over the last ``settle_window`` iterations the
    objective fell by at most ``settle_tol`` x its first value, and (homotopy stages)
    the active set stayed the same. ``history`` holds (objective, active-set bytes)."""
    w = settings.settle_window
    if len(history) <= w:
        return False
    f_start = history[0][0]
    f_then, f_now = history[-1 - w][0], history[-1][0]
    if f_then - f_now > settings.settle_tol * abs(f_start):
        return False
    return stage == 0 or all(a == history[-1][1] for _, a in history[-1 - w:])


def stage_k(settings: OptimizeSettings, stage: int) -> float | None:
    """k of a stage: None for stage 0, then k0 * factor^(stage - 1)."""
    if stage == 0:
        return None
    h = settings.homotopy
    return h.k0 * h.factor ** (stage - 1)


def schedule_done(stages: list[StageResult], settings: OptimizeSettings) -> bool:
    """Whether the homotopy is over after these stages: the next k is below k_min,
    or the active set has not changed over the last two stages (homotopy stages only)."""
    nxt = stage_k(settings, len(stages))
    if nxt is not None and nxt < settings.homotopy.k_min:
        return True
    if len(stages) >= 4:
        sets = [active_set(s.tau, settings) for s in stages[-3:]]
        return bool(np.array_equal(sets[0], sets[1]) and np.array_equal(sets[1], sets[2]))
    return False


@dataclass
class RunCallbacks:
    """Hooks for progress and recording: ``on_iteration(Iterate)`` every L-BFGS-B
    iteration, ``on_stage_start(stage, k)``, ``on_stage(StageResult)`` when a stage completes."""

    on_iteration: list = field(default_factory=list)
    on_stage_start: list = field(default_factory=list)
    on_stage: list = field(default_factory=list)


def run_stage(ik: SoftIK, stage: int, r_start: np.ndarray, callbacks: RunCallbacks,
              warm: list[np.ndarray] | None = None) -> StageResult:
    """Optimize one stage from ``r_start`` with L-BFGS-B (bounds [-pmax, cmax]). Its
    start and final states are solved from rest (what replay recomputes), or from
    ``warm``, each pose's positions (n, 2) of a nearby state, where given."""
    s = ik.settings
    k = stage_k(s, stage)
    t0 = time.perf_counter()
    ik.configure(k)
    if warm is None:
        ik.restart(r_start)
    else:
        ik.warm_start(warm)
    for cb in callbacks.on_stage_start:
        cb(stage, k)
    ev0 = ik.evaluations
    fs = ik.problem.scene.fibers
    bounds = so.Bounds(-fs.max_payout, fs.max_contraction)
    history: list[tuple[float, bytes]] = []

    def callback(intermediate_result):
        r = intermediate_result.x
        fig = ik.figures(r)
        xs, taus = ik.state()
        history.append((ik.last_value(), active_set(union_tension(taus)[0], s).tobytes()))
        for cb in callbacks.on_iteration:
            cb(Iterate(stage, k, len(history), fig, xs, taus=taus))
        if settled(history, stage, s):
            raise StopIteration

    res = so.minimize(ik.evaluate, np.asarray(r_start, dtype=float), jac=True, method="L-BFGS-B",
                      bounds=bounds, callback=callback,
                      options={"maxiter": s.stage_iterations, "ftol": 1e-15, "gtol": 1e-12,
                               "maxcor": 10, "maxls": 40})
    r = np.clip(res.x, -fs.max_payout, fs.max_contraction)
    fig, xs, taus = final_state(ik, r, warm)
    message = "settled" if res.status == 99 or "StopIteration" in str(res.message) else str(res.message)
    out = StageResult(stage, k, int(res.nit), ik.evaluations - ev0, time.perf_counter() - t0, figures=fig,
                      r=r, ac=r * ik.a0, tau=union_tension(taus)[0], xs=xs, taus=taus, message=message)
    for cb in callbacks.on_stage:
        cb(out)
    return out


def final_state(ik: SoftIK, r: np.ndarray, warm: list[np.ndarray] | None) -> tuple[Figures, np.ndarray, np.ndarray]:
    """A stage's final state at ``r``: each pose's equilibrium solved from rest (what
    replay recomputes) or, after a ``warm`` start, settled where it is; its figures,
    positions (P, n, 2) and tensions (P, C)."""
    if warm is None:
        ik.restart(r)
    else:
        ik.settle(r)
    fig = ik.figures(r)
    xs, taus = ik.state()
    return fig, xs, taus


def run_schedule(ik: SoftIK, callbacks: RunCallbacks | None = None,
                 completed: list[StageResult] | None = None,
                 r0: np.ndarray | None = None) -> list[StageResult]:
    """Run (or continue after ``completed``) the stage schedule; return all stages."""
    callbacks = callbacks or RunCallbacks()
    stages = list(completed or [])
    s = ik.settings
    if stages:
        r = stages[-1].r
    else:
        r = np.full(len(ik.a0), s.initial_contraction) if r0 is None else np.asarray(r0)
    while not (stages and schedule_done(stages, s)):
        st = run_stage(ik, len(stages), r, callbacks)
        stages.append(st)
        r = st.r
    return stages
