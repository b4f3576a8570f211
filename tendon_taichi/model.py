"""The Taichi model: energies, forces and Hessian products of body + cables.

``E_tot(x, ac) = E_body(x) + E_g(x) + sum_c U_c(x, ac)`` (DESIGN.md section 2):

* ``E_body``: compressible Neo-Hookean constant-strain triangles,
  ``sum_e h A_e psi(F_e)`` with ``F_e = D_s D_m^-1``;
* ``E_g = -sum_i m_i g . x_i`` with lumped masses;
* ``U_c = EA_c a_c Z(e_c)``, ``a_c = a0_c - ac_c``, ``e_c = (L_c - a_c)/a_c``,
  ``L_c(x)`` the length of cable ``c`` (the sum of its segment lengths).

Derived cable quantities (all per cable, evaluated at the model's positions):
tension ``tau = dU/dL = EA Z'(e)`` (N), ``kc = dtau/dL = EA Z''(e)/a`` (N/m)
and ``tau_ac = dtau/dac = EA Z''(e) L/a^2`` (N/m). The mixed derivative of the
energy is ``d2E/(dx dac_c) = tau_ac_c dL_c/dx``.

Everything lives in Taichi fields allocated once per model; numpy arrays
cross only at the public methods. Node forces are *gathered* per node (not
scattered with atomics) and sums are taken over fixed blocks, so every result
is bit-for-bit deterministic. Small models run their loops serialized (a
parallel loop costs ~0.1 ms to dispatch on the CPU backend); large ones in
parallel (``parallel``; see :func:`runtime.parallel_threshold`).
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
vec4 = ti.types.vector(4, ti.f64)

#: number of blocks of every deterministic reduction
_NB = 32


@dataclass(frozen=True)
class CGStatus:
    """Result of one PCG solve: ``iterations``, ``converged``, ``negative_curvature``
    (met p.Hp <= 0 and stopped), and the final relative residual ``residual``."""

    iterations: int
    converged: bool
    negative_curvature: bool
    residual: float


def _put(field, values: np.ndarray) -> None:
    """Copy values into a field that may be longer (padded with zeros)."""
    values = np.asarray(values)
    if field.shape[0] != values.shape[0]:
        padded = np.zeros((field.shape[0],) + values.shape[1:], dtype=values.dtype)
        padded[:len(values)] = values
        values = padded
    field.from_numpy(values)


def _csr(keys: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Row starts (n+1,) and the order that sorts ``keys`` (stable)."""
    order = np.argsort(keys, kind="stable")
    start = np.zeros(n + 1, dtype=np.int32)
    np.add.at(start, keys + 1, 1)
    return np.cumsum(start).astype(np.int32), order


@ti.data_oriented
class Model:
    """Body (mesh, clamps, material) plus cables, on Taichi.

    Parameters: ``mesh`` rest mesh; ``fixed`` bool (n,) clamped nodes;
    ``material``; ``cables``; ``eps`` the width of the unilateral energy's
    cubic zone; ``parallel`` forces parallel (True) or serialized (False)
    loops, ``None`` picks by size.
    """

    def __init__(self, mesh: Mesh, fixed: np.ndarray, material: Material, cables: CableSet,
                 eps: float = 0.01, parallel: bool | None = None):
        runtime.ensure_init()
        self.mesh, self.material, self.cables, self.eps = mesh, material, cables, float(eps)
        self.fixed = np.asarray(fixed, dtype=bool)
        n, m = mesh.n_nodes, mesh.n_triangles
        S, C, P = cables.n_segments, cables.n_cables, len(cables.points)
        self.n, self.m, self.S, self.C, self.P = n, m, S, C, P
        self.single = cables.single_segment
        if parallel is None:
            parallel = (not runtime.is_cpu()) or (m + S >= runtime.parallel_threshold())
        self.parallel = bool(parallel)
        self.serial = not self.parallel
        self.chunk_n = -(-n // _NB)
        self.chunk_m = -(-m // _NB)
        self.chunk_c = -(-C // _NB)
        self._alloc()
        self._upload()
        self.cg_iterations_total = 0

    @classmethod
    def from_problem(cls, problem, cables: CableSet | None = None,
                     parallel: bool | None = None) -> "Model":
        """The model of a :class:`~tendon_taichi.problem.Problem` with its fiber
        lattice (the idealized robot) or the given ``cables``."""
        return cls(problem.mesh, problem.fixed, problem.material,
                   problem.fiber_cables if cables is None else cables,
                   eps=problem.scene.fibers.eps, parallel=parallel)

    # ------------------------------------------------------------------ setup
    def _alloc(self):
        # Taichi fields cannot be empty: a model without cables keeps one unused slot
        n, m = self.n, self.m
        S, C, P = max(self.S, 1), max(self.C, 1), max(self.P, 1)
        f64 = ti.f64
        self.X = ti.Vector.field(2, f64, n)
        self.x = ti.Vector.field(2, f64, n)
        self.xt = ti.Vector.field(2, f64, n)
        self.dx = ti.Vector.field(2, f64, n)
        self.g = ti.Vector.field(2, f64, n)
        self.mask = ti.Vector.field(2, f64, n)
        self.fext = ti.Vector.field(2, f64, n)
        self.vin = ti.Vector.field(2, f64, n)
        self.vout = ti.Vector.field(2, f64, n)
        self.tri = ti.Vector.field(3, ti.i32, m)
        self.Bm = ti.Matrix.field(2, 2, f64, m)
        self.vol = ti.field(f64, m)
        self.D = ti.Matrix.field(4, 4, f64, m)
        self.elem_vec = ti.Vector.field(2, f64, (m, 3))
        self.elem_energy = ti.field(f64, m)
        self.node_elem_start = ti.field(ti.i32, n + 1)
        self.node_elem = ti.field(ti.i32, max(3 * m, 1))
        # cables
        self.pt_tri = ti.field(ti.i32, P)
        self.pt_bary = ti.Vector.field(3, f64, P)
        self.seg_a = ti.field(ti.i32, S)
        self.seg_b = ti.field(ti.i32, S)
        self.seg_cable = ti.field(ti.i32, S)
        self.seg_n = ti.Vector.field(2, f64, S)
        self.seg_l = ti.field(f64, S)
        self.seg_dd = ti.Vector.field(2, f64, S)
        self.seg_w = ti.field(f64, S)
        self.seg_vec = ti.Vector.field(2, f64, S)
        self.cable_start = ti.field(ti.i32, C + 1)
        self.a0 = ti.field(f64, C)
        self.ac = ti.field(f64, C)
        self.EA = ti.field(f64, C)
        self.L = ti.field(f64, C)
        self.tau = ti.field(f64, C)
        self.kc = ti.field(f64, C)
        self.tau_ac = ti.field(f64, C)
        self.cable_energy = ti.field(f64, C)
        self.cable_w = ti.field(f64, C)
        self.cable_coef = ti.field(f64, C)
        n_inc = 6 * S
        self.node_seg_start = ti.field(ti.i32, n + 1)
        self.node_seg = ti.field(ti.i32, max(n_inc, 1))
        self.node_seg_coef = ti.field(f64, max(n_inc, 1))
        # PCG state
        self.cg_b = ti.Vector.field(2, f64, n)
        self.cg_x = ti.Vector.field(2, f64, n)
        self.cg_r = ti.Vector.field(2, f64, n)
        self.cg_z = ti.Vector.field(2, f64, n)
        self.cg_p = ti.Vector.field(2, f64, n)
        self.cg_q = ti.Vector.field(2, f64, n)
        self.Minv = ti.Matrix.field(2, 2, f64, n)
        self.cg_rz = ti.field(f64, ())
        self.cg_rr = ti.field(f64, ())
        self.cg_pq = ti.field(f64, ())
        self.cg_bb = ti.field(f64, ())
        self.cg_tol2 = ti.field(f64, ())
        self.cg_iters = ti.field(ti.i32, ())
        self.cg_done = ti.field(ti.i32, ())
        self.cg_negcurv = ti.field(ti.i32, ())
        # scalars
        self.mu = ti.field(f64, ())
        self.lam = ti.field(f64, ())
        self.eps_f = ti.field(f64, ())
        self.jmin = ti.field(f64, ())
        self.s0 = ti.field(f64, ())
        self.s1 = ti.field(f64, ())
        self.s2 = ti.field(f64, ())
        self.partial = ti.field(f64, _NB)
        self.partial2 = ti.field(f64, _NB)

    def _upload(self):
        mesh, cab, mat = self.mesh, self.cables, self.material
        X = mesh.nodes.astype(np.float64)
        T = mesh.triangles.astype(np.int32)
        self.X.from_numpy(X)
        self.x.from_numpy(X)
        self.xt.from_numpy(X)
        self.tri.from_numpy(T)
        Dm = np.stack([X[T[:, 1]] - X[T[:, 0]], X[T[:, 2]] - X[T[:, 0]]], axis=2)
        self.Bm.from_numpy(np.linalg.inv(Dm))
        area = mesh.areas
        self.vol.from_numpy(mat.thickness * area)
        free = (~self.fixed).astype(np.float64)
        self.mask.from_numpy(np.repeat(free[:, None], 2, axis=1))
        mass = np.zeros(self.n)
        np.add.at(mass, T.ravel(), np.repeat(mat.density * mat.thickness * area / 3.0, 3))
        self.node_mass = mass
        self.fext.from_numpy(mass[:, None] * np.asarray(mat.gravity, dtype=float)[None, :])
        start, order = _csr(T.ravel().astype(np.int64), self.n)
        self.node_elem_start.from_numpy(start)
        self.node_elem.from_numpy(order.astype(np.int32))  # entry = 3 e + k
        # cables
        _put(self.pt_tri, cab.points.tri.astype(np.int32))
        _put(self.pt_bary, cab.points.bary.astype(np.float64))
        _put(self.seg_a, cab.segments[:, 0].astype(np.int32))
        _put(self.seg_b, cab.segments[:, 1].astype(np.int32))
        seg_cable = np.repeat(np.arange(self.C), np.diff(cab.start)).astype(np.int32)
        _put(self.seg_cable, seg_cable)
        _put(self.cable_start, cab.start.astype(np.int32))
        _put(self.a0, cab.a0.astype(np.float64))
        _put(self.ac, np.zeros(self.C))
        _put(self.EA, cab.stiffness.astype(np.float64))
        # node <- segment incidences: end b with +bary, end a with -bary
        pt_nodes = T[cab.points.tri]  # (P, 3)
        nodes, segs, coefs = [], [], []
        for end, sign in ((0, -1.0), (1, 1.0)):
            p = cab.segments[:, end]
            nodes.append(pt_nodes[p].ravel())
            segs.append(np.repeat(np.arange(self.S), 3))
            coefs.append(sign * cab.points.bary[p].ravel())
        nodes, segs, coefs = map(np.concatenate, (nodes, segs, coefs))
        start, order = _csr(nodes.astype(np.int64), self.n)
        self.node_seg_start.from_numpy(start)
        _put(self.node_seg, segs[order].astype(np.int32))
        _put(self.node_seg_coef, coefs[order].astype(np.float64))
        self.mu[None] = mat.mu
        self.lam[None] = mat.lam
        self.eps_f[None] = self.eps
        self.precond_floor = 1e-10 * mat.mu * mat.thickness

    # ------------------------------------------------------------------ Taichi functions
    @ti.func
    def _deformation_gradient(self, xs: ti.template(), e) -> mat2:
        t = self.tri[e]
        Ds = mat2([[xs[t[1]][0] - xs[t[0]][0], xs[t[2]][0] - xs[t[0]][0]],
                   [xs[t[1]][1] - xs[t[0]][1], xs[t[2]][1] - xs[t[0]][1]]])
        return Ds @ self.Bm[e]

    @ti.func
    def _store_element_vectors(self, e, G: mat2):
        """Nodal vectors of element e from dE/dDs-like G (columns: nodes 1 and 2)."""
        c1 = vec2(G[0, 0], G[1, 0])
        c2 = vec2(G[0, 1], G[1, 1])
        self.elem_vec[e, 0] = -(c1 + c2)
        self.elem_vec[e, 1] = c1
        self.elem_vec[e, 2] = c2

    @ti.func
    def _point(self, xs: ti.template(), p) -> vec2:
        t = self.tri[self.pt_tri[p]]
        b = self.pt_bary[p]
        return b[0] * xs[t[0]] + b[1] * xs[t[1]] + b[2] * xs[t[2]]

    @ti.func
    def _update_cables(self, xs: ti.template()):
        """Segment geometry, cable lengths, tensions, stiffnesses and energies at xs."""
        ti.loop_config(serialize=self.serial)
        for s in range(self.S):
            d = self._point(xs, self.seg_b[s]) - self._point(xs, self.seg_a[s])
            l = d.norm()
            self.seg_l[s] = l
            self.seg_n[s] = d / l if l > 0.0 else vec2(0.0, 0.0)
        ti.loop_config(serialize=self.serial)
        for c in range(self.C):
            L = 0.0
            if ti.static(self.single):
                L = self.seg_l[c]
            else:
                for s in range(self.cable_start[c], self.cable_start[c + 1]):
                    L += self.seg_l[s]
            a = self.a0[c] - self.ac[c]
            e = L / a - 1.0
            eps = self.eps_f[None]
            EA = self.EA[c]
            self.L[c] = L
            self.tau[c] = EA * zcq_d1(e, eps)
            self.kc[c] = EA * zcq_d2(e, eps) / a
            self.tau_ac[c] = EA * zcq_d2(e, eps) * L / (a * a)
            self.cable_energy[c] = EA * a * zcq(e, eps)

    @ti.func
    def _gather(self, dst: ti.template(), elems: ti.template(), masked: ti.template()):
        """dst[i] = sum of the element vectors (if ``elems``) and the segment vectors
        (weighted by signed barycentric coefficients) incident to node i."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            acc = vec2(0.0, 0.0)
            if ti.static(elems):
                for k in range(self.node_elem_start[i], self.node_elem_start[i + 1]):
                    ek = self.node_elem[k]
                    acc += self.elem_vec[ek // 3, ek % 3]
            for k in range(self.node_seg_start[i], self.node_seg_start[i + 1]):
                acc += self.node_seg_coef[k] * self.seg_vec[self.node_seg[k]]
            if ti.static(masked):
                acc *= self.mask[i]
            dst[i] = acc

    @ti.func
    def _dot(self, a: ti.template(), b: ti.template(), out: ti.template()):
        """out = sum_i a_i . b_i over nodes, deterministic."""
        ti.loop_config(serialize=self.serial)
        for blk in range(_NB):
            acc = 0.0
            for i in range(blk * self.chunk_n, ti.min((blk + 1) * self.chunk_n, self.n)):
                acc += a[i].dot(b[i])
            self.partial[blk] = acc
        total = 0.0
        for blk in ti.static(range(_NB)):
            total += self.partial[blk]
        out[None] = total

    @ti.func
    def _sum(self, arr: ti.template(), count: ti.template(), chunk: ti.template(), out: ti.template()):
        """out = sum of arr[0:count], deterministic."""
        ti.loop_config(serialize=self.serial)
        for blk in range(_NB):
            acc = 0.0
            for i in range(blk * chunk, ti.min((blk + 1) * chunk, count)):
                acc += arr[i]
            self.partial[blk] = acc
        total = 0.0
        for blk in ti.static(range(_NB)):
            total += self.partial[blk]
        out[None] = total

    @ti.func
    def _energy(self, xs: ti.template()):
        """s0 = E_tot(xs); jmin = the smallest det F (<= 0 means inverted)."""
        self.jmin[None] = 1e300
        ti.loop_config(serialize=self.serial)
        for e in range(self.m):
            F = self._deformation_gradient(xs, e)
            J = F.determinant()
            ti.atomic_min(self.jmin[None], J)
            psi = 0.0
            if J > 0.0:
                psi = neo_hookean_psi(F, self.mu[None], self.lam[None])
            self.elem_energy[e] = self.vol[e] * psi
        self._update_cables(xs)
        self._sum(self.elem_energy, self.m, self.chunk_m, self.s0)
        self._sum(self.cable_energy, self.C, self.chunk_c, self.s1)
        self._dot(self.fext, xs, self.s2)
        self.s0[None] = self.s0[None] + self.s1[None] - self.s2[None]

    @ti.func
    def _gradient(self):
        """g = dE_tot/dx at x (all nodes); s0 = |g|^2 over free DOFs."""
        ti.loop_config(serialize=self.serial)
        for e in range(self.m):
            F = self._deformation_gradient(self.x, e)
            P = neo_hookean_P(F, self.mu[None], self.lam[None])
            self._store_element_vectors(e, self.vol[e] * P @ self.Bm[e].transpose())
        self._update_cables(self.x)
        ti.loop_config(serialize=self.serial)
        for s in range(self.S):
            self.seg_vec[s] = self.tau[self.seg_cable[s]] * self.seg_n[s]
        self._gather(self.g, True, False)
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.g[i] -= self.fext[i]
            self.vout[i] = self.g[i] * self.mask[i]
        self._dot(self.vout, self.vout, self.s0)

    @ti.func
    def _element_diag_block(self, e, k) -> mat2:
        """The (k, k) 2x2 block of element e's Hessian."""
        B = self.Bm[e]
        gk = vec2(B[0, 0], B[0, 1])
        if k == 2:
            gk = vec2(B[1, 0], B[1, 1])
        elif k == 0:
            gk = -vec2(B[0, 0] + B[1, 0], B[0, 1] + B[1, 1])
        D = self.D[e]
        H = mat2(0.0)
        for a, j, b, l in ti.static(ti.ndrange(2, 2, 2, 2)):
            H[a, b] += D[2 * a + j, 2 * b + l] * gk[j] * gk[l]
        return self.vol[e] * H

    @ti.func
    def _segment_stiffness(self, s) -> mat2:
        """tau/l (I - n n^T) + kc n n^T of segment s (its own, PSD)."""
        c = self.seg_cable[s]
        nv = self.seg_n[s]
        l = self.seg_l[s]
        K = self.kc[c] * nv.outer_product(nv)
        if l > 0.0:
            K += self.tau[c] / l * (ti.Matrix.identity(ti.f64, 2) - nv.outer_product(nv))
        return K

    @ti.func
    def _hessian(self, project: ti.i32):
        """Per-element tangents D (exact, or PSD-projected if ``project``), cable
        stiffnesses at x, and the block-Jacobi preconditioner."""
        ti.loop_config(serialize=self.serial)
        for e in range(self.m):
            F = self._deformation_gradient(self.x, e)
            D = neo_hookean_dPdF(F, self.mu[None], self.lam[None])
            if project != 0:
                D = project_psd4(0.5 * (D + D.transpose()))
            self.D[e] = D
        self._update_cables(self.x)
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            H = mat2(0.0)
            for k in range(self.node_elem_start[i], self.node_elem_start[i + 1]):
                ek = self.node_elem[k]
                H += self._element_diag_block(ek // 3, ek % 3)
            for k in range(self.node_seg_start[i], self.node_seg_start[i + 1]):
                cf = self.node_seg_coef[k]
                H += cf * cf * self._segment_stiffness(self.node_seg[k])
            Minv = spd_inverse2(H, self.precond_floor)
            if self.mask[i][0] == 0.0:
                Minv = mat2(0.0)
            self.Minv[i] = Minv

    @ti.func
    def _segment_directional(self, src: ti.template()):
        """seg_dd = the change of each segment vector along src; cable_w = dL_c/dx . src."""
        ti.loop_config(serialize=self.serial)
        for s in range(self.S):
            dd = self._point(src, self.seg_b[s]) - self._point(src, self.seg_a[s])
            self.seg_dd[s] = dd
            self.seg_w[s] = self.seg_n[s].dot(dd)
        ti.loop_config(serialize=self.serial)
        for c in range(self.C):
            w = 0.0
            if ti.static(self.single):
                w = self.seg_w[c]
            else:
                for s in range(self.cable_start[c], self.cable_start[c + 1]):
                    w += self.seg_w[s]
            self.cable_w[c] = w

    @ti.func
    def _apply_hessian(self, src: ti.template(), dst: ti.template(), masked: ti.template()):
        """dst = H src with H the Hessian prepared by _hessian (masked: free-free block)."""
        ti.loop_config(serialize=self.serial)
        for e in range(self.m):
            t = self.tri[e]
            dDs = mat2([[src[t[1]][0] - src[t[0]][0], src[t[2]][0] - src[t[0]][0]],
                        [src[t[1]][1] - src[t[0]][1], src[t[2]][1] - src[t[0]][1]]])
            B = self.Bm[e]
            dP = tangent_apply(self.D[e], dDs @ B)
            self._store_element_vectors(e, self.vol[e] * dP @ B.transpose())
        self._segment_directional(src)
        ti.loop_config(serialize=self.serial)
        for s in range(self.S):
            c = self.seg_cable[s]
            nv = self.seg_n[s]
            dd = self.seg_dd[s]
            v = self.kc[c] * self.cable_w[c] * nv
            l = self.seg_l[s]
            if l > 0.0:
                v += self.tau[c] / l * (dd - nv * nv.dot(dd))
            self.seg_vec[s] = v
        self._gather(dst, True, masked)

    # ------------------------------------------------------------------ PCG
    @ti.func
    def _cg_begin(self, warm: ti.i32, tol: ti.f64):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.cg_b[i] *= self.mask[i]
            if warm == 0:
                self.cg_x[i] = vec2(0.0, 0.0)
            else:
                self.cg_x[i] *= self.mask[i]
        self._apply_hessian(self.cg_x, self.cg_q, True)
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            r = self.cg_b[i] - self.cg_q[i]
            self.cg_r[i] = r
            z = self.Minv[i] @ r
            self.cg_z[i] = z
            self.cg_p[i] = z
        self._dot(self.cg_r, self.cg_z, self.cg_rz)
        self._dot(self.cg_r, self.cg_r, self.cg_rr)
        self._dot(self.cg_b, self.cg_b, self.cg_bb)
        self.cg_tol2[None] = tol * tol * self.cg_bb[None]
        self.cg_iters[None] = 0
        self.cg_negcurv[None] = 0
        self.cg_done[None] = 0
        if self.cg_rr[None] <= self.cg_tol2[None]:
            self.cg_done[None] = 1

    @ti.func
    def _cg_iteration(self):
        """One PCG iteration; once done, alpha = 0 keeps the solution unchanged."""
        self._apply_hessian(self.cg_p, self.cg_q, True)
        self._dot(self.cg_p, self.cg_q, self.cg_pq)
        alpha = 0.0
        if self.cg_done[None] == 0:
            if self.cg_pq[None] <= 0.0:
                self.cg_negcurv[None] = 1
                self.cg_done[None] = 1
            else:
                alpha = self.cg_rz[None] / self.cg_pq[None]
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.cg_x[i] += alpha * self.cg_p[i]
            r = self.cg_r[i] - alpha * self.cg_q[i]
            self.cg_r[i] = r
            self.cg_z[i] = self.Minv[i] @ r
        self._dot(self.cg_r, self.cg_z, self.s1)
        self._dot(self.cg_r, self.cg_r, self.cg_rr)
        beta = 0.0
        if self.cg_done[None] == 0:
            self.cg_iters[None] += 1
            if self.cg_rr[None] <= self.cg_tol2[None]:
                self.cg_done[None] = 1
            beta = self.s1[None] / self.cg_rz[None]
            self.cg_rz[None] = self.s1[None]
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.cg_p[i] = self.cg_z[i] + beta * self.cg_p[i]

    # ------------------------------------------------------------------ kernels
    @ti.kernel
    def _k_energy(self, xs: ti.template()) -> vec2:
        self._energy(xs)
        return vec2(self.s0[None], self.jmin[None])

    @ti.kernel
    def _k_gradient(self) -> ti.f64:
        self._gradient()
        return self.s0[None]

    @ti.kernel
    def _k_hessian(self, project: ti.i32):
        self._hessian(project)

    @ti.kernel
    def _k_hessian_product(self):
        self._apply_hessian(self.vin, self.vout, False)

    @ti.kernel
    def _k_update_cables(self):
        self._update_cables(self.x)

    @ti.kernel
    def _k_cables_to_nodes(self):
        """vout = sum_c cable_coef_c dL_c/dx."""
        self._update_cables(self.x)
        ti.loop_config(serialize=self.serial)
        for s in range(self.S):
            self.seg_vec[s] = self.cable_coef[self.seg_cable[s]] * self.seg_n[s]
        self._gather(self.vout, False, False)

    @ti.kernel
    def _k_nodes_to_cables(self):
        """cable_w = dL_c/dx . vin."""
        self._update_cables(self.x)
        self._segment_directional(self.vin)

    @ti.kernel
    def _k_cg_begin(self, warm: ti.i32, tol: ti.f64) -> ti.i32:
        self._cg_begin(warm, tol)
        return self.cg_done[None]

    @ti.kernel
    def _k_cg_run(self, iterations: ti.i32) -> ti.i32:
        ti.loop_config(serialize=True)
        for _ in range(iterations):
            if self.cg_done[None] == 0:
                self._cg_iteration()
        return self.cg_done[None]

    @ti.kernel
    def _k_cg_step(self):
        self._cg_iteration()

    @ti.kernel
    def _k_cg_done(self) -> ti.i32:
        return self.cg_done[None]

    @ti.kernel
    def _k_newton_rhs(self):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.cg_b[i] = -self.g[i] * self.mask[i]

    @ti.kernel
    def _k_take_direction(self) -> ti.f64:
        """dx = cg_x; return g . dx over free DOFs."""
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.dx[i] = self.cg_x[i] * self.mask[i]
        self._dot(self.g, self.dx, self.s0)
        return self.s0[None]

    @ti.kernel
    def _k_directional(self) -> ti.f64:
        """g . dx over free DOFs (dx already masked)."""
        self._dot(self.g, self.dx, self.s0)
        return self.s0[None]

    @ti.kernel
    def _k_trial(self, alpha: ti.f64):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.xt[i] = self.x[i] + alpha * self.dx[i]

    @ti.kernel
    def _k_accept(self):
        ti.loop_config(serialize=self.serial)
        for i in range(self.n):
            self.x[i] = self.xt[i]

    # ------------------------------------------------------------------ public API (numpy)
    @property
    def dofs(self) -> int:
        """Number of free degrees of freedom."""
        return int(2 * (~self.fixed).sum())

    def positions(self) -> np.ndarray:
        """Current node positions x (n, 2), m."""
        return self.x.to_numpy()

    def set_positions(self, x: np.ndarray) -> None:
        """Set node positions (n, 2); clamped nodes are reset to their rest position."""
        x = np.array(x, dtype=np.float64).reshape(self.n, 2)
        x[self.fixed] = self.mesh.nodes[self.fixed]
        self.x.from_numpy(x)

    def reset(self) -> None:
        """Back to the rest positions."""
        self.x.copy_from(self.X)

    def contraction(self) -> np.ndarray:
        """Cable contractions ac (C,), m."""
        return self.ac.to_numpy()[:self.C]

    def set_contraction(self, ac: np.ndarray) -> None:
        """Set cable contractions ac (C,), m; a = a0 - ac must stay positive."""
        ac = np.asarray(ac, dtype=np.float64).reshape(self.C)
        if np.any(ac >= self.cables.a0):
            raise ValueError("a contraction reaches the cable's rest length")
        _put(self.ac, ac)

    def energy(self, x: np.ndarray | None = None) -> float:
        """E_tot (J) at x (default: the current positions); +inf if a triangle is inverted."""
        if x is not None:
            self.xt.from_numpy(np.asarray(x, dtype=np.float64).reshape(self.n, 2))
        E, jmin = self._k_energy(self.xt if x is not None else self.x)
        return float(E) if jmin > 0.0 else float("inf")

    def gradient(self, x: np.ndarray | None = None) -> np.ndarray:
        """dE_tot/dx (n, 2), N, at x (default: current positions), all nodes."""
        if x is not None:
            self.set_free_positions(x)
        self._k_gradient()
        return self.g.to_numpy()

    def set_free_positions(self, x: np.ndarray) -> None:
        """Set all node positions, clamped ones included (for derivative checks)."""
        self.x.from_numpy(np.asarray(x, dtype=np.float64).reshape(self.n, 2))

    def prepare_hessian(self, project: bool = False) -> None:
        """Compute the element tangents (exact or PSD-projected) at the current x."""
        self._k_hessian(1 if project else 0)

    def hessian_product(self, v: np.ndarray, project: bool = False,
                        prepare: bool = True) -> np.ndarray:
        """H v (n, 2) for v (n, 2): the exact (or projected) Hessian of E_tot at x."""
        if prepare:
            self.prepare_hessian(project)
        self.vin.from_numpy(np.asarray(v, dtype=np.float64).reshape(self.n, 2))
        self._k_hessian_product()
        return self.vout.to_numpy()

    def cable_state(self) -> dict[str, np.ndarray]:
        """Per cable at the current x: length ``L`` (m), rest length ``a`` (m), strain
        ``e``, tension ``tau`` (N), ``kc`` = dtau/dL (N/m), ``tau_ac`` = dtau/dac (N/m)."""
        self._k_update_cables()
        C = self.C
        L = self.L.to_numpy()[:C]
        a = self.cables.a0 - self.ac.to_numpy()[:C]
        return {"L": L, "a": a, "e": L / a - 1.0, "tau": self.tau.to_numpy()[:C],
                "kc": self.kc.to_numpy()[:C], "tau_ac": self.tau_ac.to_numpy()[:C]}

    def tensions(self) -> np.ndarray:
        """Cable tensions tau (C,), N, at the current x."""
        self._k_update_cables()
        return self.tau.to_numpy()[:self.C]

    def length_jacobian_product(self, w: np.ndarray) -> np.ndarray:
        """sum_c w_c dL_c/dx, (n, 2), for w (C,)."""
        _put(self.cable_coef, np.asarray(w, dtype=np.float64).reshape(self.C))
        self._k_cables_to_nodes()
        return self.vout.to_numpy()

    def length_jacobian_transpose_product(self, v: np.ndarray) -> np.ndarray:
        """dL_c/dx . v, (C,), for v (n, 2)."""
        self.vin.from_numpy(np.asarray(v, dtype=np.float64).reshape(self.n, 2))
        self._k_nodes_to_cables()
        return self.cable_w.to_numpy()[:self.C]

    def mixed_product(self, w: np.ndarray) -> np.ndarray:
        """(d2E/dx dac) w, (n, 2), for w (C,) in m."""
        st = self.cable_state()
        return self.length_jacobian_product(st["tau_ac"] * np.asarray(w, dtype=np.float64))

    def mixed_transpose_product(self, v: np.ndarray) -> np.ndarray:
        """(d2E/dx dac)^T v, (C,), for v (n, 2)."""
        st = self.cable_state()
        return st["tau_ac"] * self.length_jacobian_transpose_product(v)

    # ------------------------------------------------------------------ linear solves
    def cg_solve(self, rhs: np.ndarray | None, tol: float, max_iter: int,
                 warm: bool = False, check_every: int = 8) -> CGStatus:
        """Solve H y = rhs on the free DOFs with block-Jacobi PCG, H as last prepared.

        ``rhs`` (n, 2) is copied into the solver (None: it is already there);
        the solution stays in the solver (``cg_solution``). ``tol`` is relative to
        |rhs|; ``warm`` starts from the previous solution."""
        if rhs is not None:
            self.cg_b.from_numpy(np.asarray(rhs, dtype=np.float64).reshape(self.n, 2))
        done = self._k_cg_begin(1 if warm else 0, float(tol))
        if not done:
            if self.serial:
                self._k_cg_run(int(max_iter))
            else:
                launched = 0
                while launched < max_iter:
                    k = min(check_every, max_iter - launched)
                    for _ in range(k):
                        self._k_cg_step()
                    launched += k
                    if self._k_cg_done():
                        break
        it = int(self.cg_iters[None])
        self.cg_iterations_total += it
        bb = self.cg_bb[None]
        res = float(np.sqrt(self.cg_rr[None] / bb)) if bb > 0 else 0.0
        return CGStatus(it, bool(res <= tol), bool(self.cg_negcurv[None]), res)

    def cg_solution(self) -> np.ndarray:
        return self.cg_x.to_numpy()

    def hessian_data(self) -> dict[str, np.ndarray]:
        """What the direct backend assembles from (after prepare_hessian)."""
        return {"D": self.D.to_numpy(), "Bm": self.Bm.to_numpy(), "vol": self.vol.to_numpy(),
                "seg_n": self.seg_n.to_numpy()[:self.S], "seg_l": self.seg_l.to_numpy()[:self.S],
                "tau": self.tau.to_numpy()[:self.C], "kc": self.kc.to_numpy()[:self.C]}
