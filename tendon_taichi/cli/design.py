"""The ``design`` command: the main job end to end (``docs/cli.md``)."""

from __future__ import annotations

import math
import sys

import numpy as np

from ..errors import InputError
from ..extract.checks import PLUGIN_TIMEOUT
from ..extract.settings import BUDGET
from .common import PROG, SOLVER_CHOICES, add_json, add_level_flag, json_out
from .runs import add_optimize_flags, optimize_overrides
from .tendons import (add_consolidation_flags, add_front_flags, add_tendon_flags, consolidation, front_settings,
                      plugin_timeout, tendon_settings)


def _checked(args) -> tuple[float, int | None]:
    if not (math.isfinite(args.budget) and 0.0 < args.budget < 1.0):
        raise InputError(f"--budget must be a fraction of L in (0, 1) (got {args.budget:g})")
    if args.max_tendons is not None and args.max_tendons < 1:
        raise InputError(f"--max-tendons must be an integer >= 1 (got {args.max_tendons})")
    if not (math.isfinite(args.min_capstan) and 0.0 <= args.min_capstan <= 1.0):
        raise InputError(f"--min-capstan must be a fraction in [0, 1] (got {args.min_capstan:g})")
    if args.workers is not None and args.workers < 0:
        raise InputError(f"--workers must be >= 0 (got {args.workers})")
    return args.budget, args.max_tendons


def table(summary: dict) -> list[str]:
    """The short table ``design`` prints: the front, the recommended tendons, the files."""
    rec = summary["recommended"]
    m = rec["metrics"]
    fine = summary.get("search", {}).get("converged_resolution")
    level = summary["resolution"]
    out = [f"{summary['scene']} level {level} (L = {100 * summary['body_size']:.2f} cm, friction "
           f"{summary['friction']:g}, clearance {summary['clearance']:g} L, budget {100 * summary['budget']:g}% of L"
           + (f", min capstan {summary['min_capstan']:g}" if summary.get("min_capstan") else "")
           + (f", tendons leave at the {summary['exit']}" if summary.get("exit", "inside") != "inside" else "") + ")",
           "the front (per tendon count, the best layout found; * the recommended design):",
           f"{'tendons':>7} {'as built':>9} {f'level {level}':>9} {'capstan':>7} {'kinks':>5} {'length':>8}  from"]
    if fine is not None:
        out[1] = out[1][:-2] + f"; as built: re-solved at level {fine}):"

    def line(row: dict, mark: str) -> str:
        return (f"{row['count']:>5}{mark} {100 * row['realizable_pose_error_rel']:>8.2f}% "
                f"{100 * row['realizable_pose_error_rel_level']:>8.2f}% "
                f"{row['capstan_worst']:>7.3f} {row['kinks']:>5} {100 * row['total_length']:>5.1f} cm  "
                f"{row['source']}")

    for e in summary["front"]:
        out.append(line(e, " *" if e["count"] == rec["count"] else "  "))
    out.append(f"recommended: {rec['count']} tendon(s) (from {rec['source']}), as built "
               f"{100 * m['realizable_pose_error_rel']:.2f}% of L (level {level}: "
               f"{100 * m['realizable_pose_error_rel_level']:.2f}%, frictionless "
               f"{100 * m['realizable_pose_error_rel_frictionless']:.2f}%), worst capstan {m['capstan_worst']:.3f}, "
               f"{m['kinks']} kinks, clearance {1e3 * (m['clearance_min'] or 0):.1f} mm")
    if not rec.get("meets_min_capstan", True):
        out.append(f"  (no layout within the budget keeps {summary['min_capstan']:g} of its pull in every tendon, "
                   "--min-capstan: the limit was set aside)")
    for i, t in enumerate(rec["tendons"]):
        pulls = ", ".join(f"{1e3 * c:.2f}" for c in t["contraction"])
        leaves = "" if t.get("exit") is None else ", leaves at ({:.1f}, {:.1f}) mm".format(*(1e3 * np.array(t["exit"])))
        out.append(f"  tendon {i + 1}: {100 * t['length']:.1f} cm, pull {pulls} mm, tension {t['tension']:.3f} N, "
                   f"turning {np.degrees(t['turning']):.0f} deg, capstan {t['capstan']:.3f}{leaves}")
    out.append("files: " + ", ".join(summary["files"].values()))
    return out


def cmd_design(args) -> int:
    from ..apps.design import default_workers, design
    from ..apps.settings import DesignSettings
    from ..extract.settings import FrontSettings
    from ..body.scene import load_scene, with_overrides
    from ..io.progress import Progress

    budget, max_tendons = _checked(args)
    front = front_settings(args)
    tendons = tendon_settings(args)
    cons = consolidation(args, budget=budget)
    timeout = plugin_timeout(args)
    scene = with_overrides(load_scene(args.scene), optimize_overrides(args)).with_tendons(**tendons)
    settings = DesignSettings(args.solver, None if args.extractors is None else tuple(args.extractors), cons, budget,
                              FrontSettings(max_tendons=max_tendons, **front), min_capstan=args.min_capstan,
                              plugin_timeout=timeout, png=not args.no_png, routes_from=args.routes_from)
    result = design(scene, args.level, args.out, settings, Progress(enabled=not args.quiet),
                    workers=default_workers() if args.workers is None else args.workers)
    summary = result.summary
    for w in summary["warnings"]:
        print(f"{PROG}: warning: {w}", file=sys.stderr)
    json_out(args, summary)
    if args.json != "-":
        print("\n".join(table(summary)))
    failed = [e for e in summary["extractors"] if "error" in e]
    for e in failed:
        print(f"{PROG}: error: {e['error']}", file=sys.stderr)
    return 4 if failed else 0


def add_commands(sub) -> None:
    s = sub.add_parser("design", help="the main job: optimize, extract, consolidate, route, recommend a design")
    s.add_argument("scene", metavar="SCENE", help="built-in scene name or scene TOML file")
    add_level_flag(s, 1, "resolution level (default 1)")
    s.add_argument("--out", metavar="DIR", help="output folder (default designs/<scene>-r<N>)")
    s.add_argument("--budget", type=float, default=BUDGET, metavar="F",
                   help=f"the as-built pose error you accept, F x L (default {BUDGET:g}): the recommended "
                        "design is the fewest tendons within it")
    s.add_argument("--max-tendons", type=int, default=None, metavar="K",
                   help="recommend at most K tendons")
    s.add_argument("--min-capstan", type=float, default=0.0, metavar="F",
                   help="recommend only layouts whose every tendon keeps at least F of its pull against its "
                        "channel's friction (worst capstan factor; default 0: no limit); when none within "
                        "the budget does, the recommendation says so and ignores the limit")
    add_front_flags(s)
    s.add_argument("--routes-from", metavar="DESIGN",
                   help="also search from a prior design of the same body (its folder or design.json, for "
                        "example a coarser level's): its front's layouts, solved and optimized on this mesh")
    s.add_argument("--extractors", nargs="+", metavar="NAME", help="default: every installed one")
    s.add_argument("--solver", choices=SOLVER_CHOICES, default="auto", help="linear solver (default auto)")
    add_tendon_flags(s)
    add_consolidation_flags(s, budget=False)
    s.add_argument("--plugin-timeout", type=float, default=PLUGIN_TIMEOUT, metavar="S",
                   help=f"give up on an extractor that runs longer than S seconds (default {PLUGIN_TIMEOUT:g})")
    s.add_argument("--no-png", action="store_true", help="skip design.png and front.png")
    s.add_argument("--workers", type=int, default=None, metavar="N",
                   help="worker processes that share the consolidations and the front's solves (default: one "
                        "per core but one, at most 4; 0: none) - the same design either way")
    s.add_argument("--quiet", action="store_true", help="no progress on stderr")
    add_optimize_flags(s)
    add_json(s)
    s.set_defaults(func=cmd_design)
