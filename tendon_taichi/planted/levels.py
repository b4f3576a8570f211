"""``planted-bench --levels``: the suite at several resolution levels, and per case
the count/error front of every level and whether the recommended tendon count
is the same at all of them (a design that does not depend on the mesh).

Each level runs as :func:`~tendon_taichi.planted.bench.run_suite` into
``OUT/level<N>/``; ``OUT/levels.json`` holds the comparison and
``OUT/fronts.png`` one panel per case, one front line per level."""

from __future__ import annotations

from pathlib import Path

from ..files import write_json
from ..io.plots import new_figure, save_png
from .bench import run_suite


def run_levels(directory: str | Path, levels: list[int], out_dir: str | Path, **kwargs) -> dict:
    """The suite at each of ``levels`` (``kwargs`` as for ``run_suite``), then the
    comparison (:func:`compare_levels`), written to ``out_dir/levels.json`` and
    ``out_dir/fronts.png``."""
    out_dir = Path(out_dir)
    runs = {lv: run_suite(directory, lv, out_dir / f"level{lv}", **kwargs) for lv in levels}
    result = compare_levels(runs)
    write_json(result, out_dir / "levels.json")
    save_png(fronts_figure(result), out_dir / "fronts.png", 90)
    return result


def compare_levels(runs: dict[int, dict]) -> dict:
    """Per case (those finished at every level): the recommended ``counts`` per level,
    ``same_count`` (the same at all), the planted count, and per level the
    ``fronts`` (count, as-built error - the mesh-converged one - and where each
    came from); ``same_count`` in all, and the runs' totals per level."""
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
    budget = (runs[levels[0]].get("consolidation") or {}).get("budget") if levels else None
    return {"levels": levels, "cases": cases, "same_count": sum(c["same_count"] for c in cases),
            "budget": budget or 0.005, "totals": {str(lv): runs[lv]["totals"] for lv in levels}}


def table(result: dict) -> list[str]:
    """Per case the recommended count at each level, and whether it is the same."""
    levels = result["levels"]
    out = [f"{'case':<26} {'planted':>7} " + " ".join(f"{f'level {lv}':>8}" for lv in levels) + "  same"]
    for c in result["cases"]:
        out.append(f"{c['case']:<26} {c['planted_count']:>7} "
                   + " ".join(f"{c['counts'][str(lv)]:>8}" for lv in levels) + f"  {'yes' if c['same_count'] else 'no'}")
    out.append(f"the same recommended count at every level in {result['same_count']} of {len(result['cases'])} cases")
    return out


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
