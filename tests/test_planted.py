"""Planted layouts: random tendons whose equilibrium makes a scene's goals."""

import json
import math
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from tendon_taichi import (CableSet, InputError, Model, NewtonSolver, build_problem, builtin_scenes,
                           load_scene, parse_scene)
from tendon_taichi.body.geometry import points_in_polygon
from tendon_taichi.planted.plant import layout_json, plant
from tendon_taichi.planted.walk import PlantSettings

ROOT = Path(__file__).resolve().parents[1]
SUITE = ROOT / "benchmarks" / "planted"
SCENES = ["t_shape", "finger", "gripper", "cross", "snake"]


@pytest.fixture(scope="module")
def planted():
    """(scene name, tendons, seed) -> (text, layout), level 2, one per scene."""
    cases = [("t_shape", 3, 7), ("finger", 2, 5), ("gripper", 3, 1), ("cross", 2, 4), ("snake", 3, 9)]
    return {c: plant(c[0], c[1], c[2]) for c in cases}


def _distance_to_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    ap = points[:, None, :] - a[None]
    t = np.clip((ap * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    return np.linalg.norm(ap - t[..., None] * ab, axis=-1).min(axis=1)


def _dense(path: np.ndarray, step: float) -> np.ndarray:
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, math.ceil(np.linalg.norm(b - a) / step))
        out.append(a + np.arange(1, n + 1)[:, None] / n * (b - a))
    return np.concatenate(out)


def test_new_builtin_scenes_mesh_at_levels_1_to_3():
    assert {"cross", "snake"} <= set(builtin_scenes())
    for name in ("cross", "snake"):
        scene = load_scene(name)
        assert 3 <= len(scene.targets) <= 5
        dofs = [build_problem(scene, lv).counts()["dofs"] for lv in (1, 2, 3)]
        assert dofs[0] < dofs[1] < dofs[2] and 800 <= dofs[1] <= 3000, (name, dofs)


def test_same_seed_gives_identical_outputs(planted):
    text, layout = planted[("finger", 2, 5)]
    text2, layout2 = plant(load_scene("finger"), 2, 5)
    assert text == text2 and layout_json(layout) == layout_json(layout2)
    text3, _ = plant("finger", 2, 6)
    assert text3 != text


def test_scene_text_names_and_loads(planted):
    for (name, n, seed), (text, layout) in planted.items():
        scene = parse_scene(text, origin="planted")
        assert scene.name == layout["name"] == f"{name}_planted_{n}t_s{seed}"
        assert f"tendon-taichi planted {name} --tendons {n} --seed {seed} --level 2" in text
        base = load_scene(name)
        assert [t.point for t in scene.targets] == [t.point for t in base.targets]
        assert scene.body.outline.tolist() == base.body.outline.tolist()
        assert re.search(r"goal = \[-?\d+\.\d{10}, -?\d+\.\d{10}\]", text)
        assert layout["level"] == 2 and layout["seed"] == seed and len(layout["tendons"]) == n


def test_planted_equilibrium_reproduces_the_goals(planted):
    for (name, n, seed), (text, layout) in planted.items():
        layout = json.loads(layout_json(layout))  # exactly what the file holds
        scene = parse_scene(text, origin="planted")
        p = build_problem(scene, layout["level"])
        paths = [np.array(t["waypoints"]) for t in layout["tendons"]]
        cab = CableSet.polylines(p.mesh, paths, scene.fibers.stiffness)
        assert np.allclose(cab.a0, [t["length"] for t in layout["tendons"]], rtol=1e-12)
        ac = np.array([t["contraction"] for t in layout["tendons"]])
        eq = NewtonSolver(Model.from_problem(p, cables=cab), "direct").solve(ac=ac)
        L = p.size
        err = np.abs(p.target_positions(eq.x) - p.target_goal).max()
        assert err <= 1e-9 * L, (name, err / L)
        assert np.allclose(eq.tau, [t["tension"] for t in layout["tendons"]], rtol=1e-8)
        disp = np.linalg.norm(p.target_goal - np.array([t.point for t in scene.targets]), axis=1).max()
        assert disp >= 0.02 * L
        assert layout["pose"]["body_size"] == pytest.approx(L)
        assert layout["pose"]["max_target_displacement"] == pytest.approx(disp, rel=1e-6)


def test_tendons_are_smooth_and_inside_with_margin_and_leave_at_the_clamp(planted):
    for (name, n, seed), (text, layout) in planted.items():
        # the cross is clamped in its middle: no clamp meets its outline, its tendons end inside
        exit = layout.get("exit", "inside")
        assert exit == parse_scene(text).tendons.exit == ("inside" if name == "cross" else "clamp")
        scene = load_scene(name).with_tendons(exit=exit)
        p = build_problem(scene, 2)
        L, spacing = p.size, p.fibers.spacing
        lead = 0.0 if p.exits is None else 1.5 * max(p.exits.zone, 1.1 * spacing)  # walk.Region.lead
        paths = []
        for t in layout["tendons"]:
            w = np.array(t["waypoints"])
            if p.exits is not None:  # the pull end is where it leaves: on the outline (to 3 um), in the clamp
                assert p.exits.nearest(w[-1:])[1][0] <= 3e-6 and scene.clamp_distance(w[-1:])[0] <= 3e-6, name
                assert p.walls.inside(w[-1:])[0]
            dense = _dense(w, 0.2 * spacing)
            held = np.linalg.norm(dense - w[-1], axis=1) >= lead
            assert points_in_polygon(dense[held], scene.body.outline).all(), name
            for hole in scene.body.holes:
                assert not points_in_polygon(dense, hole).any(), name
            loops = (scene.body.outline, *scene.body.holes)
            clearance = min(_distance_to_polygon(dense[held], q).min() for q in loops)
            assert clearance >= spacing * (1 - 1e-9), (name, clearance / spacing)
            assert 0.25 * L - 1e-9 <= t["length"] <= 0.9 * L + 1e-9
            assert t["length"] == pytest.approx(np.linalg.norm(np.diff(w, axis=0), axis=1).sum(), rel=1e-12)
            d = np.diff(w, axis=0)
            ang = np.arctan2(d[:, 1], d[:, 0])
            turns = np.abs((np.diff(ang) + np.pi) % (2 * np.pi) - np.pi)
            assert turns.max() < math.radians(30) and turns.sum() <= math.pi + 1e-9  # no kinks
            clamped = p.mesh.nodes[p.fixed]
            far = np.linalg.norm(clamped - w[0], axis=1).min()  # the anchor is away from the clamps
            assert far >= np.linalg.norm(clamped - w[-1], axis=1).min() and far >= 0.15 * L
            assert 0.05 <= t["contraction_ratio"] <= 0.10
            assert t["contraction"] == pytest.approx(t["contraction_ratio"] * t["length"], rel=1e-12)
            assert t["tension"] > 0
            paths.append(dense)
        for i in range(len(paths)):  # no two tendons touch (at least one spacing apart)
            for j in range(i):
                gap = np.linalg.norm(paths[i][:, None] - paths[j][None], axis=-1).min()
                assert gap >= 0.85 * spacing, (name, gap / spacing)
        assert layout["planted_length"] == pytest.approx(sum(t["length"] for t in layout["tendons"]))


@pytest.mark.parametrize("args,message", [
    ((0, 1), "number of tendons must be 1..5"),
    ((6, 1), "number of tendons must be 1..5"),
    ((2, -1), "seed must be an integer >= 0"),
])
def test_plant_rejects_bad_arguments(args, message):
    with pytest.raises(InputError, match=message):
        plant("finger", *args)


THIN = """
name = "thin"
[body]
outline = [[0, 0], [0.1, 0], [0.1, 0.005], [0, 0.005]]
[[fixed]]
box = [[-0.001, -0.001], [0.001, 0.006]]
[[targets]]
point = [0.1, 0.0025]
goal = [0.1, 0.0025]
"""


def test_cli_writes_both_files_that_load(cli, tmp_path):
    out = tmp_path / "suite"
    r = cli("planted", "gripper", "--tendons", 2, "--seed", 3, "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    name = "gripper_planted_2t_s3"
    assert summary["name"] == name and summary["tendons"] == 2
    assert sorted(p.name for p in out.iterdir()) == [f"{name}.json", f"{name}.toml"]
    scene = load_scene(out / f"{name}.toml")
    assert scene.name == name
    layout = json.loads((out / f"{name}.json").read_text())
    assert layout["name"] == name and len(layout["tendons"]) == 2
    assert summary["max_target_displacement"] == layout["pose"]["max_target_displacement"]
    text, lay = plant("gripper", 2, 3)  # another process, the same bytes
    assert (out / f"{name}.toml").read_text() == text
    assert (out / f"{name}.json").read_text() == layout_json(lay)
    r = cli("planted", "finger", "--tendons", 1, "--seed", 2, cwd=tmp_path)  # default --out .
    assert r.returncode == 0 and len(r.stdout.strip().splitlines()) == 1, r.stderr
    assert {p.name for p in tmp_path.glob("finger_planted_1t_s2.*")} == {"finger_planted_1t_s2.toml",
                                                                        "finger_planted_1t_s2.json"}


@pytest.mark.parametrize("args,message", [
    (["nope"], "unknown scene 'nope'"),
    (["t_shape", "--tendons", "0"], "--tendons must be 1..5"),
    (["t_shape", "--tendons", "6"], "--tendons must be 1..5"),
    (["t_shape", "--level", "0"], "--level must be >= 1"),
    (["thin.toml"], "no tendon fits"),
])
def test_cli_bad_input_gives_one_line_and_writes_nothing(cli, tmp_path, args, message):
    (tmp_path / "thin.toml").write_text(THIN)
    r = cli("planted", *args, "--out", tmp_path / "out", cwd=tmp_path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tendon-taichi: error:") and message in lines[0], r.stderr
    assert "Traceback" not in r.stderr and r.stdout == ""
    assert not (tmp_path / "out").exists()


def test_checked_in_suite_loads():
    suite = tomllib.loads((SUITE / "suite.toml").read_text())
    cases = suite["cases"]
    assert len(cases) >= 12 and {c["scene"] for c in cases} == set(SCENES)
    assert sum((SUITE / f).stat().st_size for f in [p.name for p in SUITE.iterdir()]) < 200_000
    assert sum(c.get("poses", 1) == 1 for c in cases) >= 12 and any(c.get("poses", 1) > 1 for c in cases)
    for c in cases:
        poses = c.get("poses", 1)
        name = f"{c['scene']}_planted_{c['tendons']}t_s{c['seed']}" + (f"_{poses}p" if poses > 1 else "")
        scene = load_scene(SUITE / f"{name}.toml")
        layout = json.loads((SUITE / f"{name}.json").read_text())
        assert scene.name == layout["name"] == name
        assert layout["scene"] == c["scene"] and len(layout["tendons"]) == c["tendons"]
        assert layout["level"] == suite["level"]
        assert len(scene.poses) == poses and len(layout.get("poses", [0])) == poses
        assert len(scene.targets) == poses * len(load_scene(c["scene"]).targets)


def test_checked_in_case_regenerates():
    c = {"scene": "snake", "tendons": 2, "seed": 2}
    name = f"{c['scene']}_planted_{c['tendons']}t_s{c['seed']}"
    text, layout = plant(c["scene"], c["tendons"], c["seed"], settings=PlantSettings(exit="inside"))  # as the suite
    stored = json.loads((SUITE / f"{name}.json").read_text())
    for a, b in zip(layout["tendons"], stored["tendons"]):
        assert np.allclose(a["waypoints"], b["waypoints"], atol=1e-9, rtol=0)
    L = layout["pose"]["body_size"]
    goals = [t.goal for t in load_scene(SUITE / f"{name}.toml").targets]
    assert np.allclose(goals, [t["goal"] for t in layout["targets"]], atol=1e-9 * L, rtol=0)
