"""Smooth joins of two routes end to end, and which pairs of a layout's routes
are partners for one (``docs/method.md``, consolidation): what consolidation's
reductions and the front's search join."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..body.problem import Problem
from .clearance import held_clearance, keeps_as_much
from .exits import exit_route
from .routes import Route, join_routes

#: a route is joined only with its JOIN_PARTNERS nearest routes (by the distance between their
#: nearest ends), so a layout of n routes has O(n) joins, not O(n^2); with at most
#: JOIN_PARTNERS + 1 routes every pair is a partner
JOIN_PARTNERS = 3


def join_key(route: Route) -> tuple:
    """What of ``route`` its joins are made from (:func:`joined_routes`): its core's curve
    and strand tension, and the clearance it is held to - not its contraction or
    source."""
    core = route.inner()
    return (core.control.tobytes(), core.control.shape, core.samples, core.tension, core.tension_std,
            route.kept_clearance)


def smooth_joins(a: Route, b: Route, problem: Problem, reach: float, clearance: float) -> list[Route]:
    """Every smooth join of ``a`` and ``b`` end to end (either end of each) whose
    ends are within ``reach`` (m) and that keeps the ``clearance`` (m; as much of it
    as the one of them that keeps less, where one is flagged); where routes leave
    the body, of their cores, carried out of the body again (:func:`~.exits.exit_route`)."""
    def near(a2: Route, b2: Route) -> bool:
        return np.linalg.norm(a2.control[-1] - b2.control[0]) <= reach

    return list(joined_routes(a, b, problem, clearance, near))


def joined_routes(a: Route, b: Route, problem: Problem, clearance: float, joinable: Callable[[Route, Route], bool]):
    """The smooth joins of ``a`` and ``b`` (their cores) in each end-to-end orientation
    ``joinable(a2, b2)`` allows (``a2`` ends at the joint, ``b2`` starts there), made
    as :func:`smooth_joins` says, one at a time: those that keep as much clearance as
    the one of ``a`` and ``b`` that keeps less."""
    least = min(held_clearance(a, clearance), held_clearance(b, clearance))
    a, b = a.inner(), b.inner()  # routes that leave the body are joined without their runs out
    for a2 in (a, a.reversed()):
        for b2 in (b, b.reversed()):
            if joinable(a2, b2):
                joined = exit_route(join_routes(a2, b2, problem.size), problem, clearance)
                if keeps_as_much(joined, least, clearance):
                    yield joined


def end_distances(routes: list[Route]) -> np.ndarray:
    """(T, T): the least distance between an end of route i and an end of route j
    (cores' ends for routes that leave the body; inf on the diagonal)."""
    ends = np.array([r.inner().control[[0, -1]] for r in routes]).reshape(len(routes), 2, -1)
    d = np.linalg.norm(ends[:, None, :, None, :] - ends[None, :, None, :, :], axis=-1).min(axis=(2, 3))
    np.fill_diagonal(d, np.inf)
    return d


def partner_pairs(routes: list[Route], partners: int = JOIN_PARTNERS) -> list[tuple[int, int]]:
    """The pairs (i, j), i < j, in order, where j is among i's ``partners`` nearest
    routes (:func:`end_distances`) or i among j's: at most ``partners`` x T pairs of
    T routes, every pair where T <= partners + 1."""
    n = len(routes)
    if n <= partners + 1:
        return [(i, j) for i in range(n) for j in range(i + 1, n)]
    near = np.argsort(end_distances(routes), axis=1, kind="stable")[:, :partners]
    pairs = {(min(i, int(j)), max(i, int(j))) for i in range(n) for j in near[i]}
    return sorted(pairs)
