"""The linear-backend protocol of the equilibrium and adjoint solves, and the
backends' names.

Newton and the adjoint need, from a backend, solves with the model's Hessian
``H`` at its current state on the free DOFs. :class:`LinearSolver` is what
every backend implements completely (:mod:`.cg`, :mod:`.direct`); the model
is the operator, its state is passed in. The backends by name (:data:`SOLVERS`):

* ``cg`` - PCG with the Hessian products in Taichi, preconditioned by a
  reused factorization of the Hessian at a nearby state;
* ``cg-amg`` - the same PCG preconditioned by a reused algebraic-multigrid
  V-cycle of that Hessian (no factorization; cost linear in the DOFs);
* ``cg-gmg`` - the same PCG preconditioned by a reused geometric-multigrid
  V-cycle over the body's coarser meshes (no factorization but the coarsest);
* ``cg-jacobi`` - block-Jacobi PCG entirely in Taichi;
* ``direct`` - the Hessian assembled into a scipy sparse matrix and
  factorized (LDL^T; where it is not positive definite PARDISO's indefinite
  LDL^T, or SuperLU);
* ``auto`` - ``direct`` up to :data:`AUTO_DIRECT_MAX_DOFS` free DOFs, ``cg`` above.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from ..errors import InputError

#: every backend name a user may give (``--solver``, sweep files)
SOLVERS = ("auto", "cg", "cg-amg", "cg-gmg", "cg-jacobi", "direct")

#: ``auto`` takes the direct backend up to this many free DOFs and the
#: factorization-preconditioned CG above. Measured on the 2-core CPU machine
#: (t_shape), inside the optimizer: direct is 5-30 % faster at levels 1-4, 1.8x at
#: level 5 (qdldl), and with PARDISO 2.6x / 2.6x / 3.2x faster at levels 6 / 7 / 8
#: (about 21 / 41 / 82 thousand DOFs; 15 / 5 / 3 iterations per stage: 32 s against
#: 85, 48 against 124, 99 against 322), with qdldl 1.4x / 1.5x at levels 6 / 7
#: (84 s against 118, 213 against 319), at about the same peak memory (CG's
#: preconditioner is the same factorization: 566 MB against 483 at level 6, equal
#: at 7 and 8). ``python benchmarks/auto_solver.py``; above level 8 nothing was
#: measured.
AUTO_DIRECT_MAX_DOFS = 100000


@dataclass(frozen=True)
class LinearSettings:
    """A linear backend as a job asks for it: its ``name`` (:data:`SOLVERS`) and the
    threads its sparse factorizations run on, ``factor_threads`` (None: the
    process's, :func:`~tendon_taichi.physics.runtime.factor_threads`; either way one
    below :data:`~tendon_taichi.solve.pardiso.PARALLEL_MIN` DOFs). Given wherever a
    backend's name is (the ``solver`` arguments), it reaches every backend the job
    makes, in the worker processes it hands pieces to too (``design``: one thread
    where worker processes share the cores)."""

    name: str = "auto"
    factor_threads: int | None = None


def resolve_solver(name: str, dofs: int) -> str:
    """The backend that ``name`` stands for at this size (``auto`` picks by DOFs)."""
    if name == "auto":
        return "direct" if dofs <= AUTO_DIRECT_MAX_DOFS else "cg"
    if name not in SOLVERS:
        raise InputError(f"unknown solver '{name}' (choose from {', '.join(SOLVERS)})")
    return name


@dataclass
class LinearStats:
    """Counts: ``solves`` (factorizations or CG solves), ``iterations`` (CG),
    ``reused`` (direct steps with an earlier factorization)."""

    solves: int = 0
    iterations: int = 0
    reused: int = 0


class LinearSolver(ABC):
    """What Newton and the adjoint need from a linear backend (on ``self.model``)."""

    name: str
    stats: LinearStats
    #: whether :meth:`solve` after :meth:`reset` depends on the model's state alone (a
    #: fresh factorization), not on the solves before it (a reused preconditioner)
    fresh_solves: bool = False

    @abstractmethod
    def newton_direction(self, eta: float, project: bool, fresh: bool = True) -> tuple[float, bool, int]:
        """Solve H dx = -g (H exact or projected, at the model's x; g its last
        gradient) to the relative residual ``eta``, into the model's Newton
        direction; return (g . dx, met negative curvature, iterations).
        ``fresh=False`` allows a backend to reuse the Hessian of a nearby state."""

    @abstractmethod
    def solve(self, rhs: np.ndarray, tol: float, warm: bool = False, prepare: bool = True) -> np.ndarray:
        """y (n, 2) with H y = rhs on the free DOFs (exact H at x, zero on fixed DOFs),
        to the relative residual ``tol``; ``warm`` starts from the last solution
        (iterative backends); ``prepare=False`` reuses the Hessian as last prepared."""

    @abstractmethod
    def resolve(self, rhs: np.ndarray, tol: float) -> np.ndarray:
        """y (n, 2) with H y = rhs for another right-hand side, H the Hessian of the
        last :meth:`solve` (no new preparation or factorization)."""

    @abstractmethod
    def approx_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """H0^-1 rhs (n, 2) with the factorization at hand (of a nearby state's
        Hessian), or None when there is none: for first-order predictions."""

    def chord_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """H0^-1 rhs (n, 2) with the factorization that Newton's chord steps reuse (of
        the exact Hessian at a nearby state), or None when there is none at hand or
        the backend takes no chord steps (the default)."""
        return None

    @abstractmethod
    def solve_many(self, rhs: Iterable[np.ndarray], tol: float) -> Iterator[np.ndarray]:
        """y (n, 2) with H y = b for each b (n, 2) of ``rhs``, H the Hessian at the
        model's current state, prepared once."""

    @abstractmethod
    def reset(self) -> None:
        """Forget reused state (a stage start must not depend on earlier stages)."""

    def checkpoint(self):
        """What the next solves may reuse (a backend with :attr:`fresh_solves`: the
        factorization at hand), to :meth:`resume` from later; None: nothing."""
        return None

    def resume(self, state) -> None:
        """Back to a :meth:`checkpoint`, as if no solve had been made since."""
        self.reset()

    def cables_moved(self) -> None:
        """The model's cables moved (:meth:`~tendon_taichi.physics.model.Model.move_cables`):
        forget what depended on them."""
        self.reset()
