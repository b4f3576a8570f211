"""The idealized robot's fiber graph (``docs/method.md``, the model).

Fiber nodes sit on a square lattice of spacing ``s`` centred on the body's
bounding box; a fiber is a lattice edge to one of the 8 neighbours whose whole
segment lies inside the body. Fiber nodes are embedded in the rest mesh by
barycentric weights, so they follow the body: ``c_j(x) = sum_k b_jk x_k``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .geometry import segment_params_on_edges
from .mesh import Embedding, Mesh

#: lattice neighbour offsets; with their opposites they make the 8-neighbourhood
_OFFSETS = ((1, 0), (0, 1), (1, 1), (1, -1))


@dataclass(frozen=True)
class FiberPairs:
    """Pairs of fibers that share a fiber node (for the continuity term).

    ``fibers`` (P, 2) fiber ids, ``node`` (P,) the shared fiber node,
    ``cos2`` (P,) cos^2 of the angle between the two fibers at rest.
    """

    fibers: np.ndarray
    node: np.ndarray
    cos2: np.ndarray


@dataclass(frozen=True, eq=False)
class FiberGraph:
    """Fiber nodes (rest positions ``nodes`` (k, dim), m, and their ``embedding``) and
    fibers ``edges`` (f, 2) as pairs of fiber-node ids; ``spacing`` in m."""

    nodes: np.ndarray
    embedding: Embedding
    edges: np.ndarray
    spacing: float

    @property
    def n_fibers(self) -> int:
        return len(self.edges)

    @cached_property
    def a0(self) -> np.ndarray:
        """Rest lengths (f,), m."""
        d = self.nodes[self.edges[:, 1]] - self.nodes[self.edges[:, 0]]
        return np.linalg.norm(d, axis=1)

    @cached_property
    def directions(self) -> np.ndarray:
        """Unit rest directions (f, dim)."""
        d = self.nodes[self.edges[:, 1]] - self.nodes[self.edges[:, 0]]
        return d / self.a0[:, None]

    @cached_property
    def incidence(self) -> tuple[np.ndarray, np.ndarray]:
        """The fibers meeting at each fiber node, CSR: ``start`` (k+1,) and ``fibers``
        (2f,), node v's being ``fibers[start[v]:start[v+1]]`` in ascending id."""
        ends = np.concatenate([self.edges[:, 0], self.edges[:, 1]])
        fib = np.concatenate([np.arange(self.n_fibers)] * 2)
        order = np.lexsort((fib, ends))
        start = np.searchsorted(ends[order], np.arange(len(self.nodes) + 1))
        return start, fib[order]

    @cached_property
    def pairs(self) -> FiberPairs:
        """Every pair of fibers meeting at a fiber node, with cos^2 of their rest angle."""
        start, fib = self.incidence
        pa, pb, pn = [], [], []
        for v in np.flatnonzero(np.diff(start)):
            ids = fib[start[v]:start[v + 1]]
            ia, ib = np.triu_indices(len(ids), k=1)
            pa.append(ids[ia])
            pb.append(ids[ib])
            pn.append(np.full(len(ia), v))
        a, b = np.concatenate(pa), np.concatenate(pb)
        cos = np.einsum("pd,pd->p", self.directions[a], self.directions[b])
        return FiberPairs(np.stack([a, b], axis=1), np.concatenate(pn), cos * cos)


def _segments_inside(mesh: Mesh, p0: np.ndarray, p1: np.ndarray, tol: float,
                     chunk: int = 256) -> np.ndarray:
    """Whether each whole segment p0[i]->p1[i] lies inside the (closed) mesh.

    The segment is cut where it meets the mesh boundary; between cuts it is
    wholly inside or wholly outside, so each piece's midpoint decides."""
    be = mesh.boundary_edges
    if len(p0) == 0:
        return np.zeros(0, dtype=bool)
    q0, q1 = mesh.nodes[be[:, 0]], mesh.nodes[be[:, 1]]
    mids, owner = [], []
    for s in range(0, len(p0), chunk):
        sl = slice(s, s + chunk)
        lo = np.minimum(p0[sl], p1[sl]).min(axis=0) - tol
        hi = np.maximum(p0[sl], p1[sl]).max(axis=0) + tol
        near = np.all((np.maximum(q0, q1) >= lo) & (np.minimum(q0, q1) <= hi), axis=1)
        params = segment_params_on_edges(p0[sl], p1[sl], q0[near], q1[near], tol)
        for i, ts in enumerate(params):
            ts = np.unique(np.r_[0.0, ts, 1.0])
            keep = np.diff(ts) > 1e-9
            tm = 0.5 * (ts[:-1] + ts[1:])[keep]
            a, b = p0[s + i], p1[s + i]
            mids.append(a + tm[:, None] * (b - a))
            owner.append(np.full(len(tm), s + i))
    mids, owner = np.concatenate(mids), np.concatenate(owner)
    ok = mesh.contains(mids, tol)
    inside = np.ones(len(p0), dtype=bool)
    np.logical_and.at(inside, owner, ok)
    return inside


def build_lattice(mesh: Mesh, spacing: float, tol: float | None = None) -> FiberGraph:
    """The 8-neighbour lattice of ``spacing`` (m) clipped to the body.

    ``tol`` (m) is the closed-inside tolerance, 1e-9 L by default."""
    if tol is None:
        tol = 1e-9 * mesh.size
    lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = np.floor((0.5 * (hi - lo) + tol) / spacing).astype(int)
    ii, jj = np.meshgrid(np.arange(-half[0], half[0] + 1), np.arange(-half[1], half[1] + 1),
                         indexing="ij")
    grid = centre + spacing * np.stack([ii.ravel(), jj.ravel()], axis=1)
    inside = mesh.contains(grid, tol).reshape(ii.shape)
    index = -np.ones(ii.shape, dtype=np.int64)
    index[inside] = np.arange(int(inside.sum()))
    points = grid.reshape(*ii.shape, 2)[inside]

    cand = []
    nx, ny = ii.shape
    for dx, dy in _OFFSETS:
        i0 = np.arange(max(0, -dx), min(nx, nx - dx))
        j0 = np.arange(max(0, -dy), min(ny, ny - dy))
        I, J = np.meshgrid(i0, j0, indexing="ij")
        a, b = index[I, J], index[I + dx, J + dy]
        ok = (a >= 0) & (b >= 0)
        cand.append(np.stack([a[ok], b[ok]], axis=1))
    cand = np.concatenate(cand)
    keep = _segments_inside(mesh, points[cand[:, 0]], points[cand[:, 1]], tol)
    return lattice_graph(mesh, points, cand[keep], spacing)


def lattice_graph(mesh, points: np.ndarray, edges: np.ndarray, spacing: float) -> FiberGraph:
    """The fiber graph of lattice ``points`` (k, dim), m, and the ``edges`` (f, 2) kept
    inside the body: the points no fiber uses dropped, the rest embedded in ``mesh``
    (a triangle or tetrahedral mesh, anything with ``locate``)."""
    used = np.unique(edges)
    remap = -np.ones(len(points), dtype=np.int64)
    remap[used] = np.arange(len(used))
    nodes = points[used]
    embedding, _ = mesh.locate(nodes)
    return FiberGraph(nodes, embedding, remap[edges], float(spacing))
