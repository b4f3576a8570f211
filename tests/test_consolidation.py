"""Tendon consolidation: a split tendon is joined back, a useless tendon is
dropped, needed tendons are kept, the tolerance bounds the pose lost, the
budget buys fewer tendons within it, and refinement grows a cut tendon back -
also to take over from a tendon it lets drop - with the same steps whether its
candidates are screened by a Gauss-Newton step or all solved in full (a join
that looks worse than the best drop is not refined: a known weakness, xfail);
the screen's target Jacobian matches finite differences and its step reaches a
reachable pose."""

import numpy as np
import pytest

from tendon_taichi.extract.consolidation import Bridges, consolidate
from tendon_taichi.extract.settings import SCREEN, ConsolidationSettings
from tendon_taichi.extraction import FiberView, IdealizedState
from tendon_taichi.optimizer import SoftIK
from tendon_taichi.extract.realizable import predict_realizable, solve_realizable_poses, target_jacobian, tendon_cables


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


def _spacings(p, n):
    """``n`` lattice spacings as a fraction of the body size (the unit of ``gap``)."""
    return n * p.fibers.spacing / p.size


def _run(p, tendons, state, tol, budget=0.0, gap=3.0, refine=12, screen=SCREEN):
    real = solve_realizable_poses(p, tendons, state, p.scene.optimize, "direct")
    settings = ConsolidationSettings(tol, _spacings(p, gap), budget, refine, screen)
    return consolidate(p, tendons, state, p.scene.optimize, real, settings, "direct")


def test_bridge_rejoins_a_split_strand(planted):
    p, paths, eq = planted
    st = _state(p, eq, paths)
    whole = _tendons(p, [paths[1]], st)[0]
    f = list(whole.fibers)
    left, right = _tendons(p, [f[:3], f[5:]], st)  # two fibers (one spacing each) left out
    joined = Bridges(p, st, _spacings(p, 3.0)).joins(left, right)
    assert any(set(t.fibers) == set(f) for t in joined)
    assert Bridges(p, st, _spacings(p, 1.5)).joins(left, right) == []  # the ends are 2 spacings apart


def test_split_tendon_is_joined_and_the_planted_layout_restored(planted):
    p, paths, eq = planted
    st = _state(p, eq, paths)
    f = list(paths[0])
    pieces = _tendons(p, [f[:3], f[5:], paths[1]], st)  # a two-fiber gap in the arm
    out = _run(p, pieces, st, tol=1e-3)
    assert out.extracted_count == 3 and len(out.tendons) == 2
    assert [s.action for s in out.steps] == ["join"]
    assert {frozenset(t.fibers) for t in out.tendons} == {frozenset(q) for q in paths}
    # the planted layout reproduces the goals: joined, it is (nearly) exact, and better than split
    assert out.realizable.pose_error_rel <= 1e-4 < out.extracted_pose_error_rel
    assert out.evaluations >= 3


def test_useless_tendon_is_dropped_and_needed_ones_kept(planted):
    p, paths, eq = planted
    st = _state(p, eq, paths)
    # one extra fiber in the stem: the planted two already make the pose exactly, so it is not needed
    mid = p.fibers.nodes[p.fibers.edges].mean(axis=1)
    extra = int(np.argmin(np.linalg.norm(mid - [0.005, 0.03], axis=1)))
    assert extra not in np.concatenate(paths)
    tendons = _tendons(p, [paths[0], paths[1], [extra]], st)
    out = _run(p, tendons, st, tol=1e-3)
    assert len(out.tendons) == 2 and [s.action for s in out.steps] == ["drop"]
    assert out.steps[0].tendons == (2,)
    assert {frozenset(t.fibers) for t in out.tendons} == {frozenset(q) for q in paths}
    assert out.realizable.pose_error_rel <= out.extracted_pose_error_rel + 1e-3


def test_tolerance_bounds_the_lost_pose_and_negative_disables(planted):
    p, paths, eq = planted
    st = _state(p, eq, paths)
    tendons = _tendons(p, paths, st)
    kept = _run(p, tendons, st, tol=1e-3)  # each planted tendon is needed: dropping one costs > 0.1 % of L
    assert len(kept.tendons) == 2 and kept.steps == []
    loose = _run(p, tendons, st, tol=1.0)  # anything goes: down to the bare body
    assert len(loose.tendons) == 0 and [s.count for s in loose.steps] == [1, 0]
    assert loose.realizable.pose_error_rel == pytest.approx(loose.steps[-1].realizable_pose_error_rel)
    assert loose.realizable.pose_error_rel > kept.realizable.pose_error_rel + 1e-3
    off = _run(p, tendons, st, tol=-1.0)
    assert off.tendons == tendons and off.evaluations == 0 and off.steps == []


def test_budget_buys_fewer_tendons_within_it(planted):
    """Each planted tendon is needed for an exact pose, but with a budget that covers
    the error of the better one alone, that one is what is kept."""
    p, paths, eq = planted
    st = _state(p, eq, paths)
    tendons = _tendons(p, paths, st)
    alone = [solve_realizable_poses(p, [t], st, p.scene.optimize, "direct").pose_error_rel for t in tendons]
    best = int(np.argmin(alone))
    assert 1e-3 < alone[best] < 0.05  # more than the tolerance allows, so only the budget can buy it
    # no refinement: it would then grow the tendon left (the tests above and below show that)
    out = _run(p, tendons, st, tol=1e-3, budget=1.01 * alone[best], refine=0)
    assert [s.action for s in out.steps] == ["drop"] and len(out.tendons) == 1
    assert set(out.tendons[0].fibers) == set(paths[best])
    assert out.realizable.pose_error_rel == pytest.approx(alone[best], rel=1e-9)
    short = _run(p, tendons, st, tol=1e-3, budget=0.99 * alone[best], refine=0)
    assert len(short.tendons) == 2 and short.steps == []


def test_a_candidate_that_cannot_be_solved_is_skipped(planted, monkeypatch):
    """The split-tendon case again, with every layout of fewer than three tendons but
    the planted one unsolvable: the join is still found, the drops are skipped."""
    import tendon_taichi.extract.consolidation as cons
    from tendon_taichi.errors import ConvergenceError

    p, paths, eq = planted
    st = _state(p, eq, paths)
    f = list(paths[0])
    pieces = _tendons(p, [f[:3], f[5:], paths[1]], st)
    planted_sets = {frozenset(q) for q in paths}

    def solve(problem, tendons, *args):
        if len(tendons) < 3 and {frozenset(t.fibers) for t in tendons} != planted_sets:
            raise ConvergenceError("equilibrium did not converge (test)")
        return solve_realizable_poses(problem, tendons, *args)

    monkeypatch.setattr(cons, "solve_realizable_poses", solve)
    out = _run(p, pieces, st, tol=1e-3)
    assert [s.action for s in out.steps] == ["join"]
    assert {frozenset(t.fibers) for t in out.tendons} == planted_sets
    assert out.unsolved >= 3 and out.as_json()["unsolved"] == out.unsolved


@pytest.mark.parametrize("screen", [SCREEN, 0], ids=["screened", "all"])
def test_refinement_grows_a_cut_tendon_back_to_the_planted_one(planted, screen):
    """The straight planted tendon with its last two fibers cut off: no drop fits
    (tolerance 0), and refinement extends it back, fiber by fiber, to the planted
    layout, which is exact; with ``refine`` 0 nothing changes."""
    p, paths, eq = planted
    st = _state(p, eq, paths)
    tendons = _tendons(p, [paths[0], paths[1][:-2]], st)
    out = _run(p, tendons, st, tol=0.0, screen=screen)
    assert (out.screened > out.evaluations) == bool(screen)
    assert [s.action for s in out.steps] == ["extend", "extend"]
    errors = [out.extracted_pose_error_rel] + [s.realizable_pose_error_rel for s in out.steps]
    assert all(b < 0.98 * a for a, b in zip(errors, errors[1:]))  # each step gained REFINE_GAIN at least
    assert {frozenset(t.fibers) for t in out.tendons} == {frozenset(q) for q in paths}
    assert out.realizable.pose_error_rel <= 1e-4 < out.extracted_pose_error_rel
    off = _run(p, tendons, st, tol=0.0, refine=0)
    assert off.steps == [] and off.tendons == tendons


@pytest.mark.parametrize("screen", [SCREEN, 0], ids=["screened", "all"])
def test_refinement_lets_a_tendon_drop_that_a_neighbour_takes_over(planted, screen):
    """The straight planted tendon cut in two, the short piece (one fiber) out of
    join reach: dropping it alone loses pose (more than tolerance 0 allows), but
    with the long piece grown into its place the drop is kept - the planted layout."""
    p, paths, eq = planted
    st = _state(p, eq, paths)
    tendons = _tendons(p, [paths[0], paths[1][:-2], paths[1][-1:]], st)
    out = _run(p, tendons, st, tol=0.0, gap=0.5, screen=screen)
    assert [s.action for s in out.steps] == ["drop", "extend", "extend"]
    assert out.steps[0].tendons == (2,)
    assert out.steps[0].realizable_pose_error_rel > out.extracted_pose_error_rel  # outside the bound alone
    assert {frozenset(t.fibers) for t in out.tendons} == {frozenset(q) for q in paths}
    assert out.realizable.pose_error_rel <= 1e-4 < out.extracted_pose_error_rel


@pytest.mark.xfail(strict=True, reason="known weakness: only the reduction with the lowest unrefined error is "
                   "refined, so a join that would refine to the exact layout loses to a drop that refines worse")
def test_a_worse_join_is_refined_when_the_best_drop_cannot_be(planted):
    """The L-shaped planted tendon cut in two, its last two fibers also cut off:
    dropping the short piece loses less pose than joining the pieces (1.3 % of L
    against 2.0 %), and neither fits the bound (tolerance 0). Refining only the
    best drop ends with the long piece grown to 0.2 % of L, not the planted
    layout; refining the best join too would grow it back to the planted
    tendon, which is exact."""
    p, paths, eq = planted
    st = _state(p, eq, paths)
    f = list(paths[0])
    tendons = _tendons(p, [paths[1], f[:3], f[6:-2]], st)
    out = _run(p, tendons, st, tol=0.0, gap=4.0)
    assert [s.action for s in out.steps] == ["join", "extend", "extend"]
    assert out.steps[0].tendons == (1, 2)
    assert {frozenset(t.fibers) for t in out.tendons} == {frozenset(q) for q in paths}
    assert out.realizable.pose_error_rel <= 1e-4 < out.extracted_pose_error_rel


def _planted_tendons(p, paths):
    ones = IdealizedState(np.ones(p.fibers.n_fibers), np.zeros(p.fibers.n_fibers), p.mesh.nodes, 0.01)
    return _tendons(p, paths, ones)


def test_target_jacobian_matches_finite_differences(planted):
    """d(target positions)/d(c / L0) of the realizable robot against central
    differences of tightly solved equilibria, per tendon."""
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
    planted 8 % (the goals are reachable): the first cuts the pose error tenfold,
    the second a hundredfold more, and each predicts the error it leaves (as the
    equilibrium at its ratios has it) to within 5 % of the error it started from."""
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
        predicted, ratios = predict_realizable(p, tendons, p.scene.optimize, ratios, [x], "direct")
        x, now = at(ratios)
        assert now <= error / gain and abs(predicted - now) <= 0.05 * error, (gain, error, now, predicted)
        error = now
    assert np.abs(ratios - 0.08).max() <= 1e-4
