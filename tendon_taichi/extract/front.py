"""The count/error front: for every tendon count k, the best k-tendon layout found,
its routes optimized (``docs/method.md``, "The front").

Greedy consolidation (:mod:`.consolidation`) walks one path from an extractor's
tendons down to few: which layout of a given count it reaches depends on the
lattice the tendons came from. The front searches wider, from every extractor's
tendons together:

* **seeds**: every layout each extractor's consolidation passed through, and the
  *pooled* layout - the union of every extractor's consolidated routes, near
  duplicates (:func:`same_route`) kept once;
* **beam search**: from the most tendons down, the ``beam`` best distinct layouts
  of each count (by effective error, the as-built error with the pull lost to
  friction priced in - what consolidation ranks by) are each reduced by every
  drop and smooth join (ends up to ``JOIN_GAP`` x L apart; screened by one
  Gauss-Newton step, the best solved in full), and the results compete with
  the seeds of the count below;
* **exhaustive low counts**: for k up to ``EXHAUSTIVE``, every pooled route
  alone and every smooth join of two partners (each route with its
  ``JOIN_PARTNERS`` nearest; k = 1), every set of k pooled routes (k > 1; from a
  pool of more than ``PAIR_POOL``, the pairs among the routes the screen ranks
  best alone and each with the best, :func:`~.pooled.screened_pairs`) are
  screened from the best layout of the count above and the best solved in
  full; the ``beam`` best of them and the one of least pose error
  join the beam's layouts of that count (beside them: the beam's path is the
  same with or without them). Which few routes a small layout keeps matters
  most, and where the beam's path from the most tendons leads depends on the
  lattice;
* **finish**: up to the first count within the budget, every layout kept of
  that count (the beam's and the exhaustive search's) is oriented and screened
  by one short round of route optimization (control points, ends and
  contractions; ``EXTEND_SCREEN`` SLSQP iterations), the ``FINISH_BEST`` least
  costly are finished (``refine`` rounds more), and the least costly of those
  is the count's (:func:`_finish_best`); the count above it, only the best, one
  round; the counts above that are left out (``Front.left``): the recommendation
  is decided below them. Where none is within the budget yet, the counts above
  ``STALL`` in a row that each lowered the error by less than consolidation's
  tolerance are left out the same way;
* **monotone**: where a count's layout has a larger as-built error than the one
  below (by more than the soft IK's precision, ``PRECISION``), the smaller
  layout with one more pooled route added is solved and kept when it does
  better - a tendon more never makes the best layout found worse;
* **slack routes**: a finished layout whose routes include slack ones (no
  tension in any pose, :func:`slack_routes`) is the same robot without them,
  and that smaller layout replaces the front's of its count when its as-built
  error is lower;
* **extension** (:func:`_extend`): up to one count above the first within the
  budget, each count's layout with one route end carried on straight by
  ``EXTEND`` x L (each end of each route in turn), solved and screened by one
  short round of route optimization (``EXTEND_SCREEN`` SLSQP iterations); the
  best screened is finished and replaces the layout when that costs less. An
  extractor's strand ends where the optimized fibers thin out, often short of
  where the tendon does most, and route optimization moves an end only
  downhill: carried on, a route can reach a better optimum it cannot walk to
  (snake_planted_1t_s1 at level 3: one tendon 0.22 -> 0.07 % of L). Before a
  route optimization has adapted the rest of a route to its new end, an
  extension mostly costs more than the layout; after a short one, the order of
  the extensions is mostly that of their finished costs
  (``benchmarks/extension_screen.py``);
* **descent** (:func:`_descend`): from the front's most tendons down, each
  count's finished layout is reduced by every drop and smooth join (screened, the
  best solved in full); where the least costly reduction, as it is, already costs
  less than the layout held for the count below, it is finished (one round)
  and replaces that layout when it still costs less. The beam reduced the
  layouts as extracted, before route optimization moved their routes; a
  finished layout is a better start, and which of the two leads to the best
  smaller layout depends on the lattice. The monotone repair then runs again
  above each count the descent changed;
* **prior layouts** (``priors``, :class:`PriorLayout`: ``design --routes-from``,
  another design's front - a coarser level's): routes are curves in the rest
  body, not lattice paths, so each such layout is solved on this mesh from its
  own contractions and joins the layouts of its count beside the beam's (the
  beam's path is the same with or without them), and its routes join the pool.
  Which layouts the lattice leads the search to moves with the mesh; a good
  layout found on a coarser mesh is a start the search here may not reach.

Every layout finished on the way is kept (``Front.finished``): on the design
mesh several often tie, and :func:`~.converge.converge_front` lets the finer mesh choose.

The finishes of a count's layouts, the extensions and the solves on the finer
mesh are independent of each other: a pool of worker processes
(:class:`~tendon_taichi.tasks.pool.Pool`) shares them with this one, and the
front is the same.

Because a greedy layout of each count is among the seeds, the front is never
worse than greedy consolidation at any count (in effective error).
:func:`~.converge.converge_front` then solves every finished layout of each count on a
finer mesh and keeps the least costly there - the figure reported is that
mesh's, and a layout that reaches the goals only on the design mesh's lattice
(many can, at a few tendons) loses to one that reaches them on both; the same
monotone repair applies to the errors reported.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Callable

import numpy as np

from ..probes import probe
from .consolidation import Candidate, Consolidation, Layout, _Search, positions, route_settings
from .clearance import held_clearance, keeps_as_much
from .exits import exit_route
from .context import Context
from .layouts import SAME_ROUTE, distinct_routes, same_route, sources  # noqa: F401  (their import path before)
from .layouts import best_layouts as _best, layout_key as _key
from .pooled import PAIR_POOL, pooled_candidates  # noqa: F401  (their import path before they moved)
from .pooled import exhaustive_layouts as _exhaustive, kept_layouts as _kept
from .routes import Route, extend_route
from .settings import ConsolidationSettings, FrontSettings

#: the front joins routes whose ends are up to this far apart (x L; consolidation's --join-gap when
#: larger): an extractor often finds only the two ends of a tendon whose middle the sparse
#: idealized pattern left slack, and the search proves every join on the as-built robot anyway
JOIN_GAP = 0.5
#: the as-built soft IK's precision (x L): errors closer than this are equal
PRECISION = 1e-6
#: counts up to this are also searched exhaustively over the pool (:func:`pooled_candidates`)
EXHAUSTIVE = 2
#: a route added to a solved layout starts barely taut, at strain TAUT x eps (the unilateral
#: energy's cubic zone, a tension of EA eps TAUT^2 / 2) at that layout's equilibria: the soft IK
#: starts where the smaller layout ended, and the route's tension still has a gradient there
TAUT = 0.25
#: a route whose tension is at most this fraction of its layout's largest, in every pose, is slack
SLACK = 1e-6
#: the extension tries each route end carried on straight by this much (x L, :func:`_extensions`)
EXTEND = 0.1
#: SLSQP iterations of the one round of route optimization that screens each extension
#: (:func:`_screened`) and each of a count's layouts before the finish (:func:`_finish_best`);
#: only the best screened extension of a layout is finished
EXTEND_SCREEN = 15
#: of a count's layouts up to the first count within the budget, the least costly this many
#: after the screen (:func:`_finish_best`) are finished
FINISH_BEST = 2
#: where no count is within the budget yet, after this many counts in a row that each lower the
#: error by less than consolidation's tolerance below the best of fewer tendons, the counts above
#: are left out: the recommendation there is the fewest tendons within that tolerance of the
#: lowest error, and tendons that buy nothing one after the other rarely start to
STALL = 2


@dataclass(frozen=True)
class PriorLayout:
    """A layout from a prior design for the front to search from: its ``routes`` and the
    contraction ratios ``ratios`` (P, T) to solve them from."""

    routes: list[Route]
    ratios: np.ndarray


@dataclass
class Front:
    """The best layout found per tendon count (``layouts``, finished; counts from 1),
    every layout finished per count (``finished``, which :func:`~.converge.converge_front`
    chooses among), and what the search cost: ``seeds`` layouts it started from, ``pool`` distinct
    routes (``routes``), ``evaluations`` layouts solved in full, ``screened``
    candidates screened, ``route_evaluations`` equilibria of route optimization in
    ``route_s`` seconds, ``time_s`` in all; ``priors`` of the seeds came from
    a prior design (:class:`PriorLayout`); ``refit``: the counts whose routes the
    finer mesh optimized again (:func:`~.converge.converge_front`); ``slack``: each
    time a layout's slack routes were left out and the rest replaced the front's
    layout of their count (``count`` before, ``kept`` after, ``error`` as built);
    ``left``: the counts the beam searched above the front's last (one above the
    first within the budget, or the last of ``STALL`` that bought too little),
    left out unfinished; ``on_finished``,
    while :func:`search_front` runs, is called with each distinct layout as it
    joins ``finished``."""

    layouts: dict[int, Layout] = field(default_factory=dict)
    finished: dict[int, list[Layout]] = field(default_factory=dict)
    seeds: int = 0
    pool: int = 0
    routes: list[Route] = field(default_factory=list)
    evaluations: int = 0
    screened: int = 0
    route_evaluations: int = 0
    route_s: float = 0.0
    time_s: float = 0.0
    priors: int = 0
    refit: list[int] = field(default_factory=list)
    slack: list[dict] = field(default_factory=list)
    left: list[int] = field(default_factory=list)
    on_finished: Callable[[Layout], None] | None = field(default=None, repr=False, compare=False)

    def offer(self, layouts: list[Layout], size: float) -> None:
        """Keep ``layouts`` among the finished of their counts, each distinct one once."""
        for lay in layouts:
            held = self.finished.setdefault(lay.count, [])
            if _key(lay, size) not in {_key(h, size) for h in held}:
                held.append(lay)
                if self.on_finished is not None:
                    self.on_finished(lay)

    def as_json(self) -> dict:
        return {"counts": sorted(self.layouts), "seeds": self.seeds, "priors": self.priors, "pool": self.pool,
                "evaluations": self.evaluations, "screened": self.screened,
                "route_evaluations": self.route_evaluations, "route_s": self.route_s, "time_s": self.time_s,
                "refit": list(self.refit), "slack": list(self.slack), "left": list(self.left)}


def search_front(context: Context, consolidations: list[Consolidation], options: ConsolidationSettings,
                 front_settings: FrontSettings = FrontSettings(), priors: list[PriorLayout] | None = None,
                 on_finished: Callable[[Layout], None] | None = None) -> Front:
    """The front (module docstring) on the as-built robot of ``context`` from the
    extractors' ``consolidations`` and the ``priors`` (layouts from a prior design):
    per count 1 .. the most any seed has (at most ``front_settings.max_tendons``), the
    best layout found, finished, the beam ``front_settings.beam`` wide. With
    consolidation off (``options.enabled`` false), the seeds as they are, no search.
    The context's workers, a pool of worker processes, share the independent solves
    and route optimizations (the same front as without them); ``on_finished`` is
    called with each layout as it is finished (``Front.on_finished``: ``design``
    starts solving it on the finer mesh, :class:`~.converge.FineSolves`)."""
    t0 = time.perf_counter()
    say = context.say
    beam, max_tendons = front_settings.beam, front_settings.max_tendons
    wide = replace(options, gap=max(options.gap, JOIN_GAP))
    search = _Search(context, wide, route_settings(context.problem, options), "front")
    search.out = tally = Consolidation(consolidations[0].layout, 0, 0.0)
    size = context.problem.size
    by_count: dict[int, list[Layout]] = {}
    for c in consolidations:
        for lay in c.front.values():
            if lay.count:  # the bare body is no design
                by_count.setdefault(lay.count, []).append(lay)
    prior = _solved_priors(search, priors or [], max_tendons)
    pool = distinct_routes([r for c in consolidations for r in c.layout.routes]
                           + [r for c in consolidations for lay in c.front.values() for r in lay.routes]
                           + [r for lay in prior for r in lay.routes], size)
    pooled = _pooled(search, consolidations, size)
    if pooled is not None:
        by_count.setdefault(pooled.count, []).append(pooled)
    front = Front(seeds=sum(len(v) for v in by_count.values()) + len(prior), pool=len(pool), routes=pool,
                  priors=len(prior), on_finished=on_finished)
    if not options.enabled:
        for lay in prior:
            by_count.setdefault(lay.count, []).append(lay)
    if not by_count or not options.enabled:  # nothing to search, or the fitted routes as they are
        front.layouts = {k: _best(v, 1, size)[0] for k, v in sorted(by_count.items())
                         if max_tendons is None or k <= max_tendons}
        front.time_s, front.on_finished = time.perf_counter() - t0, None
        return front
    top = max(by_count)
    say(f"front: beam search from {top} tendon(s), {front.seeds} seed layouts"
        + (f" ({len(prior)} from a prior design)" if prior else "") + f", {len(pool)} distinct routes")
    exhaustive: dict[int, list[Layout]] = {}
    for k in range(top, 0, -1):
        by_count[k] = _best(by_count.get(k, []), beam, size)
        near = by_count.get(k + 1) or by_count[k]  # the layout the screen linearizes at: its first
        if k <= EXHAUSTIVE and near:
            exhaustive[k] = _kept(_exhaustive(search, pool, k, near[0]), beam, size)
        if k == 1:
            break
        for lay in by_count[k]:
            reduced = [replace(r, source=sources(r.routes)) for _, r in search.ranked(search.reductions(lay), lay)]
            by_count.setdefault(k - 1, []).extend(reduced[:beam])
    for k, found in [*exhaustive.items(), *((lay.count, [lay]) for lay in prior)]:  # beside the beam's
        kept = {_key(lay, size) for lay in by_count.get(k, [])}
        by_count[k] = by_count.get(k, []) + [lay for lay in found if _key(lay, size) not in kept]
    counts = [k for k in sorted(by_count) if by_count[k] and (max_tendons is None or k <= max_tendons)]
    horizon = None  # the most tendons the front finishes (the count above the first within the budget)
    stalled = 0  # counts in a row that bought less than the tolerance
    for k in counts:
        if horizon is not None and k > horizon:
            front.left = [j for j in counts if j > horizon]
            say(f"front: {_counts(front.left)} left out ({_why_left(front, options, stalled)})")
            break
        # up to the first count within the budget, every layout the beam kept (and the exhaustive
        # search found) is screened and the best finished - route optimization can reorder them:
        # a join often gains most; the count above it, its best, one round
        members = by_count[k] if horizon is None else _best(by_count[k], 1, size)
        say(f"front: optimizing the routes of the {'best' if len(members) == 1 else len(members)} "
            f"{k}-tendon layout{'s' if len(members) > 1 else ''}")
        done = _finish_best(search, members, options.refine if horizon is None else 1)
        lay = min(done, key=lambda m: m.cost)
        if k > 1 and k - 1 in front.layouts and lay.error > front.layouts[k - 1].error + PRECISION:
            lay = _one_more(search, front.layouts[k - 1], pool, lay, size)
        front.layouts[k] = lay
        front.offer([lay] + done, size)
        for smaller in _without_slack(search, lay):  # the same robot with fewer tendons
            front.offer([smaller], size)
            held = front.layouts.get(smaller.count)
            if held is None or smaller.error < held.error - PRECISION:
                say(f"front: {lay.count - smaller.count} of the {lay.count} routes are slack; the rest make a "
                    f"{smaller.count}-tendon layout of {100 * smaller.error:.2f}% of L")
                front.layouts[smaller.count] = smaller
                front.slack.append({"count": lay.count, "kept": smaller.count, "error": smaller.error})
        if horizon is None and any(m.error <= options.budget for m in front.layouts.values()):
            horizon = k + 1
        elif horizon is None:
            fewer = [m.error for j, m in front.layouts.items() if j < k]
            stalled = stalled + 1 if fewer and front.layouts[k].error > min(fewer) - options.tolerance else 0
            if stalled >= STALL:
                horizon = k
    _extend(search, front, pool, size, options)
    _descend(search, front, pool, size, say)
    front.evaluations, front.screened = tally.evaluations, tally.screened
    front.route_evaluations, front.route_s = tally.route_evaluations, tally.route_s
    front.time_s, front.on_finished = time.perf_counter() - t0, None
    return front


def _why_left(front: Front, options: ConsolidationSettings, stalled: int) -> str:
    """Why the front left its higher counts out, for the progress."""
    within = [j for j, m in front.layouts.items() if m.error <= options.budget]
    if within:
        return f"a {min(within)}-tendon layout is within the budget"
    return (f"none is within the budget, and the last {stalled} counts each lowered the error by less than "
            f"{100 * options.tolerance:g}% of L")


def _counts(counts: list[int]) -> str:
    """``counts`` (ascending, consecutive) in words: "the 4-tendon layouts", "the 4- to 6-tendon layouts"."""
    return f"the {counts[0]}-{f' to {counts[-1]}-' if counts[1:] else ''}tendon layouts"


def slack_routes(layout: Layout) -> list[int]:
    """The indices of a solved layout's routes that are slack - their tension in
    every pose at most ``SLACK`` x the largest of the layout's: they do no work,
    and the robot without them is the same."""
    tau = np.asarray(layout.realizable.tau, dtype=float).reshape(-1, layout.count)  # (P, T) N at the pull ends
    top = float(tau.max(initial=0.0))
    return [i for i in range(layout.count) if top > 0.0 and tau[:, i].max() <= SLACK * top]


def _without_slack(search: _Search, layout: Layout) -> list[Layout]:
    """For d = 1 .. the number of its slack routes (:func:`slack_routes`), the
    solved ``layout`` without the first d of them, solved again from its
    contractions and equilibria (the same robot, d tendons fewer; counted as
    finished: route optimization moved the routes left with the slack ones in
    place, doing nothing); empty when none is slack."""
    slack = slack_routes(layout)
    start = np.atleast_2d(layout.realizable.ratios).reshape(search.problem.n_poses, -1)
    out = []
    for d in range(1, min(len(slack), layout.count - 1) + 1):
        keep = [i for i in range(layout.count) if i not in slack[:d]]
        routes = [layout.routes[i] for i in keep]
        lay = search.solve(routes, start[:, keep], layout)
        if lay is not None:
            out.append(replace(lay, source=sources(routes), optimized=True))
    return out


def _finished(search: _Search, layout: Layout, rounds: int) -> Layout:
    """The layout oriented and its routes optimized (at most ``rounds`` rounds),
    unless it already was."""
    if layout.optimized:
        return layout
    return replace(search.finish(layout, rounds)[0], source=sources(layout.routes))


def _finish_task(spec: tuple, job: tuple[Layout, int]) -> tuple[Layout, dict]:
    """:func:`_finished` (``job``: the layout and the rounds) as a worker process runs it."""
    search = _Search.again(spec, job[0])
    return _finished(search, *job), search.tally()


def _finish_all(search: _Search, layouts: list[Layout], rounds: int) -> list[Layout]:
    """Each of ``layouts`` finished (:func:`_finished`), on the search's workers too."""
    return search.each(partial(_finished, search), _finish_task, [(m, rounds) for m in layouts])


def _finish_best(search: _Search, layouts: list[Layout], rounds: int) -> list[Layout]:
    """The ``FINISH_BEST`` least costly of ``layouts`` after a screen, finished: each
    oriented and its routes optimized one round of at most ``EXTEND_SCREEN`` SLSQP
    iterations (:func:`_screened_layout`), the least costly then ``rounds`` rounds
    more (:func:`_continued`); with at most ``FINISH_BEST`` layouts, each finished
    (:func:`_finished`), and with ``rounds`` 0 (no route optimization: nothing to
    screen by), each oriented. Route optimization reorders a count's layouts - a join
    often gains most -, but after a short round mostly as it will after the finish (so
    it does for the extensions, ``benchmarks/extension_screen.py``); on the search's
    workers too."""
    if len(layouts) <= FINISH_BEST or not rounds:
        return _finish_all(search, layouts, rounds)
    screened = search.each(partial(_screened_layout, search), _screen_layout_task, [(m,) for m in layouts])
    best = sorted(screened, key=lambda lay: lay.cost)[:FINISH_BEST]
    todo = [(lay, rounds) for lay in best if not lay.optimized]
    done = iter(search.each(partial(_continued, search), _continue_task, todo))
    return [lay if lay.optimized else next(done) for lay in best]


def _screened_layout(search: _Search, layout: Layout) -> Layout:
    """A solved ``layout`` oriented and its routes optimized one round of at most
    ``EXTEND_SCREEN`` SLSQP iterations (not yet finished); one already finished as it is."""
    if layout.optimized:
        return layout
    done = search.finish(layout, rounds=1, iterations=EXTEND_SCREEN)[0]
    return replace(done, source=sources(layout.routes), optimized=False)


def _screen_layout_task(spec: tuple, job: tuple[Layout]) -> tuple[Layout, dict]:
    """:func:`_screened_layout` as a worker runs it."""
    search = _Search.again(spec, job[0])
    return _screened_layout(search, *job), search.tally()


def _pooled(search: _Search, consolidations: list[Consolidation], size: float) -> Layout | None:
    """The union of every extractor's consolidated routes (near duplicates once),
    solved from each route's contractions in its own layout; None when it adds
    nothing to the seeds (one extractor, or all found the same routes)."""
    routes, starts = [], []
    for c in consolidations:
        ratios = np.atleast_2d(c.layout.realizable.ratios).reshape(search.problem.n_poses, -1)
        for i, r in enumerate(c.layout.routes):
            if not any(same_route(r, q, size) for q in routes):
                routes.append(r)
                starts.append(ratios[:, i])
    if len(routes) <= max(c.layout.count for c in consolidations):
        return None
    lay = search.solve(routes, np.array(starts).T)
    return None if lay is None else replace(lay, source=sources(routes))


def _solved_priors(search: _Search, priors: list[PriorLayout], max_tendons: int | None) -> list[Layout]:
    """The ``priors`` of at most ``max_tendons`` routes solved on the search's mesh from
    their own contractions; those that cannot be solved are left out."""
    out = []
    for prior in priors:
        if max_tendons is None or len(prior.routes) <= max_tendons:
            lay = search.solve(prior.routes, np.atleast_2d(prior.ratios).reshape(search.problem.n_poses, -1))
            if lay is not None:
                out.append(replace(lay, source=sources(prior.routes)))
    return out


def _taut_ratios(search: _Search, route: Route, below: Layout) -> np.ndarray:
    """Contractions (P, 1) that leave ``route`` barely taut in each pose of the
    solved layout ``below`` (strain ``TAUT`` x eps at its equilibria)."""
    fs = search.problem.scene.fibers
    tension = 0.5 * fs.stiffness * fs.eps * TAUT ** 2  # the cubic zone's tension at strain TAUT x eps
    return search.start_ratios([route], np.full((search.problem.n_poses, 1), tension), positions(below.realizable))


def _with_one_more(search: _Search, below: Layout, pool: list[Route], size: float) -> list[Layout]:
    """The layout ``below`` with one more pooled route it lacks, solved from
    ``below``'s contractions and equilibria: the least costly (screened by one
    Gauss-Newton step, then solved in full) with the new route starting barely
    taut (:func:`_taut_ratios`: the soft IK starts where ``below`` ended), and the
    least costly with it starting at its strand's tension (it does its share of
    the work from the start, and can reach an optimum far from ``below``'s)."""
    P = search.problem.n_poses
    start = np.atleast_2d(below.realizable.ratios).reshape(P, -1)
    lacking = [r for r in pool if not any(same_route(r, q, size) for q in below.routes)]

    def added(r: Route, taut: bool) -> np.ndarray:
        return _taut_ratios(search, r, below) if taut else search.start_ratios([r], np.full((P, 1), r.tension))

    out = []
    for taut in (True, False):
        cands = [Candidate("add", (), below.routes + [r], np.concatenate([start, added(r, taut)], axis=1))
                 for r in lacking]
        out += [replace(lay, source=sources(lay.routes)) for _, lay in search.ranked(cands, below)[:1]]
    return out


def _one_more(search: _Search, below: Layout, pool: list[Route], now: Layout, size: float) -> Layout:
    """The best (as built) of ``now`` and the layout ``below`` (one tendon fewer)
    with one more pooled route (:func:`_with_one_more`)."""
    return min([now] + _with_one_more(search, below, pool, size), key=lambda lay: lay.error)


def _descend(search: _Search, front: Front, pool: list[Route], size: float,
             say: Callable[[str], None]) -> None:
    """The front's descent (module docstring), in place: for k from the most
    tendons down to 2, the least costly drop or join of ``front.layouts[k]``
    (:meth:`~.consolidation._Search.ranked`) is finished (one round) where it
    costs less than the (k - 1)-tendon layout held, and replaces that layout
    when it still does; then, above each count it replaced, the monotone repair
    (:func:`_one_more`) where that count's error exceeds the new one's."""
    changed = set()
    for k in sorted(front.layouts, reverse=True):
        held = front.layouts.get(k - 1)
        if held is None:
            continue
        above = front.layouts[k]
        ranked = search.ranked(search.reductions(above), above)
        if not ranked or ranked[0][1].cost >= held.cost:
            continue
        lay = _finished(search, replace(ranked[0][1], source=sources(ranked[0][1].routes)), 1)
        front.offer([lay], size)
        if lay.cost < held.cost:
            say(f"front: a {k - 1}-tendon layout from the {k}-tendon one, {100 * lay.error:.2f}% of L "
                f"(was {100 * held.error:.2f}%)")
            front.layouts[k - 1] = lay
            changed.add(k - 1)
    _repair(search, front, pool, size, changed)


def _repair(search: _Search, front: Front, pool: list[Route], size: float, changed: set[int]) -> None:
    """The monotone repair above each count in ``changed`` (whose layout was
    replaced), in place: where the count above has a larger error, the best of it
    and the new layout with one more pooled route (:func:`_one_more`)."""
    for k in sorted(changed):
        above = front.layouts.get(k + 1)
        if above is not None and above.error > front.layouts[k].error + PRECISION:
            front.layouts[k + 1] = _one_more(search, front.layouts[k], pool, above, size)
            front.offer([front.layouts[k + 1]], size)


def _extension_jobs(search: _Search, layout: Layout, size: float) -> list[tuple]:
    """The jobs of :func:`_screened` for the solved ``layout``: its routes with one
    route end carried on straight by ``EXTEND`` x L (:func:`~.routes.extend_route`;
    each end of each route - the anchor of one that leaves the body, whose core is
    carried on and out again -, kept clear of the walls as the route was; an end the
    walls cut back to less than half that is left out)."""
    jobs = []
    c = search.rs.clearance
    for i, route in enumerate(layout.routes):
        for end in ((0,) if route.exits else (0, 1)):  # a route that leaves the body, at its anchor
            longer = exit_route(extend_route(route.inner(), end, EXTEND * size, size), search.problem, c)
            if (not keeps_as_much(longer, held_clearance(route, c), c)
                    or longer.length < route.length + 0.5 * EXTEND * size):
                continue
            jobs.append((layout, layout.routes[:i] + [longer] + layout.routes[i + 1:]))
    return jobs


def _extensions(search: _Search, layouts: list[Layout], size: float, rounds: int) -> list[Layout | None]:
    """Per layout of ``layouts``, the best of its extensions (:func:`_extension_jobs`):
    each solved and screened (:func:`_screened`), the least costly screened one
    finished (:func:`_continued`, ``rounds``); None where none can be solved. The
    screens run in one batch, then the finishes in another, on the search's workers
    too."""
    jobs = [_extension_jobs(search, lay, size) for lay in layouts]
    found = iter(search.each(partial(_screened, search), _screen_task, [job for js in jobs for job in js]))
    best = [min([lay for lay in [next(found) for _ in js] if lay is not None], key=lambda lay: lay.cost, default=None)
            for js in jobs]
    todo = [(lay, rounds) for lay in best if lay is not None]
    done = iter(search.each(partial(_continued, search), _continue_task, todo))
    return [None if lay is None else next(done) for lay in best]


@probe("screened")
def _screened(search: _Search, layout: Layout, routes: list[Route]) -> Layout | None:
    """``routes`` (``layout``'s with one extended) solved from ``layout``'s
    contractions and equilibria, oriented, and their routes optimized one round of at
    most ``EXTEND_SCREEN`` SLSQP iterations; None when they cannot be solved."""
    start = np.atleast_2d(layout.realizable.ratios).reshape(search.problem.n_poses, -1)
    lay = search.solve(routes, start, layout)
    return None if lay is None else _screened_layout(search, lay)


def _screen_task(spec: tuple, job: tuple[Layout, list[Route]]) -> tuple[Layout | None, dict]:
    """:func:`_screened` as a worker runs it."""
    search = _Search.again(spec, job[0])
    return _screened(search, *job), search.tally()


@probe("continued")
def _continued(search: _Search, layout: Layout, rounds: int) -> Layout:
    """A screened ``layout`` (:func:`_screened`) finished: its routes optimized on,
    at most ``rounds`` rounds."""
    return replace(search.optimize(layout, rounds), source=layout.source, optimized=True)


def _continue_task(spec: tuple, job: tuple[Layout, int]) -> tuple[Layout, dict]:
    """:func:`_continued` as a worker runs it."""
    search = _Search.again(spec, job[0])
    return _continued(search, *job), search.tally()


def _extend(search: _Search, front: Front, pool: list[Route], size: float, options: ConsolidationSettings) -> None:
    """The front's extension (module docstring), in place: up to one count above the
    first within the budget (where none is, the most tendons only), the better of
    each count's layout and its best extension (:func:`_extensions`, offered to
    the finer mesh); then the monotone repair (:func:`_repair`) above each count
    whose layout an extension replaced."""
    say = search.log
    within = [k for k, lay in front.layouts.items() if lay.error <= options.budget]
    counts = [k for k in sorted(front.layouts) if k <= min(within) + 1] if within else sorted(front.layouts)[-1:]
    changed = set()
    for k in counts:
        say(f"front: the {k}-tendon layout with each route end carried on by {EXTEND:g} L")
    extended = _extensions(search, [front.layouts[k] for k in counts], size, options.refine)
    for k, best in zip(counts, extended):
        held = front.layouts[k]
        if best is None:
            continue
        front.offer([best], size)
        if best.cost < held.cost:
            say(f"front: a longer route makes the {k}-tendon layout {100 * best.error:.2f}% of L "
                f"(was {100 * held.error:.2f}%)")
            front.layouts[k] = best
            changed.add(k)
    _repair(search, front, pool, size, changed)
