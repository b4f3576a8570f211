"""``design --routes-from``: a prior design's front as starting points.

``design.json`` lists with each front entry its ``routes`` (:func:`route_rows`:
control points, waypoint count, the strand tension the route started from, and
per pose its contraction ratio). Routes are curves in the rest body, not paths
on a lattice, so a prior design of the same body - at a coarser level, or an
earlier run - gives layouts this design's front can start from
(:class:`~tendon_taichi.extract.front.PriorLayout`): each is solved on this
mesh from those ratios, and its routes are optimized here like any other.
Which layouts the lattice leads a search to moves with the mesh; a layout
found on a coarser mesh is a start the search on a finer one may not reach.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..body.geometry import bbox_diagonal
from ..body.problem import Problem
from ..body.scene import Scene
from ..errors import InputError
from ..extract.consolidation import Layout
from ..extract.front import PriorLayout
from ..extract.clearance import clear_route
from ..extract.exits import exit_route
from ..extract.routes import Route

#: what a route from a prior design is marked with in ``source`` (its extractor's name follows)
PRIOR = "prior:"
#: the body sizes of two designs of the same body agree to this (relative)
SAME_SIZE = 1e-6


def route_rows(layout: Layout) -> list[dict]:
    """A solved layout's routes as ``design.json`` lists them with a front entry:
    ``control_points`` (c, 2) m, ``samples`` (waypoints), ``tension`` (N, the strand's
    it started from), ``contraction_ratio`` (one per pose) and ``source``; a route
    that leaves the body, the ``exit_segment`` (2, 2) m its pull end lies on."""
    ratios = np.atleast_2d(layout.realizable.ratios).reshape(-1, layout.count)  # (P, T)
    rows = []
    for i, r in enumerate(layout.routes):
        rows.append({"control_points": r.control.tolist(), "samples": r.samples, "tension": r.tension,
                     "contraction_ratio": ratios[:, i].tolist(), "source": r.source})
        if r.exits:
            rows[-1]["exit_segment"] = r.exit.tolist()
    return rows


@dataclass(frozen=True)
class PriorDesign:
    """A prior design's front as read from its ``design.json`` (``path``), or as
    this process designed it at the coarser ``level`` (:func:`front_prior`; ``path``
    None): per front entry with routes, that layout (its routes marked ``prior:``,
    not yet checked against a mesh's walls)."""

    path: Path | None
    layouts: list[PriorLayout]
    level: int | None = None

    @property
    def name(self) -> str:
        """Where the layouts came from, in words."""
        return f"the level-{self.level} design" if self.path is None else f"'{self.path}'"


def front_prior(front: list[dict], scene: Scene, level: int) -> PriorDesign:
    """The ``front`` of a design of ``scene`` at ``level`` as ``design.json`` lists it
    (each entry's ``routes``, :func:`route_rows`), held in memory, as a prior design."""
    rows = [e["routes"] for e in front if e.get("routes")]
    return PriorDesign(None, [_layout(routes, len(scene.poses), f"the level-{level} design") for routes in rows],
                       level)


def read_prior(path: str | Path, scene: Scene) -> PriorDesign:
    """The front of the design at ``path`` (its folder or its ``design.json``),
    checked to be one of ``scene``'s body with as many poses; one clear line
    (:class:`InputError`) when it is not."""
    p = Path(path)
    try:  # a folder on the way that cannot be entered makes even is_dir fail
        p = p / "design.json" if p.is_dir() else p
        found = p.is_file()
    except OSError as exc:
        raise InputError(f"--routes-from: cannot read '{path}': {exc.strerror or exc}") from None
    where = f"--routes-from: '{p}'"
    if not found:
        raise InputError(f"--routes-from: no design at '{path}' (a design folder or its design.json)")
    try:
        data = json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{where} is not a design.json ({exc})") from None
    if not isinstance(data, dict) or not isinstance(data.get("front"), list):
        raise InputError(f"{where} is not a design.json (no 'front' list)")
    if data.get("scene") != scene.name:
        raise InputError(f"{where} is a design of scene '{data.get('scene')}', not of '{scene.name}'")
    size = None if scene.body.outline is None else bbox_diagonal(scene.body.outline)  # a mesh file: not read yet
    theirs = data.get("body_size")
    if size is not None and (not isinstance(theirs, (int, float)) or abs(theirs - size) > SAME_SIZE * size):
        raise InputError(f"{where} is a design of another body (its size {theirs!r} m, this one {size:.6g} m)")
    rows = [e.get("routes") for e in data["front"] if isinstance(e, dict) and e.get("routes")]
    if not rows:
        raise InputError(f"{where} lists no routes with its front (written before design.json held them: "
                         "run that design again)")
    layouts = [_layout(routes, len(scene.poses), where) for routes in rows]
    return PriorDesign(p, layouts)


def _layout(rows: list, poses: int, where: str) -> PriorLayout:
    """One front entry's ``routes`` (:func:`route_rows`) as a layout to start from."""
    routes, ratios = [], []
    for r in rows:
        try:
            control = np.asarray(r["control_points"], dtype=float)
            ratio = np.asarray(r["contraction_ratio"], dtype=float)
            samples, tension = int(r["samples"]), float(r["tension"])
            ok = (control.ndim == 2 and control.shape[1] == 2 and len(control) >= 2 and samples >= 2
                  and ratio.ndim == 1 and np.isfinite(control).all() and np.isfinite(ratio).all()
                  and np.isfinite(tension))
        except (TypeError, KeyError, ValueError):
            ok = False
        if not ok:
            raise InputError(f"{where} has a malformed route in its front")
        if len(ratio) != poses:
            raise InputError(f"{where} is a design for {len(ratio)} pose(s); this scene has {poses}")
        source = str(r.get("source") or "front")
        exit = r.get("exit_segment")
        try:
            exit = None if exit is None else np.asarray(exit, dtype=float).reshape(2, 2)
        except (TypeError, ValueError):
            raise InputError(f"{where} has a malformed route in its front") from None
        routes.append(Route(control, samples, tension, source=source if source.startswith(PRIOR) else PRIOR + source,
                            exit=exit))
        ratios.append(ratio)
    return PriorLayout(routes, np.array(ratios).T)


def prior_layouts(prior: PriorDesign, problem: Problem) -> list[PriorLayout]:
    """The prior design's layouts for ``problem``'s front, each route kept clear of
    this body's walls at its clearance (or flagged with the most it keeps,
    :func:`~tendon_taichi.extract.clearance.clear_route`)."""
    clearance = problem.scene.tendons.clearance * problem.size
    return [replace(lay, routes=[_fitted(r, problem, clearance) for r in lay.routes]) for lay in prior.layouts]


def _fitted(route: Route, problem: Problem, clearance: float) -> Route:
    """A prior route kept clear of ``problem``'s walls, and leaving the body where its
    scene says: one that left where this scene's routes do not, or that stayed inside
    where they leave, is carried out of the body again (:func:`~tendon_taichi.extract.exits.exit_route`)."""
    exits = problem.exits
    if route.exits:
        _, d, k = (None, [np.inf], None) if exits is None else exits.nearest(route.control[-1:])
        route = replace(route, exit=None if d[0] > 1e-9 * problem.size else exits.segments[k[0]].copy())
    if exits is not None and not route.exits:
        return exit_route(route, problem, clearance)
    return clear_route(route, problem.walls, clearance)
