"""Routes that leave the body (``docs/method.md``, exits).

With ``[tendons] exit = "clamp"`` or ``"surface"`` a tendon is pulled from
outside the body: its channel runs on from the strand's end to the body's exit
set (:class:`~tendon_taichi.body.exits.ExitSet`) and out. :func:`exit_route`
turns a route into one that does: pulled at the end nearer the exit set, carried
on to its nearest exit point - straight where that keeps the clearance, else
along the shortest path through the mesh's nodes that keep it - and fitted again
as one smooth route whose last control point is the exit. That run is part of
the route from then on: it keeps the clearance (but within the exit's zone,
:class:`~tendon_taichi.body.exits.ExitWalls`), its bends count in the capstan
friction of the as-built robot and the metrics, and route optimization moves the
exit along its segment (:mod:`.routing`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from ..body.exits import ExitWalls
from ..body.problem import Problem
from .clearance import CLEAR_TOL, clear_route
from .routes import Route, fit_route

#: the nearest mesh nodes a path out of the body tries to leave from, at most
CANDIDATES = 64


def _clear(run: np.ndarray, problem: Problem, clearance: float) -> bool:
    """Whether a polyline (k, dim) ending at an exit keeps ``clearance`` (m) outside its zone."""
    return ExitWalls(problem.walls, run[-1], clearance).polyline_distance(run) >= clearance * (1.0 - CLEAR_TOL)


def _node_graph(problem: Problem, keep: np.ndarray):
    """The mesh's edges between nodes ``keep`` (bool (n,)), weighted by length, as a sparse graph."""
    simplices = problem.mesh.simplices
    k = simplices.shape[1]
    pairs = np.concatenate([simplices[:, [i, j]] for i in range(k) for j in range(i + 1, k)])
    pairs = pairs[keep[pairs].all(axis=1)]
    w = np.linalg.norm(problem.mesh.nodes[pairs[:, 0]] - problem.mesh.nodes[pairs[:, 1]], axis=1)
    n = problem.mesh.n_nodes
    return coo_matrix((np.r_[w, w], (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]])),
                      shape=(n, n)).tocsr()


def exit_run(problem: Problem, start: np.ndarray, clearance: float) -> tuple[np.ndarray, int]:
    """A polyline (k, dim) from ``start`` (dim,) to a point of the exit set that keeps
    ``clearance`` (m) outside the exit's zone - straight where it can, else through
    the mesh nodes that keep it, leaving from the one with the shortest way out - and
    the index of the exit segment it ends on. Where there is none, the straight one
    (the route is then made to keep what it can, :func:`~.clearance.clear_route`)."""
    exits = problem.exits
    start = np.asarray(start, dtype=float)
    foot, _, seg = exits.nearest(start[None])
    straight = np.array([start, foot[0]])
    if _clear(straight, problem, clearance):
        return straight, int(seg[0])
    nodes = problem.mesh.nodes
    keep = problem.walls.distance(nodes) >= clearance
    if not keep.any():
        return straight, int(seg[0])
    ids = np.flatnonzero(keep)
    first = ids[np.argsort(np.linalg.norm(nodes[ids] - start, axis=1))[:8]]
    held = clearance * (1.0 - CLEAR_TOL)
    first = [i for i in first if problem.walls.polyline_distance(np.array([start, nodes[i]])) >= held] or [first[0]]
    dist, pred, source = dijkstra(_node_graph(problem, keep), indices=first, min_only=True,
                                  return_predecessors=True)
    dist = dist + np.linalg.norm(nodes - start, axis=1)[np.maximum(source, 0)]
    reach = np.flatnonzero(np.isfinite(dist))
    feet, out, segs = exits.nearest(nodes[reach])
    order = np.argsort(dist[reach] + out)[:CANDIDATES]
    for i in order:
        leg = np.array([nodes[reach[i]], feet[i]])
        if _clear(leg, problem, clearance):
            path, v = [], reach[i]
            while v >= 0:
                path.append(nodes[v])
                v = pred[v]
            return np.vstack([start, np.array(path[::-1]), feet[i]]), int(segs[i])
    return straight, int(seg[0])


def exit_route(route: Route, problem: Problem, clearance: float) -> Route:
    """``route`` made to leave the body where ``problem``'s scene says (module
    docstring) and to keep ``clearance`` (m) from the walls (as much as it can,
    flagged, :func:`~.clearance.clear_route`); with ``exit = "inside"`` only the
    latter. A route that leaves already is carried out again from its core."""
    exits = problem.exits
    if exits is None:
        return clear_route(route, problem.walls, clearance)
    core = route.inner()
    _, d, _ = exits.nearest(core.waypoints[[0, -1]])
    if d[0] < d[1]:
        core = core.reversed()
    run, seg = exit_run(problem, core.waypoints[-1], clearance)
    points = np.vstack([core.waypoints, run[1:]])
    out = fit_route(points, problem.size, core.tension, core.tension_std, core.source)
    out = replace(out, contraction=core.contraction, exit=exits.segments[seg].copy(), core=core)
    return clear_route(out, problem.walls, clearance)
