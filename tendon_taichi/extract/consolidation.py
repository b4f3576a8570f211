"""Tendon consolidation: fewer tendons for (almost) the same pose, each a smooth
route that a designer can build.

An extractor reads strands off the idealized tensions; it does not know what a
tendon costs, and its tendons are chains of lattice fibers. Consolidation
first fits every extracted tendon with a smooth route that keeps the
clearance from the walls (:mod:`.routes`), then greedily reduces the count,
proving every step on the *as-built* realizable robot - the body with only
those routes, capstan friction included (:mod:`.realizable`). Each round tries

* **drop** one route, and
* **join** two routes whose ends lie within ``gap`` x L: one smooth route
  along both and across the gap (never a path through the lattice),

and ranks them by what route optimization minimizes (:mod:`.routing`): the
as-built pose error squared plus the routes' shape cost - the friction price
of the pull they lose to their bends, and the penalties on bends sharper than
a channel takes and on routes that turn back on themselves. Its square root is the layout's *effective error*
(fraction of L): its pose error with the lost pull priced in. A round first
**screens** its candidates by one Gauss-Newton step each from the current
layout's solution (:func:`~tendon_taichi.extract.realizable.predict_realizable`),
then solves the ``screen`` best in full (``screen`` 0: every one, unscreened),
and keeps the least costly whose effective error is within the bound, the
larger of

* the extracted layout's as-built error plus ``tolerance`` x L (cumulative
  over all rounds; the fitted routes' error, or, when their effective error is
  over the budget, that of the routes optimized once): a tendon that buys
  less pose accuracy than that is not worth its motor, and
* ``budget`` x L, the pose error the designer accepts anyway.

So a reduction is not taken when the pull its routes lose to friction costs
more than the budget allows - a join that loses more pull than it buys in
pose, or a drop that leaves one route bent too far to do the work of two.
When no candidate is within the bound, the PROBES least costly (within REACH
times it) have their routes optimized, and the first that comes within is
kept.
At the end the routes left are **oriented** (each pulled at the end that
serves the pose at least cost) and **optimized**: control points, anchors,
pull ends and contractions together, at most ``refine`` rounds.
Both bounds and the reach are fractions of the body size, and routes do not
depend on the mesh, so they mean the same at every resolution.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Callable, NamedTuple

import numpy as np

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..tasks.pool import Pool
from .context import Context
from .protocol import IdealizedState, Tendon, turn_angles
from .realizable import RealizableResult, pose_tension, predict_realizable, solve_realizable_poses, warm_ratios
from .clearance import clear_route, held_clearance, keeps_as_much
from .exits import exit_route
from .joins import join_key, joined_routes, partner_pairs, smooth_joins
from .joins import JOIN_PARTNERS  # noqa: F401  (its import path before it moved)
from .routes import Route, fit_route, sample_count
from .routing import PRICE_PER_BUDGET, RouteSettings, optimize_routes, shape_cost
from .settings import ConsolidationSettings


#: when no reduction fits, the PROBES least-cost ones whose as-built error is at most REACH times the
#: bound are route-optimized (one round each) to try to bring them within
REACH = 4.0
PROBES = 2
#: pieces of one strand (:func:`merge_pieces`): ends at most MERGE_GAP x L apart, running on in
#: line (tangents and the gap within MERGE_ANGLE of each other)
MERGE_GAP = 0.04
MERGE_ANGLE = np.radians(25.0)


@dataclass
class Step:
    """One accepted change: ``action`` ('drop', 'join', 'orient' or 'route'), the
    indices of the routes it acted on (in the list before it), and the count and
    as-built pose error (fraction of L) after it."""

    action: str
    tendons: tuple[int, ...]
    count: int
    realizable_pose_error_rel: float

    def as_json(self) -> dict:
        return {"action": self.action, "tendons": list(self.tendons), "count": self.count,
                "realizable_pose_error_rel": self.realizable_pose_error_rel}


@dataclass
class Layout:
    """Routes with their solved as-built robot, and what a designer weighs them by."""

    routes: list[Route]
    realizable: RealizableResult
    cost: float
    source: str
    optimized: bool = False  # oriented and route-optimized (:func:`finish`)

    @property
    def count(self) -> int:
        return len(self.routes)

    @property
    def error(self) -> float:
        return self.realizable.pose_error_rel

    @property
    def effective(self) -> float:
        """The effective error (fraction of L): the square root of the cost."""
        return float(np.sqrt(self.cost))


    def tendons(self) -> list[Tendon]:
        """The routes as tendons, each with its contraction (the first pose's)."""
        out = []
        for r, c in zip(self.routes, np.atleast_2d(self.realizable.contraction)[0] if self.routes else []):
            t = r.tendon()
            t.contraction = float(c)
            out.append(t)
        return out

    def front_entry(self, mu: float, kink_angle: float) -> dict:
        """The figures of this layout on the count/error front."""
        turns = [turn_angles(r.waypoints) for r in self.routes]
        capstan = [float(np.exp(-mu * t.sum())) for t in turns]
        return {"count": self.count, "realizable_pose_error_rel": self.error,
                "capstan_worst": min(capstan, default=1.0),
                "kinks": int(sum((t > np.radians(kink_angle)).sum() for t in turns)),
                "total_length": float(sum(r.length for r in self.routes)), "source": self.source}


@dataclass
class Consolidation:
    """The consolidated ``layout`` (routes and their as-built robot), the ``steps``
    taken from the ``extracted_count`` tendons (``strands`` routes once the pieces
    of one strand were merged) whose fitted routes had the as-built
    pose error ``extracted_pose_error_rel``, and per count the layout it passed
    through (``front``); ``evaluations`` candidate layouts were solved in full, of
    which ``unsolved`` could not be (an equilibrium did not converge) and were
    skipped; ``screened`` candidates were screened; ``route_evaluations``
    equilibria were solved by route optimization, in ``route_s`` seconds."""

    layout: Layout
    extracted_count: int
    extracted_pose_error_rel: float
    steps: list[Step] = field(default_factory=list)
    strands: int | None = None  # routes left once the pieces of one strand were merged (:func:`merge_pieces`)
    front: dict[int, Layout] = field(default_factory=dict)
    evaluations: int = 0
    unsolved: int = 0
    screened: int = 0
    route_evaluations: int = 0
    route_s: float = 0.0

    @property
    def tendons(self) -> list[Tendon]:
        return self.layout.tendons()

    @property
    def realizable(self) -> RealizableResult:
        return self.layout.realizable

    def relabel(self, source: str) -> "Consolidation":
        """The same outcome credited to extractor ``source`` (which found the same
        tendons), its route optimization not counted again."""
        old = self.layout.source

        def credit(lay: Layout) -> Layout:
            routes = [replace(r, source=source) if r.source == old else r for r in lay.routes]
            return replace(lay, routes=routes, source=source)

        return replace(self, layout=credit(self.layout), front={k: credit(lay) for k, lay in self.front.items()},
                       route_evaluations=0, route_s=0.0)

    def as_json(self) -> dict:
        return {"extracted_count": self.extracted_count, "strands": self.strands,
                "extracted_realizable_pose_error_rel": self.extracted_pose_error_rel,
                "steps": [s.as_json() for s in self.steps], "evaluations": self.evaluations,
                "unsolved": self.unsolved, "screened": self.screened,
                "route_evaluations": self.route_evaluations, "route_s": self.route_s}


class Candidate(NamedTuple):
    """A layout to try: the ``action`` that made it, the indices of the routes it
    acted on, its ``routes`` and the contractions (P, T) to start its solve from."""

    action: str
    ids: tuple[int, ...]
    routes: list[Route]
    start: np.ndarray


#: what a search counts (:class:`Consolidation` fields)
TALLY = ("evaluations", "unsolved", "screened", "route_evaluations", "route_s")


class _Search:
    """Solves and ranks layouts on the as-built robot of ``context``, counting them in ``out``."""

    def __init__(self, context: Context, options: ConsolidationSettings, route_settings: RouteSettings,
                 source: str):
        self.context = context
        self.problem, self.state, self.settings, self.solver = (context.problem, context.state, context.settings,
                                                                context.solver)
        self.options, self.rs, self.source = options, route_settings, source
        self.log = context.say
        self.out: Consolidation | None = None
        #: worker processes that share the full solves and the screen of :meth:`ranked` (None: none)
        self.workers: Pool | None = context.workers
        #: the joins made so far (:meth:`joins`), by what of the two routes makes them (:func:`~.joins.join_key`)
        self._joins: dict[tuple, list[Route]] = {}

    # ------------------------------------------------------------ the same search in a worker process
    def spec(self) -> tuple:
        """What a worker process needs to make this search again (:meth:`again`): its
        arguments (the context pickles without its log and workers)."""
        return self.context, self.options, self.rs, self.source

    @classmethod
    def again(cls, spec: tuple, layout: Layout) -> "_Search":
        """The search ``spec`` describes, silent, counting into a tally of its own."""
        search = cls(*spec)
        search.out = Consolidation(layout, 0, 0.0)
        return search

    def tally(self) -> dict:
        """What this search counted (:data:`TALLY`)."""
        return {k: getattr(self.out, k) for k in TALLY}

    def add(self, tally: dict) -> None:
        """Count what another search counted (:meth:`tally`)."""
        for k, v in tally.items():
            setattr(self.out, k, getattr(self.out, k) + v)

    # ------------------------------------------------------------ solving and ranking
    def cost(self, routes: list[Route], error: float) -> float:
        """The as-built pose error (fraction of L) squared plus the routes' shape
        cost: the friction price of their bends and the penalties on sharp bends and
        turning back (:func:`~tendon_taichi.extract.routing.shape_cost`)."""
        return error ** 2 + shape_cost([r.waypoints for r in routes], self.rs)[0]

    def solve(self, routes: list[Route], start=None, near: Layout | None = None) -> Layout | None:
        """The as-built robot of ``routes`` (its contractions solved from ``start``
        (P, T) where given, its equilibria from those of the ``near`` layout), or None
        when it cannot be solved."""
        tendons = [r.tendon() for r in routes]
        if self.out is not None:
            self.out.evaluations += 1
        try:
            real = solve_realizable_poses(self.context, tendons, start,
                                          None if near is None else positions(near.realizable))
        except ConvergenceError:  # a layout whose robot cannot be solved is not proven: skip it
            if self.out is not None:
                self.out.unsolved += 1
            return None
        return Layout(routes, real, self.cost(routes, real.pose_error_rel), self.source)

    def start_ratios(self, routes: list[Route], tensions: np.ndarray, at: list[np.ndarray] | None = None) -> np.ndarray:
        """Contractions (P, T) that give each route its tension in each pose, ``tensions``
        (P, T) N, at the idealized equilibria or at each pose's positions ``at`` (n, 2)."""
        tendons = [r.tendon() for r in routes]
        states = self.state.poses or [self.state]
        if at is not None:
            states = [replace(st, x=x) for st, x in zip(states, at)]
        return np.array([warm_ratios(self.problem, tendons, st, t) for st, t in zip(states, tensions)])

    def ranked(self, candidates: list[Candidate], now: Layout) -> list[tuple[Candidate, Layout]]:
        """The candidates (after the screen) solved in full, least cost first; those
        that cannot be solved are left out."""
        if self.options.screen and len(candidates) > self.options.screen:
            candidates = self._screened(candidates, now)
        layouts = self.each(self.solve, _solve_task, [(c.routes, c.start, now) for c in candidates])
        return sorted([s for s in zip(candidates, layouts) if s[1] is not None], key=lambda s: s[1].cost)

    def each(self, here: Callable, task: Callable, jobs: list[tuple]) -> list:
        """``here(*job)`` for every job, in order: in this process, or - where there are
        workers and more than one job - as ``task(spec, job)`` shared with them (the
        same results), each one's tally added to this search's."""
        if self.workers is None or not self.workers.active or len(jobs) < 2:
            return [here(*job) for job in jobs]
        done = self.workers.map(partial(task, self.spec()), jobs)
        for _, tally in done:
            self.add(tally)
        return [out for out, _ in done]

    def reduce(self, now: Layout, bound: float) -> tuple[Candidate, Layout] | None:
        """The next reduction: the least-cost drop or join whose effective error is
        within ``bound``; when none is, the first of the PROBES least-cost ones
        (within REACH x bound) that route optimization brings within it; None when
        no reduction fits."""
        ranked = self.ranked(self.reductions(now), now)
        within = [s for s in ranked if s[1].effective <= bound]
        if within:
            return within[0]
        for cand, lay in [s for s in ranked if s[1].effective <= REACH * bound][:PROBES]:
            lay = self.optimize(lay, rounds=1)
            if lay.effective <= bound:
                return cand, lay
        return None

    def _screened(self, candidates: list[Candidate], now: Layout) -> list[Candidate]:
        """The ``screen`` candidates of least cost as one Gauss-Newton step predicts
        them from the current layout's solution, each with its predicted contractions."""
        found = self.predicted(candidates, now)
        scored = [(cost, c._replace(start=ratios)) for c, (cost, ratios) in zip(candidates, found) if cost is not None]
        scored.sort(key=lambda s: s[0])
        return [c for _, c in scored[:self.options.screen]]

    def predicted(self, candidates: list[Candidate], now: Layout) -> list[tuple[float | None, np.ndarray | None]]:
        """:meth:`predict` for each candidate, in order (shared with the workers)."""
        return self.each(self.predict, _predict_task, [(c.routes, c.start, now) for c in candidates])

    def predict(self, routes: list[Route], start: np.ndarray, now: Layout) -> tuple[float | None, np.ndarray | None]:
        """The cost of ``routes`` and their contractions (P, T) as one Gauss-Newton step
        from ``now``'s solution predicts them (None, None where it fails)."""
        self.out.screened += 1
        try:
            error, ratios = predict_realizable(self.context, [r.tendon() for r in routes], start,
                                               positions(now.realizable))
        except ConvergenceError:
            self.out.unsolved += 1
            return None, None
        return self.cost(routes, error), ratios

    # ------------------------------------------------------------ candidates
    def reductions(self, now: Layout) -> list[Candidate]:
        """Every drop of the current layout, and every join of two partner routes
        (:func:`partner_pairs`: each with its ``JOIN_PARTNERS`` nearest)."""
        routes, start = now.routes, np.atleast_2d(now.realizable.ratios).reshape(self.problem.n_poses, -1)
        out = []
        for i in range(len(routes)):
            out.append(Candidate("drop", (i,), routes[:i] + routes[i + 1:], np.delete(start, i, axis=1)))
        reach = self.options.gap * self.problem.size
        clearance = self.rs.clearance
        pairs = partner_pairs(routes)
        self.make_joins([(routes[i], routes[j]) for i, j in pairs], reach, clearance)
        for i, j in pairs:
            rest = [r for k, r in enumerate(routes) if k not in (i, j)]
            rest_start = np.delete(start, [i, j], axis=1)
            for joined in self.joins(routes[i], routes[j], reach, clearance):
                s = np.concatenate([rest_start, 0.5 * (start[:, [i]] + start[:, [j]])], axis=1)
                out.append(Candidate("join", (i, j), rest + [joined], s))
        return out

    def joins(self, a: Route, b: Route, reach: float, clearance: float) -> list[Route]:
        """:func:`smooth_joins` of ``a`` and ``b`` in this search's body, made once per
        search for the same two routes: the front's beam meets the same pairs in many
        layouts and counts (solved, with contractions of their own), and fitting a
        join that keeps the clearance was most of what the search cost where the
        extractors over-segment. A join depends on its routes only through
        :func:`~.joins.join_key`, and routes are never changed in place, so the joins made
        before are the ones made again, to the bit."""
        key = (join_key(a), join_key(b), reach, clearance)
        if key not in self._joins:
            self._joins[key] = smooth_joins(a, b, self.problem, reach, clearance)
        return list(self._joins[key])

    def make_joins(self, pairs: list[tuple[Route, Route]], reach: float, clearance: float) -> None:
        """The joins of those ``pairs`` not made yet, made now and kept for :meth:`joins`:
        shared with the workers where there are any (each join is a fit of its own;
        the same joins as made here)."""
        todo: dict[tuple, tuple[Route, Route]] = {}
        for a, b in pairs:
            key = (join_key(a), join_key(b), reach, clearance)
            if key not in self._joins:
                todo.setdefault(key, (a, b))
        if self.workers is None or not self.workers.active or len(todo) < 2:
            return  # made one by one as they are asked for
        made = self.workers.map(partial(_joins_task, (self.problem, reach, clearance)), list(todo.values()))
        self._joins.update(zip(todo, made))

    # ------------------------------------------------------------ routes
    def orient(self, now: Layout) -> tuple[Layout, list[int]]:
        """Each route pulled at the end that serves the pose at least cost (a route
        that leaves the body is pulled where it leaves)."""
        flipped = []
        for i in range(now.count):
            if now.routes[i].exits:
                continue
            routes = list(now.routes)
            routes[i] = routes[i].reversed()
            lay = self.solve(routes, np.atleast_2d(now.realizable.ratios).reshape(self.problem.n_poses, -1), now)
            if lay is not None and lay.cost < now.cost:
                now, flipped = lay, flipped + [i]
        return now, flipped

    def finish(self, now: Layout, rounds: int | None = None,
               iterations: int | None = None) -> tuple[Layout, list[Step]]:
        """The layout oriented and its routes optimized (at most ``rounds``, default
        ``refine``, rounds of at most ``iterations``, default the route settings', SLSQP
        iterations), and the steps that took."""
        steps = []
        now, flipped = self.orient(now)
        if flipped:
            steps.append(Step("orient", tuple(flipped), now.count, now.error))
        done = self.optimize(now, rounds, iterations)
        if done is not now:
            steps.append(Step("route", tuple(range(done.count)), done.count, done.error))
        return replace(done, optimized=True), steps

    def optimize(self, now: Layout, rounds: int | None = None, iterations: int | None = None) -> Layout:
        """The layout's routes and contractions optimized together, at most
        ``rounds`` (default ``refine``) rounds of at most ``iterations`` (default the
        route settings') SLSQP iterations, while a round lowers the cost; each round
        starts from the routes resampled for their length and made to keep the
        clearance (a flagged route, as much as it kept)."""
        rounds = self.options.refine if rounds is None else min(rounds, self.options.refine)
        rs = self.rs if iterations is None else replace(self.rs, iterations=iterations)
        for k in range(rounds if now.routes else 0):
            size = self.problem.size
            routes = [replace(r, samples=sample_count(r.length, size), contraction=None) for r in now.routes]
            routes = [clear_route(r, self.problem.walls, self.rs.clearance) for r in routes]
            real = now.realizable
            self.log(f"{self.source}: optimizing {len(routes)} route(s), round {k + 1}")
            t0 = time.perf_counter()
            res = optimize_routes(self.context, routes, np.atleast_2d(real.ratios).reshape(self.problem.n_poses, -1),
                                  rs, positions(real))
            self.out.route_evaluations += res.evaluations
            self.out.route_s += time.perf_counter() - t0
            cleared = [clear_route(r, self.problem.walls, self.rs.clearance) for r in res.routes]
            c = self.rs.clearance
            if not all(keeps_as_much(a, held_clearance(b, c), c) for a, b in zip(cleared, routes)):
                break  # a route moved where it keeps less clearance than it did
            lay = self.solve(cleared, res.ratios, now)
            if lay is None or lay.cost >= now.cost * (1.0 - 1e-3):
                break
            now = lay
        return now


def _solve_task(spec: tuple, job: tuple[list[Route], np.ndarray, Layout]) -> tuple[Layout | None, dict]:
    """:meth:`_Search.solve` as a worker process runs it (``job``: routes, start, near)."""
    search = _Search.again(spec, job[2])
    return search.solve(*job), search.tally()


def _joins_task(spec: tuple, pair: tuple[Route, Route]) -> list[Route]:
    """:func:`~.joins.smooth_joins` of a pair as a worker process makes them (``spec``:
    the problem, the reach and the clearance, m)."""
    problem, reach, clearance = spec
    return smooth_joins(*pair, problem, reach, clearance)


def _predict_task(spec: tuple, job: tuple[list[Route], np.ndarray, Layout]) -> tuple[tuple, dict]:
    """:meth:`_Search.predict` as a worker process runs it."""
    search = _Search.again(spec, job[2])
    return search.predict(*job), search.tally()


def _in_line(a: Route, b: Route, gap: float) -> bool:
    """Whether ``a`` (ending where ``b`` starts) runs on into ``b``: their ends within
    ``gap`` and the tangents there, and the gap between, within MERGE_ANGLE."""
    pa, pb = a.waypoints, b.waypoints
    step = pb[0] - pa[-1]
    if np.linalg.norm(step) > gap:
        return False
    dirs = [pa[-1] - pa[-2], pb[1] - pb[0]] + ([step] if np.linalg.norm(step) > 1e-9 * gap else [])
    unit = [d / max(float(np.linalg.norm(d)), 1e-300) for d in dirs]
    return all(float(u @ v) >= np.cos(MERGE_ANGLE) for u in unit for v in unit)


def merge_pieces(routes: list[Route], tensions: np.ndarray, problem: Problem,
                 clearance: float) -> tuple[list[Route], np.ndarray]:
    """Routes (and their tensions (P, T), N) with every two pieces of one strand -
    ends within ``MERGE_GAP`` x L, running on in line - made one smooth route
    (:func:`~.routes.join_routes`, kept clear and carried out of the body as the
    scene says), until none is left: an extractor that breaks a strand where its
    fibers thin out hands the search fewer, longer routes. A merge that would keep
    less clearance than its pieces is not made; the merged tension is the
    length-weighted mean."""
    if len(routes) < 2:
        return list(routes), tensions
    routes, tensions = list(routes), np.array(tensions, dtype=float).reshape(-1, len(routes))
    while (found := _first_merge(routes, problem, clearance)) is not None:
        i, j, one = found
        a, b = routes[i].inner(), routes[j].inner()
        w = a.length / max(a.length + b.length, 1e-300)
        merged = w * tensions[:, i] + (1 - w) * tensions[:, j]
        keep = [k for k in range(len(routes)) if k not in (i, j)]
        routes = [routes[k] for k in keep] + [replace(one, source=routes[i].source or routes[j].source)]
        tensions = np.concatenate([tensions[:, keep], merged[:, None]], axis=1)
    return routes, tensions


def _first_merge(routes: list[Route], problem: Problem, clearance: float) -> tuple[int, int, Route] | None:
    """The first two partner routes (:func:`partner_pairs`) that are pieces of one
    strand (:func:`_in_line`), and the route they make; None where no two are."""
    gap = MERGE_GAP * problem.size
    for i, j in partner_pairs(routes):
        one = next(joined_routes(routes[i], routes[j], problem, clearance, lambda a2, b2: _in_line(a2, b2, gap)), None)
        if one is not None:
            return i, j, one
    return None


def positions(real: RealizableResult) -> list[np.ndarray]:
    """Each pose's equilibrium (n, 2) of a solved robot."""
    return [real.x] if real.poses is None else [p.x for p in real.poses]


def extracted_routes(problem: Problem, tendons: list[Tendon], state: IdealizedState, clearance: float,
                     source: str = "") -> tuple[list[Route], np.ndarray]:
    """Each extracted tendon as a smooth route that keeps ``clearance`` (m) from the
    walls - or, where the body is too narrow for it, the largest clearance it can,
    flagged (:func:`~.clearance.clear_route`); none is left out - and that leaves
    the body where the scene says (:func:`~.exits.exit_route`), and the routes'
    tensions in each pose (P, T), N, from their tendons' fibers."""
    states = state.poses or [state]
    routes = [exit_route(fit_route(t.waypoints, problem.size, t.tension, t.tension_std, source), problem, clearance)
              for t in tendons]
    tensions = [[pose_tension(st, t) for st in states] for t in tendons]
    return routes, np.array(tensions).reshape(len(routes), len(states)).T


def consolidate(context: Context, tendons: list[Tendon], options: ConsolidationSettings,
                source: str = "") -> Consolidation:
    """Routes from an extractor's ``tendons`` on the as-built robot of ``context``
    (its log hears of the steps), then greedy drops and smooth joins, then
    orientation and route optimization (module docstring). With consolidation off
    (``options.enabled`` false), the fitted routes as they are."""
    rs = route_settings(context.problem, options)
    search = _Search(context, options, rs, source)
    routes, tensions = extracted_routes(context.problem, tendons, context.state, rs.clearance, source)
    if options.enabled:
        count = len(routes)
        routes, tensions = merge_pieces(routes, tensions, context.problem, rs.clearance)
        if len(routes) < count:
            search.log(f"{source}: {count} extracted tendons are {len(routes)} strands (pieces in line merged)")
    for i, r in enumerate(routes):
        if r.kept_clearance is not None:
            search.log(f"{source}: route {i + 1} keeps {1e3 * r.kept_clearance:.2f} mm of the "
                       f"{1e3 * rs.clearance:.2f} mm clearance (the body is too narrow for it there)")
    first = search.solve(routes, search.start_ratios(routes, tensions))
    if first is None:
        raise ConvergenceError(f"the as-built robot of {source or 'the'} tendons cannot be solved")
    out = Consolidation(first, len(tendons), first.error, strands=len(routes))
    search.out = out
    out.front[first.count] = first
    if not options.enabled:
        return out
    if first.effective > options.budget:  # fitted routes that fall short: optimized first, for an honest start
        now = search.optimize(first, rounds=1)
        if now is not first:
            out.steps.append(Step("route", tuple(range(now.count)), now.count, now.error))
            out.front[now.count] = now
    else:
        now = first
    bound = max(now.error + options.tolerance, options.budget)
    while now.routes:
        found = search.reduce(now, bound)
        if found is None:
            break
        cand, now = found
        out.steps.append(Step(cand.action, cand.ids, now.count, now.error))
        out.front[now.count] = now
        search.log(f"{source}: {cand.action} -> {now.count} tendon(s), as built {100 * now.error:.2f}% of L")
    done, steps = search.finish(now)
    out.steps += steps
    out.layout = done
    out.front[done.count] = done
    return out


def route_settings(problem: Problem, options: ConsolidationSettings) -> RouteSettings:
    """The route optimization's settings: the scene's [tendons] table, and the price
    of the pull lost to friction from the budget (:mod:`.routing`)."""
    ts = problem.scene.tendons
    price = PRICE_PER_BUDGET * options.budget ** 2 if options.budget > 0 else RouteSettings.friction_price
    return RouteSettings(friction=ts.friction, clearance=ts.clearance * problem.size, friction_price=price)
