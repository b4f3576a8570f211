"""The realizable robot's two solvers side by side on the solves a real command makes.

Usage: python benchmarks/realizable_side_by_side.py SCENE [LEVEL] [DESIGN FLAGS ...]

Runs ``tendon-taichi design SCENE --level LEVEL`` (default level 1, and
any further ``design`` flags given) in this process, into a temporary folder,
and solves every realizable robot the design solves twice more from the same
start - by bounded Gauss-Newton (what ``solve_realizable`` uses) and by
L-BFGS-B (``run_stage``, what it used before). After the design's own table it
prints how many Gauss-Newton solves ended worse or better than L-BFGS-B's by
more than 1e-7 L, the largest differences, and the equilibria and time each
solver took in all. The design itself goes on with Gauss-Newton's result.
docs/method.md ("The realizable (as-built) robot") quotes its figures for
finger, t_shape and finger_updown at level 1.
"""

import sys
import tempfile
import time

import numpy as np

from tendon_taichi.cli import main
from tendon_taichi.errors import ConvergenceError
from tendon_taichi.extract import realizable
from tendon_taichi.optimizer.gauss_newton import gauss_newton
from tendon_taichi.optimizer.homotopy import RunCallbacks, run_stage
from tendon_taichi.optimizer.soft_ik import SoftIK
from tendon_taichi.probes import around

#: differences in pose error (fraction of L) below this are ties
TIE = 1e-7
ROWS: list[dict] = []


def _both(call, context, tendons, tensions=None, start=None, positions=None):
    """``solve_realizable`` (``call``, its probe), with the solve done by both solvers on the side."""
    problem, state, settings, solver = context.problem, context.state, context.settings, context.solver
    if tendons:
        r0 = realizable.warm_ratios(problem, tendons, state, tensions) if start is None else np.asarray(start, float)
        warm = None if positions is None else [positions]
        row = {"tendons": len(tendons)}
        for name in ("gn", "lbfgsb"):
            ik = SoftIK(problem, settings, solver, cables=realizable.tendon_cables(problem, tendons))
            t0 = time.perf_counter()
            try:
                st = gauss_newton(ik, r0, warm) if name == "gn" else run_stage(ik, 0, r0, RunCallbacks(), warm=warm)
                row[name] = (st.figures.pose_error_rel, st.evaluations, time.perf_counter() - t0)
            except ConvergenceError:
                row[name] = (np.inf, 0, time.perf_counter() - t0)
        ROWS.append(row)
    return call(context, tendons, tensions, start, positions)


def report() -> None:
    both = [r for r in ROWS if np.isfinite(r["gn"][0]) and np.isfinite(r["lbfgsb"][0])]
    d = np.array([r["gn"][0] - r["lbfgsb"][0] for r in both])
    print(f"realizable solves: {len(ROWS)} ({len(ROWS) - len(both)} unsolved by one of the two)")
    print(f"Gauss-Newton worse by > {TIE:g} L: {int((d > TIE).sum())} (largest {d.max():.2e} L); "
          f"better: {int((d < -TIE).sum())} (largest {-d.min():.2e} L)")
    for name, label in (("lbfgsb", "L-BFGS-B"), ("gn", "Gauss-Newton")):
        print(f"{label}: {sum(r[name][1] for r in ROWS)} equilibria, {sum(r[name][2] for r in ROWS):.2f} s")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__.split("\n\n")[1])
    scene, rest = sys.argv[1], sys.argv[2:]
    level = rest.pop(0) if rest and rest[0].isdigit() else "1"
    with around("solve_realizable", _both), tempfile.TemporaryDirectory() as out:
        code = main(["design", scene, "--level", level, "--out", out, "--quiet", "--workers", "0", "--no-png",
                     *rest])
    if code:
        sys.exit(code)
    report()
