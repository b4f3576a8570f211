"""Pictures (matplotlib, headless): the tension pattern over the deformed body, an
extraction's tendons on their realizable robot, the benchmark's and a sweep's
figures, and the method in five panels.

Each ``*_figure`` function builds a :class:`matplotlib.figure.Figure` (no
pyplot state), so tests can check what it draws; each ``plot_*`` writes one
atomically as a PNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..body.exits import beyond
from ..body.problem import Problem
from ..files import atomic_path
from ..version import provenance


def png_metadata() -> dict[str, str]:
    """What a PNG records of the code that drew it (its provenance)."""
    p = provenance()
    return {"Software": f"tendon-taichi {p['version']}",
            "Comment": f"commit {p['commit'] or 'unknown'}{' (with uncommitted changes)' if p['dirty'] else ''}; "
                       f"made by {p['made_by']}"}


def save_png(fig, path: str | Path, dpi: int) -> Path:
    """Write the figure ``fig`` to ``path`` as a PNG (with :func:`png_metadata`), atomically."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", metadata=png_metadata())
    return Path(path)


def load() -> None:
    """Import what the pictures use of matplotlib (a noticeable start-up) ahead of the first
    one: ``design``'s workers do as they start, and draw its pictures."""
    import matplotlib.backends.backend_agg  # noqa: F401 - what savefig writes a PNG with
    from matplotlib.collections import LineCollection  # noqa: F401
    from matplotlib.figure import Figure  # noqa: F401


def new_figure(**kwargs):
    """A matplotlib Figure of its own (no pyplot state, headless)."""
    from matplotlib.figure import Figure

    return Figure(**kwargs)


def palette() -> list[str]:
    """matplotlib's default colour cycle."""
    import matplotlib

    return matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]


def _axes_tensions(ax, problem: Problem, x: np.ndarray, tau: np.ndarray, threshold: float,
                   scale: float, title: str):
    from matplotlib.collections import LineCollection

    T = problem.mesh.triangles
    ax.triplot(problem.mesh.nodes[:, 0], problem.mesh.nodes[:, 1], T, color="0.88", lw=0.4)
    ax.triplot(x[:, 0], x[:, 1], T, color="0.72", lw=0.4)
    c = problem.fibers.embedding.positions(T, x)
    seg = c[problem.fibers.edges]
    active = tau > threshold
    ax.add_collection(LineCollection(seg[~active], colors="0.8", linewidths=0.3))
    order = np.argsort(tau[active])
    lc = LineCollection(seg[active][order], cmap="inferno_r", linewidths=2.2)
    lc.set_array(tau[active][order])
    lc.set_clim(0.0, max(2.0 * scale, float(tau.max()) if len(tau) else 1.0))
    ax.add_collection(lc)
    now = problem.target_positions(x)
    goal = problem.target_goal
    ax.scatter(goal[:, 0], goal[:, 1], s=40, marker="x", color="tab:green", zorder=5, label="goal")
    ax.scatter(now[:, 0], now[:, 1], s=18, color="tab:blue", zorder=5, label="target")
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    return lc


def plot_stages(path: str | Path, problem: Problem, panels: list[tuple], threshold: float, scale: float) -> Path:
    """:func:`stages_figure` as a PNG."""
    return save_png(stages_figure(problem, panels, threshold, scale), path, 130)


def stages_figure(problem: Problem, panels: list[tuple], threshold: float, scale: float):
    """One panel per (title, x, tau[, pose]): fibers coloured by tension (N) over the
    deformed mesh (grey: rest), the targets of ``pose`` (default 0) (blue) and their
    goals (green); fibers at most ``threshold`` (N) are slack."""
    fig = new_figure(figsize=(4.2 * len(panels), 4.0))
    axes = fig.subplots(1, len(panels), squeeze=False)
    lc = None
    for ax, (title, x, tau, *pose) in zip(axes[0], panels):
        lc = _axes_tensions(ax, problem.pose(pose[0] if pose else 0), x, tau, threshold, scale=scale, title=title)
    axes[0][0].legend(loc="lower left", fontsize=7)
    if lc is not None:
        fig.colorbar(lc, ax=list(axes[0]), shrink=0.8, label="fiber tension (N)")
    return fig


def plot_compare(path: str | Path, extraction) -> Path:
    """:func:`compare_figure` as a PNG."""
    return save_png(compare_figure(extraction), path, 130)


def compare_figure(extraction):
    """The idealized tension pattern beside each extractor's tendons drawn on its
    realizable robot's equilibrium (targets blue, goals green)."""
    p, st = extraction.problem, extraction.state
    ok = [r for r in extraction.results if r.error is None]
    fig = new_figure(figsize=(4.2 * (1 + len(ok)), 4.0))
    axes = fig.subplots(1, 1 + len(ok), squeeze=False)
    scale = max(float(st.tau.max()), 1e-9)
    lc = _axes_tensions(axes[0][0], p, st.x, st.tau, st.active_threshold, scale=scale / 2.0,
                        title=f"idealized (stage {extraction.stage}): {int(st.active.sum())} active, "
                              f"{100 * extraction.idealized_pose_error / p.size:.2f}% pose")
    T = p.mesh.triangles
    colors = palette()
    for ax, r in zip(axes[0][1:], ok):
        x = r.realizable.x
        ax.triplot(p.mesh.nodes[:, 0], p.mesh.nodes[:, 1], T, color="0.88", lw=0.4)
        ax.triplot(x[:, 0], x[:, 1], T, color="0.72", lw=0.4)
        for i, t in enumerate(r.tendons):
            path_xy = p.embed_waypoints(t.nodes, t.waypoints).positions(T, x)
            ax.plot(path_xy[:, 0], path_xy[:, 1], color=colors[i % len(colors)], lw=2.2)
            ax.plot(*path_xy[0], "o", color=colors[i % len(colors)], ms=4)
            ax.plot(*path_xy[-1], "s", color=colors[i % len(colors)], ms=4)
        first = p.pose(0)  # several poses: the first pose's equilibrium and targets
        now, goal = first.target_positions(x), first.target_goal
        ax.scatter(goal[:, 0], goal[:, 1], s=40, marker="x", color="tab:green", zorder=5)
        ax.scatter(now[:, 0], now[:, 1], s=18, color="tab:blue", zorder=5)
        m = r.metrics
        ax.set_title(f"{r.name}: {m['count']} tendons, {m['kinks']} kinks\n"
                     f"realizable pose {100 * m['realizable_pose_error_rel']:.2f}% of L", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(lc, ax=axes[0][0], shrink=0.7, label="fiber tension (N)")
    return fig


def _quality_series(rows: list[dict]) -> dict[str, list[dict]]:
    """Per series name, one dict per level with that level's optimization figures
    (empty where none ran). When no level ran more than one solver's optimization
    (``--optimize-solver auto``), all levels form one series, ``auto``."""
    solvers = sorted({s for r in rows for s, f in r["solvers"].items() if "active_length" in f})
    if all(sum("active_length" in f for f in r["solvers"].values()) <= 1 for r in rows) and len(solvers) > 1:
        return {"auto": [next((f for f in r["solvers"].values() if "active_length" in f), {}) for r in rows]}
    return {s: [r["solvers"].get(s, {}) if "active_length" in r["solvers"].get(s, {}) else {} for r in rows]
            for s in solvers}


def plot_bench(path: str | Path, result: dict, timings: tuple[str, ...]) -> Path:
    """:func:`bench_figure` as a PNG."""
    return save_png(bench_figure(result, timings), path, 120)


def bench_figure(result: dict, timings: tuple[str, ...]):
    """Left: time against DOFs (log-log) per operation and solver, with the fitted
    exponent in the legend. Right, against the level: active length and
    idealized pose error; tendon count per extractor; realizable pose error per
    extractor. ``timings``: the figures (keys ending in ``_s``) to draw, in order."""
    rows = result["levels"]
    fig = new_figure(figsize=(14, 6))
    grid = fig.add_gridspec(3, 2, width_ratios=(1.35, 1))
    ax = fig.add_subplot(grid[:, 0])
    qa, qt, qr = (fig.add_subplot(grid[i, 1]) for i in range(3))
    markers = dict(zip(timings, "osD^v*"))
    styles = ["-", "--", ":", "-."]
    solvers = sorted({s for r in rows for s in r["solvers"]})
    for si, s in enumerate(solvers):
        for key in timings:
            pts = [(r["dofs"], r["solvers"][s][key]["median"]) for r in rows
                   if s in r["solvers"] and r["solvers"][s].get(key)]
            if not pts:
                continue
            k = result["exponents"].get(s, {}).get(key)
            label = f"{s}: {key[:-2]}" + (f" (~DOFs^{k:.2f})" if k is not None else "")
            ax.loglog(*zip(*pts), styles[si % len(styles)], marker=markers[key], label=label)
    ax.set_xlabel("free DOFs")
    ax.set_ylabel("seconds (median)")
    ax.set_title(f"{result['scene']}: cost against resolution", fontsize=10)
    ax.legend(fontsize=6.5, ncol=2)
    ax.grid(True, which="both", alpha=0.3)
    levels = [r["level"] for r in rows]
    series = _quality_series(rows)
    for si, (s, q) in enumerate(series.items()):
        st = styles[si % 4]
        qa.plot(levels, [100 * f.get("active_length", np.nan) for f in q], "o" + st, label=f"{s}: active length (cm)")
        qa.plot(levels, [100 * f.get("pose_error_rel", np.nan) for f in q], "s" + st,
                label=f"{s}: idealized pose error (% of L)")
        names = sorted({n for f in q for n in f.get("extractors", {})})
        for ni, n in enumerate(names):
            ext = [f.get("extractors", {}).get(n, {}) for f in q]
            tag = n if len(series) == 1 else f"{s}/{n}"
            qt.plot(levels, [e.get("tendons", np.nan) for e in ext], "^" + st, label=tag)
            qr.plot(levels, [100 * e.get("realizable_pose_error_rel", np.nan) for e in ext], "v" + st, label=tag)
    for a_, title in ((qa, "optimization"), (qt, "tendons"), (qr, "realizable pose error (% of L)")):
        a_.set_xticks(levels)
        a_.grid(True, alpha=0.3)
        a_.set_ylabel(title, fontsize=8)
        if a_.get_legend_handles_labels()[0]:
            a_.legend(fontsize=6.5)
    qt.set_ylim(bottom=0)
    qr.set_ylim(bottom=0)
    qa.set_title("quality against resolution" + (" (solver auto picks per level)" if "auto" in series else ""),
                 fontsize=10)
    qr.set_xlabel("resolution level")
    if not series:
        qa.text(0.5, 0.5, "no optimization run (--no-optimize)", ha="center", transform=qa.transAxes)
    fig.tight_layout()
    return fig


def _swept(result: dict) -> list[tuple[str, list]]:
    """The dimensions a sweep varied: each grid key with two or more values, the
    level when several; a case index when nothing varied."""
    dims = [(f"settings.{k}", sorted(set(v), key=float)) for k, v in result["grid"].items()
            if len(set(v)) > 1 and all(isinstance(x, (int, float)) for x in v)]
    if len(result["levels"]) > 1:
        dims.append(("level", sorted(result["levels"])))
    return dims or [("case", None)]


def plot_sweep(path: str | Path, result: dict) -> Path:
    """:func:`sweep_figure` as a PNG."""
    return save_png(sweep_figure(result), path, 110)


def sweep_figure(result: dict):
    """A grid of panels: rows are tendon count, realizable pose error, active length
    and time; columns are the swept settings (values as evenly spaced ticks).
    Colour: scene; marker: extractor."""
    cases = [c for c in result["cases"] if "error" not in c]
    dims = _swept(result)
    names = result["extractors"]
    scenes = list(dict.fromkeys(c["scene"] for c in cases))
    colors = palette()
    markers = "os^vD*P"
    rows = [("tendons", lambda c, n: c["extract"].get(n, {}).get("count")),
            ("realizable pose error (% of L)",
             lambda c, n: 100 * c["extract"][n]["realizable_pose_error_rel"] if "count" in c["extract"].get(n, {})
             else None),
            ("active length (cm)", lambda c, n: 100 * c["optimize"]["active_length"]),
            ("time (s)", lambda c, n: c["time_s"])]
    fig = new_figure(figsize=(max(7.5, 4.2 * len(dims)), 2.4 * len(rows)))
    axes = fig.subplots(len(rows), len(dims), squeeze=False)
    for j, (key, values) in enumerate(dims):
        for i, (ylabel, get) in enumerate(rows):
            ax = axes[i, j]
            per_extractor = i < 2
            for si, scene in enumerate(scenes):
                for ni, n in enumerate(names if per_extractor else [None]):
                    pts = []
                    for ci, c in enumerate(cases):
                        if c["scene"] != scene:
                            continue
                        y = get(c, n)
                        if y is None:
                            continue
                        if values is None:
                            x = ci
                        else:
                            v = c["level"] if key == "level" else c["settings"][key.split(".", 1)[1]]
                            x = values.index(v)
                        pts.append((x + 0.08 * (ni - (len(names) - 1) / 2) * per_extractor, y))
                    if pts:
                        label = scene + (f" / {n}" if per_extractor else "")
                        ax.plot(*zip(*pts), markers[ni % len(markers)] if per_extractor else "o",
                                color=colors[si % len(colors)], alpha=0.8, ms=5, ls="none", label=label)
            if values is not None:
                ax.set_xticks(range(len(values)), [f"{v:g}" for v in values], fontsize=7)
            if i == len(rows) - 1:
                ax.set_xlabel(key.replace("settings.", ""))
            if j == 0:
                ax.set_ylabel(ylabel, fontsize=8)
            ax.grid(True, alpha=0.3)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7)
    fig.suptitle(f"sweep '{result['name']}': {len(cases)} cases (colour: scene; marker: extractor)", fontsize=10)
    fig.tight_layout(rect=(0, 0.02 + 0.02 * ((len(labels) + 2) // 3), 1, 0.97))
    return fig


def plot_story(path: str | Path, problem: Problem, planted: dict | None, stage0, final, extractor) -> Path:
    """:func:`story_figure` as a PNG."""
    return save_png(story_figure(problem, planted, stage0, final, extractor), path, 110)


def story_figure(problem: Problem, planted: dict | None, stage0, final, extractor):
    """The method in five panels, for a README: the planted tendons on their
    equilibrium (``planted``: a layout dict of :mod:`~tendon_taichi.planted`, or
    None), stage 0 (unregularized soft IK) and the final stage (``(x, tau,
    figures)`` each) as fiber tensions, the designed routes at rest, and their
    as-built robot (``extractor``: anything with a ``name``, ``metrics``,
    ``tendons`` and ``realizable``, e.g. an
    :class:`~tendon_taichi.apps.extract.ExtractorResult`). Fibers are coloured by
    tension as the problem's optimize settings scale it, the active ones marked."""
    st = problem.scene.optimize
    threshold, scale = st.active_threshold * st.tension_scale, st.tension_scale
    fig = new_figure(figsize=(19, 4.0))
    axes = fig.subplots(1, 5)
    T = problem.mesh.triangles
    colors = palette()
    pose = problem.pose(0)

    def frame(ax, x, title):
        _frame(ax, problem, x, title)

    ax = axes[0]
    if planted is not None:
        frame(ax, None, f"1. planted: {len(planted['tendons'])} tendons, "
                        f"{100 * planted['planted_length']:.1f} cm\n(at rest; green x: goals they make)")
        for i, t in enumerate(planted["tendons"]):
            w = np.array(t["waypoints"])
            ax.plot(w[:, 0], w[:, 1], color=colors[i % len(colors)], lw=2.2)
            ax.plot(*w[0], "o", color=colors[i % len(colors)], ms=4)
    else:
        frame(ax, None, "1. the body and its goals")
    for ax, (x, tau, f), title in ((axes[1], stage0, "2. unregularized soft IK (stage 0)"),
                                   (axes[2], final, "3. L0 homotopy + strand terms (final)")):
        _axes_tensions(ax, pose, x, tau, threshold, scale=scale,
                       title=f"{title}\n{f.active_fibers} active fibers, {100 * f.active_length:.1f} cm, "
                             f"pose {100 * f.pose_error_rel:.2f}% of L")
    ax = axes[3]
    m = extractor.metrics
    frame(ax, None, f"4. routes ({extractor.name}): {m['count']} tendons, "
                    f"{100 * m['total_length']:.1f} cm\n{m['kinks']} kinks, capstan worst {m['capstan_worst']:.2f}")
    _routes(ax, [t.waypoints for t in extractor.tendons])
    ax = axes[4]
    x = extractor.realizable.x
    frame(ax, x, f"5. as built (only those tendons, with friction)\npose {100 * m['realizable_pose_error_rel']:.2f}% of L")
    _routes(ax, [problem.embed_waypoints(t.nodes, t.waypoints).positions(T, x) for t in extractor.tendons])
    fig.tight_layout()
    return fig


def _frame(ax, problem: Problem, x, title: str, pose: Problem | None = None) -> None:
    """The rest mesh (and the deformed one at ``x``), the goals and (at ``x``) the targets."""
    T, X = problem.mesh.triangles, problem.mesh.nodes
    ax.triplot(X[:, 0], X[:, 1], T, color="0.88", lw=0.4)
    if x is not None:
        ax.triplot(x[:, 0], x[:, 1], T, color="0.72", lw=0.4)
    pose = pose or problem.pose(0)
    goal = pose.target_goal
    ax.scatter(goal[:, 0], goal[:, 1], s=40, marker="x", color="tab:green", zorder=5)
    if x is not None:
        now = pose.target_positions(x)
        ax.scatter(now[:, 0], now[:, 1], s=18, color="tab:blue", zorder=5)
    ax.set_title(title, fontsize=9)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])


def _routes(ax, paths: list[np.ndarray], leaves: list[bool] | None = None, size: float = 0.0) -> None:
    """Each path (k, 2) in its colour, its anchor a circle, its pull end a square;
    one that ``leaves`` the body there, with a dashed line out of it (``size`` x 0.06 long)."""
    colors = palette()
    for i, w in enumerate(paths):
        c = colors[i % len(colors)]
        ax.plot(w[:, 0], w[:, 1], color=c, lw=2.2, solid_capstyle="round")
        ax.plot(*w[0], "o", color=c, ms=5)
        ax.plot(*w[-1], "s", color=c, ms=5)
        if leaves is not None and leaves[i]:
            tip = beyond(w, 0.06 * size)
            ax.plot([w[-1][0], tip[0]], [w[-1][1], tip[1]], "--", color=c, lw=1.4)
        ax.annotate(str(i + 1), w[0], textcoords="offset points", xytext=(3, 3), fontsize=8, color=c)


def plot_design(path: str | Path, problem: Problem, tendons, real, title: str) -> Path:
    """:func:`design_figure` as a PNG."""
    return save_png(design_figure(problem, tendons, real, title), path, 120)


def design_figure(problem: Problem, tendons, real, title: str):
    """The routes in the rest body (anchor circle, pull end square) beside the as-built
    robot in each pose (``real`` its solved realizable result): what to build and
    what it does."""
    poses = [real] if real.poses is None else real.poses
    fig = new_figure(figsize=(4.4 * (1 + len(poses)), 4.4))
    axes = fig.subplots(1, 1 + len(poses), squeeze=False)[0]
    exits = problem.exits
    where = "" if exits is None else f"; green: where they may leave, {exits.kind}"
    _frame(axes[0], problem, None, f"{len(tendons)} route(s) at rest\n(circle: anchor, square: pull end{where})")
    if exits is not None:
        for a, b in exits.segments:
            axes[0].plot([a[0], b[0]], [a[1], b[1]], color="tab:green", lw=4, alpha=0.5, solid_capstyle="butt")
    leaves = [getattr(t, "exit", None) is not None for t in tendons]
    _routes(axes[0], [t.waypoints for t in tendons], leaves, problem.size)
    T = problem.mesh.triangles
    names = problem.pose_names
    for i, (ax, r) in enumerate(zip(axes[1:], poses)):
        label = f" '{names[i]}'" if len(poses) > 1 else ""
        _frame(ax, problem, r.x, f"as built{label}: pose error {100 * r.pose_error_rel:.2f}% of L\n"
                                 f"(blue: targets, green: goals)", problem.pose(i))
        _routes(ax, [problem.embed_waypoints(t.nodes, t.waypoints).positions(T, r.x) for t in tendons], leaves,
                problem.size)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_front(path: str | Path, front: list[dict], budget: float, chosen: int, name: str) -> Path:
    """:func:`front_figure` as a PNG."""
    return save_png(front_figure(front, budget, chosen, name), path, 110)


def front_figure(front: list[dict], budget: float, chosen: int, name: str, series: dict | None = None):
    """As-built pose error (% of L) against tendon count, a point per count (one
    line per level when ``series`` maps labels to fronts), the budget dashed and
    the recommended count ringed."""
    fig = new_figure(figsize=(5.0, 3.6))
    ax = fig.subplots()
    for label, rows in (series or {name: front}).items():
        k = [r["count"] for r in rows]
        e = [100 * r["realizable_pose_error_rel"] for r in rows]
        ax.plot(k, e, "o-", label=label)
    pick = [r for r in front if r["count"] == chosen]
    if pick:
        ax.plot(chosen, 100 * pick[0]["realizable_pose_error_rel"], "o", ms=14, mfc="none", mec="tab:red",
                label=f"recommended: {chosen}")
    ax.axhline(100 * budget, ls="--", color="0.5", label=f"budget {100 * budget:g}%")
    ax.set_xlabel("tendons")
    ax.set_ylabel("as-built pose error (% of L)")
    ax.set_xticks(sorted({r["count"] for r in front} | {chosen}))
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.set_title(f"{name}: what each tendon buys", fontsize=9)
    fig.tight_layout()
    return fig
