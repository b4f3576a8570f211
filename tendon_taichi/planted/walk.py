"""Drawing random tendons for a planted layout: curvature-bounded random walks.

A tendon is the path of a random walk with bounded curvature: its curvature
drifts (an Ornstein-Uhlenbeck process, mean zero) and is bent away from the
boundary when a look-ahead arc would come closer than the margin, so paths
follow the body's limbs instead of bouncing off them. Where the scene's
tendons leave the body (``[tendons] exit``), each walk starts at a random point
where they may leave, runs straight in and goes on from there; its pull end is
that point. Every draw comes from one ``numpy.random.Generator``, so the same
stream gives the same tendons.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from scipy.spatial import cKDTree

from ..body.geometry import distance_to_segments, segments
from ..body.problem import Problem


@dataclass(frozen=True)
class PlantSettings:
    """How tendons are drawn. Lengths are relative to the body size L (bounding-box
    diagonal) or to the fiber spacing ``s`` at the planted level.

    ``min_length``, ``max_length`` (x L): the drawn tendon length; a walk that
    gets stuck earlier is kept if it is at least ``min_length`` long.
    ``min_radius`` (x L): the tightest bend. ``margin`` (x s): clearance from
    the boundary and the holes. ``separation`` (x s): clearance between
    tendons, relaxed to ``margin`` for a tendon that does not fit otherwise.
    ``anchor_distance`` (x L): the anchor (first waypoint) lies at least this
    far from every clamped node (at most half as far as the farthest point of
    the body, for a body clamped in its middle). ``max_heading_range`` (rad):
    the spread of the path's directions (below pi, so a path never crosses
    itself); ``max_turning`` (rad): its summed turning. ``contraction``: range of the
    contraction ratio c / length. ``min_displacement`` (x L): a draw whose
    largest target displacement is smaller is rejected. ``max_draws``: layouts
    tried before giving up; ``walk_tries``: walks per tendon and draw. ``exit``:
    where the tendons leave the body (a scene's ``[tendons] exit``).
    """

    min_length: float = 0.25
    max_length: float = 0.9
    min_radius: float = 0.12
    margin: float = 1.0
    separation: float = 2.0
    anchor_distance: float = 0.25
    max_heading_range: float = 0.75 * math.pi
    max_turning: float = math.pi
    contraction: tuple[float, float] = (0.05, 0.10)
    min_displacement: float = 0.02
    max_draws: int = 200
    walk_tries: int = 25
    exit: str = "clamp"


@dataclass
class PlantedTendon:
    """A planted tendon: rest ``waypoints`` (k, 2) m (anchor first), its rest
    ``length`` (m), ``contraction`` (m) = ``ratio`` x length, and its ``tension``
    at the planted equilibrium (N)."""

    waypoints: np.ndarray
    length: float
    contraction: float
    ratio: float
    tension: float = 0.0

    def as_json(self) -> dict:
        return {"waypoints": self.waypoints.tolist(), "length": self.length,
                "contraction": self.contraction, "contraction_ratio": self.ratio,
                "tension": self.tension}


#: how far inside the outline a planted tendon's exit lies (m): its waypoints are rounded to 1 um
INSET = 1.5e-6


# ------------------------------------------------------------------ geometry
class Region:
    """The body as the walks see it: boundary segments (outline and holes), the
    clamped nodes, the size L and the clearances, all in metres."""

    def __init__(self, problem: Problem, st: PlantSettings):
        body = problem.scene.body
        if body.outline is not None:
            loops = [body.outline, *body.holes]
            self.a = np.concatenate(loops)
            self.b = np.concatenate([np.roll(q, -1, axis=0) for q in loops])
            self.polygon = shapely.Polygon(body.outline, body.holes)
        else:
            e = problem.mesh.boundary_edges
            self.a, self.b = problem.mesh.nodes[e[:, 0]], problem.mesh.nodes[e[:, 1]]
            self.polygon = shapely.union_all(shapely.polygons(problem.mesh.nodes[problem.mesh.triangles]))
        self.boundary = segments(self.a, self.b)
        shapely.prepare(self.polygon)
        self.lo, self.hi = problem.mesh.nodes.min(axis=0), problem.mesh.nodes.max(axis=0)
        self.L = problem.size
        self.spacing = problem.fibers.spacing
        self.margin = st.margin * self.spacing
        self.clamped = cKDTree(problem.mesh.nodes[problem.fixed])
        #: where the tendons leave the body (None: their pull ends stay inside), and how far each
        #: runs straight in from there before its walk starts (the walls are not held along it)
        self.exits = problem.exits
        self.lead = 0.0 if self.exits is None else 1.5 * max(self.exits.zone, 1.1 * self.margin)
        #: how far the anchor must be from the clamps: anchor_distance L, or half
        #: the farthest any point is (a body clamped in its middle), m
        reach = float(self.clamp_distance(problem.mesh.nodes).max())
        self.anchor_distance = min(st.anchor_distance * self.L, 0.5 * reach)

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance (q,) from points (q, 2) to the boundary, m."""
        return distance_to_segments(points, self.a, self.b, self.boundary)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Whether points (q, 2) lie strictly inside the body: bool (q,)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        return shapely.contains_xy(self.polygon, p[:, 0], p[:, 1])

    def clamp_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (q,) from points (q, 2) to the nearest clamped node, m."""
        return self.clamped.query(np.asarray(points, dtype=float).reshape(-1, 2))[0]


def _arc(p: np.ndarray, theta: float, kappa: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points (c, k, 2) at arc lengths s (k,) along circles of curvature kappa (c,)
    (1/m, positive: to the left) that leave p (2,) with heading theta (rad)."""
    turn = kappa[:, None] * s[None, :]
    chord = s[None, :] * np.sinc(turn / (2.0 * np.pi))  # 2 sin(turn/2) / kappa
    ang = theta + 0.5 * turn
    return p + np.stack([chord * np.cos(ang), chord * np.sin(ang)], axis=-1)


def _polyline_samples(path: np.ndarray, step: float) -> np.ndarray:
    """Points along a polyline (k, 2) no farther apart than ``step``, ends included."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.concatenate(out)


def turn_angles(path: np.ndarray) -> np.ndarray:
    """Turning angle (k-2,) at each interior waypoint of a polyline (k, 2), rad."""
    d = np.diff(path, axis=0)
    ang = np.arctan2(d[:, 1], d[:, 0])
    return np.abs((np.diff(ang) + np.pi) % (2 * np.pi) - np.pi)


# ------------------------------------------------------------------ drawing tendons
class Walker:
    """Draws one tendon path as a curvature-bounded random walk in the region,
    kept ``sep`` away from the paths already placed (``others``: segments)."""

    #: curvature candidates tried when the drifting one would hit the boundary
    N_CANDIDATES = 13

    def __init__(self, region: Region, st: PlantSettings):
        self.r, self.st = region, st
        self.kmax = 1.0 / (st.min_radius * region.L)
        self.step = 0.5 * region.margin
        self.look = st.min_radius * region.L
        #: the walk keeps a little more than the margin, so chords between its
        #: subsampled waypoints keep the margin itself
        self.walk_margin = 1.1 * region.margin
        self.corr = 0.15 * region.L  # correlation length of the curvature, m

    def _free(self, pts: np.ndarray, others: tuple[np.ndarray, np.ndarray], sep: float) -> np.ndarray:
        ok = self.r.clearance(pts) >= self.walk_margin
        if len(others[0]):
            ok &= distance_to_segments(pts, *others) >= sep
        return ok

    def start(self, rng: np.random.Generator, others, sep: float, tries: int = 200):
        """A random point (2,) with room around it, or None."""
        for _ in range(tries):
            p = rng.uniform(self.r.lo, self.r.hi)
            if self.r.inside(p)[0] and self._free(p[None], others, sep)[0]:
                return p
        return None

    def _heading(self, rng: np.random.Generator, p: np.ndarray, others, sep: float, reach: float) -> float:
        """A start heading (rad), drawn with weight (free straight run)^2 among 16, so
        that walks tend to start along a limb of the body rather than across it."""
        angles = rng.uniform(0.0, 2.0 * np.pi) + 2.0 * np.pi * np.arange(16) / 16
        s = self.step * np.arange(1, max(1, int(math.ceil(reach / self.step))) + 1)
        pts = p + s[None, :, None] * np.stack([np.cos(angles), np.sin(angles)], axis=-1)[:, None, :]
        free = self._free(pts.reshape(-1, 2), others, sep).reshape(pts.shape[:2])
        run = np.where(free.all(axis=1), len(s), free.argmin(axis=1)).astype(float)
        w = run ** 2
        if w.sum() == 0.0:
            return float(angles[0])
        return float(angles[rng.choice(len(angles), p=w / w.sum())])

    def _extend(self, rng: np.random.Generator, p: np.ndarray, theta: float, budget: float,
                others, sep: float, state: dict) -> list[np.ndarray]:
        """Walk from p (2,) with heading theta for up to ``budget`` m; the samples
        after p. ``state`` carries the heading range (in the frame of the forward
        walk: heading - ``state['offset']``) and the summed turning."""
        st, h = self.st, self.step
        decay = math.exp(-h / self.corr)
        spread = 0.4 * self.kmax * math.sqrt(1.0 - decay * decay)
        grid = np.linspace(-self.kmax, self.kmax, self.N_CANDIDATES)
        kappa, walked, out = 0.0, 0.0, []
        while walked + 0.5 * h < budget:
            want = float(np.clip(decay * kappa + spread * rng.standard_normal(), -self.kmax, self.kmax))
            cand = np.concatenate([[want], grid])
            heading = theta + cand * h - state["offset"]
            ok = ((np.maximum(state["hi"], heading) - np.minimum(state["lo"], heading)
                   <= st.max_heading_range)
                  & (state["turning"] + np.abs(cand) * h <= st.max_turning))
            n_look = max(1, int(math.ceil(min(self.look, budget - walked) / h)))
            look = _arc(p, theta, cand[ok], h * np.arange(1, n_look + 1))
            free = self._free(look.reshape(-1, 2), others, sep).reshape(look.shape[:2]).all(axis=1)
            if not free.any():
                break  # stuck: the walk ends here
            c = cand[ok][free]
            k = float(c[np.argmin(np.abs(c - want))])
            p = _arc(p, theta, np.array([k]), np.array([h]))[0, 0]
            theta += k * h
            state["lo"] = min(state["lo"], theta - state["offset"])
            state["hi"] = max(state["hi"], theta - state["offset"])
            state["turning"] += abs(k) * h
            kappa = k
            walked += h
            out.append(p)
        return out

    def from_exit(self, rng: np.random.Generator, others, sep: float) -> np.ndarray | None:
        """The samples (k, 2) of one walk that starts where the body's exit set lets a
        tendon leave: from a random point of it, straight in for ``lead`` m, then on
        as a walk; None when it is too short or its run in crosses another tendon."""
        st, h = self.st, self.step
        seg = self.r.exits.segments
        lengths = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
        k = rng.choice(len(seg), p=lengths / lengths.sum()) if lengths.sum() > 0 else 0
        a, b = seg[k]
        p0 = a + rng.uniform() * (b - a)
        along = (b - a) / max(float(np.linalg.norm(b - a)), 1e-300)
        inward = np.array([-along[1], along[0]])
        if not self.r.inside((p0 + 1e-3 * self.r.L * inward)[None])[0]:
            inward = -inward
        p0 = p0 + INSET * inward  # the waypoints are rounded to 1 um: the exit stays in the body
        lead = p0 + self.step * np.arange(1, int(math.ceil(self.r.lead / self.step)) + 1)[:, None] * inward
        if len(others[0]) and distance_to_segments(lead, *others).min() < sep:
            return None
        if not self._free(lead[-1:], others, sep)[0]:
            return None
        target = rng.uniform(st.min_length, st.max_length) * self.r.L
        theta = float(np.arctan2(inward[1], inward[0]))
        state = {"offset": 0.0, "lo": theta, "hi": theta, "turning": 0.0}
        fwd = self._extend(rng, lead[-1], theta, target - self.r.lead, others, sep=sep, state=state)
        if h * len(fwd) + self.r.lead < st.min_length * self.r.L - 1e-12:
            return None
        return np.vstack([p0, lead, *fwd])

    def walk(self, rng: np.random.Generator, others, sep: float) -> np.ndarray | None:
        """The samples (k, 2) of one walk (spacing ``step``), or None when it is too
        short. It runs forward from a random start and, if it gets stuck before its
        drawn length, on backwards from the start; where tendons leave the body, from
        the exit set (:meth:`from_exit`)."""
        st, h = self.st, self.step
        if self.r.exits is not None:
            return self.from_exit(rng, others, sep)
        p = self.start(rng, others, sep)
        if p is None:
            return None
        target = rng.uniform(st.min_length, st.max_length) * self.r.L
        theta = self._heading(rng, p, others, sep, min(self.look, target))
        state = {"offset": 0.0, "lo": theta, "hi": theta, "turning": 0.0}
        fwd = self._extend(rng, p, theta, target, others, sep=sep, state=state)
        back = []
        if h * len(fwd) + 0.5 * h < target:
            state["offset"] = np.pi
            back = self._extend(rng, p, theta + np.pi, target - h * len(fwd), others, sep=sep, state=state)
        if h * (len(fwd) + len(back)) < st.min_length * self.r.L - 1e-12:
            return None
        return np.array(back[::-1] + [p] + fwd)


def _waypoints(samples: np.ndarray, every: int = 2) -> np.ndarray:
    """Every ``every``-th walk sample and the last, rounded to 1 um: the waypoints (k, 2)."""
    idx = list(range(0, len(samples), every))
    if idx[-1] != len(samples) - 1:
        idx.append(len(samples) - 1)
    return np.round(samples[idx], 6)


def _tendon_ok(path: np.ndarray, region: Region, others, sep: float, st: PlantSettings) -> bool:
    """The final checks on a rounded path: inside with the margin (but on its run in
    from where it leaves the body), apart from the others, anchor away from the
    clamps, no kink."""
    dense = _polyline_samples(path, 0.25 * region.margin)
    held = np.linalg.norm(dense - path[-1], axis=1) >= region.lead if region.exits is not None else slice(None)
    if not region.inside(dense[:1])[0] or region.clearance(dense[held]).min() < region.margin:
        return False
    if len(others[0]) and distance_to_segments(dense, *others).min() < 0.9 * sep:
        return False
    if region.clamp_distance(path[:1])[0] < region.anchor_distance:
        return False
    return len(path) < 3 or turn_angles(path).max() < math.radians(30.0)


def path_segments(paths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """The segments of polylines (k_i, 2) as start and end points, each (e, 2)."""
    if not paths:
        return np.zeros((0, 2)), np.zeros((0, 2))
    return (np.concatenate([q[:-1] for q in paths]), np.concatenate([q[1:] for q in paths]))


def _draw_tendon(rng: np.random.Generator, walker: Walker, placed: list[np.ndarray],
                 st: PlantSettings) -> np.ndarray | None:
    """One tendon path (k, 2), anchor first, apart from ``placed``; None if none fits."""
    region = walker.r
    others = path_segments(placed)
    for attempt in range(st.walk_tries):
        # keep two fiber spacings from the other tendons where possible
        sep = (st.separation if attempt < st.walk_tries // 2 else st.margin) * region.spacing
        samples = walker.walk(rng, others, sep)
        if samples is None:
            continue
        # the anchor is the end farther from the clamps (or from where it leaves the body);
        # the pulled end the nearer
        d = region.clamp_distance(samples[[0, -1]])
        if region.exits is not None or d[1] > d[0]:
            samples = samples[::-1]
        path = _waypoints(samples)
        if _tendon_ok(path, region, others, sep, st):
            return path
    return None


def draw_layout(rng: np.random.Generator, walker: Walker, n: int,
                 st: PlantSettings) -> list[PlantedTendon] | None:
    paths: list[np.ndarray] = []
    for _ in range(n):
        path = _draw_tendon(rng, walker, paths, st)
        if path is None:
            return None
        paths.append(path)
    out = []
    for path in paths:
        length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        ratio = round(float(rng.uniform(*st.contraction)), 4)
        out.append(PlantedTendon(path, length, ratio * length, ratio))
    return out
