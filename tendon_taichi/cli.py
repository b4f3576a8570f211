"""The ``tendon-taichi`` command line (DESIGN.md section 6).

Results go to stdout (``--json`` for machines, to stdout or a file), progress
and warnings to stderr. Bad input gives one ``tendon-taichi: error: ...`` line
and exit status 2; an unexpected failure one ``internal error`` line and 1
(``--debug`` shows the traceback); Ctrl-C exits 130.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from .errors import InputError, TendonError

PROG = "tendon-taichi"


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
                     "error": float(err[i])} for i, t in enumerate(scene.targets)],
        "pose_error": float(np.sqrt((err ** 2).sum())), "pose_error_rel": float(np.sqrt((err ** 2).sum()) / L),
        "solve_s": eq.time_s, "time_s": time.perf_counter() - t0,
        "export": str(export), "vtu": args.vtu,
    }
    _json_out(args, summary)
    if args.json == "-":
        return 0
    lin = "CG" if args.solver == "cg" else "direct"
    print(f"{scene.name} level {problem.level}: {counts['nodes']} nodes, {counts['triangles']} "
          f"triangles, {counts['fibers']} fibers, {counts['dofs']} DOFs")
    print(f"equilibrium: {eq.newton_iterations} Newton iterations"
          + (f", {eq.linear_iterations} {lin} iterations" if args.solver == "cg" else f" ({lin})")
          + f", relative residual {eq.residual:.1e}, {eq.time_s:.3f} s")
    print(f"max displacement {1e3 * disp.max():.2f} mm, max tension {eq.tau.max():.3f} N, "
          f"pose error {1e3 * summary['pose_error']:.2f} mm ({100 * summary['pose_error_rel']:.2f} % of L)")
    print(f"export: {export}" + (f"; vtu: {args.vtu}" if args.vtu else ""))
    return 0


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
    s.add_argument("--solver", choices=("cg", "direct"), default="cg",
                   help="linear solver: matrix-free Taichi PCG (default) or sparse direct")
    s.add_argument("--export", metavar="OUT.npz",
                   help="problem export (default recordings/<scene>-r<N>-simulate.npz)")
    s.add_argument("--vtu", metavar="OUT.vtu", help="also write the deformed mesh and fibers as VTU")
    _add_json(s)
    s.set_defaults(func=cmd_simulate)
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
