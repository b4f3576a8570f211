"""Graph queries on a problem's fiber lattice, the ones most extractors need
(part of the plugin protocol)."""

from __future__ import annotations

import math

import numpy as np

from .protocol import IdealizedState, Tendon


class FiberView:
    """Graph queries on a problem's fiber lattice (read-only)."""

    def __init__(self, problem):
        f = problem.fibers
        self.problem = problem
        self.nodes, self.edges, self.a0 = f.nodes, f.edges, f.a0
        self.spacing = f.spacing
        ends = np.concatenate([self.edges[:, 0], self.edges[:, 1]])
        fib = np.concatenate([np.arange(len(self.edges))] * 2)
        order = np.argsort(ends, kind="stable")
        self._start = np.searchsorted(ends[order], np.arange(len(self.nodes) + 1))
        self._inc = fib[order]
        fixed_pts = problem.mesh.nodes[problem.fixed]
        self._to_clamp = np.min(np.linalg.norm(self.nodes[:, None, :] - fixed_pts[None, :, :], axis=2), axis=1) \
            if len(fixed_pts) else np.zeros(len(self.nodes))

    def incident(self, v: int) -> np.ndarray:
        """Fiber ids meeting at fiber node v."""
        return self._inc[self._start[v]:self._start[v + 1]]

    def other(self, fiber: int, v: int) -> int:
        """The end of ``fiber`` that is not node v."""
        a, b = self.edges[fiber]
        return int(b if a == v else a)

    def turn(self, f_in: int, v: int, f_out: int) -> float:
        """Turn angle (radians) at node v when a path arrives along ``f_in`` and
        leaves along ``f_out``: 0 straight on, pi straight back."""
        u, w = self.other(f_in, v), self.other(f_out, v)
        a = self.nodes[v] - self.nodes[u]
        b = self.nodes[w] - self.nodes[v]
        c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
        return math.acos(max(-1.0, min(1.0, c)))

    def distance_to_clamp(self, v: int) -> float:
        """Rest distance from fiber node v to the nearest clamped mesh node, m."""
        return float(self._to_clamp[v])

    def grow(self, seed: int, extend) -> tuple[int, list[int]]:
        """A path grown from fiber ``seed`` at both ends: ``extend(node, fiber)``
        returns, in order, the fibers to add beyond ``node`` (which the path reached
        along ``fiber``). Returns the path's start node and its fibers in order."""
        a, b = (int(v) for v in self.edges[seed])
        back = extend(b, seed)
        front = extend(a, seed)
        start = a
        for f in front:  # walk the front extension out to its far end
            start = self.other(f, start)
        return start, front[::-1] + [seed] + back

    def greedy_tendons(self, state: IdealizedState, used: np.ndarray, stepper) -> list[Tendon]:
        """Tendons grown greedily: every fiber not yet ``used`` seeds one, strongest
        tension first, grown at both ends by :meth:`grow`. ``stepper(seed, visited)``
        returns that seed's ``extend(node, fiber)``; ``visited`` (the path's fiber
        nodes, seeded with the seed's two ends) and ``used`` (bool per fiber) are
        shared with it and updated by it."""
        tendons = []
        for seed in sorted(range(len(state.tau)), key=lambda f: -state.tau[f]):
            if used[seed]:
                continue
            used[seed] = True
            visited = {int(v) for v in self.edges[seed]}
            start, fibers = self.grow(seed, stepper(seed, visited))
            tendons.append(self.tendon(start, fibers, state))
        return tendons

    def tendon(self, start: int, fibers: list[int], state: IdealizedState) -> Tendon:
        """The tendon following ``fibers`` from node ``start``, oriented so that its
        pull end is the end nearer to the clamped region (where motors sit)."""
        nodes = [int(start)]
        for f in fibers:
            nodes.append(self.other(int(f), nodes[-1]))
        nodes_a, fibers_a = np.array(nodes), np.array(fibers, dtype=np.int64)
        if self._to_clamp[nodes_a[0]] < self._to_clamp[nodes_a[-1]]:
            nodes_a, fibers_a = nodes_a[::-1].copy(), fibers_a[::-1].copy()
        src = fibers_a[state.active[fibers_a]] if len(fibers_a) else fibers_a
        t = state.tau[src] if len(src) else np.zeros(1)
        return Tendon(nodes_a, fibers_a, self.nodes[nodes_a].copy(), float(t.mean()), float(t.std()))
