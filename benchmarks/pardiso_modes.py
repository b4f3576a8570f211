"""PARDISO's factorization and solve in its reproducible mode (CNR, ``iparm[33]``)
and without it, on one thread and two, level by level.

Usage: python benchmarks/pardiso_modes.py [SCENE] [--levels 2 3 4 5] [--repeat N]

Per level, the Hessian of the fiber lattice at the equilibrium of ``tendon-taichi
bench``'s first design, in the direct backend's order; per mode and thread count
the median time of one factorization (numbers only, after the analysis) and of
one solve with one right-hand side, over N of each (default 100); and per mode
whether the solutions on one thread and on two are the same to the bit. Which
mode the direct backend uses at that size is marked ``*``
(:attr:`~tendon_taichi.solve.pardiso.PardisoLDL.reproducible`).
``tendon_taichi/solve/pardiso.py`` quotes its figures for t_shape. Needs the
``mkl`` extra.
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
from tendon_taichi.solve import pardiso
from tendon_taichi.solve.newton import NewtonSolver


def lattice_hessian(scene, level: int):
    """The lattice's ordered Hessian (CSC, free DOFs) at the first bench design's equilibrium."""
    problem = build_problem(scene, level)
    model = Model.from_problem(problem)
    first, _ = design_pair(problem)
    newton = NewtonSolver(model, "direct")
    newton.solve(ac=first * problem.fibers.a0, x0=problem.mesh.nodes)
    return newton.linear.assemble_ordered().Hp  # the solver's own pattern, not a second one


def median_us(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e6 * statistics.median(times)


def measure(H, reproducible: bool, threads: int, repeat: int) -> dict:
    """One mode on ``threads`` threads: factorization and solve times (us), a solution."""
    n = H.shape[0]
    ldl = pardiso.PardisoLDL(H.indptr, H.indices, n, reproducible=reproducible)
    ldl.threads = threads
    if not ldl.factor(H.data):
        raise SystemExit("pardiso_modes: the lattice's Hessian is not positive definite")
    b = np.random.default_rng(0).standard_normal(n)
    x = ldl.solve(b)
    return {"factor_us": median_us(lambda: ldl.factor(H.data), max(1, repeat // 5)),
            "solve_us": median_us(lambda: ldl.solve(b), repeat), "x": x}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4, 5])
    ap.add_argument("--repeat", type=int, default=100)
    args = ap.parse_args(argv)
    if not pardiso.available():
        print("pardiso_modes: PARDISO is not installed (the mkl extra)", file=sys.stderr)
        return 1
    scene = load_scene(args.scene)
    print(f"{'level':>5} {'DOFs':>6} {'mode':>12} {'factor ms 1/2 thr':>18} {'solve us 1/2 thr':>17} same bits")
    for level in args.levels:
        H = lattice_hessian(scene, level)
        n = H.shape[0]
        for reproducible in (True, False):
            one, two = (measure(H, reproducible, t, args.repeat) for t in (1, 2))
            used = "*" if reproducible == (n >= pardiso.PARALLEL_MIN) else " "
            print(f"{level:>5} {n:>6} {('CNR' if reproducible else 'plain') + used:>12} "
                  f"{one['factor_us'] / 1e3:>8.2f} / {two['factor_us'] / 1e3:<7.2f} "
                  f"{one['solve_us']:>7.0f} / {two['solve_us']:<7.0f} "
                  f"{'yes' if np.array_equal(one['x'], two['x']) else 'no'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
