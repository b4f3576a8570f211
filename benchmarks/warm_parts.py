"""Where the time of ``bench``'s warm equilibrium goes, level by level.

Usage: python benchmarks/warm_parts.py [SCENE] [--levels 2 3 4 5 6] [--repeat N] [--qdldl]

Per level, the warm equilibrium ``tendon-taichi bench`` times as "eq warm" on the
direct backend (plain exact Newton to the relative force tolerance 1e-10, from
the equilibrium of a design whose contraction ratios differ by +-0.5 %), N times
(default 5), each part's time summed over each solve; the run of the median
total is printed, in ms, each part timed by the package's probe of its name
(``tendon_taichi/probes.py``):

* ``factor``: the sparse Cholesky's numerical factorizations (PARDISO's, or
  qdldl's without MKL), with their count, and ``entries``, the factor's
  entries (its fill, as the library counts them);
* ``solves``: its triangular solves;
* ``assembly``: the Hessian's block entries summed into the sparse matrix
  (``Model.hessian_sums``);
* ``prepare``: the element tangents and cable terms it sums
  (``Model.prepare_hessian``);
* ``check``: the product with the assembled matrix that checks each solve;
* ``rest``: all else - gradients, the line search, Python.

Then each column's exponent against the DOFs, fitted as ``bench`` fits them
(from the second level on), that of one factorization (``per factorization``),
and ``linear rest``: the exponent the whole would have if every part but the
factorizations and their solves cost the same per DOF as at the first fitted
level - the growth the factorization alone sets. ``--qdldl`` factorizes with
qdldl where MKL PARDISO loads too (the direct backend told, through the probe
``pardiso``, that it did not).
docs/method.md ("Where a warm equilibrium's time goes") quotes it for t_shape.
"""

import argparse
import sys
import time
from contextlib import nullcontext

import numpy as np

from tendon_taichi.apps.bench import design_pair
from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import load_scene
from tendon_taichi.optimizer.soft_ik import SoftIK
from tendon_taichi.probes import around, timers
from tendon_taichi.solve.newton import NewtonSolver

#: the parts, each the probe (tendon_taichi/probes.py) of its name
PARTS = ("factor", "solves", "assembly", "prepare", "check")


def measure(scene, level: int, repeat: int) -> dict:
    """One level's warm equilibria, split into parts (module docstring)."""
    problem = build_problem(scene, level)
    a0, nodes = problem.fibers.a0, problem.mesh.nodes
    r0, r1 = design_pair(problem)
    ik = SoftIK(problem, scene.optimize, "direct")
    ik.configure(None)
    m, lin = ik.model, ik.linear
    newton = NewtonSolver(m, lin)  # plain exact Newton, as bench times it
    newton.solve(ac=r0 * a0, x0=nodes)  # compiles what the backend needs
    runs = []
    for _ in range(repeat):
        lin.reset()
        first = newton.solve(ac=r0 * a0, x0=nodes)
        with timers(*PARTS) as clock:
            t = time.perf_counter()
            warm = newton.solve(ac=r1 * a0)
            total = time.perf_counter() - t
        runs.append({"total": total, **{p: clock[p].seconds for p in PARTS},
                     "rest": total - sum(clock[p].seconds for p in PARTS), "factorizations": clock["factor"].calls})
        m.set_positions(first.x)
    out = sorted(runs, key=lambda r: r["total"])[(len(runs) - 1) // 2]  # the median run's parts, which add up
    return {"level": level, "dofs": 2 * int(np.sum(~m.fixed)), "steps": warm.newton_iterations,
            "entries": lin.ldl.entries if hasattr(lin.ldl, "entries") else 0, **out}


def slope(dofs: list[int], times: list[float]) -> float:
    """Least-squares slope of log(time) against log(DOFs)."""
    return float(np.polyfit(np.log(dofs), np.log(times), 1)[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--qdldl", action="store_true", help="factorize with qdldl where PARDISO loads too")
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    cols = ("total",) + PARTS + ("rest",)
    print(f"{'level':>5} {'DOFs':>6} {'steps':>5} {'factors':>7} {'entries':>9} "
          + " ".join(f"{c:>8}" for c in cols) + "   (ms)")
    rows = []
    for level in args.levels:
        with around("pardiso", lambda call: False) if args.qdldl else nullcontext():
            r = measure(scene, level, args.repeat)
        rows.append(r)
        print(f"{level:>5} {r['dofs']:>6} {r['steps']:>5} {r['factorizations']:>7.0f} {r['entries']:>9} "
              + " ".join(f"{1e3 * r[c]:>8.2f}" for c in cols), flush=True)
    if len(rows) >= 2:
        fit = rows[1:] if len(rows) >= 3 else rows
        dofs = [r["dofs"] for r in fit]
        parts = [c for c in cols if all(r[c] > 0 for r in fit)]
        print("exponents: " + ", ".join(f"{c} {slope(dofs, [r[c] for r in fit]):.2f}" for c in parts)
              + (f", entries {slope(dofs, [r['entries'] for r in fit]):.2f}" if all(r["entries"] for r in fit) else ""))
        base = fit[0]
        per_dof = (base["total"] - base["factor"] - base["solves"]) / base["dofs"]
        bound = [r["factor"] + r["solves"] + per_dof * r["dofs"] for r in fit]
        one = slope(dofs, [r["factor"] / max(r["factorizations"], 1) for r in fit])
        print(f"per factorization: {one:.2f}, linear rest: {slope(dofs, bound):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
