"""One equilibrium of the idealized robot for given fiber contractions (the
engine behind the ``simulate`` command)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..body.problem import Problem, build_problem
from ..body.scene import Scene, load_scene
from ..errors import InputError
from ..physics import runtime
from ..physics.elements import check_elements
from ..physics.model import Model
from ..solve.newton import Equilibrium, NewtonSolver


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

    def summary(self) -> dict:
        """The figures of the ``simulate`` command's JSON summary (SI units)."""
        p, eq, scene = self.problem, self.equilibrium, self.problem.scene
        L = p.size
        pos = p.target_positions(eq.x)
        err = self.pose_errors()
        disp = np.linalg.norm(eq.x - p.mesh.nodes, axis=1)
        return {
            "scene": scene.name, "resolution": p.level, **p.counts(), "body_size": L,
            "solver": self.solver.linear.name, "arch": runtime.info()["arch"], "parallel": self.model.parallel,
            "newton_iterations": eq.newton_iterations, "linear_iterations": eq.linear_iterations,
            "projected_steps": eq.projected_steps, "residual": eq.residual, "energy": eq.energy,
            "max_displacement": float(disp.max()), "tau_max": float(eq.tau.max()),
            "active_fibers": int((eq.tau > 0).sum()),
            "targets": [{"point": list(t.point), "goal": list(t.goal), "position": pos[i].tolist(),
                         "error": float(err[i]), "pose": p.pose_names[p.target_pose[i]]}
                        for i, t in enumerate(scene.targets)],
            "pose_error": float(np.sqrt((err ** 2).sum())), "pose_error_rel": float(np.sqrt((err ** 2).sum()) / L),
            "solve_s": eq.time_s,
        }


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
             tol: float = 1e-10, problem: Problem | None = None) -> Simulation:
    """Solve the equilibrium of ``scene`` at ``level`` (or of the ``problem`` built
    from it already) with every fiber contracted by ``ratios`` (scalar or (f,)) of
    its rest length."""
    if problem is None:
        scene = scene if isinstance(scene, Scene) else load_scene(scene)
        check_elements(scene.body.dim, scene.origin)
        problem = build_problem(scene, level)
    r = contraction_ratios(problem, ratios)
    model = Model.from_problem(problem)
    newton = NewtonSolver(model, solver, tol=tol)
    ac = r * problem.fibers.a0
    eq = newton.solve(ac=ac)
    return Simulation(problem, model, newton, ac, eq)
