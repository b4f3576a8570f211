"""The linear backends by name (:data:`~tendon_taichi.solve.linear.SOLVERS`)."""

from __future__ import annotations

from ..errors import InputError
from ..physics.model import Model
from .cg import CGSolver
from .direct import DirectSolver
from .linear import SOLVERS, LinearSettings, LinearSolver, resolve_solver


def make_linear_solver(name: str | LinearSettings, model: Model) -> LinearSolver:
    """A linear backend by name: ``cg`` (factorization-preconditioned), ``cg-amg``
    (algebraic-multigrid-preconditioned), ``cg-gmg`` (geometric-multigrid-
    preconditioned), ``cg-jacobi`` (block Jacobi, all in Taichi), ``direct`` or
    ``auto``; or by :class:`~.linear.LinearSettings`, whose factorizations run on
    its ``factor_threads``."""
    threads = name.factor_threads if isinstance(name, LinearSettings) else None
    name = resolve_solver(name.name if isinstance(name, LinearSettings) else name, model.dofs)
    if name == "cg":
        return CGSolver(model, factor_threads=threads)
    if name == "cg-amg":
        return CGSolver(model, preconditioner="multigrid")
    if name == "cg-gmg":
        return CGSolver(model, preconditioner="geometric")
    if name == "cg-jacobi":
        return CGSolver(model, preconditioner="jacobi")
    if name == "direct":
        return DirectSolver(model, factor_threads=threads)
    raise InputError(f"unknown solver '{name}' (choose from {', '.join(SOLVERS)})")
