"""Route optimization's two methods side by side on the calls a real command makes.

Usage: python benchmarks/routes_side_by_side.py SCENE [LEVEL] [DESIGN FLAGS ...] [--calls K]

Runs ``tendon-taichi design SCENE --level LEVEL --workers 0`` (default
level 1, and any further ``design`` flags given) in this process, into a
temporary folder, and runs every route optimization the design makes twice
more from the same start: by SLSQP with the clearance as a constraint (what
``optimize_routes`` does) and by L-BFGS-B with the clearance as a penalty
``w_clear sum_i max(0, c - d_i)^2 / L^2``, ``w_clear = 100``, for at most 60
iterations (what it did before). After the design's own table it prints in how
many calls SLSQP ended lower, the median and extreme ratios of the two
objectives (L-BFGS-B's includes its penalty, a few 1e-9 at the points it
ends at), and the evaluations, iterations and time each method took in all. The design
itself goes on with SLSQP's result; with ``--calls K`` it stops after K route
optimizations (no table: a quick look, as the tests take). docs/method.md
("Route optimization") quotes its figures for t_shape and finger_updown at level 2.
"""

import sys
import tempfile
import time

import numpy as np
import scipy.optimize as so

from tendon_taichi.cli import main
from tendon_taichi.errors import ConvergenceError
from tendon_taichi.extract.routing import RouteObjective
from tendon_taichi.probes import around

from _scene_args import scene_args
from route_replay import Enough, take_calls

#: the penalty's weight and L-BFGS-B's iterations before
PENALTY = 1.0e2
ITERATIONS = 60
ROWS: list[dict] = []
#: the route optimizations to run both ways (``--calls K``; None: every one the design makes)
LIMIT: dict[str, int | None] = {"calls": None}


def penalty_lbfgsb(problem, routes, ratios, settings, rs, solver="auto", positions=None) -> tuple[float, int, int]:
    """The best objective (penalty included) L-BFGS-B reaches in ITERATIONS, its
    evaluations and its iterations."""
    obj = RouteObjective(problem, routes, settings, rs, solver)
    obj.positions = None if positions is None else [np.asarray(x) for x in positions]
    best = {"f": np.inf}

    def fun(z):
        try:
            f, g = obj.evaluate(z)
        except ConvergenceError:
            return 10.0 * abs(best["f"] if np.isfinite(best["f"]) else 1.0) + 1.0, np.zeros_like(z)
        v, J = obj.clearance(z)
        short = np.maximum(-v, 0.0)  # (c - d_i) / L where positive
        f, g = f + PENALTY * float(short @ short), g - 2.0 * PENALTY * (J.T @ short)
        best["f"] = min(best["f"], f)
        return f, g

    z0 = obj.pack(routes, ratios)
    fun(z0)
    res = so.minimize(fun, z0, jac=True, method="L-BFGS-B", bounds=obj.bounds(),
                      options={"maxiter": ITERATIONS, "ftol": 1e-12, "gtol": 1e-10, "maxcor": 10, "maxls": 30})
    return best["f"], obj.evaluations, int(res.nit)


def _both(call, context, routes, ratios, rs, positions=None, on_iteration=None):
    """``optimize_routes`` (``call``, its probe), with L-BFGS-B and the penalty run on the side."""
    t0 = time.perf_counter()
    f_old, ev_old, it_old = penalty_lbfgsb(context.problem, routes, ratios, context.settings, rs, context.solver,
                                           positions)
    t1 = time.perf_counter()
    it = {"k": 0}

    def count(k, objective):
        it["k"] = k
        if on_iteration is not None:
            on_iteration(k, objective)

    res = call(context, routes, ratios, rs, positions, count)
    ROWS.append({"old": (f_old, ev_old, t1 - t0, it_old),
                 "new": (res.objective, res.evaluations, time.perf_counter() - t1, it["k"])})
    if LIMIT["calls"] is not None and len(ROWS) >= LIMIT["calls"]:
        raise Enough
    return res


def report() -> None:
    both = [r for r in ROWS if np.isfinite(r["old"][0]) and np.isfinite(r["new"][0]) and r["old"][0] > 0]
    ratio = np.array([r["new"][0] / r["old"][0] for r in both])
    print(f"route optimizations: {len(ROWS)} ({len(ROWS) - len(both)} without a finite objective by one of the two)")
    if len(both):
        print(f"SLSQP lower: {int((ratio < 1).sum())} of {len(both)}; objective SLSQP / L-BFGS-B: median "
              f"{np.median(ratio):.3f}, from {ratio.min():.3f} to {ratio.max():.3f}")
    for key, label in (("old", "L-BFGS-B, penalty"), ("new", "SLSQP, constraint")):
        ev, t, its = (sum(r[key][i] for r in ROWS) for i in (1, 2, 3))
        print(f"{label}: {ev} evaluations in {its} iterations, {t:.1f} s")


def run(argv: list[str]) -> int:
    argv, LIMIT["calls"] = take_calls(argv)
    scene, level, flags, _ = scene_args(argv)
    rc = 0
    try:
        with around("optimize_routes", _both), tempfile.TemporaryDirectory() as tmp:
            rc = main(["design", scene, "--level", level, "--workers", "0", "--out", tmp, *flags])
    except Enough:
        pass
    report()
    return rc


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    sys.exit(run(sys.argv[1:]))
