"""Equilibrium solves: Newton with a backtracking line search on a linear backend.

``x*(ac) = argmin_x E_tot(x, ac)`` over the free DOFs (``docs/method.md``):

* each Newton step solves ``H dx = -g`` with the *exact* Hessian first; only
  when the linear solve meets negative curvature or the step is not a descent
  direction is the step redone with per-element PSD projection;
* inexact Newton: the linear solve stops at a relative residual
  ``eta = min(0.01, sqrt(|g|/F))`` (superlinear convergence);
* the line search backtracks on ``E_tot`` and never accepts an inverted
  triangle (``det F <= 0``);
* converged when ``|g_free| <= tol * F`` with the force scale ``F = E h L``, or
  where round-off stops it just short of that: the residual has stayed within
  :data:`ROUNDOFF_FACTOR` of the tolerance and :data:`STALL_STEPS` steps did not
  halve it (t_shape's lattice at level 8, 82k DOFs, from rest: 1.2e-12 +- 10 % from
  the 12th step on, against the 1e-12 its stage states ask for; before, 89 more
  steps and an error);
* with ``reuse`` (chord steps on the direct backend's last factorization ``H0``,
  while the residual keeps shrinking fast) a fiber lattice's chord step after the first is
  corrected by the secant pairs of the steps since ``H0`` was made
  (:mod:`.secant`), and the factorization is refreshed only when a step leaves
  more than 0.7 of the residual (0.5 after plain chord steps): the same
  evaluations of t_shape's optimization at level 5 take 12 % less time (a
  quarter fewer factorizations), at levels 2 and 3 about as long
  (benchmarks/secant_replay.py);
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
from ._newton_kernels import accept, direction_from, newton_rhs, take_direction, trial
from .backends import make_linear_solver
from .linear import LinearSettings, LinearSolver
from .secant import PAIRS, SecantMemory

#: a residual at most this many times the tolerance ...
ROUNDOFF_FACTOR = 10.0
#: ... that this many steps in a row did not halve is the round-off floor: converged
STALL_STEPS = 5


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
    solves, as in the optimizer -, its chord steps corrected by secant pairs
    (:mod:`.secant`) where the cables are one segment each (the fiber lattice,
    where that was measured to pay). A tendon robot keeps plain chord steps:
    with friction its Jacobian is not the symmetric Hessian the pairs
    approximate, and without, its searches compare pose errors of a few 1e-7 L,
    at the tolerance of the equilibria inside them, which the corrections move.
    """

    def __init__(self, model: Model, solver: str | LinearSettings | LinearSolver = "auto", tol: float = 1e-10,
                 max_iter: int = 100, force_scale: float | None = None, eta_max: float = 0.01,
                 reuse: bool = False):
        self.model = model
        self.linear = solver if isinstance(solver, LinearSolver) else make_linear_solver(solver, model)
        self.tol = tol
        self.max_iter = max_iter
        self.eta_max = eta_max
        #: a step with a reused Hessian must shrink the residual at least this much
        self.chord_ratio = 0.5
        #: ... and a secant-corrected one this much: the corrections speed the next
        #: steps up, where plain chord steps keep their rate. Replaying the same 1846
        #: evaluations of t_shape at level 5 (as benchmarks/secant_replay.py does): 0.5 /
        #: 0.7 / 0.9 take 35.6 / 33.6 / 33.0 s (plain chord steps at 0.5: 38.3 s); at
        #: levels 2 and 3 0.5 and 0.7 are alike
        self.secant_chord_ratio = 0.7
        self.reuse = reuse
        #: secant pairs that correct the chord steps (0: plain chord steps)
        self.secant_pairs = PAIRS
        mat = model.material
        self.force_scale = force_scale or mat.youngs_modulus * mat.thickness * model.mesh.size
        #: a residual within this factor of the tolerance that stalls is converged (:func:`_stalled`)
        self.roundoff_factor = ROUNDOFF_FACTOR
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
        secant = self.reuse and self.secant_pairs > 0 and m.single
        memory = SecantMemory(np.repeat(~m.fixed, 2), self.secant_pairs) if secant else None
        history: list[float] = []
        for it in range(self.max_iter + 1):
            if m.capstan is not None and m.update_friction() > 0.0:
                E, _ = m.energy_and_min_det()
            previous, gnorm = gnorm, float(np.sqrt(m.gradient_norm2()))
            history.append(gnorm)
            if memory is not None:
                memory.observe(m.positions(), m.last_gradient)
            if gnorm <= tol * F or _stalled(history, self.roundoff_factor * tol * F):
                break
            if it == self.max_iter:
                raise ConvergenceError(
                    f"equilibrium did not converge: relative force residual {gnorm / F:.2e} "
                    f"after {it} Newton iterations (tolerance {tol:.1e})")
            # a reused Hessian (chord step) must keep contracting fast, else refresh it
            ratio = self.chord_ratio if memory is None else self.secant_chord_ratio
            fresh = fresh or not self.reuse or gnorm > ratio * previous
            slope = None if fresh or memory is None or not memory.pairs else self._secant_direction(memory)
            if slope is None:
                factorizations = self.linear.stats.solves
                slope, was_projected = self._direction(min(self.eta_max, np.sqrt(gnorm / F)), fresh)
                projected += was_projected
                if memory is not None and self.linear.stats.solves != factorizations:
                    memory.clear()  # a new H0
            E = self._line_search(E, slope, gnorm)
            fresh = False
        return Equilibrium(x=m.positions(), tau=m.tensions(), energy=float(E),
                           residual=gnorm / F, newton_iterations=it,
                           linear_iterations=self.linear.stats.iterations - lin0,
                           projected_steps=projected, time_s=time.perf_counter() - t0)

    def _direction(self, eta: float, fresh: bool) -> tuple[float, bool]:
        """The Newton direction: a chord step unless ``fresh``, a fresh exact Hessian
        where the chord is no descent direction, the PSD-projected one where neither
        is, steepest descent as the last resort. Returns (g . dx, whether projected)."""
        slope, negcurv, _ = self.linear.newton_direction(eta, project=False, fresh=fresh)
        if (negcurv or not slope < 0.0) and not fresh:
            slope, negcurv, _ = self.linear.newton_direction(eta, project=False, fresh=True)
        if not (negcurv or not slope < 0.0):
            return slope, False
        slope, negcurv, _ = self.linear.newton_direction(eta, project=True)
        if negcurv or not slope < 0.0:
            slope = self._steepest_descent()
        return slope, True

    def _secant_direction(self, memory: SecantMemory) -> float | None:
        """A chord step corrected by the secant pairs (:mod:`.secant`) into the model's
        Newton direction; its g . dx, or None where the backend has no exact ``H0`` at
        hand or the step is no descent direction."""
        m = self.model
        d = memory.inverse_product(-m.last_gradient, self.linear.chord_solve)
        if d is None:
            return None
        slope = direction_from(m, d)
        return slope if slope < 0.0 else None

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


def _stalled(history: list[float], floor: float) -> bool:
    """Whether the last :data:`STALL_STEPS` Newton steps, all at residuals of at most
    ``floor`` (N), did not halve the residual: round-off, not the solver, sets it
    there (``history``: the residual before each step and now)."""
    window = history[-STALL_STEPS - 1:]
    return len(window) == STALL_STEPS + 1 and max(window) <= floor and window[-1] > 0.5 * window[0]
