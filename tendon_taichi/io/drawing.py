"""The fabrication drawing: an SVG in millimetres (1 user unit = 1 mm, y up as
in the scene) of the rest body - its outline and holes - and the tendons, each
a smooth path (a route's spline as cubic Bezier segments, exactly; a lattice
tendon as a polyline) with its anchor (circle) and pull end (square),
numbered in the order given; where tendons leave the body, the stretches of
the outline they may leave through (green) and, on each that does, a dashed
line out of the body where it leaves. Written atomically."""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from ..body.exits import beyond
from ..body.problem import Problem
from ..body.spline import bezier_pieces
from ..files import atomic_path

MM = 1000.0
COLORS = ["#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf"]


class _Frame:
    """Scene metres to SVG millimetres (y flipped, with a margin)."""

    def __init__(self, problem: Problem):
        self.lo = problem.mesh.nodes.min(axis=0) * MM
        self.hi = problem.mesh.nodes.max(axis=0) * MM
        self.pad = 0.05 * float(np.max(self.hi - self.lo)) + 2.0
        self.size = self.hi - self.lo + 2 * self.pad

    def xy(self, p) -> tuple[float, float]:
        return float(p[0] * MM - self.lo[0] + self.pad), float(self.hi[1] - p[1] * MM + self.pad)

    def text(self, p) -> str:
        x, y = self.xy(p)
        return f"{x:.3f},{y:.3f}"


def _ring(frame: _Frame, ring) -> str:
    return "M " + " L ".join(frame.text(p) for p in ring) + " Z"


def _body_path(frame: _Frame, problem: Problem) -> str:
    """The outline and holes as one path (even-odd: the holes are cut out)."""
    body = problem.scene.body
    if body.outline is not None:
        return " ".join(_ring(frame, r) for r in [body.outline, *body.holes])
    X = problem.mesh.nodes  # a mesh-file body: its boundary edges
    return " ".join(f"M {frame.text(X[a])} L {frame.text(X[b])}" for a, b in problem.mesh.boundary_edges)


def tendon_path(frame: _Frame, tendon) -> str:
    """A tendon's path data: Bezier segments for a route, else its polyline."""
    if tendon.control is not None:
        pieces = bezier_pieces(tendon.control)
        out = [f"M {frame.text(pieces[0][0])}"]
        out += [f"C {frame.text(p[1])} {frame.text(p[2])} {frame.text(p[3])}" for p in pieces]
        return " ".join(out)
    return "M " + " L ".join(frame.text(p) for p in tendon.waypoints)


def write_svg(path: str | Path, problem: Problem, tendons, title: str = "") -> Path:
    """The drawing of ``tendons`` (anything with ``waypoints``, ``control``,
    ``anchor``, ``pull_end``, ``length`` and ``contraction``) in ``problem``'s body."""
    f = _Frame(problem)
    w, h = f.size
    name = escape(title or problem.scene.name)
    lines = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:.2f}mm" height="{h:.2f}mm" '
             f'viewBox="0 0 {w:.3f} {h:.3f}">',
             f"<title>{name}: {len(tendons)} tendon(s), millimetres</title>",
             f'<path id="body" d="{_body_path(f, problem)}" fill="#f4f4f4" fill-rule="evenodd" '
             f'stroke="#444" stroke-width="0.3"/>']
    exits = problem.exits
    if exits is not None:
        d = " ".join(f"M {f.text(a)} L {f.text(b)}" for a, b in exits.segments)
        lines.append(f'<path id="exits" class="exit-set" d="{d}" stroke="#2a2" stroke-width="1.2" fill="none">'
                     f"<desc>where a tendon may leave the body ({exits.kind})</desc></path>")
    for i, t in enumerate(tendons):
        c = COLORS[i % len(COLORS)]
        ax, ay = f.xy(t.anchor)
        px, py = f.xy(t.pull_end)
        out = []
        if getattr(t, "exit", None) is not None:  # on out of the body, along the route's last direction
            tip = f.text(beyond(t.waypoints, 0.04 * problem.size))
            out = [f'<path class="exit" d="M {f.text(t.waypoints[-1])} L {tip}" stroke-dasharray="1 0.6"/>']
        pull = "" if t.contraction is None else f", pull {1e3 * t.contraction:.2f} mm"
        lines += [f'<g id="tendon{i + 1}" stroke="{c}" fill="none" stroke-width="0.8">',
                  f"<desc>tendon {i + 1}: {1e3 * t.length:.1f} mm{pull}; circle: anchor, square: pull end</desc>",
                  f'<path class="route" d="{tendon_path(f, t)}" stroke-linejoin="round" stroke-linecap="round"/>',
                  f'<circle class="anchor" cx="{ax:.3f}" cy="{ay:.3f}" r="1.2" fill="{c}"/>',
                  f'<rect class="pull-end" x="{px - 1.2:.3f}" y="{py - 1.2:.3f}" width="2.4" height="2.4" fill="{c}"/>',
                  f'<text x="{ax:.3f}" y="{ay - 2:.3f}" font-size="3" fill="{c}" stroke="none">{i + 1}</text>',
                  *out, "</g>"]
    lines.append("</svg>")
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return Path(path)
