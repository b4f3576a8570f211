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
    """dU/dx (n, d) of fibers with tensions tau (f,) between fiber nodes embedded in the
    elements ``node_tri`` (k,) with weights ``node_bary`` (k, d + 1): triangles or tetrahedra."""
    c = np.einsum("kj,kjd->kd", node_bary, x[T[node_tri]])
    d = c[fibers[:, 1]] - c[fibers[:, 0]]
    n = d / np.linalg.norm(d, axis=1, keepdims=True)
    fn = np.zeros_like(c)
    np.add.at(fn, fibers[:, 1], tau[:, None] * n)
    np.add.at(fn, fibers[:, 0], -tau[:, None] * n)
    f = np.zeros_like(x)
    for j in range(node_bary.shape[1]):
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


def as_built_residual(a) -> float:
    """From an as-built export alone (``as_built.npz``, pose 0): checks that each
    tendon's segment tensions fall from its pull end by ``exp(-mu Theta_s)``
    (Theta_s the turning between segment s and the pull end, at the exported
    positions) and that the last one is the tendon's exported tension; returns the
    largest force (the body's elastic forces, reference Neo-Hookean, and the
    segments' pulls on their end points) on a free node over the largest tension."""
    X, T, fixed, x = a["nodes"], a["triangles"], a["fixed"].astype(bool), a["x"][0]
    f = body_forces(X, T, x, float(a["youngs_modulus"]), float(a["poisson_ratio"]), float(a["thickness"]))
    start, tri, bary = a["tendon_start"], a["point_tri"], a["point_bary"]
    points = np.einsum("kj,kjd->kd", bary, x[T[tri]])
    seg_t, mu = a["segment_tension"][0], float(a["friction"])
    s = 0
    for t in range(len(start) - 1):
        w = points[start[t]:start[t + 1]]
        d = np.diff(w, axis=0)
        n = d / np.linalg.norm(d, axis=1, keepdims=True)
        tens = seg_t[s:s + len(d)]
        turn = np.abs(np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], (d[:-1] * d[1:]).sum(1)))
        theta = np.r_[np.cumsum(turn[::-1])[::-1], 0.0]  # turning from each segment to the pull end
        assert abs(tens[-1] - a["tension"][0, t]) <= 1e-12 * max(abs(tens[-1]), 1e-300)
        assert np.allclose(tens, tens[-1] * np.exp(-mu * theta), rtol=1e-9)
        for i, ni in enumerate(n):  # segment i pulls its ends together
            for point, sign in ((start[t] + i + 1, 1.0), (start[t] + i, -1.0)):
                for k in range(3):
                    f[T[tri[point], k]] += sign * bary[point, k] * tens[i] * ni
        s += len(d)
    scale = np.abs(seg_t).max()
    assert scale > 0
    return float(np.abs(f[~fixed]).max() / scale)


# ---------------------------------------------------------------- 3D: constant-strain tetrahedra
def tet_edges(x, T):
    """Edge vectors x_a - x_0 (a = 1, 2, 3) of tetrahedra T (m, 4) as columns (m, 3, 3)."""
    return np.stack([x[T[:, 1]] - x[T[:, 0]], x[T[:, 2]] - x[T[:, 0]], x[T[:, 3]] - x[T[:, 0]]], axis=2)


def tet_volumes(X, T):
    """Rest volumes (m,) of tetrahedra T (m, 4): (b - a) . ((c - a) x (d - a)) / 6."""
    a, b, c, d = (X[T[:, k]] for k in range(4))
    return np.einsum("kd,kd->k", b - a, np.cross(c - a, d - a)) / 6.0


def neo_hookean_psi_3d(F, mu, lam):
    """Strain energy density (J/m^3) of F (..., 3, 3): mu/2 (|F|^2 - 3) - mu ln J + lam/2 (ln J)^2."""
    lnJ = np.log(np.linalg.det(F))
    return 0.5 * mu * (np.einsum("...ij,...ij->...", F, F) - 3) - mu * lnJ + 0.5 * lam * lnJ ** 2


def neo_hookean_P_3d(F, mu, lam):
    """First Piola-Kirchhoff stress (Pa) of F (m, 3, 3), with F^-T = cof(F) / J written by cross
    products of F's columns: mu (F - F^-T) + lam ln J F^-T."""
    f0, f1, f2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
    cof = np.stack([np.cross(f1, f2), np.cross(f2, f0), np.cross(f0, f1)], axis=2)
    J = np.einsum("kd,kd->k", f0, cof[:, :, 0])
    FinvT = cof / J[:, None, None]
    return mu * (F - FinvT) + lam * np.log(J)[:, None, None] * FinvT


def tet_body_forces(X, T, x, mu, lam):
    """Internal nodal forces dE_body/dx (n, 3) of constant-strain Neo-Hookean tetrahedra:
    V P Bm^T's columns on nodes 1-3, minus their sum on node 0."""
    Bm = np.linalg.inv(tet_edges(X, T))
    H = tet_volumes(X, T)[:, None, None] * neo_hookean_P_3d(tet_edges(x, T) @ Bm, mu, lam) @ np.swapaxes(Bm, 1, 2)
    f = np.zeros_like(x)
    for a in range(3):
        np.add.at(f, T[:, a + 1], H[:, :, a])
    np.add.at(f, T[:, 0], -H.sum(axis=2))
    return f


def tet_gravity_forces(X, T, density, g):
    """dE_g/dx = -m_i g (n, 3), each tetrahedron's mass density V lumped a quarter per corner."""
    m = np.zeros(len(X))
    np.add.at(m, T.ravel(), np.repeat(density * tet_volumes(X, T) / 4, 4))
    return -m[:, None] * np.asarray(g)[None, :]
