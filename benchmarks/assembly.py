"""The direct backend's Hessian assembly two ways, level by level: as it runs
(the block entries summed in Taichi, ``Model.hessian_sums``, no block-Jacobi
preconditioner prepared) and as it ran before (the entries' list,
``Model.hessian_entries``, scattered by ``np.bincount``, the preconditioner
prepared too).

Usage: python benchmarks/assembly.py [SCENE] [--levels 2 3 4 5] [--repeat N]

Per level, at the equilibrium of ``tendon-taichi bench``'s first design of the
fiber lattice: the entries (element and segment block entries) and the sparse
entries they sum into; each way's mean time over N assemblies (default 200), each
timed right after a factorization of the same Hessian (as in the optimizer, where
one precedes most assemblies: it leaves little of the assembly's data in the
caches); and whether the two ways' sums are the same to the bit. docs/method.md
(the direct backend) quotes its figures for t_shape.
"""

import argparse
import sys
import time

import numpy as np

from tendon_taichi.apps.bench import design_pair
from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import load_scene
from tendon_taichi.optimizer.soft_ik import SoftIK
from tendon_taichi.solve.newton import NewtonSolver


def listed(model, scatter: np.ndarray, bins: int) -> np.ndarray:
    """The assembly as it was: the preconditioner prepared, the entries' list scattered."""
    model.prepare_hessian()
    return np.bincount(scatter, weights=model.hessian_entries(), minlength=bins)


def summed(model, scatter: np.ndarray, bins: int) -> np.ndarray:
    """The assembly as the direct backend runs it."""
    model.prepare_hessian(jacobi=False)
    return model.hessian_sums(scatter, bins)


def timed(fn, factorize, repeat: int) -> float:
    """Mean ms of ``fn()``, each call right after ``factorize()``."""
    total = 0.0
    for _ in range(repeat):
        factorize()
        t = time.perf_counter()
        fn()
        total += time.perf_counter() - t
    return 1e3 * total / repeat


def measure(scene, level: int, repeat: int) -> dict:
    problem = build_problem(scene, level)
    ik = SoftIK(problem, scene.optimize, "direct")
    ik.configure(None)
    first, _ = design_pair(problem)
    model, linear = ik.model, ik.linear
    NewtonSolver(model, linear).solve(ac=first * problem.fibers.a0, x0=problem.mesh.nodes)
    H = linear.assemble_ordered()
    scatter, bins = linear.scatter, linear.nnz + 1
    same = listed(model, scatter, bins).tobytes() == summed(model, scatter, bins).tobytes()
    def factorize():
        return linear.factorize(H)
    return {"level": level, "entries": len(scatter), "sparse": linear.nnz, "same": same,
            "listed": timed(lambda: listed(model, scatter, bins), factorize, repeat),
            "summed": timed(lambda: summed(model, scatter, bins), factorize, repeat)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3, 4, 5])
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args(argv)
    scene = load_scene(args.scene)
    print(f"{'level':>5} {'entries':>8} {'sparse':>7} {'listed ms':>9} {'summed ms':>9} {'ratio':>5} same bits")
    for level in args.levels:
        r = measure(scene, level, args.repeat)
        print(f"{r['level']:>5} {r['entries']:>8} {r['sparse']:>7} {r['listed']:>9.2f} {r['summed']:>9.2f} "
              f"{r['listed'] / r['summed']:>5.2f} {'yes' if r['same'] else 'NO'}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
