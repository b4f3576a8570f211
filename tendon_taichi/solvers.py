"""Equilibrium solves: Newton with a backtracking line search, on two linear backends.

``x*(ac) = argmin_x E_tot(x, ac)`` over the free DOFs (DESIGN.md section 4):

* each Newton step solves ``H dx = -g`` with the *exact* Hessian first; only
  when the linear solve meets negative curvature or the step is not a descent
  direction is the step redone with per-element PSD projection;
* inexact Newton: the linear solve stops at a relative residual
  ``eta = min(0.01, sqrt(|g|/F))`` (superlinear convergence);
* the line search backtracks on ``E_tot`` and never accepts an inverted
  triangle (``det F <= 0``);
* converged when ``|g_free| <= tol * F`` with the force scale ``F = E h L``.

Backends (``LinearSolver`` protocol): ``cg`` - matrix-free block-Jacobi PCG in
Taichi (one kernel launch per iteration, or one per solve for serialized
small models); ``direct`` - the same Hessian assembled into a scipy sparse
matrix and factorized with SuperLU.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import ConvergenceError, InputError
from .model import CGStatus, Model

SOLVERS = ("cg", "direct")


@dataclass
class Equilibrium:
    """One equilibrium: positions ``x`` (n, 2) m, cable tensions ``tau`` (C,) N,
    ``energy`` J, relative force ``residual`` (|g_free| / F), and solver counts."""

    x: np.ndarray
    tau: np.ndarray
    energy: float
    residual: float
    newton_iterations: int
    linear_iterations: int
    projected_steps: int
    time_s: float


@dataclass
class LinearStats:
    solves: int = 0
    iterations: int = 0
    history: list = field(default_factory=list)


class LinearSolver(Protocol):
    """What Newton and the adjoint need from a linear backend."""

    name: str

    def newton_direction(self, eta: float, project: bool) -> tuple[float, bool, int]:
        """Solve H dx = -g (H exact or projected, at the model's x) into the model's
        Newton direction; return (g . dx, met negative curvature, iterations)."""

    def solve(self, rhs: np.ndarray, tol: float) -> np.ndarray:
        """y (n, 2) with H y = rhs on the free DOFs (exact H at x, zero on fixed DOFs)."""


class CGSolver:
    """Matrix-free block-Jacobi PCG on the Taichi model."""

    name = "cg"

    def __init__(self, model: Model, max_iter: int | None = None):
        self.model = model
        self.max_iter = max_iter or max(1000, 4 * model.dofs)
        self.stats = LinearStats()
        self.last: CGStatus | None = None

    def newton_direction(self, eta: float, project: bool) -> tuple[float, bool, int]:
        m = self.model
        m.prepare_hessian(project)
        m._newton_rhs()
        st = m.cg_solve(None, tol=eta, max_iter=self.max_iter)
        self._count(st)
        return m._take_direction(), st.negative_curvature, st.iterations

    def solve(self, rhs: np.ndarray, tol: float, warm: bool = False,
              prepare: bool = True) -> np.ndarray:
        m = self.model
        if prepare:
            m.prepare_hessian(False)
        st = m.cg_solve(rhs, tol=tol, max_iter=self.max_iter, warm=warm)
        self._count(st)
        if not st.converged:
            raise ConvergenceError(f"CG did not converge: relative residual {st.residual:.2e} "
                                   f"after {st.iterations} iterations (tolerance {tol:.1e})")
        return m.cg_solution()

    def _count(self, st: CGStatus) -> None:
        self.last = st
        self.stats.solves += 1
        self.stats.iterations += st.iterations


class DirectSolver:
    """The model's Hessian assembled as a scipy sparse matrix, factorized by SuperLU."""

    name = "direct"

    def __init__(self, model: Model):
        self.model = model
        self.stats = LinearStats()
        self.free = np.repeat(~model.fixed, 2)
        self._pattern = self._build_pattern()

    def _build_pattern(self):
        """Global DOF indices of every element and cable-segment Hessian entry."""
        m = self.model
        T = m.mesh.triangles
        edofs = (2 * T[:, :, None] + np.arange(2)[None, None, :]).reshape(-1, 6)  # (m, 6)
        cab = m.cables
        pt_nodes = T[cab.points.tri]
        seg_nodes = np.concatenate([pt_nodes[cab.segments[:, 0]], pt_nodes[cab.segments[:, 1]]], 1)
        seg_coef = np.concatenate([-cab.points.bary[cab.segments[:, 0]],
                                   cab.points.bary[cab.segments[:, 1]]], 1)  # (S, 6)
        sdofs = (2 * seg_nodes[:, :, None] + np.arange(2)[None, None, :]).reshape(-1, 12)
        return edofs, sdofs, seg_coef

    def assemble(self, project: bool = False, prepare: bool = True) -> sp.csr_matrix:
        """The Hessian of E_tot at x restricted to the free DOFs (exact or projected)."""
        m = self.model
        if prepare:
            m.prepare_hessian(project)
        d = m.hessian_data()
        edofs, sdofs, coef = self._pattern
        # element Hessians vol * B^T D B, B = d vec(F) / d x_local (4 x 6)
        Bm = d["Bm"]
        G = np.stack([-(Bm[:, 0] + Bm[:, 1]), Bm[:, 0], Bm[:, 1]], axis=1)  # (m, 3, 2)
        B = np.zeros((m.m, 4, 6))
        for i in range(2):
            for j in range(2):
                B[:, 2 * i + j, i::2] = G[:, :, j]
        He = d["vol"][:, None, None] * np.einsum("eri,ers,esj->eij", B, d["D"], B)
        rows = [np.repeat(edofs, 6, axis=1).ravel()]
        cols = [np.tile(edofs, (1, 6)).ravel()]
        vals = [He.ravel()]
        if m.S:
            n_s, l_s = d["seg_n"], d["seg_l"]
            seg_cable = np.repeat(np.arange(m.C), np.diff(m.cables.start))
            tau, kc = d["tau"][seg_cable], d["kc"]
            # geometric part of each segment: tau/l (I - n n^T) through the 12 DOFs
            with np.errstate(divide="ignore", invalid="ignore"):
                geo = np.where(l_s > 0, tau / l_s, 0.0)[:, None, None] * (
                    np.eye(2)[None] - n_s[:, :, None] * n_s[:, None, :])
            cc = coef[:, :, None] * coef[:, None, :]  # (S, 6, 6)
            Ks = np.einsum("sab,sij->saibj", cc, geo).reshape(-1, 12, 12)
            rows.append(np.repeat(sdofs, 12, axis=1).ravel())
            cols.append(np.tile(sdofs, (1, 12)).ravel())
            vals.append(Ks.ravel())
            # axial part kc (dL/dx)(dL/dx)^T per cable, dL/dx = sum over its segments
            grad = (coef[:, :, None] * n_s[:, None, :]).reshape(-1, 12)  # (S, 12)
            if m.single:
                rows.append(np.repeat(sdofs, 12, axis=1).ravel())
                cols.append(np.tile(sdofs, (1, 12)).ravel())
                vals.append((kc[:, None, None] * grad[:, :, None] * grad[:, None, :]).ravel())
            else:
                starts = m.cables.start
                for c in np.flatnonzero(kc > 0):
                    s0, s1 = starts[c], starts[c + 1]
                    gdofs, gv = sdofs[s0:s1].ravel(), grad[s0:s1].ravel()
                    rows.append(np.repeat(gdofs, len(gdofs)))
                    cols.append(np.tile(gdofs, len(gdofs)))
                    vals.append(kc[c] * np.outer(gv, gv).ravel())
        N = 2 * m.n
        H = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(N, N)).tocsr()
        return H[self.free][:, self.free]

    def _factor_solve(self, H: sp.csr_matrix, b: np.ndarray) -> np.ndarray:
        try:
            lu = spla.splu(H.tocsc(), permc_spec="MMD_AT_PLUS_A")
        except RuntimeError as exc:  # exactly singular
            raise np.linalg.LinAlgError(str(exc)) from None
        y = lu.solve(b)
        if not np.all(np.isfinite(y)):
            raise np.linalg.LinAlgError("non-finite solution")
        self.stats.solves += 1
        return y

    def newton_direction(self, eta: float, project: bool) -> tuple[float, bool, int]:
        m = self.model
        H = self.assemble(project)
        g = m._nodes("G").ravel()[self.free]
        try:
            y = self._factor_solve(H, -g)
        except np.linalg.LinAlgError:
            return 0.0, True, 0
        dx = np.zeros(2 * m.n)
        dx[self.free] = y
        m._write("CX", dx)
        return m._take_direction(), False, 0

    def solve(self, rhs: np.ndarray, tol: float = 0.0, warm: bool = False,
              prepare: bool = True) -> np.ndarray:
        H = self.assemble(False, prepare)
        b = np.asarray(rhs, dtype=float).ravel()[self.free]
        try:
            y = self._factor_solve(H, b)
        except np.linalg.LinAlgError as exc:
            raise ConvergenceError(f"the Hessian is singular: {exc}") from None
        out = np.zeros(2 * self.model.n)
        out[self.free] = y
        return out.reshape(-1, 2)


def make_linear_solver(name: str, model: Model) -> LinearSolver:
    """A linear backend by name: ``cg`` or ``direct``."""
    if name == "cg":
        return CGSolver(model)
    if name == "direct":
        return DirectSolver(model)
    raise InputError(f"unknown solver '{name}' (choose from {', '.join(SOLVERS)})")


class NewtonSolver:
    """Equilibrium of a model by Newton's method (see the module docstring).

    ``tol``: relative force tolerance (|g_free| / F); ``force_scale`` F in N
    (default E h L); ``max_iter`` Newton iterations; ``eta_max`` caps the
    forcing term (relative tolerance of each linear solve).
    """

    def __init__(self, model: Model, solver: str | LinearSolver = "cg", tol: float = 1e-10,
                 max_iter: int = 100, force_scale: float | None = None, eta_max: float = 0.01):
        self.model = model
        self.linear = make_linear_solver(solver, model) if isinstance(solver, str) else solver
        self.tol = tol
        self.max_iter = max_iter
        self.eta_max = eta_max
        mat = model.material
        self.force_scale = force_scale or mat.youngs_modulus * mat.thickness * model.mesh.size
        self.energy_scale = self.force_scale * model.mesh.size

    def solve(self, ac: np.ndarray | None = None, x0: np.ndarray | None = None) -> Equilibrium:
        """Equilibrium for contractions ``ac`` (C,) m (default: as set), starting from
        ``x0`` (n, 2) (default: the model's current positions: a warm start)."""
        t0 = time.perf_counter()
        m = self.model
        if ac is not None:
            m.set_contraction(ac)
        if x0 is not None:
            m.set_positions(x0)
        lin0 = self.linear.stats.iterations
        E, jmin = m._energy_at(trial=False)
        if jmin <= 0.0:
            raise ConvergenceError("the starting state has an inverted triangle")
        F = self.force_scale
        projected = 0
        gnorm = np.inf
        for it in range(self.max_iter + 1):
            gnorm = float(np.sqrt(m._gradient_norm2()))
            if gnorm <= self.tol * F:
                break
            if it == self.max_iter:
                raise ConvergenceError(
                    f"equilibrium did not converge: relative force residual {gnorm / F:.2e} "
                    f"after {it} Newton iterations (tolerance {self.tol:.1e})")
            eta = min(self.eta_max, np.sqrt(gnorm / F))
            slope, negcurv, _ = self.linear.newton_direction(eta, project=False)
            if negcurv or not slope < 0.0:
                projected += 1
                slope, negcurv, _ = self.linear.newton_direction(eta, project=True)
                if negcurv or not slope < 0.0:
                    slope = self._steepest_descent()
            E = self._line_search(E, slope, gnorm)
        return Equilibrium(x=m.positions(), tau=m.tensions(), energy=float(E),
                           residual=gnorm / F, newton_iterations=it,
                           linear_iterations=self.linear.stats.iterations - lin0,
                           projected_steps=projected, time_s=time.perf_counter() - t0)

    def _steepest_descent(self) -> float:
        m = self.model
        m._newton_rhs()
        return m._take_direction(from_cg=False)

    def _line_search(self, E: float, slope: float, gnorm: float) -> float:
        """Backtrack from the full step until Armijo holds with no inverted triangle;
        accept and return the new energy."""
        m = self.model
        slack = 1e-12 * (abs(E) + 1e-3 * self.energy_scale)  # energy round-off
        alpha = 1.0
        for _ in range(60):
            m._trial(alpha)
            E_new, jmin = m._energy_at(trial=True)
            if jmin > 0.0 and E_new <= E + 1e-4 * alpha * slope + slack:
                m._accept()
                return float(E_new)
            alpha *= 0.5
        raise ConvergenceError(
            f"equilibrium line search failed: relative force residual "
            f"{gnorm / self.force_scale:.2e}, no step decreases the energy")
