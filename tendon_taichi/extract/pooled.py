"""Layouts from the front's pool of routes (:mod:`.front`, "exhaustive low
counts"): every pooled route alone and every smooth join of two partners, and
the 2-tendon sets - all of them from a small pool; from a pool of more than
``PAIR_POOL``, the pairs among the routes the Gauss-Newton screen ranks best
alone and each route with the best, so their number grows linearly with the
pool, not with its square."""

from __future__ import annotations

from dataclasses import replace
from itertools import combinations

import numpy as np

from .consolidation import Candidate, Layout, _Search, partner_pairs
from .layouts import best_layouts, layout_key, sources
from .routes import Route

#: above this many pooled routes, the 2-tendon sets are the pairs among the PAIR_POOL single
#: routes the Gauss-Newton screen ranks best and each route with the best one
#: (:func:`screened_pairs`): O(n) sets of n pooled routes, not O(n^2)
PAIR_POOL = 7


def pooled_candidates(search: _Search, pool: list[Route], k: int,
                      among: list[tuple[int, ...]] | None = None) -> list[Candidate]:
    """The layouts of ``k`` routes from the pool: for k = 1 each pooled route alone
    ('route') and each smooth join of two partners (:func:`~.consolidation.partner_pairs`)
    within the search's gap ('join'), for k > 1 each set of k pooled routes ('set'),
    or those ``among`` (index tuples) where given; each to start from the
    contractions that give its routes their strands' tensions in every pose."""
    if k > 1:
        sets = combinations(range(len(pool)), k) if among is None else among
        return [_candidate(search, "set", ids, [pool[i] for i in ids]) for ids in sets]
    reach, clearance = search.options.gap * search.problem.size, search.rs.clearance
    out = _singles(search, pool)
    pairs = partner_pairs(pool)
    search.make_joins([(pool[i], pool[j]) for i, j in pairs], reach, clearance)
    for i, j in pairs:
        out += [_candidate(search, "join", (i, j), [joined])
                for joined in search.joins(pool[i], pool[j], reach, clearance)]
    return out


def _candidate(search: _Search, action: str, ids: tuple[int, ...], routes: list[Route]) -> Candidate:
    """A pooled layout to start from the contractions that give its routes their
    strands' tensions in every pose."""
    tensions = np.tile([r.tension for r in routes], (search.problem.n_poses, 1))
    return Candidate(action, ids, routes, search.start_ratios(routes, tensions))


def _singles(search: _Search, pool: list[Route]) -> list[Candidate]:
    """Each pooled route alone ('route'), in pool order."""
    return [_candidate(search, "route", (i,), [r]) for i, r in enumerate(pool)]


def screened_pairs(search: _Search, pool: list[Route], near: Layout) -> list[tuple[int, int]] | None:
    """The 2-tendon sets worth screening from a pool of more than ``PAIR_POOL`` routes:
    the pairs among the ``PAIR_POOL`` routes whose single layouts the Gauss-Newton
    screen ranks best (from ``near``'s equilibria), and each route with the best of
    them; None (every pair) for a smaller pool."""
    if len(pool) <= PAIR_POOL:
        return None
    found = search.predicted(_singles(search, pool), near)
    costs = np.array([np.inf if cost is None else cost for cost, _ in found])
    order = [int(i) for i in np.argsort(costs, kind="stable")]
    best = order[:PAIR_POOL]
    pairs = set(combinations(sorted(best), 2)) | {(min(order[0], i), max(order[0], i)) for i in order[1:]}
    return sorted(pairs)


def exhaustive_layouts(search: _Search, pool: list[Route], k: int, near: Layout) -> list[Layout]:
    """The pooled layouts of ``k`` routes (:func:`pooled_candidates`; for k = 2 from a
    large pool, the pairs :func:`screened_pairs` picks), screened by one Gauss-Newton step
    from ``near``'s equilibria, the best solved in full."""
    cands = pooled_candidates(search, pool, k, screened_pairs(search, pool, near) if k == 2 else None)
    search.log(f"front: {len(cands)} {k}-tendon layout(s) from the {len(pool)} pooled routes")
    ranked = search.ranked(cands, near)
    return [replace(lay, source=sources(lay.routes)) for _, lay in ranked]


def kept_layouts(layouts: list[Layout], n: int, size: float) -> list[Layout]:
    """The ``n`` least costly distinct layouts, and the one of least pose error
    besides: a fresh join's shape cost is that of a rough fit, which route
    optimization smooths away, and its pose error shows better what it can do."""
    out = best_layouts(layouts, n, size)
    closest = min(layouts, key=lambda lay: lay.error, default=None)
    if closest is not None and layout_key(closest, size) not in {layout_key(lay, size) for lay in out}:
        out.append(closest)
    return out
