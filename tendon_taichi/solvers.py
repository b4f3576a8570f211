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

Backends (``LinearSolver`` protocol): ``cg`` - PCG with the Hessian products in
Taichi, preconditioned by a reused factorization of the Hessian at a nearby
state (refreshed when a solve needs more than 20 iterations); ``cg-jacobi`` -
block-Jacobi PCG entirely in Taichi (one kernel launch per iteration, or one
per solve for serialized small models); ``direct`` - the same Hessian assembled
into a scipy sparse matrix and factorized with SuperLU; ``auto`` - direct up to
5000 free DOFs, cg above (measured).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Iterable, Iterator, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import ConvergenceError, InputError
from .model import CGStatus, Model

SOLVERS = ("auto", "cg", "cg-jacobi", "direct")

#: ``auto`` takes the direct backend up to this many free DOFs and the
#: factorization-preconditioned CG above. Measured on the 2-core CPU machine
#: (t_shape): inside the optimizer direct is 5-30 % faster at levels 1-3
#: (714-2716 DOFs) and even at level 4 (5336); single warm-started equilibria are
#: faster with CG from level 3 on (level 5, 10504 DOFs: 194 ms against 305 ms).
AUTO_DIRECT_MAX_DOFS = 5000


def resolve_solver(name: str, dofs: int) -> str:
    """The backend that ``name`` stands for at this size (``auto`` picks by DOFs)."""
    if name == "auto":
        return "direct" if dofs <= AUTO_DIRECT_MAX_DOFS else "cg"
    if name not in SOLVERS:
        raise InputError(f"unknown solver '{name}' (choose from {', '.join(SOLVERS)})")
    return name


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
    """Counts: ``solves`` (factorizations or CG solves), ``iterations`` (CG),
    ``reused`` (direct steps with an earlier factorization)."""

    solves: int = 0
    iterations: int = 0
    reused: int = 0


class LinearSolver(Protocol):
    """What Newton and the adjoint need from a linear backend."""

    name: str

    def newton_direction(self, eta: float, project: bool, fresh: bool = True) -> tuple[float, bool, int]:
        """Solve H dx = -g (H exact or projected, at the model's x) into the model's
        Newton direction; return (g . dx, met negative curvature, iterations).
        ``fresh=False`` allows a backend to reuse the Hessian of a nearby state."""

    def solve(self, rhs: np.ndarray, tol: float) -> np.ndarray:
        """y (n, 2) with H y = rhs on the free DOFs (exact H at x, zero on fixed DOFs)."""


PRECONDITIONERS = ("factor", "jacobi")


class Factorization:
    """A SuperLU factorization of ``P H P^T``, ``P`` the fill-reducing ordering of
    the backend's sparsity pattern (computed once, not per factorization);
    :meth:`solve` works in the free-DOF numbering of ``H``."""

    def __init__(self, Hp: sp.csc_matrix, order: np.ndarray):
        try:
            self.lu = spla.splu(Hp, permc_spec="NATURAL", diag_pivot_thresh=0.1,
                                options={"SymmetricMode": True})
        except RuntimeError as exc:  # exactly singular
            raise np.linalg.LinAlgError(str(exc)) from None
        self.order = order

    def solve(self, b: np.ndarray) -> np.ndarray:
        """y with H y = b, b (nf,) on the free DOFs."""
        bp = np.empty_like(b)
        bp[self.order] = b
        return self.lu.solve(bp)[self.order]


class FactorPreconditioner:
    """M^-1 = a SuperLU factorization of the Hessian at a reference state, reused
    while the solves it preconditions stay short: a solve that takes more than
    ``refresh_iterations`` marks it stale, and the next solve refreshes it at the
    state of the moment (DESIGN.md section 8: a factorization at a nearby design
    preconditions to a few tens of iterations). The exact Hessian is factorized
    first (measured: 25 instead of 34 CG iterations for a warm level-5 t_shape
    solve); where it is not positive definite (PCG meets r.M^-1 r <= 0), the
    PSD-projected one, which always is."""

    def __init__(self, model: Model, refresh_iterations: int = 20):
        self.direct = DirectSolver(model)
        self.refresh_iterations = refresh_iterations
        self.lu: Factorization | None = None
        self.projected = False
        self.refreshes = 0

    @property
    def stale(self) -> bool:
        return self.lu is None

    def refresh(self, project: bool = False) -> None:
        """Factorize the (exact or projected) Hessian at the model's current state
        (this leaves the model's element tangents so: prepare them again afterwards)."""
        try:
            self.lu = self.direct.factorize(self.direct.assemble_ordered(project=project))
        except np.linalg.LinAlgError:  # exactly singular: the projected one is not
            if project:
                raise
            self.lu = self.direct.factorize(self.direct.assemble_ordered(project=True))
            project = True
        self.projected = project
        self.refreshes += 1

    def __call__(self, r: np.ndarray) -> np.ndarray:
        z = np.zeros_like(r)
        z[self.direct.free] = self.lu.solve(r[self.direct.free])
        return z

    def reset(self) -> None:
        self.lu = None


class CGSolver:
    """Matrix-free PCG: Hessian products in Taichi, preconditioned by a reused
    factorization (``factor``, default) or by 2x2 block Jacobi inside one fused
    Taichi kernel per iteration (``jacobi``)."""

    name = "cg"

    def __init__(self, model: Model, max_iter: int | None = None, preconditioner: str = "factor"):
        if preconditioner not in PRECONDITIONERS:
            raise InputError(f"unknown preconditioner '{preconditioner}' (choose from "
                             f"{', '.join(PRECONDITIONERS)})")
        self.model = model
        self.preconditioner = preconditioner
        self.pre = FactorPreconditioner(model) if preconditioner == "factor" else None
        self.max_iter = max_iter or (200 if self.pre else max(1000, 4 * model.dofs))
        self.stats = LinearStats()
        self.last: CGStatus | None = None
        self._project = False

    def _prepare(self, project: bool) -> None:
        if self.pre is not None and self.pre.stale:
            self.pre.refresh()
        self.model.prepare_hessian(project)
        self._project = project

    def _run(self, rhs: np.ndarray | None, tol: float, warm: bool) -> CGStatus:
        m = self.model
        if self.pre is None:
            st = m.cg_solve(rhs, tol=tol, max_iter=self.max_iter, warm=warm)
        else:
            st = m.pcg_solve(rhs, tol, self.max_iter, self.pre, warm)
            if st.indefinite_preconditioner or (not st.converged and not st.negative_curvature):
                # an indefinite reference Hessian, or too far from it
                self.pre.refresh(project=st.indefinite_preconditioner or self.pre.projected)
                m.prepare_hessian(self._project)
                st = m.pcg_solve(None, tol, self.max_iter, self.pre, False)
            if st.iterations > self.pre.refresh_iterations:
                self.pre.reset()
        self.last = st
        self.stats.solves += 1
        self.stats.iterations += st.iterations
        return st

    def newton_direction(self, eta: float, project: bool, fresh: bool = True) -> tuple[float, bool, int]:
        m = self.model
        self._prepare(project)
        m._newton_rhs()
        st = self._run(None, eta, warm=False)
        return m._take_direction(), st.negative_curvature, st.iterations

    def solve(self, rhs: np.ndarray, tol: float, warm: bool = False,
              prepare: bool = True) -> np.ndarray:
        if prepare:
            self._prepare(False)
        st = self._run(rhs, tol, warm)
        if not st.converged:
            raise ConvergenceError(f"CG did not converge: relative residual {st.residual:.2e} "
                                   f"after {st.iterations} iterations (tolerance {tol:.1e})")
        return self.model.cg_solution()

    def approx_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """H^-1 rhs through the preconditioner's factorization (None without one)."""
        if self.pre is None or self.pre.lu is None:
            return None
        return self.pre(np.asarray(rhs, dtype=float).ravel()).reshape(-1, 2)

    def reset(self) -> None:
        """Forget reused state (a stage start must not depend on earlier stages)."""
        if self.pre is not None:
            self.pre.reset()


class DirectSolver:
    """The model's Hessian assembled as a scipy sparse matrix, factorized by SuperLU.

    The sparsity pattern (free DOFs only) and the scatter map from element and
    cable entries to it are built once; an assembly then only computes values."""

    name = "direct"

    def __init__(self, model: Model):
        self.model = model
        self.stats = LinearStats()
        self.free = np.repeat(~model.fixed, 2)
        self.factor = None  # the last factorization, reused by chord steps and predictors
        self.factor_exact = False
        self._build_structure()

    def _build_structure(self) -> None:
        m = self.model
        T = m.mesh.triangles
        cab = m.cables
        edofs = (2 * T[:, :, None] + np.arange(2)).reshape(-1, 6)  # (m, 6)
        pt_nodes = T[cab.points.tri] if m.P else np.zeros((0, 3), np.int64)
        seg_nodes = np.concatenate([pt_nodes[cab.segments[:, 0]], pt_nodes[cab.segments[:, 1]]], 1)
        self.seg_coef = np.concatenate([-cab.points.bary[cab.segments[:, 0]],
                                        cab.points.bary[cab.segments[:, 1]]], 1)  # (S, 6)
        sdofs = (2 * seg_nodes[:, :, None] + np.arange(2)).reshape(-1, 12)  # (S, 12)
        rows = [np.repeat(edofs, 6, axis=1).ravel(), np.repeat(sdofs, 12, axis=1).ravel()]
        cols = [np.tile(edofs, (1, 6)).ravel(), np.tile(sdofs, (1, 12)).ravel()]
        # the axial part couples all the segments of a cable (one block per cable;
        # single-segment cables add it to their segment's block)
        if not m.single:
            for c in range(m.C):
                g = sdofs[cab.start[c]:cab.start[c + 1]].ravel()
                rows.append(np.repeat(g, len(g)))
                cols.append(np.tile(g, len(g)))
        r, c = np.concatenate(rows), np.concatenate(cols)
        free_index = np.cumsum(self.free) - 1
        self.keep = self.free[r] & self.free[c]
        r, c = free_index[r[self.keep]], free_index[c[self.keep]]
        nf = int(self.free.sum())
        self.order = _fill_reducing_order(r, c, nf)
        r, c = self.order[r], self.order[c]
        key = c.astype(np.int64) * nf + r
        uniq, self.pos = np.unique(key, return_inverse=True)
        self.indices = (uniq % nf).astype(np.int32)
        self.indptr = np.searchsorted(uniq // nf, np.arange(nf + 1)).astype(np.int32)
        self.shape = (nf, nf)
        self.nnz = len(uniq)

    def _values(self) -> np.ndarray:
        """Every Hessian entry in pattern order: element and segment blocks from
        Taichi, then (multi-segment cables) one axial block per cable."""
        m = self.model
        vals = [m.hessian_entries()]
        if not m.single:
            d = m.hessian_data()
            grad = (self.seg_coef[:, :, None] * d["seg_n"][:, None, :]).reshape(-1, 12)  # dL/dx
            st = m.cables.start
            for c in range(m.C):
                gv = grad[st[c]:st[c + 1]].ravel()
                vals.append(d["kc"][c] * np.outer(gv, gv).ravel())
        return np.concatenate(vals)

    def assemble_ordered(self, project: bool = False, prepare: bool = True) -> sp.csc_matrix:
        """``P H P^T``: the Hessian on the free DOFs in the fill-reducing order, CSC."""
        if prepare:
            self.model.prepare_hessian(project)
        vals = self._values()[self.keep]
        data = np.bincount(self.pos, weights=vals, minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)

    def assemble(self, project: bool = False, prepare: bool = True) -> sp.csc_matrix:
        """The Hessian of E_tot at x on the free DOFs (exact or projected), CSC."""
        return self.assemble_ordered(project, prepare)[self.order][:, self.order].tocsc()

    def factorize(self, Hp: sp.csc_matrix) -> Factorization:
        """Factorize an ordered Hessian (:meth:`assemble_ordered`)."""
        return Factorization(Hp, self.order)

    def _factor_solve(self, Hp: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
        lu = self.factorize(Hp)
        y = lu.solve(b)
        res = b - self._ordered_product(Hp, y)
        if np.linalg.norm(res) > 1e-10 * np.linalg.norm(b):  # one step of iterative refinement
            y += lu.solve(res)
        if not np.all(np.isfinite(y)):
            raise np.linalg.LinAlgError("non-finite solution")
        self.stats.solves += 1
        self.factor = lu
        return y

    def _ordered_product(self, Hp: sp.csc_matrix, y: np.ndarray) -> np.ndarray:
        """H y from the ordered matrix, in the free-DOF numbering."""
        yp = np.empty_like(y)
        yp[self.order] = y
        return (Hp @ yp)[self.order]

    def approx_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """Solve with the last factorization (the Hessian it was made from), full (n, 2);
        None before the first."""
        if self.factor is None:
            return None
        out = np.zeros(2 * self.model.n)
        out[self.free] = self.factor.solve(np.asarray(rhs, dtype=float).ravel()[self.free])
        return out.reshape(-1, 2)

    def reset(self) -> None:
        """Forget the last factorization."""
        self.factor = None

    def newton_direction(self, eta: float, project: bool, fresh: bool = True) -> tuple[float, bool, int]:
        """With ``fresh=False`` and a factorization at hand (of the exact Hessian at a
        nearby state), reuse it: a chord step costing one triangular solve."""
        m = self.model
        g = m.g_host[self.free]
        if not fresh and not project and self.factor is not None and self.factor_exact:
            y = self.factor.solve(-g)
            self.stats.reused += 1
        else:
            try:
                y = self._factor_solve(self.assemble_ordered(project), -g)
            except np.linalg.LinAlgError:
                return 0.0, True, 0
            self.factor_exact = not project
        dx = np.zeros(2 * m.n)
        dx[self.free] = y
        return m._direction_from(dx), False, 0

    def solve(self, rhs: np.ndarray, tol: float = 0.0, warm: bool = False,
              prepare: bool = True) -> np.ndarray:
        H = self.assemble_ordered(False, prepare)
        b = np.asarray(rhs, dtype=float).ravel()[self.free]
        try:
            y = self._factor_solve(H, b)
        except np.linalg.LinAlgError as exc:
            raise ConvergenceError(f"the Hessian is singular: {exc}") from None
        self.factor_exact = True
        out = np.zeros(2 * self.model.n)
        out[self.free] = y
        return out.reshape(-1, 2)


def _fill_reducing_order(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
    """A symmetric fill-reducing ordering of a sparsity pattern (entries rows, cols
    in 0..n-1): ``order[i]`` is the new index of DOF i. SuperLU's minimum degree
    on A^T + A, run once on a diagonally dominant matrix of the pattern, so that
    each later factorization skips the ordering (a third of its time)."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    A = sp.csc_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    A = A + sp.diags(np.asarray(abs(A).sum(axis=1)).ravel() + 1.0)
    lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    return np.asarray(lu.perm_c, dtype=np.int64)


def make_linear_solver(name: str, model: Model) -> LinearSolver:
    """A linear backend by name: ``cg`` (factorization-preconditioned), ``cg-jacobi``
    (block Jacobi, all in Taichi), ``direct`` or ``auto``."""
    name = resolve_solver(name, model.dofs)
    if name == "cg":
        return CGSolver(model)
    if name == "cg-jacobi":
        return CGSolver(model, preconditioner="jacobi")
    if name == "direct":
        return DirectSolver(model)
    raise InputError(f"unknown solver '{name}' (choose from {', '.join(SOLVERS)})")


def solve_many(linear: LinearSolver, rhs: Iterable[np.ndarray], tol: float) -> Iterator[np.ndarray]:
    """y (n, 2) with H y = b for each b (n, 2) of ``rhs``, H the Hessian at the model's
    current state: the first solve prepares it (direct: factorizes it), the others
    reuse that (direct: one triangular solve each)."""
    for j, b in enumerate(rhs):
        if j and isinstance(linear, DirectSolver):
            yield linear.approx_solve(b)
        else:
            yield linear.solve(b, tol=tol, prepare=(j == 0))


class NewtonSolver:
    """Equilibrium of a model by Newton's method (see the module docstring).

    ``tol``: relative force tolerance (|g_free| / F); ``force_scale`` F in N
    (default E h L); ``max_iter`` Newton iterations; ``eta_max`` caps the
    forcing term (relative tolerance of each linear solve); ``reuse`` lets the
    direct backend reuse its last factorization (chord steps) while the residual
    keeps shrinking at least by ``chord_ratio`` per step - for sequences of nearby
    solves, as in the optimizer.
    """

    def __init__(self, model: Model, solver: str | LinearSolver = "auto", tol: float = 1e-10,
                 max_iter: int = 100, force_scale: float | None = None, eta_max: float = 0.01,
                 reuse: bool = False):
        self.model = model
        self.linear = make_linear_solver(solver, model) if isinstance(solver, str) else solver
        self.tol = tol
        self.max_iter = max_iter
        self.eta_max = eta_max
        #: a step with a reused Hessian must shrink the residual at least this much
        self.chord_ratio = 0.5
        self.reuse = reuse
        mat = model.material
        self.force_scale = force_scale or mat.youngs_modulus * mat.thickness * model.mesh.size
        self.energy_scale = self.force_scale * model.mesh.size

    def solve(self, ac: np.ndarray | None = None, x0: np.ndarray | None = None,
              tol: float | None = None) -> Equilibrium:
        """Equilibrium for contractions ``ac`` (C,) m (default: as set), starting from
        ``x0`` (n, 2) (default: the model's current positions: a warm start), to the
        relative force tolerance ``tol`` (default: the solver's)."""
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
        tol = self.tol if tol is None else tol
        projected = 0
        gnorm, fresh = np.inf, False
        for it in range(self.max_iter + 1):
            previous, gnorm = gnorm, float(np.sqrt(m._gradient_norm2()))
            if gnorm <= tol * F:
                break
            if it == self.max_iter:
                raise ConvergenceError(
                    f"equilibrium did not converge: relative force residual {gnorm / F:.2e} "
                    f"after {it} Newton iterations (tolerance {tol:.1e})")
            # a reused Hessian (chord step) must keep contracting fast, else refresh it
            fresh = fresh or not self.reuse or gnorm > self.chord_ratio * previous
            eta = min(self.eta_max, np.sqrt(gnorm / F))
            slope, negcurv, _ = self.linear.newton_direction(eta, project=False, fresh=fresh)
            if (negcurv or not slope < 0.0) and not fresh:
                fresh = True
                slope, negcurv, _ = self.linear.newton_direction(eta, project=False, fresh=True)
            if negcurv or not slope < 0.0:
                projected += 1
                slope, negcurv, _ = self.linear.newton_direction(eta, project=True)
                if negcurv or not slope < 0.0:
                    slope = self._steepest_descent()
            E = self._line_search(E, slope, gnorm)
            fresh = False
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
            E_new, jmin = m._trial(alpha)
            if jmin > 0.0 and E_new <= E + 1e-4 * alpha * slope + slack:
                m._accept()
                return float(E_new)
            alpha *= 0.5
        raise ConvergenceError(
            f"equilibrium line search failed: relative force residual "
            f"{gnorm / self.force_scale:.2e}, no step decreases the energy")
