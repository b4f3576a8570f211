"""The commands that run many cases: ``bench``, ``planted``, ``planted-bench``
and ``sweep``, and the Dask flags they share."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ..errors import InputError
from ..files import check_folder, file_stem
from .common import SOLVER_CHOICES, add_json, add_level_flag, json_out
from .runs import add_optimize_flags, optimize_overrides
from .tendons import (add_consolidation_flags, add_front_flags, add_tendon_flags, consolidation, front_settings,
                      tendon_settings)


# ------------------------------------------------------------------ bench
def cmd_bench(args) -> int:
    from ..apps.bench import BenchSettings, run_bench, table
    from ..tasks.engine import Cluster
    from ..body.scene import load_scene

    scene = load_scene(args.scene)
    if args.repeat < 1:
        raise InputError(f"--repeat must be >= 1 (got {args.repeat})")
    if args.forward_max_fibers < 0:
        raise InputError(f"--forward-max-fibers must be >= 0 (got {args.forward_max_fibers})")
    optimize_levels = [] if args.no_optimize else args.optimize_levels
    workers, scheduler = cluster_args(args)
    workers = 0 if workers is None and scheduler is None else workers
    settings = BenchSettings(tuple(args.level), tuple(args.solver), args.repeat,
                             None if optimize_levels is None else tuple(optimize_levels), args.forward_max_fibers,
                             optimize_solver=args.optimize_solver)
    result = run_bench(scene, settings, args.out, Cluster(workers, scheduler))
    json_out(args, result)
    if args.json != "-":
        print("\n".join(table(result)))
        ex = result["exponents"]
        for s, d in sorted(ex.items()):
            print(f"exponents {s}: " + ", ".join(f"{k[:-2]} {v:.2f}" for k, v in d.items()))
        print(f"compile {result['compile_s']:.1f} s; machine: {result['machine']['cores']} cores, "
              f"{result['machine']['cpu']}; outputs in {args.out}/ (bench.json, bench.csv, bench.png)")
    return 0


# ------------------------------------------------------------------ planted
def cmd_planted(args) -> int:
    from ..planted.plant import MAX_TENDONS, plant, write_planted
    from ..planted.walk import PlantSettings
    from ..body.scene import load_scene

    t0 = time.perf_counter()
    if not 1 <= args.tendons <= MAX_TENDONS:
        raise InputError(f"--tendons must be 1..{MAX_TENDONS} (got {args.tendons})")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0 (got {args.seed})")
    scene = load_scene(args.scene)
    if not 1 <= args.poses <= 4:
        raise InputError(f"--poses must be 1..4 (got {args.poses})")
    text, layout = plant(scene, args.tendons, args.seed, args.level, poses=args.poses,
                         settings=PlantSettings(exit=args.exit))
    toml_path, json_path = write_planted(args.out, text, layout)
    pose = layout["pose"]
    summary = {"name": layout["name"], "scene": layout["scene"], "tendons": args.tendons,
               "seed": args.seed, "level": args.level, "scene_file": str(toml_path),
               "layout_file": str(json_path), "planted_length": layout["planted_length"],
               "lengths": [t["length"] for t in layout["tendons"]],
               "contraction_ratios": [t["contraction_ratio"] for t in layout["tendons"]],
               "tensions": [t["tension"] for t in layout["tendons"]],
               "max_target_displacement": pose["max_target_displacement"],
               "max_target_displacement_rel": pose["max_target_displacement_rel"],
               "body_size": pose["body_size"], "draws": layout["draws"], "poses": args.poses,
               "time_s": time.perf_counter() - t0}
    json_out(args, summary)
    if args.json != "-":
        print(f"{layout['name']}: {args.tendons} tendon{'s' if args.tendons > 1 else ''}, "
              f"{100 * layout['planted_length']:.1f} cm planted, largest target displacement "
              f"{100 * pose['max_target_displacement_rel']:.2f} % of L ({layout['draws']} draw"
              f"{'s' if layout['draws'] > 1 else ''}); wrote {toml_path} and {json_path}")
    return 0


# ------------------------------------------------------------------ planted-bench
def cmd_planted_bench(args) -> int:
    from ..extract.settings import FrontSettings
    from ..planted.bench import SuiteSettings, run_suite, table
    from ..tasks.engine import Cluster

    overrides = optimize_overrides(args)
    workers, scheduler = cluster_args(args)
    levels = args.levels or args.level  # checked by main (levels_given)
    suite = _suite(args)
    settings = SuiteSettings(cases=args.cases, overrides=overrides, tendons=tendon_settings(args), solver=args.solver,
                             extractors=args.extractors, consolidation=consolidation(args),
                             front=FrontSettings(**front_settings(args)))
    kwargs = dict(settings=settings, cluster=Cluster(workers, scheduler))
    if args.levels or len(set(levels)) > 1:
        from ..planted.levels import run_levels
        from ..planted.levels import table as levels_table

        result = run_levels(suite, sorted(set(levels)), args.out,
                            coarse_to_fine=not args.independent_levels, **kwargs)
        json_out(args, result)
        if args.json != "-":
            print("\n".join(levels_table(result)))
            print(f"outputs in {args.out}/ (levels.json, fronts.png, level<N>/)")
        return 0
    result = run_suite(suite, levels[0], args.out, **kwargs)
    json_out(args, result)
    if args.json != "-":
        print("\n".join(table(result)))
        print(f"outputs in {args.out}/ (planted_bench.json, planted_bench.csv, gallery.png)")
    return 0


def _suite(args) -> Path:
    """The suite planted-bench runs: the folder given (default benchmarks/planted),
    or with ``--generated N`` that many generated cases from ``--seed``, written
    into OUT/generated/ first."""
    if args.generated is None:
        return Path(args.suite or "benchmarks/planted")
    if args.suite is not None:
        raise InputError("give a suite folder or --generated N, not both")
    if not 1 <= args.generated <= MAX_GENERATED:
        raise InputError(f"--generated must be 1..{MAX_GENERATED} (got {args.generated})")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0 (got {args.seed})")
    from ..planted.shapes import generate_suite

    folder = Path(args.out) / "generated"
    check_folder(folder, "output")
    return generate_suite(args.generated, args.seed, folder, say=lambda text: print(text, file=sys.stderr, flush=True))


#: the most cases ``planted-bench --generated`` draws
MAX_GENERATED = 1000


# ------------------------------------------------------------------ sweep
def add_cluster_flags(p: argparse.ArgumentParser, default_workers: str) -> None:
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help=f"worker processes of the local Dask cluster ({default_workers}; 0: run the cases "
                        f"one after the other in this process)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on an existing Dask cluster (tcp://HOST:PORT of a `dask scheduler`); "
                        "it is left running")


def cluster_args(args) -> tuple[int | None, str | None]:
    if args.workers is not None and args.workers < 0:
        raise InputError(f"--workers must be >= 0 (got {args.workers})")
    if args.scheduler is not None:
        from ..tasks.engine import check_address
        check_address(args.scheduler)
    return args.workers, args.scheduler


def cmd_sweep(args) -> int:
    from ..apps.sweep import load_sweep, run, table

    workers, scheduler = cluster_args(args)
    sweep = load_sweep(args.sweep, tendon_settings(args))
    out = args.out or str(Path("recordings") / "sweeps" / file_stem(sweep.name))
    result = run(sweep, out, workers, scheduler)
    json_out(args, result)
    if args.json != "-":
        print("\n".join(table(result)))
        print(f"outputs in {out}/ (sweep.json, sweep.csv, sweep.png, cases/)")
    return 4 if result["failed"] else 0


# ------------------------------------------------------------------ the parsers
def add_commands(sub) -> None:
    s = sub.add_parser("bench", help="headless resolution-scaling benchmark (JSON, CSV, PNG)")
    s.add_argument("scene", metavar="SCENE", nargs="?", default="t_shape", help="default t_shape")
    add_level_flag(s, [1, 2, 3], "the levels to measure (default 1 2 3)", many=True, aliases=("--levels",))
    s.add_argument("--solver", nargs="+", choices=SOLVER_CHOICES, default=["cg", "direct"])
    s.add_argument("--repeat", type=int, default=3, metavar="N", help="runs per timing (default 3)")
    s.add_argument("--out", default="recordings/bench", metavar="DIR")
    s.add_argument("--optimize-levels", type=int, nargs="+", default=None, metavar="N",
                   help="levels at which to run the whole optimization (default: all)")
    s.add_argument("--no-optimize", action="store_true", help="skip the whole optimizations")
    s.add_argument("--optimize-solver", choices=("each", "auto"), default="each",
                   help="run the whole optimization with each solver (default), or once per level "
                        "with the one --solver auto picks there")
    s.add_argument("--forward-max-fibers", type=int, default=2500, metavar="N",
                   help="time forward sensitivities only up to this many fibers (one solve each)")
    add_cluster_flags(s, "for the whole optimizations; default: run them in this process, after the other "
                          "measurements")
    add_json(s)
    s.set_defaults(func=cmd_bench)

    s = sub.add_parser("planted", help="a scene whose goals random planted tendons reach (a benchmark "
                                       "with a known answer)")
    s.add_argument("scene", metavar="SCENE", help="built-in scene name or scene TOML file")
    s.add_argument("--tendons", type=int, default=2, metavar="N", help="number of tendons, 1..5 (default 2)")
    s.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default 0)")
    add_level_flag(s, 2, "resolution level of the planted equilibrium (default 2)")
    s.add_argument("--poses", type=int, default=1, metavar="P",
                   help="target poses made by the same tendons, 1..4 (default 1)")
    s.add_argument("--exit", default="clamp", choices=("clamp", "surface", "inside"),
                   help="where the planted tendons leave the body, written into the scene as its [tendons] "
                        "exit (default: clamp, behind the clamped base; inside: their pull ends float inside "
                        "the body, as in the suite drawn before exits)")
    s.add_argument("--out", default=".", metavar="DIR",
                   help="writes DIR/<scene>_planted_<N>t_s<S>[_<P>p].toml and .json (default: .)")
    add_json(s)
    s.set_defaults(func=cmd_planted)

    s = sub.add_parser("planted-bench", help="the design pipeline on a suite of planted layouts, scored "
                                             "against what was planted")
    s.add_argument("suite", metavar="DIR", nargs="?", default=None,
                   help="folder of planted cases, NAME.toml + NAME.json (default benchmarks/planted)")
    s.add_argument("--generated", type=int, default=None, metavar="N",
                   help="instead of a folder, N generated cases (random bodies nobody tuned for, planted; "
                        "written into OUT/generated/ first)")
    s.add_argument("--seed", type=int, default=0, metavar="S",
                   help="with --generated, the first case's seed (default 0): cases S .. S + N - 1")
    level = s.add_mutually_exclusive_group()
    add_level_flag(level, [2], "resolution level (default 2); several levels run at each (into DIR/level<N>/) "
                               "and compare: per case the front of every level and whether the recommended "
                               "count is the same", many=True)
    level.add_argument("--levels", type=int, nargs="+", metavar="N",
                       help="as --level, and the comparison's folders (DIR/level<N>/, levels.json) even for one "
                            "level")
    s.add_argument("--independent-levels", action="store_true",
                   help="with several levels, search each level on its own (default: each level also searches from "
                        "the coarser level's designs, as design --routes-from does)")
    s.add_argument("--out", default="recordings/planted", metavar="DIR")
    s.add_argument("--cases", nargs="+", metavar="NAME", help="run only these cases")
    s.add_argument("--extractors", nargs="+", metavar="NAME", help="default: every installed one")
    s.add_argument("--solver", choices=SOLVER_CHOICES, default="auto")
    add_optimize_flags(s)
    add_consolidation_flags(s)
    add_front_flags(s)
    add_tendon_flags(s)
    add_cluster_flags(s, "default: one per core")
    add_json(s)
    s.set_defaults(func=cmd_planted_bench)

    s = sub.add_parser("sweep", help="many design cases (scenes x levels x a grid of settings) as tasks on Dask")
    s.add_argument("sweep", metavar="SWEEP.toml", help="sweep file (docs/cli.md)")
    s.add_argument("--out", default=None, metavar="DIR", help="default recordings/sweeps/<name>")
    add_tendon_flags(s)
    add_cluster_flags(s, "default: one per core")
    add_json(s)
    s.set_defaults(func=cmd_sweep)
