"""``planted-bench``: the optimizer and every extractor on a suite of planted layouts.

A suite is a folder of planted cases (``tendon-taichi planted``): per case a
scene file ``NAME.toml`` whose goals were made by known tendons, and the
layout ``NAME.json`` (``tendons`` with their rest ``waypoints``, ``length``,
``planted_length``). Each case runs ``optimize`` and then every extractor,
each followed by consolidation, on the last stage, and is scored against what
was planted: pose error, active length / planted length, tendon count /
planted count, kinks, worst capstan factor, realizable pose error, time. A
case passes when its best extractor (the lowest realizable pose error among
those that find at most planted + 1 tendons) finds at most planted + 1
tendons, with a realizable pose error of at most 1 % of L, and the active
length is at most twice the planted one.

Cases are independent and described by plain data (:func:`run_case` takes a
path, a level and settings, and returns a JSON-able dict), so that a sweep
engine can run them as separate tasks.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..apps.case import STOP, worker_setup
from ..apps.case import run_case as run_one
from ..body.scene import load_scene, with_overrides
from ..errors import InputError, Stopped
from ..extract.consolidation import ConsolidationSettings
from ..extract.plugins import available_extractors
from ..files import atomic_path, write_json
from ..io.progress import Progress
from ..tasks.engine import Task, case_id, run_tasks
from ..version import provenance
from .gallery import plot_gallery

#: pass criteria (the issue's "how it is shown")
MAX_EXTRA_TENDONS = 1
MAX_REALIZABLE_POSE_REL = 0.01
MAX_LENGTH_RATIO = 2.0


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


def best_extractor(extractors: dict[str, dict], planted_count: int) -> str | None:
    """The extractor whose tendons a designer would build: the lowest realizable pose
    error among those finding at most planted + 1 tendons (else among all)."""
    ok = {n: m for n, m in extractors.items() if "error" not in m}
    if not ok:
        return None
    few = {n: m for n, m in ok.items() if m["count"] <= planted_count + MAX_EXTRA_TENDONS} or ok
    return min(few, key=lambda n: (few[n]["realizable_pose_error_rel"], few[n]["count"], n))


def run_case(scene_path: str | Path, layout: dict, level: int, out_dir: str | Path,
             overrides: dict | None = None, extractors: list[str] | None = None,
             solver: str = "auto", consolidation: dict | None = None) -> dict:
    """Optimize one planted case and run the extractors on its last stage
    (``consolidation``: the fields of :class:`~tendon_taichi.extract.consolidation.ConsolidationSettings`);
    the recording goes to ``out_dir/NAME-rLEVEL.rrd``. Returns the case's figures."""
    t0 = time.perf_counter()
    scene = load_scene(str(scene_path))
    if overrides:
        scene = with_overrides(scene, overrides)
    case = Case(Path(scene_path).stem, Path(scene_path), layout)
    name, planted_count, planted_length = case.name, case.planted_count, case.planted_length
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rec = out_dir / f"{name}-r{level}.rrd"
    result = run_one(scene, level, rec, solver, extractors, ConsolidationSettings(**(consolidation or {})))
    run = result.run
    final = run.summary["final"]
    length_ratio = final["active_length"] / planted_length if planted_length > 0 else float("inf")
    return {"case": name, "scene": run.summary.get("scene", scene.name), "level": level,
            "planted_count": planted_count, "planted_length": planted_length,
            "pose_error_rel": final["pose_error_rel"], "active_fibers": final["active_fibers"],
            "active_length": final["active_length"], "length_ratio": length_ratio,
            "stages": len(run.stages), **score_extraction(result.extraction, planted_count, length_ratio),
            "optimize_s": result.optimize_s, "time_s": time.perf_counter() - t0, "recording": str(rec)}


def score_extraction(ex, planted_count: int, length_ratio: float) -> dict:
    """A case's extraction figures: ``extractors`` (per extractor: count, lengths,
    kinks, capstan, realizable pose error, tendons, or its ``error``), the ``best``
    one (:func:`best_extractor`) and its figures, and whether the case ``passed``."""
    per = {}
    for r in ex.results:
        if r.error is not None:
            per[r.name] = {"error": r.error}
            continue
        m = r.metrics
        per[r.name] = {"count": int(m["count"]), "extracted_count": int(m["extracted_count"]),
                       "total_length": m["total_length"], "kinks": int(m["kinks"]),
                       "capstan_worst": m["capstan_worst"], "tension_cv": m["tension_cv"],
                       "realizable_pose_error_rel": m["realizable_pose_error_rel"],
                       "tendons": [t.waypoints.tolist() for t in r.tendons]}
    best = best_extractor(per, planted_count)
    b = per.get(best, {})
    passed = bool(best is not None and b["count"] <= planted_count + MAX_EXTRA_TENDONS
                  and b["realizable_pose_error_rel"] <= MAX_REALIZABLE_POSE_REL
                  and length_ratio <= MAX_LENGTH_RATIO)
    return {"extractors": per, "best": best, "count": b.get("count"), "extracted_count": b.get("extracted_count"),
            "count_ratio": (b["count"] / planted_count) if best else None,
            "realizable_pose_error_rel": b.get("realizable_pose_error_rel"),
            "kinks": b.get("kinks"), "capstan_worst": b.get("capstan_worst"), "passed": passed}


def totals(cases: list[dict]) -> dict:
    """Suite totals: cases, passes, and medians of the ratios."""
    done = [c for c in cases if "error" not in c]

    def med(key):
        vals = [c[key] for c in done if c.get(key) is not None]
        return float(np.median(vals)) if vals else None

    return {"cases": len(cases), "failed": len(cases) - len(done), "passed": sum(c["passed"] for c in done),
            "count_within_planted_plus_one": sum(1 for c in done if c["count"] is not None
                                                 and c["count"] <= c["planted_count"] + MAX_EXTRA_TENDONS),
            "median_length_ratio": med("length_ratio"), "median_count_ratio": med("count_ratio"),
            "median_realizable_pose_error_rel": med("realizable_pose_error_rel"),
            "time_s": float(sum(c.get("time_s", 0.0) for c in cases))}


CSV_COLUMNS = ("case", "scene", "level", "planted_count", "count", "extracted_count", "best", "planted_length",
               "active_length", "length_ratio", "pose_error_rel", "realizable_pose_error_rel", "kinks",
               "capstan_worst", "passed", "time_s", "error")


def write_outputs(result: dict, out_dir: Path, suite: list[Case]) -> None:
    """planted_bench.json, planted_bench.csv and gallery.png (planted vs found)."""
    write_json(result, out_dir / "planted_bench.json")
    with atomic_path(out_dir / "planted_bench.csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_COLUMNS)
            for c in result["cases"]:
                w.writerow([c.get(k, "") if c.get(k) is not None else "" for k in CSV_COLUMNS])
    plot_gallery(out_dir / "gallery.png", result, {c.name: c for c in suite})


def _case_row(case: Case, level: int, o) -> dict:
    if o.error is not None:
        return {"case": case.name, "level": level, "planted_count": case.planted_count, "error": o.error,
                "passed": False, "reused": o.reused}
    return {**o.value, "reused": o.reused}


def _describe(row: dict) -> str:
    return (f"{row['count']}/{row['planted_count']} tendons, length x{row['length_ratio']:.2f}, "
            f"realizable {100 * row['realizable_pose_error_rel']:.2f}%, {'pass' if row['passed'] else 'miss'}")


def run_suite(directory: str | Path, level: int, out_dir: str | Path, overrides: dict | None = None,
              extractors: list[str] | None = None, solver: str = "auto", cases: list[str] | None = None,
              progress=None, workers: int | None = None, scheduler: str | None = None,
              consolidation=None) -> dict:
    """Run every case of a suite (or the named ``cases``) as tasks of
    :func:`tendon_taichi.tasks.engine.run_tasks` (``workers``: local Dask cluster size,
    None: one per core, 0: in this process; ``scheduler``: an existing cluster).
    ``consolidation`` (:class:`~tendon_taichi.extract.consolidation.ConsolidationSettings`,
    default settings if None) follows every extractor.
    Outputs are rewritten after each case, and a re-run reuses the finished ones
    (``out_dir/cases/<id>/result.json``), so an interrupted run keeps what it did."""
    suite = load_suite(directory)
    if cases:
        unknown = set(cases) - {c.name for c in suite}
        if unknown:
            raise InputError(f"no such case in the suite: {', '.join(sorted(unknown))}")
        suite = [c for c in suite if c.name in cases]
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    for case in suite:  # bad scene files or settings stop the run before it starts
        with_overrides(load_scene(str(case.scene_path)), overrides)
    names = sorted(extractors or available_extractors())
    cons = dataclasses.asdict(consolidation or ConsolidationSettings())
    out_dir = Path(out_dir)
    tasks = [Task(case_id({"kind": "planted", "scene": case.scene_path.read_text(), "layout": case.layout,
                           "level": level, "settings": overrides, "extractors": names, "solver": solver,
                           "consolidation": cons}),
                  case.name, run_case,
                  (str(case.scene_path), case.layout, level, str(out_dir / "cases"), overrides, names, solver,
                   cons))
             for case in suite]
    by_name = {c.name: c for c in suite}
    result = {"suite": str(directory), "level": level, "settings": overrides, "consolidation": cons,
              "provenance": provenance(), "cases": []}
    done = {}

    def on_outcome(o) -> None:
        done[o.task.id] = _case_row(by_name[o.task.label], level, o)
        result["cases"] = [done[t.id] for t in tasks if t.id in done]
        result["totals"] = totals(result["cases"])
        write_outputs(result, out_dir, suite)

    report = run_tasks(tasks, out_dir / "cases", workers, scheduler, progress or Progress(), on_outcome, _describe,
                       setup=worker_setup(), stop=STOP)
    result["engine"] = report.engine
    if report.outcomes:
        write_outputs(result, out_dir, suite)
    if report.interrupted:
        raise Stopped(f"interrupted: {len(report.outcomes)} of {len(tasks)} case(s) finished and kept in "
                      f"'{out_dir}'; run the same command again to do the rest")
    return result


def table(result: dict) -> list[str]:
    """The human-readable table of a planted-bench result."""
    out = [f"{'case':<28} {'tendons':>8} {'best':>17} {'length':>7} {'pose':>6} {'real.':>6} {'kinks':>5} "
           f"{'capstan':>7} {'time':>6}  result"]
    for c in result["cases"]:
        if "error" in c:
            out.append(f"{c['case']:<28} failed: {c['error']}")
            continue
        out.append(f"{c['case']:<28} {c['count']:>3} / {c['planted_count']:<2} {c['best']:>17} "
                   f"x{c['length_ratio']:>5.2f} {100 * c['pose_error_rel']:>5.2f}% "
                   f"{100 * c['realizable_pose_error_rel']:>5.2f}% {c['kinks']:>5} {c['capstan_worst']:>7.3f} "
                   f"{c['time_s']:>5.0f}s  {'pass' if c['passed'] else 'miss'}")
    t = result["totals"]
    out.append(f"passed {t['passed']} of {t['cases']} ({t['failed']} failed); tendon count <= planted + 1 in "
               f"{t['count_within_planted_plus_one']}; median length ratio {t['median_length_ratio']}, "
               f"total time {t['time_s']:.0f} s")
    return out
