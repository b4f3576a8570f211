"""The README's "how it works" picture: one planted case, from the planted tendons
to the as-built robot of the recommended design.

Usage: python benchmarks/how_it_works/make_figure.py [CASE] [--level N] [--out PNG]
       [--stage-iterations N] [--k-min K] [--beam B] [--no-converge]
(default: t_shape_planted_2t_s2 at level 2, a few minutes). Runs the design
pipeline on the planted scene with the default settings (or these overridden,
for a quick look): optimize, every extractor on the last stage,
consolidation and route optimization, the recommended design; and writes
how_it_works.png beside this file (or to --out); the PNG records the commit
that made it.
"""

import argparse
import json
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

from tendon_taichi import load_scene
from tendon_taichi.apps.case import CaseSettings, run_case
from tendon_taichi.body.scene import with_overrides
from tendon_taichi.cli.tendons import add_front_flags, front_settings
from tendon_taichi.extract.settings import FrontSettings
from tendon_taichi.io.plots import plot_story

HERE = Path(__file__).resolve().parent
SUITE = HERE.parent / "planted"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("case", nargs="?", default="t_shape_planted_2t_s2")
    ap.add_argument("--level", type=int, default=2)
    ap.add_argument("--out", type=Path, default=HERE / "how_it_works.png")
    ap.add_argument("--stage-iterations", type=int)
    ap.add_argument("--k-min", type=float)
    add_front_flags(ap)
    args = ap.parse_args()
    layout = json.loads((SUITE / f"{args.case}.json").read_text())
    scene = with_overrides(load_scene(SUITE / f"{args.case}.toml"),
                           {"stage_iterations": args.stage_iterations, "k_min": args.k_min})
    with tempfile.TemporaryDirectory() as tmp:
        settings = CaseSettings(front=FrontSettings(**front_settings(args)))
        design = run_case(scene, args.level, Path(tmp) / "design", settings)
    run, rec = design.run, design.summary["recommended"]
    s0, final = run.stages[0], run.stages[-1]
    shown = SimpleNamespace(name=f"design, from {rec['source']}", metrics=rec["metrics"],
                            tendons=design.layout.tendons(), realizable=design.layout.realizable)
    out = plot_story(args.out, run.problem, layout, (s0.x, s0.tau, s0.figures),
                     (final.x, final.tau, final.figures), shown)
    print(f"{out}: stage 0 {s0.figures.active_fibers} active, final {final.figures.active_fibers} active; "
          f"design: {rec['count']} tendons from {rec['source']}, as built "
          f"{100 * rec['metrics']['realizable_pose_error_rel']:.2f}% of L", file=sys.stderr)


if __name__ == "__main__":
    main()
