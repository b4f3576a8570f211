"""The count/error front on goals made by two straight planted tendons (frictionless,
see test_consolidation): one tendon is not enough and two are, so the front
drops at k = 2 and the recommendation is 2; it is monotone, never worse than
greedy consolidation at any count, pools the extractors' routes, and its
layouts re-solved on a finer mesh stay close."""

import numpy as np
import pytest
from test_consolidation import _state, _tendons, straight  # noqa: F401  (the fixture)

from tendon_taichi.apps.design import front_rows, recommend
from tendon_taichi.extract.consolidation import consolidate
from tendon_taichi.extract.context import Context
from tendon_taichi.extract.converge import converge_front, converged_error, pose_only_state
from tendon_taichi.extract.front import distinct_routes, same_route, search_front
from tendon_taichi.extract.settings import ConsolidationSettings

OPTIONS = ConsolidationSettings(tolerance=1e-3, gap=0.1, budget=0.005, refine=0)


@pytest.fixture(scope="module")
def searched(straight):  # noqa: F811
    """Two 'extractors': one found both planted tendons and a useless third, the
    other the stem tendon and the arm tendon in two pieces; each consolidated
    greedily, then the front searched from both."""
    p, paths, eq = straight
    st = _state(p, eq, paths)
    mid = p.fibers.nodes[p.fibers.edges].mean(axis=1)
    extra = [int(np.argmin(np.linalg.norm(mid - q, axis=1))) for q in ([0.004, 0.03], [0.004, 0.035])]
    arm = list(paths[0])
    found = {"a": _tendons(p, [paths[0], paths[1], extra], st),
             "b": _tendons(p, [paths[1], arm[:3], arm[5:]], st)}
    greedy = [consolidate(Context(p, st, p.scene.optimize, "direct"), t, OPTIONS, source=name)
              for name, t in found.items()]
    front = search_front(Context(p, st, p.scene.optimize, "direct"), greedy, OPTIONS)
    return p, st, greedy, front


def test_one_tendon_is_not_enough_and_two_are(searched):
    p, _, _, front = searched
    assert sorted(front.layouts) == [1, 2, 3]
    assert front.layouts[1].error > 0.005  # neither planted tendon alone makes the pose
    assert front.layouts[2].error < 1e-3  # both do
    rows = front_rows(front, None, 0.0, 30.0)
    assert recommend(rows, 0.005)["count"] == 2
    assert recommend(rows, 1.01 * front.layouts[1].error)["count"] == 1  # a looser budget buys one


def test_the_front_is_monotone(searched):
    _, _, _, front = searched
    errors = [front.layouts[k].error for k in sorted(front.layouts)]
    assert all(b <= a + 1e-6 for a, b in zip(errors, errors[1:])), errors  # the soft IK's precision, x L


def test_never_worse_than_greedy_at_any_count(searched):
    _, _, greedy, front = searched
    for c in greedy:
        for k, lay in c.front.items():
            if k in front.layouts:
                assert front.layouts[k].cost <= lay.cost * (1 + 1e-9), (k, c.layout.source)


def test_the_pool_holds_each_route_once(searched):
    p, _, greedy, front = searched
    routes = [r for c in greedy for lay in c.front.values() for r in lay.routes]
    pool = distinct_routes(routes, p.size)
    assert front.pool == len(pool) < len(routes)
    assert all(not same_route(a, b, p.size) for i, a in enumerate(pool) for b in pool[i + 1:])
    assert same_route(pool[0], pool[0].reversed(), p.size)  # the same curve either way round
    assert front.evaluations > 0


def test_on_a_finer_mesh_two_still_make_the_pose_and_the_front_stays_monotone(searched):
    """Each front layout's routes re-solved on the level-2 mesh: two tendons still
    make the pose, one still does not, and the errors there do not rise with k."""
    from dataclasses import replace

    from tendon_taichi import build_problem

    p, st, _, front = searched
    fine = replace(build_problem(p.scene, 2), target_goal=p.target_goal)  # the planted goals, as on level 1
    assert fine.mesh.n_nodes > 1.5 * p.mesh.n_nodes
    res = converge_front(front, Context(p, st, p.scene.optimize, "direct"), fine, OPTIONS)
    assert sorted(res) == sorted(front.layouts) and all(r is not None for r in res.values())
    assert res[2].pose_error_rel < 0.005 < res[1].pose_error_rel
    errors = [res[k].pose_error_rel for k in sorted(res)]
    assert all(b <= a + 1e-6 for a, b in zip(errors, errors[1:])), errors
    alone = converged_error(Context(fine, pose_only_state(fine), p.scene.optimize, "direct"), front.layouts[2])
    assert alone.pose_error_rel == pytest.approx(res[2].pose_error_rel, rel=1e-9)  # the same solve


def test_one_tendon_is_searched_over_every_pooled_route_and_join(searched):
    """Counts 1 and 2 are searched over the whole pool: k = 1 over each pooled route
    alone and each join of two, k = 2 over each pair; no pooled route alone, solved
    in full, does better than the front's one-tendon layout."""
    from dataclasses import replace

    from tendon_taichi.extract.consolidation import _Search, route_settings
    from tendon_taichi.extract.front import JOIN_GAP, pooled_candidates

    p, st, _, front = searched
    wide = replace(OPTIONS, gap=max(OPTIONS.gap, JOIN_GAP))
    search = _Search(Context(p, st, p.scene.optimize, "direct"), wide, route_settings(p, OPTIONS), "test")
    n = len(front.routes)
    ones = pooled_candidates(search, front.routes, 1)
    assert [c.action for c in ones[:n]] == ["route"] * n and [c.ids for c in ones[:n]] == [(i,) for i in range(n)]
    assert len(ones) > n and all(c.action == "join" and len(c.routes) == 1 for c in ones[n:])
    pairs = pooled_candidates(search, front.routes, 2)
    assert sorted(c.ids for c in pairs) == [(i, j) for i in range(n) for j in range(i + 1, n)]
    alone = [search.solve(c.routes, c.start) for c in ones[:n]]
    assert front.layouts[1].cost <= min(lay.cost for lay in alone if lay is not None) * (1 + 1e-9)


def test_the_exhaustive_search_adds_to_the_beam_and_takes_nothing_from_it(searched, monkeypatch):
    """The pooled one-tendon layouts are finished beside the beam's, never in their
    place: the one-tendon layout is at most as costly as the beam alone finds."""
    import tendon_taichi.extract.front as front_module

    p, st, greedy, front = searched
    monkeypatch.setattr(front_module, "EXHAUSTIVE", 0)
    beam_only = search_front(Context(p, st, p.scene.optimize, "direct"), greedy, OPTIONS)
    assert front.layouts[1].cost <= beam_only.layouts[1].cost * (1 + 1e-9)
    assert front.screened > beam_only.screened


def test_a_route_added_to_a_layout_starts_barely_taut(searched):
    """The monotone repair's start: at the smaller layout's equilibrium, the added
    route's contraction gives it the cubic zone's tension at strain eps / 4,
    EA eps / 32 (the model's own tension, not the inverse formula)."""
    from tendon_taichi import Model
    from tendon_taichi.extract.consolidation import _Search, route_settings
    from tendon_taichi.extract.front import _taut_ratios
    from tendon_taichi.extract.realizable import tendon_cables

    p, st, _, front = searched
    below = front.layouts[1]
    route = next(r for r in front.routes if not any(same_route(r, q, p.size) for q in below.routes))
    search = _Search(Context(p, st, p.scene.optimize, "direct"), OPTIONS, route_settings(p, OPTIONS), "test")
    ratio = _taut_ratios(search, route, below)
    assert ratio.shape == (1, 1)
    cables = tendon_cables(p, [route.tendon()])
    tau = Model.from_problem(p, cables=cables).tensions_at(ratio[0] * cables.a0, below.realizable.x)
    fs = p.scene.fibers
    assert tau[0] == pytest.approx(fs.stiffness * fs.eps / 32, rel=1e-6)


def _with_a_slack_route(p, st, search, routes):
    """``routes`` and a route across the T's arm that no contraction has pulled
    taut (its contraction 0, its tension 0: a soft IK that starts it slack leaves
    it there, its gradient is 0), solved from the routes' strand tensions."""
    from tendon_taichi.extract.routes import fit_route

    slack = fit_route(np.array([[-0.01, 0.07], [0.01, 0.07]]), p.size, 0.0, 0.0, "slack")
    tensions = np.array([[r.tension for r in routes]])
    start = np.concatenate([search.start_ratios(routes, tensions), [[0.0]]], axis=1)
    return search.solve(routes + [slack], start)


def test_a_slack_route_is_found_and_the_robot_without_it_is_the_same(searched):
    from tendon_taichi.extract.consolidation import _Search, extracted_routes, route_settings
    from tendon_taichi.extract.front import PRECISION, _without_slack, slack_routes

    p, st, _, _ = searched
    search = _Search(Context(p, st, p.scene.optimize, "direct"), OPTIONS, route_settings(p, OPTIONS), "test")
    planted, _ = extracted_routes(p, _planted_tendons(p, st), st, search.rs.clearance)
    three = _with_a_slack_route(p, st, search, planted)
    assert three.count == 3 and slack_routes(three) == [2]
    assert np.all(np.asarray(three.realizable.tau)[:2] > 0.1)  # the planted routes do the work
    (two,) = _without_slack(search, three)
    assert two.count == 2 and two.optimized and [r.source for r in two.routes] == [r.source for r in planted]
    assert abs(two.error - three.error) < PRECISION
    # the same contractions, to the soft IK's stopping rule (its steps from the same point stop anew)
    np.testing.assert_allclose(two.realizable.ratios, np.asarray(three.realizable.ratios)[:2], rtol=1e-4)
    assert slack_routes(two) == [] and _without_slack(search, two) == []


def test_a_layout_with_a_slack_route_is_offered_at_its_working_count(searched, monkeypatch):
    """When route optimization leaves a route slack, the robot without it competes
    at the count below: here the two-tendon layouts finish as one planted route
    and a slack one (the pose is out of reach), the three-tendon ones as both
    planted routes and a slack one; the front's two-tendon entry is then both
    planted routes, the recommendation 2, not 3, and the front's JSON says so."""
    from dataclasses import replace

    import tendon_taichi.extract.front as front_module
    from tendon_taichi.extract.consolidation import extracted_routes

    p, st, greedy, _ = searched
    real = front_module._finished

    def finished(search, layout, rounds):
        planted, _ = extracted_routes(p, _planted_tendons(p, st), st, search.rs.clearance)
        if layout.count in (2, 3):
            lay = _with_a_slack_route(p, st, search, planted[:layout.count - 1])
            return replace(lay, optimized=True, source="test")
        return real(search, layout, rounds)

    monkeypatch.setattr(front_module, "_finished", finished)
    front = search_front(Context(p, st, p.scene.optimize, "direct"), greedy, OPTIONS)
    assert front.layouts[3].count == 3 and front_module.slack_routes(front.layouts[3]) == [2]
    assert front.layouts[2].error < 1e-3 and front_module.slack_routes(front.layouts[2]) == []
    assert recommend(front_rows(front, None, 0.0, 30.0), 0.005)["count"] == 2
    # the routes left out are said: the three-tendon layout's slack one made the two-tendon entry
    assert {"count": 3, "kept": 2, "error": front.layouts[2].error} in front.as_json()["slack"]


def _planted_tendons(p, st):
    """The two planted lines as tendons (the fixture's strands, in its order)."""
    from test_consolidation import LINES, _tendons

    from conftest import lattice_path

    return _tendons(p, [lattice_path(p, [np.array(q) for q in line]) for line in LINES], st)


@pytest.mark.parametrize("stall", [1, 2])
def test_where_none_is_within_the_budget_counts_that_buy_nothing_end_the_front(searched, monkeypatch, stall):
    """No count within the budget, and each count above one lowers the error by
    less than the tolerance (here half of L): after STALL such counts in a row the
    counts above are left out, and the front's JSON says which."""
    from dataclasses import replace

    import tendon_taichi.extract.front as front_module

    p, st, greedy, _ = searched
    monkeypatch.setattr(front_module, "STALL", stall)
    options = replace(OPTIONS, budget=1e-9, tolerance=0.5)
    front = search_front(Context(p, st, p.scene.optimize, "direct"), greedy, options)
    # counts 2 and 3 each buy less than the tolerance: one such count ends the front, or two in a row
    kept, left = ([1, 2], [3]) if stall == 1 else ([1, 2, 3], [])
    assert sorted(front.layouts) == kept and front.left == left
    assert front.as_json()["left"] == front.left


def test_the_descent_reduces_finished_layouts(searched, monkeypatch):
    """Where finishing the two-tendon layouts left a poor one (here: the
    one-tendon layout and a slack route - no better than one tendon), the
    descent from the finished three-tendon layout finds both planted routes by
    a drop or a join; without the descent the poor layout stays (the extension
    off in both: its screen would find them too)."""
    from dataclasses import replace

    import tendon_taichi.extract.front as front_module

    p, st, greedy, searched_front = searched
    real = front_module._finished
    one = searched_front.layouts[1].routes

    def finished(search, layout, rounds):
        if layout.count == 2 and rounds == OPTIONS.refine:  # the bottom-up pass, not the descent
            return replace(_with_a_slack_route(p, st, search, one), optimized=True, source="test")
        return real(search, layout, rounds)

    monkeypatch.setattr(front_module, "_finished", finished)
    monkeypatch.setattr(front_module, "_extend", lambda *args: None)
    front = search_front(Context(p, st, p.scene.optimize, "direct"), greedy, OPTIONS)
    assert front.layouts[2].error < 1e-3 and front.layouts[2].source != "test"
    assert recommend(front_rows(front, None, 0.0, 30.0), 0.005)["count"] == 2
    monkeypatch.setattr(front_module, "_descend", lambda *args: None)
    poor = search_front(Context(p, st, p.scene.optimize, "direct"), greedy, OPTIONS)
    assert poor.layouts[2].source == "test" and poor.layouts[2].error > 0.005


def test_the_finer_mesh_chooses_among_each_counts_finished_layouts(searched):
    """Where the two-tendon layout held is a poor one (the one-tendon layout and a
    slack route) and both planted routes were finished too, the finer mesh
    chooses them; at every count the layout kept costs no more there than any
    other finished one, each solved there alone. Without the others to choose
    from, the poor layout stays."""
    from dataclasses import replace

    from tendon_taichi import build_problem
    from tendon_taichi.extract.consolidation import _Search, route_settings

    p, st, _, searched_front = searched
    search = _Search(Context(p, st, p.scene.optimize, "direct"), OPTIONS, route_settings(p, OPTIONS), "test")
    poor = replace(_with_a_slack_route(p, st, search, searched_front.layouts[1].routes), optimized=True, source="test")
    good = searched_front.layouts[2]
    fine = replace(build_problem(p.scene, 2), target_goal=p.target_goal)

    def front_with(finished_two):
        front = replace(searched_front, layouts={**searched_front.layouts, 2: poor},
                        finished={k: list(v) for k, v in searched_front.finished.items()})
        front.finished[2] = finished_two
        return front

    front = front_with([poor, good])
    res = converge_front(front, Context(p, st, p.scene.optimize, "direct"), fine, OPTIONS)
    assert front.layouts[2] is good and res[2].pose_error_rel < 1e-3
    fine_state = pose_only_state(fine)
    for k, members in front.finished.items():
        kept = search.cost(front.layouts[k].routes, res[k].pose_error_rel)
        for lay in members:
            alone = converged_error(Context(fine, fine_state, p.scene.optimize, "direct"), lay)
            assert kept <= search.cost(lay.routes, alone.pose_error_rel) * (1 + 1e-6) + 1e-12, (k, lay.source)
    stuck = front_with([poor])
    res = converge_front(stuck, Context(p, st, p.scene.optimize, "direct"), fine, OPTIONS)
    assert stuck.layouts[2] is poor and res[2].pose_error_rel > 0.005


def test_the_finer_mesh_optimizes_each_counts_routes_again(searched):
    """With route optimization on (one round), each count's routes are optimized
    again on the finer mesh: the routes held then cost no more there than any
    layout finished for the count as it was; the error reported is the new
    routes' there (the same as solving them there alone from those
    contractions); the layout held is their robot on the design mesh. The
    one-tendon layout (its routes never optimized: refine 0 in the search)
    gains. With route optimization off, nothing is optimized again."""
    import copy
    from dataclasses import replace

    from tendon_taichi import build_problem
    from tendon_taichi.extract.consolidation import _Search, route_settings

    p, st, _, searched_front = searched
    fine = replace(build_problem(p.scene, 2), target_goal=p.target_goal)
    fine_state = pose_only_state(fine)
    options = replace(OPTIONS, refine=1)
    search = _Search(Context(p, st, p.scene.optimize, "direct"), options, route_settings(p, options), "test")
    there = Context(fine, fine_state, p.scene.optimize, "direct")
    before = {k: min(search.cost(lay.routes, converged_error(there, lay).pose_error_rel)
                     for lay in [searched_front.layouts[k]] + searched_front.finished.get(k, []))
              for k in searched_front.layouts}
    front = copy.deepcopy(searched_front)
    res = converge_front(front, Context(p, st, p.scene.optimize, "direct"), fine, options)
    assert 1 in front.refit and front.as_json()["refit"] == front.refit
    for k, lay in front.layouts.items():
        assert search.cost(lay.routes, res[k].pose_error_rel) <= before[k] * (1 + 1e-9), k
        assert lay.realizable.x.shape == (p.mesh.n_nodes, 2)  # the design mesh's robot ...
        alone = converged_error(there, lay, start=res[k].ratios)
        assert alone.pose_error_rel == pytest.approx(res[k].pose_error_rel, rel=1e-6, abs=1e-9)  # ... of these routes
    assert search.cost(front.layouts[1].routes, res[1].pose_error_rel) < 0.9 * before[1]
    errors = [res[k].pose_error_rel for k in sorted(res)]
    assert all(b <= a + 1e-6 for a, b in zip(errors, errors[1:])), errors
    off = copy.deepcopy(searched_front)
    converge_front(off, Context(p, st, p.scene.optimize, "direct"), fine, OPTIONS)
    assert off.refit == []


def test_a_route_cut_short_is_carried_on_along_its_tangent(searched):
    """A layout of the stem route and an arm route that stops halfway along the
    planted arm tendon: carried on straight along its tangent at the cut end, the
    arm route runs on along the planted line and the pose error falls; the
    front's extension keeps that layout (refine 0: no route optimization, the
    extension alone does it)."""
    from test_consolidation import LINES

    from tendon_taichi.extract.consolidation import _Search, route_settings
    from tendon_taichi.extract.front import EXTEND, Front, _extend, _extensions
    from tendon_taichi.extract.routes import extend_route, fit_route

    p, st, _, _ = searched
    search = _Search(Context(p, st, p.scene.optimize, "direct"), OPTIONS, route_settings(p, OPTIONS), "test")
    arm = fit_route(np.array(LINES[0][:5]), p.size, 0.4, 0.0, "arm")  # x from 0.045 to 0.025, at y = 0.075
    stem = fit_route(np.array(LINES[1]), p.size, 0.4, 0.0, "stem")
    longer = extend_route(arm, 1, EXTEND * p.size, p.size)
    assert longer.length == pytest.approx(arm.length + EXTEND * p.size, rel=1e-3)
    np.testing.assert_allclose(longer.waypoints[:, 1], 0.075, atol=1e-6)  # on along the line ...
    assert longer.waypoints[-1, 0] == pytest.approx(0.025 - EXTEND * p.size, abs=1e-6)  # ... past the cut
    np.testing.assert_allclose(extend_route(arm, 0, 0.01, p.size).waypoints[0], [0.055, 0.075], atol=1e-6)
    short = search.solve([arm, stem], search.start_ratios([arm, stem], np.array([[0.4, 0.4]])))
    best, = _extensions(search, [short], p.size, OPTIONS.refine)
    assert best.routes[0].waypoints[:, 0].min() < 0.025 - 0.5 * EXTEND * p.size  # the cut end carried on
    assert best.error < 0.5 * short.error and best.cost < short.cost
    front = Front(layouts={2: short}, routes=[arm, stem])
    _extend(search, front, front.routes, p.size, OPTIONS)
    assert front.layouts[2].cost == best.cost and front.finished[2]


def test_worker_processes_find_the_same_front(searched):
    """With a worker process sharing the finishes, the extensions, the finer
    mesh's solves and its route optimizations (route optimization on: one round),
    and solving each finished layout on the finer mesh as the front finishes it
    (as ``design`` does, :class:`FineSolves`), the front, every finished layout,
    the routes optimized again on the finer mesh and the errors there are those
    found in one process, to the last bit."""
    import copy
    from dataclasses import replace

    from tendon_taichi import build_problem
    from tendon_taichi.extract.converge import FineSolves
    from tendon_taichi.tasks.pool import Pool

    p, st, greedy, _ = searched
    options = replace(OPTIONS, refine=1)
    fine = replace(build_problem(p.scene, 2), target_goal=p.target_goal)

    def run(workers):
        solved = FineSolves(fine, p.scene.optimize, "direct", workers)
        context = Context(p, st, p.scene.optimize, "direct", workers=workers)
        front = search_front(context, greedy, options, on_finished=solved.offer)
        assert front.on_finished is None  # only while the search runs
        searched = copy.deepcopy(front)  # converging changes the front in place: it goes on with the same layouts
        finished = [lay for held in front.finished.values() for lay in held]
        early = [solved._started[id(lay)][1] for lay in finished if id(lay) in solved._started]
        res = converge_front(front, context, fine, options, solved=solved)
        return searched, (front, res), (early, finished)

    alone, (alone_converged, alone_fine), (none_early, _) = run(None)
    assert none_early == []  # without workers nothing starts early
    with Pool(1) as pool:
        shared, (shared_converged, shared_fine), (early, finished) = run(pool)
        assert pool.broken is None
    # every finished layout was handed out as it was found, and some were solved before the front was done
    assert len(early) == len(finished) > 0
    assert any(job.future is not None for job in early)
    assert alone_converged.refit and shared_converged.refit == alone_converged.refit  # optimized again there
    for k in alone_converged.layouts:
        a, b = alone_converged.layouts[k], shared_converged.layouts[k]
        assert all(np.array_equal(r.control, q.control) for r, q in zip(a.routes, b.routes))
    assert alone.route_evaluations > 0 and shared.route_evaluations == alone.route_evaluations
    assert sorted(shared.layouts) == sorted(alone.layouts)
    for k in alone.layouts:
        a, b = alone.layouts[k], shared.layouts[k]
        assert a.error == b.error and a.cost == b.cost
        assert all(np.array_equal(r.control, q.control) for r, q in zip(a.routes, b.routes))
        assert np.array_equal(a.realizable.ratios, b.realizable.ratios)
        assert [lay.cost for lay in alone.finished[k]] == [lay.cost for lay in shared.finished[k]]
        assert alone_fine[k].pose_error_rel == shared_fine[k].pose_error_rel


def _prior_file(tmp_path, p, front) -> str:
    """``front`` as design.json lists it (with its routes), in a file."""
    import json

    rows = front_rows(front, None, p.scene.tendons.friction, 30.0)
    path = tmp_path / "design.json"
    path.write_text(json.dumps({"scene": p.scene.name, "body_size": p.size, "front": rows}))
    return str(path)


def test_a_prior_designs_layouts_read_back_are_the_same_robots(searched, tmp_path):
    """The front's routes written with design.json and read back
    (``--routes-from``): the same control points, samples and start ratios, and
    solved from those ratios the same as-built error."""
    from tendon_taichi.apps.priors import PRIOR, prior_layouts, read_prior
    from tendon_taichi.extract.consolidation import _Search, route_settings

    p, st, _, front = searched
    priors = prior_layouts(read_prior(_prior_file(tmp_path, p, front), p.scene), p)
    assert [len(q.routes) for q in priors] == sorted(front.layouts)
    search = _Search(Context(p, st, p.scene.optimize, "direct"), OPTIONS, route_settings(p, OPTIONS), "test")
    for q, k in zip(priors, sorted(front.layouts)):
        lay = front.layouts[k]
        for a, b in zip(q.routes, lay.routes):
            assert np.array_equal(a.control, b.control) and a.samples == b.samples and a.tension == b.tension
            assert a.source == PRIOR + b.source
        assert np.array_equal(q.ratios, np.atleast_2d(lay.realizable.ratios).reshape(1, -1))
        again = search.solve(q.routes, q.ratios)
        assert again.error == pytest.approx(lay.error, abs=1e-6)  # the soft IK's precision, x L


def test_a_prior_design_gives_the_front_a_layout_its_lattice_did_not(searched, straight, tmp_path):  # noqa: F811
    """An extractor that found only the stem tendon: its front has one tendon, not
    enough. With the two-tendon front as a prior design, the front has two tendons
    that make the pose, from the prior's routes."""
    from tendon_taichi.apps.priors import PRIOR, prior_layouts, read_prior

    p, st, _, front = searched
    stem = [consolidate(Context(p, st, p.scene.optimize, "direct"), _tendons(p, [straight[1][1]], st), OPTIONS,
                         source="c")]
    alone = search_front(Context(p, st, p.scene.optimize, "direct"), stem, OPTIONS)
    assert sorted(alone.layouts) == [1] and alone.layouts[1].error > 0.005 and alone.priors == 0
    priors = prior_layouts(read_prior(_prior_file(tmp_path, p, front), p.scene), p)
    helped = search_front(Context(p, st, p.scene.optimize, "direct"), stem, OPTIONS, priors=priors)
    assert helped.priors == len(front.layouts) and helped.seeds == alone.seeds + len(front.layouts)
    assert helped.layouts[2].error < 1e-3 and PRIOR in helped.layouts[2].source
    assert helped.as_json()["priors"] == len(front.layouts)
