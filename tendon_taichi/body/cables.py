"""Cables: the contractile elements of both robots (``docs/method.md``).

A cable is a polyline through points embedded in the rest mesh, with one rest
length ``a0``, one contraction ``ac`` and one axial stiffness ``EA``; it slides
through its interior points, so its length is the sum of its segment lengths.
Frictionless (``friction`` 0), its tension is the same along it; with a
friction coefficient, each bend costs tension on the way from the pull end
(the last point) to the anchor (:mod:`tendon_taichi.physics.capstan`). A fiber
of the idealized robot is a one-segment cable; a tendon of the realizable
robot is a many-segment one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Embedding, Mesh


@dataclass(frozen=True, eq=False)
class CableSet:
    """``points``: embedded points (p); ``segments`` (S, 2) pairs of point ids;
    cable ``c`` owns segments ``start[c]:start[c+1]`` (``start`` (C+1,));
    ``a0`` (C,) rest lengths, m; ``stiffness`` (C,) EA, N; ``friction`` the
    capstan coefficient mu of the channels the cables run in (0: frictionless)."""

    points: Embedding
    segments: np.ndarray
    start: np.ndarray
    a0: np.ndarray
    stiffness: np.ndarray
    friction: float = 0.0

    @property
    def n_cables(self) -> int:
        return len(self.a0)

    @property
    def n_segments(self) -> int:
        return len(self.segments)

    @property
    def single_segment(self) -> bool:
        """Every cable is one segment (the fiber lattice)."""
        return self.n_segments == self.n_cables

    @staticmethod
    def empty() -> "CableSet":
        """No cables: the bare body."""
        return CableSet(Embedding(np.zeros(0, np.int64), np.zeros((0, 3))), np.zeros((0, 2), np.int64),
                        np.zeros(1, np.int64), np.zeros(0), np.zeros(0))

    @staticmethod
    def fibers(embedding: Embedding, edges: np.ndarray, a0: np.ndarray, stiffness: float) -> "CableSet":
        """One single-segment cable per fiber (edges: pairs of embedded point ids)."""
        edges = np.asarray(edges, dtype=np.int64)
        n = len(edges)
        return CableSet(embedding, edges, np.arange(n + 1, dtype=np.int64),
                        np.asarray(a0, dtype=float), np.full(n, float(stiffness)))

    @property
    def has_friction(self) -> bool:
        """Capstan friction applies: a friction coefficient and multi-segment cables."""
        return self.friction > 0.0 and not self.single_segment

    @staticmethod
    def polylines(mesh: Mesh, paths: list[np.ndarray], stiffness: float,
                  tol: float | None = None, friction: float = 0.0) -> "CableSet":
        """One cable per rest-state polyline (each (k_i, 2), k_i >= 2, m, inside the
        body within ``tol``, default 1e-9 L), anchored at its first point and pulled
        at its last; its rest length is the polyline's length."""
        tol = 1e-9 * mesh.size if tol is None else tol
        paths = [np.asarray(path, dtype=float).reshape(-1, 2) for path in paths]
        if any(len(path) < 2 for path in paths):
            raise ValueError("a cable needs at least two waypoints")
        emb, dist = mesh.locate(np.concatenate(paths), max_dist=tol)
        if np.any(dist > tol):
            raise ValueError("a cable waypoint lies outside the body")
        segs, start, a0, base = [], [0], [], 0
        for path in paths:
            k = len(path)
            segs.append(base + np.stack([np.arange(k - 1), np.arange(1, k)], axis=1))
            start.append(start[-1] + k - 1)
            a0.append(float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()))
            base += k
        return CableSet(emb, np.concatenate(segs), np.array(start, dtype=np.int64), np.array(a0),
                        stiffness=np.full(len(paths), float(stiffness)), friction=float(friction))
