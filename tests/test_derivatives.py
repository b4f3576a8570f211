"""Every derivative of the Taichi model against central finite differences.

Random small scenes (random star-shaped bodies, random materials), random
deformed states, fibers in all three zones of the unilateral energy.
"""

import numpy as np
import pytest
from conftest import small_scene_toml

from tendon_taichi import CableSet, DirectSolver, Model, build_problem, parse_scene

SEEDS = [1, 2, 3]
TOL = 1e-6


def _problem(seed):
    return build_problem(parse_scene(small_scene_toml(seed)), 1)


def _deformed(problem, rng, stretch=0.03, noise=0.02):
    """A random affine deformation plus nodal noise (a fraction of the element size)."""
    X = problem.mesh.nodes
    A = np.eye(2) + stretch * rng.uniform(-1, 1, (2, 2))
    h = np.sqrt(2 * np.abs(problem.mesh.areas).mean())
    x = (X - X.mean(0)) @ A.T + X.mean(0) + noise * h * rng.standard_normal(X.shape)
    return x


def _zones(model, eps):
    e = model.cable_state()["e"]
    return int((e <= 0).sum()), int(((e > 0) & (e <= eps)).sum()), int((e > eps).sum())


def _fd_gradient(model, x, h):
    g = np.zeros(x.size)
    flat = x.ravel()
    for k in range(x.size):
        d = np.zeros(x.size)
        d[k] = h
        g[k] = (model.energy((flat + d).reshape(x.shape)) - model.energy((flat - d).reshape(x.shape))) / (2 * h)
    return g.reshape(x.shape)


def _rel(a, b):
    return np.linalg.norm(np.ravel(a) - np.ravel(b)) / max(np.linalg.norm(np.ravel(b)), 1e-300)


def _hessian_error(model, x, v, h=1e-7):
    """Relative error of the exact H v against central differences of the gradient at x."""
    model.set_free_positions(x)
    Hv = model.hessian_product(v)
    fd = (model.gradient(x + h * v) - model.gradient(x - h * v)) / (2 * h)
    model.set_free_positions(x)
    return _rel(fd, Hv)


@pytest.fixture(scope="module", params=SEEDS)
def fiber_case(request):
    """A model with fibers at random contractions and a random deformed state."""
    rng = np.random.default_rng(request.param)
    p = _problem(request.param)
    m = Model.from_problem(p)
    ratios = rng.uniform(-0.02, 0.03, p.fibers.n_fibers)
    m.set_contraction(ratios * p.fibers.a0)
    x = _deformed(p, rng)
    m.set_free_positions(x)
    return p, m, x, rng


def test_fibers_in_all_three_zones(fiber_case):
    p, m, x, _ = fiber_case
    slack, cubic, quad = _zones(m, p.scene.fibers.eps)
    assert slack >= 5 and cubic >= 5 and quad >= 5, (slack, cubic, quad)


def test_body_gradient_matches_energy(rng):
    p = _problem(4)
    body = Model(p.mesh, p.fixed, p.material, CableSet.empty())
    x = _deformed(p, rng, stretch=0.1)
    g = body.gradient(x)
    assert _rel(_fd_gradient(body, x, 1e-7), g) <= TOL
    assert np.abs(g).max() > 1e-3  # a real, strained state


def test_total_gradient_matches_energy(fiber_case):
    p, m, x, _ = fiber_case
    g = m.gradient(x)
    assert _rel(_fd_gradient(m, x, 1e-7), g) <= TOL


def test_fiber_gradient_is_tension_along_fibers(fiber_case):
    """The fiber part of the gradient (total minus body) is sum_i tau_i dl_i/dx."""
    p, m, x, _ = fiber_case
    body = Model(p.mesh, p.fixed, p.material, CableSet.empty())
    g_fib = m.gradient(x) - body.gradient(x)
    tau = m.tensions()
    assert _rel(m.length_jacobian_product(tau), g_fib) <= 1e-12
    # tau = EA Z'(e) is dU/dL: check against finite differences of the fiber energy in L
    st = m.cable_state()
    from reference import zcq, zcq_d1
    EA, eps, a, L = p.scene.fibers.stiffness, p.scene.fibers.eps, st["a"], st["L"]
    U = lambda LL: EA * a * zcq(LL / a - 1, eps)  # noqa: E731
    h = 1e-9
    fd = (U(L + h) - U(L - h)) / (2 * h)
    assert np.allclose(fd, tau, rtol=1e-6, atol=1e-9 * EA)
    assert np.allclose(tau, EA * zcq_d1(L / a - 1, eps), rtol=1e-14, atol=0)


@pytest.mark.parametrize("project", [False, True])
def test_hessian_product_matches_gradient(fiber_case, project):
    p, m, x, rng = fiber_case
    v = rng.standard_normal(x.shape)
    assert _hessian_error(m, x, v) <= TOL
    if project:  # the projected product is symmetric positive semi-definite
        u = rng.standard_normal(x.shape)
        Pv, Pu = m.hessian_product(v, project=True), m.hessian_product(u, project=True)
        assert abs(np.sum(u * Pv) - np.sum(v * Pu)) <= 1e-12 * np.linalg.norm(Pv) * np.linalg.norm(u)
        assert np.sum(v * Pv) > 0


def test_body_hessian_matches_gradient(rng):
    p = _problem(5)
    body = Model(p.mesh, p.fixed, p.material, CableSet.empty())
    x = _deformed(p, rng, stretch=0.1)
    assert _hessian_error(body, x, rng.standard_normal(x.shape)) <= TOL


def test_tendon_derivatives(rng):
    """Many-segment sliding cables: gradient and Hessian products."""
    p = _problem(6)
    nodes = p.fibers.nodes  # lattice points: inside the body
    lo, hi = nodes.min(0), nodes.max(0)
    pick = lambda f: nodes[np.argmin(np.linalg.norm(nodes - (lo + f * (hi - lo)), axis=1))]  # noqa: E731
    paths = [np.array([pick(np.array(f)) for f in ([0.2, 0.2], [0.5, 0.35], [0.8, 0.6], [0.6, 0.8])]),
             np.array([pick(np.array([0.2, 0.7])), pick(np.array([0.7, 0.3]))])]
    cab = CableSet.polylines(p.mesh, paths, 40.0)
    m = Model.from_problem(p, cables=cab)
    assert not m.single
    m.set_contraction(np.array([0.05, 0.03]) * cab.a0)
    x = _deformed(p, rng, stretch=0.01, noise=0.01)
    assert _rel(_fd_gradient(m, x, 1e-7), m.gradient(x)) <= TOL
    assert _hessian_error(m, x, rng.standard_normal(x.shape)) <= TOL
    assert np.all(m.tensions() > 0)


def test_mixed_derivatives(fiber_case):
    """(d2E/dx dac) w against finite differences of the gradient in ac, and its transpose."""
    p, m, x, rng = fiber_case
    ac = m.contraction()
    w = rng.uniform(-1, 1, len(ac)) * (m.cable_state()["e"] > -0.5)
    h = 1e-9
    m.set_contraction(ac + h * w)
    gp = m.gradient(x)
    m.set_contraction(ac - h * w)
    gm = m.gradient(x)
    m.set_contraction(ac)
    m.set_free_positions(x)
    Mw = m.mixed_product(w)
    assert _rel((gp - gm) / (2 * h), Mw) <= TOL
    v = rng.standard_normal(x.shape)
    MTv = m.mixed_transpose_product(v)
    assert abs(np.sum(v * Mw) - np.dot(w, MTv)) <= 1e-12 * np.linalg.norm(Mw) * np.linalg.norm(v)


def test_tension_derivatives(fiber_case):
    """dtau/dx = kc dL/dx and dtau/dac = tau_ac against finite differences."""
    p, m, x, rng = fiber_case
    m.set_free_positions(x)
    st = m.cable_state()
    v = rng.standard_normal(x.shape)
    pred_x = st["kc"] * m.length_jacobian_transpose_product(v)
    h = 1e-8
    m.set_free_positions(x + h * v)
    tp = m.tensions()
    m.set_free_positions(x - h * v)
    tm = m.tensions()
    m.set_free_positions(x)
    assert _rel((tp - tm) / (2 * h), pred_x) <= TOL
    ac = m.contraction()
    w = rng.uniform(-1, 1, len(ac))
    m.set_contraction(ac + 1e-10 * w)
    tp = m.tensions()
    m.set_contraction(ac - 1e-10 * w)
    tm = m.tensions()
    m.set_contraction(ac)
    assert _rel((tp - tm) / 2e-10, st["tau_ac"] * w) <= TOL


def test_projection_only_changes_indefinite_elements(rng):
    """Per element: the projected tangent equals the exact one where that is PSD;
    elsewhere it is the exact one with negative eigenvalues clamped to zero."""
    p = _problem(7)
    m = Model.from_problem(p)
    # stretched along x at the top, compressed at the bottom: the compressed side has
    # indefinite tangents (negative geometric stiffness of its rotation mode)
    X = p.mesh.nodes
    c, H = X.mean(0), np.ptp(X[:, 1])
    x = X.copy()
    x[:, 0] = c[0] + (X[:, 0] - c[0]) * (1 + 0.6 * (X[:, 1] - c[1]) / H)
    m.set_free_positions(x)
    m.prepare_hessian(False)
    D = m.hessian_data()["D"]
    m.prepare_hessian(True)
    Dp = m.hessian_data()["D"]
    lam, V = np.linalg.eigh(0.5 * (D + np.swapaxes(D, 1, 2)))
    psd = lam.min(axis=1) >= 0
    assert psd.any() and (~psd).any(), "the state should mix PSD and indefinite elements"
    scale = np.abs(D).max()
    assert np.abs(Dp[psd] - D[psd]).max() <= 1e-12 * scale
    clamped = np.einsum("eik,ek,ejk->eij", V, np.maximum(lam, 0), V)
    assert np.abs(Dp[~psd] - clamped[~psd]).max() <= 1e-9 * scale
    # and the assembled projected Hessian is positive semi-definite
    H = DirectSolver(m).assemble(project=True).toarray()
    assert np.abs(H - H.T).max() <= 1e-12 * np.abs(H).max()
    assert np.linalg.eigvalsh(H).min() >= -1e-10 * np.abs(H).max()


def test_direct_assembly_matches_matrix_free_product(fiber_case):
    p, m, x, rng = fiber_case
    m.set_free_positions(x)
    v = rng.standard_normal(x.shape) * (~p.fixed)[:, None]
    Hv = m.hessian_product(v) * (~p.fixed)[:, None]
    H = DirectSolver(m).assemble(project=False, prepare=False)
    free = np.repeat(~p.fixed, 2)
    assert _rel(H @ v.ravel()[free], Hv.ravel()[free]) <= 1e-12
