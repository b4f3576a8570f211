"""How many Newton steps a warm equilibrium takes, level by level, and why.

Usage: python benchmarks/warm_newton.py [SCENE] [--levels 1 2 3 4 5 6] [--repeat N]

Per level, with the two designs ``tendon-taichi bench`` times (contraction ratios
2-8 % and a nearby one, +-0.5 %), from the equilibrium of the first, the warm one
of the second three ways (median times of N repeats, default 3):

* ``bench``: plain exact Newton to the relative force tolerance 1e-10, as
  ``bench`` times its "eq warm": the relative force residual |g_free| / F before
  each step and at the end, the steps, the time;
* ``1e-8``: the same to the tolerance of the optimizer's equilibria
  (``EVAL_TOL``): steps, time;
* ``optimizer``: as the optimizer solves it - to that tolerance, by chord steps
  (secant-corrected) on the factorization of the exact Hessian at the first
  equilibrium, which the adjoint made there (before the clock starts): steps,
  factorizations, time.

Beside them, the fibers in the cubic zone of the unilateral energy
(0 < e <= eps, where its curvature changes fastest) at the second equilibrium,
and the fibers whose zone (slack, cubic, quadratic) differs between the two.
Last, each time's exponent against the DOFs over the levels from the second on,
fitted as ``bench`` fits them. docs/method.md ("Newton") quotes its figures for
t_shape.
"""

import argparse
import statistics
import sys
import time

import numpy as np

from tendon_taichi.apps.bench import design_pair
from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import load_scene
from tendon_taichi.optimizer.soft_ik import EVAL_TOL, SoftIK
from tendon_taichi.solve.newton import NewtonSolver


class TracedNewton(NewtonSolver):
    """Newton that keeps the relative force residual before each step (``trace``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.trace: list[float] = []

    def _line_search(self, E: float, slope: float, gnorm: float) -> float:
        self.trace.append(gnorm / self.force_scale)
        return super()._line_search(E, slope, gnorm)


def zones(strain: np.ndarray, eps: float) -> np.ndarray:
    """Per fiber, the zone of the unilateral energy: 0 slack, 1 cubic, 2 quadratic."""
    return np.where(strain <= 0.0, 0, np.where(strain <= eps, 1, 2))


def measure(scene, level: int, repeat: int) -> dict:
    """The warm equilibria of one level (module docstring)."""
    problem = build_problem(scene, level)
    a0, nodes, eps = problem.fibers.a0, problem.mesh.nodes, scene.fibers.eps
    r0, r1 = design_pair(problem)
    ik = SoftIK(problem, scene.optimize, "direct")
    ik.configure(None)
    m, lin = ik.model, ik.linear
    plain, chord = TracedNewton(m, lin), NewtonSolver(m, lin, reuse=True)
    plain.solve(ac=r0 * a0, x0=nodes)  # compiles what the backend needs
    times = {"bench": [], "loose": [], "optimizer": []}

    def timed(key, solver, tol):
        t = time.perf_counter()
        eq = solver.solve(ac=r1 * a0, tol=tol)
        times[key].append(time.perf_counter() - t)
        return eq

    for _ in range(repeat):
        first = plain.solve(ac=r0 * a0, x0=nodes)
        before = zones(m.cable_state()["e"], eps)
        plain.trace = []
        warm = timed("bench", plain, None)
        residuals = plain.trace + [warm.residual]
        after = zones(m.cable_state()["e"], eps)
        m.set_positions(first.x)
        loose = timed("loose", plain, EVAL_TOL)
        m.set_positions(first.x)
        m.set_contraction(r0 * a0)
        lin.solve(np.ones((m.n, 2)))  # the adjoint's factorization at the first equilibrium
        made = lin.stats.solves
        again = timed("optimizer", chord, EVAL_TOL)
        for eq in (loose, again):
            if np.abs(eq.x - warm.x).max() > 1e-6 * problem.size:
                raise SystemExit(f"level {level}: the warm solves reached different equilibria")
    return {"level": level, "dofs": 2 * int(np.sum(~m.fixed)), "fibers": len(after),
            "cubic": int(np.sum(after == 1)), "switched": int(np.sum(after != before)),
            "residuals": residuals, "steps": warm.newton_iterations,
            "loose_steps": loose.newton_iterations, "chord_steps": again.newton_iterations,
            "factorizations": lin.stats.solves - made,
            **{f"{k}_s": statistics.median(v) for k, v in times.items()}}


def slope(rows: list[dict], key: str) -> float:
    """Least-squares slope of log(time) against log(DOFs), from the second level on
    where there are three or more."""
    fit = rows[1:] if len(rows) >= 3 else rows
    return float(np.polyfit(np.log([r["dofs"] for r in fit]), np.log([r[key] for r in fit]), 1)[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    rows = []
    print(f"{'level':>5} {'DOFs':>6} {'fibers':>6} {'cubic':>5} {'switched':>8} {'bench':>5} {'ms':>6} "
          f"{'1e-8':>4} {'ms':>6} {'optimizer':>9} {'factor':>6} {'ms':>6}  bench's residuals (each step, end)")
    for level in args.levels:
        r = measure(scene, level, args.repeat)
        rows.append(r)
        print(f"{level:>5} {r['dofs']:>6} {r['fibers']:>6} {r['cubic']:>5} {r['switched']:>8} {r['steps']:>5} "
              f"{1e3 * r['bench_s']:>6.1f} {r['loose_steps']:>4} {1e3 * r['loose_s']:>6.1f} "
              f"{r['chord_steps']:>9} {r['factorizations']:>6} {1e3 * r['optimizer_s']:>6.1f}  "
              + " ".join(f"{v:.1e}" for v in r["residuals"]), flush=True)
    if len(rows) >= 2:
        names = {"bench": "bench", "loose": "1e-8", "optimizer": "optimizer"}  # as the columns are headed
        print("exponents: " + ", ".join(f"{name} {slope(rows, k + '_s'):.2f}" for k, name in names.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
