"""Tendon consolidation on smooth routes: a split tendon is joined back by a
smooth route, a useless tendon is dropped and needed ones kept, the tolerance
bounds the pose lost and a negative one keeps the fitted routes, the budget
buys fewer tendons within it, a candidate that cannot be solved is skipped, the
Gauss-Newton screen keeps the same steps as solving every candidate, route
optimization regains the pose a cut tendon lost; the screen's target Jacobian
matches finite differences and its step reaches a reachable pose.

The goals are made by two straight tendons (which a smooth route follows
exactly), without friction, and the problem has none."""

import numpy as np
import pytest

import tendon_taichi.extract.consolidation as cons
from tendon_taichi.extract.consolidation import consolidate
from tendon_taichi.extract.context import Context
from tendon_taichi.extract.protocol import turn_angles
from tendon_taichi.extract.realizable import predict_realizable, solve_realizable_poses, target_jacobian, tendon_cables
from tendon_taichi.extract.settings import SCREEN, ConsolidationSettings
from tendon_taichi.extraction import FiberView, IdealizedState
from tendon_taichi.optimizer import SoftIK


#: two straight planted tendons on lattice lines: along the right arm and up the stem
LINES = [[(0.045 - 0.005 * i, 0.075) for i in range(9)], [(-0.005, 0.01 + 0.005 * i) for i in range(9)]]


@pytest.fixture(scope="module")
def straight():
    """t_shape with its goals made by the two LINES at 8 % contraction, frictionless:
    (problem, fiber ids along each line, the planted equilibrium)."""
    from dataclasses import replace

    from conftest import lattice_path
    from tendon_taichi import Model, NewtonSolver, build_problem, load_scene
    from tendon_taichi.body.cables import CableSet

    base = build_problem(load_scene("t_shape"), 1).with_tendons(friction=0.0)
    paths = [lattice_path(base, [np.array(q) for q in line]) for line in LINES]
    cables = CableSet.polylines(base.mesh, [np.array(line) for line in LINES], base.scene.fibers.stiffness)
    eq = NewtonSolver(Model.from_problem(base, cables=cables), "direct").solve(ac=0.08 * cables.a0)
    return replace(base, target_goal=base.target_positions(eq.x)), paths, eq


def _state(p, eq, paths):
    tau = np.zeros(p.fibers.n_fibers)
    for f in paths:
        tau[f] = 0.4
    return IdealizedState(tau, np.zeros_like(tau), eq.x, 0.01)


def _tendons(p, paths, state):
    """One tendon per fiber path (each path in order, from its first fiber's free end)."""
    view, out = FiberView(p), []
    for f in paths:
        a, b = p.fibers.edges[f[0]]
        start = int(a) if len(f) == 1 or int(a) not in p.fibers.edges[f[1]] else int(b)
        out.append(view.tendon(start, list(f), state))
    return out


def _run(p, tendons, state, tol, budget=0.0, gap=0.1, refine=0, screen=SCREEN):
    return consolidate(Context(p, state, p.scene.optimize, "direct"), tendons,
                       ConsolidationSettings(tol, gap, budget, refine, screen))


def _actions(out):
    return [s.action for s in out.steps if s.action not in ("orient", "route")]


def test_a_split_tendon_is_joined_back_by_a_smooth_route(straight):
    p, paths, eq = straight
    st = _state(p, eq, paths)
    f = list(paths[0])
    pieces = _tendons(p, [paths[1], f[:3], f[5:]], st)  # two fibers (1 cm) left out of the straight one
    out = _run(p, pieces, st, tol=1e-3)
    assert out.extracted_count == 3 and out.layout.count == 2
    assert _actions(out) == ["join"] and out.steps[0].tendons == (1, 2)
    joined = out.layout.routes[-1]
    assert joined.source == "join"
    w = joined.waypoints
    assert np.degrees(turn_angles(w)).max() < 5.0  # smooth, and straight as the planted one
    ends = p.fibers.nodes[p.fibers.edges[[f[0], f[-1]]]].reshape(-1, 2)
    assert min(np.linalg.norm(ends - w[0], axis=1).min(), np.linalg.norm(ends - w[-1], axis=1).min()) < 0.01
    assert np.ptp(w[:, 0]) >= 0.025  # it spans both pieces and the gap between them
    assert out.realizable.pose_error_rel <= out.extracted_pose_error_rel + 1e-3  # within the tolerance
    assert out.evaluations >= 2


def test_a_useless_tendon_is_dropped_and_needed_ones_kept(straight):
    p, paths, eq = straight
    st = _state(p, eq, paths)
    mid = p.fibers.nodes[p.fibers.edges].mean(axis=1)
    extra = [int(np.argmin(np.linalg.norm(mid - q, axis=1))) for q in ([0.004, 0.03], [0.004, 0.035])]
    tendons = _tendons(p, [paths[0], paths[1], extra], st)
    out = _run(p, tendons, st, tol=1e-3)
    assert _actions(out) == ["drop"] and out.steps[0].tendons == (2,)
    assert out.layout.count == 2
    assert out.realizable.pose_error_rel <= out.extracted_pose_error_rel + 1e-3


def test_tolerance_bounds_the_lost_pose_and_negative_keeps_the_fitted_routes(straight):
    p, paths, eq = straight
    st = _state(p, eq, paths)
    tendons = _tendons(p, paths, st)
    kept = _run(p, tendons, st, tol=1e-3)  # each planted tendon is needed: dropping one costs > 0.1 % of L
    assert kept.layout.count == 2 and _actions(kept) == []
    loose = _run(p, tendons, st, tol=1.0)  # anything goes: down to the bare body
    assert loose.layout.count == 0 and [s.count for s in loose.steps if s.action == "drop"] == [1, 0]
    assert loose.realizable.pose_error_rel > kept.realizable.pose_error_rel + 1e-3
    off = _run(p, tendons, st, tol=-1.0, refine=2)
    assert off.steps == [] and off.evaluations == 0 and off.layout.count == 2
    assert off.realizable.pose_error_rel == pytest.approx(off.extracted_pose_error_rel)


def test_the_budget_buys_fewer_tendons_within_it(straight):
    """Each planted tendon is needed for an exact pose, but with a budget that covers
    the error of the better one alone, that one is what is kept."""
    p, paths, eq = straight
    st = _state(p, eq, paths)
    tendons = _tendons(p, paths, st)
    routes, tensions = cons.extracted_routes(p, tendons, st, 0.02 * p.size)
    search = cons._Search(Context(p, st, p.scene.optimize, "direct"), ConsolidationSettings(),
                          cons.route_settings(p, ConsolidationSettings()), "")
    start = search.start_ratios(routes, tensions)
    alone = [search.solve([r], start[:, [i]]).error for i, r in enumerate(routes)]
    best = int(np.argmin(alone))
    assert 1e-3 < alone[best] < 0.05  # more than the tolerance allows, so only the budget can buy it
    out = _run(p, tendons, st, tol=1e-3, budget=1.01 * alone[best], screen=0)
    assert _actions(out) == ["drop"] and out.layout.count == 1
    assert np.allclose(out.layout.routes[0].control, routes[best].control) or \
        np.allclose(out.layout.routes[0].control, routes[best].reversed().control)
    assert out.realizable.pose_error_rel <= 1.01 * alone[best]
    short = _run(p, tendons, st, tol=1e-3, budget=0.99 * alone[best], screen=0)
    assert short.layout.count == 2 and _actions(short) == []


def test_a_body_too_narrow_for_the_clearance_keeps_every_tendon_flagged(straight):
    """A clearance of 0.1 L (12.8 mm) in a T whose arms and stem are 20 mm wide: no
    route can keep it, and none is left out. Each keeps about the
    most the body allows (half the width, 10 mm), says so and is logged; only a
    step of consolidation removes one, and every step says so; route optimization
    keeps the clearance each had."""
    p, paths, eq = straight
    narrow = p.with_tendons(clearance=0.1)
    st = _state(narrow, eq, paths)
    tendons = _tendons(narrow, paths, st)
    routes, tensions = cons.extracted_routes(narrow, tendons, st, 0.1 * p.size)
    assert len(routes) == 2 and tensions.shape == (1, 2)
    for r in routes:
        assert r.kept_clearance == pytest.approx(narrow.walls.polyline_distance(r.waypoints), rel=1e-12)
        assert 0.0095 <= r.kept_clearance <= 0.01 * (1 + 1e-9)
    said = []
    out = consolidate(Context(narrow, st, narrow.scene.optimize, "direct", log=said.append), tendons,
                      ConsolidationSettings(0.0, 0.1, 0.0, 1, SCREEN))
    actions = [s.action for s in out.steps]
    assert "route" in actions and out.layout.count == 2 - actions.count("drop") - actions.count("join") >= 1
    assert sum("too narrow" in line for line in said) == 2
    for r in out.layout.routes:
        assert r.kept_clearance is not None and narrow.walls.polyline_distance(r.waypoints) >= 0.0095


def test_a_candidate_that_cannot_be_solved_is_skipped(straight, monkeypatch):
    """The split-tendon case again, with every layout of two tendons but the joined
    one unsolvable: the join is still found, the drops are skipped."""
    from tendon_taichi.errors import ConvergenceError

    p, paths, eq = straight
    st = _state(p, eq, paths)
    f = list(paths[0])
    pieces = _tendons(p, [paths[1], f[:3], f[5:]], st)
    real_solve = cons.solve_realizable_poses

    def solve(context, tendons, *args):
        if len(tendons) < 3 and not any(t.control is not None and np.ptp(t.waypoints[:, 0]) >= 0.025
                                        and abs(t.waypoints[:, 1] - 0.075).max() < 0.01 for t in tendons):
            raise ConvergenceError("equilibrium did not converge (test)")
        return real_solve(context, tendons, *args)

    monkeypatch.setattr(cons, "solve_realizable_poses", solve)
    out = _run(p, pieces, st, tol=1e-3, screen=0)
    assert _actions(out) == ["join"]
    assert out.unsolved >= 3 and out.as_json()["unsolved"] == out.unsolved


def test_the_screen_keeps_the_steps_of_solving_every_candidate(straight):
    p, paths, eq = straight
    st = _state(p, eq, paths)
    f = list(paths[0])
    mid = p.fibers.nodes[p.fibers.edges].mean(axis=1)
    extra = [int(np.argmin(np.linalg.norm(mid - q, axis=1))) for q in ([0.004, 0.03], [0.004, 0.035])]
    tendons = _tendons(p, [paths[1], f[:3], f[5:], extra], st)
    screened, every = _run(p, tendons, st, tol=1e-3, screen=2), _run(p, tendons, st, tol=1e-3, screen=0)
    assert screened.screened > 0 and every.screened == 0
    assert screened.evaluations < every.evaluations
    reductions = [[(s.action, s.tendons) for s in out.steps if s.action in ("drop", "join")]
                  for out in (screened, every)]
    assert reductions[0] == reductions[1] and reductions[0]


def test_route_optimization_regains_the_pose_of_a_cut_tendon(straight):
    """The arm's planted tendon with its last three fibers cut off: no reduction
    fits (tolerance 0); optimizing the routes - their control points, anchors and
    pull ends, with the contractions - regains the pose lost to the cut, and the
    routes stay smooth and clear of the walls."""
    p, paths, eq = straight
    st = _state(p, eq, paths)
    f = list(paths[0])
    tendons = _tendons(p, [paths[1], f[:-3]], st)
    fitted = _run(p, tendons, st, tol=0.0, refine=0)
    grown = _run(p, tendons, st, tol=0.0, refine=2)
    assert fitted.layout.count == grown.layout.count == 2 and _actions(grown) == []
    assert [s.action for s in grown.steps][-1] == "route" and grown.route_evaluations > 0
    assert grown.realizable.pose_error_rel < 0.2 * fitted.realizable.pose_error_rel
    for r in grown.layout.routes:
        assert p.walls.distance(r.waypoints).min() >= 0.02 * p.size * (1 - 1e-6)
        assert np.degrees(turn_angles(r.waypoints)).max() < 20.0


def _planted_tendons(p, paths):
    ones = IdealizedState(np.ones(p.fibers.n_fibers), np.zeros(p.fibers.n_fibers), p.mesh.nodes, 0.01)
    return _tendons(p, paths, ones)


def test_target_jacobian_matches_finite_differences(planted):
    """d(target positions)/d(c / L0) of the realizable robot against central
    differences of tightly solved equilibria, per tendon (with friction:
    tests/test_friction.py)."""
    p, paths, _ = planted
    cables = tendon_cables(p, _planted_tendons(p, paths))
    ps = SoftIK(p, p.scene.optimize, "direct", cables=cables).poses[0]
    r, h = np.array([0.05, 0.07]), 1e-6

    def targets(ratios):
        return p.target_positions(ps.newton.solve(ac=ratios * cables.a0, x0=p.mesh.nodes, tol=1e-13).x)

    targets(r)
    J = target_jacobian(ps, cables.a0)
    for j in range(2):
        e = h * np.eye(2)[j]
        fd = (targets(r + e) - targets(r - e)) / (2 * h)
        assert np.linalg.norm(J[..., j] - fd) <= 1e-6 * np.linalg.norm(fd)
        assert np.linalg.norm(fd) > 1e-3 * p.size


def test_gauss_newton_steps_converge_to_a_reachable_pose(planted):
    """From 5 % contraction, Gauss-Newton steps of the realizable IK converge to the
    planted 8 % (the goals are reachable without friction): the first cuts the pose
    error tenfold, the second a hundredfold more, and each predicts the error it
    leaves to within 5 % of the error it started from."""
    p, paths, _ = planted
    tendons = _planted_tendons(p, paths)
    a0 = tendon_cables(p, tendons).a0
    ps = SoftIK(p, p.scene.optimize, "direct", cables=tendon_cables(p, tendons)).poses[0]

    def at(ratios):
        x = ps.newton.solve(ac=ratios[0] * a0, x0=p.mesh.nodes, tol=1e-12).x
        return x, np.linalg.norm(p.target_positions(x) - p.target_goal) / p.size

    ratios = np.full((1, 2), 0.05)
    x, error = at(ratios)
    for gain in (10.0, 100.0):
        predicted, ratios = predict_realizable(Context(p, None, p.scene.optimize, "direct"), tendons, ratios, [x])
        x, now = at(ratios)
        assert now <= error / gain and abs(predicted - now) <= 0.05 * error, (gain, error, now, predicted)
        error = now
    assert np.abs(ratios - 0.08).max() <= 1e-4
