"""One equilibrium of the idealized robot for given fiber contractions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .model import Model
from .problem import Problem, build_problem
from .scene import Scene, load_scene
from .solvers import Equilibrium, NewtonSolver


@dataclass
class Simulation:
    """A solved equilibrium with what produced it."""

    problem: Problem
    model: Model
    solver: NewtonSolver
    ac: np.ndarray
    equilibrium: Equilibrium

    def pose_errors(self) -> np.ndarray:
        """Distance (t,) from each target point to its goal, m."""
        pos = self.problem.target_positions(self.equilibrium.x)
        return np.linalg.norm(pos - self.problem.target_goal, axis=1)


def contraction_ratios(problem: Problem, ratios) -> np.ndarray:
    """Validate per-fiber contraction ratios r = ac/a0 (a scalar or (f,)) against
    the scene's bounds [-pmax, cmax]; return them as an (f,) array."""
    f = problem.fibers.n_fibers
    r = np.asarray(ratios, dtype=float)
    if r.ndim == 0:
        r = np.full(f, float(r))
    if r.shape != (f,):
        raise InputError(f"contractions have shape {r.shape}; the scene has {f} fibers "
                         f"at resolution {problem.level}")
    if not np.all(np.isfinite(r)):
        raise InputError("contractions must be finite numbers")
    fs = problem.scene.fibers
    if r.min() < -fs.max_payout or r.max() > fs.max_contraction:
        raise InputError(f"contraction ratios must lie in [-{fs.max_payout:g}, "
                         f"{fs.max_contraction:g}] (got {r.min():g} .. {r.max():g})")
    return r


def simulate(scene: Scene | str, level: int = 1, ratios=0.0, solver: str = "auto",
             tol: float = 1e-10) -> Simulation:
    """Solve the equilibrium of ``scene`` at ``level`` with every fiber contracted by
    ``ratios`` (scalar or (f,)) of its rest length."""
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    problem = build_problem(scene, level)
    r = contraction_ratios(problem, ratios)
    model = Model.from_problem(problem)
    newton = NewtonSolver(model, solver, tol=tol)
    ac = r * problem.fibers.a0
    eq = newton.solve(ac=ac)
    return Simulation(problem, model, newton, ac, eq)
