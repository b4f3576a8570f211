"""Regenerate the checked-in planted-suite results in this folder.

Usage: python benchmarks/planted_results/make_results.py [--levels 1 2 3] [--out DIR] [--runs DIR]
       [--workers N] [--cases NAME ...] [--set KEY=VALUE ...] [--beam B] [--no-converge]
       [--independent-levels] [--generated N [--seed S]]

For each level, from the coarsest up, runs `tendon-taichi planted-bench
benchmarks/planted --level LEVEL --out RUNS/rLEVEL` (default settings, or
the [optimize] settings given by --set and the front's --beam and
--no-converge; finished cases in RUNS are reused), each level after the first
also searching from the level before's designs, as `planted-bench --levels`
does (not with --independent-levels); then writes into DIR (default: this
folder) planted_bench_level<LEVEL>.csv, gallery_level<LEVEL>.png,
counts_by_level.md (benchmarks/planted/counts_by_level.py's table),
worst_cases.png (the three worst results over every level run), fronts.png
(per case the front of every level) and README.md, the results page: per
level the suite's figures, per case its figures at every level, the levels
compared as `planted-bench --levels` compares them, and the commit that made
them. The default run (levels 1-3, 16 cases) takes about an hour on 2 cores.
With ``--generated N`` the suite is N generated cases from seed S (default 0;
``planted-bench --generated``: bodies nobody tuned for), written into
RUNS/generated/ first (kept there: a later run with the same N and S reuses
them) and copied into DIR/cases/; benchmarks/generated_results/ holds
``--generated 60 --levels 1 2 --out benchmarks/generated_results``.
"""

import argparse
import shutil
import statistics
import sys
import tomllib
from pathlib import Path

from tendon_taichi.cli.tendons import add_front_flags, front_settings
from tendon_taichi.extract.settings import FrontSettings
from tendon_taichi.planted.bench import SuiteSettings, load_suite, route_rule, run_suite
from tendon_taichi.planted.gallery import gallery_figure
from tendon_taichi.planted.levels import compare_levels, fronts_figure, prior_designs
from tendon_taichi.planted.levels import table as levels_table
from tendon_taichi.planted.shapes import generate_suite
from tendon_taichi.tasks.engine import Cluster
from tendon_taichi.version import provenance

HERE = Path(__file__).resolve().parent
SUITE = HERE.parent / "planted"
sys.path.insert(0, str(SUITE))
import counts_by_level  # noqa: E402  (a script beside the suite)

INTRO = """# {title}

`tendon-taichi planted-bench` (see `docs/cli.md`) on {suite} with the default settings - the `design` pipeline:
optimize, every extractor, consolidation and route optimization on the
as-built robot (capstan friction mu = 0.1, clearance 2 % of L), the
recommended design - at each resolution level. Everything in this folder is
written by `python benchmarks/planted_results/make_results.py`; do not edit it
by hand. A case passes when the recommended design has at most planted + 1
tendons, its as-built robot reaches the goals within 1 % of L and the active
length is at most twice the planted one; it meets the route rule when it has
no more kinks than the planted tendons and - where it has at least as many
tendons as were planted - its worst capstan factor is at least theirs minus
0.05 (same mu). Per case: `planted_bench_level<N>.csv`;
the galleries `gallery_level<N>.png` (planted tendons dashed, the design's
routes in colour, anchor a circle, pull end a square); the count at every
level: `counts_by_level.md`; the three worst results over every level (misses
first, then route-rule misses, then the highest as-built error):
`worst_cases.png`.
"""


def _median(cases, key):
    vals = [c[key] for c in cases if c.get(key) is not None]
    return statistics.median(vals) if vals else float("nan")


def summary(runs: list[dict]) -> list[str]:
    rows = ["| level | passed | count <= planted + 1 | as built within 1 % of L | route rule | "
            "median worst capstan (planted) | kinks (planted) | median as-built error | suite time |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in runs:
        done = [c for c in r["cases"] if "error" not in c]
        t = r["totals"]
        rows.append(f"| {r['level']} | {t['passed']} of {t['cases']} | {t['count_within_planted_plus_one']} | "
                    f"{t['within_one_percent']} | {t['route_rule']} | {_median(done, 'capstan_worst'):.2f} "
                    f"({_median(done, 'planted_capstan_worst'):.2f}) | {t['kinks']} ({t['planted_kinks']}) | "
                    f"{100 * _median(done, 'realizable_pose_error_rel'):.2f} % | {t['time_s']:.0f} s |")
    return rows


def per_case(runs: list[dict]) -> list[str]:
    """Per case and level: tendons designed / planted (where from), as-built pose
    error, worst capstan against the planted tendons', kinks, pass."""
    levels = [r["level"] for r in runs]
    by = [{c["case"]: c for c in r["cases"]} for r in runs]
    rows = ["| case | " + " | ".join(f"level {lv}" for lv in levels) + " |", "|---|" + "---|" * len(levels)]
    for name in sorted(set().union(*by)):
        cells = []
        for b in by:
            c = b.get(name)
            if c is None or "error" in c:
                cells.append("-" if c is None else "failed")
                continue
            rule = route_rule(c)
            cells.append(f"{c['count']}/{c['planted_count']} {c['best']}, {100 * c['realizable_pose_error_rel']:.2f} %, "
                         f"capstan {c['capstan_worst']:.2f}/{c['planted_capstan_worst']:.2f}, {c['kinks']} kinks"
                         f"{'' if c['passed'] else ' **miss**'}{'' if rule else ' **route rule**'}")
        rows.append(f"| {name} | " + " | ".join(cells) + " |")
    return rows


def worst(runs: list[dict], n: int = 3) -> list[tuple[int, dict]]:
    """The ``n`` worst (level, case) results over every run: misses first, then
    route-rule misses, then the highest as-built error."""
    done = [(r["level"], c) for r in runs for c in r["cases"] if "error" not in c]
    return sorted(done, key=lambda lc: (lc[1]["passed"], route_rule(lc[1]), -lc[1]["realizable_pose_error_rel"]))[:n]


def worst_figure(runs: list[dict], path: Path, suite: Path) -> None:
    """The gallery's panels (planted dashed, the design's routes in colour) of the
    worst results of ``suite``, each titled with its level."""
    chosen = worst(runs)
    fig = gallery_figure({"cases": [c for _, c in chosen]}, {c.name: c for c in load_suite(suite)})
    for ax, (level, _) in zip(fig.axes, chosen):
        ax.set_title(f"level {level}: {ax.get_title()}", fontsize=7)
    fig.suptitle("the worst results over every level: planted (dashed) vs designed (colour)", fontsize=10)
    fig.savefig(path, dpi=110)


def page(runs: list[dict], levels: dict, generated: tuple[int, int] | None = None) -> str:
    """The results page; ``generated``: (N, S) where the suite was N generated cases from seed S."""
    p = runs[0].get("provenance") or provenance()
    settings = runs[0]["settings"] or "the defaults"
    intro = INTRO.format(title="Planted-suite results", suite="the suite in\n`benchmarks/planted`")
    if generated is not None:
        intro = INTRO.format(title="Results on generated scenes", suite=(
            f"{generated[0]} generated cases\n(`--generated {generated[0]} --seed {generated[1]}`: random bodies nobody "
            "tuned for, `docs/method.md`, generated scenes)"))
    return "\n".join([
        intro,
        f"Made at commit `{p['commit']}`{' (with uncommitted changes)' if p['dirty'] else ''} on {p['date']}, "
        f"settings: {settings}, consolidation: {runs[0]['consolidation']}.", "",
        *summary(runs), "", "## Per case", "",
        "Tendons designed / planted (the extractor they came from), as-built pose error (% of L), worst capstan "
        "factor / the planted tendons', kinks.", "",
        *per_case(runs), "", "## The worst results", "",
        "Misses first, then route-rule misses, then the highest as-built error: "
        + ", ".join(f"{c['case']} at level {lv}" for lv, c in worst(runs)) + ".", "",
        "![the worst results](worst_cases.png)", "",
        "## The count across levels", "", *counts_by_level.table(runs), "",
        "## The front across levels", "",
        "Per case, the recommended count at each level and whether the front's mesh-converged errors agree "
        "across the levels (up to planted + 1 tendons, within 0.1 % of L or 25 %, or the planted tendons' own "
        "spread plus 0.05 % of L where that is wider; `docs/cli.md`, planted-bench, several levels); "
        + ("each level after the first also searched from the level before's designs." if levels["coarse_to_fine"]
           else "each level searched on its own."), "",
        "```text", *levels_table(levels), "```", "", "![the fronts](fronts.png)", ""])


def _setting(item: str):
    key, _, value = item.partition("=")
    try:
        return key, tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError:
        raise SystemExit(f"--set {item}: the value must be a TOML value")


def suite_folder(args) -> Path:
    """The suite to run: benchmarks/planted, or with ``--generated N`` that many
    generated cases from ``--seed``, written into RUNS/generated/ - unless that
    folder already holds exactly those cases (one scene per seed: drawing a body
    takes up to minutes; delete the folder to draw them again)."""
    if args.generated is None:
        return SUITE
    folder = args.runs / "generated"
    seeds = {f"gen{s:03d}" for s in range(args.seed, args.seed + args.generated)}
    held = [f.name.split("_")[0] for f in folder.glob("gen*.toml")] if folder.is_dir() else []
    if sorted(held) == sorted(seeds):
        print(f"the {args.generated} generated cases in {folder}", file=sys.stderr, flush=True)
        return folder
    return generate_suite(args.generated, args.seed, folder,
                          say=lambda text: print(text, file=sys.stderr, flush=True))


def copy_cases(suite: Path, out: Path) -> None:
    """The generated ``suite``'s scenes and planted layouts (NAME.toml, NAME.json)
    copied into OUT/cases/ (the results are then read beside what they were run on)."""
    (out / "cases").mkdir(parents=True, exist_ok=True)
    for f in sorted(suite.glob("gen*.*")):
        shutil.copyfile(f, out / "cases" / f.name)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--runs", type=Path, default=Path("recordings/planted_results"))
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--cases", nargs="+")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="an [optimize] setting")
    add_front_flags(ap)
    ap.add_argument("--independent-levels", action="store_true",
                    help="search each level on its own (default: from the level before's designs too)")
    ap.add_argument("--generated", type=int, default=None, metavar="N", help="N generated cases instead of the suite")
    ap.add_argument("--seed", type=int, default=0, metavar="S", help="with --generated, the first case's seed")
    args = ap.parse_args(argv)
    suite = suite_folder(args)
    front = front_settings(args)
    if args.independent_levels:
        front["coarse"] = False  # each level on its own: no case designs its coarser level either
    overrides = dict(_setting(s) for s in args.set)
    runs = []
    levels = sorted(set(args.levels))
    for level, before in zip(levels, [None] + levels[:-1]):
        run_dir = args.runs / f"r{level}"
        coarser = not args.independent_levels and before is not None
        priors = prior_designs(suite, args.runs / f"r{before}", before) if coarser else None
        settings = SuiteSettings(cases=args.cases, overrides=overrides, front=FrontSettings(**front), priors=priors)
        runs.append(run_suite(suite, level, run_dir, settings, Cluster(workers=args.workers)))
        args.out.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(run_dir / "planted_bench.csv", args.out / f"planted_bench_level{level}.csv")
        shutil.copyfile(run_dir / "gallery.png", args.out / f"gallery_level{level}.png")
    (args.out / "counts_by_level.md").write_text("\n".join(counts_by_level.table(runs)) + "\n")
    worst_figure(runs, args.out / "worst_cases.png", suite)
    compared = {**compare_levels({r["level"]: r for r in runs}), "coarse_to_fine": not args.independent_levels}
    fronts_figure(compared).savefig(args.out / "fronts.png", dpi=90)
    generated = None if args.generated is None else (args.generated, args.seed)
    if generated is not None:
        copy_cases(suite, args.out)
    (args.out / "README.md").write_text(page(runs, compared, generated))
    print(f"wrote {args.out}/", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
