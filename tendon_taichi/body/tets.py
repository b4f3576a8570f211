"""Tetrahedral meshes of 3D bodies: extrusion of a polygon with holes, import
with meshio, and barycentric embedding of material points - the 3D
counterparts of :mod:`.mesh`.

A :class:`TetMesh` holds rest positions ``nodes`` (n, 3) in metres and
``tetrahedra`` (m, 4) of positive volume.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..errors import SceneError
from .geometry import bbox_diagonal
from .mesh import Embedding, read_meshio, triangulate_polygon

#: a tet's four faces, each ordered so that its normal (b - a) x (c - a) points
#: away from the fourth node when the tet's volume is positive
_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("...d,...d->...", u, v)


def point_triangle_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray,
                            c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact distance (k,) from each point (k, 3) to its triangle ``a, b, c`` (k, 3),
    m, and the nearest point of the triangle (k, 3).

    The nearest point is found by which Voronoi region of the triangle (a vertex,
    an edge, or the face) the point's projection falls in."""
    p = np.asarray(points, dtype=float)
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    vc, vb, va = d1 * d4 - d3 * d2, d5 * d2 - d1 * d6, d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        total = va + vb + vc
        v, w = vb / total, vc / total
    regions = [
        (d1 <= 0) & (d2 <= 0),                            # vertex a
        (d3 >= 0) & (d4 <= d3),                           # vertex b
        (d6 >= 0) & (d5 <= d6),                           # vertex c
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),                # edge ab
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),                # edge ac
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),      # edge bc
    ]
    choices = [a, b, c, a + t_ab[:, None] * ab, a + t_ac[:, None] * ac, b + t_bc[:, None] * (c - b)]
    face = a + v[:, None] * ab + w[:, None] * ac
    closest = face.copy()
    # the regions are tested in order: the first that holds wins
    done = np.zeros(len(p), dtype=bool)
    for mask, choice in zip(regions, choices):
        take = mask & ~done
        closest[take] = choice[take]
        done |= take
    return np.linalg.norm(p - closest, axis=1), closest


@dataclass(frozen=True, eq=False)
class TetMesh:
    """A mesh of tetrahedra: ``nodes`` (n, 3) m and ``tetrahedra`` (m, 4) int64,
    every one of positive volume (build it with :func:`oriented`)."""

    nodes: np.ndarray
    tetrahedra: np.ndarray

    @property
    def dim(self) -> int:
        """The dimension of the nodes' space: 3."""
        return int(self.nodes.shape[1])

    @property
    def simplices(self) -> np.ndarray:
        """The elements (m, 4), by the name that holds in every dimension."""
        return self.tetrahedra

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_tetrahedra(self) -> int:
        return len(self.tetrahedra)

    @cached_property
    def volumes(self) -> np.ndarray:
        """Signed rest volumes (m,), m^3: det([b - a, c - a, d - a]) / 6."""
        return _volumes(self.nodes, self.tetrahedra)

    @cached_property
    def size(self) -> float:
        """The body size L: the diagonal of the bounding box, m."""
        return bbox_diagonal(self.nodes)

    @cached_property
    def boundary_faces(self) -> np.ndarray:
        """Faces (b, 3) that belong to one tetrahedron only, ordered so that their
        normal (b - a) x (c - a) points out of the body."""
        f = self.tetrahedra[:, _FACES].reshape(-1, 3)
        key = np.sort(f, axis=1)
        _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return f[counts[inv.ravel()] == 1]

    @cached_property
    def _centroid_tree(self) -> cKDTree:
        return cKDTree(self.nodes[self.tetrahedra].mean(axis=1))

    @cached_property
    def _max_radius(self) -> float:
        """The largest distance from a tetrahedron's centroid to its corners, m."""
        p = self.nodes[self.tetrahedra]
        return float(np.linalg.norm(p - p.mean(axis=1, keepdims=True), axis=2).max())

    def barycentric(self, points: np.ndarray, tets: np.ndarray) -> np.ndarray:
        """Barycentric weights (k, 4) of ``points`` (k, 3) w.r.t. tetrahedra ``tets`` (k,)."""
        p = self.nodes[self.tetrahedra[tets]]
        a = p[:, 0]
        u, v, w, r = p[:, 1] - a, p[:, 2] - a, p[:, 3] - a, points - a
        det = _dot(u, np.cross(v, w))
        l1 = _dot(r, np.cross(v, w)) / det
        l2 = _dot(u, np.cross(r, w)) / det
        l3 = _dot(u, np.cross(v, r)) / det
        return np.stack([1.0 - l1 - l2 - l3, l1, l2, l3], axis=1)

    def _distance_to_tets(self, points: np.ndarray, tets: np.ndarray) -> np.ndarray:
        """Distance (k,) from each point (k, 3) to its tetrahedron (0 inside)."""
        out = np.zeros(len(points))
        outside = self.barycentric(points, tets).min(axis=1) < 0.0
        if not outside.any():
            return out
        p = points[outside]
        corners = self.nodes[self.tetrahedra[tets[outside]]]  # (o, 4, 3)
        best = np.full(len(p), np.inf)
        for face in _FACES:
            d, _ = point_triangle_distance(p, corners[:, face[0]], corners[:, face[1]], corners[:, face[2]])
            best = np.minimum(best, d)
        out[outside] = best
        return out

    def locate(self, points: np.ndarray, max_dist: float = np.inf, k: int = 12) -> tuple[Embedding, np.ndarray]:
        """Embed ``points`` (q, 3): the tetrahedron nearest to each point and its
        barycentric weights (clipped to >= 0 and renormalized for points just
        outside), plus the distance (q,) from each point to the mesh, m (0 inside).
        Distances are exact up to ``max_dist``; beyond it a point only reports that
        it is farther."""
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        q = len(points)
        k = min(k, self.n_tetrahedra)
        _, cand = self._centroid_tree.query(points, k=k)
        cand = cand.reshape(q, k)
        inside = self.barycentric(np.repeat(points, k, axis=0), cand.ravel()).min(axis=1).reshape(q, k) >= 0.0
        tet = cand[np.arange(q), np.argmax(inside, axis=1)]
        d = np.zeros(q)
        # distances to the candidates only for the points that none contains
        out = np.flatnonzero(~inside.any(axis=1))
        if len(out):
            dist = self._distance_to_tets(np.repeat(points[out], k, axis=0), cand[out].ravel()).reshape(-1, k)
            best = np.argmin(dist, axis=1)
            tet[out] = cand[out, best]
            d[out] = dist[np.arange(len(out)), best]
        far = np.flatnonzero(d > 0.0)
        if len(far):
            # a nearer tetrahedron has its centroid within (distance + radius)
            radius = np.minimum(d[far], max_dist) + self._max_radius
            near = self._centroid_tree.query_ball_point(points[far], radius)
            counts = np.array([len(n) for n in near], dtype=np.int64)
            if counts.sum():
                owner = np.repeat(np.arange(len(far)), counts)
                ids = np.concatenate([np.asarray(n, dtype=np.int64) for n in near])
                nd = self._distance_to_tets(points[far[owner]], ids)
                order = np.lexsort((nd, owner))
                first = order[np.r_[True, owner[order][1:] != owner[order][:-1]]]
                at = far[owner[first]]
                better = nd[first] < d[at]
                tet[at[better]], d[at[better]] = ids[first[better]], nd[first[better]]
        bary = np.clip(self.barycentric(points, tet), 0.0, None)
        bary /= bary.sum(axis=1, keepdims=True)
        return Embedding(tet.astype(np.int64), bary), d

    def contains(self, points: np.ndarray, tol: float) -> np.ndarray:
        """Closed inside test: bool (q,), within ``tol`` metres of the mesh counts."""
        return self.locate(points, max_dist=tol)[1] <= tol


def _volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    p = nodes[tets]
    a = p[:, 0]
    return _dot(p[:, 1] - a, np.cross(p[:, 2] - a, p[:, 3] - a)) / 6.0


def oriented(nodes: np.ndarray, tets: np.ndarray, origin: str) -> TetMesh:
    """A :class:`TetMesh` of ``nodes`` (n, 3) m and ``tets`` (m, 4), unused nodes
    dropped and every tetrahedron flipped when all are negative. ``origin`` names
    the source in the :class:`SceneError` raised for degenerate (zero-volume) or
    inverted tetrahedra (volumes of mixed signs)."""
    nodes = np.asarray(nodes, dtype=float)
    tets = np.asarray(tets, dtype=np.int64).reshape(-1, 4)
    if len(tets) == 0:
        raise SceneError(f"{origin}: no tetrahedra")
    used = np.unique(tets)
    remap = -np.ones(len(nodes), dtype=np.int64)
    remap[used] = np.arange(len(used))
    nodes, tets = np.ascontiguousarray(nodes[used]), remap[tets]
    vol = _volumes(nodes, tets)
    # a flat tet's sign is rounding noise: report it as degenerate, not inverted
    flat = np.abs(vol) <= 1e-12 * bbox_diagonal(nodes) ** 3
    if flat.any():
        raise SceneError(f"{origin}: {int(flat.sum())} degenerate (zero-volume) tetrahedra")
    negative = vol < 0
    if negative.all():
        tets = tets[:, [0, 2, 1, 3]]
    elif negative.any():
        raise SceneError(f"{origin}: {int(negative.sum())} of {len(tets)} tetrahedra are inverted")
    return TetMesh(nodes, np.ascontiguousarray(tets))


def _prism_tets(triangles: np.ndarray, n2: int, nz: int) -> np.ndarray:
    """The tets (3 m nz, 4) of the prisms over ``triangles`` (m, 3) in ``nz`` layers
    of ``n2`` nodes. Each prism's quad faces are cut on the diagonal from the bottom
    of their lower node id to the top of the higher, so neighbouring prisms agree."""
    v0, v1, v2 = np.sort(triangles, axis=1).T
    out = []
    for layer in range(nz):
        b, t = layer * n2, (layer + 1) * n2
        out += [np.stack([v0 + b, v1 + b, v2 + b, v2 + t], axis=1),
                np.stack([v0 + b, v1 + b, v1 + t, v2 + t], axis=1),
                np.stack([v0 + b, v0 + t, v1 + t, v2 + t], axis=1)]
    return np.concatenate(out)


def extrude(outline: np.ndarray, holes, depth: float, edge: float) -> TetMesh:
    """The polygon ``outline`` (k, 2) m, counter-clockwise, with ``holes``, meshed with
    triangles of edge about ``edge`` (m) and extruded along z from 0 to ``depth`` (m)
    in ``ceil(depth / edge)`` equal layers; node ``layer * n2 + i`` is the 2D mesh's
    node i in that layer."""
    mesh2 = triangulate_polygon(np.asarray(outline, dtype=float), [np.asarray(h, dtype=float) for h in holes],
                                max_area=np.sqrt(3.0) / 4.0 * edge ** 2)
    n2 = mesh2.n_nodes
    nz = max(1, int(np.ceil(depth / edge - 1e-9)))
    z = np.linspace(0.0, depth, nz + 1)
    nodes = np.concatenate([np.column_stack([mesh2.nodes, np.full(n2, zl)]) for zl in z])
    tets = _prism_tets(mesh2.triangles, n2, nz)
    # sorting the triangle's ids mirrors some prisms: give each tet its positive order
    flip = _volumes(nodes, tets) < 0
    tets[flip] = tets[flip][:, [0, 2, 1, 3]]
    return oriented(nodes, tets, "extruded body")


def read_tet_mesh(path: Path, scale: float = 1.0) -> TetMesh:
    """Read the tetrahedra of a mesh file with meshio; coordinates are multiplied by
    ``scale`` (1e-3 for a file in millimetres) to give metres."""
    m = read_meshio(path)
    tets = [c.data for c in m.cells if c.type == "tetra"]
    if not tets:
        raise SceneError(f"mesh file '{path}' has no tetrahedra")
    pts = np.asarray(m.points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SceneError(f"mesh file '{path}' has points of {pts.shape[-1]} coordinates, not 3")
    return oriented(pts * scale, np.concatenate(tets), f"mesh file '{path}'")
