"""Route optimization with the gradient at every point it values, and only where SLSQP asks.

Usage: python benchmarks/route_gradients.py SCENE [LEVEL] [DESIGN FLAGS ...] [--repeat N] [--calls K]

Runs ``tendon-taichi design SCENE --level LEVEL --workers 0`` (default
level 1, and any further ``design`` flags given) in this process and keeps the
arguments of every route optimization it makes (``route_replay.record``; with
``--calls K``, of the first K only, the design stopped there).
Then it runs them all again N times (default 2) each way, alternating: with
each point's adjoint solved as the point is valued (what ``optimize_routes``
did before: the trial points SLSQP's line search rejects had their gradient
computed too) and as ``optimize_routes`` does now (the adjoint only at the
points SLSQP asks the gradient of). It prints per way the median time, the
points valued and the adjoint solves, and how the objectives the two ways end
at compare, call by call (they follow different paths from the same starts: a
point's equilibrium starts from the last factorization, which an adjoint
solve refreshes). docs/method.md ("Route optimization") quotes its figures
for t_shape at level 2.
"""

import sys
import time
from contextlib import ExitStack

import numpy as np

from tendon_taichi.extract import routing
from tendon_taichi.probes import around

from _scene_args import scene_args
from route_replay import alternating, record, take_calls

WAYS = {"gradient at every point": True, "gradient where SLSQP asks": False}


def replay(calls: list[tuple], every_point: bool) -> tuple[float, int, int, list[float]]:
    """Every call again, with ``every_point`` each point's adjoint solved as it is
    valued: the time (s), the points valued, the adjoint solves and each call's objective."""
    adjoints = [0]

    def counted(call, self, rhs):
        adjoints[0] += 1
        return call(self, rhs)

    def valued_with_gradient(call, self, z):
        f = call(self, z)
        self.gradient(z)
        return f

    with ExitStack() as stack:
        stack.enter_context(around("PoseSolve.adjoint", counted))
        if every_point:
            stack.enter_context(around("RouteObjective.value", valued_with_gradient))
        seconds, points, objectives = 0.0, 0, []
        for args, kwargs in calls:
            t0 = time.perf_counter()
            out = routing.optimize_routes(*args, **kwargs)
            seconds += time.perf_counter() - t0
            points += out.evaluations
            objectives.append(out.objective)
    return seconds, points, adjoints[0], objectives


def run(argv: list[str]) -> None:
    argv, k = take_calls(argv)
    scene, level, flags, repeat = scene_args(argv, repeat=2)
    calls = record([scene, "--level", level, *flags], k)
    runs = alternating(calls, WAYS, replay, repeat)
    print(f"route optimizations: {len(calls)} ({scene} level {level})")
    for label, done in runs.items():
        median = float(np.median([r[0] for r in done]))
        print(f"{label}: {median:.2f} s, {done[0][1]} points valued, {done[0][2]} adjoint solves")
    every, asked = (np.array(runs[label][0][3]) for label in WAYS)
    kept = np.isfinite(every) & np.isfinite(asked) & (every > 0)
    ratio = asked[kept] / every[kept]
    print(f"objective where asked / at every point: median {np.median(ratio):.3f}, from {ratio.min():.3f} to "
          f"{ratio.max():.3f}; over 1 % lower in {int((ratio < 0.99).sum())}, over 1 % higher in "
          f"{int((ratio > 1.01).sum())} of {len(ratio)}")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    run(sys.argv[1:])
