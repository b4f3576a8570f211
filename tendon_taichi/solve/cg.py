"""The matrix-free CG backend: Hessian products in Taichi (the model is the
operator), preconditioned by a reused factorization of the Hessian at a
nearby state (``cg``), by a reused algebraic-multigrid V-cycle of it
(``cg-amg``, :mod:`.multigrid`), by a reused geometric-multigrid V-cycle over
the body's coarser meshes (``cg-gmg``, the same module) or by 2x2 block Jacobi
inside one fused Taichi kernel per iteration (``cg-jacobi``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from ..errors import ConvergenceError, InputError
from ..physics.layout import CGState, Scalar
from ..physics.model import Model
from . import _cg_kernels as kernels
from ._newton_kernels import newton_rhs, take_direction
from .direct import Factorization
from .linear import LinearSolver, LinearStats
from .multigrid import GeometricMultigridPreconditioner, MultigridPreconditioner
from .preconditioner import ReusedPreconditioner

#: preconditioner -> the backend's name in SOLVERS
PRECONDITIONERS = {"factor": "cg", "multigrid": "cg-amg", "geometric": "cg-gmg", "jacobi": "cg-jacobi"}


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


def block_jacobi_pcg(model: Model, rhs: np.ndarray | None, tol: float, max_iter: int,
                     warm: bool = False, check_every: int = 8) -> CGStatus:
    """Solve H y = rhs on the free DOFs with block-Jacobi PCG, H as last prepared.

    ``rhs`` (n, 2) is copied in (None: already in place, as for Newton); the
    solution stays in the buffers (:func:`cg_solution`). ``tol`` is relative to
    |rhs|; ``warm`` starts from the previous solution. Parallel models check
    for convergence on the host every ``check_every`` iterations."""
    m = model
    if rhs is not None:
        m.write("CB", np.asarray(rhs, dtype=np.float64).reshape(m.n, 2))
    done = kernels.k_cg_begin(m.fb, m.ib, 1 if warm else 0, float(tol), m.serial)
    if not done:
        if m.serial:
            kernels.k_cg_run(m.fb, m.ib, int(max_iter))
        else:
            launched = 0
            while launched < max_iter:
                k = min(check_every, max_iter - launched)
                for _ in range(k):
                    kernels.k_cg_step(m.fb, m.ib)
                launched += k
                if kernels.k_cg_done(m.ib):
                    break
    sc = m.read("SCALARS", 13)
    it = m.read_int("CG_STATE", CGState.ITERS)
    res = float(np.sqrt(sc[Scalar.RR] / sc[Scalar.BB])) if sc[Scalar.BB] > 0 else 0.0
    return CGStatus(it, bool(res <= tol), bool(m.read_int("CG_STATE", CGState.NEGCURV)), res)


def host_pcg(model: Model, rhs: np.ndarray | None, tol: float, max_iter: int, precondition,
             warm: bool = False) -> CGStatus:
    """Solve H y = rhs on the free DOFs by CG preconditioned on the host:
    ``precondition(r)`` maps a residual (2n,) to z (2n,), e.g. a factorization's
    solve. H products stay in Taichi (as last prepared); the solution stays in
    the buffers (:func:`cg_solution`)."""
    m = model
    if rhs is not None:
        m.write("CB", np.asarray(rhs, dtype=np.float64).reshape(m.n, 2))
    r = np.empty(2 * m.n)
    bb, rr = kernels.k_pcg_begin(m.fb, m.ib, 1 if warm else 0, r, m.serial)
    tol2 = tol * tol * bb
    it, negcurv, indefinite = 0, False, False
    if rr > tol2:
        z = precondition(r)
        rz = float(r @ z)
        indefinite = not rz > 0.0
        if not indefinite:
            kernels.k_pcg_direction(m.fb, m.ib, z, 0.0, m.serial)
        while not indefinite and it < max_iter:
            pq = kernels.k_pcg_matvec(m.fb, m.ib, m.serial)
            if pq <= 0.0:
                negcurv = True
                break
            rr = kernels.k_pcg_update(m.fb, m.ib, rz / pq, r, m.serial)
            it += 1
            if rr <= tol2:
                break
            z = precondition(r)
            rz_new = float(r @ z)
            if not rz_new > 0.0:
                indefinite = True
                break
            kernels.k_pcg_direction(m.fb, m.ib, z, rz_new / rz, m.serial)
            rz = rz_new
    res = float(np.sqrt(rr / bb)) if bb > 0 else 0.0
    return CGStatus(it, bool(res <= tol), negcurv, res, indefinite)


def cg_solution(model: Model) -> np.ndarray:
    """The last CG solution (n, 2)."""
    return model.node_vectors("CX")


class FactorPreconditioner(ReusedPreconditioner):
    """M^-1 = the direct backend's factorization of the Hessian at a reference state, reused
    while the solves it preconditions stay short: a solve that takes more than
    ``refresh_iterations`` marks it stale, and the next solve refreshes it at the
    state of the moment (a factorization at a nearby design preconditions to a
    few tens of iterations). The exact Hessian is factorized first (measured: 25
    instead of 34 CG iterations for a warm level-5 t_shape solve); where it is
    not positive definite (PCG meets r.M^-1 r <= 0), the PSD-projected one,
    which always is."""

    def __init__(self, model: Model, refresh_iterations: int = 20, factor_threads: int | None = None):
        super().__init__(model, refresh_iterations, factor_threads=factor_threads)

    @property
    def lu(self) -> Factorization | None:
        """The factorization in use (None when stale)."""
        return self.operator

    def build(self, project: bool) -> Factorization:
        return self.direct.factorize(self.direct.assemble_ordered(project=project))

    def apply(self, operator: Factorization, r: np.ndarray) -> np.ndarray:
        return operator.solve(r)


class CGSolver(LinearSolver):
    """Matrix-free PCG: Hessian products in Taichi, preconditioned by a reused
    factorization (``factor``, default), a reused algebraic-multigrid V-cycle
    (``multigrid``), a reused geometric-multigrid V-cycle (``geometric``) or
    2x2 block Jacobi inside one fused Taichi kernel per iteration (``jacobi``)."""

    def __init__(self, model: Model, max_iter: int | None = None, preconditioner: str = "factor",
                 factor_threads: int | None = None):
        if preconditioner not in PRECONDITIONERS:
            raise InputError(f"unknown preconditioner '{preconditioner}' (choose from "
                             f"{', '.join(PRECONDITIONERS)})")
        #: the backend's name in SOLVERS (what a recording keeps, so replay takes the same one)
        self.name = PRECONDITIONERS[preconditioner]
        self.model = model
        self.preconditioner = preconditioner
        self.pre = (FactorPreconditioner(model, factor_threads=factor_threads) if preconditioner == "factor" else
                    MultigridPreconditioner(model) if preconditioner == "multigrid" else
                    GeometricMultigridPreconditioner(model) if preconditioner == "geometric" else None)
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
            st = block_jacobi_pcg(m, rhs, tol=tol, max_iter=self.max_iter, warm=warm)
        else:
            if self.pre.stale:  # reset by a long solve just before, on the same prepared Hessian
                self.pre.refresh()
                m.prepare_hessian(self._project)
            st = host_pcg(m, rhs, tol, self.max_iter, self.pre, warm=warm)
            if st.indefinite_preconditioner or (not st.converged and not st.negative_curvature):
                # an indefinite reference Hessian, or too far from it
                self.pre.refresh(project=st.indefinite_preconditioner or self.pre.projected)
                m.prepare_hessian(self._project)
                st = host_pcg(m, None, tol, self.max_iter, self.pre, warm=False)
            if st.iterations > self.pre.refresh_iterations:
                self.pre.reset()
        self.last = st
        self.stats.solves += 1
        self.stats.iterations += st.iterations
        return st

    def newton_direction(self, eta: float, project: bool, fresh: bool = True) -> tuple[float, bool, int]:
        m = self.model
        self._prepare(project)
        newton_rhs(m)
        st = self._run(None, eta, warm=False)
        return take_direction(m), st.negative_curvature, st.iterations

    def solve(self, rhs: np.ndarray, tol: float, warm: bool = False,
              prepare: bool = True) -> np.ndarray:
        if prepare:
            self._prepare(False)
        st = self._run(rhs, tol, warm)
        if not st.converged:
            raise ConvergenceError(f"CG did not converge: relative residual {st.residual:.2e} "
                                   f"after {st.iterations} iterations (tolerance {tol:.1e})")
        return cg_solution(self.model)

    def approx_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """H^-1 rhs through the preconditioner's factorization (None without one)."""
        if not isinstance(self.pre, FactorPreconditioner) or self.pre.lu is None:
            return None
        return self.pre(np.asarray(rhs, dtype=float).ravel()).reshape(-1, 2)

    def resolve(self, rhs: np.ndarray, tol: float) -> np.ndarray:
        """One CG solve with the Hessian as last prepared."""
        return self.solve(rhs, tol=tol, prepare=False)

    def solve_many(self, rhs: Iterable[np.ndarray], tol: float) -> Iterator[np.ndarray]:
        """One CG solve per right-hand side; the Hessian is prepared for the first."""
        for j, b in enumerate(rhs):
            yield self.solve(b, tol=tol) if j == 0 else self.resolve(b, tol)

    def reset(self) -> None:
        if self.pre is not None:
            self.pre.reset()

    def cables_moved(self) -> None:
        if self.pre is not None:
            self.pre.direct.cables_moved()
        self.reset()
