"""Smooth routes off the lattice: a zig-zag becomes the line it approximates,
splines become exact Bezier paths, the clearance is held, a join across a
body with a hole is smooth or not made, and the route gradient (control
points, anchor and pull end, contractions) matches central differences - with
friction and the bend penalty active - as does the clearance constraint's
Jacobian, and route optimization ends at routes that keep the clearance."""

import numpy as np
import pytest

from tendon_taichi import build_problem, load_scene, parse_scene
from tendon_taichi.body.spline import basis, bezier_pieces
from tendon_taichi.extract.context import Context
from tendon_taichi.extract.protocol import turn_angles
from tendon_taichi.extract.clearance import keep_clear
from tendon_taichi.extract.routes import Route, fit_route, join_routes, sample_count
from tendon_taichi.extract.routing import MAX_BEND, RouteObjective, RouteSettings, sharp_bends, turning

RING = """
name = "ring"
[body]
outline = [[-0.05, 0.0], [0.05, 0.0], [0.05, 0.08], [-0.05, 0.08]]
holes = [[[-0.02, 0.025], [0.02, 0.025], [0.02, 0.055], [-0.02, 0.055]]]
[[fixed]]
box = [[-0.06, -0.001], [0.06, 0.004]]
[[targets]]
point = [0.0, 0.08]
goal = [0.01, 0.075]
"""


def test_a_lattice_zigzag_becomes_the_line_it_follows():
    """45-degree steps either side of a straight line: the fitted route runs along
    it (within one step), about as long as the line, with no turn to speak of."""
    s = 0.005
    steps = np.array([[i * s, (i % 2) * s] for i in range(13)])
    r = fit_route(steps, size=0.1)
    assert np.allclose(r.control[[0, -1]], steps[[0, -1]])  # anchor and pull end held
    w = r.waypoints
    chord = np.linalg.norm(steps[-1] - steps[0])
    assert r.length <= 1.02 * chord < np.linalg.norm(np.diff(steps, axis=0), axis=1).sum() / 1.35
    assert np.abs(w[:, 1]).max() <= s
    assert np.degrees(turn_angles(w)).max() < 10.0 and np.degrees(turn_angles(w)).sum() < 60.0
    assert turn_angles(steps).sum() > 10 * np.pi / 2  # the zig-zag itself turned 90 degrees at every step


def test_spline_samples_and_bezier_pieces_are_the_same_curve():
    rng = np.random.default_rng(3)
    for m in (2, 3, 4, 7):
        control = rng.standard_normal((m, 2))
        pieces = bezier_pieces(control)
        B = basis(9, m)
        assert np.allclose(B.sum(axis=1), 1.0) and np.allclose(B @ control, basis(9, m) @ control)
        assert np.allclose(pieces[0, 0], control[0]) and np.allclose(pieces[-1, -1], control[-1])
        # the pieces join continuously and, being uniform, sample the same points as the basis
        assert np.allclose(pieces[1:, 0], pieces[:-1, -1])
        u = np.linspace(0, 1, len(pieces) + 1)
        assert np.allclose(basis(len(u), m) @ control, np.vstack([pieces[:, 0], pieces[-1:, -1]]))


def test_clearance_is_held():
    p = build_problem(parse_scene(RING), 1)
    c = 0.02 * p.size
    # along the outer wall, into the hole, and head-on into the bottom wall
    for path in ([[-0.045, 0.0785], [0.0, 0.0790], [0.045, 0.0785]],
                 [[-0.04, 0.012], [-0.018, 0.03], [-0.04, 0.05]],
                 [[0.035, 0.06], [0.035, 0.03], [0.035, 0.0]]):
        assert p.walls.distance(fit_route(np.array(path), p.size).waypoints).min() < c
        r = keep_clear(fit_route(np.array(path), p.size), p.walls, c)
        assert r is not None
        assert p.walls.distance(r.waypoints).min() >= c * (1 - 1e-6)
        assert p.walls.polyline_distance(r.waypoints) >= c * (1 - 1e-6)
        assert np.degrees(turn_angles(r.waypoints)).max() < 30.0
    # where the body is narrower than twice the clearance, no route fits
    assert keep_clear(fit_route(np.array([[-0.04, 0.03], [-0.04, 0.05]]), p.size), p.walls, 0.2 * p.size) is None



def test_clearance_is_held_between_the_points_it_looks_at():
    """A wall's corner pointing into the body, passed by a straight route between
    two of the points the push looks at: the route keeps the clearance along its
    whole polyline, not only at those points (with four points per segment alone
    it came to 0.997 c of the corner)."""
    from tendon_taichi.body.geometry import PolygonWalls

    walls = PolygonWalls.from_outline(np.array([[0, 0], [0.1, 0], [0.1, 0.1], [0.06, 0.1], [0.047, 0.06], [0.04, 0.1],
                                         [0, 0.1]]), [])
    size = 0.1 * np.sqrt(2)
    c = 0.02 * size
    r = keep_clear(fit_route(np.array([[0.01, 0.05901], [0.0875, 0.05901]]), size), walls, c)
    assert r is not None and walls.polyline_distance(r.waypoints) >= c * (1 - 1e-6)

def test_a_join_across_a_body_with_a_hole_is_smooth_or_not_made():
    """Two routes either side of a hole, ends facing across it: the join goes round
    the hole, keeps the clearance and has no kink - or it is not made."""
    p = build_problem(parse_scene(RING), 1)
    c = 0.02 * p.size
    left = keep_clear(fit_route(np.array([[-0.035, 0.01], [-0.035, 0.04], [-0.03, 0.07]]), p.size), p.walls, c)
    right = keep_clear(fit_route(np.array([[0.03, 0.012], [0.035, 0.04], [0.035, 0.07]]), p.size), p.walls, c)
    made = 0
    for a, b in ((left, right), (left.reversed(), right), (left, right.reversed()),
                 (left.reversed(), right.reversed())):
        joined = keep_clear(join_routes(a, b, p.size), p.walls, c)
        if joined is None:
            continue
        made += 1
        w = joined.waypoints
        assert p.walls.distance(w).min() >= c * (1 - 1e-6)
        assert p.walls.polyline_distance(w) > 0  # never through the hole
        assert np.degrees(turn_angles(w)).max() < 30.0
    assert made >= 1


def test_turning_and_bend_penalties_match_finite_differences():
    rng = np.random.default_rng(1)
    pts = np.cumsum(rng.uniform(0.5, 1.0, (9, 2)) * [[1, 0.8]], axis=0) * 0.01
    pts[4] += [0.0, 0.01]  # one sharp bend
    for fn in (turning, lambda q: sharp_bends(q, MAX_BEND)):
        f, g = fn(pts)
        h = 1e-7
        fd = np.zeros_like(pts)
        for i in range(len(pts)):
            for d in range(2):
                e = np.zeros_like(pts)
                e[i, d] = h
                fd[i, d] = (fn(pts + e)[0] - fn(pts - e)[0]) / (2 * h)
        assert np.abs(g - fd).max() <= 1e-6 * np.abs(fd).max()
    assert sharp_bends(pts, MAX_BEND)[0] > 0


def test_route_gradient_matches_central_differences():
    """d O / d (control points, anchor and pull end included, and contractions) of
    the route objective - the as-built pose with friction, the friction price and
    the bend penalty - against central differences; and the Jacobian of the
    clearance constraint (a pull end too near the wall: it is violated there)."""
    p = build_problem(load_scene("t_shape"), 1)
    L = p.size
    t = np.linspace(0, 1, 12)
    paths = [np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1),
             np.stack([0.004 * np.sin(3 * t), 0.01 + 0.05 * t], 1)]
    routes = [fit_route(q, L, 0.4) for q in paths]
    routes[1].control[2:4] += [[0.015, 0.0], [-0.015, 0.0]]  # a sharp bend (the penalty is on) ...
    routes[0].control[-1] = [0.045, 0.0785]  # ... and a pull end too near the wall (the constraint is violated)
    rs = RouteSettings(friction=0.3, clearance=0.02 * L, friction_price=1e-4)
    obj = RouteObjective(p, routes, p.scene.optimize, rs, "direct")
    obj.eval_tol = 1e-14
    assert sum(sharp_bends(r.waypoints)[0] for r in routes) > 0
    assert p.walls.distance(routes[0].waypoints).min() < rs.clearance
    z = obj.pack(routes, np.array([[0.08, 0.05]]))
    f, g = obj.evaluate(z)
    n = obj.n_control
    ends = [0, 1, n // 2 - 2, n // 2 - 1, n // 2, n - 2, n - 1]  # anchors and pull ends
    inner = [4, 7, n // 2 + 5]
    for j in ends + inner + [n, n + 1]:
        h = 1e-6
        e = np.zeros_like(z)
        e[j] = h
        fd = (obj.evaluate(z + e)[0] - obj.evaluate(z - e)[0]) / (2 * h)
        assert g[j] == pytest.approx(fd, rel=2e-5, abs=1e-9 * np.abs(g).max()), j
    c, J = obj.clearance(z)
    assert c.min() < 0.0 and np.array_equal(c, obj.clearance(z, jacobian=False)[0])
    h = 1e-7
    for j in range(n):
        e = np.zeros_like(z)
        e[j] = h
        ahead, back = ((obj.clearance(z + s * e, jacobian=False)[0] - c) / (s * h) for s in (1, -1))
        smooth = np.abs(ahead - back) <= 1e-6  # not on the walls' medial axis (route 1 starts on it)
        assert smooth.sum() >= len(c) - 1
        assert np.abs(J[smooth, j] - (ahead + back)[smooth] / 2).max() <= 1e-6, j
    assert not J[:, n:].any()  # the contractions move no waypoint


def test_a_straight_run_in_one_triangle_has_the_gradient_central_differences_see(monkeypatch):
    """A straight route whose waypoints 8-10 lie in one triangle: they stay in line
    under its affine deformation, so the joint at waypoint 9 turns by round-off,
    where |theta| has its kink. Moving a control point across the route turns that
    joint either way alike, and the gradient is what central differences see; with
    the sign of the round-off in its place (``STRAIGHT`` 0) it is not."""
    from tendon_taichi.physics import capstan

    p = build_problem(load_scene("t_shape"), 1)
    t = np.linspace(0, 1, 12)
    routes = [fit_route(np.stack([0.002 + 0.032 * t, 0.074 + 0.0 * t], 1), p.size, 0.4)]
    obj = RouteObjective(p, routes, p.scene.optimize, RouteSettings(friction=0.3, clearance=0.02 * p.size), "direct")
    obj.eval_tol = 1e-14
    z = obj.pack(routes, np.array([[0.08]]))
    across = np.arange(3, obj.n_control - 2, 2)  # the y of the interior control points

    h, fd = 1e-6, []
    for j in across:
        e = np.zeros_like(z)
        e[j] = h
        fd.append((obj.evaluate(z + e)[0] - obj.evaluate(z - e)[0]) / (2 * h))
    fd = np.array(fd)

    def gradient(straight):
        monkeypatch.setattr(capstan, "STRAIGHT", straight)
        g = obj.evaluate(z)[1]
        model = obj.ik.poses[0].model
        assert np.all(model.cables.points.tri[8:11] == model.cables.points.tri[9])
        theta = model.capstan.state(model.cables.points.positions(p.mesh.triangles, model.positions())).theta
        assert abs(theta[8]) < 1e-13 and np.abs(np.delete(theta[:-1], 8)).min() > 1e-5
        return g[across]

    assert np.abs(gradient(capstan.STRAIGHT) - fd).max() <= 2e-5 * np.abs(fd).max()
    assert np.abs(gradient(0.0) - fd).max() > 1e-3 * np.abs(fd).max()


def test_a_point_valued_alone_leaves_the_next_gradient_exact(monkeypatch):
    """The objective at a point without its gradient (a trial step SLSQP's line
    search rejects: no adjoint solve) leaves the next point's gradient what a new
    objective computes there, and it matches central differences; a gradient asked
    at a point other than the last one valued is that point's. Route optimization
    solves adjoints only at the points SLSQP asks the gradient of: fewer than the
    points it values."""
    from tendon_taichi.extract.routing import optimize_routes
    from tendon_taichi.optimizer.soft_ik import PoseSolve

    p = build_problem(load_scene("t_shape"), 1)
    t = np.linspace(0, 1, 12)
    route = fit_route(np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1), p.size, 0.4)
    rs = RouteSettings(friction=0.3, clearance=0.02 * p.size, iterations=15)

    def objective():
        obj = RouteObjective(p, [route], p.scene.optimize, rs, "direct")
        obj.eval_tol = 1e-14
        return obj

    obj, fresh = objective(), objective()
    z = obj.pack([route], np.array([[0.08]]))
    moved = z.copy()
    moved[4:8] += 0.01  # a trial step elsewhere, valued only
    obj.value(z)
    obj.value(moved)
    g = obj.gradient(z)  # not the last point valued: evaluated anew
    f_new, g_new = fresh.evaluate(z)
    assert obj.value(z) == pytest.approx(f_new, rel=1e-12)
    assert np.abs(g - g_new).max() <= 1e-9 * np.abs(g_new).max()
    for j in (0, 5, len(z) - 1):
        h = 1e-6
        e = np.zeros_like(z)
        e[j] = h
        fd = (fresh.evaluate(z + e)[0] - fresh.evaluate(z - e)[0]) / (2 * h)
        assert g[j] == pytest.approx(fd, rel=2e-5, abs=1e-9 * np.abs(g).max()), j

    adjoints = []
    solve = PoseSolve.adjoint
    monkeypatch.setattr(PoseSolve, "adjoint", lambda self, rhs: adjoints.append(1) or solve(self, rhs))
    res = optimize_routes(Context(p, None, p.scene.optimize, "direct"), [route], np.array([[0.08]]), rs)
    assert res.objective < 0.1 * res.objective_start
    assert 0 < len(adjoints) < res.evaluations


def test_route_optimization_keeps_the_clearance_where_the_best_route_would_not():
    """An arm route whose optimum with a clearance of 0.04 L lies against the wall:
    optimized with none, it passes nearer the wall than that; with it, it ends at the
    clearance (within CLEAR_TOL) and its objective still falls by 98 %."""
    from tendon_taichi.extract.routing import CLEAR_TOL, optimize_routes

    p = build_problem(load_scene("t_shape"), 1)
    t = np.linspace(0, 1, 12)
    route = fit_route(np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1), p.size, 0.4)
    c = 0.04 * p.size
    route = keep_clear(route, p.walls, c)
    ends = []
    for clearance in (0.0, c):
        rs = RouteSettings(friction=0.3, clearance=clearance, iterations=15)
        res = optimize_routes(Context(p, None, p.scene.optimize, "direct"), [route], np.array([[0.08]]), rs)
        assert res.objective < 0.02 * res.objective_start
        ends.append(p.walls.distance(res.routes[0].waypoints).min())
    assert ends[0] < 0.9 * c  # the constraint binds ...
    assert c * (1 - CLEAR_TOL) <= ends[1] <= c * (1 + 1e-3)  # ... and holds


def test_a_route_shrunk_to_a_point_is_a_step_too_far():
    """A trial step that puts every control point of a route on one point (the
    corner of their bounds) is refused at once - no robot with a tendon of no length
    is solved (its capstan factor would be 0 / 0) - and route optimization prices it
    as a failed equilibrium."""
    import warnings

    from tendon_taichi.errors import ConvergenceError
    from tendon_taichi.extract.routing import optimize_routes

    p = build_problem(load_scene("t_shape"), 1)
    t = np.linspace(0, 1, 12)
    route = fit_route(np.stack([0.004 * np.sin(3 * t), 0.01 + 0.05 * t], 1), p.size, 0.4)
    rs = RouteSettings(friction=0.1, clearance=0.02 * p.size)
    obj = RouteObjective(p, [route], p.scene.optimize, rs, "direct")
    point = route.with_control(np.tile(route.control[3], (len(route.control), 1)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no 0 / 0 on the way
        with pytest.raises(ConvergenceError, match="shrunk to a point"):
            obj.evaluate(obj.pack([point], np.array([[0.05]])))
        assert np.isfinite(obj.evaluate(obj.pack([route], np.array([[0.05]])))[0])
    res = optimize_routes(Context(p, None, p.scene.optimize, "direct"), [point], np.array([[0.05]]), rs)
    assert not np.isfinite(res.objective_start) or res.objective_start > 1.0


def test_routes_do_not_depend_on_the_mesh():
    """How many waypoints and control points a route has depends on its length and
    the body size, not on the resolution level."""
    pts = np.array([[0.0, 0.0], [0.03, 0.01], [0.06, 0.0]])
    a, b = fit_route(pts, 0.128), fit_route(pts, 0.128)
    assert a.samples == b.samples == sample_count(a.length, 0.128)
    assert np.array_equal(a.control, b.control)
    assert isinstance(a, Route)


def _arm_objective():
    """A one-route objective on t_shape at level 1 (with friction) and its start z0."""
    p = build_problem(load_scene("t_shape"), 1)
    t = np.linspace(0, 1, 12)
    routes = [fit_route(np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1), p.size, 0.4)]
    obj = RouteObjective(p, routes, p.scene.optimize, RouteSettings(friction=0.3, clearance=0.02 * p.size),
                         "direct")
    return p, obj, obj.pack(routes, np.array([[0.08]]))


def _as_a_new_robot(p, obj, z, start):
    """Whether the objective's last evaluation (at ``z``) is bit for bit that of a new
    robot of the same cables started from the equilibria ``start``; the new robot."""
    from tendon_taichi.optimizer.soft_ik import SoftIK

    ik = obj.ik
    fresh = SoftIK(p, p.scene.optimize, "direct", cables=ik.model.cables)
    fresh.eval_tol = ik.eval_tol
    for ps, x in zip(fresh.poses, start):
        ps.model.set_positions(x)
    f, g = fresh.evaluate(obj.unpack(z)[1].ravel())
    same = f == ik.last_value() and np.array_equal(g, ik._last[2])
    return same and all(np.array_equal(u, v) for u, v in zip(ik.adjoints, fresh.adjoints)), fresh


def test_a_route_moved_across_triangles_gives_what_a_new_robot_gives(monkeypatch):
    """Route optimization keeps its robot when a step moves waypoints into other
    triangles (the cables' incidences, the sparsity pattern and the capstan
    weights are rebuilt in place): the soft IK's objective, gradient and adjoints
    there are bit for bit those of a new robot of the same cables started from
    the same equilibria (which start Newton with a fresh factorization), where
    the step makes the pattern anew (no detached segments)."""
    from tendon_taichi.solve.direct import DirectSolver

    monkeypatch.setattr(DirectSolver, "chord_across_moves", False)
    monkeypatch.setattr(DirectSolver, "detached_max", 0)
    p, obj, z0 = _arm_objective()
    obj.evaluate(z0)
    ik, tri0, start = obj.ik, obj.ik.model.cables.points.tri.copy(), [x.copy() for x in obj.positions]
    z1 = z0.copy()
    z1[1:obj.n_control:2] -= 0.003 / p.size  # every control point 3 mm down
    obj.evaluate(z1)
    assert obj.ik is ik and not np.array_equal(ik.model.cables.points.tri, tri0)
    same, fresh = _as_a_new_robot(p, obj, z1, start)
    a, b = ik.poses[0].linear, fresh.poses[0].linear
    assert np.array_equal(a.indptr, b.indptr) and np.array_equal(a.indices, b.indices)
    assert same


def test_a_route_moved_back_reuses_its_earlier_pattern(monkeypatch):
    """A step back into the triangles of an earlier step takes that step's sparsity
    pattern and LDL^T analysis again (no new ones), and the evaluation there is bit
    for bit a new robot's of the same cables from the same equilibria (Newton
    started with a fresh factorization)."""
    from tendon_taichi.solve.direct import DirectSolver

    monkeypatch.setattr(DirectSolver, "chord_across_moves", False)
    monkeypatch.setattr(DirectSolver, "detached_max", 0)
    p, obj, z0 = _arm_objective()
    obj.evaluate(z0)
    linear = obj.ik.poses[0].linear
    first, ldl = linear.pattern, linear.ldl
    z1 = z0.copy()
    z1[1:obj.n_control:2] -= 0.003 / p.size
    obj.evaluate(z1)
    assert linear.pattern is not first
    start = [x.copy() for x in obj.positions]
    obj.evaluate(z0)
    assert linear.pattern is first and linear.ldl is ldl and ldl is not None
    assert _as_a_new_robot(p, obj, z0, start)[0]


def test_a_small_route_step_keeps_the_pattern_with_the_moved_segments_detached(monkeypatch):
    """A step that moves a few waypoints into other triangles keeps the sparsity
    pattern and its analysis (no new ones): the segments whose entries it lacks
    are detached (at most ``detached_max``), and the Hessian assembled with them
    is a new robot's to round-off, its factorization's solves agree to 1e-10, and
    the step's objective and gradient are those of a new robot of the same cables
    solved from the same equilibria, to the evaluation's tolerance."""
    from tendon_taichi.optimizer.soft_ik import SoftIK
    from tendon_taichi.solve.direct import DirectSolver

    monkeypatch.setattr(DirectSolver, "chord_across_moves", False)
    p, obj, z0 = _arm_objective()
    obj.evaluate(z0)
    linear = obj.ik.poses[0].linear
    first, ldl = linear.pattern, linear.ldl
    start = [x.copy() for x in obj.positions]
    z1 = z0.copy()
    z1[5] -= 0.001 / p.size  # the third control point 1 mm down
    obj.evaluate(z1)
    assert linear.pattern is first and linear.ldl is ldl
    assert 0 < len(linear.detached) <= DirectSolver.detached_max
    m = obj.ik.poses[0].model
    new = DirectSolver(m)
    assert len(new.detached) == 0 and new.pattern is not first
    H, H_new = linear.assemble().toarray(), new.assemble().toarray()
    assert np.abs(H - H_new).max() <= 1e-14 * np.abs(H_new).max()
    rhs = np.random.default_rng(0).normal(size=(m.n, 2))
    rhs[p.fixed] = 0.0
    y, y_new = linear.solve(rhs), new.solve(rhs)
    assert linear.factor.lu is None and linear.factor.U.shape[1] > len(linear.detached) - 1
    assert np.abs(y - y_new).max() <= 1e-10 * np.abs(y_new).max()
    ik = obj.ik
    fresh = SoftIK(p, p.scene.optimize, "direct", cables=ik.model.cables)
    for ps, x in zip(fresh.poses, start):
        ps.model.set_positions(x)
    f, g = fresh.evaluate(obj.unpack(z1)[1].ravel())
    assert abs(ik.last_value() - f) <= 1e-8 * abs(f)
    assert np.abs(ik._last[2] - g).max() <= 1e-6 * np.abs(g).max()


def _route_step():
    """The arm's objective evaluated at z0, then one step on (every control point 3 mm
    down, into other triangles); the problem, the objective, z1, the equilibria z1
    started from and the fresh factorizations the step took (first pose)."""
    p, obj, z0 = _arm_objective()
    obj.evaluate(z0)
    start = [x.copy() for x in obj.positions]
    lin = obj.ik.poses[0].linear
    solves = lin.stats.solves
    z1 = z0.copy()
    z1[1:obj.n_control:2] -= 0.003 / p.size
    obj.evaluate(z1)
    return p, obj, z1, start, lin.stats.solves - solves


def test_a_moved_route_starts_newton_from_the_last_factorization(monkeypatch):
    """After a route step (cables moved) Newton starts with chord steps on the last
    equilibrium's factorization instead of factorizing anew - fewer fresh
    factorizations than when the move forgets it - and reaches the equilibrium,
    objective and gradient of a new robot of the same cables solved to a far
    tighter tolerance (1e-13), as closely as the evaluation's tolerance allows."""
    from tendon_taichi.optimizer.soft_ik import SoftIK
    from tendon_taichi.solve.direct import DirectSolver

    p, obj, z1, start, chord = _route_step()
    with monkeypatch.context() as m:
        m.setattr(DirectSolver, "chord_across_moves", False)
        forgetting = _route_step()[4]
    assert chord < forgetting
    ik = obj.ik
    tight = SoftIK(p, p.scene.optimize, "direct", cables=ik.model.cables)
    tight.eval_tol = 1e-13
    for ps, x in zip(tight.poses, start):
        ps.model.set_positions(x)
    f, g = tight.evaluate(obj.unpack(z1)[1].ravel())
    for a, b in zip(ik.poses, tight.poses):
        assert np.sqrt(a.model.gradient_norm2()) <= ik.eval_tol * a.newton.force_scale
        assert np.abs(a.model.positions() - b.model.positions()).max() < 1e-7 * p.size
    assert abs(ik.last_value() - f) <= 1e-6 * abs(f)
    assert np.abs(ik._last[2] - g).max() <= 1e-4 * np.abs(g).max()


def test_a_tendon_robot_solves_with_pardiso_as_with_qdldl(monkeypatch):
    """A route step (cables moved, chord steps, friction's GMRES, the tendon's
    Woodbury term) evaluates to the same objective and gradient, to round-off,
    whether the direct backend factorizes with qdldl or with PARDISO."""
    from conftest import use_cholesky

    out = []
    for name in ("qdldl", "pardiso"):
        with monkeypatch.context() as m:
            kind = use_cholesky(m, name)
            obj = _route_step()[1]
            assert isinstance(obj.ik.poses[0].linear.ldl, kind)
            out.append((obj.ik.last_value(), obj.ik._last[2]))
    (f0, g0), (f1, g1) = out
    assert abs(f1 - f0) <= 1e-10 * abs(f0) and np.abs(g1 - g0).max() <= 1e-7 * np.abs(g0).max()


def test_robots_of_the_same_cables_share_their_pattern_not_their_factors():
    """A second robot of the same cables on the same mesh takes the sparsity pattern
    the first one made (no new analysis), factorizes into factors of its own, and
    evaluates bit for bit as a robot whose pattern was made anew."""
    from tendon_taichi.solve import direct

    p, obj, z0 = _arm_objective()
    obj.evaluate(z0)
    start = [x.copy() for x in obj.positions]
    made = obj.ik.poses[0].linear
    same, second = _as_a_new_robot(p, obj, z0, start)
    assert same
    taken = second.poses[0].linear
    assert taken.pattern is not made.pattern and taken.pattern.scatter is made.pattern.scatter
    assert taken.ldl is not None and taken.ldl is not made.ldl
    direct._SHARED_PATTERNS.clear()
    same, anew = _as_a_new_robot(p, obj, z0, start)
    assert same and anew.poses[0].linear.pattern.scatter is not made.pattern.scatter
