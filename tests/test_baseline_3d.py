"""The numpy/scipy baseline in 3D, on a small extruded finger of tetrahedra: its
gradient and Hessian are the energy's derivatives, the body energy is invariant under
rigid motions and passes the patch test, its Newton equilibrium balances forces
written independently here (tests/reference.py), and its adjoint gradient is the
objective's derivative."""

import copy

import numpy as np
import pytest
from reference import fiber_forces, lame, neo_hookean_psi_3d, tet_body_forces, tet_gravity_forces, zcq_d1

from tendon_taichi import build_problem, parse_scene
from tendon_taichi.apps.baseline import BaselineGradient

#: a 4 x 1 x 1 cm finger of tetrahedra of 4.5 mm edges, clamped at x <= 1 mm, a target at its tip
FINGER = """
name = "finger3d_small"
[body]
outline = [[0, 0], [0.04, 0], [0.04, 0.01], [0, 0.01]]
depth = 0.01
edge_length = 0.0045
gravity = [0.0, -9.81, 0.0]
[[fixed]]
box = [[-1, -1, -1], [0.001, 1, 1]]
[[targets]]
point = [0.04, 0.005, 0.005]
goal = [0.036, 0.014, 0.005]
[tendons]
exit = "inside"
"""
VOLUME = 0.04 * 0.01 * 0.01  # m^3


@pytest.fixture(scope="module")
def problem():
    p = build_problem(parse_scene(FINGER, origin="finger3d_small.toml"), 1)
    assert p.dim == 3 and 3 * p.mesh.n_nodes < 3000
    return p


@pytest.fixture(scope="module")
def base(problem):
    return BaselineGradient(problem, problem.scene.optimize.contraction_reg)


@pytest.fixture(scope="module")
def body_only(base):
    """The baseline without gravity, for the body energy alone (with :func:`slack` fibers)."""
    b = copy.copy(base)
    b.f_ext = np.zeros_like(base.f_ext)
    return b


def slack(problem) -> np.ndarray:
    """Contractions (C,) m that pay every fiber out by half its length: slack while no
    fiber is stretched by half."""
    return -0.5 * problem.fibers.a0


def upper_ratios(problem, ratio: float = 0.1) -> np.ndarray:
    """Contraction ratios (C,): ``ratio`` on the fibers whose middle is in the upper half."""
    f = problem.fibers
    middle = f.nodes[f.edges].mean(axis=1)
    return np.where(middle[:, 1] > 0.005, ratio, 0.0)


@pytest.fixture(scope="module")
def bent(problem, base):
    """The equilibrium (n, 3) with the upper fibers contracted by 10 %."""
    return base.equilibrium(upper_ratios(problem) * problem.fibers.a0, problem.mesh.nodes, tol=1e-11)


def strains(problem, x, ac):
    """The fibers' strains (C,) at positions ``x`` (n, 3) and contractions ``ac`` (C,)."""
    f = problem.fibers
    c = np.einsum("kj,kjd->kd", f.embedding.bary, x[problem.mesh.simplices[f.embedding.tri]])
    length = np.linalg.norm(c[f.edges[:, 1]] - c[f.edges[:, 0]], axis=1)
    return length / (f.a0 - ac) - 1.0


def rotation(axis, angle: float) -> np.ndarray:
    """The rotation (3, 3) by ``angle`` (rad) about ``axis`` (3,), Rodrigues' formula."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_the_gradient_and_hessian_are_the_energys_derivatives(problem, base, bent):
    ac = upper_ratios(problem) * problem.fibers.a0
    rng = np.random.default_rng(5)
    x = bent + 2e-4 * problem.size * rng.standard_normal(bent.shape) * ~problem.fixed[:, None]
    assert np.isfinite(base.energy(x, ac))  # no tetrahedron inverted
    e = strains(problem, x, ac)
    assert (e > problem.scene.fibers.eps).sum() >= 5 and (e <= 0).sum() >= 5  # taut fibers and slack ones
    g, H = base.gradient(x, ac), base.hessian(x, ac)
    for _ in range(3):
        v = rng.standard_normal(x.shape)
        h = 1e-7 * problem.size  # the energy's round-off over h stays below 1e-9 of g . v
        fd = (base.energy(x + h * v, ac) - base.energy(x - h * v, ac)) / (2 * h)
        assert abs(fd - g @ v.ravel()) <= 1e-6 * abs(g @ v.ravel())
        v = v.ravel() * base.free
        h = 1e-7 * problem.size
        fd = (base.gradient(x + h * v.reshape(-1, 3), ac) - base.gradient(x - h * v.reshape(-1, 3), ac)) / (2 * h)
        Hv = H @ v[base.free]
        assert np.linalg.norm(Hv - fd[base.free]) <= 1e-6 * np.linalg.norm(Hv)


def test_a_rigid_motion_costs_no_energy_and_no_force(problem, body_only, bent):
    X, ac = problem.mesh.nodes, slack(problem)
    R, b = rotation([1.0, -2.0, 0.5], 0.7), np.array([0.01, -0.02, 0.03])
    mu = problem.material.mu
    moved = X @ R.T + b
    assert abs(body_only.energy(moved, ac)) <= 1e-12 * mu * VOLUME
    assert np.linalg.norm(body_only.gradient(moved, ac)) <= 1e-12 * body_only.F
    assert strains(problem, moved, ac).max() < 0 and strains(problem, bent, ac).max() < 0  # slack fibers
    E, g = body_only.energy(bent, ac), body_only.gradient(bent, ac).reshape(-1, 3)
    assert E > 1e-6 * mu * VOLUME  # a deformed state
    assert body_only.energy(bent @ R.T + b, ac) == pytest.approx(E, rel=1e-12, abs=0)
    g_moved = body_only.gradient(bent @ R.T + b, ac).reshape(-1, 3)
    assert np.abs(g_moved - g @ R.T).max() <= 1e-10 * np.abs(g).max()  # the forces turn with the body


def test_an_affine_deformation_passes_the_patch_test(problem, body_only):
    X, ac = problem.mesh.nodes, slack(problem)
    A = np.eye(3) + 0.1 * np.random.default_rng(7).uniform(-1, 1, (3, 3))
    x = X @ A.T + np.array([0.003, -0.001, 0.002])
    mu, lam = lame(problem.material.youngs_modulus, problem.material.poisson_ratio)
    assert body_only.energy(x, ac) == pytest.approx(VOLUME * neo_hookean_psi_3d(A, mu, lam), rel=1e-11, abs=0)
    g = body_only.gradient(x, ac).reshape(-1, 3)
    interior = np.setdiff1d(np.arange(len(X)), problem.mesh.boundary_faces.ravel())
    assert len(interior) >= 5
    assert np.abs(g[interior]).max() <= 1e-11 * np.abs(g).max()


def test_the_newton_equilibrium_balances_independent_forces(problem, bent):
    mesh, mat, f = problem.mesh, problem.material, problem.fibers
    ac = upper_ratios(problem) * f.a0
    tip = problem.target_positions(bent)[0] - problem.target_positions(mesh.nodes)[0]
    assert tip[1] > 0.002 and np.abs(bent[problem.fixed] - mesh.nodes[problem.fixed]).max() == 0.0
    mu, lam = lame(mat.youngs_modulus, mat.poisson_ratio)
    e = strains(problem, bent, ac)
    tau = problem.scene.fibers.stiffness * zcq_d1(e, problem.scene.fibers.eps)
    assert (tau > 0).sum() >= 5
    force = (tet_body_forces(mesh.nodes, mesh.simplices, bent, mu, lam)
             + fiber_forces(mesh.simplices, bent, node_tri=f.embedding.tri, node_bary=f.embedding.bary,
                          fibers=f.edges, tau=tau)
             + tet_gravity_forces(mesh.nodes, mesh.simplices, mat.density, mat.gravity))
    assert np.abs(force[~problem.fixed]).max() <= 1e-10 * problem.force_scale
    assert np.abs(force[problem.fixed]).max() >= 1e-3 * tau.max()  # the clamp holds the finger


@pytest.mark.parametrize("ratio", [0.05, 0.1, 0.2])
def test_the_adjoint_gradient_matches_central_differences(problem, base, bent, ratio):
    rng = np.random.default_rng(int(100 * ratio))
    r = upper_ratios(problem, ratio) + rng.uniform(-0.02, 0.02, problem.fibers.n_fibers)
    _, g, x = base.objective_gradient(r, bent, tol=1e-12)
    for _ in range(2):
        d = rng.standard_normal(len(r))
        h = 1e-7  # O is strongly curved in r (fibers in the cubic zone): 3e-3 relative error at h = 1e-5
        vp = base.objective_gradient(r + h * d, x, tol=1e-12)[0]
        vm = base.objective_gradient(r - h * d, x, tol=1e-12)[0]
        assert (vp - vm) / (2 * h) == pytest.approx(g @ d, rel=1e-5)
