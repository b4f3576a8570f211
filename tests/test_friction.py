"""Capstan friction in the realizable robot: mu = 0 is the frictionless cable bit
for bit, a straight tendon does not feel mu, a tendon wrapped half a turn
delivers exp(-mu pi) of its pull at its anchor - the segment tensions fitted to
the body's own elastic forces (an independent Neo-Hookean in numpy), not read
from the model - and the equilibrium's non-symmetric Jacobian, the adjoint
gradient and the sensitivities match central differences."""

import numpy as np
import pytest

from reference import body_forces
from tendon_taichi import build_problem, load_scene, parse_scene
from tendon_taichi.body.cables import CableSet
from tendon_taichi.extract.realizable import target_jacobian
from tendon_taichi.optimizer import SoftIK
from tendon_taichi.physics.capstan import Capstan
from tendon_taichi.physics.model import Model
from tendon_taichi.solve.newton import NewtonSolver

BAR = """
name = "bar"
[body]
mesh = "bar.vtu"
[[fixed]]
box = [[-0.001, -0.011], [0.001, 0.011]]
[[targets]]
point = [0.1, 0.0]
goal = [0.095, 0.0]
"""


def _symmetric_bar(path, nx=40, ny=8, length=0.1, width=0.02):
    """A bar meshed symmetrically about its axis (y = 0): every grid cell split in
    four by its diagonals."""
    import meshio

    xs, ys = np.linspace(0, length, nx + 1), np.linspace(-width / 2, width / 2, ny + 1)
    grid = np.array([[x, y] for y in ys for x in xs])
    centres = np.array([[(xs[i] + xs[i + 1]) / 2, (ys[j] + ys[j + 1]) / 2] for j in range(ny) for i in range(nx)])
    tris = []
    for j in range(ny):
        for i in range(nx):
            a, b = j * (nx + 1) + i, j * (nx + 1) + i + 1
            c, d = b + nx + 1, a + nx + 1
            m = len(grid) + j * nx + i
            tris += [[a, b, m], [b, c, m], [c, d, m], [d, a, m]]
    pts = np.vstack([grid, centres])
    meshio.write(str(path), meshio.Mesh(np.c_[pts, np.zeros(len(pts))], [("triangle", np.array(tris))]))

#: a stiff block clamped along its bottom, for a tendon wrapped half a turn
BLOCK = """
name = "block"
[body]
outline = [[0.0, 0.0], [0.08, 0.0], [0.08, 0.06], [0.0, 0.06]]
youngs_modulus = 5.0e6
max_triangle_area = 2.0e-6
[[fixed]]
box = [[-0.001, -0.001], [0.081, 0.001]]
[[targets]]
point = [0.04, 0.06]
goal = [0.04, 0.059]
"""


def _u_turn(k: int = 12) -> np.ndarray:
    """Up a leg, half a circle over the top (k chords), down the other leg: the
    polyline turns by exactly pi in all."""
    c, r = np.array([0.04, 0.03]), 0.018
    phi = np.linspace(np.pi, 0.0, k + 1)
    arc = c + r * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    return np.vstack([[c[0] - r, 0.012], arc, [c[0] + r, 0.012]])


def _t_shape_paths():
    t = np.linspace(0, 1, 12)
    return [np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1),
            np.stack([0.004 * np.sin(3 * t), 0.01 + 0.05 * t], 1)]


def _solve(problem, paths, mu, ac, force_capstan=False):
    cables = CableSet.polylines(problem.mesh, paths, problem.scene.fibers.stiffness, friction=mu)
    model = Model.from_problem(problem, cables=cables)
    if force_capstan:  # the friction machinery on, with mu = 0: every weight exp(-0 Theta) = 1
        model.capstan = Capstan(cables, cables.points.positions(problem.mesh.triangles, problem.mesh.nodes), 0.0)
    eq = NewtonSolver(model, "direct").solve(ac=np.asarray(ac, dtype=float))
    return model, eq


def test_zero_friction_is_the_frictionless_cable_bit_for_bit():
    p = build_problem(load_scene("t_shape"), 1)
    plain, eq = _solve(p, _t_shape_paths(), 0.0, [0.004, 0.003])
    assert plain.capstan is None  # mu = 0 builds no friction at all
    forced, eq_forced = _solve(p, _t_shape_paths(), 0.0, [0.004, 0.003], force_capstan=True)
    assert np.array_equal(eq.x, eq_forced.x) and np.array_equal(eq.tau, eq_forced.tau)
    assert np.array_equal(plain.segment_tensions(), forced.segment_tensions())
    # and friction does change the equilibrium
    _, eq_mu = _solve(p, _t_shape_paths(), 0.1, [0.004, 0.003])
    assert np.abs(eq_mu.x - eq.x).max() > 1e-6 * p.size


def test_a_straight_tendon_is_unaffected_by_friction(tmp_path):
    """Along the axis of a bar clamped at one end (meshed symmetrically about it),
    a tendon pulls the bar straight in: it stays straight, so every capstan weight
    stays 1 and mu changes nothing."""
    _symmetric_bar(tmp_path / "bar.vtu")
    p = build_problem(parse_scene(BAR, base_dir=tmp_path), 1)
    path = [np.array([[0.005, 0.0], [0.03, 0.0], [0.06, 0.0], [0.095, 0.0]])]
    _, eq0 = _solve(p, path, 0.0, [0.003])
    model, eq = _solve(p, path, 0.5, [0.003])
    assert np.abs(eq.x - eq0.x).max() <= 1e-9 * p.size
    assert eq.tau[0] == pytest.approx(eq0.tau[0], rel=1e-9) and eq.tau[0] > 0.1
    assert np.abs(model.segment_tensions() - eq.tau[0]).max() <= 1e-9 * eq.tau[0]


def _fitted_tensions(problem, model, x):
    """Segment tensions (S,) that make the cable's node forces balance the body's
    elastic forces (reference Neo-Hookean) on the free nodes, by least squares:
    sum_s T_s (B_b - B_a)^T n_s = -dE_body/dx."""
    mat, T = problem.material, problem.mesh.triangles
    f_body = body_forces(problem.mesh.nodes, T, x, mat.youngs_modulus, mat.poisson_ratio, mat.thickness)
    pts = model.cables.points
    c = pts.positions(T, x)
    seg = model.cables.segments
    n = c[seg[:, 1]] - c[seg[:, 0]]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    A = np.zeros((problem.mesh.n_nodes, 2, len(seg)))
    for s, (a, b) in enumerate(seg):
        for point, sign in ((b, 1.0), (a, -1.0)):
            for k in range(3):
                A[T[pts.tri[point], k], :, s] += sign * pts.bary[point, k] * n[s]
    free = ~problem.fixed
    A, rhs = A[free].reshape(-1, len(seg)), -f_body[free].ravel()
    tensions, *_ = np.linalg.lstsq(A, rhs, rcond=None)
    return tensions, np.linalg.norm(A @ tensions - rhs) / np.linalg.norm(rhs), c


@pytest.mark.parametrize("mu", [0.1, 0.3])
def test_a_half_turn_delivers_exp_minus_mu_pi_at_the_anchor(mu):
    p = build_problem(parse_scene(BLOCK), 1)
    path = _u_turn()
    model, eq = _solve(p, [path], mu, [0.006 * np.linalg.norm(np.diff(path, axis=0), axis=1).sum()])
    tensions, residual, c = _fitted_tensions(p, model, eq.x)
    assert residual <= 1e-6  # these tensions balance the body: they are the tendon's
    d = np.diff(c, axis=0)
    turning = np.abs(np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], (d[:-1] * d[1:]).sum(1))).sum()
    assert turning == pytest.approx(np.pi, rel=1e-3)  # a stiff block: the half turn stays one
    assert tensions[-1] == pytest.approx(eq.tau[0], rel=1e-6)  # the pull end carries the full pull
    assert tensions[0] / tensions[-1] == pytest.approx(np.exp(-mu * turning), rel=1e-6)
    assert tensions[0] / tensions[-1] == pytest.approx(np.exp(-mu * np.pi), rel=1e-3)
    assert np.all(np.diff(tensions) >= -1e-9 * tensions[-1])  # it only drops toward the anchor


def test_friction_jacobian_matches_finite_differences():
    """J v = (H + E) v against central differences of the force residual with the
    weights updated from the perturbed positions; E^T is E's transpose."""
    p = build_problem(load_scene("t_shape"), 1)
    model, eq = _solve(p, _t_shape_paths(), 0.3, [0.004, 0.003])
    rng = np.random.default_rng(0)
    v = rng.standard_normal(eq.x.shape) * (~p.fixed)[:, None]
    u = rng.standard_normal(eq.x.shape) * (~p.fixed)[:, None]

    def residual(x):
        model.set_positions(x)
        model.update_friction()
        return model.gradient() * (~p.fixed)[:, None]

    model.set_positions(eq.x)
    model.update_friction()
    E = model.friction_jacobian()
    Jv = model.hessian_product(v) * (~p.fixed)[:, None] + E.product(v)
    h = 1e-6
    fd = (residual(eq.x + h * v) - residual(eq.x - h * v)) / (2 * h)
    assert np.abs(fd - Jv).max() <= 1e-5 * np.abs(fd).max()
    frozen = model.hessian_product(v) * (~p.fixed)[:, None]
    assert np.abs(fd - frozen).max() > 1e-3 * np.abs(fd).max()  # the term matters
    assert (u * E.product(v)).sum() == pytest.approx((v * E.transpose_product(u)).sum(), rel=1e-10)


@pytest.mark.parametrize("solver", ["direct", "cg", "cg-amg"])
def test_frictional_gradient_and_sensitivities_match_finite_differences(solver):
    p = build_problem(load_scene("t_shape"), 1)
    cables = CableSet.polylines(p.mesh, _t_shape_paths(), 50.0, friction=0.3)
    ik = SoftIK(p, p.scene.optimize, solver, cables=cables)
    ik.eval_tol = 1e-14
    r, h = np.array([0.08, 0.05]), 1e-5
    _, g = ik.evaluate(r)
    fd = [(ik.evaluate(r + h * e)[0] - ik.evaluate(r - h * e)[0]) / (2 * h) for e in np.eye(2)]
    assert np.abs(g - fd).max() <= 1e-6 * np.abs(fd).max()

    def targets(ratios):
        ik.evaluate(ratios)
        return p.target_positions(ik.state()[0][0])

    targets(r)
    J = target_jacobian(ik.poses[0], cables.a0)
    for j, e in enumerate(np.eye(2)):
        fd = (targets(r + h * e) - targets(r - h * e)) / (2 * h)
        assert np.linalg.norm(J[..., j] - fd) <= 1e-6 * np.linalg.norm(fd)


@pytest.mark.parametrize("solver", ["direct", "cg"])
def test_sensitivities_prepare_the_hessian_once(solver):
    """The sensitivities of every tendon share one preparation (factorization) of H
    and equal those solved one by one, each with H prepared anew."""
    from tendon_taichi.optimizer.soft_ik import ADJOINT_TOL
    from tendon_taichi.solve.frictional import solve_jacobian

    p = build_problem(load_scene("t_shape"), 1)
    cables = CableSet.polylines(p.mesh, _t_shape_paths(), 50.0, friction=0.3)
    ik = SoftIK(p, p.scene.optimize, solver, cables=cables)
    ik.evaluate(np.array([0.08, 0.05]))
    ps = ik.poses[0]
    rhs = [ps.model.mixed_product(cables.a0[j] * np.eye(1, 2, j).ravel()) for j in range(2)]
    for b in rhs:
        b[p.fixed] = 0.0
    alone = [solve_jacobian(ps.linear, ps.model.friction_jacobian(), b, ADJOINT_TOL, transpose=False) for b in rhs]
    prepared, solve = [0], ps.linear.solve

    def counted(*args, **kwargs):
        prepared[0] += kwargs.get("prepare", True)
        return solve(*args, **kwargs)

    ps.linear.solve = counted
    shared = list(ps.sensitivities(iter(rhs)))
    assert prepared[0] == 1
    for a, s in zip(alone, shared):
        assert np.linalg.norm(s - a) <= 1e-8 * np.linalg.norm(a)
