"""Routes kept clear of the walls by a constrained fit (nothing
dropped silently): a strand along a wall with room for a channel is routed,
moved about as much as it lacks; a body too narrow for the clearance gives a
flagged route that keeps the most the body allows (known here in closed form:
half the width of a strip or of a neck); over random bodies and routes, every
route comes back, and what it says it keeps is what it keeps."""

import numpy as np
import pytest
import shapely

from tendon_taichi.body.geometry import PolygonWalls
from tendon_taichi.extract.clearance import clear_route, held_clearance, keep_clear
from tendon_taichi.extract.routes import fit_route


def plate_with_hole() -> tuple[PolygonWalls, float]:
    """A 10 x 3 cm plate with a round hole of 6 mm radius (issue 73's case), and its size L."""
    t = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    hole = np.c_[0.05 + 0.006 * np.cos(t), 0.012 + 0.006 * np.sin(t)][::-1]
    return PolygonWalls.from_outline(np.array([[0, 0], [0.1, 0], [0.1, 0.03], [0, 0.03]]), [hole]), float(np.hypot(0.1, 0.03))


def test_a_strand_along_a_wall_with_room_for_a_channel_is_routed():
    """A strand 1 mm under the top edge, from the clamped edge to the tip, with 9 mm
    of material beside it: the old push-and-refit gave up on it and the tendon was
    lost; the fit keeps the full clearance and moves the route by about what it
    lacked (not round to somewhere else)."""
    walls, size = plate_with_hole()
    c = 0.02 * size
    route = fit_route(np.array([[0.002, 0.01], [0.01, 0.029], [0.05, 0.029], [0.098, 0.029]]), size)
    lack = c - walls.distance(route.waypoints).min()
    assert lack > 0.5 * c
    out = clear_route(route, walls, c)
    assert out.kept_clearance is None and held_clearance(out, c) == c
    assert walls.polyline_distance(out.waypoints) >= c * (1 - 1e-6)
    assert keep_clear(route, walls, c) is not None
    # moved off the wall by about what it lacked: no waypoint further from where the route ran
    ran = shapely.LineString(route.waypoints)
    moved = shapely.distance(shapely.points(out.waypoints), ran).max()
    assert moved <= lack + 0.25 * c


def test_a_route_that_keeps_the_clearance_comes_back_as_it_was():
    walls, size = plate_with_hole()
    route = fit_route(np.array([[0.01, 0.022], [0.05, 0.024], [0.09, 0.022]]), size)
    assert clear_route(route, walls, 0.02 * size) is route


@pytest.mark.parametrize("width", [0.003, 0.0036])
def test_a_strip_too_narrow_for_the_clearance_gives_a_flagged_route_down_its_middle(width):
    """A strip narrower than twice the clearance: the route comes back, flagged with
    the clearance it keeps, which is what its polyline keeps and within 1 % of the
    most any route can (half the width)."""
    walls = PolygonWalls.from_outline(np.array([[0, 0], [0.1, 0], [0.1, width], [0, width]]), [])
    c = 0.002
    route = fit_route(np.array([[0.01, 0.2 * width], [0.05, 0.6 * width], [0.09, 0.75 * width]]), 0.1)
    out = clear_route(route, walls, c)
    assert out.kept_clearance is not None
    assert out.kept_clearance == pytest.approx(walls.polyline_distance(out.waypoints), rel=1e-12)
    assert 0.99 * width / 2 <= out.kept_clearance <= width / 2 * (1 + 1e-9)
    assert keep_clear(route, walls, c) is None
    assert held_clearance(out, c) == out.kept_clearance
    # it still runs the strip's length
    assert out.waypoints[0, 0] < 0.015 and out.waypoints[-1, 0] > 0.085


def test_a_route_through_a_narrow_neck_keeps_its_way_and_half_the_neck():
    """Two wide lobes joined by a 4 mm neck, the asked clearance 2.15 mm: the route
    stays on its way through the neck (a fit may not run off to one lobe, which
    would keep the clearance) and keeps about 2 mm, flagged."""
    outline = np.array([[0, 0], [0.04, 0], [0.04, 0.018], [0.06, 0.018], [0.06, 0], [0.1, 0], [0.1, 0.04],
                        [0.06, 0.04], [0.06, 0.022], [0.04, 0.022], [0.04, 0.04], [0, 0.04]])
    walls = PolygonWalls.from_outline(outline, [])
    size = float(np.hypot(0.1, 0.04))
    c = 0.02 * size
    route = fit_route(np.array([[0.01, 0.03], [0.05, 0.0205], [0.09, 0.01]]), size)
    out = clear_route(route, walls, c)
    assert out.waypoints[0, 0] < 0.03 and out.waypoints[-1, 0] > 0.07
    assert out.kept_clearance == pytest.approx(walls.polyline_distance(out.waypoints), rel=1e-12)
    assert 0.99 * 0.002 <= out.kept_clearance <= 0.002 * (1 + 1e-9)


def _random_body(rng) -> PolygonWalls:
    """A star-shaped outline with wavy radius, sometimes a hole: shapes unlike the suite's."""
    k = 48
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    radius = 0.03 * (1 + 0.35 * np.sin(rng.integers(2, 6) * t + rng.uniform(0, 6)) + 0.1 * rng.uniform(-1, 1, k))
    outline = np.c_[radius * np.cos(t), radius * np.sin(t)]
    holes = []
    if rng.uniform() < 0.5:
        s = np.linspace(0, 2 * np.pi, 24, endpoint=False)[::-1]
        r = 0.006
        holes.append(np.c_[rng.uniform(-0.004, 0.004) + r * np.cos(s), rng.uniform(-0.004, 0.004) + r * np.sin(s)])
    return PolygonWalls.from_outline(outline, holes)


def test_every_route_comes_back_and_keeps_what_it_says_over_random_bodies():
    """Random bodies and random smooth routes inside them, at a clearance of 3 % of
    the body's size: no route is lost; an unflagged one keeps the clearance along
    its whole polyline, a flagged one keeps exactly what it says, more than 0."""
    rng = np.random.default_rng(73)
    flagged = kept = 0
    for _ in range(12):
        walls = _random_body(rng)
        size = 0.08
        c = 0.03 * size
        x0, y0, x1, y1 = walls.polygon.bounds
        while True:  # a route inside the body (as every extracted strand is)
            route = fit_route(rng.uniform([x0, y0], [x1, y1], (4, 2)), size)
            if walls.polyline_distance(route.waypoints) > 0.1 * c and route.length > 0.3 * size:
                break
        out = clear_route(route, walls, c)
        d = walls.polyline_distance(out.waypoints)
        if out.kept_clearance is None:
            kept += 1
            assert d >= c * (1 - 1e-6)
        else:
            flagged += 1
            assert out.kept_clearance == pytest.approx(d, rel=1e-12) and 0 < d < c
    assert kept >= 6  # most of them find room


def test_design_warns_of_each_recommended_tendon_that_keeps_less_than_the_clearance():
    from tendon_taichi.apps.design import clearance_warnings

    summary = {"clearance": 0.02, "body_size": 0.1,
               "recommended": {"tendons": [{"clearance_min": 0.002}, {"clearance_min": 0.0015}]}}
    (warning,) = clearance_warnings(summary)
    assert warning.startswith("tendon 2 keeps 1.50 mm") and "2.00 mm clearance asked" in warning
