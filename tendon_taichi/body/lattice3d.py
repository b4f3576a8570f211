"""The fiber graph of a 3D body (``docs/method.md``, the model): fiber nodes on a
cubic lattice of spacing ``s`` centred on the body's bounding box; a fiber is a
lattice edge to one of the 26 neighbours whose whole segment lies inside the
body. Fiber nodes are embedded in the rest tetrahedral mesh by barycentric
weights, as in 2D (:mod:`.fibers`).
"""

from __future__ import annotations

import numpy as np

from .fibers import FiberGraph, lattice_graph
from .tets import TetMesh

#: lattice neighbour offsets; with their opposites they make the 26-neighbourhood
OFFSETS = ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1),
           (0, 1, 1), (0, 1, -1), (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1))


def segment_triangle_params(p0: np.ndarray, p1: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray,
                            tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where segments p0[i]->p1[i] (s, 3) cross triangles ``a, b, c`` (f, 3): for every
    crossing or touch within ``tol`` (m), the segment id (h,), the triangle id (h,)
    and the segment's parameter t in [0, 1] (h,). A segment parallel to a triangle's plane meets it
    nowhere here: where it leaves a face in that plane it crosses a neighbouring,
    non-parallel face."""
    d = p1 - p0  # (s, 3)
    e1, e2 = b - a, c - a  # (f, 3)
    h = np.cross(d[:, None, :], e2[None, :, :])  # (s, f, 3)
    det = np.einsum("fd,sfd->sf", e1, h)
    dl = np.linalg.norm(d, axis=1)[:, None]
    n = np.linalg.norm(np.cross(e1, e2), axis=1)[None, :]  # twice the area
    parallel = np.abs(det) <= 1e-12 * dl * n
    w = p0[:, None, :] - a[None, :, :]  # (s, f, 3)
    qv = np.cross(w, e1[None, :, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(parallel, np.nan, 1.0 / det)
        u = np.einsum("sfd,sfd->sf", w, h) * inv
        v = np.einsum("sd,sfd->sf", d, qv) * inv
        t = np.einsum("fd,sfd->sf", e2, qv) * inv
    longest = np.maximum(np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1))
    ut = (tol / np.maximum(longest, 1e-300))[None, :]
    tt = tol / np.maximum(dl, 1e-300)
    hit = (~parallel) & (u >= -ut) & (v >= -ut) & (u + v <= 1 + ut) & (t >= -tt) & (t <= 1 + tt)
    seg, tri = np.nonzero(hit)
    return seg, tri, np.clip(t[hit], 0.0, 1.0)


def _segments_inside(mesh: TetMesh, p0: np.ndarray, p1: np.ndarray, tol: float,
                     chunk: int = 128) -> np.ndarray:
    """Whether each whole segment p0[i]->p1[i] (s, 3) lies inside the (closed) mesh.

    The segment is cut where it meets the mesh's surface; between cuts it is
    wholly inside or wholly outside, so each piece's midpoint decides."""
    if len(p0) == 0:
        return np.zeros(0, dtype=bool)
    tri = mesh.nodes[mesh.boundary_faces]  # (b, 3, 3)
    tlo, thi = tri.min(axis=1), tri.max(axis=1)
    owners, params = [np.arange(len(p0))] * 2, [np.zeros(len(p0)), np.ones(len(p0))]
    for s in range(0, len(p0), chunk):
        sl = slice(s, s + chunk)
        lo = np.minimum(p0[sl], p1[sl]).min(axis=0) - tol
        hi = np.maximum(p0[sl], p1[sl]).max(axis=0) + tol
        near = np.all((thi >= lo) & (tlo <= hi), axis=1)
        if not near.any():
            continue
        t = tri[near]
        seg, _, ts = segment_triangle_params(p0[sl], p1[sl], t[:, 0], t[:, 1], t[:, 2], tol=tol)
        owners.append(seg + s)
        params.append(ts)
    owner, ts = np.concatenate(owners), np.concatenate(params)
    order = np.lexsort((ts, owner))
    owner, ts = owner[order], ts[order]
    piece = (owner[1:] == owner[:-1]) & (np.diff(ts) > 1e-9)
    tm = 0.5 * (ts[:-1] + ts[1:])[piece]
    who = owner[:-1][piece]
    mids = p0[who] + tm[:, None] * (p1[who] - p0[who])
    inside = np.ones(len(p0), dtype=bool)
    np.logical_and.at(inside, who, mesh.contains(mids, tol))
    return inside


def _grid(mesh: TetMesh, spacing: float, tol: float) -> np.ndarray:
    """Lattice points (nx, ny, nz, 3) centred on the bounding box and covering it."""
    lo, hi = mesh.nodes.min(axis=0), mesh.nodes.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = np.floor((0.5 * (hi - lo) + tol) / spacing).astype(int)
    axes = [np.arange(-m, m + 1) for m in half]
    ijk = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    return centre + spacing * ijk


def _candidates(index: np.ndarray) -> np.ndarray:
    """Pairs (c, 2) of inside-node ids one offset apart, for every offset in :data:`OFFSETS`;
    ``index`` (nx, ny, nz) holds each lattice point's node id, -1 outside."""
    shape = np.array(index.shape)
    out = []
    for off in OFFSETS:
        o = np.array(off)
        lo, hi = np.maximum(0, -o), np.minimum(shape, shape - o)
        src = index[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        dst = index[lo[0] + o[0]:hi[0] + o[0], lo[1] + o[1]:hi[1] + o[1], lo[2] + o[2]:hi[2] + o[2]]
        ok = (src >= 0) & (dst >= 0)
        out.append(np.stack([src[ok], dst[ok]], axis=1))
    return np.concatenate(out)


def cubic_lattice(mesh: TetMesh, spacing: float, tol: float | None = None) -> FiberGraph:
    """The 26-neighbour cubic lattice of ``spacing`` (m) clipped to the body.

    ``tol`` (m) is the closed-inside tolerance, 1e-9 L by default."""
    if tol is None:
        tol = 1e-9 * mesh.size
    grid = _grid(mesh, spacing, tol)
    inside = mesh.contains(grid.reshape(-1, 3), tol).reshape(grid.shape[:3])
    index = -np.ones(grid.shape[:3], dtype=np.int64)
    index[inside] = np.arange(int(inside.sum()))
    points = grid[inside]

    cand = _candidates(index)
    keep = _segments_inside(mesh, points[cand[:, 0]], points[cand[:, 1]], tol)
    return lattice_graph(mesh, points, cand[keep], spacing)
