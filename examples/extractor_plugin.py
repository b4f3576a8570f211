"""A third-party extractor: straight runs of active fibers, tried on a run.

    python examples/extractor_plugin.py [SCENE] [--quick]

An extractor imports only the public protocol, ``tendon_taichi.extraction``
(docs/plugins.md). This one traces, from the most tensioned active fiber on,
the straight line of active fibers through it, and keeps the runs that are long
enough. The script optimizes SCENE (default finger) at level 1 into a temporary
recording, reads its last stage as an extractor sees it, runs the plugin and
prints the count, length and coverage of its tendons by the metrics every
extractor is scored by. Registered under the entry-point group
``tendon_taichi.extractors`` of an installed package (docs/plugins.md shows
the pyproject.toml lines), ``design --extractors straight_runs`` would turn
its tendons into routes like any other's. ``--quick``: a short homotopy.
"""

import argparse
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

from tendon_taichi.extraction import (EXTRACTOR_API, Extractor, FiberView, IdealizedState, MetricSettings, Tendon,
                                      prune, tendon_metrics)

#: a turn below this counts as straight on, rad (lattice angles are multiples of 45 degrees)
STRAIGHT = 1e-6


class StraightRuns(Extractor):
    """Straight lines of active fibers, strongest first, each fiber in one run at most."""

    name = "straight_runs"
    description = "straight lines of active fibers (example plugin)"
    api = EXTRACTOR_API

    @dataclass
    class Options:
        min_length: float = 0.01    # m, shorter runs are dropped
        min_tension: float = 0.25   # drop runs weaker than this x the strongest one

    def extract(self, problem, state: IdealizedState, options) -> list[Tendon]:
        view = FiberView(problem)
        used = ~state.active  # slack fibers never join a run

        def stepper(seed, visited):
            def extend(v, f_in):
                added = []
                while True:
                    nxt = [g for g in view.incident(v) if not used[g] and view.turn(f_in, v, g) < STRAIGHT]
                    if not nxt or view.other(nxt[0], v) in visited:
                        return added
                    f_in = int(nxt[0])
                    used[f_in] = True
                    v = view.other(f_in, v)
                    visited.add(v)
                    added.append(f_in)
            return extend

        return prune(view.greedy_tendons(state, used, stepper), options)


def recorded_state(scene_name: str, quick: bool, folder: Path):
    """Optimize ``scene_name`` at level 1 into ``folder``; the problem and the last
    stage's state as an extractor is given them."""
    import tendon_taichi as tt
    from tendon_taichi.apps.extract import idealized_state
    from tendon_taichi.body.scene import with_overrides

    scene = tt.load_scene(scene_name)
    if quick:
        scene = with_overrides(scene, {"stage_iterations": 10, "k_min": 0.4})
    run = tt.optimize(scene, 1, record=folder / "run.rrd")  # its export beside it
    recorded = tt.read_recording(run.recording)
    stage = len(recorded.stages) - 1
    return run.problem, idealized_state(recorded, run.problem, stage, recorded.meta["solver"])


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="finger")
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="straight-runs-") as tmp:
        problem, state = recorded_state(args.scene, args.quick, Path(tmp))
    plugin = StraightRuns()
    tendons = plugin.extract(problem, state, plugin.make_options())
    m = tendon_metrics(problem, state, tendons, MetricSettings(mu=problem.scene.tendons.friction))
    print(f"{plugin.name}: {m['count']} tendon(s), {100 * m['total_length']:.1f} cm, largest turn "
          f"{math.degrees(m['max_turn']):.1f} deg, coverage {100 * m['coverage']:.1f}% of the active tension-length")
    return m


if __name__ == "__main__":
    main()
