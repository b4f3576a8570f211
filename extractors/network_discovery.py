"""A baseline in the spirit of the two-stage method of Bern et al. 2017 ("network
discovery"), which the paper replaces. This is a re-creation for comparison, not
the original code: keep the most active fibers (tension >= ``threshold`` x the
largest tension), then repeatedly start from the most tensioned unused one and
grow a path at both ends by following the strongest co-activated neighbour,
with no rule on direction or tension similarity; drop paths shorter than
``min_length``.
"""

from __future__ import annotations

from dataclasses import dataclass

from tendon_taichi.extraction import EXTRACTOR_API, Extractor, FiberView, IdealizedState, Tendon, prune


class NetworkDiscoveryExtractor(Extractor):
    name = "network_discovery"
    description = "baseline after Bern et al. 2017: follow the strongest co-activated neighbour"
    api = EXTRACTOR_API

    @dataclass
    class Options:
        threshold: float = 0.2      # keep fibers with tau >= threshold x max tau
        min_length: float = 0.01    # m
        ranges = {"threshold": (0.0, 1.0), "min_length": (0.0, None)}  # checked by make_options

    def extract(self, problem, state: IdealizedState, options) -> list[Tendon]:
        view = FiberView(problem)
        tau = state.tau
        if not state.active.any():
            return []
        keep = state.active & (tau >= options.threshold * tau.max())
        used = ~keep
        tendons = view.greedy_tendons(state, used, lambda seed, visited:
                                      lambda v, f: self._grow(view, tau, v, used, visited))
        return prune(tendons, options)

    @staticmethod
    def _grow(view, tau, v, used, visited) -> list[int]:
        added = []
        while True:
            cands = [int(g) for g in view.incident(v) if not used[g] and view.other(int(g), v) not in visited]
            if not cands:
                return added
            g = max(cands, key=lambda f: tau[f])
            used[g] = True
            v = view.other(g, v)
            visited.add(v)
            added.append(g)
