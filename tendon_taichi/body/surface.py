"""The walls of a 3D body: its closed triangle surface (the boundary faces of its
tetrahedral mesh), the space's implementation of the walls protocol
(:class:`~.walls.Walls`) for route clearance. Points are (q, 3) arrays in
metres, in the rest configuration."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .tets import TetMesh, point_triangle_distance

#: refine a polyline's samples until the step is below this fraction of the local distance
_STEP_FRACTION = 1.0 / 16.0
#: ... or below this fraction of the body size (a polyline grazing the surface)
_MIN_STEP = 1e-5


class SurfaceWalls:
    """The boundary faces of a :class:`~.tets.TetMesh` as walls: exact signed
    distances of points from the nearest face (positive inside the body) and
    their gradients."""

    def __init__(self, mesh: TetMesh, chunk: int = 2048):
        self.mesh = mesh
        self.faces = mesh.boundary_faces
        self.corners = mesh.nodes[self.faces]  # (b, 3, 3)
        n = np.cross(self.corners[:, 1] - self.corners[:, 0], self.corners[:, 2] - self.corners[:, 0])
        self.normals = n / np.linalg.norm(n, axis=1, keepdims=True)  # (b, 3), outward
        centroids = self.corners.mean(axis=1)
        self._tree = cKDTree(centroids)
        self._radius = float(np.linalg.norm(self.corners - centroids[:, None], axis=2).max())
        self._tol = 1e-12 * mesh.size  # the closed inside test's tolerance, m
        self._chunk = chunk

    @classmethod
    def of(cls, mesh: TetMesh) -> "SurfaceWalls":
        """The walls of a body meshed as ``mesh``."""
        return cls(mesh)

    def _face_distance(self, points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = self.corners[faces]
        return point_triangle_distance(points, c[:, 0], c[:, 1], c[:, 2])

    def _nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unsigned distance (q,) of points (q, 3) from the surface, m, the
        nearest surface point (q, 3) and its face (q,)."""
        dist, closest, face = np.empty(len(points)), np.empty((len(points), 3)), np.empty(len(points), np.int64)
        for s in range(0, len(points), self._chunk):
            sl = slice(s, s + self._chunk)
            dist[sl], closest[sl], face[sl] = self._nearest_chunk(points[sl])
        return dist, closest, face

    def _nearest_chunk(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = min(8, len(self.faces))
        _, cand = self._tree.query(p, k=k)
        cand = cand.reshape(len(p), k)
        d, _ = self._face_distance(np.repeat(p, k, axis=0), cand.ravel())
        bound = d.reshape(len(p), k).min(axis=1)
        # every face nearer than the bound has its centroid within (bound + radius)
        near = self._tree.query_ball_point(p, bound + self._radius)
        counts = np.array([len(n) for n in near], dtype=np.int64)
        owner = np.repeat(np.arange(len(p)), counts)
        ids = np.concatenate([np.asarray(n, dtype=np.int64) for n in near])
        nd, nc = self._face_distance(p[owner], ids)
        order = np.lexsort((nd, owner))
        first = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]
        return nd[first], nc[first], ids[first]

    def inside(self, points: np.ndarray) -> np.ndarray:
        """bool (q,): whether each point (q, 3) lies in the body, its walls included
        (to 1e-12 of the body size)."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return self.mesh.contains(p, self._tol)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (q,) of points (q, 3) from the nearest wall, m: positive
        inside the body, negative outside."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        d, _, _ = self._nearest(p)
        return np.where(self.inside(p), d, -d)

    def distance_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances (q,) and their gradients (q, 3): the unit vector from the
        nearest wall point to each point, into the body; for a point on a wall, the
        nearest face's inward normal."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        d, closest, face = self._nearest(p)
        sign = np.where(self.inside(p), 1.0, -1.0)
        away = p - closest
        on = d <= self._tol
        g = np.where(on[:, None], -self.normals[face], away / np.where(on, 1.0, d)[:, None] * sign[:, None])
        return sign * d, g

    def polyline_distance(self, points: np.ndarray) -> float:
        """The least signed distance (m) of a polyline (k, 3) from the walls, its
        segments included; negative when it leaves the body.

        It is the minimum over samples: the vertices, and points on each segment
        refined by bisection until the step is at most 1/16 of the distance at its
        ends (or 1e-5 of the body size); as the distance changes no faster than
        the arc length, it is within half a step above the exact minimum. Pieces
        that cannot hold a value below the best sample are not refined."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        dv = self.distance(p)
        if len(p) < 2:
            return float(dv.min())
        best = float(dv.min())
        a, b = p[:-1], p[1:]
        d0, d1 = dv[:-1], dv[1:]
        floor = _MIN_STEP * self.mesh.size
        while len(a):
            h = np.linalg.norm(b - a, axis=1)
            lower = np.minimum(d0, d1) - 0.5 * h  # the Lipschitz bound on the piece
            split = (h > np.maximum(_STEP_FRACTION * np.minimum(np.abs(d0), np.abs(d1)), floor)) & (lower < best)
            a, b, d0, d1 = a[split], b[split], d0[split], d1[split]
            if not len(a):
                break
            m = 0.5 * (a + b)
            dm = self.distance(m)
            best = min(best, float(dm.min()))
            a, b = np.concatenate([a, m]), np.concatenate([m, b])
            d0, d1 = np.concatenate([d0, dm]), np.concatenate([dm, d1])
        return best
