"""The ``tendon-taichi`` command line (DESIGN.md section 6).

Results go to stdout (``--json`` for machines, to stdout or a file), progress
and warnings to stderr. Bad input gives one ``tendon-taichi: error: ...`` line
and exit status 2; an unexpected failure one ``internal error`` line and 1
(``--debug`` shows the traceback); Ctrl-C exits 130.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from .errors import InputError, Stopped, TendonError

PROG = "tendon-taichi"
SOLVER_CHOICES = ("auto", "cg", "cg-jacobi", "direct")


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line."""

    def error(self, message: str):
        raise InputError(f"{message} (see '{self.prog} --help')")


def _json_out(args, data: dict) -> None:
    """Print JSON to stdout (``--json``) or write it to a file (``--json FILE``)."""
    if args.json is None:
        return
    if args.json == "-":
        print(json.dumps(data, indent=2))
    else:
        from .export import write_json
        write_json(data, args.json)


def _add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", nargs="?", const="-", metavar="FILE",
                   help="machine-readable summary on stdout, or into FILE")


# ------------------------------------------------------------------ scenes
def cmd_scenes(args) -> int:
    from .scene import builtin_scenes, load_scene

    rows = []
    for name in builtin_scenes():
        sc = load_scene(name)
        head = []
        for line in sc.source.lstrip().splitlines():
            if not line.startswith("#"):
                break
            head.append(line.lstrip("# ").strip())
        desc = " ".join(head)
        rows.append({"name": name, "description": desc, "targets": len(sc.targets),
                     "holes": len(sc.body.holes)})
    if args.json is not None:
        _json_out(args, {"scenes": rows})
        if args.json != "-":
            print(f"wrote {args.json}")
        return 0
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        print(f"{r['name']:<{width}}  {r['description']}")
    return 0


# ------------------------------------------------------------------ simulate
def _read_ratios(path: str) -> np.ndarray:
    try:
        r = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError(f"contraction file '{path}' does not exist") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read contraction file '{path}' (expected a .npy array): {exc}") from None
    if not isinstance(r, np.ndarray) or r.dtype.kind not in "fiu":
        raise InputError(f"contraction file '{path}' must hold a numeric .npy array")
    return r.astype(float).ravel()


def cmd_simulate(args) -> int:
    from .export import write_export, write_vtu
    from .problem import build_problem
    from .scene import load_scene
    from .simulation import contraction_ratios
    from .model import Model
    from .solvers import NewtonSolver

    t0 = time.perf_counter()
    scene = load_scene(args.scene)
    problem = build_problem(scene, args.resolution)
    ratios = contraction_ratios(problem, args.uniform if args.contract is None
                                else _read_ratios(args.contract))
    export = Path(args.export or f"recordings/{scene.name}-r{problem.level}-simulate.npz")
    counts = problem.counts()
    print(f"{scene.name} level {problem.level}: {counts['nodes']} nodes, {counts['triangles']} "
          f"triangles, {counts['fibers']} fibers, {counts['dofs']} DOFs; solving ({args.solver})...",
          file=sys.stderr)
    model = Model.from_problem(problem)
    newton = NewtonSolver(model, args.solver)
    args.solver = newton.linear.name
    ac = ratios * problem.fibers.a0
    eq = newton.solve(ac=ac)
    write_export(export, problem, eq.x, ac, eq.tau)
    if args.vtu:
        write_vtu(args.vtu, problem, eq.x, eq.tau)
    L = problem.size
    pos = problem.target_positions(eq.x)
    err = np.linalg.norm(pos - problem.target_goal, axis=1)
    disp = np.linalg.norm(eq.x - problem.mesh.nodes, axis=1)
    from . import runtime
    summary = {
        "scene": scene.name, "resolution": problem.level, **counts, "body_size": L,
        "solver": args.solver, "arch": runtime.info()["arch"], "parallel": model.parallel,
        "newton_iterations": eq.newton_iterations, "linear_iterations": eq.linear_iterations,
        "projected_steps": eq.projected_steps, "residual": eq.residual, "energy": eq.energy,
        "max_displacement": float(disp.max()), "tau_max": float(eq.tau.max()),
        "active_fibers": int((eq.tau > 0).sum()),
        "targets": [{"point": list(t.point), "goal": list(t.goal), "position": pos[i].tolist(),
                     "error": float(err[i]), "pose": problem.pose_names[problem.target_pose[i]]}
                    for i, t in enumerate(scene.targets)],
        "pose_error": float(np.sqrt((err ** 2).sum())), "pose_error_rel": float(np.sqrt((err ** 2).sum()) / L),
        "solve_s": eq.time_s, "time_s": time.perf_counter() - t0,
        "export": str(export), "vtu": args.vtu,
    }
    _json_out(args, summary)
    if args.json == "-":
        return 0
    print(f"{scene.name} level {problem.level}: {counts['nodes']} nodes, {counts['triangles']} "
          f"triangles, {counts['fibers']} fibers, {counts['dofs']} DOFs")
    print(f"equilibrium: {eq.newton_iterations} Newton iterations"
          + (f", {eq.linear_iterations} CG iterations" if args.solver != "direct" else " (direct)")
          + f", relative residual {eq.residual:.1e}, {eq.time_s:.3f} s")
    print(f"max displacement {1e3 * disp.max():.2f} mm, max tension {eq.tau.max():.3f} N, "
          f"pose error {1e3 * summary['pose_error']:.2f} mm ({100 * summary['pose_error_rel']:.2f} % of L)")
    print(f"export: {export}" + (f"; vtu: {args.vtu}" if args.vtu else ""))
    return 0


# ------------------------------------------------------------------ optimize
#: command-line flags of the [optimize] settings: flag -> (key, type, help)
OPTIMIZE_FLAGS = {
    "--sparsity": ("sparsity", float, "L0 sparsity weight w_sp"),
    "--continuity": ("continuity", float, "directional continuity weight w_ct"),
    "--strand-end": ("strand_end", float, "strand-end weight w_end (tension imbalance at fiber nodes)"),
    "--effort": ("effort", float, "actuation-effort weight w_eff (tension x length, in every pose; "
                                  "against co-contraction)"),
    "--contraction-reg": ("contraction_reg", float, "contraction regularizer weight w_ac"),
    "--tension-scale": ("tension_scale", float, "tension scale tau_ref, N"),
    "--initial-contraction": ("initial_contraction", float, "uniform starting ratio r0"),
    "--active-threshold": ("active_threshold", float, "active if tau > this x tau_ref"),
    "--sparsity-measure": ("sparsity_measure", str, "length (default) or count"),
    "--continuity-measure": ("continuity_measure", str, "length (default) or count"),
    "--strand-end-measure": ("strand_end_measure", str, "tension (squared imbalance, default), count "
                                                        "(smooth L0: each end costs w_end) or linear "
                                                        "(the imbalance's magnitude)"),
    "--stage-iterations": ("stage_iterations", int, "L-BFGS-B iteration cap per stage"),
    "--settle-tol": ("settle_tol", float, "a stage ends when the objective fell by less than this x its "
                                          "start value over the settle window"),
    "--settle-window": ("settle_window", int, "iterations over which a stage must have settled"),
    "--k0": ("k0", float, "first homotopy k, N"),
    "--k-factor": ("factor", float, "k <- k * factor per stage"),
    "--k-min": ("k_min", float, "stop once k falls below this, N"),
}


def _stage_table(stages: list[dict]) -> list[str]:
    rows = [f"{'stage':>5} {'k':>8} {'iter':>5} {'pose error':>18} {'active':>7} {'length':>9} "
            f"{'tau max':>8} {'time':>7}"]
    for s in stages:
        k = "-" if s["k"] is None else f"{s['k']:.4g}"
        rows.append(f"{s['stage']:>5} {k:>8} {s['iterations']:>5} "
                    f"{1e3 * s['pose_error']:>8.3f} mm {100 * s['pose_error_rel']:>5.2f}% "
                    f"{s['active_fibers']:>7} {100 * s['active_length']:>6.1f} cm {s['tau_max']:>6.3f} N "
                    f"{s['time_s']:>6.1f}s")
    return rows


def _add_optimize_flags(p: argparse.ArgumentParser) -> None:
    for flag, (key, typ, text) in OPTIMIZE_FLAGS.items():
        p.add_argument(flag, type=typ, default=None, help=f"{text} (scene [optimize] {key})")


def _optimize_overrides(args) -> dict:
    """The [optimize] settings given on the command line (key -> value or None)."""
    return {key: getattr(args, flag[2:].replace("-", "_")) for flag, (key, _, _) in OPTIMIZE_FLAGS.items()}


def cmd_optimize(args) -> int:
    from .runs import Interrupted, Progress, optimize
    from .scene import load_scene, with_overrides

    overrides = _optimize_overrides(args)
    given = [f for f, (k, _, _) in OPTIMIZE_FLAGS.items() if overrides[k] is not None]
    if args.resume:
        if given:
            raise InputError(f"{given[0]} cannot be changed when resuming (the recorded settings are used)")
        scene = None
    else:
        if args.scene is None:
            raise InputError("a SCENE is required (or --resume RUN.rrd)")
        scene = with_overrides(load_scene(args.scene), overrides)
    if args.log_every < 1:
        raise InputError(f"--log-every must be >= 1 (got {args.log_every})")
    try:
        result = optimize(scene, args.resolution, args.solver, record=args.record, export=args.export,
                          log_every=args.log_every, progress=Progress(enabled=not args.quiet),
                          resume=args.resume, png=args.png)
    except Interrupted as exc:
        if args.json not in (None, "-"):
            _json_out(args, exc.summary)
        raise
    if args.resume and scene is None and args.scene is not None and args.scene != result.problem.scene.name:
        print(f"{PROG}: warning: the recording is of scene '{result.problem.scene.name}', not "
              f"'{args.scene}'", file=sys.stderr)
    summary = result.summary
    for w in result.warnings:
        print(f"{PROG}: warning: {w}", file=sys.stderr)
    _json_out(args, summary)
    if args.json == "-":
        return 0
    c = result.problem.counts()
    print(f"{summary['scene']} level {summary['resolution']}: {c['nodes']} nodes, {c['triangles']} "
          f"triangles, {c['fibers']} fibers, {c['dofs']} DOFs, L = {100 * summary['body_size']:.2f} cm")
    print("\n".join(_stage_table(summary["stages"])))
    print(f"total {summary['time_s']:.1f} s; recording: {summary['recording']}; export: {summary['export']}"
          + (f"; png: {summary['png']}" if "png" in summary else ""))
    return 0


def cmd_replay(args) -> int:
    from .runs import replay

    png = None
    if args.png is not None:
        png = Path(args.recording).with_suffix(".png") if args.png == "-" else Path(args.png)
    out = replay(args.recording, stage=args.stage, solver=args.solver, png=png)
    _json_out(args, out)
    if args.json != "-":
        print(f"{out['recording']}: {out['scene']} level {out['resolution']}"
              + (" (truncated file: read its complete part)" if out["truncated"] else ""))
        print(f"{'stage':>5} {'k':>8} {'recorded pose error':>20} {'recomputed':>14} {'rel. diff':>10} "
              f"{'active rec/now':>15}")
        for r in out["stages"]:
            k = "-" if r["k"] is None else f"{r['k']:.4g}"
            flag = "ok" if r["reproduces"] else "MISMATCH"
            print(f"{r['stage']:>5} {k:>8} {1e3 * r['recorded_pose_error']:>17.6f} mm "
                  f"{1e3 * r['pose_error']:>11.6f} mm {r['pose_error_rel_diff']:>10.1e} "
                  f"{r['recorded_active_fibers']:>7}/{r['active_fibers']:<7} {flag}")
        if "png" in out:
            print(f"png: {out['png']}")
    if not out["reproduces"]:
        bad = [str(r["stage"]) for r in out["stages"] if not r["reproduces"]]
        print(f"{PROG}: replay: stage(s) {', '.join(bad)} do not reproduce the recorded figures",
              file=sys.stderr)
        return 3
    return 0


# ------------------------------------------------------------------ extraction
def cmd_extractors(args) -> int:
    from .extraction import available_extractors, load_extractor

    rows = []
    for name, ep in sorted(available_extractors().items()):
        row = {"name": name, "entry_point": ep.value,
               "distribution": ep.dist.name if getattr(ep, "dist", None) else None}
        try:
            ext = load_extractor(name)
            row["description"] = ext.description
            row["options"] = {f.name: f.default for f in ext.option_fields()} \
                if hasattr(ext, "option_fields") else {}
        except TendonError as exc:
            row["error"] = str(exc)
        rows.append(row)
    _json_out(args, {"extractors": rows})
    if args.json == "-":
        return 0
    for r in rows:
        if "error" in r:
            print(f"{r['name']:<20} ERROR: {r['error']}")
            continue
        opts = ", ".join(f"{k}={v}" for k, v in r["options"].items())
        print(f"{r['name']:<20} {r['description']}  [{r['distribution']}]")
        if opts:
            print(f"{'':<20} options: {opts}")
    return 0


def _parse_options(items: list[str], default_name: str | None) -> dict[str, dict]:
    """``k=v`` (for the one extractor) or ``name.k=v`` into {name: {k: v}}."""
    out: dict[str, dict] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(f"--option expects key=value (got '{item}')")
        key, value = item.split("=", 1)
        name, _, opt = key.rpartition(".")
        name = name or default_name
        if not name:
            raise InputError(f"--option '{item}': say which extractor, as NAME.{key}=value")
        out.setdefault(name, {})[opt] = value
    return out


def _metric_table(ex) -> list[str]:
    rows = [f"{'extractor':<18} {'tendons':>7} {'length':>8} {'turning':>8} {'max turn':>8} {'kinks':>5} "
            f"{'capstan':>7} {'tens.CV':>7} {'coverage':>8} {'realizable':>10} {'x ideal':>7} {'time':>6}"]
    for r in ex.results:
        if r.error is not None:
            rows.append(f"{r.name:<18} failed: {r.error}")
            continue
        m = r.metrics
        count = f"{m['extracted_count']}->{m['count']}" if m["extracted_count"] != m["count"] else m["count"]
        rows.append(f"{r.name:<18} {count:>7} {100 * m['total_length']:>5.1f} cm "
                    f"{np.degrees(m['total_turning']):>6.0f} d {np.degrees(m['max_turn']):>6.0f} d "
                    f"{m['kinks']:>5} {m['capstan_worst']:>7.3f} {m['tension_cv']:>7.3f} "
                    f"{100 * m['coverage']:>7.1f}% {100 * m['realizable_pose_error_rel']:>9.2f}% "
                    f"{m['realizable_ratio']:>7.2f} {r.time_s:>5.1f}s")
    return rows


def _extraction_output(args, ex) -> int:
    out = ex.as_json()
    failed = [r for r in ex.results if r.error is not None]
    if getattr(args, "png", None) is not None and len(failed) < len(ex.results):
        from .plots import plot_compare
        png = Path(args.recording).with_suffix(".compare.png") if args.png == "-" else Path(args.png)
        plot_compare(png, ex)
        out["png"] = str(png)
    _json_out(args, out)
    if args.json != "-":
        print(f"{out['recording']}: {out['scene']} level {out['resolution']}, stage {out['stage']} "
              f"(idealized pose error {100 * out['idealized_pose_error_rel']:.2f}% of L)")
        print("\n".join(_metric_table(ex)))
        if "png" in out:
            print(f"png: {out['png']}")
    for r in failed:
        print(f"{PROG}: error: {r.error}", file=sys.stderr)
    return 4 if failed else 0


def _add_consolidation_flags(p: argparse.ArgumentParser) -> None:
    from .consolidation import BUDGET, GAP, REFINE, SCREEN, TOLERANCE

    p.add_argument("--consolidate-tol", type=float, default=TOLERANCE, metavar="F",
                   help="drop or join extracted tendons while the realizable pose error rises by at most "
                        f"F x L in all (default {TOLERANCE:g}; README 'Consolidation')")
    p.add_argument("--consolidate-budget", type=float, default=BUDGET, metavar="F",
                   help="... or while it stays within F x L, the pose error you accept anyway "
                        f"(default {BUDGET:g}; 0: none)")
    p.add_argument("--join-gap", type=float, default=GAP, metavar="F",
                   help=f"join two tendons whose ends are at most F x L apart (default {GAP:g})")
    p.add_argument("--refine", type=int, default=REFINE, metavar="N",
                   help="then trim or extend tendon ends, at most N steps in a row, while that lowers the "
                        f"realizable pose error (default {REFINE}; 0: never)")
    p.add_argument("--screen", type=int, default=SCREEN, metavar="N",
                   help="solve in full only the N refinement candidates a Gauss-Newton step predicts best "
                        f"(default {SCREEN}; 0: solve every one)")
    p.add_argument("--no-consolidate", action="store_true", help="keep the extracted tendons as they are")


def _consolidation(args):
    from .consolidation import ConsolidationSettings

    for flag, value in (("--consolidate-tol", args.consolidate_tol), ("--consolidate-budget", args.consolidate_budget),
                        ("--join-gap", args.join_gap)):
        if value < 0 or not math.isfinite(value):
            raise InputError(f"{flag} must be a finite number >= 0 (got {value})")
    for flag, value in (("--refine", args.refine), ("--screen", args.screen)):
        if value < 0:
            raise InputError(f"{flag} must be an integer >= 0 (got {value})")
    return ConsolidationSettings(-1.0 if args.no_consolidate else args.consolidate_tol, args.join_gap,
                                 args.consolidate_budget, args.refine, args.screen)


def cmd_extract(args) -> int:
    from .tendons import extract

    options = _parse_options(args.option, args.extractor)
    ex = extract(args.recording, [args.extractor], stage=args.stage, options=options, solver=args.solver,
                 record=not args.no_record, consolidation=_consolidation(args))
    r = ex.results[0]
    if r.error is not None:
        raise TendonError(r.error)
    if args.svg:
        from .export import write_svg
        write_svg(args.svg, ex.problem, r.tendons, f"{ex.problem.scene.name} - {r.name}")
    if args.json != "-":
        for i, t in enumerate(r.tendons):
            print(f"tendon {i + 1}: {100 * t.length:.1f} cm, {len(t.nodes)} waypoints, tension "
                  f"{t.tension:.3f} N (sd {t.tension_std:.3f}), contraction {1e3 * (t.contraction or 0):.2f} mm")
        if args.svg:
            print(f"svg: {args.svg}")
    return _extraction_output(args, ex)


def cmd_compare(args) -> int:
    from .tendons import extract

    ex = extract(args.recording, args.extractors, stage=args.stage, options=_parse_options(args.option, None),
                 solver=args.solver, record=not args.no_record, consolidation=_consolidation(args))
    return _extraction_output(args, ex)


# ------------------------------------------------------------------ bench
def cmd_bench(args) -> int:
    from .bench import run_bench, table
    from .scene import load_scene

    scene = load_scene(args.scene)
    if args.repeat < 1 or any(lv < 1 for lv in args.levels):
        raise InputError("--repeat and --levels must be >= 1")
    optimize_levels = [] if args.no_optimize else args.optimize_levels
    workers, scheduler = _cluster_args(args)
    workers = 0 if workers is None and scheduler is None else workers
    result = run_bench(scene, args.levels, args.solver, args.repeat, args.out, optimize_levels,
                       args.forward_max_fibers, optimize_solver=args.optimize_solver, workers=workers,
                       scheduler=scheduler)
    _json_out(args, result)
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
    from .planted import MAX_TENDONS, plant, write_planted
    from .scene import load_scene

    t0 = time.perf_counter()
    if not 1 <= args.tendons <= MAX_TENDONS:
        raise InputError(f"--tendons must be 1..{MAX_TENDONS} (got {args.tendons})")
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0 (got {args.seed})")
    if args.level < 1:
        raise InputError(f"--level must be >= 1 (got {args.level})")
    scene = load_scene(args.scene)
    if not 1 <= args.poses <= 4:
        raise InputError(f"--poses must be 1..4 (got {args.poses})")
    text, layout = plant(scene, args.tendons, args.seed, args.level, poses=args.poses)
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
    _json_out(args, summary)
    if args.json != "-":
        print(f"{layout['name']}: {args.tendons} tendon{'s' if args.tendons > 1 else ''}, "
              f"{100 * layout['planted_length']:.1f} cm planted, largest target displacement "
              f"{100 * pose['max_target_displacement_rel']:.2f} % of L ({layout['draws']} draw"
              f"{'s' if layout['draws'] > 1 else ''}); wrote {toml_path} and {json_path}")
    return 0


# ------------------------------------------------------------------ planted-bench
def cmd_planted_bench(args) -> int:
    from .planted_bench import run_suite, table

    overrides = _optimize_overrides(args)
    workers, scheduler = _cluster_args(args)
    result = run_suite(args.suite, args.resolution, args.out, overrides, args.extractors, args.solver,
                       args.cases, workers=workers, scheduler=scheduler, consolidation=_consolidation(args))
    _json_out(args, result)
    if args.json != "-":
        print("\n".join(table(result)))
        print(f"outputs in {args.out}/ (planted_bench.json, planted_bench.csv, gallery.png)")
    return 0


# ------------------------------------------------------------------ sweep
def _add_cluster_flags(p: argparse.ArgumentParser, default_workers: str) -> None:
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help=f"worker processes of the local Dask cluster ({default_workers}; 0: run the cases "
                        f"one after the other in this process)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on an existing Dask cluster (tcp://HOST:PORT of a `dask scheduler`); "
                        "it is left running")


def _cluster_args(args) -> tuple[int | None, str | None]:
    if args.workers is not None and args.workers < 0:
        raise InputError(f"--workers must be >= 0 (got {args.workers})")
    return args.workers, args.scheduler


def cmd_sweep(args) -> int:
    from .sweep import load_sweep, run, table

    workers, scheduler = _cluster_args(args)
    sweep = load_sweep(args.sweep)
    out = args.out or str(Path("recordings") / "sweeps" / sweep.name)
    result = run(sweep, out, workers, scheduler)
    _json_out(args, result)
    if args.json != "-":
        print("\n".join(table(result)))
        print(f"outputs in {out}/ (sweep.json, sweep.csv, sweep.png, cases/)")
    return 4 if result["failed"] else 0


# ------------------------------------------------------------------ main
def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog=PROG, description="Design the tendon layout of a 2D soft robot.")
    p.add_argument("--arch", default=None, help="Taichi backend: cpu (default), cuda, vulkan, gpu")
    p.add_argument("--threads", type=int, default=None, help="CPU threads for Taichi")
    p.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    s = sub.add_parser("scenes", help="list the built-in scenes")
    _add_json(s)
    s.set_defaults(func=cmd_scenes)

    s = sub.add_parser("simulate", help="solve one equilibrium for given fiber contractions")
    s.add_argument("scene", metavar="SCENE", help="built-in scene name or scene TOML file")
    s.add_argument("--resolution", type=int, default=1, metavar="N", help="resolution level (default 1)")
    g = s.add_mutually_exclusive_group(required=True)
    g.add_argument("--uniform", type=float, metavar="C",
                   help="contract every fiber by the ratio C of its rest length")
    g.add_argument("--contract", metavar="FILE.npy",
                   help="per-fiber contraction ratios (ac/a0), one per fiber")
    s.add_argument("--solver", choices=SOLVER_CHOICES, default="auto",
                   help="linear solver: matrix-free Taichi PCG, sparse direct, or auto (default: "
                        "picks by problem size)")
    s.add_argument("--export", metavar="OUT.npz",
                   help="problem export (default recordings/<scene>-r<N>-simulate.npz)")
    s.add_argument("--vtu", metavar="OUT.vtu", help="also write the deformed mesh and fibers as VTU")
    _add_json(s)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("optimize", help="regularized soft IK with the L0 homotopy, recorded to rerun")
    s.add_argument("scene", metavar="SCENE", nargs="?", help="built-in scene name or scene TOML file")
    s.add_argument("--resolution", type=int, default=1, metavar="N", help="resolution level (default 1)")
    s.add_argument("--record", metavar="RUN.rrd", help="recording (default recordings/<scene>-r<N>.rrd)")
    s.add_argument("--export", metavar="OUT.npz", help="final problem export (default: beside the recording)")
    s.add_argument("--solver", choices=SOLVER_CHOICES, default="auto",
                   help="linear solver of equilibria and adjoints (default auto: by problem size)")
    s.add_argument("--resume", metavar="RUN.rrd",
                   help="continue an interrupted run from its last completed stage (into --record, "
                        "default the same file)")
    s.add_argument("--png", nargs="?", const="-", metavar="FILE",
                   help="picture of the stage-0 and final tension patterns (default: beside the recording)")
    s.add_argument("--log-every", type=int, default=1, metavar="N",
                   help="record the geometry every N-th iteration (scalars every iteration)")
    s.add_argument("--quiet", action="store_true", help="no progress on stderr")
    _add_optimize_flags(s)
    _add_json(s)
    s.set_defaults(func=cmd_optimize)

    s = sub.add_parser("replay", help="re-solve a recording's stages and check they reproduce")
    s.add_argument("recording", metavar="RUN.rrd")
    s.add_argument("--stage", type=int, default=None, metavar="N", help="only this stage")
    s.add_argument("--solver", choices=("recorded",) + SOLVER_CHOICES, default="recorded",
                   help="linear solver (default: the one the run used)")
    s.add_argument("--png", nargs="?", const="-", metavar="FILE",
                   help="picture of stage 0 and the last replayed stage (default: beside the recording)")
    _add_json(s)
    s.set_defaults(func=cmd_replay)

    s = sub.add_parser("extractors", help="list the installed tendon extractors")
    _add_json(s)
    s.set_defaults(func=cmd_extractors)

    for name, helptext in (("extract", "extract tendons from a recorded stage with one extractor"),
                           ("compare", "run several extractors on a recorded stage side by side")):
        s = sub.add_parser(name, help=helptext)
        s.add_argument("recording", metavar="RUN.rrd")
        s.add_argument("--stage", type=int, default=None, metavar="N", help="stage (default: the last)")
        if name == "extract":
            s.add_argument("--extractor", required=True, metavar="NAME")
            s.add_argument("--svg", metavar="OUT.svg", help="drawing of the body and the tendons, in mm")
        else:
            s.add_argument("--extractors", nargs="+", metavar="NAME", help="default: every installed one")
            s.add_argument("--png", nargs="?", const="-", metavar="FILE",
                           help="idealized pattern beside each extractor's realizable robot")
        s.add_argument("--option", action="append", default=[], metavar="K=V",
                       help="extractor option (compare: NAME.K=V); repeatable")
        s.add_argument("--solver", choices=("recorded",) + SOLVER_CHOICES, default="recorded")
        s.add_argument("--no-record", action="store_true", help="do not log the tendons into the recording")
        _add_consolidation_flags(s)
        _add_json(s)
        s.set_defaults(func=cmd_extract if name == "extract" else cmd_compare)

    s = sub.add_parser("bench", help="headless resolution-scaling benchmark (JSON, CSV, PNG)")
    s.add_argument("scene", metavar="SCENE", nargs="?", default="t_shape", help="default t_shape")
    s.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3], metavar="N")
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
    _add_cluster_flags(s, "for the whole optimizations; default: run them in this process, after the other "
                          "measurements")
    _add_json(s)
    s.set_defaults(func=cmd_bench)

    s = sub.add_parser("planted", help="a scene whose goals random planted tendons reach (a benchmark "
                                       "with a known answer)")
    s.add_argument("scene", metavar="SCENE", help="built-in scene name or scene TOML file")
    s.add_argument("--tendons", type=int, default=2, metavar="N", help="number of tendons, 1..5 (default 2)")
    s.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (default 0)")
    s.add_argument("--level", type=int, default=2, metavar="N",
                   help="resolution level of the planted equilibrium (default 2)")
    s.add_argument("--poses", type=int, default=1, metavar="P",
                   help="target poses made by the same tendons, 1..4 (default 1; see DESIGN.md section 6)")
    s.add_argument("--out", default=".", metavar="DIR",
                   help="writes DIR/<scene>_planted_<N>t_s<S>[_<P>p].toml and .json (default: .)")
    _add_json(s)
    s.set_defaults(func=cmd_planted)

    s = sub.add_parser("planted-bench", help="optimize + every extractor on a suite of planted layouts, "
                                             "scored against what was planted")
    s.add_argument("suite", metavar="DIR", nargs="?", default="benchmarks/planted",
                   help="folder of planted cases, NAME.toml + NAME.json (default benchmarks/planted)")
    s.add_argument("--resolution", type=int, default=2, metavar="N", help="resolution level (default 2)")
    s.add_argument("--out", default="recordings/planted", metavar="DIR")
    s.add_argument("--cases", nargs="+", metavar="NAME", help="run only these cases")
    s.add_argument("--extractors", nargs="+", metavar="NAME", help="default: every installed one")
    s.add_argument("--solver", choices=SOLVER_CHOICES, default="auto")
    _add_optimize_flags(s)
    _add_consolidation_flags(s)
    _add_cluster_flags(s, "default: one per core")
    _add_json(s)
    s.set_defaults(func=cmd_planted_bench)

    s = sub.add_parser("sweep", help="many optimize + extract cases (scenes x levels x a grid of settings) "
                                     "as tasks on Dask")
    s.add_argument("sweep", metavar="SWEEP.toml", help="sweep file (DESIGN.md section 6)")
    s.add_argument("--out", default=None, metavar="DIR", help="default recordings/sweeps/<name>")
    _add_cluster_flags(s, "default: one per core")
    _add_json(s)
    s.set_defaults(func=cmd_sweep)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv or os.environ.get("TENDON_TAICHI_DEBUG") == "1"
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help(sys.stderr)
            return 2
        if getattr(args, "resolution", 1) < 1:
            raise InputError(f"--resolution must be >= 1 (got {args.resolution})")
        from . import runtime
        runtime.configure(arch=args.arch, threads=args.threads)
        return int(args.func(args) or 0)
    except TendonError as exc:
        if isinstance(exc, Stopped):
            print(f"{PROG}: {exc}", file=sys.stderr)
            return 130
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    except Exception as exc:  # noqa: BLE001 - the one place that turns bugs into one line
        if debug:
            raise
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        print(f"{PROG}: internal error: {type(exc).__name__}: {msg} "
              f"(run with --debug for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
