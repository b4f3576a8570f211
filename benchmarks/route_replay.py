"""Route optimization with and without detached segments, on the same calls.

Usage: python benchmarks/route_replay.py SCENE [LEVEL] [DESIGN FLAGS ...] [--repeat N]

Runs ``tendon-taichi design SCENE --resolution LEVEL --workers 0`` (default
level 1, and any further ``design`` flags given) in this process, into a
temporary folder, and keeps the arguments of every route optimization it makes.
Then it runs them all again N times (default 2) with each setting of the direct
backend, alternating: every moved route's pattern made anew where a waypoint
crossed into another triangle (``detached_max`` 0), and the default, which keeps
the pattern where it lacks the entries of at most ``DETACHED_MAX`` segments
(:meth:`~tendon_taichi.solve.direct.DirectSolver._reattach`). It prints the
calls, then per setting the median time, the evaluations and the milliseconds
per evaluation (the optimizations take their own paths from the same starts:
the Hessians agree to round-off), and how closely the summed objectives agree.
docs/method.md ("Route optimization") quotes its figures for t_shape at level 3.
"""

import sys
import tempfile
import time

import numpy as np

from tendon_taichi.cli import main
from tendon_taichi.extract import consolidation, routing
from tendon_taichi.physics import runtime
from tendon_taichi.solve import direct

from _scene_args import scene_args

#: the modules that call optimize_routes by their own name for it
CALLERS = (routing, consolidation)


def _copy(value):
    """Arrays (and lists of them) copied: the caller may change them afterwards."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, list) and value and isinstance(value[0], np.ndarray):
        return [v.copy() for v in value]
    return value


def record(argv: list[str]) -> list[tuple]:
    """Run ``design`` with ``argv`` (no workers); return every route optimization's
    arguments."""
    calls = []
    original = routing.optimize_routes

    def logged(*args, **kwargs):
        kept = {k: _copy(v) for k, v in kwargs.items() if k != "on_iteration"}
        calls.append((tuple(_copy(a) for a in args), kept))
        return original(*args, **kwargs)
    patched = [m for m in CALLERS if getattr(m, "optimize_routes", None) is original]
    for m in patched:
        m.optimize_routes = logged
    try:
        with tempfile.TemporaryDirectory() as d:
            rc = main(["design", *argv, "--quiet", "--workers", "0", "--no-png", "--out", d])
    finally:
        for m in patched:
            m.optimize_routes = original
    if rc:
        sys.exit(rc)
    return calls


def replay(calls: list[tuple], detached_max: int) -> tuple[float, int, float]:
    """Every call again with ``detached_max``: the time (s), the evaluations and the
    summed objective."""
    before = direct.DirectSolver.detached_max
    direct.DirectSolver.detached_max = detached_max
    try:
        seconds, evaluations, total = 0.0, 0, 0.0
        for args, kwargs in calls:
            t0 = time.perf_counter()
            out = routing.optimize_routes(*args, **kwargs)
            seconds += time.perf_counter() - t0
            evaluations += out.evaluations
            total += out.objective
    finally:
        direct.DirectSolver.detached_max = before
    return seconds, evaluations, total


def alternating(calls: list[tuple], settings: dict, replay, repeat: int) -> dict[str, list]:
    """``replay(calls, value)`` ``repeat`` times for each ``settings`` label and value,
    the settings alternating, one thread per factorization (as in design's
    processes): per label, the list of what each replay returned."""
    runs = {label: [] for label in settings}
    with runtime.cores_shared():
        for _ in range(repeat):
            for label, value in settings.items():
                runs[label].append(replay(calls, value))
    return runs


def run(argv: list[str]) -> None:
    scene, level, flags, repeat = scene_args(argv, repeat=2)
    calls = record([scene, "--resolution", level, *flags])
    settings = {"every pattern made anew": 0, "detached segments": direct.DETACHED_MAX}
    runs = alternating(calls, settings, replay, repeat)
    print(f"route optimizations: {len(calls)} ({scene} level {level})")
    for label, done in runs.items():
        median = float(np.median([r[0] for r in done]))
        evaluations = done[0][1]
        print(f"{label}: {median:.2f} s, {evaluations} evaluations, {1e3 * median / evaluations:.2f} ms each")
    anew, detached = (runs[label][0][2] for label in settings)
    print(f"summed objectives agree to: {abs(anew - detached) / abs(anew):.1e} (relative difference)")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    run(sys.argv[1:])
