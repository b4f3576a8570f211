"""Pictures (matplotlib, headless): the tension pattern over the deformed body."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .problem import Problem


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


def plot_stages(path: str | Path, problem: Problem, panels: list[tuple[str, np.ndarray, np.ndarray]],
                threshold: float, scale: float) -> Path:
    """A PNG with one panel per (title, x, tau): fibers coloured by tension (N) over
    the deformed mesh (grey: rest), targets (blue) and goals (green)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .export import atomic_path

    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 4.0), squeeze=False)
    lc = None
    for ax, (title, x, tau) in zip(axes[0], panels):
        lc = _axes_tensions(ax, problem, x, tau, threshold, scale, title)
    axes[0][0].legend(loc="lower left", fontsize=7)
    if lc is not None:
        fig.colorbar(lc, ax=list(axes[0]), shrink=0.8, label="fiber tension (N)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, format="png")
    plt.close(fig)
    return Path(path)


def plot_compare(path: str | Path, extraction) -> Path:
    """The idealized tension pattern beside each extractor's tendons drawn on its
    realizable robot's equilibrium (targets blue, goals green)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .export import atomic_path

    p, st = extraction.problem, extraction.state
    ok = [r for r in extraction.results if r.error is None]
    fig, axes = plt.subplots(1, 1 + len(ok), figsize=(4.2 * (1 + len(ok)), 4.0), squeeze=False)
    scale = max(float(st.tau.max()), 1e-9)
    lc = _axes_tensions(axes[0][0], p, st.x, st.tau, st.active_threshold, scale / 2.0,
                        f"idealized (stage {extraction.stage}): {int(st.active.sum())} active, "
                        f"{100 * extraction.idealized_pose_error / p.size:.2f}% pose")
    T = p.mesh.triangles
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, r in zip(axes[0][1:], ok):
        x = r.realizable.x
        ax.triplot(p.mesh.nodes[:, 0], p.mesh.nodes[:, 1], T, color="0.88", lw=0.4)
        ax.triplot(x[:, 0], x[:, 1], T, color="0.72", lw=0.4)
        c = p.fibers.embedding.positions(T, x)
        for i, t in enumerate(r.tendons):
            path_xy = c[t.nodes]
            ax.plot(path_xy[:, 0], path_xy[:, 1], color=colors[i % len(colors)], lw=2.2)
            ax.plot(*path_xy[0], "o", color=colors[i % len(colors)], ms=4)
            ax.plot(*path_xy[-1], "s", color=colors[i % len(colors)], ms=4)
        now, goal = p.target_positions(x), p.target_goal
        ax.scatter(goal[:, 0], goal[:, 1], s=40, marker="x", color="tab:green", zorder=5)
        ax.scatter(now[:, 0], now[:, 1], s=18, color="tab:blue", zorder=5)
        m = r.metrics
        ax.set_title(f"{r.name}: {m['count']} tendons, {m['kinks']} kinks\n"
                     f"realizable pose {100 * m['realizable_pose_error_rel']:.2f}% of L", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.colorbar(lc, ax=axes[0][0], shrink=0.7, label="fiber tension (N)")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, format="png")
    plt.close(fig)
    return Path(path)


def plot_bench(path: str | Path, result: dict) -> Path:
    """Two panels: time against DOFs (log-log) per operation and solver, with the
    fitted exponent in the legend; quality (active length, tendons, realizable pose
    error) against the level."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .bench import TIMINGS
    from .export import atomic_path

    rows = result["levels"]
    fig, (ax, aq) = plt.subplots(1, 2, figsize=(13, 5))
    markers = dict(zip(TIMINGS, "osD^v*"))
    styles = ["-", "--", ":", "-."]
    solvers = sorted({s for r in rows for s in r["solvers"]})
    for si, s in enumerate(solvers):
        for key in TIMINGS:
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
    for si, s in enumerate(solvers):
        q = [r["solvers"].get(s, {}) for r in rows]
        if not any("active_length" in f for f in q):
            continue
        aq.plot(levels, [100 * f.get("active_length", np.nan) for f in q], "o" + styles[si % 4],
                label=f"{s}: active length (cm)")
        aq.plot(levels, [100 * f.get("pose_error_rel", np.nan) for f in q], "s" + styles[si % 4],
                label=f"{s}: idealized pose error (% of L)")
        names = sorted({n for f in q for n in f.get("extractors", {})})
        for n in names:
            ext = [f.get("extractors", {}).get(n, {}) for f in q]
            aq.plot(levels, [e.get("tendons", np.nan) for e in ext], "^" + styles[si % 4],
                    label=f"{s}/{n}: tendons")
            aq.plot(levels, [100 * e.get("realizable_pose_error_rel", np.nan) for e in ext], "v" + styles[si % 4],
                    label=f"{s}/{n}: realizable pose error (% of L)")
    aq.set_xlabel("resolution level")
    aq.set_xticks(levels)
    aq.set_title("quality against resolution", fontsize=10)
    if aq.get_legend_handles_labels()[0]:
        aq.legend(fontsize=6.5)
    else:
        aq.text(0.5, 0.5, "no optimization run (--no-optimize)", ha="center", transform=aq.transAxes)
    aq.grid(True, alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, format="png")
    plt.close(fig)
    return Path(path)
