"""Several target poses at once: scene format, the union-tension objective and its
adjoint gradient, and a two-pose run end to end (optimize, replay, export, compare)."""

import json
import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from tendon_taichi import build_problem, load_scene, parse_scene
from tendon_taichi.errors import SceneError
from tendon_taichi.objective import SparsityTerm, State, union_tension
from tendon_taichi.optimizer import SoftIK
from tendon_taichi.planted.plant import PlantedTendon, plant, solve_tendons

from reference import objective_fd

FINGER = """
name = "f"
[body]
outline = [[0.0, 0.0], [0.10, 0.0], [0.10, 0.02], [0.0, 0.02]]
[[fixed]]
box = [[-0.0005, -0.0005], [0.0005, 0.0205]]
"""
POSE = """
[[poses]]
{name}
[[poses.targets]]
point = [0.10, 0.01]
goal = [{gx}, {gy}]
"""


def _two_poses(goal_a=(0.094, 0.034), goal_b=(0.094, -0.013), names=('name = "a"', 'name = "b"')):
    return FINGER + POSE.format(name=names[0], gx=goal_a[0], gy=goal_a[1]) + \
        POSE.format(name=names[1], gx=goal_b[0], gy=goal_b[1])


def test_builtin_two_pose_scene():
    sc = load_scene("finger_updown")
    assert [p.name for p in sc.poses] == ["up", "down"]
    assert len(sc.targets) == 4 and sc.target_pose.tolist() == [0, 0, 1, 1]
    p = build_problem(sc, 1)
    assert p.n_poses == 2 and p.pose_names == ["up", "down"]
    up = p.pose(0)
    assert up.n_poses == 1 and np.array_equal(up.target_goal, p.target_goal[:2])
    assert up.mesh is p.mesh and up.fibers is p.fibers


def test_one_pose_scene_is_one_unnamed_pose():
    sc = load_scene("finger")
    assert len(sc.poses) == 1 and sc.targets == sc.poses[0].targets
    p = build_problem(sc, 1)
    assert p.pose(0) is p


@pytest.mark.parametrize("text, message", [
    (_two_poses() + '[[targets]]\npoint = [0.1, 0.01]\ngoal = [0.1, 0.02]\n', "not both"),
    (_two_poses(names=('name = "a"', 'name = "a"')), "pose names must differ"),
    (FINGER + '[[poses]]\nname = "a"\n', "[[poses[0].targets]]"),
    (FINGER + '[[poses]]\nspeed = 1\n[[poses.targets]]\npoint = [0.1, 0.01]\ngoal = [0.1, 0.02]\n',
     "unknown key 'speed' in poses[0]"),
    (FINGER + '[[poses]]\nname = 3\n[[poses.targets]]\npoint = [0.1, 0.01]\ngoal = [0.1, 0.02]\n',
     "poses[0].name"),
    (FINGER + '[[poses]]\n[[poses.targets]]\npoint = [0.1]\ngoal = [0.1, 0.02]\n', "poses[0].targets[0].point"),
])
def test_bad_poses_are_scene_errors(text, message):
    with pytest.raises(SceneError, match=re.escape(message)):
        parse_scene(text, origin="s.toml")


def test_a_target_outside_names_its_pose():
    sc = parse_scene(_two_poses(goal_b=(0.1, 0.0)).replace("point = [0.10, 0.01]\ngoal = [0.1, 0.0]",
                                                             "point = [0.20, 0.01]\ngoal = [0.1, 0.0]"),
                     origin="s.toml")
    with pytest.raises(SceneError, match=r"poses\[1\]\.targets\[0\]\.point"):
        build_problem(sc, 1)


def test_union_tension_and_its_derivative():
    rng = np.random.default_rng(3)
    taus = np.abs(rng.standard_normal((3, 50)))
    taus[:, 7] = 0.0
    tu, d = union_tension(taus)
    assert np.allclose(tu, np.linalg.norm(taus, axis=0)) and tu[7] == 0 and np.all(d[:, 7] == 0)
    h = 1e-7
    for p in range(3):
        e = np.zeros_like(taus)
        e[p] = h
        fd = (union_tension(taus + e)[0] - union_tension(taus - e)[0]) / (2 * h)
        ok = tu > 0
        assert np.allclose(fd[ok], d[p][ok], rtol=1e-6)
    one = taus[:1]
    t1, d1 = union_tension(one)
    assert np.array_equal(t1, one[0]) and np.array_equal(d1, np.ones_like(one))


def test_two_identical_poses_count_the_pose_twice_and_share_the_layout():
    """Both poses ask for the same goal: at r = [r, r] the pose and contraction terms
    are twice one pose's, and the layout terms see sqrt(2) x the one-pose tension."""
    one = build_problem(parse_scene(FINGER + POSE.format(name="", gx=0.094, gy=0.034), origin="o"), 1)
    two = build_problem(parse_scene(_two_poses(goal_b=(0.094, 0.034)), origin="t"), 1)
    s = one.scene.optimize
    r = np.random.default_rng(5).uniform(0.0, 0.1, one.fibers.n_fibers)
    ik1, ik2 = SoftIK(one, s, "direct"), SoftIK(two, s, "direct")
    for ik in (ik1, ik2):
        ik.configure(0.3)
        ik.restart(np.tile(r, ik.problem.n_poses))
    f1, g1 = ik1.evaluate(r)
    f2, g2 = ik2.evaluate(np.concatenate([r, r]))
    t1, t2 = ik1._last[3].terms, ik2._last[3].terms
    assert t2["pose"] == pytest.approx(2 * t1["pose"], rel=1e-9)
    assert t2["contraction"] == pytest.approx(2 * t1["contraction"], rel=1e-12)
    tau = ik1.tensions()[0]
    sp = SparsityTerm(one, s.sparsity, s.sparsity_measure, 0.3).evaluate(State(None, None, np.sqrt(2) * tau))
    assert t2["sparsity"] == pytest.approx(sp.value, rel=1e-9)
    assert np.allclose(g2[:len(r)], g2[len(r):], rtol=1e-9, atol=1e-14)  # symmetric in the poses


@pytest.mark.parametrize("solver", ["direct", "cg"])
def test_two_pose_adjoint_gradient_matches_finite_differences(solver):
    p = build_problem(load_scene("finger_updown"), 1)
    ik = SoftIK(p, replace(p.scene.optimize, strand_end=1e-4, continuity=1e-4), solver)
    ik.eval_tol = 1e-13
    ik.configure(0.3)
    rng = np.random.default_rng(11)
    n = p.fibers.n_fibers
    r = np.concatenate([rng.uniform(-0.05, 0.12, n), rng.uniform(-0.05, 0.12, n)])
    ik.restart(r)
    f, g = ik.evaluate(r)
    assert len(g) == 2 * n
    taus = ik.tensions()
    assert ((taus > 0) & (taus < 0.3)).any() and (taus > 0.3).any()
    for trial in range(2):
        d = rng.standard_normal(len(r))
        if trial == 1:
            d[:n] = 0.0  # only the second pose moves
        fd = objective_fd(ik, r, d)
        assert abs(fd - np.dot(g, d)) <= 1e-5 * abs(fd), (fd, np.dot(g, d))


def test_planted_two_poses_reproduce_their_goals():
    text, layout = plant("finger", 2, 2, level=1, poses=2)
    assert layout["name"] == "finger_planted_2t_s2_2p" and len(layout["poses"]) == 2
    assert plant("finger", 2, 2, level=1, poses=2)[0] == text  # deterministic
    sc = parse_scene(text, origin="planted")
    assert [q.name for q in sc.poses] == ["pose0", "pose1"]
    ratios = np.array([q["contraction_ratios"] for q in layout["poses"]])
    assert np.allclose(ratios[0], [t["contraction_ratio"] for t in layout["tendons"]])
    assert (ratios[1] < 0).any() and (ratios[1] > 0).any()  # the second pose uses a proper subset
    p = build_problem(sc, 1)
    tendons = [PlantedTendon(np.array(t["waypoints"]), t["length"], t["contraction"], t["contraction_ratio"])
               for t in layout["tendons"]]
    lengths = np.array([t.length for t in tendons])
    for i in range(2):
        eq = solve_tendons(p, tendons, ratios[i] * lengths)
        q = p.pose(i)
        assert np.abs(q.target_positions(eq.x) - q.target_goal).max() < 1e-9


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "tendon_taichi", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=900)


def test_two_pose_run_end_to_end(tmp_path):
    """optimize reaches both poses with one layout; replay reproduces it; the export
    holds each pose; every extractor's realizable robot re-solves per pose (no final
    route-optimization rounds: consolidation is tested elsewhere). With the
    effort term, the fibers that pull in one pose are paid out in the other (without
    it, 14 of 26 active fibers pull in both poses: co-contraction)."""
    rec = tmp_path / "fud.rrd"
    r = _cli("optimize", "finger_updown", "--record", rec, "--json", "--png", "--effort", "1e-3")
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    final = s["final"]
    L = s["body_size"]
    assert [q["name"] for q in final["poses"]] == ["up", "down"]
    assert all(q["pose_error_rel"] < 0.01 for q in final["poses"])
    assert final["pose_error"] == pytest.approx(np.hypot(*[q["pose_error"] for q in final["poses"]]))
    assert final["active_length"] < 0.5 * s["stages"][0]["active_length"]
    with np.load(s["export"]) as z:
        assert z["pose_x"].shape == (2, s["nodes"], 2) and z["pose_ac"].shape == (2, s["fibers"])
        assert list(z["pose_names"]) == ["up", "down"] and z["target_pose"].tolist() == [0, 0, 1, 1]
        assert np.array_equal(z["x"], z["pose_x"][0]) and np.array_equal(z["ac"], z["pose_ac"][0])
        assert np.allclose(z["tau_union"], np.linalg.norm(z["pose_tau"], axis=0))
        # the two poses pull different fibers: few are active in both
        act = z["pose_tau"] > 0.01
        assert (act[0] & act[1]).sum() <= 0.25 * (act[0] | act[1]).sum()
    r = _cli("replay", rec, "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["reproduces"], r.stderr
    r = _cli("compare", rec, "--json", "--no-record", "--refine", "0")
    assert r.returncode == 0, r.stderr
    for ex in json.loads(r.stdout)["extractors"]:
        m, real = ex["metrics"], ex["realizable"]
        assert len(real["poses"]) == 2 and np.shape(real["contraction"]) == (2, m["count"])
        errs = [q["pose_error"] for q in real["poses"]]
        assert m["realizable_pose_error"] == pytest.approx(np.hypot(*errs))
        assert m["realizable_pose_errors_rel"] == pytest.approx([e / L for e in errs])
        assert m["realizable_pose_error_rel"] < 0.01
