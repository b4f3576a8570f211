"""Planted layouts: scenes whose goals a known set of tendons reaches exactly.

:func:`plant` draws a few random but plausible tendons in a scene's body,
contracts them, solves the body with only those tendons as sliding cables
(the realizable robot of DESIGN.md section 2) and writes where the scene's
target points went as their goals. The result is a benchmark with a known
answer: an optimizer and its extractors should find tendons like the planted
ones, and a realizable pose error near zero is attainable.

A tendon is the path of a random walk with bounded curvature: its curvature
drifts (an Ornstein-Uhlenbeck process, mean zero) and is bent away from the
boundary when a look-ahead arc would come closer than the margin, so paths
follow the body's limbs instead of bouncing off them. Every draw comes from
one ``numpy.random.Generator`` seeded by ``seed``, so a (scene, tendon count,
seed, level) gives byte-identical outputs.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .cables import CableSet
from .errors import ConvergenceError, InputError
from .problem import Problem, build_problem
from .scene import Scene, load_scene, parse_scene

#: the most tendons a planted layout may have
MAX_TENDONS = 5


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
    tried before giving up; ``walk_tries``: walks per tendon and draw.
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


# ------------------------------------------------------------------ geometry
class _Region:
    """The body as the walks see it: boundary segments (outline and holes), the
    clamped nodes, the size L and the clearances, all in metres."""

    def __init__(self, problem: Problem, st: PlantSettings):
        body = problem.scene.body
        if body.outline is not None:
            loops = [body.outline, *body.holes]
            self.a = np.concatenate(loops)
            self.b = np.concatenate([np.roll(q, -1, axis=0) for q in loops])
        else:
            e = problem.mesh.boundary_edges
            self.a, self.b = problem.mesh.nodes[e[:, 0]], problem.mesh.nodes[e[:, 1]]
        self.lo, self.hi = problem.mesh.nodes.min(axis=0), problem.mesh.nodes.max(axis=0)
        self.L = problem.size
        self.spacing = problem.fibers.spacing
        self.margin = st.margin * self.spacing
        self.clamped = cKDTree(problem.mesh.nodes[problem.fixed])
        #: how far the anchor must be from the clamps: anchor_distance L, or half
        #: the farthest any point is (a body clamped in its middle), m
        reach = float(self.clamp_distance(problem.mesh.nodes).max())
        self.anchor_distance = min(st.anchor_distance * self.L, 0.5 * reach)

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance (q,) from points (q, 2) to the boundary, m."""
        return _distance_to_segments(points, self.a, self.b)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Even-odd test against the boundary segments: bool (q,)."""
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        x, y = p[:, :1], p[:, 1:]
        ay, by = self.a[None, :, 1], self.b[None, :, 1]
        crosses = (ay > y) != (by > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = self.a[None, :, 0] + (y - ay) * (self.b[None, :, 0] - self.a[None, :, 0]) / (by - ay)
        return (np.sum(crosses & (x < xi), axis=1) % 2) == 1

    def clamp_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance (q,) from points (q, 2) to the nearest clamped node, m."""
        return self.clamped.query(np.asarray(points, dtype=float).reshape(-1, 2))[0]


def _distance_to_segments(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (q,) from points (q, 2) to the nearest of segments a[j] -> b[j] (e, 2);
    inf when there is no segment."""
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(a) == 0:
        return np.full(len(p), np.inf)
    ab = b - a
    ap = p[:, None, :] - a[None, :, :]
    t = np.clip((ap * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300)[None], 0.0, 1.0)
    d = ap - t[..., None] * ab[None]
    return np.sqrt((d * d).sum(-1).min(axis=1))


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
class _Walker:
    """Draws one tendon path as a curvature-bounded random walk in the region,
    kept ``sep`` away from the paths already placed (``others``: segments)."""

    #: curvature candidates tried when the drifting one would hit the boundary
    N_CANDIDATES = 13

    def __init__(self, region: _Region, st: PlantSettings):
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
            ok &= _distance_to_segments(pts, *others) >= sep
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

    def walk(self, rng: np.random.Generator, others, sep: float) -> np.ndarray | None:
        """The samples (k, 2) of one walk (spacing ``step``), or None when it is too
        short. It runs forward from a random start and, if it gets stuck before its
        drawn length, on backwards from the start."""
        st, h = self.st, self.step
        p = self.start(rng, others, sep)
        if p is None:
            return None
        target = rng.uniform(st.min_length, st.max_length) * self.r.L
        theta = self._heading(rng, p, others, sep, min(self.look, target))
        state = {"offset": 0.0, "lo": theta, "hi": theta, "turning": 0.0}
        fwd = self._extend(rng, p, theta, target, others, sep, state)
        back = []
        if h * len(fwd) + 0.5 * h < target:
            state["offset"] = np.pi
            back = self._extend(rng, p, theta + np.pi, target - h * len(fwd), others, sep, state)
        if h * (len(fwd) + len(back)) < st.min_length * self.r.L - 1e-12:
            return None
        return np.array(back[::-1] + [p] + fwd)


def _waypoints(samples: np.ndarray, every: int = 2) -> np.ndarray:
    """Every ``every``-th walk sample and the last, rounded to 1 um: the waypoints (k, 2)."""
    idx = list(range(0, len(samples), every))
    if idx[-1] != len(samples) - 1:
        idx.append(len(samples) - 1)
    return np.round(samples[idx], 6)


def _tendon_ok(path: np.ndarray, region: _Region, others, sep: float, st: PlantSettings) -> bool:
    """The final checks on a rounded path: inside with the margin, apart from the
    others, anchor away from the clamps, no kink."""
    dense = _polyline_samples(path, 0.25 * region.margin)
    if not region.inside(dense[:1])[0] or region.clearance(dense).min() < region.margin:
        return False
    if len(others[0]) and _distance_to_segments(dense, *others).min() < 0.9 * sep:
        return False
    if region.clamp_distance(path[:1])[0] < region.anchor_distance:
        return False
    return len(path) < 3 or turn_angles(path).max() < math.radians(30.0)


def _segments(paths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    if not paths:
        return np.zeros((0, 2)), np.zeros((0, 2))
    return (np.concatenate([q[:-1] for q in paths]), np.concatenate([q[1:] for q in paths]))


def _draw_tendon(rng: np.random.Generator, walker: _Walker, placed: list[np.ndarray],
                 st: PlantSettings) -> np.ndarray | None:
    """One tendon path (k, 2), anchor first, apart from ``placed``; None if none fits."""
    region = walker.r
    others = _segments(placed)
    for attempt in range(st.walk_tries):
        # keep two fiber spacings from the other tendons where possible
        sep = (st.separation if attempt < st.walk_tries // 2 else st.margin) * region.spacing
        samples = walker.walk(rng, others, sep)
        if samples is None:
            continue
        # the anchor is the end farther from the clamps; the pulled end the nearer
        d = region.clamp_distance(samples[[0, -1]])
        if d[1] > d[0]:
            samples = samples[::-1]
        path = _waypoints(samples)
        if _tendon_ok(path, region, others, sep, st):
            return path
    return None


def _draw_layout(rng: np.random.Generator, walker: _Walker, n: int,
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


# ------------------------------------------------------------------ simulating
def solve_tendons(problem: Problem, tendons: list[PlantedTendon], ac=None):
    """The equilibrium of the body with only these tendons as sliding cables (EA =
    the scene's fiber stiffness), contracted by their ``contraction`` (or ``ac``) (m)."""
    from .model import Model
    from .solvers import NewtonSolver

    cables = CableSet.polylines(problem.mesh, [t.waypoints for t in tendons],
                                problem.scene.fibers.stiffness)
    ac = np.array([t.contraction for t in tendons]) if ac is None else np.asarray(ac, dtype=float)
    return NewtonSolver(Model.from_problem(problem, cables=cables), "direct").solve(ac=ac)


def pose_ratios(rng: np.random.Generator, tendons: list[PlantedTendon], n_poses: int,
                st: PlantSettings) -> np.ndarray:
    """Contraction ratios (P, n) of the tendons in each pose: pose 0 contracts every
    tendon by its drawn ratio; each further pose contracts a random non-empty subset
    (a proper one when there are several tendons, so the poses need different
    tendons), with ratios drawn anew, and pays the others out by the largest
    contraction ratio (slack)."""
    n = len(tendons)
    out = [np.array([t.ratio for t in tendons])]
    for _ in range(1, n_poses):
        on = np.zeros(n, dtype=bool)
        while not on.any() or (n > 1 and on.all()):
            on = rng.random(n) < 0.5
        ratios = np.round(rng.uniform(*st.contraction, n), 4)
        out.append(np.where(on, ratios, -st.contraction[1]))
    return np.array(out)


# ------------------------------------------------------------------ writing
def planted_name(scene: Scene, n_tendons: int, seed: int, poses: int = 1) -> str:
    """``<scene>_planted_<n>t_s<seed>``, with ``_<P>p`` for several poses."""
    return f"{scene.name}_planted_{n_tendons}t_s{seed}" + (f"_{poses}p" if poses > 1 else "")


def _source_command(scene: Scene, n: int, seed: int, level: int, poses: int = 1) -> str:
    src = scene.origin[len("builtin:"):] if scene.origin.startswith("builtin:") else scene.origin
    return (f"tendon-taichi planted {src} --tendons {n} --seed {seed} --level {level}"
            + (f" --poses {poses}" if poses > 1 else ""))


def _strip_header(text: str) -> str:
    """The TOML text without its leading comment block (it describes the old goals)."""
    lines = text.splitlines()
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        i += 1
    return "\n".join(lines[i:]) + "\n"


def _fmt(v: float) -> str:
    return f"{v:.10f}"


def _poses_toml(scene: Scene, poses: list[np.ndarray]) -> str:
    """``[[poses]]`` tables, one per goal array (t, 2) m, over the scene's target points."""
    out = []
    for i, goals in enumerate(poses):
        out.append(f'\n[[poses]]\nname = "pose{i}"\n')
        for t, g in zip(scene.targets, goals):
            out.append("\n[[poses.targets]]\npoint = [{}, {}]\ngoal = [{}, {}]\n".format(
                *(repr(float(v)) for v in t.point), *map(_fmt, g)))
    return "".join(out)


def scene_text(scene: Scene, name: str, goals, header: list[str]) -> str:
    """A copy of the scene's TOML with ``name``, the target ``goals`` (t, 2) m written
    to 10 decimals, and the comment ``header`` lines in place of its own. A list of
    several goal arrays replaces the ``[[targets]]`` with one ``[[poses]]`` each."""
    body = _strip_header(scene.source)
    if isinstance(goals, list) and len(goals) > 1:
        blocks = re.split(r"(?m)^(?=\[)", body)
        body = "".join(b for b in blocks if not b.startswith("[[targets]]")).rstrip() + "\n"
        body += _poses_toml(scene, goals)
        goals = np.zeros((0, 2))
    elif isinstance(goals, list):
        goals = goals[0]
    hits = list(re.finditer(r"(?m)^(\s*goal\s*=\s*)\[[^\]]*\]", body))
    if len(hits) != len(goals) and len(goals):
        raise InputError(f"{scene.origin}: cannot rewrite the goals of its [[targets]] "
                         f"(found {len(hits)} 'goal = [x, y]' lines for {len(goals)} targets)")
    it = iter(goals)
    if len(goals):
        body = re.sub(r"(?m)^(\s*goal\s*=\s*)\[[^\]]*\]",
                      lambda m: m.group(1) + "[{}, {}]".format(*map(_fmt, next(it))), body)
    name_line = f'name = "{name}"'
    body, count = re.subn(r'(?m)^name\s*=\s*"[^"\n]*"', name_line, body, count=1)
    if not count:
        body = name_line + "\n" + body
    if scene.body.mesh_file is not None:
        body = re.sub(r'(?m)^(\s*mesh\s*=\s*)"[^"\n]*"',
                      lambda m: m.group(1) + json.dumps(str(scene.body.mesh_file)), body, count=1)
    return "".join(f"# {h}".rstrip() + "\n" for h in header) + body


def _header(scene: Scene, name: str, tendons: list[PlantedTendon], n: int, seed: int, level: int,
            disp_rel: float, ratios: np.ndarray | None = None) -> list[str]:
    P = 1 if ratios is None else len(ratios)
    rows = [f"Planted from '{scene.name}': its goals are where {n} random tendon"
            f"{'s' if n > 1 else ''} (seed {seed}, level {level}),",
            "contracted and solved as sliding cables, bring the target points"
            + (f" in each of {P} poses" if P > 1 else "") + ". Made by",
            f"  {_source_command(scene, n, seed, level, P)}",
            f"The tendons (waypoints, contractions) are in {name}.json:"]
    for i, t in enumerate(tendons):
        rows.append(f"  {i + 1}: {100 * t.length:.2f} cm, contracted {100 * t.ratio:.2f} % "
                    f"({1e3 * t.contraction:.3f} mm), tension {t.tension:.4f} N")
    if P > 1:
        for q in range(1, P):
            rows.append(f"  pose{q}: contraction ratios "
                        + ", ".join(f"{100 * r:.2f} %" for r in ratios[q]) + " (negative: paid out, slack)")
    rows.append(f"Largest target displacement: {100 * disp_rel:.2f} % of L.")
    return rows


# ------------------------------------------------------------------ the entry point
def plant(scene: Scene | str, n_tendons: int, seed: int, level: int = 2,
          settings: PlantSettings | None = None, poses: int = 1) -> tuple[str, dict]:
    """Draw ``n_tendons`` (1..5) random tendons in ``scene`` (a Scene or a name/path),
    solve the body with only them at resolution ``level`` and return the scene's
    TOML text with their equilibrium as its goals, and the layout (dict, JSON-ready:
    ``scene``, ``name``, ``seed``, ``level``, ``tendons`` (each ``waypoints`` (m,
    rest, anchor first), ``length`` (m), ``contraction`` (m), ``contraction_ratio``,
    ``tension`` (N)), ``planted_length`` (m), ``pose`` (``max_target_displacement``
    m, ``body_size`` L m), ``targets``, ``draws``). Deterministic in its inputs.
    ``poses`` > 1: the same tendons make several poses (:func:`pose_ratios`); the
    scene gets one ``[[poses]]`` table each, the layout a ``poses`` list (per pose
    ``name``, ``contraction_ratios``, ``tensions``, ``max_target_displacement``,
    ``targets``); its tendons' contraction and tension are those of pose 0.
    A draw whose pose is too small (largest target displacement below
    ``min_displacement`` L) or whose solve fails is redrawn from the same stream."""
    st = settings or PlantSettings()
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if isinstance(n_tendons, bool) or not isinstance(n_tendons, (int, np.integer)) \
            or not 1 <= n_tendons <= MAX_TENDONS:
        raise InputError(f"the number of tendons must be 1..{MAX_TENDONS} (got {n_tendons!r})")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"the seed must be an integer >= 0 (got {seed!r})")
    if isinstance(poses, bool) or not isinstance(poses, (int, np.integer)) or not 1 <= poses <= 4:
        raise InputError(f"the number of poses must be 1..4 (got {poses!r})")
    if len(scene.poses) > 1:
        raise InputError(f"{scene.origin}: plant from a one-pose scene (it has {len(scene.poses)} poses)")
    n_tendons, seed, poses = int(n_tendons), int(seed), int(poses)
    problem = build_problem(scene, level)
    region = _Region(problem, st)
    walker = _Walker(region, st)
    rng = np.random.default_rng(seed)
    if walker.start(rng, _segments([]), 0.0, tries=2000) is None:
        raise InputError(f"{scene.origin}: no point of the body is {1e3 * walker.walk_margin:.2f} mm "
                         "from its boundary: no tendon fits")
    L = problem.size
    rest = problem.target_positions(problem.mesh.nodes)
    placed_any = False
    for draw in range(1, st.max_draws + 1):
        tendons = _draw_layout(rng, walker, n_tendons, st)
        if tendons is None:
            continue
        placed_any = True
        ratios = pose_ratios(rng, tendons, poses, st) if poses > 1 else None
        lengths = np.array([t.length for t in tendons])
        try:
            eqs = [solve_tendons(problem, tendons, None if ratios is None else r * lengths)
                   for r in (ratios if ratios is not None else [None])]
        except ConvergenceError:
            continue
        pose_goals = [problem.target_positions(eq.x) for eq in eqs]
        pose_disp = [np.linalg.norm(g - rest, axis=1) for g in pose_goals]
        if min(d.max() for d in pose_disp) < st.min_displacement * L:
            continue
        eq, disp = eqs[0], np.max(pose_disp, axis=0)
        for t, tau in zip(tendons, eq.tau):
            t.tension = float(tau)
        pose_goals = [np.array([[float(_fmt(v)) for v in g] for g in goals]) for goals in pose_goals]
        goals = pose_goals[0]
        name = planted_name(scene, n_tendons, seed, poses)
        text = scene_text(scene, name, pose_goals,
                          _header(scene, name, tendons, n_tendons, seed, level, disp.max() / L, ratios))
        parse_scene(text, origin=name, base_dir=None, default_name=name)  # it must load
        extra = {} if ratios is None else {"poses": [
            {"name": f"pose{q}", "contraction_ratios": ratios[q].tolist(),
             "tensions": eqs[q].tau.tolist(), "max_target_displacement": float(pose_disp[q].max()),
             "max_target_displacement_rel": float(pose_disp[q].max() / L),
             "targets": [{"point": list(tg.point), "goal": pose_goals[q][i].tolist(),
                          "displacement": float(pose_disp[q][i])} for i, tg in enumerate(scene.targets)]}
            for q in range(poses)]}
        layout = {
            "scene": scene.name, "name": name, "seed": seed, "level": int(level),
            "n_tendons": n_tendons,
            "tendons": [t.as_json() for t in tendons],
            "planted_length": float(sum(t.length for t in tendons)),
            "pose": {"max_target_displacement": float(disp.max()), "body_size": L,
                     "max_target_displacement_rel": float(disp.max() / L)},
            "targets": [{"point": list(tg.point), "goal": goals[i].tolist(), "displacement": float(disp[i])}
                        for i, tg in enumerate(scene.targets)],
            "margin": region.margin, "draws": draw, **extra,
        }
        return text, layout
    why = ("the drawn tendons never moved the targets by " f"{100 * st.min_displacement:g} % of L"
           if placed_any else f"no {n_tendons} tendon(s) fit in the body")
    raise InputError(f"{scene.origin}: cannot plant a layout after {st.max_draws} draws: {why}")


def layout_json(layout: dict) -> str:
    """The layout as written to ``<name>.json`` (indented; each [x, y] on one line)."""
    text = json.dumps(layout, indent=2)
    return re.sub(r"\[\s+(-?[\d.eE+-]+),\s+(-?[\d.eE+-]+)\s+\]", r"[\1, \2]", text) + "\n"


def write_planted(out_dir, text: str, layout: dict):
    """Write ``DIR/<name>.toml`` and ``DIR/<name>.json`` atomically (both or neither);
    return their paths."""
    from pathlib import Path

    from .export import atomic_path

    out = Path(out_dir)
    toml_path, json_path = out / f"{layout['name']}.toml", out / f"{layout['name']}.json"
    with atomic_path(toml_path) as tmp_toml, atomic_path(json_path) as tmp_json:
        tmp_toml.write_text(text)
        tmp_json.write_text(layout_json(layout))
    return toml_path, json_path


def plot_layouts(path, cases: list[tuple[Scene, dict]], columns: int = 4, dpi: int = 72):
    """A PNG gallery, one panel per (planted scene, layout): the rest outline (grey),
    the planted equilibrium's outline (black), the tendons on it (colours; dot: anchor,
    thin: at rest), the target points at rest (blue) and their goals (green x)."""
    import io
    from pathlib import Path

    import matplotlib
    matplotlib.use("Agg")
    from PIL import Image
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from .export import atomic_path

    rows = -(-len(cases) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(2.6 * columns, 2.6 * rows), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
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
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    plt.close(fig)
    buf.seek(0)
    with Image.open(buf) as im, atomic_path(path) as tmp:  # a 64-colour palette: a small file
        im.convert("RGB").quantize(64).save(tmp, format="png", optimize=True)
    return Path(path)
