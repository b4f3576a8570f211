"""The algebraic-multigrid preconditioner of the matrix-free CG backend
(``cg-amg``): one V-cycle of a smoothed-aggregation hierarchy (pyamg) of the
Hessian at a reference state, in place of a factorization of it.

Building the hierarchy and applying a V-cycle both cost time linear in the DOFs
(no fill), which a factorization does not promise (in 3D its fill grows much
faster than the DOFs). The hierarchy is built from the assembled sparse part of
the Hessian - elements and cable segments - in the free DOFs' own numbering;
the rigid motions of the body at its current positions are the near-null space
it is told about. A taut tendon's axial term ``kc g g^T`` (a dense rank-one
block, :mod:`.direct`) is left to CG: a rank-r change of the operator costs CG
at most r extra iterations, so the preconditioner need not see it.

Like the factorization it is reused across nearby states: a solve that takes
more than ``refresh_iterations`` marks it stale and the next solve rebuilds it
at the state of the moment."""

from __future__ import annotations

import numpy as np

from ..physics.model import Model
from .direct import DirectSolver


def rigid_modes(x: np.ndarray) -> np.ndarray:
    """The rigid motions of points ``x`` (k, 2), as (2k, 3) columns in the
    interleaved numbering (x0, y0, x1, y1, ...): two translations and the
    rotation about the origin, (-y, x)."""
    B = np.zeros((2 * len(x), 3))
    B[0::2, 0] = 1.0
    B[1::2, 1] = 1.0
    B[0::2, 2] = -x[:, 1]
    B[1::2, 2] = x[:, 0]
    return B


class MultigridPreconditioner:
    """M^-1 = one V-cycle (symmetric Gauss-Seidel smoothing, a direct solve on
    the coarsest level) of a smoothed-aggregation AMG hierarchy of the Hessian's
    sparse part at a reference state; the interface of
    :class:`~tendon_taichi.solve.cg.FactorPreconditioner`.

    ``refresh_iterations``: a solve that takes more iterations than this marks
    the hierarchy stale. A fresh hierarchy preconditions a tight (1e-8) solve on
    t_shape to 26-60 iterations at levels 1-6, so the limit is higher than a
    factorization's."""

    def __init__(self, model: Model, refresh_iterations: int = 80):
        self.direct = DirectSolver(model, ordered=False)
        self.refresh_iterations = refresh_iterations
        self.cycle = None
        self.levels = 0
        self.projected = False
        self.refreshes = 0

    @property
    def stale(self) -> bool:
        return self.cycle is None

    def refresh(self, project: bool = False) -> None:
        """Build the hierarchy of the (exact or PSD-projected) Hessian at the model's
        current state (this leaves the model's element tangents so: prepare them
        again afterwards)."""
        import pyamg  # half a second to import: only where this backend runs

        m = self.direct.model
        A = self.direct.assemble_ordered(project=project).Hp.tocsr()
        B = rigid_modes(m.positions()[~m.fixed])
        ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="hermitian",
                                               strength=("symmetric", {"theta": 0.0}))
        self.cycle = ml.aspreconditioner(cycle="V")
        self.levels = len(ml.levels)
        self.projected = project
        self.refreshes += 1

    def __call__(self, r: np.ndarray) -> np.ndarray:
        z = np.zeros_like(r)
        z[self.direct.free] = self.cycle @ r[self.direct.free]
        return z

    def reset(self) -> None:
        self.cycle = None
