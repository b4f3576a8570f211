"""Neo-Hookean patch test: a uniform deformation of a multi-triangle mesh gives the
analytic stress, i.e. zero force at interior nodes and the traction h P N at the boundary."""

import numpy as np
from reference import lame, neo_hookean_P, neo_hookean_psi

from tendon_taichi import CableSet, Model
from tendon_taichi.body.mesh import triangulate_polygon
from tendon_taichi.body.scene import Material


def test_uniform_deformation_gives_analytic_stress():
    W, H = 0.04, 0.02
    mesh = triangulate_polygon(np.array([[0, 0], [W, 0], [W, H], [0, H]], float), (), 2e-5)
    assert mesh.n_triangles > 20
    mat = Material(youngs_modulus=3e4, poisson_ratio=0.4, thickness=0.005)
    model = Model(mesh, np.zeros(mesh.n_nodes, bool), mat, CableSet.empty())
    F = np.array([[1.15, 0.08], [-0.05, 0.92]])
    x = mesh.nodes @ F.T
    g = model.gradient(x)
    mu, lam = lame(mat.youngs_modulus, mat.poisson_ratio)
    P = neo_hookean_P(F, mu, lam)
    # expected nodal forces: h * P N * (half of each adjacent boundary edge's length)
    expected = np.zeros_like(x)
    for a, b in mesh.boundary_edges:  # counter-clockwise: outward normal = (dy, -dx)
        d = mesh.nodes[b] - mesh.nodes[a]
        N_len = np.array([d[1], -d[0]])  # outward normal times edge length
        t = 0.5 * mat.thickness * P @ N_len
        expected[a] += t
        expected[b] += t
    scale = np.abs(expected).max()
    assert scale > 1e-3
    assert np.abs(g - expected).max() <= 1e-10 * scale
    interior = np.setdiff1d(np.arange(mesh.n_nodes), mesh.boundary_edges.ravel())
    assert len(interior) > 5 and np.abs(g[interior]).max() <= 1e-10 * scale
    E = model.energy(x)
    assert abs(E - mat.thickness * W * H * neo_hookean_psi(F, mu, lam)) <= 1e-12 * abs(E)
