"""The search stays cheap when the extractors over-segment: pieces of one strand
are merged before any layout is solved, a route is joined only with its
nearest partners, and the 2-tendon sets of a large pool are the pairs among the
best few - so the candidates grow at most linearly with the extracted count."""

from itertools import combinations

import numpy as np
import pytest

from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import load_scene
from tendon_taichi.extract.consolidation import (JOIN_PARTNERS, Layout, _Search, merge_pieces, partner_pairs,
                                                 route_settings)
from tendon_taichi.extract.context import Context
from tendon_taichi.extract.pooled import PAIR_POOL, pooled_candidates, screened_pairs
from tendon_taichi.extract.protocol import IdealizedState
from tendon_taichi.extract.realizable import RealizableResult
from tendon_taichi.extract.routes import fit_route
from tendon_taichi.extract.settings import ConsolidationSettings


@pytest.fixture(scope="module")
def finger():
    return build_problem(load_scene("finger"), 1)


def _pieces(y: float, n: int, gap: float = 0.001, x0: float = 0.01, x1: float = 0.09, bend: float = 0.0):
    """A strand along y (gently bent by ``bend`` m) cut into n pieces ``gap`` m apart, as points (k, 2) each."""
    edges = np.linspace(x0, x1, n + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:]):
        x = np.linspace(a + gap / 2, b - gap / 2, 6)
        out.append(np.stack([x, y + bend * np.sin(np.pi * (x - x0) / (x1 - x0))], axis=1))
    return out


def _search(problem):
    state = IdealizedState(np.zeros(problem.fibers.n_fibers), np.zeros(problem.fibers.n_fibers), None, 0.0)
    options = ConsolidationSettings()
    return _Search(Context(problem, state, problem.scene.optimize), options, route_settings(problem, options), "t")


def _layout(routes):
    T = len(routes)
    real = RealizableResult(np.zeros(T), np.full(T, 0.05), np.ones(T), None, 0.0, 0.0, 0.0, 0, 0, 0.0)
    return Layout(routes, real, 0.0, "t")


@pytest.mark.parametrize("n", [2, 4, 8])
def test_the_pieces_of_one_strand_merge_into_one_route(finger, n):
    h = finger.scene.tendons.clearance * finger.size
    pieces = [fit_route(p, finger.size, tension=0.3 + 0.01 * i) for i, p in enumerate(_pieces(0.015, n, bend=0.002))]
    order = np.random.default_rng(n).permutation(n)  # in any order, either way round
    given = [pieces[i] if i % 2 else pieces[i].reversed() for i in order]
    routes, tensions = merge_pieces(given, np.array([[r.tension for r in given]]), finger, h)
    assert len(routes) == 1 and tensions.shape == (1, 1)
    w = routes[0].waypoints
    assert sorted([w[0, 0], w[-1, 0]]) == pytest.approx([0.0105, 0.0895], abs=1e-9)  # end to end
    assert 0.3 <= tensions[0, 0] <= 0.3 + 0.01 * (n - 1)


def test_no_route_or_one_is_left_as_it_is(finger):
    h = finger.scene.tendons.clearance * finger.size
    assert merge_pieces([], np.zeros((1, 0)), finger, h)[0] == []
    one = [fit_route(np.array([[0.02, 0.01], [0.05, 0.01]]), finger.size)]
    assert merge_pieces(one, np.ones((1, 1)), finger, h)[0] == one


def test_strands_side_by_side_or_across_are_not_merged(finger):
    h = finger.scene.tendons.clearance * finger.size
    two = [fit_route(p, finger.size) for y in (0.006, 0.014) for p in _pieces(y, 3)]
    routes, _ = merge_pieces(two, np.ones((1, 6)), finger, h)
    assert len(routes) == 2  # each strand whole, the two apart
    across = [fit_route(np.array([[0.02, 0.01], [0.05, 0.01]]), finger.size),
              fit_route(np.array([[0.0505, 0.005], [0.0505, 0.016]]), finger.size)]
    assert len(merge_pieces(across, np.ones((1, 2)), finger, h)[0]) == 2  # touching, but at a right angle


@pytest.mark.parametrize("n", [3, 4, 5, 9, 16, 30])
def test_a_route_has_at_most_its_partners_and_small_layouts_keep_every_pair(n):
    rng = np.random.default_rng(n)
    routes = [fit_route(rng.uniform(0, 0.1, (2, 2)), 0.1) for _ in range(n)]
    pairs = partner_pairs(routes)
    assert pairs == sorted(set(pairs)) and all(i < j for i, j in pairs)
    assert len(pairs) <= JOIN_PARTNERS * n
    if n <= JOIN_PARTNERS + 1:
        assert pairs == list(combinations(range(n), 2))


def test_the_candidates_grow_linearly_with_an_over_segmented_count(finger):
    """Drops and joins of a layout of n pieces (three strands, each cut into n / 3),
    and the one-route candidates of a pool of them: at most a constant times n."""
    search = _search(finger)
    counts = []
    for n in (3, 6, 12, 24):
        pieces = [fit_route(p, finger.size, tension=0.3) for y in (0.005, 0.01, 0.015)
                  for p in _pieces(y, n // 3, gap=0.004)]
        reductions = search.reductions(_layout(pieces))
        singles_and_joins = pooled_candidates(search, pieces, 1)
        counts.append((n, len(reductions), len(singles_and_joins)))
    for n, red, pooled in counts:
        assert red <= (1 + 4 * JOIN_PARTNERS) * n and pooled <= (1 + 4 * JOIN_PARTNERS) * n, counts


@pytest.mark.parametrize("n", [5, 7, 8, 20])
def test_the_two_tendon_sets_of_a_large_pool_are_the_best_few_pairs(finger, monkeypatch, n):
    search = _search(finger)
    rng = np.random.default_rng(n)
    pool = [fit_route(np.array([[0.01 + 0.004 * i, 0.004], [0.01 + 0.004 * i, 0.016]]), finger.size)
            for i in range(n)]
    cost = rng.permutation(n).astype(float)  # what the screen says of each route alone
    monkeypatch.setattr(search, "predicted", lambda cands, near: [(cost[c.ids[0]], None) for c in cands])
    pairs = screened_pairs(search, pool, _layout(pool[:1]))
    if n <= PAIR_POOL:
        assert pairs is None  # every pair
        return
    best = set(np.argsort(cost)[:PAIR_POOL].tolist())
    top = int(np.argmin(cost))
    assert len(pairs) <= PAIR_POOL * (PAIR_POOL - 1) // 2 + n - 1
    assert set(combinations(sorted(best), 2)) <= set(pairs)
    assert all((i in best and j in best) or top in (i, j) for i, j in pairs)
    assert {(min(top, i), max(top, i)) for i in range(n) if i != top} <= set(pairs)
