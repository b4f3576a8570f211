"""A plain numpy/scipy implementation of one soft-IK gradient: the baseline that
``tendon-taichi bench`` measures the Taichi pipeline against, side by side.

The same method and the same numbers as :class:`~tendon_taichi.optimizer.soft_ik.SoftIK`
at stage 0 (the pose and contraction terms) on the fiber lattice, written as a
careful numpy/scipy user would write it, with none of the project's solver
machinery: the energy, its gradient and its exact Hessian vectorized over the
elements and fibers (``docs/method.md``, section 1), assembled as a scipy sparse
matrix; Newton with SuperLU (``scipy.sparse.linalg.splu``, its default ordering)
and a backtracking line search to the same force tolerance (``EVAL_TOL`` x the
problem's force scale); then one adjoint solve on a fresh factorization of the
Hessian at the equilibrium (section 2, "The adjoint gradient"). No prediction
from the last equilibrium, no chord steps, no reused ordering: those are what the
pipeline adds.

It works in the body's dimension d = 2 or 3: constant-strain triangles of
thickness h in plane strain, or tetrahedra (d + 1 nodes per element either way),
so that it is also the reference the 3D pipeline is checked against.

Arrays in SI units: positions (n, d) m, contractions (C,) m, ratios r = ac / a0.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..body.problem import Problem
from ..errors import ConvergenceError
from ..optimizer.soft_ik import EVAL_TOL


def _zcq(e: np.ndarray, eps: float, d: int) -> np.ndarray:
    """Z(e) (d = 0), Z'(e) (1) or Z''(e) (2) of the unilateral strain energy."""
    quad = [0.5 * e * e - 0.5 * eps * e + eps * eps / 6, e - 0.5 * eps, np.ones_like(e)][d]
    cubic = [e ** 3 / (6 * eps), e * e / (2 * eps), e / eps][d]
    return np.where(e > eps, quad, np.where(e > 0, cubic, 0.0))


def _embedding_matrix(tri: np.ndarray, bary: np.ndarray, simplices: np.ndarray, n: int) -> sp.csr_matrix:
    """The linear map (k, n) from node positions to embedded points' positions: points
    in elements ``tri`` (k,) with barycentric weights ``bary`` (k, d + 1)."""
    rows = np.repeat(np.arange(len(tri)), bary.shape[1])
    return sp.csr_matrix((bary.ravel(), (rows, simplices[tri].ravel())), shape=(len(tri), n))


def _edge_matrix(x: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Each element's edge vectors x_a - x_0 (a = 1..d) as columns, (m, d, d) m, of
    positions ``x`` (n, d) and elements ``T`` (m, d + 1)."""
    return np.stack([x[T[:, a]] - x[T[:, 0]] for a in range(1, T.shape[1])], axis=2)


def _rest_volumes(Dm: np.ndarray, thickness: float | None) -> np.ndarray:
    """The elements' rest volumes (m,), m^3: h |det Dm| / 2 of triangles of thickness
    ``thickness`` h (m), |det Dm| / 6 of tetrahedra (no thickness)."""
    if Dm.shape[1] == 2:
        return thickness * 0.5 * np.abs(np.linalg.det(Dm))
    return np.abs(np.linalg.det(Dm)) / 6.0


def _deformation_derivative(Bm: np.ndarray) -> np.ndarray:
    """dF/dx (m, d*d, (d+1)*d), 1/m, of elements with inverse rest edge matrices ``Bm``
    (m, d, d): vec(F)_(d i + j) = sum_a x_(a,i) G_(a,j), G (m, d + 1, d) the
    shape-function gradients."""
    m, d = Bm.shape[:2]
    G = np.concatenate([-Bm.sum(axis=1, keepdims=True), Bm], axis=1)
    dFdx = np.zeros((m, d * d, (d + 1) * d))
    for a in range(d + 1):
        for i in range(d):
            dFdx[:, d * i:d * i + d, d * a + i] = G[:, a, :]
    return dFdx


def _gravity_load(T: np.ndarray, vol: np.ndarray, n: int, mat) -> np.ndarray:
    """The gravity load m_i g (d n,), N, on ``n`` nodes: each element's mass density x
    ``vol`` (m,) m^3 lumped equally on its d + 1 corners ``T`` (m, d + 1)."""
    corners = T.shape[1]
    mass = np.zeros(n)
    np.add.at(mass, T.ravel(), np.repeat(mat.density * vol / float(corners), corners))
    return (mass[:, None] * np.asarray(mat.gravity, dtype=float)[None, :]).ravel()


class BaselineGradient:
    """One pose of a problem with its fiber lattice, in 2D or 3D: energy, gradient,
    Hessian, Newton and the adjoint gradient of O = O_pos + O_reg, in numpy/scipy."""

    def __init__(self, problem: Problem, contraction_reg: float):
        if problem.n_poses != 1:
            raise ValueError("the baseline gradient is written for one pose")
        mesh, mat, fs = problem.mesh, problem.material, problem.scene.fibers
        self.d = d = problem.dim
        self.X, self.T = mesh.nodes, mesh.simplices
        n, T = len(self.X), self.T
        self.free = np.repeat(~problem.fixed, d)
        self.mu, self.lam = mat.mu, mat.lam
        self.h = mat.thickness if d == 2 else None  # m; a 3D body has none
        Dm = _edge_matrix(self.X, T)
        self.Bm = np.linalg.inv(Dm)  # (m, d, d)
        self.vol = _rest_volumes(Dm, self.h)  # h A_e in 2D, V_e in 3D, m^3
        self.dFdx = _deformation_derivative(self.Bm)
        self.edofs = (d * T[:, :, None] + np.arange(d)).reshape(-1, (d + 1) * d)
        self.f_ext = _gravity_load(T, self.vol, n, mat)
        # fibers: d_i = c(end 1) - c(end 0) = D x, one row per fiber
        C = _embedding_matrix(problem.fibers.embedding.tri, problem.fibers.embedding.bary, T, n)
        e = problem.fibers.edges
        D = (C[e[:, 1]] - C[e[:, 0]]).tocsr()
        self.Dx = sp.kron(D, sp.identity(d), format="csr")  # (dC, dn)
        self.a0, self.EA, self.eps = problem.fibers.a0, fs.stiffness, fs.eps
        self.Ct = sp.kron(_embedding_matrix(problem.target.tri, problem.target.bary, T, n), sp.identity(d),
                          format="csr")
        self.goal, self.L = problem.target_goal.ravel(), problem.size
        self.w_reg = contraction_reg
        self.F = problem.force_scale  # E h L in 2D, E L^2 in 3D, N

    # ------------------------------------------------------------ the energy
    def _elements(self, x: np.ndarray):
        Fm = _edge_matrix(x, self.T) @ self.Bm
        J = np.linalg.det(Fm)
        return Fm, J

    def _fibers(self, x: np.ndarray, ac: np.ndarray):
        d = (self.Dx @ x.ravel()).reshape(-1, self.d)
        length = np.linalg.norm(d, axis=1)
        a = self.a0 - ac
        return d, length, a, length / a - 1.0

    def energy(self, x: np.ndarray, ac: np.ndarray) -> float:
        """E_tot (J) at positions ``x`` (n, d) m and contractions ``ac`` (C,) m; inf where
        an element is inverted."""
        Fm, J = self._elements(x)
        if np.any(J <= 0):
            return np.inf
        lnJ = np.log(J)
        psi = 0.5 * self.mu * (np.einsum("eij,eij->e", Fm, Fm) - self.d) - self.mu * lnJ + 0.5 * self.lam * lnJ ** 2
        _, _, a, strain = self._fibers(x, ac)
        return float(self.vol @ psi + self.EA * a @ _zcq(strain, self.eps, 0) - self.f_ext @ x.ravel())

    def gradient(self, x: np.ndarray, ac: np.ndarray) -> np.ndarray:
        """dE_tot/dx (d n,), N, at positions ``x`` (n, d) m and contractions ``ac`` (C,) m."""
        Fm, J = self._elements(x)
        FinvT = np.swapaxes(np.linalg.inv(Fm), 1, 2)
        P = self.mu * (Fm - FinvT) + self.lam * np.log(J)[:, None, None] * FinvT
        ge = self.vol[:, None] * np.einsum("ek,ekd->ed", P.reshape(-1, self.d * self.d), self.dFdx)
        g = np.bincount(self.edofs.ravel(), ge.ravel(), minlength=self.X.size)
        d, length, _, strain = self._fibers(x, ac)
        tau = self.EA * _zcq(strain, self.eps, 1)
        return g + self.Dx.T @ (tau[:, None] * d / length[:, None]).ravel() - self.f_ext

    def _body_hessian(self, x: np.ndarray) -> sp.csr_matrix:
        """d2E_body/dx2 (d n, d n), N/m, on all DOFs."""
        Fm, J = self._elements(x)
        Fi = np.linalg.inv(Fm)
        c = self.mu - self.lam * np.log(J)
        # dP_ij/dF_kl = c Fi_li Fi_jk + lam Fi_ji Fi_lk + mu d_ik d_jl
        t = (c[:, None, None, None, None] * np.einsum("eli,ejk->eijkl", Fi, Fi)
             + self.lam * np.einsum("eji,elk->eijkl", Fi, Fi))
        dd, k = self.d * self.d, self.edofs.shape[1]
        tangent = t.reshape(-1, dd, dd) + self.mu * np.eye(dd)
        Ke = self.vol[:, None, None] * np.einsum("eki,ekl,elj->eij", self.dFdx, tangent, self.dFdx)
        rows, cols = np.repeat(self.edofs, k, axis=1).ravel(), np.tile(self.edofs, (1, k)).ravel()
        return sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(self.X.size, self.X.size))

    def hessian(self, x: np.ndarray, ac: np.ndarray) -> sp.csc_matrix:
        """The exact d2E_tot/dx2 on the free DOFs, CSC, N/m, at positions ``x`` (n, d) m
        and contractions ``ac`` (C,) m."""
        H = self._body_hessian(x)
        d, length, a, strain = self._fibers(x, ac)
        nrm = d / length[:, None]
        tau, kc = self.EA * _zcq(strain, self.eps, 1), self.EA * _zcq(strain, self.eps, 2) / a
        nn = nrm[:, :, None] * nrm[:, None, :]
        Kf = kc[:, None, None] * nn + (tau / length)[:, None, None] * (np.eye(self.d) - nn)
        H = H + self.Dx.T @ sp.block_diag(list(Kf), format="csr") @ self.Dx
        return H.tocsc()[self.free][:, self.free].tocsc()

    # ------------------------------------------------------------ Newton and the adjoint
    def equilibrium(self, ac: np.ndarray, x0: np.ndarray, tol: float = EVAL_TOL,
                    max_iter: int = 100) -> np.ndarray:
        """x*(ac) (n, d) m by Newton from ``x0`` (n, d) m: exact Hessian, SuperLU, halving
        until Armijo holds (up to the energy's round-off) and no element is
        inverted; |g_free| <= tol x the force scale (E h L in 2D, E L^2 in 3D)."""
        x = np.array(x0, dtype=float)
        E = self.energy(x, ac)
        for _ in range(max_iter):
            g = self.gradient(x, ac)[self.free]
            if np.linalg.norm(g) <= tol * self.F:
                return x
            step = np.zeros(x.size)
            step[self.free] = spla.splu(self.hessian(x, ac)).solve(-g)
            slope, alpha = float(g @ step[self.free]), 1.0
            if slope >= 0:  # not a descent direction: steepest descent
                step[self.free], slope = -g, -float(g @ g)
                alpha = 1e-3 * self.L / np.abs(g).max()
            slack = 1e-12 * (abs(E) + 1e-3 * self.F * self.L)  # the energy's round-off
            for _ in range(60):
                trial = x + alpha * step.reshape(-1, self.d)
                Et = self.energy(trial, ac)
                if Et <= E + 1e-4 * alpha * slope + slack:
                    break
                alpha *= 0.5
            else:
                raise ConvergenceError("baseline Newton: no step decreases the energy")
            x, E = trial, Et
        raise ConvergenceError("baseline Newton did not converge")

    def objective_gradient(self, r: np.ndarray, x0: np.ndarray,
                           tol: float = EVAL_TOL) -> tuple[float, np.ndarray, np.ndarray]:
        """O(r) = sum_t |x_t - goal_t|^2 / L^2 + w_ac sum_i r_i^2 at x*(r a0), its
        gradient dO/dr (C,) by one adjoint solve, and x* (n, d) m, Newton from ``x0``
        to ``tol``."""
        ac = r * self.a0
        x = self.equilibrium(ac, x0, tol)
        res = self.Ct @ x.ravel() - self.goal
        value = float(res @ res) / self.L ** 2 + self.w_reg * float(r @ r)
        dOdx = 2.0 * (self.Ct.T @ res) / self.L ** 2
        lam = np.zeros(x.size)
        lam[self.free] = spla.splu(self.hessian(x, ac)).solve(dOdx[self.free])
        # d2E/(dx dac_i) = tau_ac_i dl_i/dx, tau_ac = EA Z''(e) l / a^2
        d, length, a, strain = self._fibers(x, ac)
        tau_ac = self.EA * _zcq(strain, self.eps, 2) * length / a ** 2
        mixed = tau_ac * np.einsum("cd,cd->c", (self.Dx @ lam).reshape(-1, self.d), d / length[:, None])
        dOdac = 2.0 * self.w_reg * r / self.a0 - mixed
        return value, dOdac * self.a0, x
