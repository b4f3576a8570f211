"""The front's extension screen checked against finishing every extension in full.

Usage: python benchmarks/extension_screen.py SCENE [LEVEL] [DESIGN FLAGS ...]

Runs ``tendon-taichi design SCENE --level LEVEL --workers 0`` (default
level 1, and any further ``design`` flags given) in this process, into a
temporary folder. Each extension the front tries is screened, as the front
does (one round of at most ``EXTEND_SCREEN`` SLSQP iterations), and also
finished in full from the same start (oriented, ``--refine`` rounds of the
route settings' iterations: what the extension did before the screen). After
the design's own table it prints, over the layouts whose extensions were
tried, in how many the screen's best extension is the one whose full finish
costs least (and in how many the solve's alone, before any route optimization,
is), how the screened best's finish (the front's) compares with the
least full finish, and the route evaluations of the screens, the front's
finishes and the full finishes. The design itself goes on with the screen's
result. Two costs whose square roots (a pose error, where the routes' shape
costs nothing) differ by at most ``PRECISION``, the soft IK's precision, are
equal. docs/method.md ("The front", *extension*) quotes its figures.
"""

import sys
import tempfile

import numpy as np

from tendon_taichi.cli import main
from tendon_taichi.extract import front
from tendon_taichi.probes import around

from _scene_args import scene_args

#: per layout tried (the held layout's id): [(solved cost, screened cost, full finish cost)]
SCREENS: dict[int, list[tuple[float, float, float]]] = {}
#: per layout tried, in order: the cost of the screened best finished by the front
CONTINUED: list[float] = []
EVALS = {"screen": 0, "full": 0, "continued": 0}


def _screened(screen, search, layout, routes):
    """The front's screen (the probe ``screened``), and each extension finished in full beside."""
    before = search.out.route_evaluations
    lay = screen(search, layout, routes)
    EVALS["screen"] += search.out.route_evaluations - before
    if lay is None:
        return None
    before = search.out.route_evaluations
    start = np.atleast_2d(layout.realizable.ratios).reshape(search.problem.n_poses, -1)
    full = search.solve(routes, start, layout)
    cost = np.inf if full is None else search.finish(full)[0].cost
    EVALS["full"] += search.out.route_evaluations - before
    SCREENS.setdefault(id(layout), []).append((np.inf if full is None else full.cost, lay.cost, cost))
    return lay


def _continued(finish, search, layout, rounds):
    """The front's finish of the screened best (the probe ``continued``), its evaluations counted."""
    before = search.out.route_evaluations
    done = finish(search, layout, rounds)
    EVALS["continued"] += search.out.route_evaluations - before
    CONTINUED.append(done.cost)
    return done


def _equal(a: float, b: float) -> bool:
    """Whether two costs are equal (module docstring)."""
    return abs(np.sqrt(a) - np.sqrt(b)) <= front.PRECISION


def report() -> None:
    groups = [np.array(g) for g in SCREENS.values()]
    solve, screen = (sum(int(_equal(g[np.argmin(g[:, i]), 2], g[:, 2].min())) for g in groups) for i in (0, 1))
    ratio = np.array([1.0 if _equal(c, g[:, 2].min()) else c / g[:, 2].min() for g, c in zip(groups, CONTINUED)])
    print(f"extensions: {sum(map(len, groups))} of {len(groups)} layouts")
    print(f"solve's best finishes least: {solve} of {len(groups)}")
    print(f"screen's best finishes least: {screen} of {len(groups)}")
    if len(ratio):
        print(f"front's finish / least full finish: median {np.median(ratio):.3f}, worst {ratio.max():.3f}")
    print(f"route evaluations: screens {EVALS['screen']}, front's finishes {EVALS['continued']}, "
          f"full finishes {EVALS['full']}")


def run(argv: list[str]) -> int:
    scene, level, flags, _ = scene_args(argv)
    with around("screened", _screened), around("continued", _continued), tempfile.TemporaryDirectory() as tmp:
        rc = main(["design", scene, "--level", level, "--workers", "0", "--out", tmp, *flags])
    report()
    return rc


if __name__ == "__main__":
    if len(sys.argv) < 2:
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        sys.exit(2)
    sys.exit(run(sys.argv[1:]))
