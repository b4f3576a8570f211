"""The numpy/scipy baseline that bench measures the gradient against: it is the
same gradient (the pipeline's soft IK at stage 0 gives the same objective and
gradient) and a true one (central differences of its own objective)."""

import numpy as np
import pytest

from tendon_taichi import build_problem, load_scene
from tendon_taichi.apps.baseline import BaselineGradient
from tendon_taichi.apps.bench import design_pair
from tendon_taichi.optimizer.soft_ik import SoftIK


@pytest.fixture(scope="module")
def pair():
    p = build_problem(load_scene("t_shape"), 1)
    r0, r1 = design_pair(p)
    ik = SoftIK(p, p.scene.optimize, "direct")
    ik.configure(None)  # stage 0: pose and contraction, what the baseline computes
    ik.restart(r0)
    ik.evaluate(r0)
    x0 = ik.state()[0][0]
    value, grad = ik.evaluate(r1)
    return p, BaselineGradient(p, p.scene.optimize.contraction_reg), r1, x0, value, grad, ik.state()[0][0]


def test_the_baseline_computes_the_pipelines_gradient(pair):
    p, base, r1, x0, value, grad, x = pair
    v, g, xb = base.objective_gradient(r1, x0)
    assert v == pytest.approx(value, rel=1e-6)
    assert np.linalg.norm(g - grad) <= 1e-5 * np.linalg.norm(grad)  # both equilibria to 1e-8 E h L
    assert np.abs(xb - x).max() <= 1e-8 * p.size
    assert np.linalg.norm(base.gradient(xb, r1 * p.fibers.a0)[base.free]) <= 1e-8 * base.F


def test_the_baseline_gradient_matches_central_differences(pair):
    p, base, r1, x0, *_ = pair
    rng = np.random.default_rng(3)
    d = rng.standard_normal(len(r1))
    _, g, x = base.objective_gradient(r1, x0, tol=1e-12)
    h = 1e-6
    vp = base.objective_gradient(r1 + h * d, x, tol=1e-12)[0]
    vm = base.objective_gradient(r1 - h * d, x, tol=1e-12)[0]
    assert (vp - vm) / (2 * h) == pytest.approx(g @ d, rel=1e-5)


def test_the_baseline_hessian_is_the_gradients_derivative(pair):
    p, base, r1, x0, *_ = pair
    ac = r1 * p.fibers.a0
    x = base.equilibrium(ac, x0)
    v = np.random.default_rng(4).standard_normal(x.size) * base.free
    h = 1e-7 * p.size
    fd = (base.gradient(x + h * v.reshape(-1, 2), ac) - base.gradient(x - h * v.reshape(-1, 2), ac)) / (2 * h)
    Hv = base.hessian(x, ac) @ v[base.free]
    assert np.linalg.norm(Hv - fd[base.free]) <= 1e-6 * np.linalg.norm(Hv)
