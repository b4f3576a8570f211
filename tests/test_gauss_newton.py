"""The realizable robot's bounded Gauss-Newton (``tendon_taichi/optimizer/gauss_newton.py``):
it reaches a pose its tendons provably can reach, it ends no worse than L-BFGS-B on the
same objective from the same starts, and it leaves objectives that are not its sum of
squares to L-BFGS-B."""

from dataclasses import replace

import numpy as np
import pytest

from tendon_taichi import build_problem, load_scene
from tendon_taichi.body.cables import CableSet
from tendon_taichi.optimizer import SoftIK
from tendon_taichi.optimizer.gauss_newton import applies, gauss_newton
from tendon_taichi.optimizer.homotopy import RunCallbacks, run_stage


def _paths():
    """Two tendons in the t_shape body: along the bar, and up the stem (bent)."""
    t = np.linspace(0, 1, 12)
    return [np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1),
            np.stack([0.004 * np.sin(3 * t), 0.01 + 0.05 * t], 1)]


@pytest.fixture(scope="module")
def t_shape():
    p = build_problem(load_scene("t_shape"), 1)
    return p, CableSet.polylines(p.mesh, _paths(), p.scene.fibers.stiffness, friction=0.3)


def _ik(problem, cables):
    return SoftIK(problem, problem.scene.optimize, "direct", cables=cables)


def test_it_reaches_a_pose_its_tendons_can_reach(t_shape):
    """Goals put where the two tendons pull the targets at known contractions (with
    capstan friction): from a start far from them it ends at those contractions, with
    a pose error the regularizer alone explains."""
    p, cables = t_shape
    r_star = np.array([0.06, 0.03])
    x = _ik(p, cables).restart(r_star)[0].x
    reachable = replace(p, target_goal=p.target_positions(x))
    st = gauss_newton(_ik(reachable, cables), np.array([0.01, 0.01]))
    assert st.figures.pose_error_rel <= 1e-6, st.figures.pose_error_rel
    assert np.abs(st.r - r_star).max() <= 1e-4, st.r
    lbfgs = run_stage(_ik(reachable, cables), 0, np.array([0.01, 0.01]), RunCallbacks())
    assert st.evaluations < lbfgs.evaluations  # what it is for: fewer equilibria


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_it_ends_no_worse_than_lbfgsb_from_the_same_start(t_shape, seed):
    """The scene's own goals (not reachable exactly by these two tendons), starts drawn
    over the contraction range: Gauss-Newton's pose error is at most L-BFGS-B's + 1e-7 L."""
    p, cables = t_shape
    start = np.random.default_rng(seed).uniform(0.0, 0.1, 2)
    gn = gauss_newton(_ik(p, cables), start)
    lbfgs = run_stage(_ik(p, cables), 0, start, RunCallbacks())
    assert gn.figures.pose_error_rel <= lbfgs.figures.pose_error_rel + 1e-7, (gn.figures, lbfgs.figures)
    assert np.all((gn.r >= -p.scene.fibers.max_payout) & (gn.r <= p.scene.fibers.max_contraction))


def test_only_the_realizable_sum_of_squares_is_solved_by_it(t_shape):
    p, cables = t_shape
    ik = _ik(p, cables)
    assert applies(ik)
    ik.objective.active = ik.objective.active | {"a plugin's term"}
    assert not applies(ik)
    assert not applies(SoftIK(p, p.scene.optimize, "direct"))  # the fiber lattice's objective


def test_the_box_keeps_it_in_the_starts_basin(monkeypatch):
    """Two routes a finger design solved (``tests/data/finger_basin.json``): from their
    start an unboxed Gauss-Newton step leaves the start's basin and ends far worse than
    L-BFGS-B; inside the box it ends no worse."""
    import json
    from pathlib import Path

    from tendon_taichi.optimizer import gauss_newton as gn

    data = json.loads((Path(__file__).parent / "data" / "finger_basin.json").read_text())
    p = build_problem(load_scene(data["scene"]), data["level"])
    cables = CableSet.polylines(p.mesh, [np.array(w) for w in data["waypoints"]], p.scene.fibers.stiffness,
                                friction=p.scene.tendons.friction)
    start = np.array(data["start"])
    lbfgs = run_stage(_ik(p, cables), 0, start, RunCallbacks()).figures.pose_error_rel
    assert gauss_newton(_ik(p, cables), start).figures.pose_error_rel <= lbfgs + 1e-7
    monkeypatch.setattr(gn, "RADIUS", 1e9)
    assert gauss_newton(_ik(p, cables), start).figures.pose_error_rel > lbfgs + 1e-5  # the hazard
