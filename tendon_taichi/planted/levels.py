"""``planted-bench --levels``: the suite at several resolution levels, and per case
the count/error front of every level, whether the recommended tendon count
is the same at all of them (a design that does not depend on the mesh), and
whether the front's mesh-converged errors agree across levels.

**Agreement.** For each count k up to planted + 1 that every level's front has,
the errors at the levels agree when their spread (largest - smallest) is at
most ``AGREE_ABS`` (0.1 % of L) or ``AGREE_REL`` (25 %) of the largest,
whichever is larger. The finite-element discretization alone moves an
as-built error too: the planted tendons' own as-built error, their
contractions re-solved at each level against the same goals, has a spread
across the levels; where that spread is larger than the window, the window
is that spread plus ``AGREE_SLACK`` (0.05 % of L).

**Coarse to fine.** Routes are curves in the rest body, so by default each
level after the first also searches from the coarser level's front: each
case's design there is its prior design (``design --routes-from``), whose
layouts join the seeds of its front. Which layouts the lattice leads a
search to moves with the mesh, and a layout found on a coarser mesh is a
start the finer one's search may not reach. The first level's cases design
their own coarser level first, as ``design`` does (unless the front's settings
say ``coarse = false``). ``coarse_to_fine=False`` searches each level on its
own: no priors, and no case designs a coarser level.

**The same routes.** Where the recommended count is the same at every level,
``route_shift`` is how far the recommended routes moved between levels: each
route matched with one of the other level's (the matching that moves them
least), the mean distance between the two curves (resampled at 32 points,
either way round), the largest over the routes and the pairs of levels, x L.
Within ``SAME_ROUTES`` (0.05 L) the levels recommend the same design.

Each level runs as :func:`~tendon_taichi.planted.bench.run_suite` into
``OUT/level<N>/``; ``OUT/levels.json`` holds the comparison and
``OUT/fronts.png`` one panel per case, one front line per level."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..extract.routes import resample
from ..files import write_json
from ..io.plots import new_figure, save_png
from .bench import SuiteSettings, case_folder, load_suite, run_suite

#: the front's errors at several levels agree within this (x L) ...
AGREE_ABS = 1e-3
#: ... or this fraction of the largest, whichever is larger
AGREE_REL = 0.25
#: added to the planted tendons' own spread where that is wider (x L)
AGREE_SLACK = 5e-4
#: the recommended routes at several levels are the same design when they moved at most this (x L)
SAME_ROUTES = 0.05


def run_levels(directory: str | Path, levels: list[int], out_dir: str | Path, coarse_to_fine: bool = True,
               settings: SuiteSettings = SuiteSettings(), **kwargs) -> dict:
    """The suite at each of ``levels`` (``settings`` and ``kwargs`` as for ``run_suite``;
    its ``priors`` set here), from the
    coarsest up, each after the first searching from the one before's designs too
    (``coarse_to_fine``, module docstring); then the comparison
    (:func:`compare_levels`), written to ``out_dir/levels.json`` and
    ``out_dir/fronts.png``."""
    out_dir = Path(out_dir)
    runs: dict[int, dict] = {}
    order = sorted(levels)
    if not coarse_to_fine:
        settings = replace(settings, front=replace(settings.front, coarse=False))
    for lv, before in zip(order, [None] + order[:-1]):
        priors = prior_designs(directory, out_dir / f"level{before}", before) if coarse_to_fine and before else None
        runs[lv] = run_suite(directory, lv, out_dir / f"level{lv}", replace(settings, priors=priors), **kwargs)
    result = {**compare_levels(runs), "coarse_to_fine": coarse_to_fine}
    write_json(result, out_dir / "levels.json")
    save_png(fronts_figure(result), out_dir / "fronts.png", 90)
    return result


def prior_designs(directory: str | Path, level_dir: str | Path, level: int) -> dict[str, Path]:
    """Per case of the suite in ``directory``, its design at ``level`` (``design.json``,
    as :func:`~.bench.run_suite` into ``level_dir`` wrote it), where one was written."""
    found = {c.name: case_folder(Path(level_dir) / "cases", c.name, level) / "design.json"
             for c in load_suite(directory)}
    return {name: path for name, path in found.items() if path.is_file()}


def compare_levels(runs: dict[int, dict]) -> dict:
    """Per case (those finished at every level): the recommended ``counts`` per level,
    ``same_count`` (the same at all), the planted count, per level the ``fronts``
    (count, as-built error - the mesh-converged one - and where each came from),
    and the errors' ``agreement`` (:func:`agreement`); ``same_count`` and
    ``errors_agree`` in all, and the runs' totals per level."""
    levels = sorted(runs)
    rows = {lv: {c["case"]: c for c in runs[lv]["cases"] if "error" not in c} for lv in levels}
    names = sorted(set.intersection(*(set(r) for r in rows.values()))) if rows else []
    cases = []
    for name in names:
        counts = {str(lv): rows[lv][name]["count"] for lv in levels}
        cases.append({"case": name, "planted_count": rows[levels[0]][name]["planted_count"], "counts": counts,
                      "same_count": len(set(counts.values())) == 1,
                      "fronts": {str(lv): [{k: e[k] for k in ("count", "realizable_pose_error_rel", "source")}
                                           for e in rows[lv][name]["front"]] for lv in levels}})
        cases[-1]["agreement"] = agreement(cases[-1], {str(lv): rows[lv][name].get("planted_as_built_error_rel")
                                                       for lv in levels})
        cases[-1]["route_shift"] = route_shift([rows[lv][name] for lv in levels])
    budget = (runs[levels[0]].get("consolidation") or {}).get("budget") if levels else None
    return {"levels": levels, "cases": cases, "same_count": sum(c["same_count"] for c in cases),
            "errors_agree": sum(c["agreement"]["agree"] for c in cases),
            "same_routes": sum(c["route_shift"] is not None and c["route_shift"] <= SAME_ROUTES for c in cases),
            "budget": budget or 0.005, "totals": {str(lv): runs[lv]["totals"] for lv in levels}}


def route_shift(rows: list[dict]) -> float | None:
    """How far a case's recommended routes moved between levels (module docstring),
    x L, from its row at each level (``tendons``: each route's waypoints (k, 2) m;
    ``body_size`` m, or - rows written before they held it - read from the
    ``design.json`` beside the ``recording``); None where the counts differ."""
    if any(r.get("tendons") is None for r in rows) or len({len(r["tendons"]) for r in rows}) != 1:
        return None
    size = next((s for s in map(_body_size, rows) if s), None)
    curves = [[resample(np.asarray(w, dtype=float), 32)[0] for w in r["tendons"]] for r in rows]
    shift = 0.0
    for a, b in itertools.combinations(curves, 2):
        far = [[min(np.linalg.norm(p - q, axis=1).mean(), np.linalg.norm(p - q[::-1], axis=1).mean()) for q in b]
               for p in a]
        shift = max(shift, min((max((far[i][j] for i, j in enumerate(perm)), default=0.0)
                                for perm in itertools.permutations(range(len(b)))), default=0.0))
    return None if size is None else shift / size


def _body_size(row: dict) -> float | None:
    """A case row's body size L (m): its own, or its design.json's."""
    if row.get("body_size"):
        return float(row["body_size"])
    try:
        return float(json.loads((Path(row["recording"]).parent / "design.json").read_text())["body_size"])
    except (KeyError, TypeError, OSError, ValueError):
        return None


def agreement(case: dict, planted: dict[str, float | None]) -> dict:
    """Whether a case's front errors agree across levels (module docstring):
    ``planted_errors`` (the planted tendons' as-built error per level) and their
    ``planted_spread`` (None if one could not be solved), and per count k up to
    planted + 1 its ``errors`` per level (None where that level's front stops
    below k), ``spread``, ``window`` and ``agree``; ``agree`` holds when every
    count the levels share agrees, ``compared`` lists those counts."""
    known = [e for e in planted.values() if e is not None]
    planted_spread = max(known) - min(known) if known and len(known) == len(planted) else None
    counts = {}
    for k in range(1, case["planted_count"] + 2):
        errors = {lv: next((e["realizable_pose_error_rel"] for e in front if e["count"] == k), None)
                  for lv, front in case["fronts"].items()}
        row = {"errors": errors}
        if all(e is not None for e in errors.values()):
            spread = max(errors.values()) - min(errors.values())
            window = max(AGREE_ABS, AGREE_REL * max(errors.values()))
            if planted_spread is not None and planted_spread > window:
                window = planted_spread + AGREE_SLACK
            row.update(spread=spread, window=window, agree=bool(spread <= window))
        counts[str(k)] = row
    compared = [int(k) for k, r in counts.items() if "agree" in r]
    return {"planted_errors": planted, "planted_spread": planted_spread, "counts": counts, "compared": compared,
            "agree": all(counts[str(k)]["agree"] for k in compared)}


def table(result: dict) -> list[str]:
    """Per case the recommended count at each level, whether it is the same, and
    whether the front's errors agree (the widest spread over the counts compared,
    and the planted tendons' own spread, % of L)."""
    levels = result["levels"]
    out = [f"{'case':<26} {'planted':>7} " + " ".join(f"{f'level {lv}':>8}" for lv in levels)
           + "  same  errors  widest spread  planted spread  routes moved"]
    for c in result["cases"]:
        a = c["agreement"]
        spreads = [a["counts"][str(k)]["spread"] for k in a["compared"]]
        widest = f"{100 * max(spreads):.3f}%" if spreads else "-"
        planted = "-" if a["planted_spread"] is None else f"{100 * a['planted_spread']:.3f}%"
        out.append(f"{c['case']:<26} {c['planted_count']:>7} "
                   + " ".join(f"{c['counts'][str(lv)]:>8}" for lv in levels)
                   + f"  {'yes' if c['same_count'] else 'no':>4}  {'agree' if a['agree'] else 'differ':>6}"
                   + f"  {widest:>13}  {planted:>14}  {_moved(c.get('route_shift')):>12}")
    n = len(result["cases"])
    out.append(f"the same recommended count at every level in {result['same_count']} of {n} cases, "
               f"the same routes (moved at most {SAME_ROUTES:g} L) in {result.get('same_routes', 0)}; the front's "
               f"errors agree up to planted + 1 tendons in {result['errors_agree']} of {n}"
               + ("; each level after the first also searched from the one before's designs"
                  if result.get("coarse_to_fine") else "; each level searched on its own"))
    return out


def _moved(shift: float | None) -> str:
    return "-" if shift is None else f"{shift:.3f} L"


def fronts_figure(result: dict, columns: int = 4):
    """One panel per case: as-built error (% of L, log) against tendon count, one
    line per level; the planted count dotted, the budget dashed."""
    cases = result["cases"]
    columns = max(1, min(columns, len(cases)))
    rows = max(1, -(-len(cases) // columns))
    fig = new_figure(figsize=(3.2 * columns, 2.6 * rows))
    axes = fig.subplots(rows, columns, squeeze=False).ravel()
    for ax, c in zip(axes, cases):
        for lv in result["levels"]:
            front = c["fronts"][str(lv)]
            ax.plot([e["count"] for e in front], [max(100 * e["realizable_pose_error_rel"], 1e-4) for e in front],
                    "o-", ms=3, label=f"level {lv}: {c['counts'][str(lv)]}")
        ax.axvline(c["planted_count"], ls=":", color="0.4")
        ax.axhline(100 * result.get("budget", 0.005), ls="--", color="0.6", lw=0.8)
        ax.set_xticks(sorted({e["count"] for f in c["fronts"].values() for e in f} | {c["planted_count"]}))
        ax.set_yscale("log")
        ax.set_title(f"{c['case']}{'' if c['same_count'] else ' (count moves)'}", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=5, title="recommended", title_fontsize=5)
    for ax in axes[len(cases):]:
        ax.axis("off")
    fig.supxlabel("tendons", fontsize=8)
    fig.supylabel("as-built pose error (% of L)", fontsize=8)
    fig.tight_layout()
    return fig
