"""Tendon consolidation: fewer tendons for (almost) the same pose.

An extractor reads strands off the idealized tensions; it does not know what a
tendon costs. A designer pays for every tendon (a motor, an anchor, routing),
so after extraction the engine greedily reduces the count, proving every step
on the realizable robot (:mod:`~tendon_taichi.extract.realizable`). Each reduction
round tries

* **drop** one tendon, and
* **join** two tendons whose ends lie within ``gap`` x L (rest coordinates),
  bridged by the shortest fiber path between those ends - one cable, one
  tension;

solves the realizable robot for every candidate, and keeps the candidate with
the lowest realizable pose error, provided that error is at most the larger of

* the extracted layout's error plus ``tolerance`` x L (the rise is cumulative
  over all rounds): a tendon that buys less pose accuracy than that is not
  worth its motor, and
* ``budget`` x L, the pose error the designer accepts anyway: while the pose
  is within it, fewer tendons are better;

a candidate whose robot cannot be solved is skipped. **Refinement** tries

* **trim** one fiber off one end of one tendon, and
* **extend** one end by one lattice fiber that turns by at most ``MAX_TURN``
  and reaches a fiber node no tendon uses,

keeps the best, and repeats, at most ``refine`` rounds, while each round
lowers the realizable pose error by at least ``REFINE_GAIN`` of it (and
``REFINE_FLOOR`` x L). A round first **screens** its candidates by one
Gauss-Newton step each from the current layout's solution
(:func:`~tendon_taichi.extract.realizable.predict_realizable`, a few linear solves
instead of an L-BFGS-B run), then solves in full, from the predicted
contractions, only the ``screen`` best predicted, and of those only the ones
predicted to make the gain a step needs (within ``SCREEN_MARGIN``). When the
best reduction is outside the bound, it is refined, and kept if that brings it
within. When no reduction fits, the layout left is refined, and if that
helped the reductions are tried again. Why: an extractor follows the idealized
tensions, which the realizable robot - one tension per tendon - cannot
reproduce exactly, and a dropped tendon's work can often be taken over by a
neighbour grown a little longer. Both bounds and the reach are fractions of the
body size, so they mean the same at every resolution.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..objective.settings import OptimizeSettings
from .fiber_view import FiberView
from .protocol import IdealizedState, Tendon
from .realizable import RealizableResult, predict_realizable, solve_realizable_poses
from .settings import MAX_TURN, REFINE_FLOOR, REFINE_GAIN, SCREEN_MARGIN, ConsolidationSettings

@dataclass
class Step:
    """One accepted round: ``action`` ('drop', 'join', 'trim' or 'extend'), the indices of the tendons
    it acted on (in the list before the round), and the count and realizable pose
    error (fraction of L) after it."""

    action: str
    tendons: tuple[int, ...]
    count: int
    realizable_pose_error_rel: float

    def as_json(self) -> dict:
        return {"action": self.action, "tendons": list(self.tendons), "count": self.count,
                "realizable_pose_error_rel": self.realizable_pose_error_rel}


@dataclass
class Consolidation:
    """The consolidated ``tendons``, their ``realizable`` robot, and the ``steps``
    taken from the ``extracted_count`` tendons whose realizable pose error was
    ``extracted_pose_error_rel``; ``evaluations`` candidate layouts were solved in
    full, of which ``unsolved`` could not be solved (an equilibrium did not
    converge) and were skipped; ``screened`` refinement candidates were screened
    (a candidate whose screen fails counts as unsolved)."""

    tendons: list[Tendon]
    realizable: RealizableResult
    extracted_count: int
    extracted_pose_error_rel: float
    steps: list[Step] = field(default_factory=list)
    evaluations: int = 0
    unsolved: int = 0
    screened: int = 0

    def as_json(self) -> dict:
        return {"extracted_count": self.extracted_count,
                "extracted_realizable_pose_error_rel": self.extracted_pose_error_rel,
                "steps": [s.as_json() for s in self.steps], "evaluations": self.evaluations,
                "unsolved": self.unsolved, "screened": self.screened}


class Bridges:
    """Joins of two tendons through the fiber lattice (rest coordinates); ``gap``
    is the reach as a fraction of the body size."""

    def __init__(self, problem: Problem, state: IdealizedState, gap: float):
        from scipy.sparse import csr_matrix

        f = problem.fibers
        self.view = FiberView(problem)
        self.state = state
        self.reach = gap * problem.size
        n, e = len(f.nodes), f.edges
        self.graph = csr_matrix((np.r_[f.a0, f.a0], (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                                shape=(n, n))

    def joins(self, a: Tendon, b: Tendon) -> list[Tendon]:
        """Every join of ``a`` and ``b`` end to end (up to four: either end of each)
        whose ends are within reach and whose bridged path visits no node twice."""
        out = []
        for na in (a.nodes[::-1], a.nodes):  # na ends at the joint
            for nb in (b.nodes, b.nodes[::-1]):  # nb starts there
                t = self.join(na, nb)
                if t is not None:
                    out.append(t)
        return out

    def join(self, na: np.ndarray, nb: np.ndarray) -> Tendon | None:
        """The tendon along ``na``, the shortest fiber path from its last node to the
        first of ``nb``, then ``nb``; None when the ends are out of reach."""
        from scipy.sparse.csgraph import dijkstra

        u, v = int(na[-1]), int(nb[0])
        nodes = self.view.nodes
        if np.linalg.norm(nodes[u] - nodes[v]) > self.reach:
            return None
        dist, pred = dijkstra(self.graph, indices=u, return_predecessors=True, limit=2.0 * self.reach)
        if not np.isfinite(dist[v]):
            return None
        bridge = [v]
        while bridge[-1] != u:
            bridge.append(int(pred[bridge[-1]]))
        path = [int(w) for w in na] + bridge[::-1][1:-1] + [int(w) for w in nb]
        if len(set(path)) != len(path):
            return None
        fibers = [self._fiber(path[k], path[k + 1]) for k in range(len(path) - 1)]
        return self.view.tendon(path[0], fibers, self.state)

    def _fiber(self, u: int, w: int) -> int:
        """The fiber joining fiber nodes u and w (neighbours on a path)."""
        return next(int(f) for f in self.view.incident(u) if self.view.other(int(f), u) == w)


class Candidate(NamedTuple):
    """A layout tried: the ``action`` that made it, the indices of the tendons it
    acted on, the ``tendons`` and their solved ``realizable`` robot."""

    action: str
    ids: tuple[int, ...]
    tendons: list[Tendon]
    realizable: RealizableResult

    @property
    def error(self) -> float:
        return self.realizable.pose_error_rel


class _Search:
    """Solves candidate layouts on the realizable robot, counting them in ``out``."""

    def __init__(self, problem, state, settings, solver, out: Consolidation, bridges: Bridges,
                 options: ConsolidationSettings):
        self.args = (problem, state, settings, solver)
        self.out, self.bridges = out, bridges
        self.rounds, self.screen = options.refine, options.screen

    def best(self, candidates, starts=None) -> Candidate | None:
        """The candidate with the lowest realizable pose error, or None; ``starts``
        (one (P, T) array or None per candidate) warm starts their solves."""
        problem, state, settings, solver = self.args
        best = None
        candidates = list(candidates)
        for (action, ids, tendons), start in zip(candidates, starts or [None] * len(candidates)):
            self.out.evaluations += 1
            try:
                r = solve_realizable_poses(problem, tendons, state, settings, solver, start)
            except ConvergenceError:  # a layout whose robot cannot be solved is not proven: skip it
                self.out.unsolved += 1
                continue
            if best is None or r.pose_error_rel < best.realizable.pose_error_rel:
                best = Candidate(action, ids, tendons, r)
        return best

    def refine(self, tendons: list[Tendon], real: RealizableResult) -> list[Candidate]:
        """Trims and extensions of ``tendons`` (solved as ``real``), the best each
        round, while each lowers the pose error enough (module docstring)."""
        chain = []
        for _ in range(self.rounds if tendons else 0):
            now = real.pose_error_rel
            need = min((1.0 - REFINE_GAIN) * now, now - REFINE_FLOOR)
            candidates = list(_refinements(tendons, self.bridges))
            if self.screen:
                candidates, starts = self._screened(candidates, real, need)
            else:
                starts = [real.ratios] * len(candidates)
            c = self.best(candidates, starts)
            if c is None or c.error > need:
                break
            chain.append(c)
            tendons, real = c.tendons, c.realizable
        return chain

    def _screened(self, candidates: list, real: RealizableResult, need: float) -> tuple[list, list]:
        """The candidates worth a full solve, and their predicted contractions: the
        ``screen`` best by :func:`predict_realizable` from ``real``, each predicted
        within ``SCREEN_MARGIN`` of ``need``."""
        problem, _, settings, solver = self.args
        positions = [real.x] if real.poses is None else [p.x for p in real.poses]
        scored = []  # (predicted error, predicted ratios, candidate)
        for c in candidates:
            self.out.screened += 1
            try:
                error, ratios = predict_realizable(problem, c[2], settings, real.ratios, positions, solver)
            except ConvergenceError:
                self.out.unsolved += 1
                continue
            scored.append((error, ratios, c))
        scored.sort(key=lambda s: s[0])
        kept = [(c, ratios) for error, ratios, c in scored[:self.screen] if error <= (1.0 + SCREEN_MARGIN) * need]
        return [c for c, _ in kept], [ratios for _, ratios in kept]


def consolidate(problem: Problem, tendons: list[Tendon], state: IdealizedState, settings: OptimizeSettings,
                real: RealizableResult, options: ConsolidationSettings, solver: str = "auto") -> Consolidation:
    """Greedy drops and joins, helped by refinement, then refinement of what is
    left (module docstring), from ``tendons``, whose realizable robot ``real`` is
    already solved."""
    base = real.pose_error_rel
    out = Consolidation(list(tendons), real, len(tendons), base)
    if not options.enabled:
        return out
    search = _Search(problem, state, settings, solver, out, Bridges(problem, state, options.gap), options)
    bound = max(base + options.tolerance, options.budget)
    while True:
        while out.tendons:
            c = search.best(_reductions(out.tendons, search.bridges))
            if c is None:
                break
            chain = [c] + (search.refine(c.tendons, c.realizable) if c.error > bound else [])
            if chain[-1].error > bound:
                break
            _accept(out, chain)
        polish = search.refine(out.tendons, out.realizable)
        _accept(out, polish)
        if not polish:
            return out


def _accept(out: Consolidation, chain: list[Candidate]) -> None:
    for c in chain:
        out.tendons, out.realizable = c.tendons, c.realizable
        out.steps.append(Step(c.action, c.ids, len(c.tendons), c.error))


def _reductions(tendons: list[Tendon], bridges: Bridges):
    """(action, tendon indices, tendon list) for every drop and every join."""
    for i in range(len(tendons)):
        yield "drop", (i,), tendons[:i] + tendons[i + 1:]
    for i in range(len(tendons)):
        for j in range(i + 1, len(tendons)):
            rest = [t for k, t in enumerate(tendons) if k not in (i, j)]
            for joined in bridges.joins(tendons[i], tendons[j]):
                yield "join", (i, j), rest + [joined]


def _refinements(tendons: list[Tendon], bridges: Bridges):
    """(action, (tendon index,), tendon list) for every trim and every extension
    of either end of every tendon (module docstring)."""
    view, state = bridges.view, bridges.state
    used = {int(v) for t in tendons for v in t.nodes}
    for i, t in enumerate(tendons):
        for nodes, fibers in ((list(t.nodes), list(t.fibers)), (list(t.nodes[::-1]), list(t.fibers[::-1]))):
            start, last, f_in = int(nodes[0]), int(nodes[-1]), int(fibers[-1])  # this pass edits the last end
            if len(fibers) > 1:
                yield "trim", (i,), tendons[:i] + [view.tendon(start, fibers[:-1], state)] + tendons[i + 1:]
            for f in (int(f) for f in view.incident(last)):
                if f != f_in and view.other(f, last) not in used and view.turn(f_in, last, f) <= MAX_TURN + 1e-9:
                    yield "extend", (i,), tendons[:i] + [view.tendon(start, fibers + [f], state)] + tendons[i + 1:]
