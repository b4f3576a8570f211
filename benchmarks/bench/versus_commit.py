"""Time ``design`` of this checkout against ``optimize`` + ``compare`` of an
earlier commit, side by side in one run (issue 25's end-to-end target: the
old pipeline stopped at the compared extractors; ``design`` adds the routes,
the front and the mesh-converged errors).

Usage: python benchmarks/bench/versus_commit.py OLD_VENV [--scene t_shape]
       [--levels 2 3] [--repeat N] [--out DIR] [--json FILE] [--tiny]

OLD_VENV is a virtual environment with the earlier commit installed, for
example::

    git worktree add /tmp/old b58fd16
    python3 -m venv /tmp/old-venv && /tmp/old-venv/bin/pip install /tmp/old
    python benchmarks/bench/versus_commit.py /tmp/old-venv

Per level the old pipeline runs first, then this checkout's ``design`` (the
``tendon-taichi`` of the interpreter running this script), each in its own
process; wall times in seconds, the ratio old / new, on stdout (and as JSON).
``--repeat N`` (default 1) runs that pair N times per level, one after the
other: each figure is then its own median over the N runs (so the old
pipeline's two parts need not add up to its whole; the ratio is the median of
the runs' own ratios, with its lowest and highest), and the JSON keeps each run
too - on a shared machine the ratio moves by several percent from run to run.
``--tiny`` (for the tests) runs 30 iterations per stage and no consolidation in
both, and ``design`` on the design mesh alone: no measurement.
"""

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed(cmd: list[str]) -> float:
    """Wall time of one command (s); its output is discarded, a failure stops the run."""
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t


def summarized(level: int, runs: list[dict]) -> dict:
    """A level's row: each figure's median over ``runs`` (one run: its own figures),
    the ratio's lowest and highest, and the runs."""
    row = {"level": level, **{key: statistics.median(r[key] for r in runs) for key in runs[0]}}
    row.update(speedup_min=min(r["speedup"] for r in runs), speedup_max=max(r["speedup"] for r in runs),
               runs=runs)
    return row


def line(row: dict) -> str:
    """The row as one line of stdout."""
    n = len(row["runs"])
    spread = "" if n == 1 else f" (median of {n} runs: {row['speedup_min']:.2f}-{row['speedup_max']:.2f})"
    return (f"level {row['level']}: old optimize {row['old_optimize_s']:.1f} s + compare {row['old_compare_s']:.1f} s "
            f"= {row['old_s']:.1f} s; design {row['design_s']:.1f} s; old / new {row['speedup']:.2f}{spread}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old_venv", type=Path)
    ap.add_argument("--scene", default="t_shape")
    ap.add_argument("--levels", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--repeat", type=int, default=1, help="pairs of runs per level (the medians are reported)")
    ap.add_argument("--out", type=Path, default=None, help="work folder (default: a temporary one)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--tiny", action="store_true", help="a run that only checks the script works")
    args = ap.parse_args(argv)
    if args.repeat < 1:
        ap.error("--repeat must be at least 1")
    short = ["--stage-iterations", "30"] if args.tiny else []
    bare = ["--no-consolidate"] if args.tiny else []
    quick = short + bare + ["--no-converge"] if args.tiny else []
    old = str(args.old_venv / "bin" / "tendon-taichi")
    new = [sys.executable, "-m", "tendon_taichi"]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = args.out or Path(tmp)
        for level in args.levels:
            runs = []
            for k in range(args.repeat):
                tag = f"r{level}" if k == 0 else f"r{level}-{k + 1}"
                run = work / f"old-{tag}.rrd"
                # the old commit's flag (--level came later; --resolution stays its alias)
                t_opt = timed([old, "optimize", args.scene, "--resolution", str(level), "--record", str(run),
                               "--quiet"] + short)
                t_cmp = timed([old, "compare", str(run), "--no-record"] + bare)
                t_new = timed(new + ["design", args.scene, "--level", str(level), "--out",
                                     str(work / f"design-{tag}"), "--quiet", "--no-png"] + quick)
                runs.append({"old_optimize_s": t_opt, "old_compare_s": t_cmp, "old_s": t_opt + t_cmp,
                             "design_s": t_new, "speedup": (t_opt + t_cmp) / t_new})
            rows.append(summarized(level, runs))
            print(line(rows[-1]), flush=True)
    if args.json:
        args.json.write_text(json.dumps({"scene": args.scene, "old_venv": str(args.old_venv), "levels": rows},
                                        indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
