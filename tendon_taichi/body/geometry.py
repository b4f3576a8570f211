"""Plane geometry on polygons and segments: orientation and predicates of the
outline and holes, distances to segments (shapely), and where a set of
segments crosses a mesh boundary (numpy, vectorized)."""

from __future__ import annotations

import numpy as np
import shapely


def bbox_diagonal(points: np.ndarray) -> float:
    """The diagonal of the bounding box of ``points`` (k, dim), m: the body size L
    when they are a body's."""
    return float(np.linalg.norm(np.ptp(points, axis=0)))


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


def _spike(poly: np.ndarray, scale: float) -> bool:
    """Two adjacent edges folding back onto each other."""
    a, b, c = poly, np.roll(poly, -1, axis=0), np.roll(poly, -2, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    back = ((b - a) * (c - b)).sum(axis=1) < 0
    return bool(np.any((np.abs(cross) <= 1e-12 * scale * scale) & back))


def polygon_self_intersects(poly: np.ndarray) -> bool:
    """True for a degenerate polygon (repeated points, zero area, spikes) or one whose
    edges cross or touch anywhere but at shared corners."""
    poly = normalize_polygon(poly)
    k = len(poly)
    scale = np.ptp(poly, axis=0).max()
    if k < 3 or scale == 0.0 or abs(signed_area(poly)) <= 1e-12 * scale * scale:
        return True
    edges = np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)
    if edges.min() <= 1e-12 * scale or _spike(poly, scale):
        return True
    return not shapely.LinearRing(poly).is_simple


#: a polygon whose mean width (2 area / perimeter) is below this fraction of its extent is
#: too thin to mesh: a quality triangulation needs elements as small as the width
MIN_WIDTH_RATIO = 1e-4


def polygon_too_thin(poly: np.ndarray) -> float | None:
    """The mean width 2 A / P (m) of a polygon (k, 2) thinner than :data:`MIN_WIDTH_RATIO`
    of its extent (triangle would refine it almost without end), else None."""
    poly = normalize_polygon(poly)
    perimeter = float(np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1).sum())
    width = 2.0 * abs(signed_area(poly)) / perimeter
    return width if width < MIN_WIDTH_RATIO * np.ptp(poly, axis=0).max() else None


def points_in_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Whether each point lies strictly inside the polygon (k, 2): bool (q,); points
    on its boundary are outside."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    return shapely.contains_xy(shapely.Polygon(poly), p[:, 0], p[:, 1])


def polygons_overlap(outline: np.ndarray, holes) -> str | None:
    """Describe the first way ``holes`` fail to lie strictly inside ``outline`` and
    apart from each other, or None when they are fine."""
    body = shapely.Polygon(outline)
    rings = [shapely.Polygon(h) for h in holes]
    for i, hole in enumerate(rings):
        if not body.contains(hole):
            return f"holes[{i}] is not inside the outline"
        if hole.boundary.intersects(body.boundary):
            return f"holes[{i}] touches or crosses the outline"
        for j, other in enumerate(rings):
            if j == i:
                continue
            if hole.boundary.intersects(other.boundary):
                return f"holes[{i}] touches or crosses holes[{j}]"
            if hole.contains(other):
                return f"holes[{j}] lies inside holes[{i}]"
    return None


def outline_meets_box(outline: np.ndarray, lo, hi) -> bool:
    """Whether a closed outline (k, 2) crosses or touches the box with corners ``lo``, ``hi``."""
    return bool(shapely.LinearRing(np.asarray(outline, dtype=float)).intersects(shapely.box(*lo, *hi)))


def segments(a: np.ndarray, b: np.ndarray):
    """The segments a[j] -> b[j] (e, 2) as one shapely geometry (for distances)."""
    return shapely.multilinestrings(np.stack([a, b], axis=1))


def distance_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray, lines=None) -> np.ndarray:
    """Distance (q,) from points (q, 2) to the nearest of segments a[j] -> b[j] (e, 2)
    (or to ``lines``, those segments made once by :func:`segments`); inf when there is
    no segment."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(a) == 0:
        return np.full(len(p), np.inf)
    return shapely.distance(shapely.points(p), segments(a, b) if lines is None else lines)


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


class PolygonWalls:
    """The walls of a 2D body - its outline and holes - as one shapely polygon, for
    the clearance of tendon routes: signed distances of points from the nearest wall
    (positive inside the body) and their gradients; the plane's implementation of
    the walls protocol (:class:`~.walls.Walls`)."""

    def __init__(self, polygon):
        self.polygon = polygon
        self.boundary = polygon.boundary
        shapely.prepare(self.polygon)

    @classmethod
    def from_outline(cls, outline: np.ndarray, holes) -> "PolygonWalls":
        return cls(shapely.Polygon(outline, [np.asarray(h) for h in holes]))

    @classmethod
    def from_triangles(cls, corners: np.ndarray) -> "PolygonWalls":
        """From a mesh's triangles (m, 3, 2): their union."""
        return cls(shapely.union_all(shapely.polygons(corners)))

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (q,) of points (q, 2) from the nearest wall, m: positive
        inside the body, negative outside."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        d = shapely.distance(shapely.points(p), self.boundary)
        return np.where(self.inside(p), d, -d)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """bool (q,): whether each point (q, 2) lies in the body, its walls included."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return shapely.intersects_xy(self.polygon, p[:, 0], p[:, 1])

    def distance_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances (q,) and their gradients (q, 2): the unit vector from the
        nearest wall point to each point (away from the wall, into the body); for a
        point on a wall, the signed distance's central difference."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        d = self.distance(p)
        lines = shapely.shortest_line(shapely.points(p), self.boundary)
        near = shapely.get_coordinates(lines).reshape(-1, 2, 2)[:, 1]
        away = p - near
        norm = np.linalg.norm(away, axis=1)
        g = np.where(norm[:, None] > 0, away / np.maximum(norm, 1e-300)[:, None], 0.0)
        g = np.where(d[:, None] < 0, -g, g)
        on = norm <= 1e-12 * max(float(np.ptp(np.asarray(self.boundary.bounds).reshape(2, 2), axis=0).max()), 1e-300)
        if on.any():
            h = 1e-7 * float(np.ptp(np.asarray(self.boundary.bounds).reshape(2, 2), axis=0).max())
            q = p[on]
            fd = np.stack([(self.distance(q + e) - self.distance(q - e)) / (2 * h) for e in (h * np.eye(2))], 1)
            g[on] = fd / np.maximum(np.linalg.norm(fd, axis=1), 1e-300)[:, None]
        return d, g

    def polyline_distance(self, points: np.ndarray) -> float:
        """The least distance (m) of a polyline (k, 2) from the walls (its segments
        included), negative when it leaves the body."""
        line = shapely.LineString(np.asarray(points, dtype=float))
        d = float(shapely.distance(line, self.boundary))
        return d if shapely.covers(self.polygon, line) else -d
