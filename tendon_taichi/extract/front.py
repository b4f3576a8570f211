"""The count/error front: for every tendon count k, the best k-tendon layout found,
its routes optimized (``docs/method.md``, "The front").

Greedy consolidation (:mod:`.consolidation`) walks one path from an extractor's
tendons down to few: which layout of a given count it reaches depends on the
lattice the tendons came from. The front searches wider, from every extractor's
tendons together:

* **seeds**: every layout each extractor's consolidation passed through, and the
  *pooled* layout - the union of every extractor's consolidated routes, near
  duplicates (:func:`same_route`) kept once;
* **beam search**: from the most tendons down, the ``beam`` best distinct layouts
  of each count (by effective error, the as-built error with the pull lost to
  friction priced in - what consolidation ranks by) are each reduced by every
  drop and smooth join (screened by one Gauss-Newton step, the best solved in
  full), and the results compete with the seeds of the count below;
* **finish**: the best layout of each count is oriented and its routes
  optimized (control points, ends and contractions): ``refine`` rounds up to
  the first count within the budget, one round above it;
* **monotone**: where a count's layout has a larger as-built error than the one
  below (by more than the soft IK's precision, ``PRECISION``), the smaller layout with one more pooled route added is solved and kept
  when it does better - a tendon more never makes the best layout found worse.

Because a greedy layout of each count is among the seeds, the front is never
worse than greedy consolidation at any count (in effective error).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..body.problem import Problem
from ..objective.settings import OptimizeSettings
from .consolidation import Candidate, Consolidation, Layout, _Search, route_settings
from .protocol import IdealizedState
from .realizable import RealizableResult, solve_realizable_poses
from .routes import Route, resample
from .settings import BEAM, ConsolidationSettings

#: the as-built soft IK's precision (x L): errors closer than this are equal
PRECISION = 1e-6
#: two routes closer than this (mean distance between their resampled polylines, x L) are one route
SAME_ROUTE = 0.02


@dataclass
class Front:
    """The best layout found per tendon count (``layouts``, finished), and what the
    search cost: ``seeds`` layouts it started from, ``pool`` distinct routes,
    ``evaluations`` layouts solved in full, ``screened`` candidates screened,
    ``route_evaluations`` equilibria of route optimization in ``route_s`` seconds,
    ``time_s`` in all."""

    layouts: dict[int, Layout] = field(default_factory=dict)
    seeds: int = 0
    pool: int = 0
    evaluations: int = 0
    screened: int = 0
    route_evaluations: int = 0
    route_s: float = 0.0
    time_s: float = 0.0

    def as_json(self) -> dict:
        return {"counts": sorted(self.layouts), "seeds": self.seeds, "pool": self.pool,
                "evaluations": self.evaluations, "screened": self.screened,
                "route_evaluations": self.route_evaluations, "route_s": self.route_s, "time_s": self.time_s}


def same_route(a: Route, b: Route, size: float, tol: float = SAME_ROUTE) -> bool:
    """Whether two routes run along the same curve (either way round): the mean
    distance between their polylines, resampled at 32 points, is below ``tol`` x L."""
    pa = resample(a.waypoints, 32)[0]
    pb = resample(b.waypoints, 32)[0]
    d = min(np.linalg.norm(pa - pb, axis=1).mean(), np.linalg.norm(pa - pb[::-1], axis=1).mean())
    return bool(d < tol * size)


def distinct_routes(routes: list[Route], size: float) -> list[Route]:
    """``routes`` with near duplicates (:func:`same_route`) kept once, the first seen."""
    out: list[Route] = []
    for r in routes:
        if not any(same_route(r, q, size) for q in out):
            out.append(r)
    return out


def sources(routes: list[Route]) -> str:
    """The extractors a layout's routes came from, joined by '+'."""
    return "+".join(sorted({r.source for r in routes if r.source})) or "front"


def _key(layout: Layout, size: float) -> tuple:
    """A layout's identity: its routes' control points (to 1e-4 L), in any order."""
    return tuple(sorted(np.round(r.control / size, 4).tobytes() for r in layout.routes))


def _best(layouts: list[Layout], n: int, size: float) -> list[Layout]:
    """The ``n`` distinct layouts of least cost."""
    out, seen = [], set()
    for lay in sorted(layouts, key=lambda lay: lay.cost):
        k = _key(lay, size)
        if k not in seen:
            seen.add(k)
            out.append(lay)
        if len(out) == n:
            break
    return out


def search_front(problem: Problem, state: IdealizedState, settings: OptimizeSettings,
                 consolidations: list[Consolidation], options: ConsolidationSettings, solver: str = "auto",
                 max_tendons: int | None = None, beam: int = BEAM,
                 log: Callable[[str], None] | None = None) -> Front:
    """The front (module docstring) from the extractors' ``consolidations``: per count
    1 .. the most any seed has (at most ``max_tendons``), the best layout found,
    finished. With consolidation off (``options.enabled`` false), the seeds as they
    are, no search."""
    t0 = time.perf_counter()
    say = log or (lambda text: None)
    search = _Search(problem, state, settings, solver, options, route_settings(problem, options), "front", log)
    search.out = tally = Consolidation(consolidations[0].layout, 0, 0.0)
    size = problem.size
    by_count: dict[int, list[Layout]] = {}
    for c in consolidations:
        for lay in c.front.values():
            by_count.setdefault(lay.count, []).append(lay)
    pool = distinct_routes([r for c in consolidations for r in c.layout.routes]
                           + [r for c in consolidations for lay in c.front.values() for r in lay.routes], size)
    pooled = _pooled(search, consolidations, size)
    if pooled is not None:
        by_count.setdefault(pooled.count, []).append(pooled)
    front = Front(seeds=sum(len(v) for v in by_count.values()), pool=len(pool))
    if not options.enabled:  # the extracted tendons' fitted routes as they are
        front.layouts = {k: _best(v, 1, size)[0] for k, v in sorted(by_count.items())
                         if max_tendons is None or k <= max_tendons}
        front.time_s = time.perf_counter() - t0
        return front
    top = max(by_count)
    say(f"front: beam search from {top} tendon(s), {front.seeds} seed layouts, {len(pool)} distinct routes")
    for k in range(top, 0, -1):
        by_count[k] = _best(by_count.get(k, []), beam, size)
        if k == 1:
            break
        for lay in by_count[k]:
            reduced = [replace(r, source=sources(r.routes)) for _, r in search.ranked(search.reductions(lay), lay)]
            by_count.setdefault(k - 1, []).extend(reduced[:beam])
    counts = [k for k in sorted(by_count) if by_count[k] and (max_tendons is None or k <= max_tendons)]
    within = False
    for k in counts:
        lay = by_count[k][0]
        if not lay.optimized:
            say(f"front: optimizing the routes of the best {k}-tendon layout")
            rounds = 1 if within else options.refine
            lay = replace(search.finish(lay, rounds)[0], source=sources(lay.routes))
        if k > 1 and k - 1 in front.layouts and lay.error > front.layouts[k - 1].error + PRECISION:
            lay = _one_more(search, front.layouts[k - 1], pool, lay, size)
        front.layouts[k] = lay
        within = within or lay.error <= options.budget
    front.evaluations, front.screened = tally.evaluations, tally.screened
    front.route_evaluations, front.route_s = tally.route_evaluations, tally.route_s
    front.time_s = time.perf_counter() - t0
    return front


def _pooled(search: _Search, consolidations: list[Consolidation], size: float) -> Layout | None:
    """The union of every extractor's consolidated routes (near duplicates once),
    solved from each route's contractions in its own layout; None when it adds
    nothing to the seeds (one extractor, or all found the same routes)."""
    routes, starts = [], []
    for c in consolidations:
        ratios = np.atleast_2d(c.layout.realizable.ratios).reshape(search.problem.n_poses, -1)
        for i, r in enumerate(c.layout.routes):
            if not any(same_route(r, q, size) for q in routes):
                routes.append(r)
                starts.append(ratios[:, i])
    if len(routes) <= max(c.layout.count for c in consolidations):
        return None
    lay = search.solve(routes, np.array(starts).T)
    return None if lay is None else replace(lay, source=sources(routes))


def _one_more(search: _Search, below: Layout, pool: list[Route], now: Layout, size: float) -> Layout:
    """The better of ``now`` and the layout ``below`` (one tendon fewer) with one
    more pooled route, the least costly as the Gauss-Newton screen predicts it,
    solved from ``below``'s contractions and equilibria."""
    extra = [r for r in pool if not any(same_route(r, q, size) for q in below.routes)]
    if not extra:
        return now
    start = np.atleast_2d(below.realizable.ratios).reshape(search.problem.n_poses, -1)
    cands = []
    for r in extra:
        add = search.start_ratios([r], np.full((search.problem.n_poses, 1), r.tension))
        cands.append(Candidate("add", (), below.routes + [r], np.concatenate([start, add], axis=1)))
    ranked = search.ranked(cands, below)
    if ranked and ranked[0][1].error < now.error:
        return replace(ranked[0][1], source=sources(ranked[0][1].routes))
    return now


def pose_only_state(problem: Problem) -> IdealizedState:
    """An idealized state that gives only ``problem``'s poses (no tensions, the rest
    shape): what a layout's as-built robot needs when its contractions are given."""
    f = problem.fibers.n_fibers
    one = IdealizedState(np.zeros(f), np.zeros(f), None, 0.0)
    return replace(one, poses=[one] * problem.n_poses) if problem.n_poses > 1 else one


def converged_error(fine: Problem, layout: Layout, state: IdealizedState, settings: OptimizeSettings,
                    solver: str = "auto") -> RealizableResult:
    """A layout's as-built robot on a finer mesh of the same body (``fine``; ``state``
    from :func:`pose_only_state`): its routes, which do not depend on the mesh,
    embedded in that mesh and their contractions solved again from the layout's."""
    start = np.atleast_2d(layout.realizable.ratios).reshape(fine.n_poses, -1)
    return solve_realizable_poses(fine, layout.tendons(), state, settings, solver, start)
