"""The reused preconditioners of the matrix-free CG backend (:mod:`.cg`): an
operator ``M^-1`` made from the Hessian at a reference state, assembled by the
direct backend, and kept while the solves it preconditions stay short.

A subclass says how to make the operator (:meth:`ReusedPreconditioner.build`)
and how to apply it (:meth:`ReusedPreconditioner.apply`); the bookkeeping - when
it is stale, how often it was refreshed, whether from the projected Hessian - is
here. :class:`~tendon_taichi.solve.cg.FactorPreconditioner` factorizes the
Hessian, :class:`~tendon_taichi.solve.multigrid.MultigridPreconditioner` builds
an algebraic-multigrid hierarchy of it."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from ..physics.model import Model
from .direct import DirectSolver


class ReusedPreconditioner(ABC):
    """``M^-1`` from the Hessian at a reference state, on the free DOFs.

    A solve that takes more than ``refresh_iterations`` marks it stale (the CG
    backend calls :meth:`reset`), and the next solve refreshes it at the state
    of the moment. ``ordered``: assemble in the direct backend's fill-reducing
    order (for a factorization) or in the free DOFs' own numbering;
    ``factor_threads``: the threads of its factorizations (:class:`DirectSolver`)."""

    def __init__(self, model: Model, refresh_iterations: int, ordered: bool = True,
                 factor_threads: int | None = None):
        self.direct = DirectSolver(model, ordered=ordered, factor_threads=factor_threads)
        self.refresh_iterations = refresh_iterations
        self.operator = None
        self.projected = False
        self.refreshes = 0

    @abstractmethod
    def build(self, project: bool):
        """The operator from the (exact or PSD-projected) Hessian at the model's
        current state; may raise :class:`numpy.linalg.LinAlgError`."""

    @abstractmethod
    def apply(self, operator, r: np.ndarray) -> np.ndarray:
        """``M^-1 r`` for a residual ``r`` (nf,) on the free DOFs."""

    @property
    def stale(self) -> bool:
        return self.operator is None

    def refresh(self, project: bool = False) -> None:
        """Make the operator at the model's current state (this leaves the model's
        element tangents so: prepare them again afterwards); an exactly singular
        exact Hessian falls back to the projected one, which is not."""
        try:
            self.operator = self.build(project)
        except np.linalg.LinAlgError:
            if project:
                raise
            self.operator = self.build(True)
            project = True
        self.projected = project
        self.refreshes += 1

    def __call__(self, r: np.ndarray) -> np.ndarray:
        """``z = M^-1 r`` for a residual over all DOFs (2n,), zero on clamped ones."""
        z = np.zeros_like(r)
        z[self.direct.free] = self.apply(self.operator, r[self.direct.free])
        return z

    def reset(self) -> None:
        self.operator = None
