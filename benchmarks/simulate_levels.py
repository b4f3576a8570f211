"""Equilibrium figures of `simulate t_shape --uniform 0.1` at levels 1-4, both solvers.

Usage: python benchmarks/simulate_levels.py [--levels 1 2 3 4] [--repeat 5]
Prints, per level and solver: nodes, triangles, fibers, DOFs, Newton and CG
iterations, and the median / min / max wall time of the solve after a warm-up
(compilation excluded), plus the time of the very first solve in the process
(which includes compiling the Taichi kernels).
"""

import argparse
import statistics
import time

from tendon_taichi import Model, NewtonSolver, build_problem, load_scene


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scene", default="t_shape")
    args = ap.parse_args()
    first = None
    print(f"{'level':>5} {'nodes':>6} {'tris':>6} {'fibers':>6} {'dofs':>6} {'solver':>7} {'newton':>6} "
          f"{'cg it':>6} {'median s':>9} {'min s':>8} {'max s':>8}")
    for lv in args.levels:
        p = build_problem(load_scene(args.scene), lv)
        c = p.counts()
        for solver in ("cg", "direct"):
            m = Model.from_problem(p)
            newton = NewtonSolver(m, solver)
            ac = 0.1 * p.fibers.a0
            t0 = time.perf_counter()
            eq = newton.solve(ac=ac, x0=p.mesh.nodes)
            if first is None:
                first = time.perf_counter() - t0
            times = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                eq = newton.solve(ac=ac, x0=p.mesh.nodes)
                times.append(time.perf_counter() - t0)
            print(f"{lv:>5} {c['nodes']:>6} {c['triangles']:>6} {c['fibers']:>6} {c['dofs']:>6} {solver:>7} "
                  f"{eq.newton_iterations:>6} {eq.linear_iterations:>6} {statistics.median(times):>9.4f} "
                  f"{min(times):>8.4f} {max(times):>8.4f}")
    print(f"first solve in the process (includes compiling the kernels): {first:.2f} s")


if __name__ == "__main__":
    main()
