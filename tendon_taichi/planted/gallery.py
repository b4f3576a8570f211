"""Pictures of planted layouts: every layout of a suite on its planted
equilibrium, and a planted-bench run's gallery (planted against found)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..body.problem import build_problem
from ..body.scene import load_scene
from ..files import atomic_path
from ..io.plots import new_figure, palette, png_metadata, save_png
from .plant import solve_tendons
from .walk import PlantedTendon


def plot_layouts(path, cases: list[tuple], columns: int = 4, dpi: int = 72) -> Path:
    """:func:`layouts_figure` as a PNG with a 64-colour palette (a small file)."""
    from PIL import Image, PngImagePlugin

    buf = io.BytesIO()
    layouts_figure(cases, columns).savefig(buf, dpi=dpi, format="png")
    buf.seek(0)
    info = PngImagePlugin.PngInfo()
    for key, value in png_metadata().items():
        info.add_text(key, value)
    with Image.open(buf) as im, atomic_path(path) as tmp:
        im.convert("RGB").quantize(64).save(tmp, format="png", optimize=True, pnginfo=info)
    return Path(path)


def layouts_figure(cases: list[tuple], columns: int = 4):
    """One panel per (planted scene, layout): the rest outline (grey), the planted
    equilibrium's outline (black), the tendons on it (colours; dot: anchor, thin: at
    rest), the target points at rest (blue) and their goals (green x)."""
    from matplotlib.collections import LineCollection

    rows = -(-len(cases) // columns)
    fig = new_figure(figsize=(2.6 * columns, 2.6 * rows))
    axes = fig.subplots(rows, columns, squeeze=False)
    colors = palette()
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (scene, layout) in zip(axes.ravel(), cases):
        problem = build_problem(scene, layout["level"])
        tendons = [PlantedTendon(np.array(t["waypoints"]), t["length"], t["contraction"],
                                 t["contraction_ratio"], t["tension"]) for t in layout["tendons"]]
        x = solve_tendons(problem, tendons).x
        X, T, e = problem.mesh.nodes, problem.mesh.triangles, problem.mesh.boundary_edges
        ax.add_collection(LineCollection(X[e], colors="0.75", linewidths=0.6))
        ax.add_collection(LineCollection(x[e], colors="0.1", linewidths=0.8))
        for i, t in enumerate(tendons):
            c = colors[i % len(colors)]
            emb, _ = problem.mesh.locate(t.waypoints, max_dist=1e-9 * problem.size)
            now = emb.positions(T, x)
            ax.plot(t.waypoints[:, 0], t.waypoints[:, 1], color=c, lw=0.7, alpha=0.5)
            ax.plot(now[:, 0], now[:, 1], color=c, lw=1.8)
            ax.plot(*now[0], "o", color=c, ms=3.5)
        pts, goals = np.array([tg.point for tg in scene.targets]), problem.target_goal
        ax.scatter(pts[:, 0], pts[:, 1], s=10, color="tab:blue", zorder=5)
        ax.scatter(goals[:, 0], goals[:, 1], s=28, marker="x", color="tab:green", zorder=5)
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(f"{layout['name']}\n{100 * layout['planted_length']:.1f} cm, max disp. "
                     f"{100 * layout['pose']['max_target_displacement_rel']:.1f} % L", fontsize=7)
    fig.tight_layout()
    return fig


def plot_gallery(path: Path, result: dict, suite: dict) -> Path:
    """:func:`gallery_figure` as a PNG."""
    return save_png(gallery_figure(result, suite), path, 110)


def gallery_figure(result: dict, suite: dict):
    """One panel per case of a planted-bench ``result``: the body, the planted
    tendons (dashed black) and the recommended design's routes (colours, anchor a
    circle, pull end a square), in rest coordinates; ``suite`` maps case names to
    their cases."""
    cases = result["cases"]
    cols = min(4, max(1, len(cases)))
    rows = (len(cases) + cols - 1) // cols
    fig = new_figure(figsize=(3.6 * cols, 3.3 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    colors = palette()
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, c in zip(axes.ravel(), cases):
        case = suite.get(c["case"])
        if case is not None:
            body = load_scene(str(case.scene_path)).body
            for poly in ([body.outline] if body.outline is not None else []) + list(body.holes):
                q = np.vstack([poly, poly[:1]])
                ax.plot(q[:, 0], q[:, 1], color="0.6", lw=0.8)
            for t in case.layout["tendons"]:
                w = np.asarray(t["waypoints"])
                ax.plot(w[:, 0], w[:, 1], "--", color="k", lw=1.2)
        if "error" in c:
            ax.set_title(f"{c['case']}\nfailed: {c['error'][:40]}", fontsize=7)
        else:
            for i, w in enumerate(c.get("tendons", [])):
                w, col = np.asarray(w), colors[i % len(colors)]
                ax.plot(w[:, 0], w[:, 1], color=col, lw=2.0, alpha=0.85)
                ax.plot(*w[0], "o", color=col, ms=3.5)
                ax.plot(*w[-1], "s", color=col, ms=3.5)
            rp = c["realizable_pose_error_rel"]
            ax.set_title(f"{c['case']} ({'pass' if c['passed'] else 'miss'})\n"
                         f"{c['count']}/{c['planted_count']} tendons ({c['best']}), as built {100 * rp:.2f}%, "
                         f"capstan {c['capstan_worst']:.2f}/{c['planted_capstan_worst']:.2f}", fontsize=7)
        ax.set_aspect("equal")
    fig.suptitle("planted (dashed) vs found (colour)", fontsize=10)
    fig.tight_layout()
    return fig
