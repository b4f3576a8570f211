"""The README's "how it works" picture: one planted case, from the planted tendons
to the realizable robot.

Usage: python benchmarks/how_it_works/make_figure.py [CASE] [--level N] [--out PNG]
       [--stage-iterations N] [--k-min K]
(default: t_shape_planted_2t_s2 at level 2, about a minute). Optimizes the
planted scene with the default settings (or these two overridden, for a quick
look), runs every extractor on the last stage, each followed by consolidation,
picks the one planted-bench would (the lowest realizable pose error among those
with at most planted + 1 tendons) and writes how_it_works.png beside this file
(or to --out); the PNG records the commit that made it.
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path

from tendon_taichi import load_scene
from tendon_taichi.apps.case import run_case
from tendon_taichi.body.scene import with_overrides
from tendon_taichi.io.plots import plot_story
from tendon_taichi.planted.bench import best_extractor

HERE = Path(__file__).resolve().parent
SUITE = HERE.parent / "planted"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("case", nargs="?", default="t_shape_planted_2t_s2")
    ap.add_argument("--level", type=int, default=2)
    ap.add_argument("--out", type=Path, default=HERE / "how_it_works.png")
    ap.add_argument("--stage-iterations", type=int)
    ap.add_argument("--k-min", type=float)
    args = ap.parse_args()
    layout = json.loads((SUITE / f"{args.case}.json").read_text())
    scene = with_overrides(load_scene(SUITE / f"{args.case}.toml"),
                           {"stage_iterations": args.stage_iterations, "k_min": args.k_min})
    with tempfile.TemporaryDirectory() as tmp:
        case = run_case(scene, args.level, Path(tmp) / "run.rrd", log_tendons=False)
    run, ex = case.run, case.extraction
    s0, final = run.stages[0], run.stages[-1]
    metrics = {r.name: r.metrics for r in ex.results if r.error is None}
    best = next(r for r in ex.results if r.name == best_extractor(metrics, len(layout["tendons"])))
    st = run.problem.scene.optimize
    out = plot_story(args.out, run.problem, layout, (s0.x, s0.tau, s0.figures),
                     (final.x, final.tau, final.figures), best, st.active_threshold * st.tension_scale,
                     st.tension_scale)
    print(f"{out}: stage 0 {s0.figures.active_fibers} active, final {final.figures.active_fibers} active; "
          f"{best.name}: {best.metrics['count']} tendons, realizable "
          f"{100 * best.metrics['realizable_pose_error_rel']:.2f}% of L", file=sys.stderr)


if __name__ == "__main__":
    main()
