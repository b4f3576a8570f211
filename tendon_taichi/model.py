"""The Taichi model: energies, forces and Hessian products of body + cables.

``E_tot(x, ac) = E_body(x) + E_g(x) + sum_c U_c(x, ac)`` (DESIGN.md section 2):

* ``E_body``: compressible Neo-Hookean constant-strain triangles,
  ``sum_e h A_e psi(F_e)`` with ``F_e = D_s D_m^-1``;
* ``E_g = -sum_i m_i g . x_i`` with lumped masses;
* ``U_c = EA_c a_c Z(e_c)``, ``a_c = a0_c - ac_c``, ``e_c = (L_c - a_c)/a_c``,
  ``L_c(x)`` the length of cable ``c`` (the sum of its segment lengths).

Derived cable quantities (per cable, at the model's positions): tension
``tau = dU/dL = EA Z'(e)`` (N), ``kc = dtau/dL = EA Z''(e)/a`` (N/m) and
``tau_ac = dtau/dac = EA Z''(e) L/a^2`` (N/m). The mixed derivative of the
energy is ``d2E/(dx dac_c) = tau_ac_c dL_c/dx``.

Storage: every array of a model lives in two flat Taichi ndarrays allocated
once per model, ``F`` (f64) and ``I`` (i32); ``I`` starts with a table of
sizes and offsets (the ``_`` slots below). Kernels are module-level and take
``(F, I)``, so they compile once per process and serve every model (a new
mesh, a sweep case, a realizable robot) without recompiling, at a launch
cost of a few tens of microseconds. Node forces are *gathered* per node (no
atomics) and sums run over fixed blocks, so results are bit-for-bit
deterministic. Small models run their loops serialized (on the CPU a
parallel loop costs ~0.1 ms to dispatch), large ones in parallel.
"""

from dataclasses import dataclass

import numpy as np

from . import runtime
from .cables import CableSet
from .energies import (mat2, mat4, neo_hookean_dPdF, neo_hookean_P, neo_hookean_psi,
                       project_psd4, spd_inverse2, tangent_apply, zcq, zcq_d1, zcq_d2)
from .mesh import Mesh
from .runtime import ti
from .scene import Material

vec2 = ti.types.vector(2, ti.f64)
vec3 = ti.types.vector(3, ti.f64)
F64 = ti.types.ndarray(dtype=ti.f64, ndim=1)
I32 = ti.types.ndarray(dtype=ti.i32, ndim=1)

#: blocks of every deterministic reduction
_NB = 32

# ---------------------------------------------------------------- layout slots
# I[slot] holds a size or the offset of an array (in F for f64 arrays, in I for ints).
_SIZES = ("N", "M", "S", "C", "P", "SINGLE")
_INTS = (  # name, length in units of (n, m, S, C, P, 1)
    ("TRI", (0, 3, 0, 0, 0, 0)),         # triangle corners
    ("NE_START", (1, 0, 0, 0, 0, 1)),    # node -> element-corner CSR starts
    ("NE", (0, 3, 0, 0, 0, 0)),          # entries 3 e + k
    ("NS_START", (1, 0, 0, 0, 0, 1)),    # node -> segment CSR starts
    ("NS", (0, 0, 6, 0, 0, 0)),          # segment ids
    ("PT_TRI", (0, 0, 0, 0, 1, 0)),      # triangle of each embedded point
    ("SEG", (0, 0, 3, 0, 0, 0)),         # per segment: point a, point b, cable
    ("CAB_START", (0, 0, 0, 1, 0, 1)),   # cable -> segment starts
    ("CG_STATE", (0, 0, 0, 0, 0, 4)),    # iterations, done, negative curvature
)
_FLOATS = (
    ("X0", (2, 0, 0, 0, 0, 0)), ("X", (2, 0, 0, 0, 0, 0)), ("XT", (2, 0, 0, 0, 0, 0)),
    ("DX", (2, 0, 0, 0, 0, 0)), ("G", (2, 0, 0, 0, 0, 0)), ("MASK", (2, 0, 0, 0, 0, 0)),
    ("FEXT", (2, 0, 0, 0, 0, 0)), ("VIN", (2, 0, 0, 0, 0, 0)), ("VOUT", (2, 0, 0, 0, 0, 0)),
    ("CB", (2, 0, 0, 0, 0, 0)), ("CX", (2, 0, 0, 0, 0, 0)), ("CR", (2, 0, 0, 0, 0, 0)),
    ("CZ", (2, 0, 0, 0, 0, 0)), ("CP", (2, 0, 0, 0, 0, 0)), ("CQ", (2, 0, 0, 0, 0, 0)),
    ("MINV", (4, 0, 0, 0, 0, 0)),        # block-Jacobi preconditioner, 2x2 per node
    ("BM", (0, 4, 0, 0, 0, 0)),          # D_m^-1 per element
    ("VOL", (0, 1, 0, 0, 0, 0)),         # h A per element
    ("D", (0, 16, 0, 0, 0, 0)),          # dP/dF per element (exact or projected)
    ("EV", (0, 6, 0, 0, 0, 0)),          # per-element nodal vectors (scratch)
    ("EE", (0, 1, 0, 0, 0, 0)),          # per-element energy
    ("NS_COEF", (0, 0, 6, 0, 0, 0)),     # signed barycentric weight of each node-segment entry
    ("PT_BARY", (0, 0, 0, 0, 3, 0)),
    ("SEG_N", (0, 0, 2, 0, 0, 0)), ("SEG_L", (0, 0, 1, 0, 0, 0)), ("SEG_DD", (0, 0, 2, 0, 0, 0)),
    ("SEG_W", (0, 0, 1, 0, 0, 0)), ("SEG_VEC", (0, 0, 2, 0, 0, 0)),
    ("A0", (0, 0, 0, 1, 0, 0)), ("AC", (0, 0, 0, 1, 0, 0)), ("EA", (0, 0, 0, 1, 0, 0)),
    ("L", (0, 0, 0, 1, 0, 0)), ("TAU", (0, 0, 0, 1, 0, 0)), ("KC", (0, 0, 0, 1, 0, 0)),
    ("TAU_AC", (0, 0, 0, 1, 0, 0)), ("CE", (0, 0, 0, 1, 0, 0)), ("CW", (0, 0, 0, 1, 0, 0)),
    ("CCOEF", (0, 0, 0, 1, 0, 0)),
    ("SCALARS", (0, 0, 0, 0, 0, 16)), ("PARTIAL", (0, 0, 0, 0, 0, _NB)),
)
_SLOTS = {name: k for k, name in enumerate(_SIZES + tuple(n for n, _ in _INTS + _FLOATS))}
globals().update({f"_{name}": k for name, k in _SLOTS.items()})
_HEADER = len(_SLOTS)
# SCALARS entries
_MU, _LAM, _EPS, _FLOOR, _S0, _S1, _S2, _JMIN, _RZ, _RR, _PQ, _BB, _TOL2 = range(13)
# CG_STATE entries
_ITERS, _DONE, _NEGCURV = range(3)


# ---------------------------------------------------------------- accessors
@ti.func
def _v(F: ti.template(), I: ti.template(), slot, i) -> vec2:
    o = I[slot] + 2 * i
    return vec2(F[o], F[o + 1])


@ti.func
def _set_v(F: ti.template(), I: ti.template(), slot, i, v: vec2):
    o = I[slot] + 2 * i
    F[o] = v[0]
    F[o + 1] = v[1]


@ti.func
def _m2(F: ti.template(), I: ti.template(), slot, i) -> mat2:
    o = I[slot] + 4 * i
    return mat2([[F[o], F[o + 1]], [F[o + 2], F[o + 3]]])


@ti.func
def _set_m2(F: ti.template(), I: ti.template(), slot, i, A: mat2):
    o = I[slot] + 4 * i
    F[o], F[o + 1], F[o + 2], F[o + 3] = A[0, 0], A[0, 1], A[1, 0], A[1, 1]


@ti.func
def _m4(F: ti.template(), I: ti.template(), slot, i) -> mat4:
    o = I[slot] + 16 * i
    A = mat4(0.0)
    for r, c in ti.static(ti.ndrange(4, 4)):
        A[r, c] = F[o + 4 * r + c]
    return A


@ti.func
def _set_m4(F: ti.template(), I: ti.template(), slot, i, A: mat4):
    o = I[slot] + 16 * i
    for r, c in ti.static(ti.ndrange(4, 4)):
        F[o + 4 * r + c] = A[r, c]


@ti.func
def _f(F: ti.template(), I: ti.template(), slot, i) -> ti.f64:
    return F[I[slot] + i]


@ti.func
def _set_f(F: ti.template(), I: ti.template(), slot, i, v: ti.f64):
    F[I[slot] + i] = v


@ti.func
def _sc(F: ti.template(), I: ti.template(), k) -> ti.f64:
    return F[I[_SCALARS] + k]


@ti.func
def _set_sc(F: ti.template(), I: ti.template(), k, v: ti.f64):
    F[I[_SCALARS] + k] = v


@ti.func
def _cg(I: ti.template(), k) -> ti.i32:
    return I[I[_CG_STATE] + k]


@ti.func
def _set_cg(I: ti.template(), k, v: ti.i32):
    I[I[_CG_STATE] + k] = v


# ---------------------------------------------------------------- building blocks
@ti.func
def _deformation_gradient(F: ti.template(), I: ti.template(), xslot, e) -> mat2:
    """F_e = D_s D_m^-1 for the positions stored at ``xslot``."""
    ot = I[_TRI] + 3 * e
    a, b, c = I[ot], I[ot + 1], I[ot + 2]
    xa = _v(F, I, xslot, a)
    d1 = _v(F, I, xslot, b) - xa
    d2 = _v(F, I, xslot, c) - xa
    Ds = mat2([[d1[0], d2[0]], [d1[1], d2[1]]])
    return Ds @ _m2(F, I, _BM, e)


@ti.func
def _store_element_vectors(F: ti.template(), I: ti.template(), e, G: mat2):
    """Nodal vectors of element e from G = dE/dDs (columns: its nodes 1 and 2)."""
    c1 = vec2(G[0, 0], G[1, 0])
    c2 = vec2(G[0, 1], G[1, 1])
    o = I[_EV] + 6 * e
    F[o], F[o + 1] = -(c1[0] + c2[0]), -(c1[1] + c2[1])
    F[o + 2], F[o + 3] = c1[0], c1[1]
    F[o + 4], F[o + 5] = c2[0], c2[1]


@ti.func
def _point(F: ti.template(), I: ti.template(), xslot, p) -> vec2:
    """Position of embedded point p for the positions at ``xslot``."""
    ot = I[_TRI] + 3 * I[I[_PT_TRI] + p]
    ob = I[_PT_BARY] + 3 * p
    return (F[ob] * _v(F, I, xslot, I[ot]) + F[ob + 1] * _v(F, I, xslot, I[ot + 1])
            + F[ob + 2] * _v(F, I, xslot, I[ot + 2]))


@ti.func
def _segment_vector(F: ti.template(), I: ti.template(), xslot, s) -> vec2:
    """End minus start of segment s for the node vectors at ``xslot``."""
    os = I[_SEG] + 3 * s
    return _point(F, I, xslot, I[os + 1]) - _point(F, I, xslot, I[os])


@ti.func
def _reduce(F: ti.template(), I: ti.template(), count, term: ti.template(), a, b, out,
            serial: ti.template()):
    """scalars[out] = sum of term(F, I, a, b, i) for i in [0, count): fixed blocks summed
    in a fixed order, so the result does not depend on threads."""
    chunk = (count + _NB - 1) // _NB
    op = I[_PARTIAL]
    ti.loop_config(serialize=serial)
    for blk in range(_NB):
        acc = 0.0
        for i in range(blk * chunk, ti.min((blk + 1) * chunk, count)):
            acc += term(F, I, a, b, i)
        F[op + blk] = acc
    total = 0.0
    for blk in ti.static(range(_NB)):
        total += F[op + blk]
    _set_sc(F, I, out, total)


@ti.func
def _node_dot(F: ti.template(), I: ti.template(), aslot, bslot, i) -> ti.f64:
    return _v(F, I, aslot, i).dot(_v(F, I, bslot, i))


@ti.func
def _entry(F: ti.template(), I: ti.template(), slot, unused, i) -> ti.f64:
    return _f(F, I, slot, i)


@ti.func
def _dot(F: ti.template(), I: ti.template(), aslot, bslot, out, serial: ti.template()):
    """scalars[out] = sum_i a_i . b_i over nodes."""
    _reduce(F, I, I[_N], _node_dot, aslot, bslot, out, serial)


@ti.func
def _sum(F: ti.template(), I: ti.template(), slot, count, out, serial: ti.template()):
    """scalars[out] = sum of the f64 array at ``slot`` over [0, count)."""
    _reduce(F, I, count, _entry, slot, 0, out, serial)


@ti.func
def _cable_sum(F: ti.template(), I: ti.template(), slot, c) -> ti.f64:
    """The sum of a per-segment value over the segments of cable c."""
    total = 0.0
    if I[_SINGLE] != 0:
        total = _f(F, I, slot, c)
    else:
        for s in range(I[I[_CAB_START] + c], I[I[_CAB_START] + c + 1]):
            total += _f(F, I, slot, s)
    return total


@ti.func
def _update_cables(F: ti.template(), I: ti.template(), xslot, serial: ti.template()):
    """Segment geometry, cable lengths, tensions, stiffnesses and energies at ``xslot``."""
    ti.loop_config(serialize=serial)
    for s in range(I[_S]):
        d = _segment_vector(F, I, xslot, s)
        l = d.norm()
        _set_f(F, I, _SEG_L, s, l)
        nv = vec2(0.0, 0.0)
        if l > 0.0:
            nv = d / l
        _set_v(F, I, _SEG_N, s, nv)
    eps = _sc(F, I, _EPS)
    ti.loop_config(serialize=serial)
    for c in range(I[_C]):
        L = _cable_sum(F, I, _SEG_L, c)
        a = _f(F, I, _A0, c) - _f(F, I, _AC, c)
        e = L / a - 1.0
        EA = _f(F, I, _EA, c)
        _set_f(F, I, _L, c, L)
        _set_f(F, I, _TAU, c, EA * zcq_d1(e, eps))
        _set_f(F, I, _KC, c, EA * zcq_d2(e, eps) / a)
        _set_f(F, I, _TAU_AC, c, EA * zcq_d2(e, eps) * L / (a * a))
        _set_f(F, I, _CE, c, EA * a * zcq(e, eps))


@ti.func
def _segment_vectors_along(F: ti.template(), I: ti.template(), coef, serial: ti.template()):
    """SEG_VEC = w_c n_s for each segment s of cable c, w the per-cable array at
    ``coef`` (tensions: the cable forces; any weights: sum_c w_c dL_c/dx)."""
    ti.loop_config(serialize=serial)
    for s in range(I[_S]):
        c = I[I[_SEG] + 3 * s + 2]
        _set_v(F, I, _SEG_VEC, s, _f(F, I, coef, c) * _v(F, I, _SEG_N, s))


@ti.func
def _gather(F: ti.template(), I: ti.template(), dst, elems: ti.template(), masked: ti.template(), serial: ti.template()):
    """dst_i = sum of the element vectors (if ``elems``) and the segment vectors
    (times their signed barycentric weights) incident to node i."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        acc = vec2(0.0, 0.0)
        if ti.static(elems):
            for k in range(I[I[_NE_START] + i], I[I[_NE_START] + i + 1]):
                ek = I[I[_NE] + k]
                o = I[_EV] + 2 * ek  # ek = 3 e + corner; 6 e + 2 corner
                acc += vec2(F[o], F[o + 1])
        for k in range(I[I[_NS_START] + i], I[I[_NS_START] + i + 1]):
            acc += F[I[_NS_COEF] + k] * _v(F, I, _SEG_VEC, I[I[_NS] + k])
        if ti.static(masked):
            acc *= _v(F, I, _MASK, i)
        _set_v(F, I, dst, i, acc)


@ti.func
def _energy(F: ti.template(), I: ti.template(), xslot, serial: ti.template()):
    """scalars[S0] = E_tot at xslot; scalars[JMIN] = the smallest det F."""
    _set_sc(F, I, _JMIN, 1e300)
    mu, lam = _sc(F, I, _MU), _sc(F, I, _LAM)
    ti.loop_config(serialize=serial)
    for e in range(I[_M]):
        Fe = _deformation_gradient(F, I, xslot, e)
        J = Fe.determinant()
        ti.atomic_min(F[I[_SCALARS] + _JMIN], J)
        psi = 0.0
        if J > 0.0:
            psi = neo_hookean_psi(Fe, mu, lam)
        _set_f(F, I, _EE, e, _f(F, I, _VOL, e) * psi)
    _update_cables(F, I, xslot, serial)
    _sum(F, I, _EE, I[_M], _S0, serial)
    body = _sc(F, I, _S0)
    _sum(F, I, _CE, I[_C], _S0, serial)
    cables = _sc(F, I, _S0)
    _dot(F, I, _FEXT, xslot, _S0, serial)
    _set_sc(F, I, _S0, body + cables - _sc(F, I, _S0))


@ti.func
def _gradient(F: ti.template(), I: ti.template(), serial: ti.template()):
    """G = dE_tot/dx at X (all nodes); scalars[S0] = |G|^2 over the free DOFs."""
    mu, lam = _sc(F, I, _MU), _sc(F, I, _LAM)
    ti.loop_config(serialize=serial)
    for e in range(I[_M]):
        P = neo_hookean_P(_deformation_gradient(F, I, _X, e), mu, lam)
        _store_element_vectors(F, I, e, _f(F, I, _VOL, e) * P @ _m2(F, I, _BM, e).transpose())
    _update_cables(F, I, _X, serial)
    _segment_vectors_along(F, I, _TAU, serial)
    _gather(F, I, _G, True, False, serial)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        g = _v(F, I, _G, i) - _v(F, I, _FEXT, i)
        _set_v(F, I, _G, i, g)
        _set_v(F, I, _VOUT, i, g * _v(F, I, _MASK, i))
    _dot(F, I, _VOUT, _VOUT, _S0, serial)


@ti.func
def _element_diag_block(F: ti.template(), I: ti.template(), e, k) -> mat2:
    """The (k, k) 2x2 block of element e's Hessian."""
    B = _m2(F, I, _BM, e)
    gk = vec2(B[0, 0], B[0, 1])
    if k == 2:
        gk = vec2(B[1, 0], B[1, 1])
    elif k == 0:
        gk = -vec2(B[0, 0] + B[1, 0], B[0, 1] + B[1, 1])
    D = _m4(F, I, _D, e)
    H = mat2(0.0)
    for a, j, b, l in ti.static(ti.ndrange(2, 2, 2, 2)):
        H[a, b] += D[2 * a + j, 2 * b + l] * gk[j] * gk[l]
    return _f(F, I, _VOL, e) * H


@ti.func
def _segment_stiffness(F: ti.template(), I: ti.template(), s) -> mat2:
    """tau/l (I - n n^T) + kc n n^T of segment s alone (PSD)."""
    c = I[I[_SEG] + 3 * s + 2]
    nv = _v(F, I, _SEG_N, s)
    l = _f(F, I, _SEG_L, s)
    K = _f(F, I, _KC, c) * nv.outer_product(nv)
    if l > 0.0:
        K += _f(F, I, _TAU, c) / l * (ti.Matrix.identity(ti.f64, 2) - nv.outer_product(nv))
    return K


@ti.func
def _hessian(F: ti.template(), I: ti.template(), project: ti.i32, serial: ti.template()):
    """Element tangents D (exact, or PSD-projected if ``project``), cable stiffnesses
    at X, and the block-Jacobi preconditioner."""
    mu, lam = _sc(F, I, _MU), _sc(F, I, _LAM)
    ti.loop_config(serialize=serial)
    for e in range(I[_M]):
        D = neo_hookean_dPdF(_deformation_gradient(F, I, _X, e), mu, lam)
        if project != 0:
            D = project_psd4(0.5 * (D + D.transpose()))
        _set_m4(F, I, _D, e, D)
    _update_cables(F, I, _X, serial)
    floor = _sc(F, I, _FLOOR)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        H = mat2(0.0)
        for k in range(I[I[_NE_START] + i], I[I[_NE_START] + i + 1]):
            ek = I[I[_NE] + k]
            H += _element_diag_block(F, I, ek // 3, ek % 3)
        for k in range(I[I[_NS_START] + i], I[I[_NS_START] + i + 1]):
            cf = F[I[_NS_COEF] + k]
            H += cf * cf * _segment_stiffness(F, I, I[I[_NS] + k])
        Minv = spd_inverse2(H, floor)
        if _v(F, I, _MASK, i)[0] == 0.0:
            Minv = mat2(0.0)
        _set_m2(F, I, _MINV, i, Minv)


@ti.func
def _segment_directional(F: ti.template(), I: ti.template(), src, serial: ti.template()):
    """SEG_DD = change of each segment vector along src; CW = dL_c/dx . src."""
    ti.loop_config(serialize=serial)
    for s in range(I[_S]):
        dd = _segment_vector(F, I, src, s)
        _set_v(F, I, _SEG_DD, s, dd)
        _set_f(F, I, _SEG_W, s, _v(F, I, _SEG_N, s).dot(dd))
    ti.loop_config(serialize=serial)
    for c in range(I[_C]):
        _set_f(F, I, _CW, c, _cable_sum(F, I, _SEG_W, c))


@ti.func
def _apply_hessian(F: ti.template(), I: ti.template(), src, dst, masked: ti.template(), serial: ti.template()):
    """dst = H src, H as prepared by _hessian (``masked``: the free-free block)."""
    ti.loop_config(serialize=serial)
    for e in range(I[_M]):
        ot = I[_TRI] + 3 * e
        a, b, c = I[ot], I[ot + 1], I[ot + 2]
        sa = _v(F, I, src, a)
        d1 = _v(F, I, src, b) - sa
        d2 = _v(F, I, src, c) - sa
        B = _m2(F, I, _BM, e)
        dP = tangent_apply(_m4(F, I, _D, e), mat2([[d1[0], d2[0]], [d1[1], d2[1]]]) @ B)
        _store_element_vectors(F, I, e, _f(F, I, _VOL, e) * dP @ B.transpose())
    _segment_directional(F, I, src, serial)
    ti.loop_config(serialize=serial)
    for s in range(I[_S]):
        c = I[I[_SEG] + 3 * s + 2]
        nv = _v(F, I, _SEG_N, s)
        dd = _v(F, I, _SEG_DD, s)
        v = _f(F, I, _KC, c) * _f(F, I, _CW, c) * nv
        l = _f(F, I, _SEG_L, s)
        if l > 0.0:
            v += _f(F, I, _TAU, c) / l * (dd - nv * nv.dot(dd))
        _set_v(F, I, _SEG_VEC, s, v)
    _gather(F, I, dst, True, masked, serial)


@ti.func
def _cg_residual(F: ti.template(), I: ti.template(), warm: ti.i32, serial: ti.template()):
    """Mask the right-hand side CB, start CX at 0 (or the last solution, ``warm``)
    and set CR = CB - H CX; scalars BB = |CB|^2 and RR = |CR|^2."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        m = _v(F, I, _MASK, i)
        _set_v(F, I, _CB, i, _v(F, I, _CB, i) * m)
        x0 = vec2(0.0, 0.0)
        if warm != 0:
            x0 = _v(F, I, _CX, i) * m
        _set_v(F, I, _CX, i, x0)
    _apply_hessian(F, I, _CX, _CQ, True, serial)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _CR, i, _v(F, I, _CB, i) - _v(F, I, _CQ, i))
    _dot(F, I, _CR, _CR, _RR, serial)
    _dot(F, I, _CB, _CB, _BB, serial)


@ti.func
def _cg_begin(F: ti.template(), I: ti.template(), warm: ti.i32, tol: ti.f64, serial: ti.template()):
    _cg_residual(F, I, warm, serial)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        z = _m2(F, I, _MINV, i) @ _v(F, I, _CR, i)
        _set_v(F, I, _CZ, i, z)
        _set_v(F, I, _CP, i, z)
    _dot(F, I, _CR, _CZ, _RZ, serial)
    _set_sc(F, I, _TOL2, tol * tol * _sc(F, I, _BB))
    _set_cg(I, _ITERS, 0)
    _set_cg(I, _NEGCURV, 0)
    _set_cg(I, _DONE, 0)
    if _sc(F, I, _RR) <= _sc(F, I, _TOL2):
        _set_cg(I, _DONE, 1)


@ti.func
def _cg_iteration(F: ti.template(), I: ti.template(), serial: ti.template()):
    """One PCG iteration; once done, alpha = 0 leaves the solution unchanged."""
    _apply_hessian(F, I, _CP, _CQ, True, serial)
    _dot(F, I, _CP, _CQ, _PQ, serial)
    alpha = 0.0
    if _cg(I, _DONE) == 0:
        if _sc(F, I, _PQ) <= 0.0:
            _set_cg(I, _NEGCURV, 1)
            _set_cg(I, _DONE, 1)
        else:
            alpha = _sc(F, I, _RZ) / _sc(F, I, _PQ)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _CX, i, _v(F, I, _CX, i) + alpha * _v(F, I, _CP, i))
        r = _v(F, I, _CR, i) - alpha * _v(F, I, _CQ, i)
        _set_v(F, I, _CR, i, r)
        _set_v(F, I, _CZ, i, _m2(F, I, _MINV, i) @ r)
    _dot(F, I, _CR, _CZ, _S1, serial)
    _dot(F, I, _CR, _CR, _RR, serial)
    beta = 0.0
    if _cg(I, _DONE) == 0:
        _set_cg(I, _ITERS, _cg(I, _ITERS) + 1)
        if _sc(F, I, _RR) <= _sc(F, I, _TOL2):
            _set_cg(I, _DONE, 1)
        beta = _sc(F, I, _S1) / _sc(F, I, _RZ)
        _set_sc(F, I, _RZ, _sc(F, I, _S1))
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _CP, i, _v(F, I, _CZ, i) + beta * _v(F, I, _CP, i))


# ---------------------------------------------------------------- kernels
# ``serial`` is a compile-time switch: every kernel exists at most twice per process.
@ti.kernel
def _k_energy(F: F64, I: I32, xslot: ti.i32, serial: ti.template()) -> vec2:
    _energy(F, I, xslot, serial)
    return vec2(_sc(F, I, _S0), _sc(F, I, _JMIN))


@ti.kernel
def _k_gradient(F: F64, I: I32, g_out: ti.types.ndarray(dtype=ti.f64, ndim=1),
                serial: ti.template()) -> ti.f64:
    """G = dE_tot/dx (also copied to g_out as 2n values); returns |G_free|^2."""
    _gradient(F, I, serial)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        g = _v(F, I, _G, i)
        g_out[2 * i], g_out[2 * i + 1] = g[0], g[1]
    return _sc(F, I, _S0)


@ti.kernel
def _k_hessian(F: F64, I: I32, project: ti.i32, serial: ti.template()):
    _hessian(F, I, project, serial)


@ti.func
def _shape_gradient(B: mat2, a) -> vec2:
    """grad N_a of corner a from D_m^-1 (rows: corners 1 and 2)."""
    g = -vec2(B[0, 0] + B[1, 0], B[0, 1] + B[1, 1])
    if a == 1:
        g = vec2(B[0, 0], B[0, 1])
    elif a == 2:
        g = vec2(B[1, 0], B[1, 1])
    return g


@ti.kernel
def _k_hessian_entries(F: F64, I: I32, out: ti.types.ndarray(dtype=ti.f64, ndim=1),
                       serial: ti.template()):
    """The Hessian's element blocks (36 per element, (6, 6) row-major over the
    corners' x, y) and segment blocks (144 per segment, over the 6 nodes of its
    two points), as last prepared; single-segment cables include their axial
    term kc dL/dx dL/dx^T. For the direct backend's assembly."""
    ti.loop_config(serialize=serial)
    for e in range(I[_M]):
        B = _m2(F, I, _BM, e)
        D = _m4(F, I, _D, e)
        vol = _f(F, I, _VOL, e)
        for a, b in ti.static(ti.ndrange(3, 3)):
            ga, gb = _shape_gradient(B, a), _shape_gradient(B, b)
            for k, l in ti.static(ti.ndrange(2, 2)):
                h = 0.0
                for j, m in ti.static(ti.ndrange(2, 2)):
                    h += ga[j] * D[2 * k + j, 2 * l + m] * gb[m]
                out[36 * e + 6 * (2 * a + k) + 2 * b + l] = vol * h
    base = 36 * I[_M]
    ti.loop_config(serialize=serial)
    for s in range(I[_S]):
        os = I[_SEG] + 3 * s
        c = I[os + 2]
        coef = ti.Vector([0.0] * 6, dt=ti.f64)
        for k in ti.static(range(3)):
            coef[k] = -F[I[_PT_BARY] + 3 * I[os] + k]
            coef[3 + k] = F[I[_PT_BARY] + 3 * I[os + 1] + k]
        nv = _v(F, I, _SEG_N, s)
        l = _f(F, I, _SEG_L, s)
        K = mat2(0.0)
        if l > 0.0:
            K = _f(F, I, _TAU, c) / l * (ti.Matrix.identity(ti.f64, 2) - nv.outer_product(nv))
        if I[_SINGLE] != 0:
            K += _f(F, I, _KC, c) * nv.outer_product(nv)
        for a, b in ti.ndrange(6, 6):
            cab = coef[a] * coef[b]
            for i, j in ti.static(ti.ndrange(2, 2)):
                out[base + 144 * s + 12 * (2 * a + i) + 2 * b + j] = cab * K[i, j]


@ti.kernel
def _k_hessian_product(F: F64, I: I32, serial: ti.template()):
    _apply_hessian(F, I, _VIN, _VOUT, False, serial)


@ti.kernel
def _k_update_cables(F: F64, I: I32, serial: ti.template()):
    _update_cables(F, I, _X, serial)


@ti.kernel
def _k_cables_to_nodes(F: F64, I: I32, serial: ti.template()):
    """VOUT = sum_c CCOEF_c dL_c/dx."""
    _update_cables(F, I, _X, serial)
    _segment_vectors_along(F, I, _CCOEF, serial)
    _gather(F, I, _VOUT, False, False, serial)


@ti.kernel
def _k_nodes_to_cables(F: F64, I: I32, serial: ti.template()):
    """CW = dL_c/dx . VIN."""
    _update_cables(F, I, _X, serial)
    _segment_directional(F, I, _VIN, serial)


@ti.kernel
def _k_cg_begin(F: F64, I: I32, warm: ti.i32, tol: ti.f64, serial: ti.template()) -> ti.i32:
    _cg_begin(F, I, warm, tol, serial)
    return _cg(I, _DONE)


@ti.kernel
def _k_cg_run(F: F64, I: I32, iterations: ti.i32) -> ti.i32:
    """A whole PCG solve in one launch (serialized models)."""
    ti.loop_config(serialize=True)
    for _ in range(iterations):
        if _cg(I, _DONE) == 0:
            _cg_iteration(F, I, True)
    return _cg(I, _DONE)


@ti.kernel
def _k_cg_step(F: F64, I: I32):
    """One PCG iteration with parallel loops."""
    _cg_iteration(F, I, False)


@ti.kernel
def _k_cg_done(I: I32) -> ti.i32:
    return _cg(I, _DONE)


# PCG driven from the host, for a preconditioner applied there (a factorization):
# three launches per iteration, the residual going out and the preconditioned one in.
NDARRAY = ti.types.ndarray(dtype=ti.f64, ndim=1)


@ti.kernel
def _k_pcg_begin(F: F64, I: I32, warm: ti.i32, r_out: NDARRAY, serial: ti.template()) -> vec2:
    """CR = CB - H CX0 (copied to r_out as 2n values); returns (|CB|^2, |CR|^2)."""
    _cg_residual(F, I, warm, serial)
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        r = _v(F, I, _CR, i)
        r_out[2 * i], r_out[2 * i + 1] = r[0], r[1]
    return vec2(_sc(F, I, _BB), _sc(F, I, _RR))


@ti.kernel
def _k_pcg_matvec(F: F64, I: I32, serial: ti.template()) -> ti.f64:
    """CQ = H CP on the free DOFs; returns CP . CQ."""
    _apply_hessian(F, I, _CP, _CQ, True, serial)
    _dot(F, I, _CP, _CQ, _PQ, serial)
    return _sc(F, I, _PQ)


@ti.kernel
def _k_pcg_update(F: F64, I: I32, alpha: ti.f64, r_out: NDARRAY, serial: ti.template()) -> ti.f64:
    """CX += alpha CP, CR -= alpha CQ (copied to r_out); returns |CR|^2."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _CX, i, _v(F, I, _CX, i) + alpha * _v(F, I, _CP, i))
        r = _v(F, I, _CR, i) - alpha * _v(F, I, _CQ, i)
        _set_v(F, I, _CR, i, r)
        r_out[2 * i], r_out[2 * i + 1] = r[0], r[1]
    _dot(F, I, _CR, _CR, _RR, serial)
    return _sc(F, I, _RR)


@ti.kernel
def _k_pcg_direction(F: F64, I: I32, z_in: NDARRAY, beta: ti.f64, serial: ti.template()):
    """CP = z + beta CP with z the preconditioned residual (masked)."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        z = vec2(z_in[2 * i], z_in[2 * i + 1]) * _v(F, I, _MASK, i)
        _set_v(F, I, _CP, i, z + beta * _v(F, I, _CP, i))


@ti.kernel
def _k_newton_rhs(F: F64, I: I32, serial: ti.template()):
    """CB = -G on the free DOFs."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _CB, i, -_v(F, I, _G, i) * _v(F, I, _MASK, i))


@ti.kernel
def _k_take_direction(F: F64, I: I32, from_cg: ti.i32, serial: ti.template()) -> ti.f64:
    """DX = CX (or CB) on the free DOFs; return G . DX."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        v = _v(F, I, _CB, i)
        if from_cg != 0:
            v = _v(F, I, _CX, i)
        _set_v(F, I, _DX, i, v * _v(F, I, _MASK, i))
    _dot(F, I, _G, _DX, _S0, serial)
    return _sc(F, I, _S0)


@ti.kernel
def _k_direction_from(F: F64, I: I32, d_in: NDARRAY, serial: ti.template()) -> ti.f64:
    """DX = d (2n values from the host) on the free DOFs; return G . DX."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _DX, i, vec2(d_in[2 * i], d_in[2 * i + 1]) * _v(F, I, _MASK, i))
    _dot(F, I, _G, _DX, _S0, serial)
    return _sc(F, I, _S0)


@ti.kernel
def _k_trial(F: F64, I: I32, alpha: ti.f64, serial: ti.template()) -> vec2:
    """XT = X + alpha DX; returns (E_tot, min det F) at XT."""
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, _XT, i, _v(F, I, _X, i) + alpha * _v(F, I, _DX, i))
    _energy(F, I, _XT, serial)
    return vec2(_sc(F, I, _S0), _sc(F, I, _JMIN))


@ti.kernel
def _k_copy_nodes(F: F64, I: I32, src: ti.i32, dst: ti.i32, serial: ti.template()):
    ti.loop_config(serialize=serial)
    for i in range(I[_N]):
        _set_v(F, I, dst, i, _v(F, I, src, i))


@ti.kernel
def _k_read(F: F64, start: ti.i32, out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    ti.loop_config(serialize=True)
    for k in range(out.shape[0]):
        out[k] = F[start + k]


@ti.kernel
def _k_write(F: F64, start: ti.i32, src: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    ti.loop_config(serialize=True)
    for k in range(src.shape[0]):
        F[start + k] = src[k]


@ti.kernel
def _k_read_ranges(F: F64, ranges: ti.types.ndarray(dtype=ti.i32, ndim=2),
                   out: ti.types.ndarray(dtype=ti.f64, ndim=1)):
    """out[dst:dst+len] = F[start:start+len] for each row (start, len, dst)."""
    ti.loop_config(serialize=True)
    for r in range(ranges.shape[0]):
        start, length, dst = ranges[r, 0], ranges[r, 1], ranges[r, 2]
        for k in range(length):
            out[dst + k] = F[start + k]


@ti.kernel
def _k_read_int(I: I32, start: ti.i32) -> ti.i32:
    return I[start]


# ---------------------------------------------------------------- host side
@dataclass(frozen=True)
class CGStatus:
    """Result of one PCG solve: ``iterations``, ``converged``, ``negative_curvature``
    (met p.Hp <= 0 and stopped), the final relative residual ``residual``, and
    ``indefinite_preconditioner`` (met r.M^-1 r <= 0 and stopped)."""

    iterations: int
    converged: bool
    negative_curvature: bool
    residual: float
    indefinite_preconditioner: bool = False


def _csr(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Row starts (n+1,) and the stable order that sorts ``keys``."""
    order = np.argsort(keys, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.add.at(start, keys + 1, 1)
    return np.cumsum(start), order


class Model:
    """Body (mesh, clamps, material) plus cables, on Taichi.

    Parameters: ``mesh`` rest mesh; ``fixed`` bool (n,) clamped nodes;
    ``material``; ``cables``; ``eps`` the width of the unilateral energy's
    cubic zone (strain); ``parallel`` forces parallel (True) or serialized
    (False) loops, ``None`` picks by size.
    """

    def __init__(self, mesh: Mesh, fixed: np.ndarray, material: Material, cables: CableSet,
                 eps: float = 0.01, parallel: bool | None = None):
        runtime.ensure_init()
        self.mesh, self.material, self.cables, self.eps = mesh, material, cables, float(eps)
        self.fixed = np.asarray(fixed, dtype=bool)
        self.n, self.m = mesh.n_nodes, mesh.n_triangles
        self.S, self.C, self.P = cables.n_segments, cables.n_cables, len(cables.points)
        self.single = cables.single_segment
        if parallel is None:
            parallel = (not runtime.is_cpu()) or (self.m + self.S >= runtime.parallel_threshold())
        self.parallel = bool(parallel)
        self.serial = not self.parallel
        self._build()

    @classmethod
    def from_problem(cls, problem, cables: CableSet | None = None,
                     parallel: bool | None = None) -> "Model":
        """The model of a :class:`~tendon_taichi.problem.Problem` with its fiber
        lattice (the idealized robot) or the given ``cables``."""
        return cls(problem.mesh, problem.fixed, problem.material,
                   problem.fiber_cables if cables is None else cables,
                   eps=problem.scene.fibers.eps, parallel=parallel)

    # ------------------------------------------------------------ layout and upload
    def _build(self) -> None:
        sizes = np.array([self.n, self.m, self.S, self.C, self.P, 1])
        header = np.zeros(_HEADER, dtype=np.int64)
        header[:6] = [self.n, self.m, self.S, self.C, self.P, int(self.single)]
        self.offset: dict[str, int] = {}
        ni = _HEADER
        for name, unit in _INTS:
            header[_SLOTS[name]] = self.offset[name] = ni
            ni += int(np.dot(unit, sizes))
        nf = 0
        for name, unit in _FLOATS:
            header[_SLOTS[name]] = self.offset[name] = nf
            nf += int(np.dot(unit, sizes))
        ih = np.zeros(ni, dtype=np.int64)
        fh = np.zeros(nf, dtype=np.float64)
        ih[:_HEADER] = header
        if ni > np.iinfo(np.int32).max or nf > np.iinfo(np.int32).max:
            raise ValueError("model too large for 32-bit offsets")

        def put_i(name, arr):
            a = np.asarray(arr, dtype=np.int64).ravel()
            ih[self.offset[name]:self.offset[name] + len(a)] = a

        def put_f(name, arr):
            a = np.asarray(arr, dtype=np.float64).ravel()
            fh[self.offset[name]:self.offset[name] + len(a)] = a

        mesh, cab, mat = self.mesh, self.cables, self.material
        X, T = mesh.nodes.astype(np.float64), mesh.triangles.astype(np.int64)
        put_i("TRI", T)
        start, order = _csr(T.ravel(), self.n)
        put_i("NE_START", start)
        put_i("NE", order)  # entry = 3 e + corner
        for name in ("X0", "X", "XT"):
            put_f(name, X)
        Dm = np.stack([X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]], axis=2)
        put_f("BM", np.linalg.inv(Dm))
        put_f("VOL", mat.thickness * mesh.areas)
        put_f("MASK", np.repeat((~self.fixed).astype(float)[:, None], 2, axis=1))
        mass = np.zeros(self.n)
        np.add.at(mass, T.ravel(), np.repeat(mat.density * mat.thickness * mesh.areas / 3.0, 3))
        self.node_mass = mass
        put_f("FEXT", mass[:, None] * np.asarray(mat.gravity, dtype=float)[None, :])
        # cables
        put_i("PT_TRI", cab.points.tri)
        put_f("PT_BARY", cab.points.bary)
        seg_cable = np.repeat(np.arange(self.C), np.diff(cab.start))
        put_i("SEG", np.column_stack([cab.segments, seg_cable]) if self.S else [])
        put_i("CAB_START", cab.start)
        put_f("A0", cab.a0)
        put_f("EA", cab.stiffness)
        # node <- segment incidences: end b with +bary, end a with -bary
        pt_nodes = T[cab.points.tri] if self.P else np.zeros((0, 3), np.int64)
        nodes = np.concatenate([pt_nodes[cab.segments[:, e]].ravel() for e in (0, 1)])
        segs = np.tile(np.repeat(np.arange(self.S), 3), 2)
        coefs = np.concatenate([s * cab.points.bary[cab.segments[:, e]].ravel()
                                for e, s in ((0, -1.0), (1, 1.0))]) if self.S else np.zeros(0)
        start, order = _csr(nodes, self.n)
        put_i("NS_START", start)
        put_i("NS", segs[order])
        put_f("NS_COEF", coefs[order])
        so = self.offset["SCALARS"]
        fh[so + _MU], fh[so + _LAM], fh[so + _EPS] = mat.mu, mat.lam, self.eps
        fh[so + _FLOOR] = 1e-10 * mat.mu * mat.thickness
        self.Bm = np.linalg.inv(Dm)
        self.vol = mat.thickness * mesh.areas
        self.F = ti.ndarray(ti.f64, len(fh))
        self.I = ti.ndarray(ti.i32, len(ih))
        self.F.from_numpy(fh)
        self.g_host = np.zeros(2 * self.n)  # the last gradient, as the host sees it
        self.I.from_numpy(ih.astype(np.int32))

    def _read(self, name: str, count: int, at: int = 0) -> np.ndarray:
        out = np.empty(count, dtype=np.float64)
        if count:
            _k_read(self.F, self.offset[name] + at, out)
        return out

    def _write(self, name: str, values: np.ndarray, at: int = 0) -> None:
        v = np.ascontiguousarray(values, dtype=np.float64).ravel()
        if len(v):
            _k_write(self.F, self.offset[name] + at, v)

    def _read_many(self, items: list[tuple[str, int]]) -> list[np.ndarray]:
        """Several arrays (name, count) in one kernel launch."""
        counts = [c for _, c in items]
        dst = np.concatenate([[0], np.cumsum(counts)])
        ranges = np.array([[self.offset[n], c, d] for (n, c), d in zip(items, dst[:-1])], dtype=np.int32)
        out = np.empty(int(dst[-1]), dtype=np.float64)
        if len(out):
            _k_read_ranges(self.F, ranges, out)
        return [out[a:b] for a, b in zip(dst[:-1], dst[1:])]

    def _nodes(self, name: str) -> np.ndarray:
        return self._read(name, 2 * self.n).reshape(self.n, 2)

    def _scalar(self, k: int) -> float:
        return float(self._read("SCALARS", 1, at=k)[0])

    def _cg_state(self, k: int) -> int:
        return int(_k_read_int(self.I, self.offset["CG_STATE"] + k))

    # ------------------------------------------------------------ kernel calls (host handles)
    def _energy_at(self, trial: bool) -> tuple[float, float]:
        E, jmin = _k_energy(self.F, self.I, _XT if trial else _X, self.serial)
        return float(E), float(jmin)

    def _gradient_norm2(self) -> float:
        """Computes G (also kept on the host, :attr:`g_host`, (2n,)); returns |G_free|^2."""
        return float(_k_gradient(self.F, self.I, self.g_host, self.serial))

    def _newton_rhs(self) -> None:
        _k_newton_rhs(self.F, self.I, self.serial)

    def _take_direction(self, from_cg: bool = True) -> float:
        return float(_k_take_direction(self.F, self.I, 1 if from_cg else 0, self.serial))

    def _direction_from(self, d: np.ndarray) -> float:
        """The Newton direction from the host, d (2n,); returns G . d on the free DOFs."""
        return float(_k_direction_from(self.F, self.I, np.ascontiguousarray(d, dtype=np.float64),
                                       self.serial))

    def _trial(self, alpha: float) -> tuple[float, float]:
        """XT = X + alpha DX; returns (E_tot, min det F) there."""
        E, jmin = _k_trial(self.F, self.I, float(alpha), self.serial)
        return float(E), float(jmin)

    def _accept(self) -> None:
        _k_copy_nodes(self.F, self.I, _XT, _X, self.serial)

    # ------------------------------------------------------------ public API (numpy)
    @property
    def dofs(self) -> int:
        """Number of free degrees of freedom."""
        return int(2 * (~self.fixed).sum())

    def positions(self) -> np.ndarray:
        """Current node positions x (n, 2), m."""
        return self._nodes("X")

    def set_positions(self, x: np.ndarray) -> None:
        """Set node positions (n, 2); clamped nodes are reset to their rest position."""
        x = np.array(x, dtype=np.float64).reshape(self.n, 2)
        x[self.fixed] = self.mesh.nodes[self.fixed]
        self._write("X", x)

    def set_free_positions(self, x: np.ndarray) -> None:
        """Set all node positions, clamped ones included (for derivative checks)."""
        self._write("X", np.asarray(x, dtype=np.float64).reshape(self.n, 2))

    def reset(self) -> None:
        """Back to the rest positions."""
        _k_copy_nodes(self.F, self.I, _X0, _X, self.serial)

    def contraction(self) -> np.ndarray:
        """Cable contractions ac (C,), m."""
        return self._read("AC", self.C)

    def set_contraction(self, ac: np.ndarray) -> None:
        """Set cable contractions ac (C,), m; the rest length a0 - ac must stay positive."""
        ac = np.asarray(ac, dtype=np.float64).reshape(self.C)
        if np.any(ac >= self.cables.a0):
            raise ValueError("a contraction reaches the cable's rest length")
        self._write("AC", ac)

    def energy(self, x: np.ndarray | None = None) -> float:
        """E_tot (J) at x (default: the current positions); +inf if a triangle is inverted."""
        if x is not None:
            self._write("XT", np.asarray(x, dtype=np.float64).reshape(self.n, 2))
        E, jmin = self._energy_at(trial=x is not None)
        return E if jmin > 0.0 else float("inf")

    def gradient(self, x: np.ndarray | None = None) -> np.ndarray:
        """dE_tot/dx (n, 2), N, at x (default: current positions), all nodes; a given
        x becomes the current positions."""
        if x is not None:
            self.set_free_positions(x)
        self._gradient_norm2()
        return self.g_host.reshape(self.n, 2).copy()

    def prepare_hessian(self, project: bool = False) -> None:
        """Element tangents (exact or PSD-projected), cable stiffnesses and the
        preconditioner at the current x."""
        _k_hessian(self.F, self.I, 1 if project else 0, self.serial)

    def hessian_product(self, v: np.ndarray, project: bool = False,
                        prepare: bool = True) -> np.ndarray:
        """H v (n, 2) for v (n, 2): the exact (or projected) Hessian of E_tot at x."""
        if prepare:
            self.prepare_hessian(project)
        self._write("VIN", np.asarray(v, dtype=np.float64).reshape(self.n, 2))
        _k_hessian_product(self.F, self.I, self.serial)
        return self._nodes("VOUT")

    def cable_state(self) -> dict[str, np.ndarray]:
        """Per cable at the current x: length ``L`` (m), rest length ``a`` (m), strain
        ``e``, tension ``tau`` (N), ``kc`` = dtau/dL (N/m), ``tau_ac`` = dtau/dac (N/m)."""
        _k_update_cables(self.F, self.I, self.serial)
        C = self.C
        L, ac, tau, kc, tau_ac = self._read_many([("L", C), ("AC", C), ("TAU", C), ("KC", C), ("TAU_AC", C)])
        a = self.cables.a0 - ac
        return {"L": L, "a": a, "e": L / a - 1.0, "tau": tau, "kc": kc, "tau_ac": tau_ac}

    def tensions(self) -> np.ndarray:
        """Cable tensions tau (C,), N, at the current x."""
        _k_update_cables(self.F, self.I, self.serial)
        return self._read("TAU", self.C)

    def length_jacobian_product(self, w: np.ndarray) -> np.ndarray:
        """sum_c w_c dL_c/dx, (n, 2), for w (C,)."""
        self._write("CCOEF", np.asarray(w, dtype=np.float64).reshape(self.C))
        _k_cables_to_nodes(self.F, self.I, self.serial)
        return self._nodes("VOUT")

    def length_jacobian_transpose_product(self, v: np.ndarray) -> np.ndarray:
        """dL_c/dx . v, (C,), for v (n, 2)."""
        self._write("VIN", np.asarray(v, dtype=np.float64).reshape(self.n, 2))
        _k_nodes_to_cables(self.F, self.I, self.serial)
        return self._read("CW", self.C)

    def mixed_product(self, w: np.ndarray) -> np.ndarray:
        """(d2E/dx dac) w, (n, 2), for w (C,) in m."""
        tau_ac = self.cable_state()["tau_ac"]
        return self.length_jacobian_product(tau_ac * np.asarray(w, dtype=np.float64))

    def mixed_transpose_product(self, v: np.ndarray) -> np.ndarray:
        """(d2E/dx dac)^T v, (C,), for v (n, 2)."""
        tau_ac = self.cable_state()["tau_ac"]
        return tau_ac * self.length_jacobian_transpose_product(v)

    # ------------------------------------------------------------ linear solves
    def cg_solve(self, rhs: np.ndarray | None, tol: float, max_iter: int,
                 warm: bool = False, check_every: int = 8) -> CGStatus:
        """Solve H y = rhs on the free DOFs with block-Jacobi PCG, H as last prepared.

        ``rhs`` (n, 2) is copied in (None: already in place, as for Newton); the
        solution stays in the solver (:meth:`cg_solution`). ``tol`` is relative
        to |rhs|; ``warm`` starts from the previous solution."""
        if rhs is not None:
            self._write("CB", np.asarray(rhs, dtype=np.float64).reshape(self.n, 2))
        done = _k_cg_begin(self.F, self.I, 1 if warm else 0, float(tol), self.serial)
        if not done:
            if self.serial:
                _k_cg_run(self.F, self.I, int(max_iter))
            else:
                launched = 0
                while launched < max_iter:
                    k = min(check_every, max_iter - launched)
                    for _ in range(k):
                        _k_cg_step(self.F, self.I)
                    launched += k
                    if _k_cg_done(self.I):
                        break
        sc = self._read("SCALARS", 13)
        it = self._cg_state(_ITERS)
        res = float(np.sqrt(sc[_RR] / sc[_BB])) if sc[_BB] > 0 else 0.0
        return CGStatus(it, bool(res <= tol), bool(self._cg_state(_NEGCURV)), res)

    def pcg_solve(self, rhs: np.ndarray | None, tol: float, max_iter: int, precondition,
                  warm: bool = False) -> CGStatus:
        """Solve H y = rhs on the free DOFs by CG preconditioned on the host:
        ``precondition(r)`` maps a residual (2n,) to z (2n,), e.g. a factorization's
        solve. H products stay in Taichi (as last prepared); the solution stays in
        the solver (:meth:`cg_solution`)."""
        if rhs is not None:
            self._write("CB", np.asarray(rhs, dtype=np.float64).reshape(self.n, 2))
        r = np.empty(2 * self.n)
        bb, rr = _k_pcg_begin(self.F, self.I, 1 if warm else 0, r, self.serial)
        tol2 = tol * tol * bb
        it, negcurv, indefinite = 0, False, False
        if rr > tol2:
            z = precondition(r)
            rz = float(r @ z)
            indefinite = not rz > 0.0
            if not indefinite:
                _k_pcg_direction(self.F, self.I, z, 0.0, self.serial)
            while not indefinite and it < max_iter:
                pq = _k_pcg_matvec(self.F, self.I, self.serial)
                if pq <= 0.0:
                    negcurv = True
                    break
                rr = _k_pcg_update(self.F, self.I, rz / pq, r, self.serial)
                it += 1
                if rr <= tol2:
                    break
                z = precondition(r)
                rz_new = float(r @ z)
                if not rz_new > 0.0:
                    indefinite = True
                    break
                _k_pcg_direction(self.F, self.I, z, rz_new / rz, self.serial)
                rz = rz_new
        res = float(np.sqrt(rr / bb)) if bb > 0 else 0.0
        return CGStatus(it, bool(res <= tol), negcurv, res, indefinite)

    def cg_solution(self) -> np.ndarray:
        return self._nodes("CX")

    def hessian_entries(self) -> np.ndarray:
        """Element and segment Hessian blocks as last prepared, (36 m + 144 S,):
        see ``_k_hessian_entries``."""
        out = np.empty(36 * self.m + 144 * self.S)
        _k_hessian_entries(self.F, self.I, out, self.serial)
        return out

    def hessian_data(self) -> dict[str, np.ndarray]:
        """What the direct backend assembles from (after prepare_hessian)."""
        m, S, C = self.m, self.S, self.C
        D, seg_n, seg_l, tau, kc = self._read_many([("D", 16 * m), ("SEG_N", 2 * S), ("SEG_L", S),
                                                    ("TAU", C), ("KC", C)])
        return {"D": D.reshape(m, 4, 4), "Bm": self.Bm, "vol": self.vol,
                "seg_n": seg_n.reshape(S, 2), "seg_l": seg_l, "tau": tau, "kc": kc}

