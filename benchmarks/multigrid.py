"""The geometric multigrid preconditioner (``cg-gmg``) level by level, beside the
algebraic one (``cg-amg``) and the factorization (``direct``).

Usage: python benchmarks/multigrid.py [SCENE] [--levels 2 3 4 5 6] [--repeat N]
       [--tol 1e-8 1e-10] [--sweeps forward-backward symmetric]

Per level, at the equilibrium of ``tendon-taichi bench``'s first design of the
fiber lattice: for each V-cycle (``cg-gmg`` with each ``--sweeps``: a forward
Gauss-Seidel sweep before the coarse correction and a backward one after, or
symmetric sweeps on both sides; ``cg-amg``) its levels, the time to build it at
that state, and the PCG iterations and time (the Hessian products in Taichi)
of one solve for a random right-hand side to each relative tolerance, building
a fresh one first (its time included); for ``direct``, the time to assemble,
factorize and solve. Times are the median of N repeats (default 3).
docs/method.md (the linear backends) quotes its figures for t_shape.
"""

import argparse
import statistics
import sys
import time

import numpy as np

from tendon_taichi.apps.bench import design_pair
from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import load_scene
from tendon_taichi.physics.model import Model
from tendon_taichi.solve.newton import NewtonSolver

SWEEPS = {"forward-backward": ("forward", "backward"), "symmetric": ("symmetric", "symmetric")}


def _median_ms(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def cycle_row(newton: NewtonSolver, b: np.ndarray, tols: list[float], repeat: int) -> dict:
    """A multigrid backend's build time and, per tolerance, its PCG iterations and time."""
    lin = newton.linear
    row = {"build_ms": _median_ms(lambda: lin.pre.refresh(), repeat), "levels": lin.pre.levels}
    for tol in tols:
        def solve():
            lin.pre.reset()
            lin.solve(b, tol=tol)
        row[tol] = (_median_ms(solve, repeat), lin.last.iterations)
    return row


def measure(scene, level: int, tols: list[float], sweeps: list[str], repeat: int) -> dict:
    problem = build_problem(scene, level)
    first, _ = design_pair(problem)
    b = np.random.default_rng(0).standard_normal((problem.mesh.n_nodes, 2))
    out = {"level": level, "dofs": problem.counts()["dofs"], "rows": {}}
    for name in [f"cg-gmg {s}" for s in sweeps] + ["cg-amg", "direct"]:
        backend = name.split()[0]
        newton = NewtonSolver(Model.from_problem(problem), backend)
        newton.solve(ac=first * problem.fibers.a0, x0=problem.mesh.nodes)
        if backend == "direct":
            out["rows"][name] = {"solve_ms": _median_ms(lambda: newton.linear.solve(b, tol=min(tols)), repeat)}
            continue
        if backend == "cg-gmg":
            newton.linear.pre.sweeps = SWEEPS[name.split()[1]]
        out["rows"][name] = cycle_row(newton, b, tols, repeat)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4, 5, 6])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tol", type=float, nargs="+", default=[1e-8, 1e-10])
    ap.add_argument("--sweeps", nargs="+", choices=sorted(SWEEPS), default=["forward-backward", "symmetric"])
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    head = f"{'level':>5} {'DOFs':>6} {'backend':>24} {'levels':>6} {'build ms':>8}"
    print(head + "".join(f" {f'tol {t:.0e}: it':>14} {'ms':>8}" for t in args.tol))
    for level in args.levels:
        r = measure(scene, level, args.tol, args.sweeps, args.repeat)
        for name, row in r["rows"].items():
            line = f"{r['level']:>5} {r['dofs']:>6} {name:>24}"
            if "solve_ms" in row:
                line += f" {'-':>6} {'-':>8} {'(factorize + solve)':>14} {row['solve_ms']:>8.1f}"
            else:
                line += f" {row['levels']:>6} {row['build_ms']:>8.1f}"
                line += "".join(f" {row[t][1]:>14} {row[t][0]:>8.1f}" for t in args.tol)
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
