"""Solving for equilibria and with the Hessian: Newton (:mod:`.newton`) on the
linear backends of the protocol :mod:`.linear` - matrix-free CG (:mod:`.cg`,
its multigrid preconditioner in :mod:`.multigrid`) and the sparse direct
factorization (:mod:`.direct`), by name in :mod:`.backends`."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".linear": ("LinearSolver", "LinearStats", "LinearSettings", "SOLVERS", "AUTO_DIRECT_MAX_DOFS", "resolve_solver"),
    ".backends": ("make_linear_solver",),
    ".cg": ("CGSolver", "CGStatus", "FactorPreconditioner"),
    ".preconditioner": ("ReusedPreconditioner",),
    ".multigrid": ("MultigridPreconditioner", "rigid_modes"),
    ".direct": ("DirectSolver", "Factorization"),
    ".cholesky": ("LDL", "cholesky_library"),
    ".newton": ("NewtonSolver", "Equilibrium"),
})
