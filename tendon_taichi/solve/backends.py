"""The linear backends by name (:data:`~tendon_taichi.solve.linear.SOLVERS`)."""

from __future__ import annotations

from ..errors import InputError
from ..physics.model import Model
from .cg import CGSolver
from .direct import DirectSolver
from .linear import SOLVERS, LinearSolver, resolve_solver


def make_linear_solver(name: str, model: Model) -> LinearSolver:
    """A linear backend by name: ``cg`` (factorization-preconditioned), ``cg-amg``
    (algebraic-multigrid-preconditioned), ``cg-gmg`` (geometric-multigrid-
    preconditioned), ``cg-jacobi`` (block Jacobi, all in Taichi), ``direct`` or
    ``auto``."""
    name = resolve_solver(name, model.dofs)
    if name == "cg":
        return CGSolver(model)
    if name == "cg-amg":
        return CGSolver(model, preconditioner="multigrid")
    if name == "cg-gmg":
        return CGSolver(model, preconditioner="geometric")
    if name == "cg-jacobi":
        return CGSolver(model, preconditioner="jacobi")
    if name == "direct":
        return DirectSolver(model)
    raise InputError(f"unknown solver '{name}' (choose from {', '.join(SOLVERS)})")
