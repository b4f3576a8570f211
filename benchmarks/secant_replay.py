"""Newton's chord steps plain and secant-corrected, on the same evaluations.

Usage: python benchmarks/secant_replay.py SCENE [LEVEL] [OPTIMIZE FLAGS ...] [--repeat N]

Runs ``tendon-taichi optimize SCENE --level LEVEL`` (default level 1, and
any further ``optimize`` flags given) in this process, into a temporary folder,
and logs every call the optimizer makes to its soft IK (stage settings,
restarts, evaluations). Then it replays that sequence N times (default 2) with
each kind of chord step, alternating: plain chord steps refreshed where a step
leaves more than 0.5 of the residual, and secant-corrected ones (the
default, :mod:`tendon_taichi.solve.secant`). Both solve the same equilibria and
adjoints, so the time they take compares the two alone, whatever path the
optimization took. It prints the evaluations, then per kind the median time of
all evaluations, the factorizations and the chord solves, and how closely the
two kinds' objectives agree (the equilibria agree to Newton's tolerance).
docs/method.md ("Newton") quotes its figures for t_shape at level 5.
"""

import sys
import tempfile
import time
from contextlib import ExitStack

import numpy as np

from tendon_taichi.cli import main
from tendon_taichi.optimizer import soft_ik
from tendon_taichi.probes import around

from _scene_args import scene_args

CALLS = ("configure", "restart", "warm_start", "settle", "evaluate")


def record(argv: list[str]) -> tuple[tuple, list]:
    """Run ``optimize`` with ``argv``; return the soft IK's (problem, settings, solver)
    and its calls [(name, args)]."""
    made, calls = [], []

    def logged_init(call, self, problem, settings, solver="auto", cables=None):
        made.append((problem, settings, solver))
        call(self, problem, settings, solver, cables)

    def logging(name):
        def logged(call, self, *args):
            calls.append((name, [np.array(a) if isinstance(a, np.ndarray) else a for a in args]))
            return call(self, *args)
        return logged
    with ExitStack() as stack:
        stack.enter_context(around("SoftIK.__init__", logged_init))
        for name in CALLS:
            stack.enter_context(around(f"SoftIK.{name}", logging(name)))
        with tempfile.TemporaryDirectory() as d:
            rc = main(["optimize", *argv, "--quiet", "--record", f"{d}/run.rrd"])
    if rc:
        sys.exit(rc)
    return made[0], calls


def replay(made: tuple, calls: list, secant: bool) -> tuple[float, int, int, np.ndarray]:
    """The calls replayed on a new soft IK: the time its evaluations took (s), its
    factorizations and chord solves, and the objective of each evaluation."""
    ik = soft_ik.SoftIK(*made)
    for ps in ik.poses:
        if not secant:
            ps.newton.secant_pairs = 0
    seconds, values = 0.0, []
    for name, args in calls:
        t0 = time.perf_counter()
        out = getattr(ik, name)(*args)
        if name == "evaluate":
            seconds += time.perf_counter() - t0
            values.append(out[0])
    stats = [ps.linear.stats for ps in ik.poses]
    return seconds, sum(s.solves for s in stats), sum(s.reused for s in stats), np.array(values)


def run(argv: list[str]) -> None:
    scene, level, flags, repeat = scene_args(argv, repeat=2)
    made, calls = record([scene, "--level", level, *flags])
    runs = {False: [], True: []}
    for _ in range(repeat):
        for secant in (False, True):
            runs[secant].append(replay(made, calls, secant))
    print(f"evaluations: {sum(name == 'evaluate' for name, _ in calls)} ({scene} level {level})")
    for secant, label in ((False, "plain chord steps"), (True, "secant-corrected")):
        _, factorizations, chords, _ = runs[secant][0]
        median = float(np.median([r[0] for r in runs[secant]]))
        print(f"{label}: {median:.2f} s, {factorizations} factorizations, {chords} chord solves")
    plain, corrected = runs[False][0][3], runs[True][0][3]
    print(f"objectives agree to: {np.max(np.abs(plain - corrected) / np.abs(plain)):.1e} (largest relative difference)")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    run(sys.argv[1:])
