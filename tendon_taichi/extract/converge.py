"""The front's figures on a finer mesh (``docs/method.md``, "The front"): routes
are curves in the rest body, so each finished layout of the front
(:class:`~.front.Front`) can be embedded in the next finer mesh of the same body
and its contractions solved again there; :func:`converge_front` keeps, per
count, the least costly there and the front monotone there."""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from typing import Callable

import numpy as np

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..objective.settings import OptimizeSettings
from ..tasks.pool import Pool
from .consolidation import Consolidation, Layout, _Search, route_settings
from .front import PRECISION, Front, _key, _with_one_more
from .protocol import IdealizedState
from .realizable import RealizableResult, solve_realizable_poses
from .settings import ConsolidationSettings


def pose_only_state(problem: Problem) -> IdealizedState:
    """An idealized state that gives only ``problem``'s poses (no tensions, the rest
    shape): what a layout's as-built robot needs when its contractions are given."""
    f = problem.fibers.n_fibers
    one = IdealizedState(np.zeros(f), np.zeros(f), None, 0.0)
    return replace(one, poses=[one] * problem.n_poses) if problem.n_poses > 1 else one


def converged_error(fine: Problem, layout: Layout, state: IdealizedState, settings: OptimizeSettings,
                    solver: str = "auto", start=None) -> RealizableResult:
    """A layout's as-built robot on a finer mesh of the same body (``fine``; ``state``
    from :func:`pose_only_state`): its routes, which do not depend on the mesh,
    embedded in that mesh and their contractions solved again, from ``start`` (P, T)
    or else the layout's own."""
    start = np.atleast_2d(layout.realizable.ratios if start is None else start).reshape(fine.n_poses, -1)
    return solve_realizable_poses(fine, layout.tendons(), state, settings, solver, start)


def converge_front(front: Front, problem: Problem, state: IdealizedState, fine: Problem, settings: OptimizeSettings,
                   options: ConsolidationSettings, solver: str = "auto", log: Callable[[str], None] | None = None,
                   workers: Pool | None = None) -> dict[int, RealizableResult | None]:
    """Each count's layouts on the finer mesh ``fine`` (:func:`converged_error`; None
    where none can be solved), in place: of the layout held and every other one
    finished for that count (``front.finished``), the least costly there (its pose
    error there squared plus its routes' shape cost; the one held on ties) becomes
    the count's. The front is then kept monotone there: where a count's error is
    above the count below's by more than ``PRECISION``, that smaller layout with
    one more pooled route (the best on ``problem``'s mesh from each start,
    :func:`_with_one_more`, where that keeps the front on ``problem``'s mesh
    monotone) is solved on ``fine`` as well and replaces the front's layout when it
    does better there. ``workers`` share the solves of the finished layouts."""
    fine_state = pose_only_state(fine)
    search = _Search(problem, state, settings, solver, options, route_settings(problem, options), "front", log)
    search.out = Consolidation(next(iter(front.layouts.values())), 0, 0.0)
    search.workers = workers
    size = problem.size
    out: dict[int, RealizableResult | None] = {}
    spec = (fine, fine_state, settings, solver)
    choices = {}
    for k in sorted(front.layouts):
        key = _key(front.layouts[k], size)
        choices[k] = [front.layouts[k]] + [m for m in front.finished.get(k, []) if _key(m, size) != key]
    jobs = [(lay, None) for k in sorted(choices) for lay in choices[k]]
    if len(jobs) > len(choices):
        search.log(f"front: the {len(jobs)} finished layouts on the finer mesh")
    task = partial(_fine_task, spec)
    found = workers.map(task, jobs) if workers is not None else [task(job) for job in jobs]
    solved = {id(lay): res for (lay, _), res in zip(jobs, found)}
    for k in sorted(front.layouts):
        held, others = choices[k][0], choices[k][1:]
        res = solved[id(held)]
        best = np.inf if res is None else search.cost(held.routes, res.pose_error_rel)
        for lay in others:
            there = solved[id(lay)]
            cost = np.inf if there is None else search.cost(lay.routes, there.pose_error_rel)
            if cost < best - PRECISION ** 2:
                front.layouts[k], res, best = lay, there, cost
        below = out.get(k - 1)
        if below is not None and (res is None or res.pose_error_rel > below.pose_error_rel + PRECISION):
            smaller = front.layouts[k - 1]
            for lay in [m for m in _with_one_more(search, smaller, front.routes, size)
                        if m.error <= max(smaller.error, front.layouts[k].error) + PRECISION]:
                start = np.concatenate([np.atleast_2d(below.ratios).reshape(fine.n_poses, -1),
                                        np.atleast_2d(lay.realizable.ratios).reshape(fine.n_poses, -1)[:, -1:]],
                                       axis=1)
                more = task((lay, start))
                if more is not None and (res is None or more.pose_error_rel < res.pose_error_rel):
                    front.layouts[k], res = lay, more
        out[k] = res
    front.evaluations += search.out.evaluations
    front.screened += search.out.screened
    return out


def _fine_task(spec: tuple, job: tuple[Layout, np.ndarray | None]) -> RealizableResult | None:
    """:func:`converged_error` (``spec``: the finer problem, its pose-only state, the
    settings and the solver; ``job``: the layout and where to start), None where
    it cannot be solved."""
    fine, fine_state, settings, solver = spec
    try:
        return converged_error(fine, job[0], fine_state, settings, solver, job[1])
    except ConvergenceError:
        return None
