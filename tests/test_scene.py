"""Scenes, meshing, the fiber lattice and embeddings."""

import re

import numpy as np
import pytest

from tendon_taichi import SceneError, build_problem, builtin_scenes, load_scene, parse_scene
from tendon_taichi.body.geometry import points_in_polygon
from tendon_taichi.body.scene import FiberSettings, Material, with_overrides
from tendon_taichi.objective.settings import OptimizeSettings

SQUARE = """
name = "sq"
[body]
outline = {outline}
max_triangle_area = 2e-5
[[fixed]]
box = [[-1, -0.0001], [1, 0.0001]]
[[targets]]
point = [0.02, 0.04]
goal = [0.02, 0.05]
"""


def _square(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]"):
    return parse_scene(SQUARE.format(outline=outline))


def test_builtin_scenes_parse_and_mesh():
    assert {"t_shape", "finger", "gripper"} <= set(builtin_scenes())
    for name in builtin_scenes():
        p = build_problem(load_scene(name), 1)
        assert p.fixed.any() and p.fibers.n_fibers > 100 and len(p.target_goal) >= 1


def test_t_shape_sizes_match_the_design_card():
    p = build_problem(load_scene("t_shape"), 1)
    c = p.counts()
    assert 300 <= c["nodes"] <= 420 and 550 <= c["triangles"] <= 720 and 480 <= c["fibers"] <= 620
    X = p.mesh.nodes
    assert np.allclose(X.min(0), [-0.05, 0.0]) and np.allclose(X.max(0), [0.05, 0.08])
    # the bottom edge is clamped, nothing else
    assert np.all(np.abs(X[p.fixed, 1]) < 1e-12) and p.fixed.sum() >= 3


def test_defaults_are_documented_values():
    sc = _square()
    assert sc.body.material == Material()
    assert sc.fibers == FiberSettings()
    assert sc.optimize == OptimizeSettings()
    assert sc.optimize.sparsity == 1e-4 and sc.optimize.continuity == 2.5e-5
    assert sc.optimize.homotopy.k0 == 0.25 and sc.optimize.homotopy.factor == 0.5


def test_a_k_min_above_the_default_k0_starts_the_homotopy_there_unless_k0_is_given():
    hom = lambda table: _with_optimize(table).optimize.homotopy  # noqa: E731
    assert (hom("homotopy = { k_min = 0.4 }").k0, hom("homotopy = { k_min = 0.1 }").k0) == (0.4, 0.25)
    assert hom("homotopy = { k0 = 1.0, k_min = 0.4 }").k0 == 1.0
    with pytest.raises(SceneError, match=r"k_min \(0.4\) must be <= k0 \(0.2\)"):
        hom("homotopy = { k0 = 0.2, k_min = 0.4 }")
    sc = load_scene("t_shape")
    assert with_overrides(sc, {"k_min": 0.4}).optimize.homotopy.k0 == 0.4  # --k-min 0.4 alone
    assert with_overrides(sc, {"k_min": 0.1}).optimize.homotopy.k0 == 0.25
    with pytest.raises(SceneError, match="must be <= k0"):
        with_overrides(sc, {"k0": 0.2, "k_min": 0.4})


def _with_optimize(table: str):
    return parse_scene(SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                       + f"\n[optimize]\n{table}\n")


def test_resolution_halves_area_and_shrinks_spacing():
    sc = load_scene("finger")
    p1, p2, p3 = (build_problem(sc, k) for k in (1, 2, 3))
    assert np.abs(p1.mesh.areas).max() <= 8e-6 * (1 + 1e-9)
    assert np.abs(p2.mesh.areas).max() <= 4e-6 * (1 + 1e-9)
    assert np.abs(p3.mesh.areas).max() <= 2e-6 * (1 + 1e-9)
    assert p2.fibers.spacing == pytest.approx(0.005 / np.sqrt(2))
    assert p3.fibers.spacing == pytest.approx(0.0025)
    assert p1.mesh.n_nodes < p2.mesh.n_nodes < p3.mesh.n_nodes


def _closed_inside(points, outline, holes, tol):
    from tendon_taichi.body.geometry import normalize_polygon
    def near(poly):
        a, b = poly, np.roll(poly, -1, axis=0)
        ab = b - a
        t = np.clip(np.einsum("pkd,kd->pk", points[:, None] - a[None], ab) / (ab * ab).sum(1), 0, 1)
        return np.linalg.norm(points[:, None] - (a[None] + t[..., None] * ab[None]), axis=2).min(1) <= tol
    inside = points_in_polygon(points, outline) | near(outline)
    for h in holes:
        inside &= ~points_in_polygon(points, h) | near(normalize_polygon(h))
    return inside


@pytest.mark.parametrize("name", ["t_shape", "gripper"])
def test_every_fiber_lies_inside_the_body(name):
    sc = load_scene(name)
    p = build_problem(sc, 1)
    f = p.fibers
    t = np.linspace(0, 1, 41)
    a, b = f.nodes[f.edges[:, 0]], f.nodes[f.edges[:, 1]]
    pts = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 2)
    assert _closed_inside(pts, sc.body.outline, sc.body.holes, 1e-9 * p.size).all()
    # 8-neighbour lattice: lengths s or s sqrt 2, 4 directions (up to sign)
    L = f.a0 / f.spacing
    assert np.all(np.isclose(L, 1) | np.isclose(L, np.sqrt(2)))
    d = np.round(f.directions * np.sign(f.directions[:, :1] + 1e-9 * f.directions[:, 1:]), 6)
    assert len(np.unique(d, axis=0)) == 4


def test_lattice_is_complete_inside_a_square():
    """A square aligned with the lattice gets every one of its 8-neighbour edges."""
    p = build_problem(_square(), 1)
    k = 9  # 0.04 / 0.005 + 1 points per side
    assert len(p.fibers.nodes) == k * k
    assert p.fibers.n_fibers == 2 * k * (k - 1) + 2 * (k - 1) ** 2


def test_fiber_nodes_and_targets_are_embedded():
    p = build_problem(load_scene("gripper"), 2)
    X, T = p.mesh.nodes, p.mesh.triangles
    assert np.abs(p.fibers.embedding.positions(T, X) - p.fibers.nodes).max() <= 1e-12
    assert np.all(p.fibers.embedding.bary >= 0) and np.allclose(p.fibers.embedding.bary.sum(1), 1)
    pts = np.array([t.point for t in p.scene.targets])
    assert np.abs(p.target_positions(X) - pts).max() <= 1e-12


def test_continuity_pairs_and_weights():
    p = build_problem(_square(), 1)
    pairs = p.fibers.pairs
    assert set(np.round(np.unique(pairs.cos2), 9)) == {0.0, 0.5, 1.0}
    e = p.fibers.edges
    shares = [pairs.node[k] in e[pairs.fibers[k, 0]] and pairs.node[k] in e[pairs.fibers[k, 1]]
              for k in range(len(pairs.node))]
    assert all(shares)
    # an interior lattice node has 8 fibers: 28 pairs there
    counts = np.bincount(pairs.node)
    assert counts.max() == 28


def test_orientation_is_normalized():
    ccw = build_problem(_square(), 1)
    cw = build_problem(_square("[[0, 0], [0, 0.04], [0.04, 0.04], [0.04, 0]]"), 1)
    assert np.isclose(np.abs(ccw.mesh.areas).sum(), np.abs(cw.mesh.areas).sum())
    assert np.all(cw.mesh.areas > 0)
    assert ccw.fibers.n_fibers == cw.fibers.n_fibers


def test_target_on_the_boundary_is_accepted():
    sc = parse_scene(SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                     .replace("point = [0.02, 0.04]", "point = [0.04, 0.04]"))
    p = build_problem(sc, 1)
    assert np.abs(p.target_positions(p.mesh.nodes) - [0.04, 0.04]).max() < 1e-12


def test_a_corrupt_mesh_file_is_a_scene_error(tmp_path, capfd):
    """meshio prints and exits on a cut VTU file; that becomes one SceneError."""
    import meshio

    pts = np.array([[0, 0, 0], [0.04, 0, 0], [0, 0.04, 0.0]])
    meshio.write(str(tmp_path / "ok.vtu"), meshio.Mesh(pts, [("triangle", np.array([[0, 1, 2]]))]))
    data = (tmp_path / "ok.vtu").read_bytes()
    (tmp_path / "body.vtu").write_bytes(data[: len(data) // 2])
    (tmp_path / "s.toml").write_text('name = "cut"\n[body]\nmesh = "body.vtu"\n[[fixed]]\nbox = [[-1, -1], [1, 0]]\n'
                                     "[[targets]]\npoint = [0.01, 0.01]\ngoal = [0.01, 0.02]\n")
    with pytest.raises(SceneError, match=re.escape(f"cannot read mesh file '{tmp_path / 'body.vtu'}': Couldn't read")):
        build_problem(load_scene(tmp_path / "s.toml"), 1)
    assert capfd.readouterr() == ("", "")


@pytest.mark.parametrize("fmt,suffix", [("vtu", ".vtu"), ("gmsh22", ".msh"), ("obj", ".obj")])
def test_mesh_file_body(tmp_path, fmt, suffix):
    import meshio

    ref = build_problem(load_scene("gripper"), 1)
    pts = np.column_stack([ref.mesh.nodes, np.zeros(ref.mesh.n_nodes)])
    path = tmp_path / f"body{suffix}"
    meshio.write(str(path), meshio.Mesh(pts, [("triangle", ref.mesh.triangles)]), file_format=fmt)
    text = load_scene("gripper").source
    text = text.replace("max_triangle_area = 8.0e-6", "")
    start = text.index("outline =")
    end = text.index("youngs_modulus")
    text = text[:start] + f'mesh = "{path.name}"\n' + text[end:]
    (tmp_path / "s.toml").write_text(text)
    sc = load_scene(tmp_path / "s.toml")
    p1 = build_problem(sc, 1)
    assert p1.mesh.n_triangles == ref.mesh.n_triangles
    assert np.allclose(np.sort(p1.mesh.nodes, axis=0), np.sort(ref.mesh.nodes, axis=0))
    assert p1.fibers.n_fibers == ref.fibers.n_fibers
    p2 = build_problem(sc, 2)
    assert np.abs(p2.mesh.areas).max() <= 0.5 * np.abs(p1.mesh.areas).max() * (1 + 1e-9)
    # the refined mesh keeps the body: same area, same hole
    assert np.isclose(np.abs(p2.mesh.areas).sum(), np.abs(p1.mesh.areas).sum())


BAD = {
    "bad TOML": ("name = [unclosed", "invalid TOML"),
    "self-intersecting outline": (SQUARE.format(outline="[[0, 0], [0.04, 0.04], [0.04, 0], [0, 0.04]]"),
                                  "self-intersecting"),
    "no clamped node": (SQUARE.format(outline="[[0, 0.01], [0.04, 0.01], [0.04, 0.05], [0, 0.05]]"),
                        "not clamped"),
    "a 1 um body": ("name = 'tiny'\n[body]\noutline = [[0, 0], [1e-6, 0], [1e-6, 1e-6], [0, 1e-6]]\n"
                    "[[fixed]]\nbox = [[-1, -1e-8], [1, 1e-8]]\n[[targets]]\npoint = [5e-7, 1e-6]\n"
                    "goal = [5e-7, 1.1e-6]\n", "no fiber fits inside the body at spacing 0.005 m"),
    "every node clamped": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                           + "[[fixed]]\nbox = [[-1, -1], [1, 1]]\n", "every mesh node lies in a [[fixed]] box"),
    "target outside": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                       .replace("point = [0.02, 0.04]", "point = [0.05, 0.02]"),
                       "point [0.05, 0.02] lies outside the body"),
    "negative modulus": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                         .replace("max_triangle_area", "youngs_modulus = -5.0\nmax_triangle_area"),
                         "youngs_modulus must be > 0"),
    "nu = 0.5": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                 .replace("max_triangle_area", "poisson_ratio = 0.5\nmax_triangle_area"),
                 "poisson_ratio must be < 0.5"),
    "unknown key": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                    .replace("max_triangle_area", "youngs_modulos = 5e4\nmax_triangle_area"),
                    "unknown key 'youngs_modulos' in body"),
    "hole outside": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                     .replace("max_triangle_area", "holes = [[[0.05, 0.01], [0.06, 0.01], [0.06, 0.02]]]\n"
                                                   "max_triangle_area"), "not inside the outline"),
    "missing target goal": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                            .replace("goal = [0.02, 0.05]", ""), "goal is required"),
    "no fixed": ("name = 'x'\n[body]\noutline = [[0, 0], [1, 0], [0, 1]]\n[[targets]]\npoint = [0.1, 0.1]\n"
                 "goal = [0.1, 0.1]\n", "[[fixed]]"),
    "a sliver": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 1e-12], [0, 1e-12]]"),
                 "body.outline is too thin to mesh: "),
    "deeply nested TOML": ("x = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deeply"),
    "a goal 1e300 m away": (SQUARE.format(outline="[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]")
                            .replace("goal = [0.02, 0.05]", "goal = [1e300, 0.05]"),
                            "targets[0].goal must be [x, y] with numbers of magnitude at most 1e+06"),
    "missing mesh file": ("name = 'x'\n[body]\nmesh = 'nothere.vtu'\n[[fixed]]\nbox = [[0, 0], [1, 1]]\n"
                          "[[targets]]\npoint = [0.1, 0.1]\ngoal = [0.1, 0.1]\n", "does not exist"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_scenes_raise_scene_error(case, tmp_path):
    text, message = BAD[case]
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SceneError, match=re.escape(message)):
        build_problem(load_scene(path), 1)


@pytest.mark.parametrize("name", ["t_shape", "gripper", "cross"])
def test_the_size_estimate_is_close_to_the_mesh(name):
    """What a scene is refused by (before meshing): the DOFs within 10 % of what meshing
    gives, the fibers never under the lattice's count and at most 1.5 times it."""
    from tendon_taichi.body.geometry import signed_area
    from tendon_taichi.body.size import estimate

    sc = load_scene(name)
    p = build_problem(sc, 2)
    area = abs(signed_area(sc.body.outline)) - sum(abs(signed_area(h)) for h in sc.body.holes)
    dofs, fibers = estimate(area, sc.body.max_triangle_area / 2, sc.fibers.spacing / np.sqrt(2))
    assert dofs == pytest.approx(p.counts()["dofs"], rel=0.1)
    assert p.fibers.n_fibers <= fibers <= 1.5 * p.fibers.n_fibers
