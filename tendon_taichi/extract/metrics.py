"""The metrics of a tendon set, the same for every extractor
(``docs/method.md``, extraction)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..body.exits import ExitWalls
from .protocol import IdealizedState, Tendon


@dataclass
class MetricSettings:
    """``kink_angle`` (degrees) above which a turn is a kink; ``mu`` the friction
    coefficient of the capstan factor exp(-mu Theta)."""

    kink_angle: float = 30.0
    mu: float = 0.1


#: an active fiber is covered by a route that passes within this many lattice
#: spacings of its midpoint and runs within COVER_ANGLE of its direction there
COVER_SPACINGS = 1.0
COVER_ANGLE = np.pi / 4


def covered_fibers(problem, tendons: list[Tendon], fibers: np.ndarray) -> np.ndarray:
    """bool (len(fibers),): which of these fibers a tendon carries - a lattice
    tendon the fibers it runs along, a route those it passes alongside (within
    COVER_SPACINGS lattice spacings of the fiber's midpoint, within COVER_ANGLE of
    its direction)."""
    f = problem.fibers
    fibers = np.asarray(fibers, dtype=np.int64)
    out = np.zeros(len(fibers), dtype=bool)
    ends = f.nodes[f.edges[fibers]]  # (k, 2, 2)
    mid = ends.mean(axis=1)
    along = ends[:, 1] - ends[:, 0]
    along /= np.maximum(np.linalg.norm(along, axis=1), 1e-300)[:, None]
    for t in tendons:
        if t.on_lattice:
            out |= np.isin(fibers, t.fibers)
            continue
        a, b = t.waypoints[:-1], t.waypoints[1:]
        d = b - a
        dd = np.maximum((d * d).sum(axis=1), 1e-300)
        u = np.clip(((mid[:, None, :] - a[None]) * d[None]).sum(-1) / dd[None], 0.0, 1.0)  # (k, s)
        dist = np.linalg.norm(mid[:, None, :] - (a[None] + u[..., None] * d[None]), axis=2)
        near = np.argmin(dist, axis=1)
        seg = d[near] / np.sqrt(dd[near])[:, None]
        out |= (dist[np.arange(len(mid)), near] <= COVER_SPACINGS * f.spacing) & \
            (np.abs((seg * along).sum(axis=1)) >= np.cos(COVER_ANGLE))
    return out


def tendon_metrics(problem, state: IdealizedState, tendons: list[Tendon],
                   settings: MetricSettings | None = None) -> dict:
    """The metrics of ``docs/method.md`` (extraction), the same for every extractor (SI units,
    angles in radians): ``count``, ``total_length``, ``lengths``, ``total_turning``
    (sum of |turn angles| over all tendons), ``max_turn``, ``kinks``, ``capstan``
    (exp(-mu Theta) per tendon) and ``capstan_worst``, ``tension_cv`` (the largest
    coefficient of variation of the tension along a source strand, over the
    tendons; ``tension_cvs`` per tendon), ``coverage`` (the share of the
    idealized active tension-length sum tau_i a0_i that the tendons carry,
    :func:`covered_fibers`), ``clearances``, each tendon's least distance from
    the outline and holes, m (negative where one leaves the body; for one that
    leaves through its exit, outside the exit's zone), and
    ``clearance_min``, the least of them (None with no tendon)."""
    s = settings or MetricSettings()
    a0 = problem.fibers.a0
    turns = [t.turn_angles() for t in tendons]
    theta = np.array([tt.sum() for tt in turns]) if tendons else np.zeros(0)
    all_turns = np.concatenate(turns) if turns else np.zeros(0)
    capstan = np.exp(-s.mu * theta)
    cvs = np.array([t.tension_std / t.tension if t.tension > 0 else 0.0 for t in tendons])
    active = np.flatnonzero(state.active)
    total = float((state.tau[active] * a0[active]).sum())
    used = active[covered_fibers(problem, tendons, active)]
    covered = float((state.tau[used] * a0[used]).sum())
    h = problem.scene.tendons.clearance * problem.size
    clearances = [problem.walls.polyline_distance(t.waypoints) if t.exit is None
                  else ExitWalls(problem.walls, t.exit, h).kept(t.waypoints) for t in tendons]
    return {
        "count": len(tendons),
        "total_length": float(sum(t.length for t in tendons)),
        "lengths": [t.length for t in tendons],
        "total_turning": float(theta.sum()),
        "max_turn": float(all_turns.max()) if len(all_turns) else 0.0,
        "kinks": int((all_turns > math.radians(s.kink_angle)).sum()),
        "capstan": capstan.tolist(),
        "capstan_worst": float(capstan.min()) if len(capstan) else 1.0,
        "tension_cv": float(cvs.max()) if len(cvs) else 0.0,
        "tension_cvs": cvs.tolist(),
        "coverage": covered / total if total > 0 else 0.0,
        "clearances": clearances,
        "clearance_min": min(clearances, default=None),
    }
