"""Plane geometry on polygons and segments (numpy, vectorized where it matters)."""

from __future__ import annotations

import numpy as np


def signed_area(poly: np.ndarray) -> float:
    """Shoelace area of a closed polygon (k, 2); positive when counter-clockwise."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def normalize_polygon(poly: np.ndarray, ccw: bool = True) -> np.ndarray:
    """Drop a repeated closing point and orient the polygon as asked."""
    poly = np.asarray(poly, dtype=float)
    if len(poly) > 3 and np.allclose(poly[0], poly[-1]):
        poly = poly[:-1]
    if (signed_area(poly) > 0) != ccw:
        poly = poly[::-1]
    return np.ascontiguousarray(poly)


def _orient(a, b, c) -> float:
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def _on_segment(a, b, p, tol) -> bool:
    return (min(a[0], b[0]) - tol <= p[0] <= max(a[0], b[0]) + tol
            and min(a[1], b[1]) - tol <= p[1] <= max(a[1], b[1]) + tol)


def segments_intersect(p1, p2, q1, q2, tol: float = 0.0) -> bool:
    """Whether closed segments p1p2 and q1q2 share a point (touching counts)."""
    scale = max(np.ptp(np.array([p1, p2, q1, q2]), axis=0).max(), 1e-300)
    eps = tol * scale * scale
    d1, d2 = _orient(q1, q2, p1), _orient(q1, q2, p2)
    d3, d4 = _orient(p1, p2, q1), _orient(p1, p2, q2)
    if ((d1 > eps and d2 < -eps) or (d1 < -eps and d2 > eps)) and \
       ((d3 > eps and d4 < -eps) or (d3 < -eps and d4 > eps)):
        return True
    ts = tol * scale
    return ((abs(d1) <= eps and _on_segment(q1, q2, p1, ts)) or
            (abs(d2) <= eps and _on_segment(q1, q2, p2, ts)) or
            (abs(d3) <= eps and _on_segment(p1, p2, q1, ts)) or
            (abs(d4) <= eps and _on_segment(p1, p2, q2, ts)))


def polygon_self_intersects(poly: np.ndarray) -> bool:
    """True for a degenerate polygon (repeated points, zero area, spikes) or one whose
    edges cross or touch anywhere but at shared corners."""
    poly = normalize_polygon(poly)
    k = len(poly)
    scale = np.ptp(poly, axis=0).max()
    if k < 3 or scale == 0.0 or abs(signed_area(poly)) <= 1e-12 * scale * scale:
        return True
    edges = np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)
    if edges.min() <= 1e-12 * scale:
        return True
    for i in range(k):
        a, b = poly[i], poly[(i + 1) % k]
        c = poly[(i + 2) % k]
        # adjacent edges folding back onto each other (a spike)
        if abs(_orient(a, b, c)) <= 1e-12 * scale * scale and np.dot(b - a, c - b) < 0:
            return True
        for j in range(i + 2, k):
            if i == 0 and j == k - 1:
                continue
            if segments_intersect(a, b, poly[j], poly[(j + 1) % k], tol=1e-12):
                return True
    return False


def points_in_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd test (strict interior; boundary points are undefined): bool (k,)."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    x, y = p[:, 0:1], p[:, 1:2]
    a = poly[None, :, :]
    b = np.roll(poly, -1, axis=0)[None, :, :]
    ay, by = a[..., 1], b[..., 1]
    crosses = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = a[..., 0] + (y - ay) * (b[..., 0] - a[..., 0]) / (by - ay)
    return (np.sum(crosses & (x < xi), axis=1) % 2) == 1


def polygons_overlap(outline: np.ndarray, holes) -> str | None:
    """Describe the first way ``holes`` fail to lie strictly inside ``outline`` and
    apart from each other, or None when they are fine."""
    polys = [outline, *holes]
    for i, hole in enumerate(holes):
        if not np.all(points_in_polygon(hole, outline)):
            return f"holes[{i}] is not inside the outline"
        for j, other in enumerate(polys):
            if j == i + 1:
                continue
            for a, b in zip(hole, np.roll(hole, -1, axis=0)):
                for c, d in zip(other, np.roll(other, -1, axis=0)):
                    if segments_intersect(a, b, c, d, tol=1e-12):
                        what = "the outline" if j == 0 else f"holes[{j - 1}]"
                        return f"holes[{i}] touches or crosses {what}"
        for j, other in enumerate(holes):
            if j != i and np.any(points_in_polygon(other, hole)):
                return f"holes[{j}] lies inside holes[{i}]"
    return None


def segment_params_on_edges(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray,
                            tol: float) -> list[np.ndarray]:
    """For segments p0[i]->p1[i] (s, 2) and edges q0[j]->q1[j] (e, 2): per segment the
    parameters t in [0, 1] where it meets any edge (crossing, touching, or the ends
    of a collinear overlap). ``tol`` is a length."""
    d = p1 - p0  # (s, 2)
    e = q1 - q0  # (e, 2)
    w = q0[None, :, :] - p0[:, None, :]  # (s, e, 2)
    denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # cross(d, e)
    cross_we = w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]
    cross_wd = w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]
    dl = np.linalg.norm(d, axis=1)[:, None]
    el = np.linalg.norm(e, axis=1)[None, :]
    parallel = np.abs(denom) <= 1e-12 * dl * el
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(parallel, np.nan, cross_we / denom)
        u = np.where(parallel, np.nan, cross_wd / denom)
    tt, ut = tol / np.maximum(dl, 1e-300), tol / np.maximum(el, 1e-300)
    hit = (~parallel) & (t >= -tt) & (t <= 1 + tt) & (u >= -ut) & (u <= 1 + ut)
    # collinear overlaps: project the edge ends onto the segment
    dist_line = np.abs(cross_we) / np.maximum(el, 1e-300)  # distance of p0 from the edge's line
    coll = parallel & (dist_line <= tol)
    dd = np.maximum((d * d).sum(axis=1), 1e-300)[:, None]
    t0 = ((q0[None, :, :] - p0[:, None, :]) * d[:, None, :]).sum(-1) / dd
    t1 = ((q1[None, :, :] - p0[:, None, :]) * d[:, None, :]).sum(-1) / dd
    out = []
    for i in range(len(p0)):
        ts = list(t[i, hit[i]])
        if coll[i].any():
            for a, b in zip(t0[i, coll[i]], t1[i, coll[i]]):
                lo, hi = min(a, b), max(a, b)
                if hi >= -tt[i, 0] and lo <= 1 + tt[i, 0]:
                    ts.extend([lo, hi])
        out.append(np.clip(np.array(ts, dtype=float), 0.0, 1.0))
    return out
