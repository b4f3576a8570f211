"""Bounded Gauss-Newton for a soft IK that is a least-squares problem: the
realizable robot's (``docs/method.md``, "The realizable (as-built) robot").

The realizable robot's objective has two terms only, the pose and the
contraction regularizer (:class:`~tendon_taichi.optimizer.soft_ik.SoftIK` with
``cables``)::

    O(r) = sum_p |res_p(r_p)|^2 + w^2 |r|^2,   res_p = (targets_p(x*_p(r_p)) - goals_p) / L,
    w^2 = contraction_reg,

a sum of squares over a handful of variables (a few tendons per pose). Each
step linearizes the residuals at the current point - the targets'
sensitivity to each tendon's ratio, one solve per tendon with the
factorization the equilibrium left (:func:`target_jacobian`) - and takes the
bounded linear least-squares step (:func:`step`) inside a box trust region:
at first ``RADIUS`` in contraction ratio, shrunk where the objective falls by
less than a quarter of what the linear model predicts, doubled where it falls
as predicted with the step at the box's edge. The box matters: the unilateral
cables make the problem non-convex, and an unbounded first step can land in
another basin than the start's (``benchmarks/realizable_side_by_side.py``;
docs/method.md has the figures).

It stops when the full (unboxed) step predicts a decrease of at most
``DECREASE_TOL`` of the objective, when ``SETTLE_WINDOW`` steps lowered the
objective's root (the pose error, fraction of L, where the regularizer is
small) by at most ``SETTLE``, or when the box has shrunk to nothing. Each
step costs one equilibrium and, when it is taken, T solves with one
factorization: 2-4x fewer equilibria than L-BFGS-B on the same objective
(benchmarks/realizable_side_by_side.py).
"""

from __future__ import annotations

import time

import numpy as np
from scipy.optimize import lsq_linear

from ..errors import ConvergenceError
from ..objective.objective import union_tension
from .homotopy import StageResult, final_state
from .soft_ik import ADJOINT_TOL, PoseSolve, SoftIK

#: the terms whose sum is the least-squares objective this solver minimizes
TERMS = frozenset({"pose", "contraction"})
#: stop when the full step predicts a decrease of at most this fraction of the objective
DECREASE_TOL = 1e-10
#: a step is taken when the objective falls by at least this fraction of the predicted decrease
ACCEPT = 1e-4
#: the first trust radius: a box on the step, in contraction ratio (c / L0)
RADIUS = 0.01
#: the box is given up when it shrinks below this
MIN_RADIUS = 1e-10
#: settled: SETTLE_WINDOW steps taken lowered the root of the objective by at most SETTLE
SETTLE_WINDOW = 3
SETTLE = 1e-8
#: steps tried at most
MAX_ITERATIONS = 100


def applies(ik: SoftIK) -> bool:
    """Whether ``ik``'s active objective is the least-squares one (:data:`TERMS`):
    a realizable robot's, with no other term registered for tendons."""
    return not ik.lattice and set(ik.objective.active) <= TERMS


def target_jacobian(ps: PoseSolve, a0: np.ndarray) -> np.ndarray:
    """d(target positions)/d(c / L0) at the pose's last equilibrium, (t, 2, T) m:
    per cable j the sensitivity dx*/dr_j = -J^-1 (d2E/dx dac) a0_j e_j (J the
    equilibrium's Jacobian), read at the targets (their positions are linear in x)."""
    def rhs():
        for j in range(len(a0)):
            b = ps.model.mixed_product(a0[j] * np.eye(1, len(a0), j).ravel())
            b[ps.problem.fixed] = 0.0
            yield b

    return np.stack([-ps.problem.target_positions(dx) for dx in ps.sensitivities(rhs(), ADJOINT_TOL)], axis=-1)


def step(res: np.ndarray, A: np.ndarray, r: np.ndarray, w: float, lo, hi) -> np.ndarray:
    """The bounded Gauss-Newton step d (T,) from ratios ``r`` (T,): the least-squares
    solution of ``[A; w I] d = -[res; w r]`` with ``lo <= r + d <= hi`` (scalars or
    (T,)); ``res`` (m,) the scaled residuals, ``A`` (m, T) their Jacobian."""
    return lsq_linear(np.vstack([A, w * np.eye(len(r))]), -np.concatenate([res, w * r]),
                      bounds=(lo - r, hi - r), method="bvls").x


class _Point:
    """Each pose's scaled residuals ``res`` at ratios ``r`` (P C,), the objective
    ``value`` there, and once :meth:`linearize` d, their Jacobians ``A``."""

    def __init__(self, ik: SoftIK, r: np.ndarray, w: float):
        self.r, self.w = r, w
        ac = ik.split(r * ik.a0)
        self.res = []
        for i, ps in enumerate(ik.poses):
            x = ps.solve(ac[i], ik.eval_tol).x
            self.res.append(((ps.problem.target_positions(x) - ps.problem.target_goal) / ik.problem.size).ravel())
        self.value = float(sum(np.dot(e, e) for e in self.res) + w * w * np.dot(r, r))
        self.A: list[np.ndarray] | None = None

    def linearize(self, ik: SoftIK) -> None:
        """Each pose's residual Jacobian (t 2, C); this point's equilibria must be the
        poses' last solves."""
        a0 = ik.split(ik.a0)
        self.A = [target_jacobian(ps, a0[i]).reshape(len(self.res[i]), ik.n_cables) / ik.problem.size
                  for i, ps in enumerate(ik.poses)]

    def step(self, bounds: tuple[float, float], radius: float | None = None) -> tuple[np.ndarray, float]:
        """The step (P C,) within ``bounds`` and, where given, ``radius`` of this point
        (per pose, :func:`step`), and the decrease of the objective its linear model
        predicts."""
        r = self.r.reshape(len(self.A), -1)
        d, predicted = np.empty_like(r), 0.0
        for i, (res, A) in enumerate(zip(self.res, self.A)):
            lo, hi = bounds
            if radius is not None:
                lo, hi = np.maximum(lo, r[i] - radius), np.minimum(hi, r[i] + radius)
            d[i] = step(res, A, r[i], self.w, lo=lo, hi=hi)
            lin, now = res + A @ d[i], r[i] + d[i]
            predicted += float(np.dot(lin, lin)) + self.w * self.w * float(np.dot(now, now))
        return d.ravel(), self.value - predicted


def first_step(ik: SoftIK, r: np.ndarray) -> tuple[float, np.ndarray]:
    """One step (no box) from ratios ``r`` (P C,), each pose's equilibrium solved from
    where its model is: the pose error (fraction of L, over every pose) the linear
    model predicts after it, and the ratios (P, C) it predicts that at. Raises
    ConvergenceError when an equilibrium cannot be solved."""
    fs = ik.problem.scene.fibers
    bounds = (-fs.max_payout, fs.max_contraction)
    point = _Point(ik, r, float(np.sqrt(ik.settings.contraction_reg)))
    point.linearize(ik)
    d = ik.split(point.step(bounds)[0])
    err2 = sum(float(np.sum((res + A @ di) ** 2)) for res, A, di in zip(point.res, point.A, d))
    return float(np.sqrt(err2)), np.clip(ik.split(r) + d, *bounds)


def gauss_newton(ik: SoftIK, r_start: np.ndarray, warm: list[np.ndarray] | None = None) -> StageResult:
    """Minimize ``ik``'s least-squares objective (:func:`applies`) from ``r_start``
    (P C,) within [-pmax, cmax], its start and final states solved as
    :func:`~.homotopy.run_stage` solves them (from rest, or from ``warm``, each pose's
    positions (n, 2)). Returns the stage-0 :class:`~.homotopy.StageResult`
    (``iterations``: steps tried, ``evaluations``: points whose equilibria were
    solved, ``message``: why it stopped). Raises ConvergenceError when the start's
    equilibrium cannot be solved."""
    t0 = time.perf_counter()
    fs = ik.problem.scene.fibers
    bounds = (-fs.max_payout, fs.max_contraction)
    ik.configure(None)
    if warm is None:
        ik.restart(r_start)
    else:
        ik.warm_start(warm)
    now = _Point(ik, np.clip(np.asarray(r_start, dtype=float), *bounds), float(np.sqrt(ik.settings.contraction_reg)))
    roots, radius, evaluations, message = [np.sqrt(now.value)], RADIUS, 1, "iteration limit"
    for iterations in range(1, MAX_ITERATIONS + 1):
        if now.A is None:  # a point just taken: its equilibria are the poses' last solves
            now.linearize(ik)
        if now.step(bounds)[1] <= DECREASE_TOL * now.value:
            message = "converged"
            break
        d, decrease = now.step(bounds, radius)
        try:
            trial = _Point(ik, np.clip(now.r + d, *bounds), now.w)
            gain = (now.value - trial.value) / decrease if decrease > 0.0 else -np.inf
        except ConvergenceError:  # an equilibrium that fails is a step too far
            trial, gain = None, -np.inf
        evaluations += 1
        length = float(np.abs(d).max())
        if gain < 0.25:
            radius = 0.25 * length
        elif gain > 0.75 and length >= 0.99 * radius:
            radius *= 2.0
        if gain > ACCEPT:
            now = trial
            roots.append(np.sqrt(now.value))
            if len(roots) > SETTLE_WINDOW and roots[-1 - SETTLE_WINDOW] - roots[-1] <= SETTLE:
                message = "settled"
                break
        elif radius < MIN_RADIUS:
            message = "no decrease near the point"
            break
    fig, xs, taus = final_state(ik, now.r, warm)
    return StageResult(0, None, iterations, evaluations, time.perf_counter() - t0, figures=fig, r=now.r,
                       ac=now.r * ik.a0, tau=union_tension(taus)[0], xs=xs, taus=taus, message=message)
