"""Generated scenes (bodies nobody tuned for): drawn from a seed and only from it,
every family a valid body with its holes inside, a clamp on one side that holds
some of its outline, and 2-4 targets on it far from the clamp; a case plants
1-3 tendons whose goals the scene carries; planted-bench runs them, and bad
flags are one line."""

import subprocess
import sys

import numpy as np
import pytest
import shapely

from tendon_taichi.body.scene import parse_scene
from tendon_taichi.planted.shapes import CLAMPED, SHAPES, generated_case, generated_scene


def test_the_same_seed_draws_the_same_scene_and_another_another():
    a, b = generated_scene(7), generated_scene(7)
    assert a.source == b.source
    assert generated_scene(8).source != a.source and generated_scene(7, attempt=1).source != a.source


@pytest.mark.parametrize("seed", range(2 * len(SHAPES)))
def test_every_family_draws_a_body_with_a_clamp_and_far_targets(seed):
    scene = generated_scene(seed)
    assert scene.name.endswith(SHAPES[seed % len(SHAPES)])
    body = shapely.Polygon(scene.body.outline, [np.asarray(h) for h in scene.body.holes])
    assert body.is_valid and body.area > 0
    outer = shapely.Polygon(scene.body.outline)
    extent = float(np.ptp(scene.body.outline, axis=0).max())
    assert 0.06 <= extent <= 0.125
    for h in scene.body.holes:  # inside, clear of the outline
        assert outer.exterior.distance(shapely.Polygon(h)) > 0.05 * extent
    (fixed,) = scene.fixed
    held = shapely.box(*fixed.lo, *fixed.hi)
    assert outer.exterior.intersection(held).length >= CLAMPED * extent * (1 - 1e-6)
    points = np.array([t.point for t in scene.targets])
    assert 2 <= len(points) <= 4
    d = shapely.distance(shapely.points(points), held)
    assert d.min() > 0 and np.all(body.contains(shapely.points(points)))
    assert min(np.linalg.norm(p - q) for i, p in enumerate(points) for q in points[i + 1:]) > 0.05 * extent


@pytest.mark.parametrize("seed", [1, 8])
def test_a_generated_case_plants_tendons_whose_goals_the_scene_carries(seed):
    text, layout = generated_case(seed)
    assert (text, layout) == generated_case(seed)  # byte for byte
    scene = parse_scene(text, origin=layout["name"])
    assert 1 <= layout["n_tendons"] == len(layout["tendons"]) <= 3
    goals = [np.array([t.goal for t in p.targets]) for p in scene.poses]
    assert len(goals) == (len(layout["poses"]) if "poses" in layout else 1)
    rest = np.array([t.point for t in scene.poses[0].targets])
    assert max(np.linalg.norm(g - rest, axis=1).max() for g in goals) >= 0.02 * layout["pose"]["body_size"]


@pytest.mark.parametrize("args, says", [
    (["benchmarks/planted", "--generated", "2"], "give a suite folder or --generated N, not both"),
    (["--generated", "0"], "--generated must be 1..1000 (got 0)"),
    (["--generated", "1", "--seed", "-1"], "--seed must be >= 0 (got -1)"),
])
def test_bad_generated_flags_are_one_line(tmp_path, args, says):
    r = subprocess.run([sys.executable, "-m", "tendon_taichi", "planted-bench", *args, "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.strip() == f"tendon-taichi: error: {says}"
    assert not (tmp_path / "o").exists()
