"""The realizable robot (``docs/method.md``): the body with only the given
tendons, each a cable through its waypoints (a lattice tendon's fiber nodes, or
a smooth route's waypoints located in the rest mesh) with one rest length,
pulled at its last waypoint and sliding through the others with the scene's
capstan friction - the *as-built* robot (frictionless where mu = 0). Its tendon
contractions minimize the same soft-IK objective as the idealized robot's stage
0 (pose and contraction terms, bounds [-pmax, cmax] on c / L0) - a least-squares
problem in a handful of variables, solved by bounded Gauss-Newton
(:mod:`~tendon_taichi.optimizer.gauss_newton`; L-BFGS-B where a plugin adds a
term that is not a sum of squares).

:func:`predict_realizable` estimates a layout's realizable pose error far more
cheaply, by one Gauss-Newton step from a nearby solved layout; consolidation
uses it to screen small edits before solving the promising ones in full."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..body.cables import CableSet
from ..body.mesh import Embedding
from ..body.problem import Problem
from ..optimizer.gauss_newton import applies, first_step, gauss_newton
from ..optimizer.gauss_newton import target_jacobian  # noqa: F401  (its import path before it moved)
from ..optimizer.homotopy import RunCallbacks, run_stage
from ..optimizer.soft_ik import SoftIK, pose_errors
from ..physics.model import Model
from ..probes import probe
from ..solve.newton import NewtonSolver
from .context import Context
from .protocol import IdealizedState, Tendon


@dataclass
class RealizableResult:
    """Tendon contractions ``contraction`` (T,) m and ratios (T,), tensions ``tau``
    (T,) N, the equilibrium ``x`` (n, 2), pose errors (m; relative to L), and cost."""

    contraction: np.ndarray
    ratios: np.ndarray
    tau: np.ndarray
    x: np.ndarray
    pose_error: float
    pose_error_rel: float
    pose_error_max: float
    iterations: int
    evaluations: int
    time_s: float
    poses: list["RealizableResult"] | None = None


def deformed_waypoints(problem: Problem, tendons: list[Tendon], x: np.ndarray) -> list[np.ndarray]:
    """Each tendon's waypoints (k, 2) where node positions ``x`` (n, 2) put them."""
    return [problem.embed_waypoints(t.nodes, t.waypoints).positions(problem.mesh.triangles, x) for t in tendons]


def tendon_cables(problem: Problem, tendons: list[Tendon], hint: np.ndarray | None = None) -> CableSet:
    """Tendons as many-segment cables through their waypoints
    (:meth:`~tendon_taichi.body.problem.Problem.embed_waypoints`; ``hint``: a
    triangle per waypoint, all tendons', to try first), with the scene's fiber
    stiffness as EA and its tendon friction."""
    tri, bary = [], []
    segs, start, base = [], [0], 0
    for t in tendons:
        h = None if hint is None or len(hint) < base + len(t.waypoints) else hint[base:base + len(t.waypoints)]
        e = problem.embed_waypoints(t.nodes, t.waypoints, h)
        tri.append(e.tri)
        bary.append(e.bary)
        k = len(t.waypoints)
        segs.append(base + np.stack([np.arange(k - 1), np.arange(1, k)], axis=1))
        start.append(start[-1] + k - 1)
        base += k
    a0 = np.array([t.length for t in tendons])
    return CableSet(Embedding(np.concatenate(tri).astype(np.int64), np.concatenate(bary)), np.concatenate(segs),
                    np.array(start, dtype=np.int64), a0,
                    stiffness=np.full(len(tendons), problem.scene.fibers.stiffness),
                    friction=problem.scene.tendons.friction)


def warm_ratios(problem: Problem, tendons: list[Tendon], state: IdealizedState,
                tensions=None) -> np.ndarray:
    """Starting c / L0 per tendon: the contraction that gives the tendon its source
    strand's mean tension (or ``tensions`` (T,) N) at the idealized equilibrium
    (Z'(e) = tau / EA)."""
    fs = problem.scene.fibers
    EA, eps = fs.stiffness, fs.eps
    x = problem.mesh.nodes if state.x is None else state.x
    tensions = [t.tension for t in tendons] if tensions is None else tensions
    out = []
    for t, tension, points in zip(tendons, tensions, deformed_waypoints(problem, tendons, x)):
        L = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
        z1 = max(tension, 0.0) / EA
        e = z1 + 0.5 * eps if z1 >= 0.5 * eps else np.sqrt(2.0 * eps * z1)
        out.append((t.length - L / (1.0 + e)) / t.length)
    return np.clip(np.array(out), -fs.max_payout, fs.max_contraction)


def solve_realizable_poses(context: Context, tendons: list[Tendon], ratios=None, positions=None) -> RealizableResult:
    """The realizable robot of ``context`` (its problem, idealized state, settings and
    solver) in every target pose: one layout, its tendon contractions
    re-solved per pose (warm started from ``ratios`` (P, T) c / L0 where given, else
    from each tendon's tension in that pose; its equilibria from ``positions``, each
    pose's (n, 2), where given, else from rest).
    With several poses the result's pose errors cover every pose's targets,
    ``contraction``, ``ratios`` and ``tau`` are (P, T), ``x`` is the first pose's
    and ``poses`` holds each pose's result."""
    problem = context.problem
    if ratios is not None:
        ratios = np.asarray(ratios, dtype=float).reshape(problem.n_poses, len(tendons))
    warm = [None] * problem.n_poses if positions is None else list(positions)
    if problem.n_poses == 1:
        return solve_realizable(context, tendons, start=None if ratios is None else ratios[0], positions=warm[0])
    t0 = time.perf_counter()
    res = []
    for i, st in enumerate(context.state.poses):
        tensions = [pose_tension(st, t) for t in tendons]
        res.append(solve_realizable(context.on(problem.pose(i), st), tendons, tensions,
                                    start=None if ratios is None else ratios[i], positions=warm[i]))
    err = np.array([r.pose_error for r in res])
    pe = float(np.sqrt((err ** 2).sum()))
    shape = (len(res), len(tendons))
    return RealizableResult(np.array([r.contraction for r in res]).reshape(shape),
                            np.array([r.ratios for r in res]).reshape(shape),
                            np.array([r.tau for r in res]).reshape(shape), res[0].x, pe,
                            pose_error_rel=pe / problem.size, pose_error_max=max(r.pose_error_max for r in res),
                            iterations=sum(r.iterations for r in res), evaluations=sum(r.evaluations for r in res),
                            time_s=time.perf_counter() - t0, poses=res)


def pose_tension(state: IdealizedState, tendon: Tendon) -> float:
    """A tendon's tension in one pose: the mean of its fibers' there (a route, which
    has none, keeps its strand's tension)."""
    return float(state.tau[tendon.fibers].mean()) if len(tendon.fibers) else tendon.tension


@probe()
def solve_realizable(context: Context, tendons: list[Tendon], tensions=None, start=None,
                     positions=None) -> RealizableResult:
    """Solve the realizable robot's tendon contractions for the targets of the
    context's problem (one pose), warm started from ``start`` (T,) c / L0, or else
    :func:`warm_ratios` (from ``tensions`` (T,) N where given), its equilibria from
    ``positions`` (n, 2) where given, else from rest."""
    t0 = time.perf_counter()
    problem, state, settings, solver = context.problem, context.state, context.settings, context.solver
    L = problem.size
    if not tendons:  # the bare body (it sags under gravity, if any)
        x = NewtonSolver(Model.from_problem(problem, cables=CableSet.empty()), solver).solve().x
        pe, worst, _ = pose_errors(problem, [x])
        return RealizableResult(np.zeros(0), np.zeros(0), np.zeros(0), x, pe, pose_error_rel=pe / L,
                                pose_error_max=worst, iterations=0, evaluations=0, time_s=time.perf_counter() - t0)
    ik = SoftIK(problem, settings, solver, cables=tendon_cables(problem, tendons))
    r0 = warm_ratios(problem, tendons, state, tensions) if start is None else np.asarray(start, dtype=float)
    warm = None if positions is None else [positions]
    st = gauss_newton(ik, r0, warm) if applies(ik) else run_stage(ik, 0, r0, RunCallbacks(), warm=warm)
    f = st.figures
    return RealizableResult(st.ac, st.r, st.tau, st.x, f.pose_error, pose_error_rel=f.pose_error_rel,
                            pose_error_max=f.pose_error_max, iterations=st.iterations, evaluations=st.evaluations,
                            time_s=time.perf_counter() - t0)


def predict_realizable(context: Context, tendons: list[Tendon], ratios, positions) -> tuple[float, np.ndarray]:
    """One Gauss-Newton step of the realizable soft IK of ``context`` (its problem,
    settings and solver)
    (:func:`~tendon_taichi.optimizer.gauss_newton.first_step`): the equilibrium at
    ``ratios`` (P, T) c / L0, warm started from ``positions`` (P, n, 2) m (those of a
    nearby layout), its target Jacobian (:func:`target_jacobian`), and the bounded
    linear least-squares step of the pose + contraction objective. Returns the predicted
    pose error (fraction of L, over every pose) and the ratios (P, T) it predicts
    them at. Raises ConvergenceError when an equilibrium cannot be solved."""
    ik = SoftIK(context.problem, context.settings, context.solver, cables=tendon_cables(context.problem, tendons))
    for ps, x in zip(ik.poses, positions):
        ps.model.set_positions(x)
    return first_step(ik, ik.split(ratios).ravel())


def as_built_arrays(problem: Problem, tendons: list[Tendon], real: RealizableResult) -> dict:
    """What the as-built export holds of a solved realizable robot: the waypoints
    at rest ``waypoints`` (k, 2) m, all tendons one after the other, tendon t's
    from ``tendon_start[t]`` to ``tendon_start[t+1]``, embedded by ``point_tri``
    (k,) and ``point_bary`` (k, 3); per pose ``x`` (P, n, 2) m, ``contraction``
    (P, T) m, ``tension`` (P, T) N at the pull end and ``segment_tension`` (P, S)
    N (S = k - T segments, in waypoint order); the tendons' ``rest_length`` (T,) m,
    ``stiffness`` (T,) EA, N, and ``eps`` (the width of the unilateral energy's
    cubic zone, strain); the routes' spline ``control_points`` (all of them, tendon
    t's from ``control_start[t]``; none for a lattice tendon)."""
    cables = tendon_cables(problem, tendons)
    model = Model.from_problem(problem, cables=cables)
    poses = [real] if real.poses is None else real.poses
    P, T = len(poses), len(tendons)
    seg = []
    for r, ac in zip(poses, np.asarray(real.contraction).reshape(P, T)):
        model.set_contraction(ac)
        model.set_positions(r.x)
        model.update_friction()
        seg.append(model.segment_tensions())
    points = cables.points
    return {"waypoints": np.concatenate([t.waypoints for t in tendons]) if tendons else np.zeros((0, 2)),
            "tendon_start": np.concatenate([[0], np.cumsum([len(t.waypoints) for t in tendons])]).astype(np.int64),
            "point_tri": points.tri, "point_bary": points.bary, "x": np.array([r.x for r in poses]),
            "contraction": np.asarray(real.contraction, dtype=float).reshape(P, T),
            "tension": np.asarray(real.tau, dtype=float).reshape(P, T), "segment_tension": np.array(seg),
            "rest_length": cables.a0, "stiffness": cables.stiffness, "eps": problem.scene.fibers.eps,
            "control_points": np.concatenate([t.control for t in tendons if t.control is not None] or
                                             [np.zeros((0, 2))]),
            "control_start": np.concatenate([[0], np.cumsum([0 if t.control is None else len(t.control)
                                                             for t in tendons])]).astype(np.int64)}
