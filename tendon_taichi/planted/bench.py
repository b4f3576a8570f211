"""``planted-bench``: the ``design`` pipeline on a suite of planted layouts.

A suite is a folder of planted cases (``tendon-taichi planted``): per case a
scene file ``NAME.toml`` whose goals were made by known tendons, and the
layout ``NAME.json`` (``tendons`` with their rest ``waypoints``, ``length``,
``planted_length``). Each case runs the design pipeline (optimize, every
extractor, consolidation, route optimization, the recommendation) and is
scored against what was planted, with the same friction: the recommended
design's tendon count / planted count, its as-built pose error, worst
capstan factor, kinks and clearance against the planted tendons' (their
as-built error is their own contractions re-solved with friction), active
length / planted length, time. A case passes when the design has at most
planted + 1 tendons, an as-built pose error of at most 1 % of L, and the
active length is at most twice the planted one; it meets the route rule when
its worst capstan is at least the planted tendons' minus 0.05 and it has no
more kinks than they have.

Cases are independent and described by data that pickles (:func:`run_case`
takes the case, its scene, a level and the design's settings, and returns a
JSON-able dict), so that a sweep engine can run them as separate tasks.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..apps.case import STOP, CaseSettings, worker_setup
from ..apps.case import run_case as run_one
from ..apps.design import unaccounted
from ..apps.provenance import result_provenance
from ..body.problem import Problem
from ..body.scene import Scene, load_scene, with_overrides
from ..errors import ConvergenceError, InputError, Stopped
from ..extract.consolidation import ConsolidationSettings
from ..extract.context import Context
from ..extract.plugins import available_extractors
from ..extract.protocol import IdealizedState, Tendon, turn_angles
from ..extract.realizable import solve_realizable_poses
from ..extract.settings import FrontSettings, front_id
from ..files import atomic_path, file_stem, write_json
from ..io.progress import Progress
from ..tasks.engine import Cluster, Task, case_id, run_tasks
from .gallery import plot_gallery

#: pass criteria (the issue's "how it is shown")
MAX_EXTRA_TENDONS = 1
MAX_REALIZABLE_POSE_REL = 0.01
MAX_LENGTH_RATIO = 2.0
#: the route rule: worst capstan at least the planted tendons' minus this, no more kinks
CAPSTAN_SLACK = 0.05
KINK_ANGLE = 30.0


@dataclass(frozen=True)
class Case:
    """One planted case: ``name``, its scene file and its planted ``layout``."""

    name: str
    scene_path: Path
    layout: dict

    @property
    def planted_count(self) -> int:
        return len(self.layout["tendons"])

    @property
    def planted_length(self) -> float:
        return float(self.layout.get("planted_length", sum(t["length"] for t in self.layout["tendons"])))


def load_suite(directory: str | Path) -> list[Case]:
    """Every ``NAME.toml`` in ``directory`` with a layout ``NAME.json`` beside it, by name."""
    d = Path(directory)
    if not d.is_dir():
        raise InputError(f"planted suite '{d}' is not a folder")
    if not os.access(d, os.R_OK | os.X_OK):
        raise InputError(f"cannot read the planted suite '{d}': permission denied")
    cases = []
    for toml in sorted(d.glob("*.toml")):
        js = toml.with_suffix(".json")
        if not js.exists():
            continue
        try:
            layout = json.loads(js.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(f"planted layout '{js}' is unreadable: {exc}") from None
        if not isinstance(layout, dict) or not isinstance(layout.get("tendons"), list):
            raise InputError(f"planted layout '{js}' has no 'tendons' list")
        cases.append(Case(toml.stem, toml, layout))
    if not cases:
        raise InputError(f"planted suite '{d}' has no case (NAME.toml with NAME.json)")
    return cases


def planted_ratios(layout: dict, n_poses: int) -> np.ndarray:
    """The planted contraction ratios, (n_poses, T): each pose's own where the
    layout has ``poses``, else every tendon's ``contraction_ratio`` for all."""
    poses = layout.get("poses") or []
    if len(poses) == n_poses and all("contraction_ratios" in p for p in poses):
        return np.array([[float(r) for r in p["contraction_ratios"]] for p in poses])
    ratios = np.array([float(t.get("contraction_ratio", 0.05)) for t in layout["tendons"]])
    return np.tile(ratios, (n_poses, 1))


def planted_figures(problem: Problem, layout: dict, solver: str = "auto") -> dict:
    """The planted tendons scored as a design is, with the scene's friction:
    ``planted_capstan_worst``, ``planted_kinks``, ``planted_total_turning`` (rad) and
    ``planted_as_built_error_rel``, their own contractions re-solved with friction
    from the planted ones (:func:`planted_ratios`; None if that robot cannot be solved)."""
    mu = problem.scene.tendons.friction
    paths = [np.asarray(t["waypoints"], dtype=float) for t in layout["tendons"]]
    turns = [turn_angles(w) for w in paths]
    theta = [float(t.sum()) for t in turns]
    tendons = [Tendon(np.zeros(0, np.int64), np.zeros(0, np.int64), w, float(t.get("tension", 0.0)), 0.0)
               for w, t in zip(paths, layout["tendons"])]
    state = IdealizedState(np.zeros(problem.fibers.n_fibers), np.zeros(problem.fibers.n_fibers), None, 0.0)
    if problem.n_poses > 1:
        state.poses = [state] * problem.n_poses
    try:
        real = solve_realizable_poses(Context(problem, state, problem.scene.optimize, solver), tendons,
                                      planted_ratios(layout, problem.n_poses))
        error = real.pose_error_rel
    except ConvergenceError:
        error = None
    return {"planted_capstan_worst": float(np.exp(-mu * max(theta, default=0.0))),
            "planted_kinks": int(sum((t > np.radians(KINK_ANGLE)).sum() for t in turns)),
            "planted_total_turning": float(sum(theta)), "planted_as_built_error_rel": error}


@dataclass(frozen=True)
class SuiteSettings:
    """What a suite run changes and how its cases are designed: the ``cases`` to run
    (None: all), ``overrides`` of every case's [optimize] settings and ``tendons``
    of its [tendons] ones (None values are left out), the linear ``solver``, the
    ``extractors`` (None: every installed one), ``consolidation`` after each (None:
    the defaults), the ``front``'s search, and ``priors``: per case name, a prior
    design (``design.json``) whose front that case's front searches from too."""

    cases: tuple[str, ...] | None = None
    overrides: dict = field(default_factory=dict)
    tendons: dict = field(default_factory=dict)
    solver: str = "auto"
    extractors: tuple[str, ...] | None = None
    consolidation: ConsolidationSettings | None = None
    front: FrontSettings = FrontSettings()
    priors: dict[str, Path] | None = None


def case_scene(case: Case, overrides: dict, tendons: dict) -> Scene:
    """The case's scene with the [optimize] ``overrides`` and the [tendons] settings
    ``tendons`` applied."""
    scene = load_scene(str(case.scene_path))
    if overrides:
        scene = with_overrides(scene, overrides)
    return scene.with_tendons(**tendons)


def run_case(case: Case, scene: Scene, level: int, out_dir: str | Path, settings: CaseSettings) -> dict:
    """Design one planted ``case`` on its ``scene`` (:func:`case_scene`) as
    ``settings`` say; its files go to ``out_dir/NAME-rLEVEL/`` (:func:`case_folder`).
    Returns the case's figures."""
    t0 = time.perf_counter()
    layout, name, planted_count, planted_length = case.layout, case.name, case.planted_count, case.planted_length
    folder = case_folder(out_dir, name, level)
    solver, routes_from = settings.solver, settings.routes_from
    d = run_one(scene, level, folder, settings)
    run, summary = d.run, d.summary
    final = run.summary["final"]
    length_ratio = final["active_length"] / planted_length if planted_length > 0 else float("inf")
    return {"case": name, "scene": run.summary.get("scene", scene.name), "level": level,
            "planted_count": planted_count, "planted_length": planted_length,
            "pose_error_rel": final["pose_error_rel"], "active_fibers": final["active_fibers"],
            "active_length": final["active_length"], "length_ratio": length_ratio,
            "stages": len(run.stages), **planted_figures(d.extraction.problem, layout, solver),
            **score_design(summary, planted_count, length_ratio),
            "optimize_s": summary["timing"]["optimize_s"], "time_s": time.perf_counter() - t0,
            "recording": str(folder / "run.rrd"), "routes_from": routes_from}


def case_folder(out_dir: str | Path, name: str, level: int) -> Path:
    """Where :func:`run_case` writes a case's design: ``out_dir/NAME-rLEVEL/``."""
    return Path(out_dir) / f"{file_stem(name)}-r{level}"


def _prior_id(path: Path | None) -> list | None:
    """What a case's task id holds of its prior design: its front's routes (a
    prior that changed makes the case run again)."""
    if path is None:
        return None
    return [e.get("routes") for e in json.loads(path.read_text()).get("front", [])]


def score_design(summary: dict, planted_count: int, length_ratio: float) -> dict:
    """A case's design figures: the recommended ``count``, where it came from
    (``best``), its as-built error, the frictionless one, worst capstan, kinks,
    clearance and tendons, the body size L (m), the ``front``, each extractor's final figures, how
    many of the extractors' tendons went missing without a step that says so (``dropped``:
    :func:`~tendon_taichi.apps.design.unaccounted`, None where no extractor's accounting was
    written), and whether the case ``passed`` (route rule aside: :func:`route_rule`)."""
    rec = summary["recommended"]
    m = rec["metrics"]
    passed = bool(rec["count"] <= planted_count + MAX_EXTRA_TENDONS
                  and m["realizable_pose_error_rel"] <= MAX_REALIZABLE_POSE_REL and length_ratio <= MAX_LENGTH_RATIO)
    return {"count": rec["count"], "best": rec["source"], "count_ratio": rec["count"] / planted_count,
            "realizable_pose_error_rel": m["realizable_pose_error_rel"],
            "realizable_pose_error_rel_frictionless": m["realizable_pose_error_rel_frictionless"],
            "kinks": int(m["kinks"]), "capstan_worst": m["capstan_worst"], "clearance_min": m["clearance_min"],
            "total_length": m["total_length"], "tendons": [t["waypoints"] for t in rec["tendons"]],
            "body_size": summary["body_size"], "front": summary["front"], "extractors": {e["name"]: e for e in summary["extractors"]},
            "dropped": _dropped(summary["extractors"]), "passed": passed}


def _dropped(extractors: list[dict]) -> int | None:
    """Tendons the extractors returned that went missing silently, summed over them."""
    counts = [n for n in map(unaccounted, extractors) if n is not None]
    return sum(counts) if counts else None


def route_rule(case: dict) -> bool:
    """The design has no more kinks than the planted tendons and, where it uses at
    least as many tendons as were planted, its worst capstan is at least theirs
    minus CAPSTAN_SLACK. A design with fewer tendons is better even at a lower
    capstan: its as-built error already pays for the friction (``docs/method.md``, the planted suite)."""
    capstan = (case["count"] < case["planted_count"]
               or case["capstan_worst"] >= case["planted_capstan_worst"] - CAPSTAN_SLACK)
    return bool(capstan and case["kinks"] <= case["planted_kinks"])


def totals(cases: list[dict]) -> dict:
    """Suite totals: cases, passes, and medians of the ratios."""
    done = [c for c in cases if "error" not in c]

    def med(key):
        vals = [c[key] for c in done if c.get(key) is not None]
        return float(np.median(vals)) if vals else None

    return {"cases": len(cases), "failed": len(cases) - len(done), "passed": sum(c["passed"] for c in done),
            "count_within_planted_plus_one": sum(1 for c in done if c["count"] is not None
                                                 and c["count"] <= c["planted_count"] + MAX_EXTRA_TENDONS),
            "within_one_percent": sum(c["realizable_pose_error_rel"] <= MAX_REALIZABLE_POSE_REL for c in done),
            "route_rule": sum(route_rule(c) for c in done),
            "median_length_ratio": med("length_ratio"), "median_count_ratio": med("count_ratio"),
            "median_realizable_pose_error_rel": med("realizable_pose_error_rel"),
            "median_capstan_worst": med("capstan_worst"), "median_planted_capstan_worst": med("planted_capstan_worst"),
            "kinks": sum(c["kinks"] for c in done), "planted_kinks": sum(c["planted_kinks"] for c in done),
            "dropped": sum(c.get("dropped") or 0 for c in done),
            "time_s": float(sum(c.get("time_s", 0.0) for c in cases))}


CSV_COLUMNS = ("case", "scene", "level", "planted_count", "count", "best", "planted_length",
               "active_length", "length_ratio", "pose_error_rel", "realizable_pose_error_rel",
               "realizable_pose_error_rel_frictionless", "planted_as_built_error_rel", "kinks", "planted_kinks",
               "capstan_worst", "planted_capstan_worst", "clearance_min", "passed", "route_rule", "dropped", "time_s",
               "error")


def write_outputs(result: dict, out_dir: Path, suite: list[Case]) -> None:
    """planted_bench.json, planted_bench.csv and gallery.png (planted vs found)."""
    write_json(result, out_dir / "planted_bench.json")
    with atomic_path(out_dir / "planted_bench.csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_COLUMNS)
            for c in result["cases"]:
                row = {**c, "route_rule": route_rule(c)} if "error" not in c else c
                w.writerow([row.get(k, "") if row.get(k) is not None else "" for k in CSV_COLUMNS])
    plot_gallery(out_dir / "gallery.png", result, {c.name: c for c in suite})


def _case_row(case: Case, level: int, o) -> dict:
    if o.error is not None:
        return {"case": case.name, "level": level, "planted_count": case.planted_count, "error": o.error,
                "passed": False, "reused": o.reused}
    return {**o.value, "reused": o.reused}


def _describe(row: dict) -> str:
    return (f"{row['count']}/{row['planted_count']} tendons, length x{row['length_ratio']:.2f}, as built "
            f"{100 * row['realizable_pose_error_rel']:.2f}%, capstan {row['capstan_worst']:.2f} (planted "
            f"{row['planted_capstan_worst']:.2f}), {row['kinks']} kinks, {'pass' if row['passed'] else 'miss'}")


def run_suite(directory: str | Path, level: int, out_dir: str | Path, settings: SuiteSettings = SuiteSettings(),
              cluster: Cluster = Cluster(), progress=None) -> dict:
    """Run every case of a suite (``settings.cases``: only those) as tasks of
    :func:`tendon_taichi.tasks.engine.run_tasks` on ``cluster`` (its ``workers``:
    local Dask cluster size, None: one per core, 0: in this process; ``scheduler``:
    an existing cluster), each designed as ``settings`` say. Outputs are rewritten
    after each case, and a re-run reuses the finished ones
    (``out_dir/cases/<id>/result.json``), so an interrupted run keeps what it did."""
    suite = load_suite(directory)
    if settings.cases:
        unknown = set(settings.cases) - {c.name for c in suite}
        if unknown:
            raise InputError(f"no such case in the suite: {', '.join(sorted(unknown))}")
        suite = [c for c in suite if c.name in settings.cases]
    overrides = {k: v for k, v in (settings.overrides or {}).items() if v is not None}
    tendons = {k: v for k, v in (settings.tendons or {}).items() if v is not None}
    for case in suite:  # bad scene files or settings stop the run before it starts
        with_overrides(load_scene(str(case.scene_path)), overrides).with_tendons(**tendons)
    names = sorted(settings.extractors or available_extractors())
    solver, consolidation = settings.solver, settings.consolidation or ConsolidationSettings()
    cons = dataclasses.asdict(consolidation)
    search = settings.front.table()
    design = CaseSettings(solver=solver, extractors=tuple(names), consolidation=consolidation,
                          budget=consolidation.budget or 0.005, front=settings.front)
    out_dir = Path(out_dir)
    priors = settings.priors or {}
    tasks = [Task(case_id({"kind": "planted-design", "scene": case.scene_path.read_text(), "layout": case.layout,
                           "level": level, "settings": overrides, "extractors": names, "solver": solver,
                           "consolidation": cons, "tendons": tendons, **front_id(search),
                           **({"routes_from": _prior_id(priors[case.name])} if case.name in priors else {})}),
                  case.name, run_case,
                  (case, case_scene(case, overrides, tendons), level, str(out_dir / "cases"),
                   replace(design, routes_from=str(priors[case.name]) if case.name in priors else None)))
             for case in suite]
    by_name = {c.name: c for c in suite}
    result = {"suite": str(directory), "level": level, "settings": overrides, "consolidation": cons,
              "tendons": tendons, "front_search": search, "provenance": result_provenance(), "cases": []}
    done = {}

    def on_outcome(o) -> None:
        done[o.task.id] = _case_row(by_name[o.task.label], level, o)
        result["cases"] = [done[t.id] for t in tasks if t.id in done]
        result["totals"] = totals(result["cases"])
        write_outputs(result, out_dir, suite)

    report = run_tasks(tasks, out_dir / "cases", replace(cluster, setup=worker_setup(), stop=STOP),
                       progress or Progress(), on_outcome, describe=_describe)
    result["engine"] = report.engine
    if report.outcomes:
        write_outputs(result, out_dir, suite)
    if report.interrupted:
        raise Stopped(f"interrupted: {len(report.outcomes)} of {len(tasks)} case(s) finished and kept in "
                      f"'{out_dir}'; run the same command again to do the rest")
    return result


def table(result: dict) -> list[str]:
    """The human-readable table of a planted-bench result."""
    out = [f"{'case':<26} {'tendons':>7} {'from':>17} {'length':>6} {'pose':>6} {'built':>6} {'capstan':>11} "
           f"{'kinks':>5} {'time':>5}  result"]
    for c in result["cases"]:
        if "error" in c:
            out.append(f"{c['case']:<26} failed: {c['error']}")
            continue
        out.append(f"{c['case']:<26} {c['count']:>3} / {c['planted_count']:<1} {c['best']:>17} "
                   f"x{c['length_ratio']:>5.2f} {100 * c['pose_error_rel']:>5.2f}% "
                   f"{100 * c['realizable_pose_error_rel']:>5.2f}% {c['capstan_worst']:>5.2f}/{c['planted_capstan_worst']:<5.2f} "
                   f"{c['kinks']:>2}/{c['planted_kinks']:<2} {c['time_s']:>4.0f}s  {'pass' if c['passed'] else 'miss'}"
                   f"{'' if route_rule(c) else ', route rule missed'}")
    t = result["totals"]
    out.append(f"passed {t['passed']} of {t['cases']} ({t['failed']} failed); tendon count <= planted + 1 in "
               f"{t['count_within_planted_plus_one']}; as built within 1 % of L in {t['within_one_percent']}; "
               f"route rule (kinks <= planted; with as many tendons as planted or more, capstan >= planted - "
               f"{CAPSTAN_SLACK:g}) in {t['route_rule']}; "
               f"median capstan {t['median_capstan_worst']} (planted {t['median_planted_capstan_worst']}); "
               f"median length ratio {t['median_length_ratio']}, "
               f"{t.get('dropped', 0)} tendon(s) dropped silently, total time {t['time_s']:.0f} s")
    return out
