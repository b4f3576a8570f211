"""Route optimization with and without detached segments, on the same calls.

Usage: python benchmarks/route_replay.py SCENE [LEVEL] [DESIGN FLAGS ...] [--repeat N] [--calls K]

Runs ``tendon-taichi design SCENE --level LEVEL --workers 0`` (default
level 1, and any further ``design`` flags given) in this process, into a
temporary folder, and keeps the arguments of every route optimization it makes
(with ``--calls K``, of the first K only, the design stopped there: a quick
look, as the tests take).
Then it runs them all again N times (default 2) with each setting of the direct
backend, alternating: every moved route's pattern made anew where a waypoint
crossed into another triangle (``detached_max`` 0), and the default, which keeps
the pattern where it lacks the entries of at most ``DETACHED_MAX`` segments
(:meth:`~tendon_taichi.solve.direct.DirectSolver._reattach`). It prints the
calls, then per setting the median time, the evaluations and the milliseconds
per evaluation (the optimizations take their own paths from the same starts:
the Hessians agree to round-off), and how closely the summed objectives agree.
Those paths split: SLSQP's steps amplify the two settings' differences of
round-off (at one point, about 1e-12 of the objective and 1e-10 of the
gradient), its points drift apart by up to 1e-9, and after 50-90 evaluations a
line search decides otherwise, so an optimization can end elsewhere (on
t_shape at level 1, one of 20 ended 1.2 % apart). What the setting must not
change is the objective and its gradient at a point: so it
also evaluates every point the default setting's optimizations evaluated again,
in the same order (the same warm starts), with every pattern made anew, and
prints how closely the objectives and gradients agree at the same points.
Last, where PARDISO loads (the ``mkl`` extra), the calls again with each way of
factorizing a Hessian that is not positive definite - PARDISO's symmetric
indefinite LDL^T (the default) and SuperLU - alternating, N times: how many such
factorizations the optimizations met and their median time each (the failed
Cholesky included). docs/method.md ("Route optimization", the direct backend)
quotes its figures for t_shape at level 3.
"""

import sys
import tempfile
import time
from contextlib import ExitStack
from unittest import mock

import numpy as np
import scipy.optimize as so

from tendon_taichi.cli import main
from tendon_taichi.extract import routing
from tendon_taichi.physics import runtime
from tendon_taichi.probes import around
from tendon_taichi.solve import direct, pardiso

from _scene_args import scene_args


def _copy(value):
    """Arrays (and lists of them) copied: the caller may change them afterwards."""
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, list) and value and isinstance(value[0], np.ndarray):
        return [v.copy() for v in value]
    return value


class Enough(BaseException):
    """Raised from a probe once a script holds the calls it asked for: the rest of
    the design is not needed (not an Exception, so nothing on the way turns it
    into an error line)."""


def record(argv: list[str], limit: int | None = None) -> list[tuple]:
    """Run ``design`` with ``argv`` (no workers); return every route optimization's
    arguments - with ``limit``, the first ``limit``, the design stopped there."""
    calls = []

    def logged(call, *args, **kwargs):
        kept = {k: _copy(v) for k, v in kwargs.items() if k != "on_iteration"}
        calls.append((tuple(_copy(a) for a in args), kept))
        if limit is not None and len(calls) >= limit:
            raise Enough
        return call(*args, **kwargs)
    try:
        with around("optimize_routes", logged), tempfile.TemporaryDirectory() as d:
            rc = main(["design", *argv, "--quiet", "--workers", "0", "--no-png", "--out", d])
    except Enough:
        return calls
    if rc:
        sys.exit(rc)
    return calls


def replay(calls: list[tuple], detached_max: int) -> tuple[float, int, float]:
    """Every call again with ``detached_max``: the time (s), the evaluations and the
    summed objective."""
    seconds, evaluations, total = 0.0, 0, 0.0
    with direct.detached_at_most(detached_max):
        for args, kwargs in calls:
            t0 = time.perf_counter()
            out = routing.optimize_routes(*args, **kwargs)
            seconds += time.perf_counter() - t0
            evaluations += out.evaluations
            total += out.objective
    return seconds, evaluations, total


def same_points(calls: list[tuple], reference: int, other: int) -> tuple[float, float, int]:
    """Every call optimized with ``detached_max`` ``reference``, then its objective and
    gradient evaluated again with ``other`` at the points the optimization asked for
    them, in its order (so from the same warm starts): the largest relative
    difference of the objectives, that of the gradients (by norm, relative to the
    call's first gradient), and how many evaluations were compared."""
    real = so.minimize  # scipy's, which optimize_routes calls as so.minimize
    asked: list[tuple] = []  # per call: (kind, point, what it gave) in order

    def recording(fun, z0, jac=None, **kwargs):
        def f(z):
            asked.append(("f", np.array(z), fun(z)))
            return asked[-1][2]

        def g(z):
            asked.append(("g", np.array(z), np.array(jac(z))))
            return asked[-1][2]
        return real(f, z0, jac=g, **kwargs)

    def playing(fun, z0, jac=None, **kwargs):
        ops = recorded.pop(0)
        scale = next((np.linalg.norm(value) for kind, _, value in ops if kind == "g"), 1.0)
        for kind, z, value in ops:
            again = fun(z) if kind == "f" else jac(z)
            if kind == "f":
                worst[0] = max(worst[0], abs(again - value) / max(abs(value), 1e-300))
            else:  # against the first gradient's norm: near the optimum a gradient is the equilibria's round-off
                worst[1] = max(worst[1], np.linalg.norm(again - value) / max(scale, 1e-300))
            worst[2] += 1
        return so.OptimizeResult(x=z0, message="replayed")

    recorded, worst = [], [0.0, 0.0, 0]
    with runtime.cores_shared():  # scipy's minimize swapped for the recorder, then the player
        with mock.patch.object(so, "minimize", recording), direct.detached_at_most(reference):
            for args, kwargs in calls:
                asked.clear()
                routing.optimize_routes(*args, **kwargs)
                recorded.append(list(asked))
        with mock.patch.object(so, "minimize", playing), direct.detached_at_most(other):
            for args, kwargs in calls:
                routing.optimize_routes(*args, **kwargs)
    return worst[0], worst[1], worst[2]


def indefinite_replay(calls: list[tuple], way: str) -> tuple[float, int]:
    """Every call again, the Hessians that are not positive definite factorized
    ``way`` ("PARDISO": its indefinite LDL^T, "SuperLU"): the median time of such a
    factorization (s; the failed Cholesky included) and how many there were."""
    made = []

    def timed(call, self, *args, **kwargs):
        t0 = time.perf_counter()
        call(self, *args, **kwargs)
        if self.ldl is None or self.ldl.indefinite:  # SuperLU's or the indefinite LDL^T: not the Cholesky
            made.append(time.perf_counter() - t0)

    with ExitStack() as stack:
        stack.enter_context(around("factorization", timed))
        if way == "SuperLU":  # no indefinite LDL^T: SuperLU factorizes
            stack.enter_context(around("indefinite", lambda call, pattern: None))
        for args, kwargs in calls:
            routing.optimize_routes(*args, **kwargs)
    return (float(np.median(made)) if made else 0.0), len(made)


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


def take_calls(argv: list[str]) -> tuple[list[str], int | None]:
    """``argv`` without ``--calls K``, and K (None where it is not given)."""
    argv = list(argv)
    if "--calls" not in argv:
        return argv, None
    i = argv.index("--calls")
    k = int(argv[i + 1])
    del argv[i:i + 2]
    return argv, k


def run(argv: list[str]) -> None:
    argv, k = take_calls(argv)
    scene, level, flags, repeat = scene_args(argv, repeat=2)
    calls = record([scene, "--level", level, *flags], k)
    settings = {"every pattern made anew": 0, "detached segments": direct.DETACHED_MAX}
    runs = alternating(calls, settings, replay, repeat)
    print(f"route optimizations: {len(calls)} ({scene} level {level})")
    for label, done in runs.items():
        median = float(np.median([r[0] for r in done]))
        evaluations = done[0][1]
        print(f"{label}: {median:.2f} s, {evaluations} evaluations, {1e3 * median / evaluations:.2f} ms each")
    anew, detached = (runs[label][0][2] for label in settings)
    print(f"summed objectives agree to: {abs(anew - detached) / abs(anew):.1e} (relative difference)")
    f, g, n = same_points(calls, direct.DETACHED_MAX, 0)
    print(f"at the same points: objectives agree to {f:.1e}, gradients to {g:.1e} of the first ({n} evaluations)")
    if pardiso.available():
        ways = alternating(calls, {"PARDISO": "PARDISO", "SuperLU": "SuperLU"}, indefinite_replay, repeat)
        print("not positive definite: " + ", ".join(
            f"{way} {1e3 * float(np.median([r[0] for r in done])):.2f} ms each ({done[0][1]})"
            for way, done in ways.items()))


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    run(sys.argv[1:])
