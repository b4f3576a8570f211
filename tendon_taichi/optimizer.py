"""Regularized soft IK with an L0 homotopy (DESIGN.md section 3).

The design variables are the scaled contractions ``r = ac / a0`` within
``[-pmax, cmax]``. Each evaluation solves the equilibrium ``x*(ac)`` (warm
started from the previous one), evaluates the objective, and gets the whole
gradient from ONE adjoint solve with the exact Hessian::

    H lambda = dO/dx                       (dO/dx includes the path through tau)
    dO/dac = dO/dac|explicit + dO/dtau dtau/dac - lambda^T d2E/(dx dac)

Stages: stage 0 is the paper's plain soft IK (pose and the small contraction
regularizer); stage s >= 1 adds sparsity with ``k = k0 factor^(s-1)`` and
continuity, and re-optimizes from the previous stage's ``r``. The schedule
stops when the active set has not changed over two stages or ``k < k_min``.
Every stage starts from the equilibrium solved from rest, so a stage depends
only on its starting ``r``: a resumed run repeats an uninterrupted one exactly.

Several poses: ``r`` stacks one ratio vector per pose, each pose has its own
equilibrium and adjoint solve, and the layout terms see the union tension
(:mod:`~tendon_taichi.objectives`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize as so

from .errors import ConvergenceError
from .model import Model
from .objectives import (ContinuityTerm, ContractionTerm, EffortTerm, Evaluation, Objective, PoseTerm,
                         SparsityTerm, State, StrandEndTerm, union_tension)
from .problem import Problem
from .scene import OptimizeSettings
from .solvers import Equilibrium, NewtonSolver

#: relative tolerance of the adjoint solve (the gradient's accuracy)
ADJOINT_TOL = 1e-10
#: relative force tolerance of the equilibria inside a stage (positions to ~1e-8 L)
EVAL_TOL = 1e-8
#: ... and of a stage's start and final states, solved from rest by exact Newton
#: (what replay recomputes: tight enough to reproduce a 0.1 %-of-L pose error to 1e-8)
STATE_TOL = 1e-12


def state_solver(model: Model, linear) -> NewtonSolver:
    """The solver of stage states: exact Newton from rest to STATE_TOL; the run and
    replay use it alike, so a recorded stage is recomputed exactly."""
    return NewtonSolver(model, linear, tol=STATE_TOL, reuse=False)


@dataclass
class Figures:
    """What a state achieves: pose error (m, root of summed squares over every
    pose's targets), relative to L, worst single target (m), active fibers (union
    tension > threshold), their rest length (m), the largest tension (N), the
    objective terms, and with several poses ``poses``: per pose its ``name``,
    ``pose_error``, ``pose_error_rel`` and ``pose_error_max``."""

    pose_error: float
    pose_error_rel: float
    pose_error_max: float
    active_fibers: int
    active_length: float
    tau_max: float
    objective: dict[str, float]
    poses: list[dict] | None = None

    def as_dict(self) -> dict:
        out = {"pose_error": self.pose_error, "pose_error_rel": self.pose_error_rel,
               "pose_error_max": self.pose_error_max, "active_fibers": self.active_fibers,
               "active_length": self.active_length, "tau_max": self.tau_max,
               "objective": dict(self.objective)}
        if self.poses is not None:
            out["poses"] = [dict(p) for p in self.poses]
        return out


def pose_errors(problem: Problem, xs) -> tuple[float, float, list[dict] | None]:
    """Root of the summed squared target distances over every pose (m), the worst
    single target (m), and (several poses) the same per pose, for one equilibrium
    ``xs[p]`` (n, 2) per pose."""
    rows, errs = [], []
    for i, x in enumerate(xs):
        pp = problem.pose(i)
        err = np.linalg.norm(pp.target_positions(x) - pp.target_goal, axis=1)
        errs.append(err)
        pe = float(np.sqrt((err ** 2).sum()))
        rows.append({"name": problem.pose_names[i], "pose_error": pe, "pose_error_rel": pe / problem.size,
                     "pose_error_max": float(err.max())})
    err = np.concatenate(errs)
    return float(np.sqrt((err ** 2).sum())), float(err.max()), rows if len(xs) > 1 else None


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


@dataclass
class Iterate:
    """Passed to progress callbacks once per L-BFGS-B iteration: per-pose positions
    ``xs`` (P, n, 2) and tensions ``taus`` (P, C)."""

    stage: int
    k: float | None
    iteration: int
    figures: Figures
    xs: np.ndarray
    taus: np.ndarray


class PoseSolve:
    """The equilibrium of one pose and its adjoint: a model, its Newton solver with
    warm starts, and the state of the last solve (``x_last``, the prediction base)."""

    def __init__(self, problem: Problem, solver: str, cables=None):
        self.problem = problem
        self.model = Model.from_problem(problem, cables=cables)
        self.newton = NewtonSolver(self.model, solver, reuse=True)
        self.linear = self.newton.linear
        self.state_newton = state_solver(self.model, self.linear)
        self.lambda_warm = False
        self.pred = None
        self.x_last = problem.mesh.nodes

    def restart(self, ac: np.ndarray) -> Equilibrium:
        """The equilibrium at ``ac`` (m) solved from rest, and a cold adjoint."""
        self.lambda_warm = False
        self.pred = None
        self.linear.reset()
        return self.state_newton.solve(ac=ac, x0=self.problem.mesh.nodes)

    def _predict(self, ac: np.ndarray) -> np.ndarray | None:
        """First-order prediction of x*(ac) from the last equilibrium, whose Hessian the
        adjoint just factorized: x* - H^-1 (d2E/dx dac) (ac - ac_last)."""
        if self.pred is None:
            return None
        x_last, ac_last = self.pred
        self.pred = None
        dx = self.linear.approx_solve(self.model.mixed_product(ac - ac_last))
        return None if dx is None else x_last - dx

    def solve(self, ac: np.ndarray, tol: float) -> Equilibrium:
        """The equilibrium for ``ac`` (m), warm started from the last one (plus a prediction)."""
        pred = self._predict(ac)
        if pred is not None:
            self.model.set_positions(pred)
            if self.model.energy() == float("inf"):  # the prediction inverts a triangle
                self.model.set_positions(self.x_last)
        try:
            eq = self.newton.solve(ac=ac, tol=tol)
        except ConvergenceError:
            eq = self.newton.solve(ac=ac, x0=self.problem.mesh.nodes, tol=tol)
        self.x_last = eq.x
        self.pred = (eq.x, ac)
        return eq

    def adjoint(self, rhs: np.ndarray) -> np.ndarray:
        """lambda = H^-1 dO/dx, warm started from the last one (iterative backends)."""
        lam = self.linear.solve(rhs, tol=ADJOINT_TOL, warm=self.lambda_warm)
        self.lambda_warm = True
        return lam


class SoftIK:
    """The objective over ``r = ac / a0`` and its adjoint gradient.

    One :class:`PoseSolve` per pose of the problem; ``r`` stacks the poses'
    ratios, (P C,). ``solver``: the linear backend of both the equilibrium and
    the adjoint (``cg``, ``direct`` or ``auto``). With ``cables`` (the tendons of
    a realizable robot) instead of the fiber lattice, the objective is the pose
    and the contraction regularizer only.
    """

    def __init__(self, problem: Problem, settings: OptimizeSettings, solver: str = "auto",
                 cables=None):
        self.problem, self.settings = problem, settings
        self.poses = [PoseSolve(problem.pose(i), solver, cables) for i in range(problem.n_poses)]
        self.model = self.poses[0].model
        self.linear = self.poses[0].linear
        s = settings
        a0 = problem.fibers.a0 if cables is None else cables.a0
        if cables is None:
            terms = [PoseTerm(problem),
                     SparsityTerm(problem, s.sparsity, s.sparsity_measure, s.homotopy.k0),
                     ContinuityTerm(problem, s.continuity, s.tension_scale, s.continuity_measure),
                     StrandEndTerm(problem, s.strand_end, s.tension_scale, s.strand_end_measure, s.homotopy.k0),
                     ContractionTerm(a0, s.contraction_reg),
                     EffortTerm(problem, s.effort, s.tension_scale)]
        else:
            terms = [PoseTerm(problem), ContractionTerm(a0, s.contraction_reg)]
        #: rest lengths (m) per entry of r: a0 once per pose, (P C,)
        self.a0 = np.tile(a0, problem.n_poses)
        self.n_cables = len(a0)
        self.objective = Objective(terms)
        self.k: float | None = None
        self.configure(None)
        self.evaluations = 0
        #: the last evaluated point: r, objective, gradient, evaluation, positions (P, n, 2), tensions (P, C)
        self._last: tuple[np.ndarray, float, np.ndarray, Evaluation, np.ndarray, np.ndarray] | None = None
        self.eval_tol = EVAL_TOL

    # ------------------------------------------------------------ stages
    def configure(self, k: float | None) -> None:
        """Stage 0 (``k`` None): pose + contraction; else sparsity at ``k``, the
        strand terms (continuity, strand ends) and the effort too."""
        self.k = k
        active = {"pose", "contraction"}
        if k is not None:
            self.objective.term("sparsity").k = k
            self.objective.term("strand_end").k = k
            active |= {"sparsity", "continuity", "strand_end", "effort"}
        self.objective.active = active
        self._last = None

    def split(self, v: np.ndarray) -> np.ndarray:
        """A stacked (P C,) vector as (P, C)."""
        return np.asarray(v, dtype=float).reshape(len(self.poses), self.n_cables)

    def restart(self, r: np.ndarray) -> list[Equilibrium]:
        """The canonical start of a stage: each pose's equilibrium at ``r`` solved
        from rest, and cold adjoints."""
        self._last = None
        ac = self.split(np.asarray(r, dtype=float) * self.a0)
        return [ps.restart(ac[i]) for i, ps in enumerate(self.poses)]

    # ------------------------------------------------------------ evaluation
    def evaluate(self, r: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and its gradient w.r.t. r at the poses' equilibria for r."""
        r = np.array(r, dtype=float)
        if self._last is not None and np.array_equal(r, self._last[0]):
            return self._last[1], self._last[2]
        ac = self.split(r * self.a0)
        states, cabs = [], []
        for i, ps in enumerate(self.poses):
            eq = ps.solve(ac[i], self.eval_tol)
            cabs.append(ps.model.cable_state())
            states.append(State(eq.x, ac[i], cabs[-1]["tau"], i))
        ev = self.objective.evaluate(states)
        grad = np.empty((len(self.poses), self.n_cables))
        for i, (ps, cab) in enumerate(zip(self.poses, cabs)):
            m = ps.model
            # the whole x-derivative, through the tensions too, and one adjoint solve
            dOdx = ev.dx[i] + m.length_jacobian_product(ev.dtau[i] * cab["kc"])
            dOdx[self.problem.fixed] = 0.0
            lam = ps.adjoint(dOdx)
            grad[i] = ev.dac[i] + ev.dtau[i] * cab["tau_ac"] - m.mixed_transpose_product(lam)
        grad = grad.ravel() * self.a0
        self.evaluations += 1
        self._last = (r, ev.total, grad, ev, np.array([s.x for s in states]), np.array([s.tau for s in states]))
        return ev.total, grad

    def figures(self, r: np.ndarray) -> Figures:
        """Figures at r (evaluated if it is not the last point)."""
        self.evaluate(r)
        _, _, _, ev, xs, taus = self._last
        p = self.problem
        tau = union_tension(taus)[0]
        pe, worst, rows = pose_errors(p, xs)
        active = active_set(tau, self.settings)
        return Figures(pe, pe / p.size, worst, int(active.sum()),
                       float(self.a0[:self.n_cables][active].sum()), float(tau.max()), dict(ev.terms), rows)

    def tensions(self) -> np.ndarray:
        """Per-pose tensions (P, C) of the last evaluated point, N."""
        return self._last[5]

    def last_value(self) -> float:
        """The objective at the last evaluated point."""
        return self._last[1]

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-pose positions (P, n, 2) and tensions (P, C) of the last evaluated point."""
        return self._last[4], self._last[5]


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


def active_set(tau: np.ndarray, settings: OptimizeSettings) -> np.ndarray:
    return tau > settings.active_threshold * settings.tension_scale


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


def run_stage(ik: SoftIK, stage: int, r_start: np.ndarray, callbacks: RunCallbacks) -> StageResult:
    """Optimize one stage from ``r_start`` with L-BFGS-B (bounds [-pmax, cmax])."""
    s = ik.settings
    k = stage_k(s, stage)
    t0 = time.perf_counter()
    ik.configure(k)
    ik.restart(r_start)
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
            cb(Iterate(stage, k, len(history), fig, xs, taus))
        if settled(history, stage, s):
            raise StopIteration

    res = so.minimize(ik.evaluate, np.asarray(r_start, dtype=float), jac=True, method="L-BFGS-B",
                      bounds=bounds, callback=callback,
                      options={"maxiter": s.stage_iterations, "ftol": 1e-15, "gtol": 1e-12,
                               "maxcor": 10, "maxls": 40})
    r = np.clip(res.x, -fs.max_payout, fs.max_contraction)
    # the stage's final state, solved from rest (what replay recomputes)
    ik.restart(r)
    fig = ik.figures(r)
    xs, taus = ik.state()
    message = "settled" if res.status == 99 or "StopIteration" in str(res.message) else str(res.message)
    out = StageResult(stage, k, int(res.nit), ik.evaluations - ev0, time.perf_counter() - t0, fig,
                      r, r * ik.a0, union_tension(taus)[0], xs, taus, message)
    for cb in callbacks.on_stage:
        cb(out)
    return out


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
