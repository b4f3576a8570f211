"""Secant corrections of Newton's chord steps.

A chord step solves with ``H0``, the factorized exact Hessian of a nearby state,
instead of the Hessian at ``x``: it converges linearly, at the rate of
``I - H0^-1 H``. Every step taken gives a secant pair ``s = x_new - x``,
``y = g_new - g`` (``y ~ H s``). L-BFGS's two-loop recursion (Nocedal & Wright,
*Numerical Optimization*, Algorithm 7.4) with ``H0^-1`` as its initial inverse
folds the last few pairs into the step: ``d = -B^-1 g`` with ``B^-1`` the BFGS
update of ``H0^-1`` by those pairs, which satisfies the secant equation
``B^-1 y = s`` of the newest pair. What the Hessian changed since ``H0`` was made
(fibers turned taut or slack by a design move, above all) is then learned from
the steps instead of only damped by them.

The pairs belong to one ``H0``: a new factorization clears them (:meth:`clear`).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

#: secant pairs a Newton solve keeps (the most recent ones)
PAIRS = 5


class SecantMemory:
    """The last :data:`PAIRS` secant pairs of one Newton solve, on the free DOFs
    (``free`` (2n,) bool; the other entries of the vectors are ignored)."""

    def __init__(self, free: np.ndarray, size: int = PAIRS):
        self.free = np.asarray(free, dtype=bool)
        self.size = size
        #: (s, y, 1 / s.y) per pair, oldest first; each s, y (2n,) zero off the free DOFs
        self.pairs: list[tuple[np.ndarray, np.ndarray, float]] = []
        self._last: tuple[np.ndarray, np.ndarray] | None = None

    def observe(self, x: np.ndarray, g: np.ndarray) -> None:
        """A new iterate: positions ``x`` and gradient ``g`` (2n,) (or (n, 2)). The pair from
        the last one is kept where it has positive curvature (``s.y > 0``), as a
        stable equilibrium's neighbourhood gives."""
        x = np.where(self.free, np.ravel(x), 0.0)
        g = np.where(self.free, np.ravel(g), 0.0)
        if self._last is not None:
            s, y = x - self._last[0], g - self._last[1]
            sy = float(s @ y)
            if sy > 0.0:
                self.pairs.append((s, y, 1.0 / sy))
                del self.pairs[:-self.size]
        self._last = (x, g)

    def clear(self) -> None:
        """Forget the pairs (``H0`` was replaced); the last iterate stays, the base of
        the next pair."""
        self.pairs.clear()

    def inverse_product(self, q: np.ndarray, h0_solve: Callable[[np.ndarray], np.ndarray | None]) -> np.ndarray | None:
        """``B^-1 q`` (2n,) by the two-loop recursion, ``h0_solve(v)`` giving ``H0^-1 v``
        (2n,) (None: no ``H0`` at hand, and so None here)."""
        q = np.where(self.free, np.ravel(q), 0.0)
        alphas = []
        for s, y, rho in reversed(self.pairs):
            a = rho * float(s @ q)
            q -= a * y
            alphas.append(a)
        r = h0_solve(q)
        if r is None:
            return None
        r = np.where(self.free, np.ravel(r), 0.0)
        for (s, y, rho), a in zip(self.pairs, reversed(alphas)):
            r += (a - rho * float(y @ r)) * s
        return r
