"""The front's figures on a finer mesh (``docs/method.md``, "The front"): routes
are curves in the rest body, so each finished layout of the front
(:class:`~.front.Front`) can be embedded in the next finer mesh of the same body
and its contractions solved again there; :func:`converge_front` keeps, per
count, the least costly there, optimizes its routes again there, and keeps the
front monotone there."""

from __future__ import annotations

from dataclasses import replace
from functools import partial
from typing import Callable

import numpy as np

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..objective.settings import OptimizeSettings
from ..tasks.pool import Deferred, Pool
from .consolidation import Consolidation, Layout, _Search, _solve_task, route_settings
from .context import Context
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


def converged_error(fine: Context, layout: Layout, start=None) -> RealizableResult:
    """A layout's as-built robot on a finer mesh of the same body (``fine``: that
    mesh's problem, its state from :func:`pose_only_state`, the settings and the
    solver): its routes, which do not depend on the mesh, embedded in that mesh and
    their contractions solved again, from ``start`` (P, T) or else the layout's own."""
    start = np.atleast_2d(layout.realizable.ratios if start is None else start).reshape(fine.problem.n_poses, -1)
    return solve_realizable_poses(fine, layout.tendons(), start)


class FineSolves:
    """The as-built robots on the finer mesh ``fine`` (:func:`converged_error` from
    each layout's own contractions) of the layouts the front finishes, started as
    the front offers them (:meth:`offer`, the front's ``on_finished``): ``workers``
    run them while they have nothing else to do (:meth:`~tendon_taichi.tasks.pool.Pool.defer`),
    and :func:`converge_front` collects them (:meth:`results`); the rest are solved
    there. Without workers nothing starts early. The results are those solved later."""

    def __init__(self, fine: Problem, settings: OptimizeSettings, solver: str = "auto", workers: Pool | None = None):
        self.fine, self.state = fine, pose_only_state(fine)
        self.context = Context(fine, self.state, settings, solver)
        self.task = partial(_fine_task, self.context)
        self.workers = workers
        self._started: dict[int, tuple[Layout, Deferred]] = {}  # by id(layout); the layout keeps its id

    def offer(self, layout: Layout) -> None:
        """Start solving ``layout`` on the finer mesh when a worker is free."""
        if self.workers is not None and self.workers.active and id(layout) not in self._started:
            self._started[id(layout)] = (layout, self.workers.defer(self.task, (layout, None)))

    def results(self, layouts: list[Layout]) -> list[RealizableResult | None]:
        """Each of ``layouts`` solved on the finer mesh (None where it cannot be), in
        order: those started collected, the others solved now (on the workers too)."""
        started = [self._started[id(lay)][1] for lay in layouts if id(lay) in self._started]
        fresh = [(lay, None) for lay in layouts if id(lay) not in self._started]
        got = iter(self.workers.collect(started) if started else [])
        new = iter(_mapped(self.workers, self.task, fresh))
        return [next(got) if id(lay) in self._started else next(new) for lay in layouts]


def _mapped(workers: Pool | None, task: Callable, jobs: list) -> list:
    """``[task(job) for job in jobs]``, shared with ``workers`` where there are any."""
    return workers.map(task, jobs) if workers is not None else [task(job) for job in jobs]


def converge_front(front: Front, context: Context, fine: Problem, options: ConsolidationSettings,
                   solved: FineSolves | None = None) -> dict[int, RealizableResult | None]:
    """Each count's layouts, searched on the as-built robot of ``context``, on the
    finer mesh ``fine`` (:func:`converged_error`; None
    where none can be solved), in place: of the layout held and every other one
    finished for that count (``front.finished``), the least costly there (its pose
    error there squared plus its routes' shape cost; the one held on ties) becomes
    the count's, and its routes are optimized again there (:func:`_refit`). The
    front is then kept monotone there: where a count's error is above the count
    below's by more than ``PRECISION``, that smaller layout with one more pooled
    route (the best on ``problem``'s mesh from each start, :func:`_with_one_more`,
    where that keeps the front on ``problem``'s mesh monotone) is solved on
    ``fine`` as well and replaces the front's layout when it does better there.
    The context's workers share the solves of the finished layouts and the refits;
    ``solved`` (made with ``fine`` and the context's settings and solver) holds those
    of the finished layouts started while the front was searched."""
    problem, workers = context.problem, context.workers
    solved = solved or FineSolves(fine, context.settings, context.solver, workers)
    fine_state = solved.state
    search = _Search(context, options, route_settings(problem, options), "front")
    search.out = Consolidation(next(iter(front.layouts.values())), 0, 0.0)
    size = problem.size
    task = solved.task
    there = _least_costly_there(search, front, solved)
    _refit(search, front, there, fine, fine_state)
    out: dict[int, RealizableResult | None] = {}
    for k in sorted(front.layouts):
        res, below = there[k], out.get(k - 1)
        if below is not None and (res is None or res.pose_error_rel > below.pose_error_rel + PRECISION):
            smaller = front.layouts[k - 1]
            more_layouts = [m for m in _with_one_more(search, smaller, front.routes, size)
                            if m.error <= max(smaller.error, front.layouts[k].error) + PRECISION]
            starts = [np.concatenate([np.atleast_2d(below.ratios).reshape(fine.n_poses, -1),
                                      np.atleast_2d(lay.realizable.ratios).reshape(fine.n_poses, -1)[:, -1:]], axis=1)
                      for lay in more_layouts]
            for lay, more in zip(more_layouts, _mapped(workers, task, list(zip(more_layouts, starts)))):
                if more is not None and (res is None or more.pose_error_rel < res.pose_error_rel):
                    front.layouts[k], res = lay, more
        out[k] = res
    front.evaluations += search.out.evaluations
    front.screened += search.out.screened
    front.route_evaluations += search.out.route_evaluations
    front.route_s += search.out.route_s
    return out


def _least_costly_there(search: _Search, front: Front, solved: FineSolves) -> dict[int, RealizableResult | None]:
    """Per count, of the layout held and every other one finished for it, the least
    costly on the finer mesh (``solved``; the one held on ties) made the count's, in
    place, and its as-built robot there (None where none can be solved); the
    search's workers share the solves not started yet."""
    size = search.problem.size
    choices = {}
    for k in sorted(front.layouts):
        key = _key(front.layouts[k], size)
        choices[k] = [front.layouts[k]] + [m for m in front.finished.get(k, []) if _key(m, size) != key]
    jobs = [lay for k in sorted(choices) for lay in choices[k]]
    if len(jobs) > len(choices):
        search.log(f"front: the {len(jobs)} finished layouts on the finer mesh")
    found = dict(zip(map(id, jobs), solved.results(jobs)))
    there: dict[int, RealizableResult | None] = {}
    for k in sorted(front.layouts):
        held, others = choices[k][0], choices[k][1:]
        res = found[id(held)]
        best = np.inf if res is None else search.cost(held.routes, res.pose_error_rel)
        for lay in others:
            got = found[id(lay)]
            cost = np.inf if got is None else search.cost(lay.routes, got.pose_error_rel)
            if cost < best - PRECISION ** 2:
                front.layouts[k], res, best = lay, got, cost
        there[k] = res
    return there


def _refit(search: _Search, front: Front, there: dict[int, RealizableResult | None], fine: Problem,
           fine_state: IdealizedState) -> None:
    """Each count's routes optimized again on the finer mesh ``fine`` (one round, from
    its robot solved there, ``there[k]``), in place: where that lowers its cost there,
    the new routes, solved on the design mesh from their new contractions, become the
    count's layout and ``there[k]`` their robot on ``fine``. Route optimization on one
    mesh fits that mesh's discretization too (gripper_planted_3t_s2 at level 1: two
    tendons 1e-6 L on level 1, 0.40 % of L on level 2 as they are, 1e-6 L there once
    optimized again); the finer mesh's fit is nearer the body's. The search's workers
    share the optimizations."""
    counts = [k for k in sorted(front.layouts) if there[k] is not None and front.layouts[k].routes]
    if not counts or not search.options.refine:
        return
    fine_search = _Search(search.context.on(fine, fine_state), search.options, search.rs, "front")
    fine_search.out = search.out
    search.log(f"front: the routes of {len(counts)} layout(s) optimized again on the finer mesh")
    starts = [Layout(front.layouts[k].routes, there[k], fine_search.cost(front.layouts[k].routes,
                                                                        there[k].pose_error_rel),
                     front.layouts[k].source) for k in counts]
    done = fine_search.each(partial(_refitted, fine_search), _refit_task, [(lay,) for lay in starts])
    changed = [(k, lay) for k, lay, was in zip(counts, done, starts) if lay.cost < was.cost]
    P = search.problem.n_poses
    coarse = search.each(search.solve, _solve_task,
                         [(lay.routes, np.atleast_2d(lay.realizable.ratios).reshape(P, -1), front.layouts[k])
                          for k, lay in changed])
    for (k, lay), here in zip(changed, coarse):
        if here is not None:
            front.layouts[k] = replace(here, source=front.layouts[k].source, optimized=True)
            there[k] = lay.realizable
            front.refit.append(k)


def _refitted(search: _Search, layout: Layout) -> Layout:
    """``layout`` (solved on the search's mesh) with its routes optimized there, one round."""
    return search.optimize(layout, 1)


def _refit_task(spec: tuple, job: tuple[Layout]) -> tuple[Layout, dict]:
    """:func:`_refitted` as a worker process runs it."""
    search = _Search.again(spec, job[0])
    return _refitted(search, job[0]), search.tally()


def _fine_task(fine: Context, job: tuple[Layout, np.ndarray | None]) -> RealizableResult | None:
    """:func:`converged_error` (``fine``: the finer problem, its pose-only state, the
    settings and the solver; ``job``: the layout and where to start), None where
    it cannot be solved."""
    try:
        return converged_error(fine, job[0], job[1])
    except ConvergenceError:
        return None
