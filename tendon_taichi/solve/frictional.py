"""Linear solves with the Jacobian of a frictional equilibrium.

With capstan friction the equilibrium's Jacobian is ``J = H + E``: the
symmetric Hessian ``H`` of the frozen-weight energy (what the backends solve)
plus the non-symmetric term ``E`` of the weights' dependence on the positions
(:class:`~tendon_taichi.physics.capstan.FrictionJacobian`). The adjoint needs
``J^T y = b`` and the sensitivities ``J y = b``. Both are solved by GMRES on
``(I + H^-1 E) y = H^-1 b`` (or with ``E^T``): ``H^-1 E`` has the rank of the
tendons' joints and is small where friction is (it is proportional to mu), so
a few iterations, each one more solve with the factorization (or CG) that the
first one prepared, reach the tolerance.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from ..errors import ConvergenceError
from ..physics.capstan import FrictionJacobian
from .linear import LinearSolver

#: GMRES iterations before giving up (each one solve with H)
MAX_ITERATIONS = 200


def solve_jacobian(linear: LinearSolver, friction: FrictionJacobian | None, rhs: np.ndarray, tol: float,
                   transpose: bool, prepare: bool = True) -> np.ndarray:
    """y (n, 2) with ``J y = rhs`` (``transpose``: ``J^T y = rhs``) on the free DOFs,
    ``J = H + E`` at the model's current state (``friction`` None: ``J = H``, one
    plain solve, not warm started: a caller that wants that solves with ``linear``
    itself); ``tol`` relative to |rhs|.
    ``prepare=False``: H as the backend last prepared it (its factorization or
    preconditioner, :meth:`~.linear.LinearSolver.resolve`), for another
    right-hand side at the same state. Raises ConvergenceError when GMRES does
    not reach it."""
    if friction is None:
        return linear.solve(rhs, tol=tol) if prepare else linear.resolve(rhs, tol)
    n2 = np.asarray(rhs).size
    mask = np.repeat(friction.pm.free[:, 0] > 0, 2)  # the free DOFs
    apply_E = friction.transpose_product if transpose else friction.product
    inner = 0.1 * tol  # each H solve inside the outer tolerance (exact for the direct backend)

    def h_solve(v: np.ndarray) -> np.ndarray:
        return linear.resolve(v.reshape(-1, 2), inner).ravel()

    y0 = (linear.solve(rhs, tol=inner) if prepare else linear.resolve(rhs, inner)).ravel()

    def matvec(z: np.ndarray) -> np.ndarray:
        full = np.zeros(n2)
        full[mask] = z
        return z + h_solve(apply_E(full.reshape(-1, 2)).ravel())[mask]

    op = spla.LinearOperator((int(mask.sum()),) * 2, matvec=matvec, dtype=float)
    z, info = spla.gmres(op, y0[mask], rtol=tol, atol=0.0, restart=MAX_ITERATIONS, maxiter=1)
    if info != 0:
        raise ConvergenceError(f"the frictional Jacobian solve did not converge in {MAX_ITERATIONS} "
                               f"GMRES iterations (tolerance {tol:.1e})")
    out = np.zeros(n2)
    out[mask] = z
    return out.reshape(-1, 2)
