"""The README's "how it works" picture: one planted case, from the planted tendons
to the realizable robot.

Usage: python benchmarks/how_it_works/make_figure.py [CASE] [--level N]
(default: t_shape_planted_2t_s2 at level 2; about 30 s). Optimizes the planted
scene with the default settings, runs every extractor on the last stage, picks
the one planted-bench would (fewest tendons within planted + 1, then the lowest
realizable pose error) and writes how_it_works.png beside this file.
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

from tendon_taichi import load_scene
from tendon_taichi.planted.bench import best_extractor
from tendon_taichi.io.plots import plot_story
from tendon_taichi.apps.optimize import optimize
from tendon_taichi.apps.extract import extract

HERE = Path(__file__).resolve().parent
SUITE = HERE.parent / "planted"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("case", nargs="?", default="t_shape_planted_2t_s2")
    ap.add_argument("--level", type=int, default=2)
    args = ap.parse_args()
    layout = json.loads((SUITE / f"{args.case}.json").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        run = optimize(load_scene(SUITE / f"{args.case}.toml"), args.level, record=Path(tmp) / "run.rrd")
        ex = extract(run.recording, record=False)
    s0, final = run.stages[0], run.stages[-1]
    metrics = {r.name: r.metrics for r in ex.results if r.error is None}
    best = next(r for r in ex.results if r.name == best_extractor(metrics, len(layout["tendons"])))
    st = run.problem.scene.optimize
    out = plot_story(HERE / "how_it_works.png", run.problem, layout, (s0.x, s0.tau, s0.figures),
                     (final.x, final.tau, final.figures), best, st.active_threshold * st.tension_scale,
                     st.tension_scale)
    print(f"{out}: stage 0 {s0.figures.active_fibers} active, final {final.figures.active_fibers} active; "
          f"{best.name}: {best.metrics['count']} tendons, realizable "
          f"{100 * best.metrics['realizable_pose_error_rel']:.2f}% of L", file=sys.stderr)


if __name__ == "__main__":
    main()
