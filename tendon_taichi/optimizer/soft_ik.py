"""Regularized soft IK: the objective over the scaled contractions and its
adjoint gradient (``docs/method.md``).

The design variables are the scaled contractions ``r = ac / a0`` within
``[-pmax, cmax]``. Each evaluation solves the equilibrium ``x*(ac)`` (warm
started from the previous one, with a first-order prediction), evaluates the
objective, and gets the whole gradient from ONE adjoint solve with the exact
Hessian::

    H lambda = dO/dx                       (dO/dx includes the path through tau)
    dO/dac = dO/dac|explicit + dO/dtau dtau/dac - lambda^T d2E/(dx dac)

Several poses: ``r`` stacks one ratio vector per pose, each pose has its own
equilibrium and adjoint solve, and the layout terms see the union tension
(:mod:`~tendon_taichi.objective`). The stages that minimize it are in
:mod:`.homotopy`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..objective.objective import Evaluation, Objective, union_tension
from ..objective.settings import OptimizeSettings
from ..objective.term import State
from ..objective.terms import registered
from ..physics.model import Model
from ..probes import probe
from ..solve.frictional import solve_jacobian
from ..solve.newton import Equilibrium, NewtonSolver

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
        #: the last restart: its contractions (bytes), equilibrium and the linear
        #: backend's checkpoint after it (:meth:`restart`)
        self.rest: tuple | None = None

    def restart(self, ac: np.ndarray) -> Equilibrium:
        """The equilibrium at ``ac`` (m) solved from rest, and a cold adjoint.

        A solve from rest depends on ``ac`` alone, so a restart at the last one's
        ``ac`` (a stage's final state is the next stage's start) takes its
        equilibrium, and the factorization it left, again - where nothing else
        carries over from the solves in between: no friction (its weights follow
        the path) and a backend whose solves start afresh
        (:attr:`~tendon_taichi.solve.linear.LinearSolver.fresh_solves`)."""
        self.lambda_warm = False
        self.pred = None
        self.linear.reset()
        ac = np.asarray(ac, dtype=float)
        key = ac.tobytes()
        reusable = self.model.capstan is None and self.linear.fresh_solves
        if reusable and self.rest is not None and self.rest[0] == key:
            _, eq, state = self.rest
            self.model.set_contraction(ac)
            self.model.set_positions(eq.x)
            self.linear.resume(state)
            return replace(eq, x=eq.x.copy(), tau=eq.tau.copy())
        eq = self.state_newton.solve(ac=ac, x0=self.problem.mesh.nodes)
        self.rest = (key, eq, self.linear.checkpoint()) if reusable else None
        return eq

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

    @probe()
    def adjoint(self, rhs: np.ndarray) -> np.ndarray:
        """lambda = J^-T dO/dx, J the equilibrium's Jacobian (the Hessian H, plus the
        capstan term with friction), warm started from the last one (iterative backends)."""
        fj = self.model.friction_jacobian()
        if fj is None:
            lam = self.linear.solve(rhs, tol=ADJOINT_TOL, warm=self.lambda_warm)
        else:
            lam = solve_jacobian(self.linear, fj, rhs, ADJOINT_TOL, transpose=True)
        self.lambda_warm = True
        return lam

    def sensitivities(self, rhs, tol: float = ADJOINT_TOL):
        """J^-1 b (n, 2) for each b (n, 2) of ``rhs``, at the last equilibrium, H
        prepared (factorized) once for all of them."""
        fj = self.model.friction_jacobian()
        if fj is None:
            yield from self.linear.solve_many(rhs, tol)
            return
        for j, b in enumerate(rhs):
            yield solve_jacobian(self.linear, fj, b, tol, transpose=False, prepare=j == 0)


class SoftIK:
    """The objective over ``r = ac / a0`` and its adjoint gradient.

    One :class:`PoseSolve` per pose of the problem; ``r`` stacks the poses'
    ratios, (P C,). ``solver``: the linear backend of both the equilibrium and
    the adjoint (``cg``, ``direct`` or ``auto``). With ``cables`` (the tendons of
    a realizable robot) instead of the fiber lattice, the objective is the pose
    and the contraction regularizer only.
    """

    @probe()
    def __init__(self, problem: Problem, settings: OptimizeSettings, solver: str = "auto",
                 cables=None):
        self.problem, self.settings = problem, settings
        self.poses = [PoseSolve(problem.pose(i), solver, cables) for i in range(problem.n_poses)]
        self.model = self.poses[0].model
        self.linear = self.poses[0].linear
        a0 = problem.fibers.a0 if cables is None else cables.a0
        self.lattice = cables is None
        #: rest lengths (m) per entry of r: a0 once per pose, (P C,)
        self.a0 = np.tile(a0, problem.n_poses)
        self.n_cables = len(a0)
        self.objective = self._objective(a0)
        self.k: float | None = None
        self.configure(None)
        self.evaluations = 0
        #: the last evaluated point: r, objective, gradient (None until :meth:`gradient`), evaluation,
        #: positions (P, n, 2), tensions (P, C); and its cables' states (``Model.cable_state``)
        self._cabs: list[dict] = []
        self._last: tuple[np.ndarray, float, np.ndarray | None, Evaluation, np.ndarray, np.ndarray] | None = None
        self.eval_tol = EVAL_TOL
        #: each pose's adjoint lambda (n, 2) of the last evaluation
        self.adjoints: list[np.ndarray] = []

    # ------------------------------------------------------------ stages
    @probe()
    def configure(self, k: float | None) -> None:
        """Stage 0 (``k`` None): the terms that are on in every stage (pose,
        contraction); else every term, those that read ``k`` at this ``k``."""
        self.k = k
        active = set()
        for t in self.objective.terms:
            if k is not None and t.uses_k:
                t.k = k
            if k is not None or not t.homotopy:
                active.add(t.name)
        self.objective.active = active
        self._last = None

    def split(self, v: np.ndarray) -> np.ndarray:
        """A stacked (P C,) vector as (P, C)."""
        return np.asarray(v, dtype=float).reshape(len(self.poses), self.n_cables)

    @probe()
    def restart(self, r: np.ndarray) -> list[Equilibrium]:
        """The canonical start of a stage: each pose's equilibrium at ``r`` solved
        from rest, and cold adjoints."""
        self._last = None
        ac = self.split(np.asarray(r, dtype=float) * self.a0)
        return [ps.restart(ac[i]) for i, ps in enumerate(self.poses)]

    def _objective(self, a0: np.ndarray) -> Objective:
        """The objective's terms for cables of rest lengths ``a0`` (the fiber lattice:
        every term; tendons: those that are not the lattice's)."""
        return Objective([term.from_settings(self.problem, self.settings, a0) for term in registered()
                          if self.lattice or not term.lattice])

    def move_cables(self, cables) -> None:
        """The realizable robot's cables (tendons) replaced by ``cables`` of the same
        structure (:meth:`~tendon_taichi.physics.model.Model.move_cables`), without
        rebuilding the models: positions stay as they are (warm starts)."""
        for ps in self.poses:
            ps.model.move_cables(cables)
            ps.linear.cables_moved()
            ps.lambda_warm, ps.pred, ps.rest = False, None, None
        self.a0 = np.tile(cables.a0, self.problem.n_poses)
        self.objective = self._objective(cables.a0)
        self.configure(self.k)

    @probe()
    def warm_start(self, positions: list[np.ndarray]) -> None:
        """Start from each pose's ``positions`` (n, 2) instead of rest, with cold adjoints."""
        self._last = None
        for ps, x in zip(self.poses, positions):
            ps.lambda_warm, ps.pred = False, None
            ps.linear.reset()
            ps.model.set_positions(x)

    @probe()
    def settle(self, r: np.ndarray) -> list[Equilibrium]:
        """Each pose's equilibrium at ``r`` solved to the stage-state tolerance from
        where the poses are (not from rest). The next evaluation starts from these
        states as they are: no prediction from an earlier point moves them."""
        self._last = None
        for ps in self.poses:
            ps.pred = None
        ac = self.split(np.asarray(r, dtype=float) * self.a0)
        return [ps.state_newton.solve(ac=ac[i]) for i, ps in enumerate(self.poses)]

    # ------------------------------------------------------------ evaluation
    @probe()
    def evaluate(self, r: np.ndarray) -> tuple[float, np.ndarray]:
        """Objective and its gradient w.r.t. r at the poses' equilibria for r."""
        return self.value(r), self.gradient()

    def value(self, r: np.ndarray) -> float:
        """The objective at the poses' equilibria for r, its gradient left to
        :meth:`gradient` (an optimizer's line search that rejects the point needs
        none: its adjoint solves are saved)."""
        r = np.array(r, dtype=float)
        if self._last is not None and np.array_equal(r, self._last[0]):
            return self._last[1]
        ac = self.split(r * self.a0)
        states, cabs = [], []
        for i, ps in enumerate(self.poses):
            eq = ps.solve(ac[i], self.eval_tol)
            cabs.append(ps.model.cable_state())
            states.append(State(eq.x, ac[i], cabs[-1]["tau"], i))
        ev = self.objective.evaluate(states)
        self.adjoints = []
        self.evaluations += 1
        self._cabs = cabs
        self._last = (r, ev.total, None, ev, np.array([s.x for s in states]), np.array([s.tau for s in states]))
        return ev.total

    def gradient(self) -> np.ndarray:
        """The gradient w.r.t. r (P C,) at the last point :meth:`value` evaluated: one
        adjoint solve per pose (``adjoints``), at its equilibrium."""
        r, total, grad, ev, xs, taus = self._last
        if grad is not None:
            return grad
        grad = np.empty((len(self.poses), self.n_cables))
        self.adjoints = []
        for i, (ps, cab) in enumerate(zip(self.poses, self._cabs)):
            m = ps.model
            # the whole x-derivative, through the tensions too, and one adjoint solve
            dOdx = ev.dx[i] + m.length_jacobian_product(ev.dtau[i] * cab["kc"])
            if m.capstan is not None and np.any(ev.dtau[i]):
                dOdx += m.friction_jacobian().tension_gradient(ev.dtau[i])
            dOdx[self.problem.fixed] = 0.0
            lam = ps.adjoint(dOdx)
            self.adjoints.append(lam)
            grad[i] = ev.dac[i] + ev.dtau[i] * cab["tau_ac"] - m.mixed_transpose_product(lam)
        grad = grad.ravel() * self.a0
        self._last = (r, total, grad, ev, xs, taus)
        return grad

    def figures(self, r: np.ndarray) -> Figures:
        """Figures at r (evaluated if it is not the last point)."""
        self.evaluate(r)
        _, _, _, ev, xs, taus = self._last
        p = self.problem
        tau = union_tension(taus)[0]
        pe, worst, rows = pose_errors(p, xs)
        active = active_set(tau, self.settings)
        return Figures(pe, pe / p.size, worst, int(active.sum()), float(self.a0[:self.n_cables][active].sum()),
                       tau_max=float(tau.max()), objective=dict(ev.terms), poses=rows)

    def tensions(self) -> np.ndarray:
        """Per-pose tensions (P, C) of the last evaluated point, N."""
        return self._last[5]

    def last_value(self) -> float:
        """The objective at the last evaluated point."""
        return self._last[1]

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-pose positions (P, n, 2) and tensions (P, C) of the last evaluated point."""
        return self._last[4], self._last[5]


def active_set(tau: np.ndarray, settings: OptimizeSettings) -> np.ndarray:
    """bool (C,): the fibers whose tension exceeds ``active_threshold x tension_scale``."""
    return tau > settings.active_threshold * settings.tension_scale
