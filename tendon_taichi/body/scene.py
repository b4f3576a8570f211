"""Scene files: the TOML format of ``docs/scenes.md``, validated into typed objects.

Units are SI throughout (metres, pascals, newtons, kilograms). Every key is
optional unless marked *required*; the defaults below are the documented ones.

``[body]``
    ``outline`` (*required* unless ``mesh``): polygon ``[[x, y], ...]``, m,
    either orientation. ``holes``: list of polygons. ``mesh``: a triangle mesh
    file read with meshio (``.msh``, ``.vtu``, ``.obj``, ...), relative to the
    scene file. ``youngs_modulus`` 5e4 Pa, ``poisson_ratio`` 0.45,
    ``thickness`` 0.01 m, ``density`` 1100 kg/m^3, ``gravity`` [0, 0] m/s^2,
    ``max_triangle_area`` 8e-6 m^2 at resolution 1 (halves per level; for a
    mesh file: the file's mesh at level 1, refined to half its largest area
    per level).
    A 3D body (``docs/scenes.md``): ``depth`` (m) extrudes the outline along z
    from 0 to depth, with tetrahedra of edge ``edge_length`` (m, *required*, at
    level 1; divided by sqrt(2) per level); or ``mesh`` names a file of
    tetrahedra (``.msh``, ``.vtu``, ``.vtk``; used at level 1 only for now) in
    ``units`` "m" (default) or "mm". No ``thickness`` or ``max_triangle_area``;
    ``gravity``, boxes and points have three coordinates.
``[fibers]``
    ``spacing`` 0.005 m (divided by sqrt(2) per level), ``stiffness`` (EA)
    50 N, ``max_contraction`` (cmax) 0.33, ``max_payout`` (pmax) 0.5,
    ``eps`` 0.01 (width of the cubic zone of the unilateral energy, strain).
``[[fixed]]`` (*required*, one or more)
    ``box = [[xmin, ymin], [xmax, ymax]]``: nodes inside (edges included) are
    clamped.
``[[targets]]`` (*required*, one or more, unless ``[[poses]]``)
    ``point = [x, y]`` a material point of the body, ``goal = [x, y]`` where
    it should go, m.
``[[poses]]`` (instead of ``[[targets]]``: several target poses at once)
    ``name`` (default ``pose<i>``) and ``[[poses.targets]]`` as above. Each pose
    gets its own contractions; one tendon layout serves them all.
``[tendons]``
    The realizable robot's tendons: ``friction`` 0.1, the capstan friction
    coefficient mu of their channels (0: frictionless); ``clearance`` 0.02,
    the least distance of a route from the outline and the holes, as a
    fraction of the body size L; ``exit`` "inside" ("clamp" for a 3D body).
``[optimize]``
    See :class:`OptimizeSettings`.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from ..errors import SceneError
from ..objective.settings import Homotopy, OptimizeSettings, read_optimize
from ..tables import TableReader, as_point
from .geometry import (MIN_WIDTH_RATIO, normalize_polygon, outline_meets_box, polygon_self_intersects,
                       polygon_too_thin, polygons_overlap)
from .mesh import mesh_file_dim

#: a 3D body's mesh file units: metres per unit
UNITS = {"m": 1.0, "mm": 1e-3}
#: the [body] keys of 3D bodies only
SOLID_KEYS = ("depth", "edge_length", "units")
#: the [body] keys of 2D bodies only, and what a 3D body has instead
PLANE_KEYS = {"thickness": "a 3D body's thickness is its depth or its mesh",
              "max_triangle_area": "give edge_length, the tetrahedra's edge"}


@dataclass(frozen=True)
class Material:
    """Body material and loading: E (Pa), nu, thickness h (m; 2D bodies only), density
    (kg/m^3), gravity (dim,) m/s^2."""

    youngs_modulus: float = 5.0e4
    poisson_ratio: float = 0.45
    thickness: float = 0.01
    density: float = 1100.0
    gravity: tuple[float, ...] = (0.0, 0.0)

    @property
    def mu(self) -> float:
        """The shear modulus (Lame's mu) E / (2 (1 + nu)), Pa."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lam(self) -> float:
        """Lame's lambda E nu / ((1 + nu)(1 - 2 nu)), Pa."""
        nu = self.poisson_ratio
        return self.youngs_modulus * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


@dataclass(frozen=True)
class Body:
    """The body's shape (an outline with holes, extruded to ``depth`` in 3D, or a mesh
    file) and its material."""

    outline: np.ndarray | None  # (k, 2), counter-clockwise after loading
    holes: tuple[np.ndarray, ...]  # each (k, 2), clockwise after loading
    mesh_file: Path | None
    material: Material
    max_triangle_area: float | None  # m^2 at level 1 (2D)
    depth: float | None = None  # m: the outline extruded along z from 0 to depth (3D)
    edge_length: float | None = None  # m: the tetrahedra's edge at level 1 (3D)
    units: str = "m"  # the length unit of a 3D mesh file (:data:`UNITS`)
    tetrahedra: bool = False  # the mesh file holds tetrahedra (3D)

    @property
    def dim(self) -> int:
        """The body's dimension: 3 for an extruded outline or a mesh file of
        tetrahedra, else 2 (an outline, or a triangle mesh file)."""
        return 3 if self.depth is not None or self.tetrahedra else 2

    @property
    def scale(self) -> float:
        """Metres per unit of the mesh file's coordinates."""
        return UNITS[self.units]


@dataclass(frozen=True)
class FiberSettings:
    """The idealized robot's fiber lattice (``docs/method.md``)."""

    spacing: float = 0.005
    stiffness: float = 50.0
    max_contraction: float = 0.33
    max_payout: float = 0.5
    eps: float = 0.01


#: the largest friction coefficient a scene or the command line may give
MAX_FRICTION = 2.0
#: the largest clearance (fraction of L): a route must fit between the walls
MAX_CLEARANCE = 0.2
#: where a tendon may leave the body (``docs/method.md``, exits): its pull end inside the body,
#: on the outline where a [[fixed]] box clamps it, or anywhere on the outline
EXITS = ("inside", "clamp", "surface")


@dataclass(frozen=True)
class TendonSettings:
    """The built tendons (``docs/method.md``, friction and routes): ``friction`` mu
    of the capstan factor exp(-mu Theta) in the realizable robot and the metrics;
    ``clearance`` the least distance of a route from the outline and holes, x L;
    ``exit`` where a route's pull end leaves the body (:data:`EXITS`)."""

    friction: float = 0.1
    clearance: float = 0.02
    exit: str = "inside"

    def checked(self, origin: str = "command line") -> "TendonSettings":
        """Itself, or a SceneError naming the first value out of range."""
        for key, value, top in (("friction", self.friction, MAX_FRICTION),
                                ("clearance", self.clearance, MAX_CLEARANCE)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) \
                    or not 0.0 <= value <= top:
                raise SceneError(f"{origin}: tendons.{key} must be a number in [0, {top:g}] (got {value!r})")
        if self.exit not in EXITS:
            raise SceneError(f"{origin}: tendons.exit must be one of {', '.join(map(repr, EXITS))} "
                             f"(got {self.exit!r})")
        return self


#: the ``[tendons] exit`` of a scene that does not say, by the body's dimension
DEFAULT_EXIT = {2: TendonSettings.exit, 3: "clamp"}


@dataclass(frozen=True)
class Box:
    """An axis-aligned box, edges included: ``lo`` and ``hi`` corners (dim,), m."""

    lo: tuple[float, ...]
    hi: tuple[float, ...]

    def contains(self, points: np.ndarray, tol: float = 0.0) -> np.ndarray:
        p = np.asarray(points, dtype=float)
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        return np.all((p >= lo - tol) & (p <= hi + tol), axis=1)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """The distance (q,) m of points (q, dim) from the box (0 inside it)."""
        p = np.asarray(points, dtype=float)
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        return np.linalg.norm(np.maximum(np.maximum(lo - p, p - hi), 0.0), axis=1)


@dataclass(frozen=True)
class Target:
    """A material point (rest coordinates (dim,), m) and its goal position (dim,), m."""

    point: tuple[float, ...]
    goal: tuple[float, ...]


@dataclass(frozen=True)
class Pose:
    """A named target pose: the material points and goals to reach at once."""

    name: str
    targets: tuple[Target, ...]


@dataclass(frozen=True)
class Scene:
    """A validated scene. ``source`` is the TOML text it was read from."""

    name: str
    body: Body
    fibers: FiberSettings
    fixed: tuple[Box, ...]
    poses: tuple[Pose, ...]
    optimize: OptimizeSettings
    source: str
    origin: str  # a file path, or "builtin:<name>"
    tendons: TendonSettings = TendonSettings()

    def clamp_distance(self, points: np.ndarray) -> np.ndarray:
        """The distance (q,) m of points (q, dim) from the nearest [[fixed]] box."""
        return np.min([box.distance(points) for box in self.fixed], axis=0)

    @property
    def targets(self) -> tuple[Target, ...]:
        """Every pose's targets, pose after pose."""
        return tuple(t for p in self.poses for t in p.targets)

    @property
    def target_pose(self) -> np.ndarray:
        """int (t,): the pose each of :attr:`targets` belongs to."""
        return np.repeat(np.arange(len(self.poses)), [len(p.targets) for p in self.poses])

    def target_label(self, i: int) -> str:
        """How the scene file names target ``i`` of :attr:`targets` (for messages)."""
        if len(self.poses) == 1:
            return f"targets[{i}]"
        p = int(self.target_pose[i])
        first = sum(len(q.targets) for q in self.poses[:p])
        return f"poses[{p}].targets[{i - first}]"

    def with_optimize(self, **changes) -> "Scene":
        """A copy with some optimize settings replaced (CLI overrides)."""
        return replace(self, optimize=replace(self.optimize, **changes))

    def with_tendons(self, origin: str = "command line", **changes) -> "Scene":
        """A copy with some [tendons] settings replaced (None values ignored), checked."""
        changes = {k: v for k, v in changes.items() if v is not None}
        if not changes:
            return self
        return _clamp_checked(replace(self, tendons=replace(self.tendons, **changes).checked(origin)))


# --------------------------------------------------------------------------- parsing

def _read_body(r: TableReader, base_dir: Path | None, check_files: bool = True) -> Body:
    E = r.number("youngs_modulus", Material.youngs_modulus, gt=0.0)
    nu = r.number("poisson_ratio", Material.poisson_ratio, gt=-1.0, lt=0.5)
    h = r.number("thickness", Material.thickness, gt=0.0)
    rho = r.number("density", Material.density, ge=0.0)
    mesh_file = _mesh_file(r, base_dir, check_files)
    dim = _body_dim(r, mesh_file)
    g = r.point("gravity", (0.0,) * dim, dim=dim, unit="components")
    material = Material(E, nu, h, rho, g)
    if dim == 3:
        return _solid_body(r, mesh_file, material)
    area = r.number("max_triangle_area", None, gt=0.0)
    extra = [key for key in SOLID_KEYS if r.has(key)]
    if extra:
        raise SceneError(f"{r.origin}: body.{extra[0]} applies to 3D bodies only (an outline with a depth, "
                         "or a mesh file of tetrahedra)")
    outline, holes = (None, ()) if mesh_file is not None else _read_outline(r)
    if mesh_file is None and area is None:
        area = 8.0e-6
    r.finish()
    return Body(outline, holes, mesh_file, material, area)


def _mesh_file(r: TableReader, base_dir: Path | None, check_files: bool) -> Path | None:
    """The body's mesh file (relative to ``base_dir``), None for an outline; one line
    where there is not exactly one of them, or the file is missing (``check_files``)."""
    if r.has("mesh") == r.has("outline"):
        raise SceneError(f"{r.origin}: [body] needs exactly one of 'outline' or 'mesh'")
    if not r.has("mesh"):
        return None
    name = r.raw("mesh")
    if not isinstance(name, str) or not name:
        raise SceneError(f"{r.origin}: body.mesh must be a file name")
    mesh_file = Path(name)
    if not mesh_file.is_absolute():
        mesh_file = (base_dir or Path.cwd()) / mesh_file
    if check_files and not mesh_file.is_file():
        raise SceneError(f"{r.origin}: body.mesh file '{mesh_file}' does not exist")
    if r.has("holes"):
        raise SceneError(f"{r.origin}: body.holes cannot be combined with body.mesh")
    return mesh_file


def _body_dim(r: TableReader, mesh_file: Path | None) -> int:
    """3 for an outline with a ``depth`` or a mesh file of tetrahedra, else 2; a mesh
    file that is not there (a recorded run's) is 3D when the body has 3D keys."""
    if r.has("depth"):
        return 3
    if mesh_file is None:
        return 2
    if mesh_file.is_file():
        try:
            return mesh_file_dim(mesh_file)
        except SceneError as exc:
            raise SceneError(f"{r.origin}: body.mesh: {exc}") from None
    return 3 if r.has("edge_length") or r.has("units") else 2


def _solid_body(r: TableReader, mesh_file: Path | None, material: Material) -> Body:
    """A 3D [body]: an outline extruded to ``depth`` with tetrahedra of ``edge_length``,
    or a mesh file of tetrahedra in ``units``."""
    for key, instead in PLANE_KEYS.items():
        if r.has(key):
            raise SceneError(f"{r.origin}: body.{key} does not apply to a 3D body ({instead})")
    depth = r.number("depth", None, gt=0.0)
    edge = r.number("edge_length", None, gt=0.0)
    units = r.choice("units", "m", tuple(UNITS))
    if mesh_file is not None:
        if depth is not None:
            raise SceneError(f"{r.origin}: body.depth extrudes an outline; it cannot be combined with body.mesh")
        r.finish()
        return Body(None, (), mesh_file, material, None, edge_length=edge, units=units, tetrahedra=True)
    if edge is None:
        raise SceneError(f"{r.origin}: body.edge_length is required for an extruded body (the tetrahedra's "
                         "edge at level 1, m)")
    if r.has("units"):
        raise SceneError(f"{r.origin}: body.units applies to a mesh file only (an outline and its depth are "
                         "in metres)")
    outline, holes = _read_outline(r)
    r.finish()
    return Body(outline, holes, None, material, None, depth=depth, edge_length=edge)


def _read_outline(r: TableReader) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """The body's outline (k, 2), counter-clockwise, and its holes, each (k, 2) clockwise, m."""
    outline = r.polygon(r.raw("outline"), "outline")
    if polygon_self_intersects(outline):
        raise SceneError(f"{r.origin}: body.outline is self-intersecting or degenerate")
    _check_width(outline, f"{r.origin}: body.outline")
    outline = normalize_polygon(outline, ccw=True)
    if not r.has("holes"):
        return outline, ()
    raw = r.raw("holes")
    if not isinstance(raw, list):
        raise SceneError(f"{r.origin}: body.holes must be a list of polygons")
    hs = []
    for i, poly in enumerate(raw):
        hole = r.polygon(poly, f"holes[{i}]")
        if polygon_self_intersects(hole):
            raise SceneError(f"{r.origin}: body.holes[{i}] is self-intersecting or degenerate")
        _check_width(hole, f"{r.origin}: body.holes[{i}]")
        hs.append(normalize_polygon(hole, ccw=False))
    holes = tuple(hs)
    problem = polygons_overlap(outline, holes)
    if problem:
        raise SceneError(f"{r.origin}: body.{problem}")
    return outline, holes


def _read_fibers(r: TableReader) -> FiberSettings:
    d = FiberSettings()
    fs = FiberSettings(
        spacing=r.number("spacing", d.spacing, gt=0.0),
        stiffness=r.number("stiffness", d.stiffness, gt=0.0),
        max_contraction=r.number("max_contraction", d.max_contraction, gt=0.0, lt=1.0),
        max_payout=r.number("max_payout", d.max_payout, ge=0.0),
        eps=r.number("eps", d.eps, gt=0.0),
    )
    r.finish()
    return fs


def _read_tendons(r: TableReader, dim: int) -> TendonSettings:
    d = TendonSettings()
    ts = TendonSettings(friction=r.number("friction", d.friction, ge=0.0, le=MAX_FRICTION),
                        clearance=r.number("clearance", d.clearance, ge=0.0, le=MAX_CLEARANCE),
                        exit=r.choice("exit", DEFAULT_EXIT[dim], EXITS))
    r.finish()
    return ts


def _array_of_tables(doc: TableReader, key: str, prefix: str = "") -> list[dict]:
    if not doc.has(key):
        raise SceneError(f"{doc.origin}: at least one [[{prefix}{key}]] entry is required")
    items = doc.raw(key)
    if not isinstance(items, list) or not items:
        raise SceneError(f"{doc.origin}: [[{prefix}{key}]] must be a non-empty array of tables")
    return items


def _check_width(poly: np.ndarray, where: str) -> None:
    width = polygon_too_thin(poly)
    if width is not None:
        raise SceneError(f"{where} is too thin to mesh: {width:.3g} m wide on average, under "
                         f"{MIN_WIDTH_RATIO:g} of its extent")


def parse_scene(text: str, origin: str = "<scene>", base_dir: Path | None = None,
                default_name: str = "scene", check_files: bool = True) -> Scene:
    """Parse and validate scene TOML ``text``; ``origin`` names it in errors.
    ``check_files=False`` accepts a mesh file that is not there (a recorded run
    carries its mesh)."""
    try:
        doc_raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: invalid TOML: {exc}") from None
    except RecursionError:
        raise SceneError(f"{origin}: invalid TOML: arrays or tables nested too deeply") from None
    doc = TableReader(doc_raw, "scene", origin)
    name = doc.raw("name") if doc.has("name") else default_name
    if not isinstance(name, str) or not name:
        raise SceneError(f"{origin}: 'name' must be a non-empty string")
    if not doc.has("body"):
        raise SceneError(f"{origin}: a [body] table is required")
    body = _read_body(TableReader(doc.raw("body"), "body", origin), base_dir, check_files)
    fibers = _read_fibers(TableReader(doc.raw("fibers") if doc.has("fibers") else {}, "fibers", origin))

    fixed = _read_fixed(doc, body.dim)
    poses = _read_poses(doc, body.dim)
    opt = read_optimize(TableReader(doc.raw("optimize") if doc.has("optimize") else {},
                                    "optimize", origin), fibers)
    tendons = _read_tendons(TableReader(doc.raw("tendons") if doc.has("tendons") else {}, "tendons", origin),
                            body.dim)
    doc.finish()
    return _clamp_checked(Scene(name, body, fibers, fixed, poses, optimize=opt, source=text, origin=origin,
                                tendons=tendons))


#: how a [[fixed]] box is written, by the body's dimension
_BOX_FORMS = {2: "[[xmin, ymin], [xmax, ymax]]", 3: "[[xmin, ymin, zmin], [xmax, ymax, zmax]]"}


def _read_fixed(doc: TableReader, dim: int) -> tuple[Box, ...]:
    """The [[fixed]] boxes of a ``dim``-dimensional body."""
    origin = doc.origin
    fixed = []
    for i, item in enumerate(_array_of_tables(doc, "fixed")):
        r = TableReader(item, f"fixed[{i}]", origin)
        if not r.has("box"):
            raise SceneError(f"{origin}: fixed[{i}].box is required")
        box = r.raw("box")
        if not isinstance(box, list) or len(box) != 2:
            raise SceneError(f"{origin}: fixed[{i}].box must be {_BOX_FORMS[dim]}")
        lo, hi = (as_point(c, f"{origin}: fixed[{i}].box", dim, "coordinates per corner") for c in box)
        if any(a > b for a, b in zip(lo, hi)):
            raise SceneError(f"{origin}: fixed[{i}].box has min > max")
        r.finish()
        fixed.append(Box(lo, hi))
    return tuple(fixed)


def _clamp_checked(scene: Scene) -> Scene:
    """The scene, or a SceneError where its tendons must leave at the clamp and no
    [[fixed]] box meets its outline (known before a mesh: an outline body's)."""
    body = scene.body
    if scene.tendons.exit != "clamp" or body.outline is None or body.dim != 2:
        return scene
    if any(outline_meets_box(body.outline, box.lo, box.hi) for box in scene.fixed):
        return scene
    raise SceneError(f"{scene.origin}: tendons.exit = \"clamp\" but no [[fixed]] box meets the outline")


def _read_targets(holder: TableReader, where: str, dim: int) -> tuple[Target, ...]:
    targets = []
    for i, item in enumerate(_array_of_tables(holder, "targets", where)):
        r = TableReader(item, f"{where}targets[{i}]", holder.origin)
        targets.append(Target(r.point("point", required=True, dim=dim), r.point("goal", required=True, dim=dim)))
        r.finish()
    return tuple(targets)


def _read_poses(doc: TableReader, dim: int) -> tuple[Pose, ...]:
    """``[[targets]]`` (one pose) or ``[[poses]]`` with their own ``[[poses.targets]]``,
    points of ``dim`` coordinates."""
    if doc.has("poses") and doc.has("targets"):
        raise SceneError(f"{doc.origin}: give either [[targets]] (one pose) or [[poses]], not both")
    if not doc.has("poses"):
        return (Pose("pose", _read_targets(doc, "", dim)),)
    poses = []
    for i, item in enumerate(_array_of_tables(doc, "poses")):
        r = TableReader(item, f"poses[{i}]", doc.origin)
        name = r.raw("name") if r.has("name") else f"pose{i}"
        if not isinstance(name, str) or not name:
            raise SceneError(f"{doc.origin}: poses[{i}].name must be a non-empty string")
        poses.append(Pose(name, _read_targets(r, f"poses[{i}].", dim)))
        r.finish()
    names = [p.name for p in poses]
    if len(set(names)) != len(names):
        raise SceneError(f"{doc.origin}: pose names must differ (got {', '.join(names)})")
    return tuple(poses)


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with the package."""
    folder = resources.files("tendon_taichi") / "scenes"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a built-in scene by name, or a scene TOML file by path."""
    s = str(name_or_path)
    path = Path(s)
    if s.endswith(".toml") or path.is_file():
        try:
            text = path.read_text()
        except FileNotFoundError:
            raise SceneError(f"scene file '{s}' does not exist") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneError(f"cannot read scene file '{s}': {exc}") from None
        return parse_scene(text, origin=s, base_dir=path.resolve().parent, default_name=path.stem)
    if s in builtin_scenes():
        res = resources.files("tendon_taichi") / "scenes" / f"{s}.toml"
        return parse_scene(res.read_text(), origin=f"builtin:{s}", base_dir=None, default_name=s)
    raise SceneError(f"unknown scene '{s}': not a file, and not a built-in scene "
                     f"({', '.join(builtin_scenes())})")


def with_overrides(scene: Scene, overrides: dict, origin: str = "command line") -> Scene:
    """A copy of ``scene`` with [optimize] settings replaced, validated like the file.

    ``overrides`` maps optimize keys (``homotopy`` keys as ``k0``, ``factor``,
    ``k_min``) to values; None values are ignored. A ``k0`` at its default, not
    overridden, is left for :func:`~tendon_taichi.objective.settings.read_optimize`
    to raise to a larger ``k_min``."""
    table = {k: v for k, v in scene.optimize.__dict__.items() if k != "homotopy"}
    hom = dict(scene.optimize.homotopy.__dict__)
    if overrides.get("k0") is None and hom["k0"] == Homotopy().k0:
        del hom["k0"]
    for key, value in overrides.items():
        if value is None:
            continue
        if key in hom:
            hom[key] = value
        elif key in table:
            table[key] = value
        else:
            raise SceneError(f"{origin}: unknown optimize setting '{key}'")
    table["homotopy"] = hom
    opt = read_optimize(TableReader(table, "optimize", origin), scene.fibers)
    return replace(scene, optimize=opt)
