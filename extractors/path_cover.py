"""A global path cover of the active fibers.

At every fiber node, its incident active fibers are paired by a maximum-weight
matching; a pair may form only if the path turns by at most ``max_turn`` and the
two tensions differ by at most ``tension_tol`` (relative), and weighs
``(1 + cos turn) / 2 * (1 - relative tension difference)``. Unpaired fibers end
paths, so following the pairs covers the active fibers with paths that keep
straight where they can - also where parallel strands of similar tension run
side by side, which confuses greedy tracing. Closed loops are cut at their
weakest pairing; with ``bridge_gaps`` two path ends facing each other across one
slack fiber are joined; paths shorter than ``min_length`` or weaker than
``min_tension`` x the strongest path (scattered weak activations) are dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tendon_taichi.extraction import EXTRACTOR_API, Extractor, FiberView, IdealizedState, Tendon, prune


def max_weight_matching(items: list[int], weight) -> tuple[float, list[tuple[int, int]]]:
    """The best set of disjoint pairs of ``items`` (a handful: fibers at one node);
    ``weight(a, b)`` is None for a pair that may not form."""
    if len(items) < 2:
        return 0.0, []
    first, rest = items[0], items[1:]
    best = max_weight_matching(rest, weight)  # ``first`` stays unpaired
    for i, other in enumerate(rest):
        w = weight(first, other)
        if w is None:
            continue
        sub_w, sub = max_weight_matching(rest[:i] + rest[i + 1:], weight)
        if w + sub_w > best[0]:
            best = (w + sub_w, [(first, other)] + sub)
    return best


class PathCoverExtractor(Extractor):
    name = "path_cover"
    description = "global path cover: per-node maximum-weight matching on straightness and tension"
    api = EXTRACTOR_API

    @dataclass
    class Options:
        max_turn: float = 60.0      # degrees, largest turn a pairing may make
        tension_tol: float = 0.5    # largest relative tension difference of a pairing
        bridge_gaps: bool = True    # join path ends across one slack fiber
        min_length: float = 0.01    # m
        min_tension: float = 0.25   # drop paths weaker than this x the strongest one
        ranges = {"max_turn": (0.0, 180.0), "tension_tol": (0.0, None), "min_length": (0.0, None),
                  "min_tension": (0.0, 1.0)}  # checked by make_options

    def extract(self, problem, state: IdealizedState, options) -> list[Tendon]:
        view = FiberView(problem)
        tau, active = state.tau, state.active
        max_turn = math.radians(options.max_turn) + 1e-9  # lattice angles are exact multiples of 45

        def weight(v):
            def w(a, b):
                turn = view.turn(a, v, b)
                diff = abs(tau[a] - tau[b]) / max(tau[a], tau[b])
                if turn > max_turn or diff > options.tension_tol:
                    return None
                return 0.5 * (1.0 + math.cos(turn)) * (1.0 - diff)
            return w

        # partner[(fiber, node)] = the fiber it continues into at that node
        partner: dict[tuple[int, int], int] = {}
        pair_weight: dict[frozenset, float] = {}
        for v in range(len(view.nodes)):
            inc = [int(f) for f in view.incident(v) if active[f]]
            _, pairs = max_weight_matching(inc, weight(v))
            for a, b in pairs:
                partner[(a, v)], partner[(b, v)] = b, a
                pair_weight[frozenset((a, b))] = weight(v)(a, b)
        paths = self._paths(view, active, partner, pair_weight)
        if options.bridge_gaps:
            paths = self._bridge(view, state, paths, max_turn, options.tension_tol)
        tendons = [view.tendon(_nodes_of(view, fibers)[0], fibers, state) for fibers in paths]
        return prune(tendons, options)

    @staticmethod
    def _walk(view, partner, f, v) -> tuple[list[int], bool]:
        """The fibers after ``f`` when leaving it through its end ``v``, following the
        pairs, and whether they lead back to ``f`` (a closed loop)."""
        out, f0 = [], f
        while (f, v) in partner:
            g = partner[(f, v)]
            if g == f0:
                return out, True
            v = view.other(g, v)
            out.append(g)
            f = g
        return out, False

    def _paths(self, view, active, partner, pair_weight) -> list[list[int]]:
        """Every path as a fiber list; a closed loop is first cut at its weakest pair."""
        seen, paths = set(), []
        for f0 in (int(i) for i in range(len(active)) if active[i]):
            if f0 in seen:
                continue
            a, b = (int(v) for v in view.edges[f0])
            fwd, closed = self._walk(view, partner, f0, b)
            if closed:
                loop = [f0] + fwd
                links = [(loop[i], loop[(i + 1) % len(loop)]) for i in range(len(loop))]
                x, y = min(links, key=lambda p: pair_weight[frozenset(p)])
                for key in [k for k, g in partner.items() if {k[0], g} == {x, y}]:
                    del partner[key]
                fwd, _ = self._walk(view, partner, f0, b)
            back, _ = self._walk(view, partner, f0, a)
            fibers = back[::-1] + [f0] + fwd
            seen.update(fibers)
            paths.append(fibers)
        return paths

    @staticmethod
    def _bridge(view, state, paths, max_turn, tol) -> list[list[int]]:
        """Join path ends that face each other across one slack fiber, until none do."""
        def join():
            ends = {}
            for i, fibers in enumerate(paths):
                nodes = _nodes_of(view, fibers)
                ends.setdefault(nodes[0], []).append((i, fibers[0], 0))
                ends.setdefault(nodes[-1], []).append((i, fibers[-1], 1))
            for v, here in ends.items():
                for i, f, side in here:
                    for h in (int(h) for h in view.incident(v)):
                        if state.active[h] or view.turn(f, v, h) > max_turn:
                            continue
                        u = view.other(h, v)
                        for j, g, side_j in ends.get(u, []):
                            ti, tj = state.tau[f], state.tau[g]
                            if j != i and view.turn(h, u, g) <= max_turn and abs(ti - tj) <= tol * max(ti, tj):
                                return i, side, h, j, side_j
            return None

        paths = [list(p) for p in paths]
        while (found := join()) is not None:
            i, side, h, j, side_j = found
            a = paths[i] if side == 1 else paths[i][::-1]
            b = paths[j] if side_j == 0 else paths[j][::-1]
            paths[i] = a + [h] + b
            del paths[j]
        return paths


def _nodes_of(view, fibers: list[int]) -> list[int]:
    """The node sequence of a fiber path."""
    a, b = (int(v) for v in view.edges[fibers[0]])
    if len(fibers) > 1 and a in view.edges[fibers[1]]:
        a, b = b, a
    nodes = [a, b]
    for f in fibers[1:]:
        nodes.append(view.other(f, nodes[-1]))
    return nodes
