"""Meshes of the body: meshing with ``triangle``, import with meshio, and
barycentric embedding of material points (``docs/method.md``).

A :class:`Mesh` holds rest positions ``nodes`` (n, dim) in metres and its
simplices of ``dim + 1`` nodes; in 2D, the dimension built so far,
counter-clockwise ``triangles`` (m, 3).
"""

from __future__ import annotations

import contextlib
import io
import warnings
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import triangle as tr
from scipy.spatial import cKDTree

from ..errors import SceneError
from .geometry import bbox_diagonal


@dataclass(frozen=True)
class Embedding:
    """Points embedded in the rest mesh: simplex ``tri`` (k,) (a triangle in 2D, a
    tetrahedron in 3D) and barycentric weights ``bary`` (k, dim + 1), so that a point
    follows ``sum_j bary_j x[T[tri, j]]``."""

    tri: np.ndarray
    bary: np.ndarray

    def positions(self, mesh_triangles: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Positions (k, dim) of the embedded points for node positions ``x`` (n, dim)."""
        corners = x[mesh_triangles[self.tri]]  # (k, dim + 1, dim)
        return np.einsum("kj,kjd->kd", self.bary, corners)

    def __len__(self) -> int:
        return len(self.tri)


@dataclass(frozen=True, eq=False)
class Mesh:
    """A mesh of simplices of ``dim + 1`` nodes: ``nodes`` (n, dim) m and
    ``triangles`` (m, dim + 1) - in 2D, the only dimension built so far,
    triangles, counter-clockwise."""

    nodes: np.ndarray
    triangles: np.ndarray

    @property
    def dim(self) -> int:
        """The dimension of the nodes' space."""
        return int(self.nodes.shape[1])

    @property
    def simplices(self) -> np.ndarray:
        """The elements (m, dim + 1), by the name that holds in every dimension."""
        return self.triangles

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @cached_property
    def areas(self) -> np.ndarray:
        """Signed rest areas (m,), m^2; positive for a valid mesh."""
        p = self.nodes[self.triangles]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])

    @cached_property
    def size(self) -> float:
        """The body size L: the diagonal of the bounding box, m."""
        return bbox_diagonal(self.nodes)

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        """Edges (b, 2) that belong to one triangle only, oriented as in it."""
        e = np.concatenate([self.triangles[:, [0, 1]], self.triangles[:, [1, 2]],
                            self.triangles[:, [2, 0]]])
        key = np.sort(e, axis=1)
        _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        return e[counts[inv.ravel()] == 1]

    @cached_property
    def _centroid_tree(self) -> cKDTree:
        return cKDTree(self.nodes[self.triangles].mean(axis=1))

    def barycentric(self, points: np.ndarray, tris: np.ndarray) -> np.ndarray:
        """Barycentric weights (k, 3) of ``points`` (k, 2) w.r.t. triangles ``tris`` (k,)."""
        p = self.nodes[self.triangles[tris]]
        a, b, c = p[:, 0], p[:, 1], p[:, 2]
        v0, v1, v2 = b - a, c - a, points - a
        det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
        l1 = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
        l2 = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
        return np.stack([1.0 - l1 - l2, l1, l2], axis=1)

    def _distance_to_triangles(self, points: np.ndarray, tris: np.ndarray) -> np.ndarray:
        """Distance (k,) from each point to its triangle (0 inside)."""
        bary = self.barycentric(points, tris)
        inside = bary.min(axis=1) >= 0.0
        p = self.nodes[self.triangles[tris]]
        best = np.full(len(points), np.inf)
        for i, j in ((0, 1), (1, 2), (2, 0)):
            a, b = p[:, i], p[:, j]
            ab = b - a
            t = np.clip(((points - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
            best = np.minimum(best, np.linalg.norm(points - (a + t[:, None] * ab), axis=1))
        return np.where(inside, 0.0, best)

    @cached_property
    def _max_circumradius(self) -> float:
        p = self.nodes[self.triangles]
        return float(np.linalg.norm(p - p.mean(axis=1, keepdims=True), axis=2).max())

    def locate(self, points: np.ndarray, max_dist: float = np.inf, k: int = 12,
               hint: np.ndarray | None = None) -> tuple[Embedding, np.ndarray]:
        """Embed ``points`` (q, 2): the triangle nearest to each point and its
        barycentric weights (projected onto the triangle for points just outside),
        plus the distance (q,) from each point to the mesh (0 inside). Distances
        are exact up to ``max_dist``; beyond it a point only reports that it is farther.
        ``hint`` (q,): a triangle per point to try first (where the point was a
        moment ago); a point inside it stays in it."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if hint is not None and len(hint) == len(points) and len(points):
            bary = self.barycentric(points, hint)
            inside = bary.min(axis=1) >= 0.0
            if inside.all():
                return Embedding(np.asarray(hint, dtype=np.int64).copy(), bary / bary.sum(axis=1, keepdims=True)), \
                    np.zeros(len(points))
            rest, dist = self.locate(points[~inside], max_dist, k)
            tri = np.asarray(hint, dtype=np.int64).copy()
            tri[~inside] = rest.tri
            bary[~inside] = rest.bary
            d = np.zeros(len(points))
            d[~inside] = dist
            return Embedding(tri, bary / bary.sum(axis=1, keepdims=True)), d
        q = len(points)
        k = min(k, self.n_triangles)
        _, cand = self._centroid_tree.query(points, k=k)
        cand = cand.reshape(q, k)
        dist = self._distance_to_triangles(np.repeat(points, k, axis=0), cand.ravel()).reshape(q, k)
        best = np.argmin(dist, axis=1)
        tri = cand[np.arange(q), best]
        d = dist[np.arange(q), best]
        # a nearer triangle has its centroid within (distance + circumradius)
        for i in np.flatnonzero(d > 0.0):
            radius = min(d[i], max_dist) + self._max_circumradius
            near = np.array(self._centroid_tree.query_ball_point(points[i], radius), dtype=np.int64)
            if len(near) == 0:
                continue
            nd = self._distance_to_triangles(np.repeat(points[i:i + 1], len(near), 0), near)
            j = int(np.argmin(nd))
            if nd[j] < d[i]:
                tri[i], d[i] = near[j], nd[j]
        bary = self.barycentric(points, tri)
        # points on (or within tolerance of) an edge: clip to the triangle
        bary = np.clip(bary, 0.0, None)
        bary /= bary.sum(axis=1, keepdims=True)
        return Embedding(tri.astype(np.int64), bary), d

    def contains(self, points: np.ndarray, tol: float) -> np.ndarray:
        """Closed inside test: bool (q,), within ``tol`` metres of the mesh counts."""
        return self.locate(points, max_dist=tol)[1] <= tol


def _decimal(value: float) -> str:
    """A number in plain decimal notation (Triangle would read an 'e' as a switch)."""
    return np.format_float_positional(value, trim="-")


def _interior_point(poly: np.ndarray) -> np.ndarray:
    """A point strictly inside a simple polygon (the centroid of one of its triangles)."""
    k = len(poly)
    seg = np.stack([np.arange(k), (np.arange(k) + 1) % k], axis=1)
    t = tr.triangulate({"vertices": poly, "segments": seg}, "pQ")
    return t["vertices"][t["triangles"][0]].mean(axis=0)


def triangulate_polygon(outline: np.ndarray, holes, max_area: float,
                        min_angle: float = 30.0) -> Mesh:
    """Quality-mesh a polygon with holes: Triangle's ``pq<angle>a<area>``."""
    verts, segs, start = [], [], 0
    for poly in (outline, *holes):
        k = len(poly)
        verts.append(poly)
        segs.append(start + np.stack([np.arange(k), (np.arange(k) + 1) % k], axis=1))
        start += k
    data = {"vertices": np.concatenate(verts), "segments": np.concatenate(segs)}
    if holes:
        data["holes"] = np.array([_interior_point(h) for h in holes])
    out = tr.triangulate(data, f"pq{min_angle:g}a{_decimal(max_area)}Q")
    return _clean(out["vertices"], out["triangles"])


def _clean(nodes: np.ndarray, triangles: np.ndarray) -> Mesh:
    """Drop unused nodes and orient every triangle counter-clockwise."""
    nodes = np.ascontiguousarray(nodes[:, :2], dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    used = np.unique(triangles)
    remap = -np.ones(len(nodes), dtype=np.int64)
    remap[used] = np.arange(len(used))
    mesh = Mesh(nodes[used], remap[triangles])
    flip = mesh.areas < 0
    if flip.any():
        t = mesh.triangles.copy()
        t[flip] = t[flip][:, [0, 2, 1]]
        mesh = Mesh(mesh.nodes, t)
    return mesh


def read_meshio(path: Path):
    """meshio's reading of the mesh file ``path``, its failures as one
    :class:`~tendon_taichi.errors.SceneError` line."""
    import meshio

    said = io.StringIO()
    try:
        with contextlib.redirect_stdout(said), contextlib.redirect_stderr(said), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # meshio's own (an ASCII STL's size check overflows): not the user's
            return meshio.read(str(path))
    except (Exception, SystemExit) as exc:  # meshio raises many types for bad files; on some it prints and exits
        lines = [ln for ln in (str(exc) if isinstance(exc, Exception) else said.getvalue()).splitlines() if ln.strip()]
        why = lines[0].removeprefix("Error: ") if lines else "not a mesh file meshio can read"
        raise SceneError(f"cannot read mesh file '{path}': {why}") from None


#: the one line for a mesh file that holds a surface (triangles in space), not tetrahedra
SURFACE_UNAVAILABLE = ("tetrahedralizing a surface file is not available yet; give a tetrahedral mesh "
                       "(.msh, .vtu, .vtk) or an extruded outline")


def _planar(points: np.ndarray) -> bool:
    """Whether points (n, 2 or 3) lie in a plane z = const (relative to their x-y extent)."""
    return points.shape[1] < 3 or np.ptp(points[:, 2]) <= 1e-12 * max(np.ptp(points[:, :2]), 1e-300)


@lru_cache(maxsize=16)
def _file_dim(path: str, stamp: tuple[int, int]) -> int:
    m = read_meshio(Path(path))
    if any(c.type.startswith("tetra") for c in m.cells):
        return 3
    if len(m.points) and not _planar(np.asarray(m.points, dtype=float)):
        raise SceneError(f"mesh file '{path}' is a surface: {SURFACE_UNAVAILABLE}")
    return 2


def mesh_file_dim(path: Path) -> int:
    """The dimension of the body a mesh file holds: 3 where it has tetrahedra, else 2
    (a planar triangle mesh); one SceneError line for a surface (points not in a plane,
    no tetrahedra) or a file meshio cannot read. Read once per file version."""
    st = Path(path).stat()
    return _file_dim(str(path), (st.st_mtime_ns, st.st_size))


def read_mesh(path: Path) -> Mesh:
    """Read the triangles of a mesh file with meshio (z coordinates are dropped)."""
    m = read_meshio(path)
    tris = [c.data for c in m.cells if c.type == "triangle"]
    if not tris:
        raise SceneError(f"mesh file '{path}' has no triangle cells")
    pts = np.asarray(m.points, dtype=float)
    if not _planar(pts):
        raise SceneError(f"mesh file '{path}' is not planar (z varies)")
    mesh = _clean(pts[:, :2], np.concatenate(tris))
    if np.any(np.abs(mesh.areas) <= 1e-14 * mesh.size ** 2):
        raise SceneError(f"mesh file '{path}' has degenerate (zero-area) triangles")
    return mesh


def refine(mesh: Mesh, max_area: float) -> Mesh:
    """Refine a mesh so that no triangle is larger than ``max_area``, keeping its boundary."""
    seg = mesh.boundary_edges
    out = tr.triangulate({"vertices": mesh.nodes, "triangles": mesh.triangles, "segments": seg},
                         f"rpq30a{_decimal(max_area)}Q")
    return _clean(out["vertices"], out["triangles"])
