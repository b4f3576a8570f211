"""Scenes nobody tuned for: random bodies for planted cases (``docs/method.md``,
the planted suite).

A generated scene is drawn from one seed: an outline of one of :data:`SHAPES`
(a star, a hook, a tapered finger, a wavy strip, a notched bar, two lobes on a
narrow neck), 0-3 round holes where they fit, a clamp on one of its four sides
(an axis-aligned box holding at least :data:`CLAMPED` of the body's size of
its outline), 2-4 targets on the outline far from the clamp, spread apart. The
body is 7-12 cm long; its mesh and lattice are scaled with its size as the
built-in scenes' are, so a case costs about what theirs do. :func:`generated_case`
then plants 1-3 random tendons in it (:func:`~.plant.plant`), in one or two
poses: its goals have a known answer. Every draw comes from one
``numpy.random.Generator`` seeded by the case's seed: the same seed, the same
files, byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon, box

from ..body.scene import Scene, parse_scene
from ..errors import InputError
from .plant import plant, write_planted

#: the outline families, drawn in turn by seed
SHAPES = ("star", "hook", "tapered", "wavy", "notched", "neck")
#: the body's longest extent is drawn from this range, m
EXTENT = (0.07, 0.12)
#: the built-in scenes' fiber spacing and triangle area at level 1 for a body of REFERENCE size L (m)
SPACING, AREA, REFERENCE = 0.005, 8.0e-6, 0.11
#: the clamp holds at least this much of the outline (x the body's extent): the planted tendons
#: leave the body there, each a channel apart, clear of the clamp's corners (0.12 left no room
#: for three in most bodies)
CLAMPED = 0.25
#: holes keep this far from the outline and from each other (x the body's extent)
HOLE_MARGIN = 0.06
#: targets lie this far inside the outline (x the body's extent)
TARGET_INSET = 0.002
#: draws of a body tried per case before giving up
MAX_BODY_DRAWS = 20
#: after this many bodies that take none of the drawn tendons, each next one is asked for one fewer
#: (at least one): all of them must leave through the clamp, and some bodies have room for fewer
FEWER_AFTER = 8


def _outline(rng: np.random.Generator, shape: str, extent: float) -> Polygon:
    """A body outline of family ``shape`` about ``extent`` m long."""
    if shape == "star":
        k, a = int(rng.integers(3, 6)), rng.uniform(0.2, 0.4)
        t = np.linspace(0.0, 2 * np.pi, 72, endpoint=False)
        r = 0.5 * extent / (1 + a) * (1 + a * np.cos(k * t + rng.uniform(0, 2 * np.pi)))
        return Polygon(np.c_[r * np.cos(t), r * np.sin(t)])
    if shape == "hook":
        width, radius = rng.uniform(0.016, 0.024), rng.uniform(0.15, 0.25) * extent
        straight, sweep = extent - radius - width, np.radians(rng.uniform(120, 200))
        arc = np.linspace(0.0, sweep, 24)
        centre = np.array([straight, radius])
        curve = np.c_[centre[0] + radius * np.sin(arc), centre[1] - radius * np.cos(arc)]
        line = LineString(np.vstack([[0.0, 0.0], curve]))
        return line.buffer(width / 2, cap_style="flat", join_style="round", quad_segs=6)
    if shape == "tapered":
        base, tip = rng.uniform(0.024, 0.036), rng.uniform(0.008, 0.014)
        s = np.linspace(0.0, 1.0, 24)
        bend = rng.uniform(-0.15, 0.15) * extent
        centre = np.c_[s * extent, bend * s * s]
        half = 0.5 * (base + (tip - base) * s)
        normal = np.c_[-2 * bend * s, np.full_like(s, extent)]
        normal /= np.linalg.norm(normal, axis=1)[:, None]
        return Polygon(np.vstack([centre - half[:, None] * normal, (centre + half[:, None] * normal)[::-1]]))
    if shape == "wavy":
        s = np.linspace(0.0, extent, 48)
        m, amp, width = rng.uniform(1.0, 2.5), rng.uniform(0.05, 0.12) * extent, rng.uniform(0.018, 0.03)
        phase = rng.uniform(0, 2 * np.pi)
        y = amp * np.sin(2 * np.pi * m * s / extent + phase)
        half = 0.5 * width * (1 + 0.25 * np.sin(2 * np.pi * 2 * m * s / extent))
        return Polygon(np.vstack([np.c_[s, y - half], np.c_[s, y + half][::-1]]))
    if shape == "notched":
        width = rng.uniform(0.025, 0.04)
        body = box(0.0, 0.0, extent, width)
        for _ in range(int(rng.integers(2, 5))):
            x, w = rng.uniform(0.2, 0.9) * extent, rng.uniform(0.06, 0.12) * extent
            depth = rng.uniform(0.25, 0.45) * width
            y = 0.0 if rng.uniform() < 0.5 else width
            tri = Polygon([(x - w / 2, y), (x + w / 2, y), (x, y + depth if y == 0.0 else y - depth)])
            body = body.difference(tri)
        return body
    if shape == "neck":
        lobe, neck = rng.uniform(0.28, 0.38) * extent, rng.uniform(0.009, 0.014)
        left = Point(lobe / 2, 0.0).buffer(lobe / 2, quad_segs=12)
        right = Point(extent - lobe / 2, 0.0).buffer(lobe / 2 * rng.uniform(0.8, 1.0), quad_segs=12)
        bar = box(lobe / 2, -neck / 2, extent - lobe / 2, neck / 2)
        return shapely.union_all([left, right, bar])
    raise ValueError(f"unknown shape {shape!r}")


def _holes(rng: np.random.Generator, body: Polygon, extent: float) -> list[Polygon]:
    """0-3 round holes (radius 2.5-6 mm) where they fit, each keeping HOLE_MARGIN x
    extent from the outline and from the others."""
    out: list[Polygon] = []
    margin = HOLE_MARGIN * extent
    for _ in range(int(rng.integers(0, 4))):
        r = rng.uniform(0.0025, 0.006)
        room = body.buffer(-(r + margin))
        for h in out:
            room = room.difference(h.buffer(r + margin))
        if room.is_empty or room.area <= 0:
            continue
        x0, y0, x1, y1 = room.bounds
        for _ in range(200):
            c = rng.uniform([x0, y0], [x1, y1])
            if room.contains(Point(c)):
                out.append(Point(c).buffer(r, quad_segs=6))
                break
    return out


def _clamp(rng: np.random.Generator, body: Polygon, extent: float) -> tuple[np.ndarray, np.ndarray]:
    """An axis-aligned box on one of the body's four sides (drawn) holding at least
    CLAMPED x extent of its outline: its corners (lo, hi), m."""
    side = int(rng.integers(0, 4))  # -x, +x, -y, +y
    axis, sign = side // 2, (-1, 1)[side % 2]
    x0, y0, x1, y1 = body.bounds
    lo, hi = np.array([x0, y0]) - 1e-3, np.array([x1, y1]) + 1e-3
    edge = (x0, x1, y0, y1)[side]
    ring = body.exterior
    band = 0.01 * extent
    while band < 0.3 * extent:
        a, b = np.array(lo), np.array(hi)
        if sign < 0:
            b[axis] = edge + band
        else:
            a[axis] = edge - band
        if ring.intersection(box(*a, *b)).length >= CLAMPED * extent:
            return a, b
        band *= 1.3
    return a, b


def _targets(rng: np.random.Generator, body: Polygon, clamp: tuple[np.ndarray, np.ndarray], extent: float,
             count: int) -> np.ndarray:
    """``count`` points (count, 2) on the outline, far from the clamp (at least half
    as far as the farthest), spread apart (each next the farthest from those chosen)."""
    ring = body.buffer(-TARGET_INSET * extent).exterior  # just inside: a point on the outline, rounded, may not be
    s = np.linspace(0.0, ring.length, 400, endpoint=False)
    pts = shapely.get_coordinates(shapely.line_interpolate_point(ring, s))
    held = box(*clamp[0], *clamp[1])
    d = shapely.distance(shapely.points(pts), held)
    far = pts[d >= 0.5 * d.max()]
    chosen = [far[int(rng.integers(len(far)))]]
    while len(chosen) < count:
        gap = np.min(np.linalg.norm(far[:, None] - np.array(chosen)[None], axis=2), axis=1)
        chosen.append(far[int(np.argmax(gap))])
    return np.array(chosen)


def _fmt(v: float) -> str:
    return f"{float(v):.6f}".rstrip("0").rstrip(".") if v != 0 else "0.0"


def _ring(coords: np.ndarray) -> str:
    return "[" + ", ".join(f"[{_fmt(x)}, {_fmt(y)}]" for x, y in coords) + "]"


@dataclass(frozen=True)
class DrawnBody:
    """A drawn body: its outline (``body``, m), round ``holes``, the ``clamp`` box's
    corners (lo, hi), the ``targets`` (t, 2) on its outline and its ``extent`` (m)."""

    body: Polygon
    holes: list[Polygon]
    clamp: tuple[np.ndarray, np.ndarray]
    targets: np.ndarray
    extent: float


def scene_toml(name: str, drawn: DrawnBody, header: str) -> str:
    """The scene's TOML text (outline counter-clockwise, holes clockwise), the
    comment ``header`` first."""
    body = shapely.geometry.polygon.orient(drawn.body, 1.0)
    clamp, targets, scale = drawn.clamp, drawn.targets, drawn.extent / REFERENCE
    outline = np.asarray(body.exterior.coords)[:-1]
    rings = [np.asarray(shapely.geometry.polygon.orient(h, 1.0).exterior.coords)[:-1][::-1] for h in drawn.holes]
    lines = [f"# {header}", f'name = "{name}"', "", "[body]", f"outline = {_ring(outline)}"]
    if rings:
        lines.append("holes = [" + ", ".join(_ring(r) for r in rings) + "]")
    lines += ["youngs_modulus = 5.0e4", "poisson_ratio = 0.45", "thickness = 0.01",
              f"max_triangle_area = {AREA * scale * scale:.3e}", "", "[fibers]",
              f"spacing = {SPACING * scale:.6f}", "stiffness = 50.0", "", "[[fixed]]",
              f"box = [[{_fmt(clamp[0][0])}, {_fmt(clamp[0][1])}], [{_fmt(clamp[1][0])}, {_fmt(clamp[1][1])}]]"]
    for p in targets:
        lines += ["", "[[targets]]", f"point = [{_fmt(p[0])}, {_fmt(p[1])}]", f"goal = [{_fmt(p[0])}, {_fmt(p[1])}]"]
    return "\n".join(lines) + "\n"


def generated_scene(seed: int, attempt: int = 0) -> Scene:
    """The random body of case ``seed`` (its ``attempt``-th draw), as a scene whose
    goals are its targets' rest positions (module docstring)."""
    rng = np.random.default_rng([seed, attempt])
    shape = SHAPES[seed % len(SHAPES)]
    extent = rng.uniform(*EXTENT)
    body = shapely.make_valid(_outline(rng, shape, extent))
    if body.geom_type != "Polygon":  # a notch that cut the bar in two: its largest piece
        body = max(getattr(body, "geoms", [body]), key=lambda g: g.area)
    body = shapely.simplify(body, 1e-4 * extent)
    holes = _holes(rng, body, extent)
    clamp = _clamp(rng, body, extent)
    targets = _targets(rng, body, clamp, extent, int(rng.integers(2, 5)))
    name = f"gen{seed:03d}_{shape}"
    text = scene_toml(name, DrawnBody(body, holes, clamp, targets, extent),
                      f"Generated: {shape}, {len(holes)} hole(s), seed {seed}, draw {attempt} "
                      f"(tendon-taichi planted-bench --generated).")
    return parse_scene(text, origin=name, base_dir=None, default_name=name)


def generated_case(seed: int, level: int = 2) -> tuple[str, dict]:
    """Case ``seed`` of the generated suite: a random body (:func:`generated_scene`)
    with 1-3 planted tendons in one or two poses, drawn from the seed; the scene's
    TOML text and the planted layout (:func:`~.plant.plant`). A body in which no
    such layout can be planted is drawn again (at most MAX_BODY_DRAWS times), after
    FEWER_AFTER of them with one tendon fewer each time (at least one)."""
    rng = np.random.default_rng([seed, 73])
    drawn, poses = int(rng.integers(1, 4)), int(rng.integers(1, 3))
    why = ""
    for attempt in range(MAX_BODY_DRAWS):
        scene = generated_scene(seed, attempt)
        tendons = max(1, drawn - attempt // FEWER_AFTER)  # bodies that take none: one tendon fewer
        try:
            return plant(scene, tendons, seed, level, poses=poses)
        except InputError as exc:
            why = str(exc)
    raise InputError(f"generated case {seed}: no body of {MAX_BODY_DRAWS} draws takes {drawn} planted "
                     f"tendon(s) or fewer: {why}")


def generate_suite(count: int, seed: int, folder: str | Path, say=None) -> Path:
    """Cases ``seed`` .. ``seed + count - 1`` of the generated suite
    (:func:`generated_case`) written into ``folder`` as ``NAME.toml`` and
    ``NAME.json`` (a planted suite, :func:`~.bench.load_suite`); ``say`` hears of
    each. Returns the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(count):
        text, layout = generated_case(seed + i)
        write_planted(folder, text, layout)
        if say is not None:
            say(f"generated [{i + 1}/{count}] {layout['name']}: {layout['n_tendons']} planted tendon(s), "
                f"{len(layout.get('poses', [])) or 1} pose(s)")
    return folder
