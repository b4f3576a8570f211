"""The energy densities of the body and the fibers (``docs/method.md``) as Taichi
functions, for :mod:`.forces`.

Neo-Hookean (compressible), per unit reference volume, with F the 2x2
deformation gradient and J = det F::

    psi(F) = mu/2 (tr(F^T F) - 2) - mu ln J + lam/2 (ln J)^2
    P(F)   = mu (F - F^-T) + lam ln J F^-T                       (first Piola-Kirchhoff)
    dP     = mu dF + (mu - lam ln J) F^-T dF^T F^-T + lam tr(F^-1 dF) F^-T

The 4x4 tangent ``dP/dF`` is indexed by row-major vec(F): entry (2i+j, 2k+l)
is dP_ij / dF_kl.

Unilateral "zero-cubic-quadratic" strain energy per unit strain, C2 in e::

    Z(e) = 0                              e <= 0
         = e^3 / (6 eps)                  0 < e <= eps
         = e^2/2 - eps e/2 + eps^2/6      e > eps
"""


from .runtime import ti

mat2 = ti.types.matrix(2, 2, ti.f64)
mat4 = ti.types.matrix(4, 4, ti.f64)


@ti.func
def zcq(e: ti.f64, eps: ti.f64) -> ti.f64:
    """Z(e)."""
    z = 0.0
    if e > eps:
        z = 0.5 * e * e - 0.5 * eps * e + eps * eps / 6.0
    elif e > 0.0:
        z = e * e * e / (6.0 * eps)
    return z


@ti.func
def zcq_d1(e: ti.f64, eps: ti.f64) -> ti.f64:
    """Z'(e)."""
    z = 0.0
    if e > eps:
        z = e - 0.5 * eps
    elif e > 0.0:
        z = e * e / (2.0 * eps)
    return z


@ti.func
def zcq_d2(e: ti.f64, eps: ti.f64) -> ti.f64:
    """Z''(e)."""
    z = 0.0
    if e > eps:
        z = 1.0
    elif e > 0.0:
        z = e / eps
    return z


@ti.func
def neo_hookean_psi(F: mat2, mu: ti.f64, lam: ti.f64) -> ti.f64:
    """psi(F), J/m^3; only meaningful for det F > 0."""
    lnJ = ti.log(F.determinant())
    return 0.5 * mu * ((F.transpose() @ F).trace() - 2.0) - mu * lnJ + 0.5 * lam * lnJ * lnJ


@ti.func
def neo_hookean_P(F: mat2, mu: ti.f64, lam: ti.f64) -> mat2:
    """First Piola-Kirchhoff stress P(F), Pa."""
    FinvT = F.inverse().transpose()
    lnJ = ti.log(F.determinant())
    return mu * (F - FinvT) + lam * lnJ * FinvT


@ti.func
def neo_hookean_dPdF(F: mat2, mu: ti.f64, lam: ti.f64) -> mat4:
    """The exact tangent dP/dF (4x4, row-major vec(F)), Pa."""
    Fi = F.inverse()
    lnJ = ti.log(F.determinant())
    c = mu - lam * lnJ
    D = mat4(0.0)
    for i, j, k, l in ti.static(ti.ndrange(2, 2, 2, 2)):
        v = c * Fi[l, i] * Fi[j, k] + lam * Fi[j, i] * Fi[l, k]
        if ti.static(i == k and j == l):
            v += mu
        D[2 * i + j, 2 * k + l] = v
    return D


@ti.func
def tangent_apply(D: mat4, dF: mat2) -> mat2:
    """dP = D : dF."""
    dP = mat2(0.0)
    for i, j, k, l in ti.static(ti.ndrange(2, 2, 2, 2)):
        dP[i, j] += D[2 * i + j, 2 * k + l] * dF[k, l]
    return dP


@ti.func
def project_psd4(A: mat4) -> mat4:
    """Nearest positive semi-definite matrix to a symmetric 4x4 ``A``: negative
    eigenvalues clamped to zero (cyclic Jacobi eigen-decomposition)."""
    B = A
    V = ti.Matrix.identity(ti.f64, 4)
    for _sweep in range(16):
        off = 0.0
        for p, q in ti.static([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]):
            off += B[p, q] * B[p, q]
        scale = 0.0
        for p in ti.static(range(4)):
            scale += B[p, p] * B[p, p]
        if off <= 1e-30 * scale or off == 0.0:
            break
        for p, q in ti.static([(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]):
            apq = B[p, q]
            if apq != 0.0:
                theta = (B[q, q] - B[p, p]) / (2.0 * apq)
                t = 0.0
                if ti.abs(theta) > 1e150:
                    t = 0.5 / theta
                else:
                    t = 1.0 / (ti.abs(theta) + ti.sqrt(theta * theta + 1.0))
                    if theta < 0.0:
                        t = -t
                c = 1.0 / ti.sqrt(t * t + 1.0)
                s = t * c
                for k in ti.static(range(4)):  # B <- B J
                    bkp, bkq = B[k, p], B[k, q]
                    B[k, p] = c * bkp - s * bkq
                    B[k, q] = s * bkp + c * bkq
                for k in ti.static(range(4)):  # B <- J^T B
                    bpk, bqk = B[p, k], B[q, k]
                    B[p, k] = c * bpk - s * bqk
                    B[q, k] = s * bpk + c * bqk
                for k in ti.static(range(4)):  # V <- V J
                    vkp, vkq = V[k, p], V[k, q]
                    V[k, p] = c * vkp - s * vkq
                    V[k, q] = s * vkp + c * vkq
    R = mat4(0.0)
    for k in ti.static(range(4)):
        lam_k = ti.max(B[k, k], 0.0)
        for i, j in ti.static(ti.ndrange(4, 4)):
            R[i, j] += lam_k * V[i, k] * V[j, k]
    return R


@ti.func
def spd_inverse2(A: mat2, floor: ti.f64) -> mat2:
    """Inverse of a symmetric 2x2 block made positive definite (eigenvalues
    replaced by max(|lambda|, floor)): a safe block-Jacobi preconditioner."""
    a, b, d = A[0, 0], 0.5 * (A[0, 1] + A[1, 0]), A[1, 1]
    mean = 0.5 * (a + d)
    rad = ti.sqrt(0.25 * (a - d) * (a - d) + b * b)
    l1 = ti.max(ti.abs(mean + rad), floor)
    l2 = ti.max(ti.abs(mean - rad), floor)
    # eigenvector of the larger eigenvalue
    vx, vy = 1.0, 0.0
    if rad > 1e-300:
        if a >= d:
            vx, vy = a - mean + rad, b
        else:
            vx, vy = b, d - mean + rad
        nrm = ti.sqrt(vx * vx + vy * vy)
        vx, vy = vx / nrm, vy / nrm
    # A^-1 = v v^T / l1 + w w^T / l2 with w = (-vy, vx)
    return mat2([[vx * vx / l1 + vy * vy / l2, vx * vy / l1 - vx * vy / l2],
                 [vx * vy / l1 - vx * vy / l2, vy * vy / l1 + vx * vx / l2]])
