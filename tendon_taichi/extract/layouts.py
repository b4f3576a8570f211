"""What the front (:mod:`.front`) says of routes and layouts: whether two routes
are one (:func:`same_route`), a pool without near duplicates, which extractors a
layout came from, a layout's identity and the least costly distinct layouts."""

from __future__ import annotations

import numpy as np

from .consolidation import Layout
from .routes import Route, resample

#: two routes closer than this (mean distance between their resampled polylines, x L) are one route
SAME_ROUTE = 0.02


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


def layout_key(layout: Layout, size: float) -> tuple:
    """A layout's identity: its routes' control points (to 1e-4 L), in any order."""
    return tuple(sorted(np.round(r.control / size, 4).tobytes() for r in layout.routes))


def best_layouts(layouts: list[Layout], n: int, size: float) -> list[Layout]:
    """The ``n`` distinct layouts of least cost."""
    out, seen = [], set()
    for lay in sorted(layouts, key=lambda lay: lay.cost):
        k = layout_key(lay, size)
        if k not in seen:
            seen.add(k)
            out.append(lay)
        if len(out) == n:
            break
    return out
