"""Where a tendon may leave the body (``docs/method.md``, exits): the *exit set*
of a scene's ``[tendons] exit`` - the stretches of the outline inside a
``[[fixed]]`` box (``"clamp"``: the actuator sits behind the clamped base) or the
whole outline (``"surface"``) - as straight segments a route's pull end may lie
on. The outline is cut at its corners and every piece is kept ``zone`` (m) clear
of its ends, so that a route leaving through it does not graze the wall beside
it; ``zone`` is also the radius around an exit point within which a route need
not keep the clearance (it is leaving the body there: :class:`ExitWalls`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops

from ..errors import SceneError
from .scene import Scene
from .walls import Walls

#: a vertex of the outline that turns by more than this (rad) cuts an exit stretch in two
CORNER = np.radians(30.0)
#: the radius of the waived zone around an exit, in units of the clearance: a route that leaves
#: the wall at 30 degrees or more keeps the clearance outside it
ZONE = 2.0
#: within the zone the clearance is lifted by ``LIFT h - |p - e| / ZONE`` (h the clearance, e the exit)
LIFT = 1.01


@dataclass(frozen=True)
class ExitSet:
    """The segments ``segments`` (s, 2, dim), m, a route's pull end may lie on, of the
    scene's exit ``kind``, and the radius ``zone`` (m) of the waived zone around an exit."""

    kind: str
    segments: np.ndarray
    zone: float

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For points (q, dim): the nearest point of the set (q, dim), its distance (q,)
        and the index of its segment (q,)."""
        p = np.asarray(points, dtype=float).reshape(-1, self.segments.shape[2])
        a, b = self.segments[:, 0], self.segments[:, 1]
        ab = b - a
        t = np.einsum("qsd,sd->qs", p[:, None, :] - a[None], ab) / np.maximum((ab * ab).sum(axis=1), 1e-300)
        foot = a[None] + np.clip(t, 0.0, 1.0)[:, :, None] * ab[None]
        d = np.linalg.norm(p[:, None, :] - foot, axis=2)
        k = np.argmin(d, axis=1)
        q = np.arange(len(p))
        return foot[q, k], d[q, k], k


class ExitWalls:
    """The walls as a route leaving through ``exit`` (dim,) sees them: within ``zone``
    of the exit its distance from the walls is lifted by ``LIFT h - |p - e| / ZONE``
    (h the clearance), so that the points where it runs out through the wall keep
    the clearance while a route that leaves at 30 degrees or more is held to it
    everywhere else. Implements the walls protocol (:class:`~.walls.Walls`)."""

    def __init__(self, walls: Walls, exit: np.ndarray, clearance: float):
        self.walls, self.exit, self.clearance = walls, np.asarray(exit, dtype=float), clearance
        self.zone = ZONE * LIFT * clearance

    def lift(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The lift (q,) of points (q, dim) and its gradient (q, dim)."""
        r = np.asarray(points, dtype=float) - self.exit
        n = np.linalg.norm(r, axis=1)
        near = n < self.zone
        lift = np.where(near, LIFT * self.clearance - n / ZONE, 0.0)
        grad = np.where(near[:, None], -r / np.maximum(n, 1e-300)[:, None] / ZONE, 0.0)
        return lift, grad

    def distance(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float).reshape(-1, len(self.exit))
        return self.walls.distance(p) + self.lift(p)[0]

    def distance_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = np.asarray(points, dtype=float).reshape(-1, len(self.exit))
        d, g = self.walls.distance_gradient(p)
        lift, lg = self.lift(p)
        return d + lift, g + lg

    def inside(self, points: np.ndarray) -> np.ndarray:
        return self.walls.inside(points)

    def kept(self, points: np.ndarray) -> float:
        """The least distance (m) of a polyline (k, dim) from the walls outside the
        exit's zone (what its channel keeps before it runs out), at points 1/64 of
        the zone apart; negative where it leaves the body."""
        dense = self._dense(points)
        far = np.linalg.norm(dense - self.exit, axis=1) >= self.zone
        return float(self.walls.distance(dense[far]).min()) if far.any() else float(LIFT * self.clearance)

    def _dense(self, points: np.ndarray) -> np.ndarray:
        """A polyline (k, dim) resampled at points 1/64 of the zone apart."""
        p = np.asarray(points, dtype=float)
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
        if s[-1] <= 0:
            return p[:1]
        u = np.linspace(0, s[-1], max(2, int(np.ceil(64 * s[-1] / self.zone)) + 1))
        return np.stack([np.interp(u, s, p[:, d]) for d in range(p.shape[1])], axis=1)

    def polyline_distance(self, points: np.ndarray) -> float:
        """The least lifted distance of a polyline (k, dim): at points 1/64 of the zone
        apart, and the walls' exact one on its stretches between waypoints outside the zone."""
        p = np.asarray(points, dtype=float)
        dense = self._dense(p)
        out = float(self.distance(dense).min())
        far = np.linalg.norm(p - self.exit, axis=1) >= self.zone
        idx = np.flatnonzero(far)
        for run in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1):  # exact outside the zone
            if len(run) >= 2:
                out = min(out, self.walls.polyline_distance(p[run]))
        if not self.walls.inside(dense).all():
            return -abs(out)
        return out


def beyond(points: np.ndarray, length: float) -> np.ndarray:
    """The point (dim,) ``length`` (m) past a polyline's (k, dim) last point, along its
    last segment: where a drawing shows a tendon running on out of the body."""
    way = points[-1] - points[-2]
    return points[-1] + length * way / max(float(np.linalg.norm(way)), 1e-300)


def _pieces(line: np.ndarray) -> list[np.ndarray]:
    """A polyline (k, 2) cut at its corners (turns above CORNER)."""
    d = np.diff(line, axis=0)
    keep = np.linalg.norm(d, axis=1) > 0
    line = np.vstack([line[:1], line[1:][keep]])
    if len(line) < 3:
        return [line] if len(line) == 2 else []
    d = np.diff(line, axis=0)
    turn = np.abs(np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], (d[:-1] * d[1:]).sum(axis=1)))
    cuts = np.flatnonzero(turn > CORNER) + 1
    return [line[a:b + 1] for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(line) - 1]) if b > a]


def _trimmed(piece: np.ndarray, zone: float) -> np.ndarray | None:
    """The segments (s, 2, 2) of a polyline piece with ``zone`` cut off each end, or
    None where it is not longer than two zones."""
    line = shapely.LineString(piece)
    if line.length <= 2.0 * zone:
        return None
    core = shapely.get_coordinates(shapely.ops.substring(line, zone, line.length - zone))
    return np.stack([core[:-1], core[1:]], axis=1)


def _lines(geometry) -> list[np.ndarray]:
    """The coordinates (k, 2) of every line in a shapely geometry."""
    out = []
    for g in shapely.get_parts(geometry):
        if isinstance(g, (shapely.LineString, shapely.LinearRing)):
            out.append(shapely.get_coordinates(g))
        elif isinstance(g, (shapely.MultiLineString, shapely.GeometryCollection)):
            out += _lines(g)
    return out


def plane_exits(scene: Scene, walls, clearance: float) -> ExitSet | None:
    """The exit set of a 2D body (module docstring) with ``walls`` (the polygon set,
    :class:`~.geometry.PolygonWalls`) and the routes' ``clearance`` (m); None for
    ``exit = "inside"``. One clear line where the clamp does not meet the outline."""
    kind = scene.tendons.exit
    if kind == "inside":
        return None
    outline = shapely.get_exterior_ring(shapely.get_parts(walls.polygon))
    outline = shapely.line_merge(shapely.union_all(outline))
    if kind == "clamp":
        boxes = shapely.union_all([shapely.box(*b.lo, *b.hi) for b in scene.fixed])
        outline = shapely.line_merge(shapely.intersection(outline, boxes))
    zone = ZONE * LIFT * clearance
    lines = [ln for ln in _lines(outline) if len(ln) >= 2]
    pieces = [p for ln in lines for p in _pieces(ln)]
    kept = [s for s in (_trimmed(p, zone) for p in pieces) if s is not None]
    if not kept:  # no stretch longer than two zones: the middle of the longest piece
        if not pieces:
            raise SceneError(f"{scene.origin}: tendons.exit = \"{kind}\" but no [[fixed]] box meets the outline")
        longest = max(pieces, key=lambda p: shapely.LineString(p).length)
        mid = shapely.get_coordinates(shapely.LineString(longest).interpolate(0.5, normalized=True))[0]
        kept = [np.array([[mid, mid]])]
    return ExitSet(kind, np.concatenate(kept), zone)
