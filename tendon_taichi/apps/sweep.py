"""``sweep``: many independent design cases as Dask tasks (``docs/cli.md``).

A sweep file names scenes, levels, extractors and a grid of ``[optimize]``
settings (and the ``[tendons]`` ones, ``friction`` and ``clearance``); every
(scene, level, grid point) is a case. Each case runs the ``design`` pipeline
(optimize, the extractors on its last stage with consolidation and route
optimization, the recommended design), and writes ``DIR/cases/<id>/``
(``run.rrd``, ``run.npz``, ``design.json``, ``design.svg``, ``optimize.json``,
``compare.json``, and ``result.json``, the figures the sweep keeps). The
sweep writes ``DIR/sweep.json``, ``DIR/sweep.csv`` and ``DIR/sweep.png``.
Cases (:func:`tendon_taichi.apps.case.run_case`) run through :func:`tendon_taichi.tasks.engine.run_tasks`: a local Dask
cluster by default, an existing one by scheduler address, or in this process.

On a cluster whose workers do not share DIR's file system, each case's
recording stays on the machine that ran it; ``result.json``, ``sweep.json``,
``sweep.csv`` and ``sweep.png`` are always written where the command runs.
"""

from __future__ import annotations

import csv
import hashlib
import math
import itertools
import time
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path

from ..body.scene import Scene, load_scene, with_overrides
from ..errors import InputError, Stopped
from ..extract.plugins import available_extractors, unknown_extractor
from ..extract.settings import BUDGET, FRONT_DEFAULTS, ConsolidationSettings, FrontSettings, front_id
from ..files import atomic_path, write_json
from ..io.plots import plot_sweep
from ..io.progress import Progress
from ..solve.linear import SOLVERS
from ..tasks.engine import Cluster, Task, case_id, run_tasks
from .case import STOP, CaseSettings, worker_setup
from .case import run_case as run_one
from .provenance import result_provenance

SWEEP_KEYS = ("name", "scenes", "levels", "extractors", "solver", "grid", "set", "consolidation", "front")
#: grid and set keys that are [tendons] settings (the others are [optimize] ones)
TENDON_KEYS = ("friction", "clearance", "exit")


class SweepInterrupted(Stopped):
    """Ctrl-C during a sweep; ``result`` holds the finished cases (also on disk)."""

    def __init__(self, result: dict, out_dir: Path):
        done = len(result["cases"])
        super().__init__(f"interrupted: {done} case(s) finished and kept in '{out_dir}' (sweep.json, "
                         f"sweep.csv); run the same command again to do the rest")
        self.result = result


@dataclass(frozen=True)
class SweepCase:
    """One (scene, level, grid point): the validated ``scene`` with the point's
    settings applied, ``settings`` (the sweep's [set] plus the grid point) and ``id``."""

    id: str
    scene: Scene
    level: int
    settings: dict
    point: dict  # the grid point alone

    @property
    def label(self) -> str:
        return f"{self.scene.name} L{self.level}" + "".join(f" {k}={_text(v)}" for k, v in self.point.items())


def _text(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


@dataclass(frozen=True)
class Sweep:
    """A validated sweep file."""

    name: str
    path: Path | None
    scenes: tuple[Scene, ...]
    levels: tuple[int, ...]
    extractors: tuple[str, ...]
    solver: str
    grid: dict
    fixed: dict
    cases: tuple[SweepCase, ...]
    consolidation: dict = field(default_factory=dict)  # the [consolidation] table: ConsolidationSettings fields
    front: dict = field(default_factory=lambda: dict(FRONT_DEFAULTS))  # the [front] table over the defaults

    def case_settings(self) -> CaseSettings:
        """How each case is designed: the sweep's solver, extractors, [consolidation]
        (its budget, else the default, also picks the recommendation) and [front]."""
        cons = ConsolidationSettings(**self.consolidation)
        return CaseSettings(solver=self.solver, extractors=tuple(self.extractors), consolidation=cons,
                            budget=cons.budget or BUDGET, front=FrontSettings(**self.front))


def _fail(origin: str, msg: str):
    raise InputError(f"sweep file '{origin}': {msg}")


def _scene(entry, base: Path, origin: str) -> Scene:
    if not isinstance(entry, str) or not entry:
        _fail(origin, f"scenes entries must be built-in names or paths (got {entry!r})")
    path = Path(entry) if Path(entry).is_absolute() else base / entry
    return load_scene(path if entry.endswith(".toml") or path.is_file() else entry)


def _scene_digest(scene: Scene) -> dict:
    """What identifies a scene: its file's text, and the mesh file it names."""
    out = {"scene": scene.source}
    mesh = scene.body.mesh_file
    if mesh is not None:
        out["mesh"] = hashlib.sha256(Path(mesh).read_bytes()).hexdigest()
    return out


def parse_sweep(doc: dict, origin: str = "<sweep>", base: Path | None = None,
                tendons: dict | None = None) -> Sweep:
    """Validate a parsed sweep file and expand it into cases (scene x level x grid
    point); ``tendons`` replaces [tendons] settings of every scene (command line)."""
    base = base or Path.cwd()
    unknown = sorted(set(doc) - set(SWEEP_KEYS))
    if unknown:
        _fail(origin, f"unknown key '{unknown[0]}' (known: {', '.join(SWEEP_KEYS)})")
    name = doc.get("name", Path(origin).stem)
    if not isinstance(name, str) or not name:
        _fail(origin, "'name' must be a non-empty string")
    scenes = doc.get("scenes")
    if not isinstance(scenes, list) or not scenes:
        _fail(origin, "'scenes' must be a non-empty list of built-in scene names or scene files")
    levels = doc.get("levels", [1])
    if (not isinstance(levels, list) or not levels
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in levels)):
        _fail(origin, f"'levels' must be a non-empty list of integers >= 1 (got {levels!r})")
    extractors = doc.get("extractors", sorted(available_extractors()))
    if not isinstance(extractors, list) or not extractors or not all(isinstance(e, str) for e in extractors):
        _fail(origin, "'extractors' must be a non-empty list of extractor names")
    unknown = unknown_extractor(extractors)
    if unknown:
        _fail(origin, unknown)
    solver = doc.get("solver", "auto")
    if solver not in SOLVERS:
        _fail(origin, f"'solver' must be one of {', '.join(SOLVERS)} (got {solver!r})")
    grid, fixed = doc.get("grid", {}), doc.get("set", {})
    if not isinstance(grid, dict) or not isinstance(fixed, dict):
        _fail(origin, "[grid] and [set] must be tables of [optimize] settings")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            _fail(origin, f"grid.{key} must be a non-empty list of values")
    for key in set(grid) & set(fixed):
        _fail(origin, f"'{key}' is both in [grid] and in [set]")
    consolidation = _consolidation(doc.get("consolidation", {}), origin)
    front = _front(doc.get("front", {}), origin)
    loaded = [_scene(s, base, origin) for s in scenes]
    given = {k: v for k, v in (tendons or {}).items() if v is not None}
    cases = []
    for scene, level in itertools.product(loaded, levels):
        for point in itertools.product(*grid.values()):
            point = dict(zip(grid, point))
            settings = {**fixed, **point}
            where = f"sweep file '{origin}'"
            sc = with_overrides(scene, {k: v for k, v in settings.items() if k not in TENDON_KEYS}, origin=where)
            sc = sc.with_tendons(where, **{k: v for k, v in settings.items() if k in TENDON_KEYS})
            sc = sc.with_tendons(**given)
            cid = case_id({"kind": "sweep-design", **_scene_digest(scene), "level": level, "settings": settings,
                           "tendons": given, "extractors": list(extractors), "solver": solver,
                           "consolidation": consolidation, **front_id(front)})
            cases.append(SweepCase(cid, sc, level, settings, point))
    return Sweep(name, None, tuple(loaded), tuple(levels), tuple(extractors), solver=solver, grid=dict(grid),
                 fixed=dict(fixed), cases=tuple(cases), consolidation=consolidation, front=front)


def _consolidation(table, origin: str) -> dict:
    """The [consolidation] table: fields of ConsolidationSettings, checked."""
    if not isinstance(table, dict):
        _fail(origin, "[consolidation] must be a table")
    known = {f.name: f for f in fields(ConsolidationSettings)}
    for key, value in table.items():
        if key not in known:
            _fail(origin, f"unknown consolidation setting '{key}' (known: {', '.join(known)})")
        whole = known[key].type in (int, "int")
        ok = isinstance(value, int) if whole else isinstance(value, (int, float)) and math.isfinite(value)
        if isinstance(value, bool) or not ok or (value < 0 and key != "tolerance"):
            _fail(origin, f"consolidation.{key} must be {'an integer' if whole else 'a number'} >= 0 "
                          f"(got {value!r})")
    return dict(table)


def _front(table, origin: str) -> dict:
    """The [front] table (``beam``, an integer >= 1; ``converge`` and ``coarse``, true
    or false) over :data:`~tendon_taichi.extract.settings.FRONT_DEFAULTS`, checked."""
    if not isinstance(table, dict):
        _fail(origin, "[front] must be a table")
    for key, value in table.items():
        if key not in FRONT_DEFAULTS:
            _fail(origin, f"unknown front setting '{key}' (known: {', '.join(FRONT_DEFAULTS)})")
        if key == "beam" and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            _fail(origin, f"front.beam must be an integer >= 1 (got {value!r})")
        if key in ("converge", "coarse") and not isinstance(value, bool):
            _fail(origin, f"front.{key} must be true or false (got {value!r})")
    return {**FRONT_DEFAULTS, **table}


def load_sweep(path: str | Path, tendons: dict | None = None) -> Sweep:
    """Read and validate a sweep file (TOML); scene paths are relative to it;
    ``tendons`` replaces [tendons] settings (:func:`parse_sweep`)."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"sweep file '{path}' does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read sweep file '{path}': {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"sweep file '{path}': invalid TOML: {exc}") from None
    except RecursionError:
        raise InputError(f"sweep file '{path}': invalid TOML: arrays or tables nested too deeply") from None
    sw = parse_sweep(doc, str(path), path.resolve().parent, tendons)
    return Sweep(**{**sw.__dict__, "path": path})


# ---------------------------------------------------------------- one case
#: the figures of the recommended design a sweep keeps
DESIGN_KEYS = ("realizable_pose_error_rel", "realizable_pose_error_rel_frictionless", "capstan_worst", "kinks",
               "clearance_min", "total_length")


def run_case(scene: Scene, level: int, case_dir: str, settings: CaseSettings = CaseSettings()) -> dict:
    """Design ``scene`` at ``level`` as ``settings`` say (:meth:`Sweep.case_settings`)
    into ``case_dir`` (``run.rrd``, ``run.npz``, ``design.json``, ``design.svg``,
    ``optimize.json``, ``compare.json``). Returns the case's
    figures: ``optimize`` (the final stage), ``extract`` (per extractor its
    metrics, or its error), ``design`` (the recommended design's count, source
    and figures), ``stages``."""
    d = Path(case_dir)
    case = run_one(scene, level, d, settings)
    run, comp = case.run, case.extraction.as_json()
    write_json(run.summary, d / "optimize.json")
    write_json(comp, d / "compare.json")
    rec = case.summary["recommended"]
    return {"optimize": run.summary["final"], "stages": len(run.stages), "optimize_s": run.summary["time_s"],
            "warnings": run.warnings,
            "extract": {e["name"]: ({"error": e["error"]} if "error" in e else e["metrics"])
                        for e in comp["extractors"]},
            "design": {"count": rec["count"], "source": rec["source"],
                       **{k: rec["metrics"][k] for k in DESIGN_KEYS}}}


def _describe(value: dict) -> str:
    f, d = value["optimize"], value["design"]
    return (f"pose {100 * f['pose_error_rel']:.2f}%, active {100 * f['active_length']:.1f} cm, design: "
            f"{d['count']} tendon(s) from {d['source']}, as built {100 * d['realizable_pose_error_rel']:.2f}%, "
            f"capstan {d['capstan_worst']:.2f}")


# ---------------------------------------------------------------- the sweep
def run(sweep: Sweep | str | Path, out_dir: str | Path, workers: int | None = None, scheduler: str | None = None,
        progress=None) -> dict:
    """Run every case of ``sweep`` (a :class:`Sweep` or a sweep file) and write
    ``out_dir``'s ``sweep.json``, ``sweep.csv``, ``sweep.png`` and ``cases/``.
    ``workers``: local cluster size (None: one per core; 0: in this process);
    ``scheduler``: the address of an existing Dask cluster. Returns sweep.json's
    content; raises :class:`SweepInterrupted` (after writing) on Ctrl-C."""
    sw = sweep if isinstance(sweep, Sweep) else load_sweep(sweep)
    out = Path(out_dir)
    t0 = time.perf_counter()
    settings = sw.case_settings()
    tasks = [Task(c.id, c.label, run_case, (c.scene, c.level, str(out / "cases" / c.id), settings)) for c in sw.cases]
    report = run_tasks(tasks, out / "cases", Cluster(workers, scheduler, setup=worker_setup(), stop=STOP),
                       progress or Progress(), describe=_describe)
    by_id = {c.id: c for c in sw.cases}
    rows = [case_row(by_id[o.task.id], o) for o in report.outcomes]
    result = {"name": sw.name, "sweep": str(sw.path) if sw.path else None,
              "scenes": [s.name for s in sw.scenes], "levels": list(sw.levels), "extractors": list(sw.extractors),
              "solver": sw.solver, "grid": sw.grid, "set": sw.fixed, "consolidation": sw.consolidation,
              "front": sw.front, "cases": rows,
              "failed": sum("error" in r for r in rows), "reused": sum(r["reused"] for r in rows),
              "interrupted": report.interrupted, "engine": report.engine, "provenance": result_provenance(),
              "time_s": time.perf_counter() - t0}
    write_outputs(result, out)
    if report.interrupted:
        raise SweepInterrupted(result, out)
    return result


def case_row(case: SweepCase, o) -> dict:
    """A sweep.json entry: the case's inputs and figures (or its error)."""
    row = {"case": case.id, "scene": case.scene.name, "level": case.level, "settings": case.settings,
           "reused": o.reused, "time_s": o.time_s}
    if o.error is not None:
        row["error"] = o.error
        if o.traceback:
            row["traceback"] = o.traceback
    else:
        v = o.value
        row.update(optimize=v["optimize"], extract=v["extract"], design=v["design"], stages=v["stages"],
                   optimize_s=v["optimize_s"], warnings=v.get("warnings", []))
    if o.worker:
        row["worker"] = o.worker
    return row


def _flat(prefix: str, value, out: dict) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flat(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif not isinstance(value, list):
        out[prefix] = value


def csv_rows(result: dict) -> tuple[list[str], list[dict]]:
    """sweep.csv: one row per case, figures flattened (``extract.<name>.<metric>``)."""
    keys = ("case", "scene", "level", "settings", "reused", "optimize", "stages", "optimize_s", "extract",
            "design", "time_s", "error")
    rows, columns = [], []
    for r in result["cases"]:
        flat: dict = {}
        for k in keys:
            if k in r:
                _flat(k, r[k], flat)
        rows.append(flat)
        columns += [c for c in flat if c not in columns]
    return columns, rows


def write_outputs(result: dict, out: Path) -> None:
    """sweep.json, sweep.csv and sweep.png (figures against the swept settings)."""

    out.mkdir(parents=True, exist_ok=True)
    columns, rows = csv_rows(result)
    with atomic_path(out / "sweep.csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=columns)
            w.writeheader()
            w.writerows(rows)
    if any("error" not in r for r in result["cases"]):
        plot_sweep(out / "sweep.png", result)
    write_json(result, out / "sweep.json")


def table(result: dict) -> list[str]:
    """The human-readable table of a sweep."""
    names = result["extractors"]
    head = f"{'case':<16} {'scene':<12} {'lvl':>3} {'settings':<34} {'pose':>6} {'active':>7} " + \
           " ".join(f"{n[:12]:>12}" for n in names) + f" {'design':>12} {'time':>6}"
    rows = [head]
    for r in result["cases"]:
        s = " ".join(f"{k}={_text(v)}" for k, v in r["settings"].items() if k in result["grid"])
        start = f"{r['case']:<16} {r['scene'][:12]:<12} {r['level']:>3} {s[:34]:<34}"
        if "error" in r:
            rows.append(f"{start} failed: {r['error']}")
            continue
        f = r["optimize"]
        ex = " ".join(f"{_tendon_text(r['extract'].get(n, {})):>12}" for n in names)
        rows.append(f"{start} {100 * f['pose_error_rel']:>5.2f}% {100 * f['active_length']:>5.1f}cm {ex} "
                    f"{_tendon_text(r.get('design', {})):>12} {r['time_s']:>5.0f}s" + (" (reused)" if r["reused"] else ""))
    rows.append(f"{len(result['cases'])} cases, {result['failed']} failed, {result['reused']} reused; "
                f"columns per extractor and for the recommended design: tendons / as-built pose error; "
                f"{result['time_s']:.0f} s")
    return rows


def _tendon_text(m: dict) -> str:
    if "count" not in m:
        return "failed"
    return f"{m['count']} / {100 * m['realizable_pose_error_rel']:.2f}%"


__all__ = ["Sweep", "SweepCase", "SweepInterrupted", "load_sweep", "parse_sweep", "run", "run_case", "table"]
