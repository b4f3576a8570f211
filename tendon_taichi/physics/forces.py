"""The physics of body + cables in Taichi: energy, forces and Hessian products of
``E_tot(x, ac) = E_body(x) + E_g(x) + sum_c U_c(x, ac)`` (``docs/method.md``):

* ``E_body``: compressible Neo-Hookean constant-strain triangles,
  ``sum_e h A_e psi(F_e)`` with ``F_e = D_s D_m^-1``;
* ``E_g = -sum_i m_i g . x_i`` with lumped masses;
* ``U_c = EA_c a_c Z(e_c)``, ``a_c = rho_c (a0_c - ac_c)``, ``e_c = (L_c - a_c)/a_c``,
  ``L_c(x) = sum_s w_s l_s`` the weighted length of cable ``c`` (the sum of its
  segment lengths for a frictionless cable, whose weights ``w_s`` and factor
  ``rho_c`` are 1). Capstan friction (:mod:`.capstan`) sets ``w_s = exp(-mu
  Theta_s)`` and ``rho_c = sum_s w_s l0_s / sum_s l0_s`` from the current
  angles and keeps them frozen inside each Newton step, so that segment ``s``
  pulls with ``w_s tau``.

Derived cable quantities (per cable, at the model's positions): tension
``tau = dU/dL = EA Z'(e)`` (N), ``kc = dtau/dL = EA Z''(e)/a`` (N/m) and
``tau_ac = dtau/dac = EA Z''(e) L rho/a^2`` (N/m). The mixed derivative of the
energy is ``d2E/(dx dac_c) = tau_ac_c dL_c/dx``.

Node forces are *gathered* per node (no atomics) and sums run over fixed
blocks, so results are bit-for-bit deterministic. ``serial`` is a compile-time
switch: small models run their loops serialized (on the CPU a parallel loop
costs ~0.1 ms to dispatch: benchmarks/kernel_launch.py), large ones in parallel where there are threads to
spare (:func:`~.runtime.parallel_threshold`); every kernel exists at
most twice per process. The ``k_`` functions are kernels (one launch each).
"""

from .buffers import (F64, I32, dot_nodes, get_f, get_m2, get_m4, get_sc, get_v, set_f, set_m2, set_m4, set_sc,
                      set_v, sum_array, vec2)
from .energies import (mat2, neo_hookean_dPdF, neo_hookean_P, neo_hookean_psi, project_psd4, spd_inverse2,
                       tangent_apply, zcq, zcq_d1, zcq_d2)
from .launch import kernel
from .layout import Scalar, Slot
from .runtime import ti

#: an element's Hessian block (its corners' x, y) and a segment's node weights
mat6 = ti.types.matrix(6, 6, ti.f64)
vec6 = ti.types.vector(6, ti.f64)


# ---------------------------------------------------------------- elements
@ti.func
def deformation_gradient(fb: ti.template(), ib: ti.template(), xslot, e) -> mat2:
    """F_e = D_s D_m^-1 for the positions stored at ``xslot``."""
    ot = ib[Slot.TRI] + 3 * e
    a, b, c = ib[ot], ib[ot + 1], ib[ot + 2]
    xa = get_v(fb, ib, xslot, a)
    d1 = get_v(fb, ib, xslot, b) - xa
    d2 = get_v(fb, ib, xslot, c) - xa
    Ds = mat2([[d1[0], d2[0]], [d1[1], d2[1]]])
    return Ds @ get_m2(fb, ib, Slot.BM, e)


@ti.func
def store_element_vectors(fb: ti.template(), ib: ti.template(), e, G: mat2):
    """Nodal vectors of element e from G = dE/dDs (columns: its nodes 1 and 2)."""
    c1 = vec2(G[0, 0], G[1, 0])
    c2 = vec2(G[0, 1], G[1, 1])
    o = ib[Slot.EV] + 6 * e
    fb[o], fb[o + 1] = -(c1[0] + c2[0]), -(c1[1] + c2[1])
    fb[o + 2], fb[o + 3] = c1[0], c1[1]
    fb[o + 4], fb[o + 5] = c2[0], c2[1]


# ---------------------------------------------------------------- cables
@ti.func
def embedded_point(fb: ti.template(), ib: ti.template(), xslot, p) -> vec2:
    """Position of embedded point p for the positions at ``xslot``."""
    ot = ib[Slot.TRI] + 3 * ib[ib[Slot.PT_TRI] + p]
    ob = ib[Slot.PT_BARY] + 3 * p
    return (fb[ob] * get_v(fb, ib, xslot, ib[ot]) + fb[ob + 1] * get_v(fb, ib, xslot, ib[ot + 1])
            + fb[ob + 2] * get_v(fb, ib, xslot, ib[ot + 2]))


@ti.func
def segment_vector(fb: ti.template(), ib: ti.template(), xslot, s) -> vec2:
    """End minus start of segment s for the node vectors at ``xslot``."""
    os = ib[Slot.SEG] + 3 * s
    return embedded_point(fb, ib, xslot, ib[os + 1]) - embedded_point(fb, ib, xslot, ib[os])


@ti.func
def cable_sum(fb: ti.template(), ib: ti.template(), slot, c) -> ti.f64:
    """The sum of a per-segment value over the segments of cable c, each weighted
    by its capstan weight (single-segment cables have none)."""
    total = 0.0
    if ib[Slot.SINGLE] != 0:
        total = get_f(fb, ib, slot, c)
    else:
        for s in range(ib[ib[Slot.CAB_START] + c], ib[ib[Slot.CAB_START] + c + 1]):
            total += get_f(fb, ib, Slot.SEG_WT, s) * get_f(fb, ib, slot, s)
    return total


@ti.func
def update_cables(fb: ti.template(), ib: ti.template(), xslot, serial: ti.template()):
    """Segment geometry, cable lengths, tensions, stiffnesses and energies at ``xslot``."""
    ti.loop_config(serialize=serial)
    for s in range(ib[Slot.S]):
        d = segment_vector(fb, ib, xslot, s)
        l = d.norm()
        set_f(fb, ib, Slot.SEG_L, s, l)
        nv = vec2(0.0, 0.0)
        if l > 0.0:
            nv = d / l
        set_v(fb, ib, Slot.SEG_N, s, nv)
    eps = get_sc(fb, ib, Scalar.EPS)
    ti.loop_config(serialize=serial)
    for c in range(ib[Slot.C]):
        L = cable_sum(fb, ib, Slot.SEG_L, c)
        rho = get_f(fb, ib, Slot.RHO, c)
        a = rho * (get_f(fb, ib, Slot.A0, c) - get_f(fb, ib, Slot.AC, c))
        e = L / a - 1.0
        EA = get_f(fb, ib, Slot.EA, c)
        set_f(fb, ib, Slot.L, c, L)
        set_f(fb, ib, Slot.TAU, c, EA * zcq_d1(e, eps))
        set_f(fb, ib, Slot.KC, c, EA * zcq_d2(e, eps) / a)
        set_f(fb, ib, Slot.TAU_AC, c, EA * zcq_d2(e, eps) * L * rho / (a * a))
        set_f(fb, ib, Slot.CE, c, EA * a * zcq(e, eps))


@ti.func
def segment_vectors_along(fb: ti.template(), ib: ti.template(), coef, serial: ti.template()):
    """SEG_VEC = k_c w_s n_s for each segment s of cable c, k the per-cable array at
    ``coef`` (tensions: the cable forces; any factors: sum_c k_c dL_c/dx), w_s the
    segment's capstan weight."""
    ti.loop_config(serialize=serial)
    for s in range(ib[Slot.S]):
        c = ib[ib[Slot.SEG] + 3 * s + 2]
        k = get_f(fb, ib, coef, c) * get_f(fb, ib, Slot.SEG_WT, s)
        set_v(fb, ib, Slot.SEG_VEC, s, k * get_v(fb, ib, Slot.SEG_N, s))


# ---------------------------------------------------------------- body + cables
@ti.func
def gather(fb: ti.template(), ib: ti.template(), dst, elems: ti.template(), masked: ti.template(), serial: ti.template()):
    """dst_i = sum of the element vectors (if ``elems``) and the segment vectors
    (times their signed barycentric weights) incident to node i."""
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        acc = vec2(0.0, 0.0)
        if ti.static(elems):
            for k in range(ib[ib[Slot.NE_START] + i], ib[ib[Slot.NE_START] + i + 1]):
                ek = ib[ib[Slot.NE] + k]
                o = ib[Slot.EV] + 2 * ek  # ek = 3 e + corner; 6 e + 2 corner
                acc += vec2(fb[o], fb[o + 1])
        for k in range(ib[ib[Slot.NS_START] + i], ib[ib[Slot.NS_START] + i + 1]):
            acc += fb[ib[Slot.NS_COEF] + k] * get_v(fb, ib, Slot.SEG_VEC, ib[ib[Slot.NS] + k])
        if ti.static(masked):
            acc *= get_v(fb, ib, Slot.MASK, i)
        set_v(fb, ib, dst, i, acc)


@ti.func
def energy(fb: ti.template(), ib: ti.template(), xslot, serial: ti.template()):
    """scalars[S0] = E_tot at xslot; scalars[JMIN] = the smallest det F."""
    set_sc(fb, ib, Scalar.JMIN, 1e300)
    mu, lam = get_sc(fb, ib, Scalar.MU), get_sc(fb, ib, Scalar.LAM)
    ti.loop_config(serialize=serial)
    for e in range(ib[Slot.M]):
        Fe = deformation_gradient(fb, ib, xslot, e)
        J = Fe.determinant()
        ti.atomic_min(fb[ib[Slot.SCALARS] + Scalar.JMIN], J)
        psi = 0.0
        if J > 0.0:
            psi = neo_hookean_psi(Fe, mu, lam)
        set_f(fb, ib, Slot.EE, e, get_f(fb, ib, Slot.VOL, e) * psi)
    update_cables(fb, ib, xslot, serial)
    sum_array(fb, ib, Slot.EE, ib[Slot.M], Scalar.S0, serial=serial)
    body = get_sc(fb, ib, Scalar.S0)
    sum_array(fb, ib, Slot.CE, ib[Slot.C], Scalar.S0, serial=serial)
    cables = get_sc(fb, ib, Scalar.S0)
    dot_nodes(fb, ib, Slot.FEXT, xslot, Scalar.S0, serial=serial)
    set_sc(fb, ib, Scalar.S0, body + cables - get_sc(fb, ib, Scalar.S0))


@ti.func
def gradient(fb: ti.template(), ib: ti.template(), serial: ti.template()):
    """G = dE_tot/dx at X (all nodes); scalars[S0] = |G|^2 over the free DOFs."""
    mu, lam = get_sc(fb, ib, Scalar.MU), get_sc(fb, ib, Scalar.LAM)
    ti.loop_config(serialize=serial)
    for e in range(ib[Slot.M]):
        P = neo_hookean_P(deformation_gradient(fb, ib, Slot.X, e), mu, lam)
        store_element_vectors(fb, ib, e, get_f(fb, ib, Slot.VOL, e) * P @ get_m2(fb, ib, Slot.BM, e).transpose())
    update_cables(fb, ib, Slot.X, serial)
    segment_vectors_along(fb, ib, Slot.TAU, serial)
    gather(fb, ib, Slot.G, True, False, serial=serial)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        g = get_v(fb, ib, Slot.G, i) - get_v(fb, ib, Slot.FEXT, i)
        set_v(fb, ib, Slot.G, i, g)
        set_v(fb, ib, Slot.VOUT, i, g * get_v(fb, ib, Slot.MASK, i))
    dot_nodes(fb, ib, Slot.VOUT, Slot.VOUT, Scalar.S0, serial=serial)


@ti.func
def element_diag_block(fb: ti.template(), ib: ti.template(), e, k) -> mat2:
    """The (k, k) 2x2 block of element e's Hessian."""
    B = get_m2(fb, ib, Slot.BM, e)
    gk = vec2(B[0, 0], B[0, 1])
    if k == 2:
        gk = vec2(B[1, 0], B[1, 1])
    elif k == 0:
        gk = -vec2(B[0, 0] + B[1, 0], B[0, 1] + B[1, 1])
    D = get_m4(fb, ib, Slot.D, e)
    H = mat2(0.0)
    for a, j, b, l in ti.static(ti.ndrange(2, 2, 2, 2)):
        H[a, b] += D[2 * a + j, 2 * b + l] * gk[j] * gk[l]
    return get_f(fb, ib, Slot.VOL, e) * H


@ti.func
def segment_stiffness(fb: ti.template(), ib: ti.template(), s) -> mat2:
    """w tau/l (I - n n^T) + w^2 kc n n^T of segment s alone (PSD), w its capstan weight."""
    c = ib[ib[Slot.SEG] + 3 * s + 2]
    w = get_f(fb, ib, Slot.SEG_WT, s)
    nv = get_v(fb, ib, Slot.SEG_N, s)
    l = get_f(fb, ib, Slot.SEG_L, s)
    K = get_f(fb, ib, Slot.KC, c) * w * w * nv.outer_product(nv)
    if l > 0.0:
        K += get_f(fb, ib, Slot.TAU, c) * w / l * (ti.Matrix.identity(ti.f64, 2) - nv.outer_product(nv))
    return K


@ti.func
def hessian(fb: ti.template(), ib: ti.template(), project: ti.i32, jacobi: ti.template(), serial: ti.template()):
    """Element tangents D (exact, or PSD-projected if ``project``), cable stiffnesses
    at X, and (if ``jacobi``) the block-Jacobi preconditioner."""
    mu, lam = get_sc(fb, ib, Scalar.MU), get_sc(fb, ib, Scalar.LAM)
    ti.loop_config(serialize=serial)
    for e in range(ib[Slot.M]):
        D = neo_hookean_dPdF(deformation_gradient(fb, ib, Slot.X, e), mu, lam)
        if project != 0:
            D = project_psd4(0.5 * (D + D.transpose()))
        set_m4(fb, ib, Slot.D, e, D)
    update_cables(fb, ib, Slot.X, serial)
    if ti.static(jacobi):
        block_jacobi(fb, ib, serial)


@ti.func
def block_jacobi(fb: ti.template(), ib: ti.template(), serial: ti.template()):
    """MINV: per node the inverse of its 2x2 diagonal Hessian block (zero on clamped nodes)."""
    floor = get_sc(fb, ib, Scalar.FLOOR)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        H = mat2(0.0)
        for k in range(ib[ib[Slot.NE_START] + i], ib[ib[Slot.NE_START] + i + 1]):
            ek = ib[ib[Slot.NE] + k]
            H += element_diag_block(fb, ib, ek // 3, ek % 3)
        for k in range(ib[ib[Slot.NS_START] + i], ib[ib[Slot.NS_START] + i + 1]):
            cf = fb[ib[Slot.NS_COEF] + k]
            H += cf * cf * segment_stiffness(fb, ib, ib[ib[Slot.NS] + k])
        Minv = spd_inverse2(H, floor)
        if get_v(fb, ib, Slot.MASK, i)[0] == 0.0:
            Minv = mat2(0.0)
        set_m2(fb, ib, Slot.MINV, i, Minv)


@ti.func
def segment_directional(fb: ti.template(), ib: ti.template(), src, serial: ti.template()):
    """SEG_DD = change of each segment vector along src; CW = dL_c/dx . src (L the
    weighted length)."""
    ti.loop_config(serialize=serial)
    for s in range(ib[Slot.S]):
        dd = segment_vector(fb, ib, src, s)
        set_v(fb, ib, Slot.SEG_DD, s, dd)
        set_f(fb, ib, Slot.SEG_W, s, get_v(fb, ib, Slot.SEG_N, s).dot(dd))
    ti.loop_config(serialize=serial)
    for c in range(ib[Slot.C]):
        set_f(fb, ib, Slot.CW, c, cable_sum(fb, ib, Slot.SEG_W, c))


@ti.func
def apply_hessian(fb: ti.template(), ib: ti.template(), src, dst, masked: ti.template(), serial: ti.template()):
    """dst = H src, H as prepared by hessian (``masked``: the free-free block)."""
    ti.loop_config(serialize=serial)
    for e in range(ib[Slot.M]):
        ot = ib[Slot.TRI] + 3 * e
        a, b, c = ib[ot], ib[ot + 1], ib[ot + 2]
        sa = get_v(fb, ib, src, a)
        d1 = get_v(fb, ib, src, b) - sa
        d2 = get_v(fb, ib, src, c) - sa
        B = get_m2(fb, ib, Slot.BM, e)
        dP = tangent_apply(get_m4(fb, ib, Slot.D, e), mat2([[d1[0], d2[0]], [d1[1], d2[1]]]) @ B)
        store_element_vectors(fb, ib, e, get_f(fb, ib, Slot.VOL, e) * dP @ B.transpose())
    segment_directional(fb, ib, src, serial)
    ti.loop_config(serialize=serial)
    for s in range(ib[Slot.S]):
        c = ib[ib[Slot.SEG] + 3 * s + 2]
        w = get_f(fb, ib, Slot.SEG_WT, s)
        nv = get_v(fb, ib, Slot.SEG_N, s)
        dd = get_v(fb, ib, Slot.SEG_DD, s)
        v = get_f(fb, ib, Slot.KC, c) * get_f(fb, ib, Slot.CW, c) * w * nv
        l = get_f(fb, ib, Slot.SEG_L, s)
        if l > 0.0:
            v += get_f(fb, ib, Slot.TAU, c) * w / l * (dd - nv * nv.dot(dd))
        set_v(fb, ib, Slot.SEG_VEC, s, v)
    gather(fb, ib, dst, True, masked, serial=serial)


# ---------------------------------------------------------------- kernels
@kernel
def k_energy(fb: F64, ib: I32, xslot: ti.i32, serial: ti.template()) -> vec2:
    energy(fb, ib, xslot, serial)
    return vec2(get_sc(fb, ib, Scalar.S0), get_sc(fb, ib, Scalar.JMIN))


@kernel
def k_gradient(fb: F64, ib: I32, g_out: ti.types.ndarray(dtype=ti.f64, ndim=1),
                serial: ti.template()) -> ti.f64:
    """G = dE_tot/dx (also copied to g_out as 2n values); returns |G_free|^2."""
    gradient(fb, ib, serial)
    ti.loop_config(serialize=serial)
    for i in range(ib[Slot.N]):
        g = get_v(fb, ib, Slot.G, i)
        g_out[2 * i], g_out[2 * i + 1] = g[0], g[1]
    return get_sc(fb, ib, Scalar.S0)


@kernel
def k_hessian(fb: F64, ib: I32, project: ti.i32, jacobi: ti.template(), serial: ti.template()):
    hessian(fb, ib, project, jacobi, serial)


@ti.func
def shape_gradient(B: mat2, a) -> vec2:
    """grad N_a of corner a from D_m^-1 (rows: corners 1 and 2)."""
    g = -vec2(B[0, 0] + B[1, 0], B[0, 1] + B[1, 1])
    if a == 1:
        g = vec2(B[0, 0], B[0, 1])
    elif a == 2:
        g = vec2(B[1, 0], B[1, 1])
    return g


@ti.func
def element_block(fb: ti.template(), ib: ti.template(), e) -> mat6:
    """Element e's Hessian block as last prepared, (6, 6) over its corners' x, y:
    ``vol grad N_a . D . grad N_b`` for corners a, b."""
    B = get_m2(fb, ib, Slot.BM, e)
    D = get_m4(fb, ib, Slot.D, e)
    vol = get_f(fb, ib, Slot.VOL, e)
    out = mat6(0.0)
    for a, b in ti.static(ti.ndrange(3, 3)):
        ga, gb = shape_gradient(B, a), shape_gradient(B, b)
        for k, l in ti.static(ti.ndrange(2, 2)):
            h = 0.0
            for j, m in ti.static(ti.ndrange(2, 2)):
                h += ga[j] * D[2 * k + j, 2 * l + m] * gb[m]
            out[2 * a + k, 2 * b + l] = vol * h
    return out


@ti.func
def segment_weights(fb: ti.template(), ib: ti.template(), s) -> vec6:
    """Segment s's signed barycentric weights over the 6 nodes of its two points:
    -start point's, then +end point's."""
    os = ib[Slot.SEG] + 3 * s
    coef = vec6(0.0)
    for k in ti.static(range(3)):
        coef[k] = -fb[ib[Slot.PT_BARY] + 3 * ib[os] + k]
        coef[3 + k] = fb[ib[Slot.PT_BARY] + 3 * ib[os + 1] + k]
    return coef


@ti.func
def segment_block(fb: ti.template(), ib: ti.template(), s) -> mat2:
    """K of segment s's Hessian block ``coef_a coef_b K`` (nodes a, b of its points,
    :func:`segment_weights`): ``tau w / l (I - n n^T)``, plus the axial term
    ``kc n n^T`` of a single-segment cable."""
    c = ib[ib[Slot.SEG] + 3 * s + 2]
    nv = get_v(fb, ib, Slot.SEG_N, s)
    l = get_f(fb, ib, Slot.SEG_L, s)
    K = mat2(0.0)
    if l > 0.0:
        K = get_f(fb, ib, Slot.TAU, c) * get_f(fb, ib, Slot.SEG_WT, s) / l * (
            ti.Matrix.identity(ti.f64, 2) - nv.outer_product(nv))
    if ib[Slot.SINGLE] != 0:
        K += get_f(fb, ib, Slot.KC, c) * nv.outer_product(nv)
    return K


@ti.func
def hessian_blocks(fb: ti.template(), ib: ti.template(), out: ti.template(), scatter: ti.template(),
                   summed: ti.template(), serial: ti.template()):
    """Every block entry v_k of the Hessian as last prepared, in the order k: element
    e's 36 from ``36 e`` ((6, 6) row-major over its corners' x, y), then segment s's
    144 from ``36 m + 144 s`` (over the 6 nodes of its two points), with their capstan
    weights; single-segment cables include their axial term kc dL/dx dL/dx^T.
    ``out[k] = v_k``, or with ``summed`` ``out[scatter[k]] += v_k`` - serially, so
    that each sum takes its terms in the order k."""
    ti.loop_config(serialize=serial or summed)
    for e in range(ib[Slot.M]):
        He = element_block(fb, ib, e)
        for r in ti.static(range(6)):
            for c in ti.static(range(6)):
                put_entry(out, scatter, 36 * e + 6 * r + c, He[r, c], summed)
    base = 36 * ib[Slot.M]
    ti.loop_config(serialize=serial or summed)
    for s in range(ib[Slot.S]):
        coef, K = segment_weights(fb, ib, s), segment_block(fb, ib, s)
        for a in range(6):  # entry 12 (2 a + i) + 2 b + j
            for i in ti.static(range(2)):
                for b in range(6):
                    cab = coef[a] * coef[b]
                    for j in ti.static(range(2)):
                        put_entry(out, scatter, base + 144 * s + 12 * (2 * a + i) + 2 * b + j, cab * K[i, j],
                                  summed)


@ti.func
def put_entry(out: ti.template(), scatter: ti.template(), k, v, summed: ti.template()):
    if ti.static(summed):
        out[scatter[k]] += v
    else:
        out[k] = v


@kernel
def k_hessian_entries(fb: F64, ib: I32, out: ti.types.ndarray(dtype=ti.f64, ndim=1),
                       serial: ti.template()):
    """The Hessian's block entries (:func:`hessian_blocks`), (36 m + 144 S,): for the
    direct backend's assembly and its tests."""
    hessian_blocks(fb, ib, out, out, False, serial=serial)  # no scatter: out passed in its place


@kernel
def k_hessian_sums(fb: F64, ib: I32, scatter: ti.types.ndarray(dtype=ti.i32, ndim=1),
                    out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """``out[scatter[k]] += v_k`` for the block entries v (:func:`hessian_blocks`),
    ``out`` zeroed first: ``np.bincount(scatter, weights=v)`` to the bit, for any
    ``scatter``, without the entries' list (1.6 M at level 5, whose writing and
    reading cost more than the sums). Serial whatever the model's size: the order
    is the sums' round-off. ``scatter`` unchecked: every bin in ``out``."""
    ti.loop_config(serialize=True)
    for q in range(out.shape[0]):
        out[q] = 0.0
    hessian_blocks(fb, ib, out, scatter, True, serial=True)


@kernel
def k_hessian_product(fb: F64, ib: I32, serial: ti.template()):
    apply_hessian(fb, ib, Slot.VIN, Slot.VOUT, False, serial=serial)


@kernel
def k_update_cables(fb: F64, ib: I32, serial: ti.template()):
    update_cables(fb, ib, Slot.X, serial)


@kernel
def k_cables_to_nodes(fb: F64, ib: I32, serial: ti.template()):
    """VOUT = sum_c CCOEF_c dL_c/dx."""
    update_cables(fb, ib, Slot.X, serial)
    segment_vectors_along(fb, ib, Slot.CCOEF, serial)
    gather(fb, ib, Slot.VOUT, False, False, serial=serial)


@kernel
def k_nodes_to_cables(fb: F64, ib: I32, serial: ti.template()):
    """CW = dL_c/dx . VIN."""
    update_cables(fb, ib, Slot.X, serial)
    segment_directional(fb, ib, Slot.VIN, serial)


