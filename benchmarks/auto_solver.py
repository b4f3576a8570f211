"""Which linear backend ``--solver auto`` should pick: ``direct`` against ``cg``
inside the whole optimization, level by level.

Usage: python benchmarks/auto_solver.py [SCENE] [--levels 6 7 8]
       [--iterations 15 5 3] [--factorizations pardiso qdldl]

Per level (with its iterations per stage; fewer at the finer levels, where
one evaluation takes seconds) and per sparse Cholesky (``pardiso`` where MKL is
installed, ``qdldl`` always), the regularized optimization of SCENE with
``--solver direct`` and with ``--solver cg``, each in a process of its own:
wall seconds (mesh, model and the optimization; kernels from the cache),
evaluations, the last stage's pose error and the process's peak resident
memory, then the ratio cg / direct. Both backends use the same factorization
(``cg`` as its preconditioner), so what differs is the Krylov iterations
against the exact solves. ``AUTO_DIRECT_MAX_DOFS`` in
``tendon_taichi/solve/linear.py`` quotes its figures for t_shape.
"""

import argparse
import json
import subprocess
import sys

ONE = r"""
import contextlib, json, resource, sys, time
scene_name, level, iterations, solver, factor = sys.argv[1:6]
from tendon_taichi.probes import around
from tendon_taichi.solve import pardiso
if factor == "pardiso" and not pardiso.available():
    print(json.dumps(None)); sys.exit(0)
from tendon_taichi.apps.optimize import optimize
from tendon_taichi.body.scene import load_scene, with_overrides
scene = with_overrides(load_scene(scene_name), {"stage_iterations": int(iterations)})
t = time.perf_counter()
# qdldl: the direct backend told that PARDISO did not load (its probe), so it factorizes with qdldl
with around("pardiso", lambda call: False) if factor == "qdldl" else contextlib.nullcontext():
    run = optimize(scene, int(level), solver)
wall = time.perf_counter() - t
print(json.dumps({"wall_s": wall, "evaluations": run.summary.get("evaluations"),
                  "pose_error_rel": run.stages[-1].figures.pose_error_rel,
                  "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def one(scene: str, level: int, iterations: int, solver: str, factor: str) -> dict | None:
    """One optimization in a fresh process; None where that factorization is not installed."""
    out = subprocess.run([sys.executable, "-c", ONE, scene, str(level), str(iterations), solver, factor],
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[6, 7, 8])
    ap.add_argument("--iterations", type=int, nargs="+", default=[15, 5, 3],
                    help="iterations per stage, one per level (the last one repeats)")
    ap.add_argument("--factorizations", nargs="+", default=["pardiso", "qdldl"], choices=["pardiso", "qdldl"])
    args = ap.parse_args(argv)
    print("level  iters  factor    solver    wall s  evals  error %   peak MB   cg/direct")
    for i, level in enumerate(args.levels):
        iters = args.iterations[min(i, len(args.iterations) - 1)]
        for factor in args.factorizations:
            rows = {s: one(args.scene, level, iters, s, factor) for s in ("direct", "cg")}
            if rows["direct"] is None:
                print(f"{level:5d}  {iters:5d}  {factor:8s}  (not installed)")
                continue
            for s, r in rows.items():
                ratio = f"{rows['cg']['wall_s'] / rows['direct']['wall_s']:9.2f}" if s == "cg" else ""
                print(f"{level:5d}  {iters:5d}  {factor:8s}  {s:8s}  {r['wall_s']:6.1f}  {r['evaluations']:5d}  "
                      f"{100 * r['pose_error_rel']:7.4f}  {r['peak_mb']:8.0f}  {ratio}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
