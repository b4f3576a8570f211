"""The front's errors on a mesh no route was fitted to.

Usage: python benchmarks/planted/held_out.py RUN [RUN ...] [--above N]

`design` reports each front entry's as-built error on the next finer mesh
(level + 1), after optimizing its routes once more there (docs/method.md, the
front). This solves each entry of every case of a planted-bench run
(RUN/planted_bench.json; the counts up to planted + 1) on the mesh N levels
above the design's (default 2: a mesh no route of the entry was optimized on),
from the entry's own contraction ratios, and prints per entry the error
reported, the error there and their difference (% of L), then per run the
median and the extremes of the difference and how many entries exceed 0.05 and
0.1 % of L. Nothing is written.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from tendon_taichi import build_problem
from tendon_taichi.apps.priors import read_prior
from tendon_taichi.errors import ConvergenceError
from tendon_taichi.extract.context import Context
from tendon_taichi.extract.converge import pose_only_state
from tendon_taichi.extract.realizable import solve_realizable_poses
from tendon_taichi.io.recording import read_recording


def held_out(case: dict, above: int) -> list[tuple[int, float, float]]:
    """Per front entry of a planted-bench case (up to planted + 1 tendons): its
    count, the error reported and the error on the mesh ``above`` levels up
    (fractions of L; nan where it cannot be solved there)."""
    recording = Path(case["recording"])
    design = json.loads((recording.parent / "design.json").read_text())
    run = read_recording(recording)
    problem = run.problem()
    far = build_problem(problem.scene, problem.level + above)
    state = pose_only_state(far)
    out = []
    entries = [e for e in design["front"] if e.get("routes")]  # those read_prior makes layouts of, in order
    for entry, layout in zip(entries, read_prior(recording.parent, problem.scene).layouts):
        if entry["count"] > case["planted_count"] + 1:
            break
        try:
            context = Context(far, state, run.settings, run.meta.get("solver", "auto"))
            error = solve_realizable_poses(context, [r.tendon() for r in layout.routes], layout.ratios).pose_error_rel
        except ConvergenceError:
            error = float("nan")
        out.append((entry["count"], entry["realizable_pose_error_rel"], error))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="planted-bench output folders (with planted_bench.json)")
    ap.add_argument("--above", type=int, default=2, help="levels above the design's (default 2)")
    args = ap.parse_args(argv)
    for folder in args.runs:
        result = json.loads((folder / "planted_bench.json").read_text())
        diffs = []
        for case in result["cases"]:
            if "error" in case:
                continue
            for count, reported, there in held_out(case, args.above):
                diffs.append(there - reported)
                print(f"{case['case']:<26} k={count} reported {100 * reported:.4f}% "
                      f"level+{args.above} {100 * there:.4f}% difference {100 * (there - reported):+.4f}%")
        d = np.array(diffs)
        print(f"level {result['level']}: {len(d)} entries; level+{args.above} minus reported: median "
              f"{100 * np.nanmedian(d):+.4f}%, largest {100 * np.nanmax(d):+.4f}%, smallest {100 * np.nanmin(d):+.4f}%, "
              f"over 0.05%: {int((d > 5e-4).sum())}, over 0.1%: {int((d > 1e-3).sum())}, "
              f"not solved: {int(np.isnan(d).sum())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
