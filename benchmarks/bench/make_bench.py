"""Regenerate the checked-in benchmark results: this folder's bench.json, bench.csv,
bench.png and table.txt, and the performance page docs/performance.md.

Usage: python benchmarks/bench/make_bench.py [--levels 1 2 3 4 5 6] [--repeat 3] [--out DIR]
       [--page FILE] [--optimize-levels N ... | --no-optimize] [--alone N | --alone]
       python benchmarks/bench/make_bench.py --page-only [--out DIR] [--page FILE]

Runs the resolution-scaling benchmark on t_shape with the linear backends cg,
cg-amg, cg-gmg and direct, and the whole design pipeline with the backend ``--solver
auto`` picks at each level
(``tendon-taichi bench t_shape --levels ... --solver cg cg-amg cg-gmg direct --repeat N
--optimize-solver auto --out DIR``; ``--optimize-levels`` runs the whole
optimization at those levels only), then writes DIR/table.txt and the page
(the table, the fitted exponents, the plot, the optimization's quality per
level, the machine and the commit that made it; the design pipeline's own
folders go to a temporary folder, removed at the end); then the whole
optimization at level ``--alone`` (5; none with a bare ``--alone``) in a process
of its own (``tendon-taichi optimize t_shape --level N --quiet --json``):
its wall time and peak resident memory, into bench.json and the page.
``--page-only`` writes table.txt and the page again from DIR/bench.json without
measuring. Defaults: levels 1-6 (the whole design pipeline at 1-3: at 4 and 5 it
takes most of an hour more), 3 repeats, this folder and docs/performance.md; the
run takes about ten minutes on 2 cores (8 min at 0650ba5), plus the level run
alone (about 2 min at level 5).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tendon_taichi import load_scene
from tendon_taichi.apps.bench import BenchSettings, run_bench, table
from tendon_taichi.files import write_json
from tendon_taichi.solve.pardiso import PARALLEL_MIN

HERE = Path(__file__).resolve().parent
PAGE = HERE.parent.parent / "docs" / "performance.md"

INTRO = """# Performance

How cost and quality scale with the mesh resolution on the built-in `t_shape`,
measured by `tendon-taichi bench` (see `docs/cli.md`). This page and the files
in `benchmarks/bench/` are written by `python benchmarks/bench/make_bench.py`;
do not edit them by hand.

Per level and linear backend (`cg`, `cg-amg`, `cg-gmg` and `direct`, see the linear backends in
`docs/method.md`), in seconds (medians of the repeats, compiling the
Taichi kernels excluded): `eq cold`, one equilibrium from rest; `eq warm`, one
from the equilibrium of a design whose contraction ratios differ by +-0.5 %;
`Newton` and `CG it`, iterations cold/warm; `adjoint`, one adjoint solve;
`gradient`, one warm equilibrium plus the adjoint; `numpy x`, how many times
faster that gradient is than the same gradient by a plain numpy/scipy
implementation (`tendon_taichi/apps/baseline.py`: the energy, its gradient and
exact Hessian vectorized in numpy, Newton with SuperLU, the adjoint), timed in
the same run; `forward`, the same gradient
by one solve per fiber (where that finishes in reasonable time); `optimize`, the
whole regularized optimization with the backend `--solver auto` picks at that
size; `mem MB`, the process's peak resident memory. Exponents are least-squares
slopes of log(time) against log(DOFs) over the levels from the second on. Where
`eq warm`'s time goes, part by part (the factorizations, their solves, the
assembly), and why `direct`'s grows faster than the DOFs: "Where a warm
equilibrium's time goes" in [method.md](method.md) (`benchmarks/warm_parts.py`).

Two more scripts time what `bench` does not: `benchmarks/simulate_levels.py`, one equilibrium of
`simulate t_shape --uniform 0.1` per level and backend after a warm-up, and the first solve of a
process, which compiles the kernels; `benchmarks/bench/versus_commit.py`, `design` of this
checkout against `optimize` and `compare` of an earlier commit installed in a virtual environment
of its own, level by level.
"""


def quality_table(result: dict) -> list[str]:
    """Per level: the whole optimization and each extractor's tendons (count /
    realizable pose error in % of L / kinks)."""
    names = sorted({n for lv in result["levels"] for f in lv["solvers"].values() for n in f.get("extractors", {})})
    rows = ["| level | optimize | design | recording | pose error | active length | " + " | ".join(names) + " |",
            "|---|---|---|---|---|---|" + "---|" * len(names)]
    for lv in result["levels"]:
        for solver, f in lv["solvers"].items():
            if "optimize_s" not in f:
                continue
            cells = []
            for n in names:
                e = f["extractors"].get(n, {})
                cells.append("failed" if "error" in e else
                             f"{e['tendons']} / {100 * e['realizable_pose_error_rel']:.2f} / {e['kinks']}")
            design = f"{f['design_s']:.1f} s" if "design_s" in f else "-"
            size = f"{f['recording_mb']:.1f} MB" if "recording_mb" in f else "-"
            rows.append(f"| {lv['level']} | {f['optimize_s']['median']:.1f} s ({solver}) | {design} | {size} | "
                        f"{100 * f['pose_error_rel']:.2f} % | {100 * f['active_length']:.1f} cm | "
                        + " | ".join(cells) + " |")
    return rows


def _high_water_mb(pid: int) -> float | None:
    """A process's peak resident memory so far (Linux: VmHWM of /proc/PID/status), MB."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except (OSError, ValueError):
        pass
    return None


def optimize_alone(level: int) -> dict:
    """The whole optimization of t_shape at ``level`` in a process of its own: its
    wall time (s), its peak resident memory (MB; read from /proc while it runs:
    the rusage of a child counts the memory of the process that forked it), and
    its summary's evaluations and own time."""
    cmd = [sys.executable, "-m", "tendon_taichi", "optimize", "t_shape", "--level", str(level),
           "--quiet", "--json"]
    with tempfile.TemporaryFile() as out:
        t = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out)
        peak = None
        while proc.poll() is None:
            peak = _high_water_mb(proc.pid) or peak
            time.sleep(0.2)
        wall = time.perf_counter() - t
        if proc.returncode:
            raise SystemExit(f"make_bench: {' '.join(cmd[1:])} failed (exit status {proc.returncode})")
        out.seek(0)
        summary = json.loads(out.read())
    return {"level": level, "command": "tendon-taichi " + " ".join(cmd[3:]), "wall_s": wall,
            "peak_mb": peak, "evaluations": summary["evaluations"], "time_s": summary["time_s"]}


def alone_line(alone: dict) -> str:
    peak = "-" if alone["peak_mb"] is None else f"{alone['peak_mb']:.0f} MB"
    return (f"The whole optimization at level {alone['level']} in a process of its own (`{alone['command']}`): "
            f"{alone['wall_s']:.1f} s wall ({alone['evaluations']} evaluations), peak resident memory {peak}.")


def _loops(machine: dict) -> str:
    """How the Taichi loops ran, as the machine line says it (nothing for a bench made
    before the threshold was recorded)."""
    if "parallel_threshold" not in machine:
        return ""
    t = machine["parallel_threshold"]
    return ", every Taichi loop serialized" if t is None else f", Taichi loops in parallel from {t} elements + segments"


def page(result: dict, lines: list[str], plot: str) -> str:
    m, p = result["machine"], result["provenance"]
    exps = [f"exponents {s}: " + ", ".join(f"{k[:-2]} {v:.2f}" for k, v in d.items())
            for s, d in sorted(result["exponents"].items())]
    alone = [alone_line(result["alone"]), ""] if result.get("alone") else []
    return "\n".join([
        INTRO,
        f"Measured on {m['cores']} cores ({m['cpu']}, Taichi {m['arch']}, Python {m['python']}"
        + (f", PARDISO's factorizations of {PARALLEL_MIN} DOFs or more on {m['factor_threads']} thread(s)"
           if m.get("pardiso_threaded", m.get("pardiso")) else "")
        + _loops(m) + "), "
        f"{result['repeat']} repeat(s), at commit `{p['commit']}`{' (with uncommitted changes)' if p['dirty'] else ''} "
        f"on {p['date']}, by `{p['made_by']}`.",
        "", "```text", *lines, *exps, f"compile {result['compile_s']:.1f} s", "```", "",
        f"![bench]({plot})", "",
        "The whole design pipeline per level (`optimize`, its regularized optimization; `design`, all of it -",
        "the optimization, every extractor with consolidation and route optimization, the front re-solved",
        "on the next finer mesh - in one process, with no worker processes: `tendon-taichi design` shares",
        "the consolidations and the front's search with worker processes by default (`--workers`), which",
        "takes less wall time where cores are spare; `recording`, the size of its `run.rrd`; extractor",
        "columns: tendons / realizable pose error in % of L / kinks):",
        "", *quality_table(result), "", *alone])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--page", type=Path, default=PAGE)
    ap.add_argument("--optimize-levels", type=int, nargs="+", default=[1, 2, 3], metavar="N")
    ap.add_argument("--no-optimize", action="store_true")
    ap.add_argument("--alone", type=int, nargs="?", const=None, default=5, metavar="N",
                    help="the level whose whole optimization runs in a process of its own (bare: none)")
    ap.add_argument("--page-only", action="store_true", help="write table.txt and the page from DIR/bench.json")
    args = ap.parse_args(argv)
    if args.page_only:
        result = json.loads((args.out / "bench.json").read_text())
    else:
        with tempfile.TemporaryDirectory() as cases:  # the design folders are not results to check in
            settings = BenchSettings(tuple(args.levels), ("cg", "cg-amg", "cg-gmg", "direct"), args.repeat,
                                     () if args.no_optimize else args.optimize_levels, optimize_solver="auto")
            result = run_bench(load_scene("t_shape"), settings, args.out, cases_dir=cases)
        if args.alone is not None:
            print(f"optimize t_shape at level {args.alone} in a process of its own ...", file=sys.stderr)
            result["alone"] = optimize_alone(args.alone)
            write_json(result, args.out / "bench.json")
    lines = table(result)
    (args.out / "table.txt").write_text("\n".join(lines) + "\n")
    plot = os.path.relpath(args.out / "bench.png", args.page.parent)
    args.page.parent.mkdir(parents=True, exist_ok=True)
    args.page.write_text(page(result, lines, plot))
    made = "table.txt" if args.page_only else "bench.json, bench.csv, bench.png, table.txt"
    print(f"wrote {args.out}/ ({made}) and {args.page}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
