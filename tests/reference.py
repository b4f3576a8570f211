"""Independent numpy formulas and finite differences used by the tests (not imported by the package)."""

import numpy as np


def lame(E, nu):
    return E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))


def neo_hookean_P(F, mu, lam):
    """First Piola-Kirchhoff stress of F (..., 2, 2)."""
    Finv_T = np.swapaxes(np.linalg.inv(F), -1, -2)
    lnJ = np.log(np.linalg.det(F))[..., None, None]
    return mu * (F - Finv_T) + lam * lnJ * Finv_T


def neo_hookean_psi(F, mu, lam):
    lnJ = np.log(np.linalg.det(F))
    return 0.5 * mu * (np.einsum("...ij,...ij->...", F, F) - 2) - mu * lnJ + 0.5 * lam * lnJ ** 2


def body_forces(X, T, x, E, nu, h):
    """Internal nodal forces dE_body/dx (n, 2) of constant-strain Neo-Hookean triangles."""
    mu, lam = lame(E, nu)
    Dm = np.stack([X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]], axis=2)
    Ds = np.stack([x[T[:, 1]] - x[T[:, 0]], x[T[:, 2]] - x[T[:, 0]]], axis=2)
    Bm = np.linalg.inv(Dm)
    area = 0.5 * np.linalg.det(Dm)
    P = neo_hookean_P(Ds @ Bm, mu, lam)
    G = (h * area)[:, None, None] * P @ np.swapaxes(Bm, 1, 2)
    f = np.zeros_like(x)
    np.add.at(f, T[:, 1], G[:, :, 0])
    np.add.at(f, T[:, 2], G[:, :, 1])
    np.add.at(f, T[:, 0], -(G[:, :, 0] + G[:, :, 1]))
    return f


def fiber_forces(T, x, node_tri, node_bary, fibers, tau):
    """dU/dx (n, 2) of fibers with tensions tau between embedded fiber nodes."""
    c = np.einsum("kj,kjd->kd", node_bary, x[T[node_tri]])
    d = c[fibers[:, 1]] - c[fibers[:, 0]]
    n = d / np.linalg.norm(d, axis=1, keepdims=True)
    fn = np.zeros_like(c)
    np.add.at(fn, fibers[:, 1], tau[:, None] * n)
    np.add.at(fn, fibers[:, 0], -tau[:, None] * n)
    f = np.zeros_like(x)
    for j in range(3):
        np.add.at(f, T[node_tri, j], node_bary[:, j:j + 1] * fn)
    return f


def gravity_forces(X, T, h, density, g):
    """dE_g/dx = -m_i g (n, 2) with lumped masses."""
    Dm = np.stack([X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]], axis=2)
    area = 0.5 * np.linalg.det(Dm)
    m = np.zeros(len(X))
    np.add.at(m, T.ravel(), np.repeat(density * h * area / 3, 3))
    return -m[:, None] * np.asarray(g)[None, :]


def zcq(e, eps):
    e = np.asarray(e, dtype=float)
    return np.where(e > eps, 0.5 * e * e - 0.5 * eps * e + eps * eps / 6,
                    np.where(e > 0, e ** 3 / (6 * eps), 0.0))


def zcq_d1(e, eps):
    e = np.asarray(e, dtype=float)
    return np.where(e > eps, e - 0.5 * eps, np.where(e > 0, e * e / (2 * eps), 0.0))


def objective_fd(ik, r, d, h=1e-6):
    """Central difference of a SoftIK objective at ``r`` along ``d`` (each side solved afresh)."""
    vals = []
    for sgn in (1, -1):
        ik._last = None
        vals.append(ik.evaluate(r + sgn * h * d)[0])
    return (vals[0] - vals[1]) / (2 * h)
