"""Greedy strand tracing.

Seed at the most tensioned unused active fiber and extend both ends through the
active neighbour that continues straightest (ties: the closest tension),
provided the turn is at most ``max_turn`` and its tension is within
``tension_tol`` of the strand's mean; across one slack fiber if
``bridge_gaps``. Stop at a sharp turn, a tension jump, or a node the strand
already visits; drop strands shorter than ``min_length`` or weaker than
``min_tension`` x the strongest strand.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from tendon_taichi.extraction import EXTRACTOR_API, Extractor, FiberView, IdealizedState, Tendon, prune


class StrandsExtractor(Extractor):
    name = "strands"
    description = "greedy strand tracing: straightest continuation with a similar tension"
    api = EXTRACTOR_API

    @dataclass
    class Options:
        max_turn: float = 45.0      # degrees, largest turn inside a strand
        tension_tol: float = 0.35   # largest |tau - strand mean| / strand mean
        bridge_gaps: bool = True    # continue across one slack fiber
        min_length: float = 0.01    # m
        min_tension: float = 0.25   # drop strands weaker than this x the strongest one
        ranges = {"max_turn": (0.0, 180.0), "tension_tol": (0.0, None), "min_length": (0.0, None),
                  "min_tension": (0.0, 1.0)}  # checked by make_options

    def extract(self, problem, state: IdealizedState, options) -> list[Tendon]:
        view = FiberView(problem)
        tau, active = state.tau, state.active
        used = ~active  # slack fibers never seed a strand

        def stepper(seed, visited):
            tensions = [tau[seed]]  # the strand's tensions so far, shared by both ends
            return lambda v, f: self._grow(view, state, options, v, f, used, visited, tensions)

        return prune(view.greedy_tendons(state, used, stepper), options)

    def _grow(self, view, state, o, v, f_in, used, visited, tensions) -> list[int]:
        """Extend from node v (reached along f_in); returns the fibers added, in order."""
        max_turn = math.radians(o.max_turn) + 1e-9  # lattice angles are exact multiples of 45
        added = []
        while True:
            mean = sum(tensions) / len(tensions)
            step = self._next(view, state, v, f_in, used, visited, mean, max_turn, o.tension_tol)
            if step is None and o.bridge_gaps:
                step = self._bridge(view, state, v, f_in, used, visited, mean, max_turn, o.tension_tol)
            if step is None:
                return added
            for g in step:
                used[g] = True
                v = view.other(g, v)
                visited.add(v)
                added.append(g)
            f_in = step[-1]
            tensions.append(state.tau[step[-1]])

    @staticmethod
    def _next(view, state, v, f_in, used, visited, mean, max_turn, tol):
        best = None
        for g in view.incident(v):
            g = int(g)
            if g == f_in or used[g] or view.other(g, v) in visited:
                continue
            turn = view.turn(f_in, v, g)
            if turn > max_turn or abs(state.tau[g] - mean) > tol * mean:
                continue
            key = (round(turn, 9), abs(state.tau[g] - mean))
            if best is None or key < best[0]:
                best = (key, g)
        return None if best is None else [best[1]]

    def _bridge(self, view, state, v, f_in, used, visited, mean, max_turn, tol):
        """Across one slack fiber h to an active continuation g."""
        best = None
        for h in view.incident(v):
            h = int(h)
            u = view.other(h, v)
            if h == f_in or state.active[h] or u in visited or view.turn(f_in, v, h) > max_turn:
                continue
            nxt = self._next(view, state, u, h, used, visited | {u}, mean, max_turn, tol)
            if nxt is not None:
                turn = view.turn(f_in, v, h) + view.turn(h, u, nxt[0])
                if best is None or turn < best[0]:
                    best = (turn, [h, nxt[0]])
        return None if best is None else best[1]
