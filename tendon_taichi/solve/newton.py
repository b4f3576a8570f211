"""Equilibrium solves: Newton with a backtracking line search on a linear backend.

``x*(ac) = argmin_x E_tot(x, ac)`` over the free DOFs (``docs/method.md``):

* each Newton step solves ``H dx = -g`` with the *exact* Hessian first; only
  when the linear solve meets negative curvature or the step is not a descent
  direction is the step redone with per-element PSD projection;
* inexact Newton: the linear solve stops at a relative residual
  ``eta = min(0.01, sqrt(|g|/F))`` (superlinear convergence);
* the line search backtracks on ``E_tot`` and never accepts an inverted
  triangle (``det F <= 0``);
* converged when ``|g_free| <= tol * F`` with the force scale ``F = E h L``;
* with capstan friction (:mod:`tendon_taichi.physics.capstan`) the weights
  are set from the current angles before every step and frozen inside it, so
  the converged state balances the frictional forces.

The backend (:mod:`.linear`) is given by name or as a
:class:`~tendon_taichi.solve.linear.LinearSolver`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import ConvergenceError
from ..physics.model import Model
from ._newton_kernels import accept, newton_rhs, take_direction, trial
from .backends import make_linear_solver
from .linear import LinearSolver


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
        E, jmin = m.energy_and_min_det()
        if jmin <= 0.0:
            raise ConvergenceError("the starting state has an inverted triangle")
        F = self.force_scale
        tol = self.tol if tol is None else tol
        projected = 0
        gnorm, fresh = np.inf, False
        for it in range(self.max_iter + 1):
            if m.capstan is not None and m.update_friction() > 0.0:
                E, _ = m.energy_and_min_det()
            previous, gnorm = gnorm, float(np.sqrt(m.gradient_norm2()))
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
        newton_rhs(m)
        return take_direction(m, from_cg=False)

    def _line_search(self, E: float, slope: float, gnorm: float) -> float:
        """Backtrack from the full step until Armijo holds with no inverted triangle;
        accept and return the new energy."""
        m = self.model
        slack = 1e-12 * (abs(E) + 1e-3 * self.energy_scale)  # energy round-off
        alpha = 1.0
        for _ in range(60):
            E_new, jmin = trial(m, alpha)
            if jmin > 0.0 and E_new <= E + 1e-4 * alpha * slope + slack:
                accept(m)
                return float(E_new)
            alpha *= 0.5
        raise ConvergenceError(
            f"equilibrium line search failed: relative force residual "
            f"{gnorm / self.force_scale:.2e}, no step decreases the energy")
