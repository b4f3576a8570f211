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
from .preconditioner import ReusedPreconditioner


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


class MultigridPreconditioner(ReusedPreconditioner):
    """M^-1 = one V-cycle (symmetric Gauss-Seidel smoothing, a direct solve on
    the coarsest level) of a smoothed-aggregation AMG hierarchy of the Hessian's
    sparse part at a reference state; the same state gives the same hierarchy,
    bit for bit (replays rely on it).

    ``refresh_iterations``: a solve that takes more iterations than this marks
    the hierarchy stale. A fresh hierarchy preconditions a tight (1e-8) solve on
    t_shape to 26-64 iterations at levels 1-6, so the limit is higher than a
    factorization's."""

    def __init__(self, model: Model, refresh_iterations: int = 80):
        super().__init__(model, refresh_iterations, ordered=False)
        self.levels = 0

    def build(self, project: bool):
        import pyamg  # half a second to import: only where this backend runs

        m = self.direct.model
        A = self.direct.assemble_ordered(project=project).Hp.tocsr()
        B = rigid_modes(m.positions()[~m.fixed])
        # "local" weighting scales the prolongation smoother by row sums; the default
        # estimates a spectral radius from a random start, which would make replays differ
        ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="hermitian",
                                               strength=("symmetric", {"theta": 0.0}),
                                               smooth=("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}))
        self.levels = len(ml.levels)
        return ml.aspreconditioner(cycle="V")

    def apply(self, operator, r: np.ndarray) -> np.ndarray:
        return operator @ r
