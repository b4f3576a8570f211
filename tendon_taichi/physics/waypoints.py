"""How the equilibrium's residual moves with the rest positions of the cables'
points: what routes are optimized by (``docs/method.md``, routes).

A cable point embedded at rest position ``X`` follows ``p = sum_k b_k(X) x_k``,
so ``dp/dX = F``, the deformation gradient of its triangle; the cable's rest
length is its rest polyline's length ``a0 = sum_s l0_s`` and its contraction
``ac = r a0`` for a fixed ratio ``r``. For an adjoint ``lambda`` the residual
``R = dE/dx`` (free DOFs) enters the gradient of an objective as
``-lambda^T dR/dX``; only the cable part of ``R``,
``R_c = tau sum_s w_s g_s``, depends on ``X``, through

* the points' deformed positions ``p`` (lengths, directions, capstan angles),
* the interpolated adjoint ``Lambda_i = sum_k b_k(X_i) lambda_k`` (its
  derivative is the gradient of the field lambda, ``dLambda/dX = G_lambda``),
* the rest segment lengths ``l0_s`` (through ``a = (1 - r) sum_s w_s l0_s``).

:func:`rest_point_gradient` returns ``d(lambda^T R)/dX`` per point.
"""

from __future__ import annotations

import numpy as np

from .capstan import Capstan, FrictionJacobian


def field_gradients(triangles: np.ndarray, Bm: np.ndarray, tri: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The gradient (k, 2, 2) of the piecewise linear node field ``v`` (n, 2) in
    triangles ``tri`` (k,): ``[v_b - v_a, v_c - v_a] D_m^-1`` (for positions x, F)."""
    T = triangles[tri]
    Ds = np.stack([v[T[:, 1]] - v[T[:, 0]], v[T[:, 2]] - v[T[:, 0]]], axis=2)
    return Ds @ Bm[tri]


def rest_point_gradient(model, lam: np.ndarray) -> np.ndarray:
    """d(lambda^T R)/dX (P, 2) for the model's cable points at its current state
    (an equilibrium with its capstan weights in place), ``lam`` (n, 2) an adjoint
    (zero on clamped nodes). Every cable's rest length must be its rest
    polyline's length (module docstring)."""
    cables, mesh = model.cables, model.mesh
    rest = cables.points.positions(mesh.triangles, mesh.nodes)
    cap = model.capstan or Capstan(cables, rest, 0.0)
    x = model.positions()
    st = cap.state(cables.points.positions(mesh.triangles, x))
    cs = model.cable_state()
    fj = FrictionJacobian(cap, st, cs["tau"], cs["kc"], cs["e"], free_length=cables.a0 - cs["ac"], pm=model.point_map)
    c = cap.cable
    tau, kc, e = cs["tau"][c], cs["kc"][c], cs["e"][c]
    ratio = (cs["ac"] / cables.a0)[c]
    n = st.n
    Lam = model.point_map.to_points(lam)
    dLam = fj.segment_diff(Lam)
    psi = (n * dLam).sum(axis=1)
    Psi = np.bincount(c, st.w * psi, minlength=cables.n_cables)[c]
    # partials of lambda^T R_c w.r.t. the interpolated adjoint, the deformed points and l0
    d_Lam = fj.segment_forces(tau * st.w, n)
    h = (dLam - n * psi[:, None]) / np.maximum(st.l, 1e-300)[:, None]
    d_p = (fj.segment_forces(Psi * kc * st.w, n) + fj.segment_forces(tau * st.w, h)
           + fj.weight_forces(Psi * fj.dtau_dw + tau * psi))
    d_l0 = -Psi * kc * (1.0 + e) * (1.0 - ratio) * st.w
    rest_d = rest[cap.seg[:, 1]] - rest[cap.seg[:, 0]]
    m = rest_d / np.maximum(np.linalg.norm(rest_d, axis=1), 1e-300)[:, None]
    # chain to the rest positions: dp/dX = F, dLambda/dX = G_lambda
    tri = cables.points.tri
    F = field_gradients(mesh.triangles, model.Bm, tri, x)
    G = field_gradients(mesh.triangles, model.Bm, tri, np.asarray(lam).reshape(-1, 2))
    return (np.einsum("kij,ki->kj", F, d_p) + np.einsum("kij,ki->kj", G, d_Lam)
            + fj.segment_forces(d_l0, m))
