"""The commands that run the model: ``scenes``, ``simulate``, ``optimize`` and
``replay``."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..files import file_stem
from ..objective.settings import SETTINGS
from .common import PROG, SOLVER_CHOICES, add_json, add_level_flag, json_out


# ------------------------------------------------------------------ scenes
def cmd_scenes(args) -> int:
    from ..body.scene import builtin_scenes, load_scene

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
        json_out(args, {"scenes": rows})
        if args.json != "-":
            print(f"wrote {args.json}")
        return 0
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        print(f"{r['name']:<{width}}  {r['description']}")
    return 0


# ------------------------------------------------------------------ simulate
def _read_ratios(path: str) -> np.ndarray:
    """The contraction ratios in the .npy file ``path``, one per fiber (f,)."""
    try:
        with open(path, "rb") as fh:
            if fh.read(6) != b"\x93NUMPY":
                raise InputError(f"contraction file '{path}' is not a .npy file (numpy.save writes one)")
        r = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise InputError(f"contraction file '{path}' does not exist") from None
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read contraction file '{path}' (expected a .npy array): {exc}") from None
    if not isinstance(r, np.ndarray) or r.dtype.kind not in "fiu":
        raise InputError(f"contraction file '{path}' must hold a numeric .npy array")
    if r.ndim > 1:
        raise InputError(f"contraction file '{path}' holds a {r.shape} array: give one ratio per fiber, "
                         f"a 1-D array")
    return r.astype(float).ravel()


def cmd_simulate(args) -> int:
    from ..apps.simulate import contraction_ratios, simulate
    from ..body.problem import build_problem
    from ..body.scene import load_scene
    from ..io.export import write_export, write_vtu
    from ..physics.elements import check_elements

    t0 = time.perf_counter()
    scene = load_scene(args.scene)
    check_elements(scene.body.dim, scene.origin)
    problem = build_problem(scene, args.level)
    ratios = contraction_ratios(problem, args.uniform if args.contract is None
                                else _read_ratios(args.contract))
    export = Path(args.export or Path("recordings") / f"{file_stem(scene.name)}-r{problem.level}-simulate.npz")
    c = problem.counts()
    if not args.quiet:
        print(f"{scene.name} level {problem.level}: {c['nodes']} nodes, {c['triangles']} "
              f"triangles, {c['fibers']} fibers, {c['dofs']} DOFs; solving ({args.solver})...",
              file=sys.stderr)
    sim = simulate(scene, problem.level, ratios, args.solver, problem=problem)
    eq = sim.equilibrium
    write_export(export, problem, eq.x, sim.ac, eq.tau)
    if args.vtu:
        write_vtu(args.vtu, problem, eq.x, eq.tau)
    summary = {**sim.summary(), "time_s": time.perf_counter() - t0, "export": str(export), "vtu": args.vtu}
    json_out(args, summary)
    if args.json == "-":
        return 0
    disp = summary["max_displacement"]
    print(f"{scene.name} level {problem.level}: {c['nodes']} nodes, {c['triangles']} "
          f"triangles, {c['fibers']} fibers, {c['dofs']} DOFs")
    print(f"equilibrium: {eq.newton_iterations} Newton iterations"
          + (f", {eq.linear_iterations} CG iterations" if summary["solver"] != "direct" else " (direct)")
          + f", relative residual {eq.residual:.1e}, {eq.time_s:.3f} s")
    print(f"max displacement {1e3 * disp:.2f} mm, max tension {eq.tau.max():.3f} N, "
          f"pose error {1e3 * summary['pose_error']:.2f} mm ({100 * summary['pose_error_rel']:.2f} % of L)")
    print(f"export: {export}" + (f"; vtu: {args.vtu}" if args.vtu else ""))
    return 0


# ------------------------------------------------------------------ optimize
def add_optimize_flags(p: argparse.ArgumentParser) -> None:
    """One flag per [optimize] setting (the objective's declarations)."""
    for s in SETTINGS:
        p.add_argument(s.flag, dest=s.name, type=s.kind, default=None,
                       help=f"{s.text}{', ' + s.unit if s.unit else ''} (scene [optimize] {s.key})")


def optimize_overrides(args) -> dict:
    """The [optimize] settings given on the command line (key -> value or None)."""
    return {s.name: getattr(args, s.name) for s in SETTINGS}


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


def cmd_optimize(args) -> int:
    from ..apps.optimize import Interrupted, RunOptions, optimize
    from ..body.scene import load_scene, with_overrides
    from ..io.progress import Progress

    overrides = optimize_overrides(args)
    given = [s.flag for s in SETTINGS if overrides[s.name] is not None]
    if args.resume:
        if given:
            raise InputError(f"{given[0]} cannot be changed when resuming (the recorded settings are used)")
        scene = None if args.scene is None else load_scene(args.scene)  # must be the recorded one
    else:
        if args.scene is None:
            raise InputError("a SCENE is required (or --resume RUN.rrd)")
        scene = with_overrides(load_scene(args.scene), overrides)
    if args.log_every < 0:
        raise InputError(f"--log-every must be >= 0 (got {args.log_every})")
    try:
        result = optimize(scene, args.level, args.solver, record=args.record,
                          progress=Progress(enabled=not args.quiet),
                          options=RunOptions(resume=args.resume, export=args.export, log_every=args.log_every,
                                             png=args.png))
    except Interrupted as exc:
        if args.json not in (None, "-"):
            json_out(args, exc.summary)
        raise
    summary = result.summary
    for w in result.warnings:
        print(f"{PROG}: warning: {w}", file=sys.stderr)
    json_out(args, summary)
    if args.json == "-":
        return 0
    c = result.problem.counts()
    print(f"{summary['scene']} level {summary['resolution']}: {c['nodes']} nodes, {c['triangles']} "
          f"triangles, {c['fibers']} fibers, {c['dofs']} DOFs, L = {100 * summary['body_size']:.2f} cm")
    print("\n".join(_stage_table(summary["stages"])))
    print(f"total {summary['time_s']:.1f} s; recording: {summary['recording']}; export: {summary['export']}"
          + (f"; png: {summary['png']}" if "png" in summary else ""))
    return 0


# ------------------------------------------------------------------ replay
def cmd_replay(args) -> int:
    from ..apps.replay import replay

    png = None
    if args.png is not None:
        png = Path(args.recording).with_suffix(".png") if args.png == "-" else Path(args.png)
    out = replay(args.recording, stage=args.stage, solver=args.solver, png=png)
    json_out(args, out)
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


# ------------------------------------------------------------------ the parsers
def add_commands(sub) -> None:
    s = sub.add_parser("scenes", help="list the built-in scenes")
    add_json(s)
    s.set_defaults(func=cmd_scenes)

    s = sub.add_parser("simulate", help="solve one equilibrium for given fiber contractions")
    s.add_argument("scene", metavar="SCENE", help="built-in scene name or scene TOML file")
    add_level_flag(s, 1, "resolution level (default 1)")
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
    s.add_argument("--quiet", action="store_true", help="no progress line on stderr")
    add_json(s)
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser("optimize", help="regularized soft IK with the L0 homotopy, recorded to rerun")
    s.add_argument("scene", metavar="SCENE", nargs="?", help="built-in scene name or scene TOML file")
    add_level_flag(s, None, "resolution level (default 1; when resuming, the recorded one)")
    s.add_argument("--record", metavar="RUN.rrd", help="recording (default recordings/<scene>-r<N>.rrd)")
    s.add_argument("--export", metavar="OUT.npz", help="final problem export (default: beside the recording)")
    s.add_argument("--solver", choices=SOLVER_CHOICES, default=None,
                   help="linear solver of equilibria and adjoints (default auto: by problem size; when "
                        "resuming, the recorded one)")
    s.add_argument("--resume", metavar="RUN.rrd",
                   help="continue an interrupted run from its last completed stage (into --record, "
                        "default the same file)")
    s.add_argument("--png", nargs="?", const="-", metavar="FILE",
                   help="picture of the stage-0 and final tension patterns (default: beside the recording)")
    s.add_argument("--log-every", type=int, default=0, metavar="N",
                   help="record the geometry every N-th iteration of a stage (default 0: iterations 1, 2, 4, "
                        "8, ...); scalars every iteration, every stage's end always")
    s.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_optimize_flags(s)
    add_json(s)
    s.set_defaults(func=cmd_optimize)

    s = sub.add_parser("replay", help="re-solve a recording's stages and check they reproduce")
    s.add_argument("recording", metavar="RUN.rrd")
    s.add_argument("--stage", type=int, default=None, metavar="N", help="only this stage")
    s.add_argument("--solver", choices=("recorded",) + SOLVER_CHOICES, default="recorded",
                   help="linear solver (default: the one the run used)")
    s.add_argument("--png", nargs="?", const="-", metavar="FILE",
                   help="picture of stage 0 and the last replayed stage (default: beside the recording)")
    add_json(s)
    s.set_defaults(func=cmd_replay)
