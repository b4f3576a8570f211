"""The tendon commands: ``extractors``, ``extract`` and ``compare``, and the
consolidation and [tendons] flags they share with ``design``, ``planted-bench``
and ``sweep``."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError, TendonError
from ..extract.checks import PLUGIN_TIMEOUT
from ..extract.settings import BEAM, BUDGET, GAP, REFINE, SCREEN, TOLERANCE, ConsolidationSettings
from .common import PROG, SOLVER_CHOICES, add_json, json_out


def cmd_extractors(args) -> int:
    from ..extract.plugins import available_extractors, load_extractor

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
    json_out(args, {"extractors": rows})
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
            f"{'capstan':>7} {'tens.CV':>7} {'coverage':>8} {'as built':>10} {'x ideal':>7} {'time':>6}"]
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
        from ..io.plots import plot_compare
        png = Path(args.recording).with_suffix(".compare.png") if args.png == "-" else Path(args.png)
        plot_compare(png, ex)
        out["png"] = str(png)
    if out["truncated"]:
        print(f"{PROG}: warning: '{out['recording']}' is truncated (an interrupted run?): only its "
              f"complete stages 0..{len(ex.run.stages) - 1} were read; extracted from stage {out['stage']}",
              file=sys.stderr)
    json_out(args, out)
    if args.json != "-":
        print(f"{out['recording']}: {out['scene']} level {out['resolution']}, stage {out['stage']} "
              f"(idealized pose error {100 * out['idealized_pose_error_rel']:.2f}% of L)")
        print("\n".join(_metric_table(ex)))
        if "png" in out:
            print(f"png: {out['png']}")
        if "record" in out:
            print(f"tendons logged into: {out['record']}")
    for r in failed:
        print(f"{PROG}: error: {r.error}", file=sys.stderr)
    if ex.record_error is not None:
        print(f"{PROG}: error: {ex.record_error}", file=sys.stderr)
    return 4 if failed else 2 if ex.record_error is not None else 0


def add_consolidation_flags(p: argparse.ArgumentParser, budget: bool = True) -> None:
    p.add_argument("--consolidate-tol", type=float, default=TOLERANCE, metavar="F",
                   help="drop or join tendons while the as-built pose error rises by at most "
                        f"F x L in all (default {TOLERANCE:g}; docs/cli.md 'Consolidation')")
    if budget:
        p.add_argument("--consolidate-budget", type=float, default=BUDGET, metavar="F",
                       help="... or while it stays within F x L, the pose error you accept anyway "
                            f"(default {BUDGET:g}; 0: none)")
    p.add_argument("--join-gap", type=float, default=GAP, metavar="F",
                   help=f"join two tendons whose ends are at most F x L apart (default {GAP:g})")
    p.add_argument("--refine", type=int, default=REFINE, metavar="N",
                   help="then optimize the routes (control points, ends and contractions), at most N "
                        f"rounds (default {REFINE}; 0: keep the fitted routes)")
    p.add_argument("--screen", type=int, default=SCREEN, metavar="N",
                   help="solve in full only the N drops and joins a Gauss-Newton step predicts best "
                        f"(default {SCREEN}; 0: solve every one)")
    p.add_argument("--no-consolidate", action="store_true", help="keep the extracted tendons' routes as they are")


def add_front_flags(p: argparse.ArgumentParser) -> None:
    """``--beam``, ``--no-converge`` and ``--no-coarse``: how wide the count/error front
    searches, whether its errors are re-solved (and its routes optimized again) on the
    next finer mesh, and whether a design above level 1 searches from the level below's too."""
    p.add_argument("--beam", type=int, default=BEAM, metavar="B",
                   help=f"layouts kept per tendon count by the front's beam search (default {BEAM})")
    p.add_argument("--no-converge", action="store_true",
                   help="report the front's errors on the design's mesh, not re-solved (and its routes not "
                        "optimized again) on the next finer one")
    p.add_argument("--no-coarse", action="store_true",
                   help="above level 1, do not design at the level below first (its front's layouts are "
                        "otherwise searched from too; a prior design given with --routes-from takes its place)")


def front_settings(args) -> dict:
    """``beam``, ``converge`` and ``coarse`` of the command line, validated (fields of
    :class:`~tendon_taichi.extract.settings.FrontSettings`)."""
    if args.beam < 1:
        raise InputError(f"--beam must be an integer >= 1 (got {args.beam})")
    return {"beam": args.beam, "converge": not args.no_converge, "coarse": not args.no_coarse}


def add_tendon_flags(p: argparse.ArgumentParser) -> None:
    """``--friction``, ``--clearance`` and ``--exit``: the scene's [tendons] settings, replaced."""
    p.add_argument("--friction", type=float, default=None, metavar="MU",
                   help="capstan friction coefficient of the tendon channels, 0..2 (default: the scene's "
                        "[tendons] friction, 0.1; 0: frictionless)")
    p.add_argument("--clearance", type=float, default=None, metavar="F",
                   help="least distance of a route from the outline and holes, F x L, 0..0.2 (default: "
                        "the scene's [tendons] clearance, 0.02)")
    p.add_argument("--exit", default=None, choices=("inside", "clamp", "surface"),
                   help="where a tendon leaves the body: its pull end inside it, on the outline where it "
                        "is clamped, or anywhere on the outline (default: the scene's [tendons] exit, "
                        "'inside' for 2D scenes that do not say)")


def tendon_settings(args) -> dict:
    """``friction``, ``clearance`` and ``exit`` of the command line (None: the scene's), validated."""
    from ..body.scene import MAX_CLEARANCE, MAX_FRICTION

    for flag, value, top in (("--friction", args.friction, MAX_FRICTION),
                             ("--clearance", args.clearance, MAX_CLEARANCE)):
        if value is not None and not (math.isfinite(value) and 0.0 <= value <= top):
            raise InputError(f"{flag} must be a number in [0, {top:g}] (got {value:g})")
    return {"friction": args.friction, "clearance": args.clearance, "exit": args.exit}


def consolidation(args, budget: float | None = None) -> ConsolidationSettings:
    """The consolidation settings of the command line (``budget``: the one a command
    takes as its own flag), validated."""
    budget = args.consolidate_budget if budget is None else budget
    for flag, value in (("--consolidate-tol", args.consolidate_tol), ("--consolidate-budget", budget),
                        ("--join-gap", args.join_gap)):
        if value < 0 or not math.isfinite(value):
            raise InputError(f"{flag} must be a finite number >= 0 (got {value:g})")
    for flag, value in (("--refine", args.refine), ("--screen", args.screen)):
        if value < 0:
            raise InputError(f"{flag} must be an integer >= 0 (got {value})")
    return ConsolidationSettings(-1.0 if args.no_consolidate else args.consolidate_tol, args.join_gap,
                                 budget, args.refine, args.screen)


def _progress(args, command: str):
    """``log(text)`` for the extraction: a ``COMMAND: text`` line on stderr (none with --quiet)."""
    from ..io.progress import Progress

    progress = Progress(enabled=not args.quiet)
    return lambda text: progress.message(f"{command}: {text}")


def cmd_extract(args) -> int:
    from ..apps.extract import extract
    from ..apps.settings import ExtractSettings

    options = _parse_options(args.option, args.extractor)
    how = ExtractSettings(names=(args.extractor,), stage=args.stage, options=options, solver=args.solver,
                          consolidation=consolidation(args), plugin_timeout=plugin_timeout(args),
                          **tendon_settings(args))
    ex = extract(args.recording, how, record=record(args), on_wait=_waiting(args), log=_progress(args, "extract"))
    r = ex.results[0]
    if r.error is not None:
        raise TendonError(r.error)
    if args.svg:
        from ..io.drawing import write_svg
        write_svg(args.svg, ex.problem, r.tendons, f"{ex.problem.scene.name} - {r.name}")
    if args.json != "-":
        for i, t in enumerate(r.tendons):
            print(f"tendon {i + 1}: {100 * t.length:.1f} cm, {len(t.waypoints)} waypoints, strand tension "
                  f"{t.tension:.3f} N (sd {t.tension_std:.3f}), contraction {1e3 * (t.contraction or 0):.2f} mm")
        if args.svg:
            print(f"svg: {args.svg}")
    return _extraction_output(args, ex)


def cmd_compare(args) -> int:
    from ..apps.extract import extract
    from ..apps.settings import ExtractSettings

    how = ExtractSettings(names=None if args.extractors is None else tuple(args.extractors), stage=args.stage,
                          options=_parse_options(args.option, None), solver=args.solver,
                          consolidation=consolidation(args), plugin_timeout=plugin_timeout(args),
                          **tendon_settings(args))
    ex = extract(args.recording, how, record=record(args), on_wait=_waiting(args), log=_progress(args, "compare"))
    return _extraction_output(args, ex)


def record(args) -> bool | str:
    """Where ``--record`` asks the tendons to be logged: False (not given: the
    recording is only read), True (``--record`` alone: into the run's recording)
    or a file of their own."""
    if args.record is not None and args.no_record:
        raise InputError("--record and --no-record contradict each other")
    return False if args.record is None else True if args.record == "-" else args.record


def plugin_timeout(args) -> float:
    if not args.plugin_timeout > 0 or not math.isfinite(args.plugin_timeout):
        raise InputError(f"--plugin-timeout must be a finite number of seconds > 0 (got {args.plugin_timeout})")
    return args.plugin_timeout


def _waiting(args):
    """What to say while another process is writing the recording."""
    return lambda: print(f"{PROG}: waiting for another process to finish writing '{args.recording}'",
                         file=sys.stderr, flush=True)


# ------------------------------------------------------------------ the parsers
def add_commands(sub) -> None:
    s = sub.add_parser("extractors", help="list the installed tendon extractors")
    add_json(s)
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
        s.add_argument("--record", nargs="?", const="-", metavar="FILE.rrd",
                       help="log the tendons: alone, into RUN.rrd (rewritten); with FILE.rrd, into a file of "
                            "their own that rerun shows with the run (default: RUN.rrd is only read)")
        s.add_argument("--no-record", action="store_true", help="log nothing (the default; kept for scripts)")
        add_consolidation_flags(s)
        add_tendon_flags(s)
        s.add_argument("--plugin-timeout", type=float, default=PLUGIN_TIMEOUT, metavar="S",
                       help=f"give up on an extractor that runs longer than S seconds (default {PLUGIN_TIMEOUT:g})")
        s.add_argument("--quiet", action="store_true", help="no progress on stderr")
        add_json(s)
        s.set_defaults(func=cmd_extract if name == "extract" else cmd_compare)
