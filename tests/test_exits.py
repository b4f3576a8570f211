"""Tendons that leave the body (``docs/method.md``, exits): the scene key and its
bad values, the exit set of a clamp, a route carried out of the body (straight,
and around a hole that blocks the straight way), the lifted walls and the route
optimization's clearance Jacobian against finite differences, and ``design``
with ``exit = "clamp"`` end to end: every recommended tendon leaves inside a
clamped box, its channel keeps the clearance up to there, its capstan factor
counts the bends of the run out (an independent computation from the exported
waypoints), and the exported as-built equilibrium balances forces with tensions
that follow the capstan law from the exit."""

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import shapely

from reference import as_built_residual
from tendon_taichi.body.exits import ExitWalls
from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import parse_scene
from tendon_taichi.errors import SceneError
from tendon_taichi.extract.exits import exit_route
from tendon_taichi.extract.routes import fit_route
from tendon_taichi.extract.routing import RouteObjective, RouteSettings
from tendon_taichi.planted.plant import with_exit

PLATE = """
name = "plate"
[body]
outline = [[0.0, 0.0], [0.10, 0.0], [0.10, 0.04], [0.0, 0.04]]
{holes}
max_triangle_area = 1.5e-5
[fibers]
spacing = 0.005
[[fixed]]
box = [[-0.001, -0.001], [0.004, 0.041]]
[[targets]]
point = [0.10, 0.02]
goal = [0.095, 0.035]
[tendons]
exit = "{exit}"
"""
HOLE = "holes = [[[0.022, 0.008], [0.034, 0.008], [0.034, 0.032], [0.022, 0.032]]]"
SVG = "{http://www.w3.org/2000/svg}"


def _plate(exit="clamp", holes=""):
    return build_problem(parse_scene(PLATE.format(exit=exit, holes=holes)), 1)


def test_the_exit_key_defaults_to_inside_and_bad_values_are_one_line():
    assert parse_scene(PLATE.format(exit="inside", holes="")).tendons.exit == "inside"
    assert parse_scene(PLATE.replace('exit = "{exit}"', "").format(holes="")).tendons.exit == "inside"
    with pytest.raises(SceneError, match="tendons.exit must be one of 'inside', 'clamp', 'surface'"):
        parse_scene(PLATE.format(exit="base", holes=""))
    away = PLATE.replace("box = [[-0.001, -0.001], [0.004, 0.041]]", "box = [[0.04, 0.015], [0.05, 0.025]]")
    with pytest.raises(SceneError, match="no \\[\\[fixed\\]\\] box meets the outline"):
        build_problem(parse_scene(away.format(exit="clamp", holes="")), 1)
    assert build_problem(parse_scene(away.format(exit="inside", holes="")), 1).exits is None


def test_a_clamp_exit_where_no_clamp_meets_the_outline_is_one_line_and_writes_nothing(cli, tmp_path):
    r = cli("design", "cross", "--exit", "clamp", "--out", "out", "--quiet", cwd=tmp_path)  # clamped in its middle
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        'tendon-taichi: error: builtin:cross: tendons.exit = "clamp" but no [[fixed]] box meets the outline']
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("tendons", ["", "[tendons]\nfriction = 0.2\n",
                                     "[tendons]\nexit = \"surface\"\nfriction = 0.2\n"])
def test_a_planted_scene_gets_its_exit_in_its_tendons_table(tendons):
    base = PLATE.replace('[tendons]\nexit = "{exit}"\n', "").format(holes="")
    text = with_exit(base + tendons + "[optimize]\nhomotopy = { k0 = 1.0 }\n", "clamp")
    scene = parse_scene(text)
    assert scene.tendons.exit == "clamp" and scene.optimize.homotopy.k0 == 1.0
    assert text.count("[tendons]") == 1 and text.count("exit =") == 1
    if "friction" in tendons:
        assert scene.tendons.friction == 0.2


def test_the_clamps_exit_set_is_its_stretch_of_the_outline_clear_of_the_corners():
    p = _plate()
    ex = p.exits
    h = p.scene.tendons.clearance * p.size
    pts = ex.segments.reshape(-1, 2)
    assert np.abs(p.walls.distance(pts)).max() <= 1e-12  # on the outline ...
    assert p.scene.clamp_distance(pts).max() == 0.0  # ... inside the clamped box
    corners = np.array([[0.0, 0.0], [0.0, 0.04]])
    assert np.linalg.norm(pts[:, None] - corners[None], axis=2).min() >= ex.zone - 1e-12 > 2 * h
    assert ex.segments[:, :, 0].max() == 0.0  # the left edge only: the clamp's bits of the top and bottom are corners
    surface = _plate("surface").exits
    assert len(surface.segments) == 4 and surface.zone == ex.zone


def test_a_route_is_carried_straight_out_through_the_clamp_from_its_nearer_end():
    p = _plate()
    h = p.scene.tendons.clearance * p.size
    r = fit_route(np.array([[0.08, 0.03], [0.05, 0.031], [0.02, 0.03]]), p.size)
    for given in (r, r.reversed()):
        out = exit_route(given, p, h)
        assert out.exits and out.kept_clearance is None
        assert np.allclose(out.control[0], [0.08, 0.03])  # the far end stays the anchor
        foot, d, _ = p.exits.nearest(out.control[-1:])
        assert d[0] <= 1e-12 and out.control[-1][0] == 0.0
        assert ExitWalls(p.walls, out.control[-1], h).kept(out.waypoints) >= h * (1 - 1e-6)
        assert np.allclose(out.waypoints[-1], out.tendon().exit)
    assert exit_route(r, _plate("inside"), h).exit is None


def test_a_route_whose_straight_way_out_is_blocked_goes_round_the_hole():
    p = _plate(holes=HOLE)
    h = p.scene.tendons.clearance * p.size
    r = fit_route(np.array([[0.09, 0.02], [0.06, 0.021], [0.045, 0.02]]), p.size)
    out = exit_route(r, p, h)
    assert out.exits and out.kept_clearance is None
    assert p.exits.nearest(out.control[-1:])[1][0] <= 1e-12
    hole = shapely.Polygon([[0.022, 0.008], [0.034, 0.008], [0.034, 0.032], [0.022, 0.032]])
    assert not shapely.LineString(out.waypoints).intersects(hole)
    assert ExitWalls(p.walls, out.control[-1], h).kept(out.waypoints) >= h * (1 - 1e-6)


def test_the_lifted_walls_gradient_matches_finite_differences():
    p = _plate()
    h = p.scene.tendons.clearance * p.size
    e = p.exits.segments[0].mean(axis=0)
    walls = ExitWalls(p.walls, e, h)
    rng = np.random.default_rng(3)
    pts = np.vstack([e + rng.uniform([0.0005, -0.003], [0.004, 0.003], (12, 2)),
                     rng.uniform([0.02, 0.005], [0.08, 0.035], (6, 2))])
    d, g = walls.distance_gradient(pts)
    eps = 1e-8
    for k in range(2):
        step = np.zeros(2)
        step[k] = eps
        fd = (walls.distance(pts + step) - walls.distance(pts - step)) / (2 * eps)
        assert np.allclose(g[:, k], fd, atol=1e-6)
    assert (walls.lift(pts)[0][:12] > 0).any() and (walls.lift(pts)[0][12:] == 0).all()


def test_the_route_clearance_jacobian_with_an_exit_matches_finite_differences():
    p = _plate()
    h = p.scene.tendons.clearance * p.size
    route = exit_route(fit_route(np.array([[0.08, 0.03], [0.05, 0.026], [0.02, 0.02]]), p.size), p, h)
    obj = RouteObjective(p, [route], p.scene.optimize, RouteSettings(friction=0.1, clearance=h))
    z = obj.pack([route], np.zeros((1, 1)))
    values, J = obj.clearance(z)
    eps = 1e-7
    for j in range(obj.n_control):
        dz = np.zeros_like(z)
        dz[j] = eps
        fd = (obj.clearance(z + dz, jacobian=False)[0] - obj.clearance(z - dz, jacobian=False)[0]) / (2 * eps)
        assert np.allclose(J[:, j], fd, atol=2e-5), j
    (eq,) = obj.on_exits()
    assert abs(eq["fun"](z)[0]) <= 1e-12  # the exit is on its segment
    lo, hi = obj.bounds().lb[obj.n_control - 2:obj.n_control], obj.bounds().ub[obj.n_control - 2:obj.n_control]
    assert np.all(lo <= z[obj.n_control - 2:obj.n_control] + 1e-15)
    assert np.all(z[obj.n_control - 2:obj.n_control] <= hi + 1e-15)


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    from conftest import run_cli

    d = tmp_path_factory.mktemp("exits")
    # clamped on the lower half of its edge only: a tendon along the top bends down to leave
    scene = PLATE.format(exit="clamp", holes="").replace("[tendons]", "[tendons]\nfriction = 0.2")
    (d / "plate.toml").write_text(scene.replace("[0.004, 0.041]", "[0.004, 0.02]"))
    r = run_cli("design", "plate.toml", "--out", "out", "--stage-iterations", "25", "--k-min", "0.1",
                "--extractors", "strands", "path_cover", "--refine", "1", "--json", "out.json", cwd=d)
    assert r.returncode == 0, r.stderr
    return d


def test_every_recommended_tendon_leaves_inside_the_clamp_with_its_channel_clear(designed):
    summary = json.loads((designed / "out" / "design.json").read_text())
    scene = parse_scene((designed / "plate.toml").read_text())
    p = build_problem(scene, 1)
    h = scene.tendons.clearance * summary["body_size"]
    assert summary["exit"] == "clamp" and summary["recommended"]["count"] >= 1
    turnings = []
    for t in summary["recommended"]["tendons"]:
        w = np.array(t["waypoints"])
        assert t["exit"] == t["pull_end"] == w[-1].tolist()
        assert t["clamp_distance"] == 0.0 and scene.clamp_distance(w[-1:])[0] == 0.0
        assert abs(p.walls.distance(w[-1:])[0]) <= 1e-9 * p.size  # on the outline: where it leaves
        assert t["clearance_min"] >= h * (1 - 1e-3)
        assert ExitWalls(p.walls, w[-1], h).kept(w) >= h * (1 - 1e-3)
        d = np.diff(w, axis=0)  # the capstan factor counts every bend, the run out included
        turning = np.abs(np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], (d[:-1] * d[1:]).sum(1))).sum()
        assert t["turning"] == pytest.approx(turning, rel=1e-6, abs=1e-6)
        assert t["capstan"] == pytest.approx(np.exp(-0.2 * turning), rel=1e-6)
        turnings.append(turning)
    assert max(turnings) > 0.1  # the run down to the clamp bends, and that bend is counted
    root = ET.parse(designed / "out" / "design.svg").getroot()
    classes = [e.get("class") for e in root.iter(f"{SVG}path")]
    assert classes.count("exit-set") == 1 and classes.count("exit") == summary["recommended"]["count"]


def test_the_as_built_equilibrium_with_exits_balances_forces_and_follows_the_capstan_law(designed):
    """From the export alone (``reference.as_built_residual``): the tensions fall from
    the exit by exp(-mu Theta), the run out's bends included, and balance the body."""
    assert as_built_residual(np.load(designed / "out" / "as_built.npz")) <= 1e-7
