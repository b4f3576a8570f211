"""3D scenes: an extruded outline or a tetrahedral mesh file parses as a 3D body and
builds a problem (tetrahedra, clamps, the cubic lattice, embedded targets); bad 3D
input is one line naming the key; the physics of a 3D body is one clear line."""

import re

import meshio
import numpy as np
import pytest

from tendon_taichi import SceneError, build_problem, load_scene, parse_scene
from tendon_taichi.body.dimension import SOLID, dimension_of
from tendon_taichi.body.solid import estimate_solid, extruded_volume
from tendon_taichi.body.surface import SurfaceWalls
from tendon_taichi.body.tets import TetMesh
from tendon_taichi.errors import TendonError

#: a 6 x 1.5 cm finger, 1.5 cm deep, clamped at x <= 2 mm, two targets
FINGER3D = """
name = "finger3d"
[body]
outline = [[0, 0], [0.06, 0], [0.06, 0.015], [0, 0.015]]
depth = 0.015
edge_length = 0.004
gravity = [0.0, -9.81, 0.0]
[[fixed]]
box = [[-1, -1, -1], [0.002, 1, 1]]
[[targets]]
point = [0.06, 0.0075, 0.0075]
goal = [0.05, 0.025, 0.0075]
[[targets]]
point = [0.03, 0.015, 0.01]
goal = [0.03, 0.02, 0.012]
[tendons]
exit = "inside"
"""

#: a 2 cm cube of tetrahedra in a mesh file in millimetres, clamped at z = 0
CUBE = """
name = "cube"
[body]
mesh = "cube.vtu"
units = "mm"
[[fixed]]
box = [[-1, -1, -1], [1, 1, 0.0001]]
[[targets]]
point = [0.01, 0.01, 0.02]
goal = [0.015, 0.01, 0.018]
[tendons]
exit = "inside"
"""

MSG_PHYSICS = "3D bodies can be meshed and rigged, but their physics (element kernels) is not built yet"


def cube_tets(n: int = 4, side: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """A cube of ``side`` (mm) cut into n^3 cubes of 6 tetrahedra each (the same
    split in every cube, so neighbours share their faces' diagonals): nodes (k, 3) and
    tetrahedra (6 n^3, 4) of positive volume."""
    g = np.linspace(0.0, side, n + 1)
    nodes = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    idx = np.arange((n + 1) ** 3).reshape(n + 1, n + 1, n + 1)
    paths = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    tets = []
    for i, j, k in np.ndindex(n, n, n):
        for path in paths:  # the corner-to-corner walks along x, y, z in every order
            c, corners = np.array([i, j, k]), [idx[i, j, k]]
            for axis in path:
                c = c.copy()
                c[axis] += 1
                corners.append(idx[tuple(c)])
            tets.append(corners)
    tets = np.array(tets)
    p = nodes[tets]
    odd = np.einsum("kd,kd->k", p[:, 1] - p[:, 0], np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 0])) < 0
    tets[odd] = tets[odd][:, [0, 2, 1, 3]]  # every one of positive volume, as a mesher writes them
    return nodes, tets


def write_scene(folder, text: str, name: str = "s.toml"):
    (folder / name).write_text(text)
    return folder / name


@pytest.fixture(scope="module")
def finger():
    return parse_scene(FINGER3D, origin="finger3d.toml")


@pytest.fixture(scope="module")
def levels(finger):
    return build_problem(finger, 1), build_problem(finger, 2)


@pytest.fixture
def cube_file(tmp_path):
    nodes, tets = cube_tets()
    meshio.write(str(tmp_path / "cube.vtu"), meshio.Mesh(nodes, [("tetra", tets)]))
    return tmp_path / "cube.vtu"


def mean_edge(mesh: TetMesh) -> float:
    t = mesh.tetrahedra
    e = np.unique(np.sort(t[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2), axis=1), axis=0)
    return float(np.linalg.norm(mesh.nodes[e[:, 0]] - mesh.nodes[e[:, 1]], axis=1).mean())


def test_an_extruded_outline_is_a_3d_body(finger):
    body = finger.body
    assert body.dim == 3 and dimension_of(finger) is SOLID
    assert body.depth == 0.015 and body.edge_length == 0.004 and body.max_triangle_area is None
    assert body.material.gravity == (0.0, -9.81, 0.0)
    assert finger.fixed[0].hi == (0.002, 1.0, 1.0) and finger.targets[1].point == (0.03, 0.015, 0.01)
    assert finger.tendons.exit == "inside"
    assert parse_scene(FINGER3D.replace('exit = "inside"', "")).tendons.exit == "clamp"


def test_the_extruded_finger_builds_at_two_levels(finger, levels):
    p1, p2 = levels
    for p in levels:
        assert isinstance(p.mesh, TetMesh) and p.dim == 3 and p.mesh.volumes.min() > 0
        assert p.mesh.volumes.sum() == pytest.approx(0.06 * 0.015 * 0.015, rel=1e-9)
        on = p.mesh.nodes[:, 0] <= 0.002 + 1e-9 * p.size
        assert np.array_equal(p.fixed, on) and 0 < p.fixed.sum() < p.mesh.n_nodes
        assert np.abs(p.target_positions(p.mesh.nodes) - [t.point for t in finger.targets]).max() < 1e-12
        assert p.fibers.n_fibers > 0 and p.fibers.nodes.shape[1] == 3
        assert isinstance(p.walls, SurfaceWalls) and p.exits is None
        c = p.counts()
        assert list(c) == ["nodes", "tetrahedra", "fibers", "dofs"] and c["dofs"] == 3 * int((~p.fixed).sum())
    assert p2.mesh.n_tetrahedra > p1.mesh.n_tetrahedra
    assert mean_edge(p2.mesh) / mean_edge(p1.mesh) == pytest.approx(1 / np.sqrt(2), rel=0.15)
    assert p2.fibers.spacing == pytest.approx(p1.fibers.spacing / np.sqrt(2))


def test_waypoints_are_located_in_the_tetrahedra(levels):
    p = levels[0]
    points = np.array([[0.01, 0.005, 0.005], [0.05, 0.01, 0.012]])
    emb = p.embed_waypoints(np.array([0]), points, hint=np.array([0, 0]))
    assert np.abs(emb.positions(p.mesh.simplices, p.mesh.nodes) - points).max() < 1e-12


def test_the_size_estimate_bounds_the_extrusion(finger, levels):
    """The DOFs (3 per node) estimated before meshing are within 25 % of the mesh's, the
    fibers within a factor 2 of the lattice's."""
    for level, p in enumerate(levels, start=1):
        scale = np.sqrt(2.0) ** (level - 1)
        dofs, fibers = estimate_solid(extruded_volume(finger), 0.004 / scale, finger.fibers.spacing / scale)
        assert dofs == pytest.approx(3 * p.mesh.n_nodes, rel=0.25)
        assert 0.5 * p.fibers.n_fibers <= fibers <= 2.0 * p.fibers.n_fibers


def test_a_tet_mesh_file_in_millimetres_is_a_3d_body_in_metres(tmp_path, cube_file):
    scene = load_scene(write_scene(tmp_path, CUBE))
    assert scene.body.dim == 3 and scene.body.units == "mm" and scene.body.edge_length is None
    p = build_problem(scene, 1)
    assert np.allclose(p.mesh.nodes.max(axis=0), 0.02) and np.allclose(p.mesh.nodes.min(axis=0), 0.0)
    assert p.mesh.volumes.sum() == pytest.approx(0.02 ** 3, rel=1e-9)
    assert p.mesh.n_tetrahedra == 6 * 4 ** 3 and p.fixed.sum() == 25 and p.fibers.n_fibers > 0
    assert np.abs(p.target_positions(p.mesh.nodes) - [0.01, 0.01, 0.02]).max() < 1e-12


def test_a_triangle_mesh_file_stays_2d_and_an_absent_one_too(tmp_path):
    pts = np.array([[0, 0, 0], [0.04, 0, 0], [0, 0.04, 0.0]])
    meshio.write(str(tmp_path / "flat.vtu"), meshio.Mesh(pts, [("triangle", np.array([[0, 1, 2]]))]))
    text = ('name = "flat"\n[body]\nmesh = "flat.vtu"\n[[fixed]]\nbox = [[-1, -1], [1, 0]]\n'
            "[[targets]]\npoint = [0.01, 0.01]\ngoal = [0.01, 0.02]\n")
    assert load_scene(write_scene(tmp_path, text)).body.dim == 2
    absent = parse_scene(text.replace("flat.vtu", "gone.vtu"), base_dir=tmp_path, check_files=False)
    assert absent.body.dim == 2 and absent.tendons.exit == "inside"


def test_a_built_in_2d_scene_is_unchanged():
    scene = load_scene("finger")
    assert scene.body.dim == 2 and scene.tendons.exit == "inside"
    assert scene.body.depth is None and scene.body.edge_length is None and scene.body.units == "m"
    assert len(scene.body.material.gravity) == 2 and build_problem(scene, 1).counts()["triangles"] > 0


SOLID_BODY = "depth = 0.015\nedge_length = 0.004\n"
PLANE_FINGER = (FINGER3D.replace(SOLID_BODY, "").replace("gravity = [0.0, -9.81, 0.0]", "")
                .replace("[[-1, -1, -1], [0.002, 1, 1]]", "[[-1, -1], [0.002, 1]]")
                .replace("[0.06, 0.0075, 0.0075]", "[0.06, 0.0075]").replace("[0.05, 0.025, 0.0075]", "[0.05, 0.025]")
                .replace("[0.03, 0.015, 0.01]", "[0.03, 0.015]").replace("[0.03, 0.02, 0.012]", "[0.03, 0.02]"))
CUBE_BODY = 'mesh = "cube.vtu"\nunits = "mm"\n'

#: (where the case starts, what it replaces, with what, the message, whether it is said at build)
BAD = {
    "2D box corners": (FINGER3D, "[[-1, -1, -1], [0.002, 1, 1]]", "[[-1, -1], [0.002, 1]]",
                       "fixed[0].box must have 3 coordinates per corner for a 3D body", False),
    "2D target point": (FINGER3D, "[0.06, 0.0075, 0.0075]", "[0.06, 0.0075]",
                        "targets[0].point must have 3 coordinates for a 3D body", False),
    "2D target goal": (FINGER3D, "[0.03, 0.02, 0.012]", "[0.03, 0.02]",
                       "targets[1].goal must have 3 coordinates for a 3D body", False),
    "2D gravity": (FINGER3D, "[0.0, -9.81, 0.0]", "[0.0, -9.81]",
                   "body.gravity must have 3 components for a 3D body", False),
    "3D box in 2D": (PLANE_FINGER, "[[-1, -1], [0.002, 1]]", "[[-1, -1, -1], [0.002, 1, 1]]",
                     "fixed[0].box must have 2 coordinates per corner for a 2D body", False),
    "3D point in 2D": (PLANE_FINGER, "[0.06, 0.0075]", "[0.06, 0.0075, 0.0]",
                       "targets[0].point must have 2 coordinates for a 2D body", False),
    "thickness in 3D": (FINGER3D, SOLID_BODY, SOLID_BODY + "thickness = 0.01\n",
                        "body.thickness does not apply to a 3D body", False),
    "triangle area in 3D": (FINGER3D, SOLID_BODY, SOLID_BODY + "max_triangle_area = 8e-6\n",
                            "body.max_triangle_area does not apply to a 3D body", False),
    "edge_length in 2D": (PLANE_FINGER, "[body]\n", "[body]\nedge_length = 0.004\n",
                          "body.edge_length applies to 3D bodies only", False),
    "units in 2D": (PLANE_FINGER, "[body]\n", '[body]\nunits = "mm"\n', "body.units applies to 3D bodies only", False),
    "units of an extrusion": (FINGER3D, SOLID_BODY, SOLID_BODY + 'units = "m"\n',
                              "body.units applies to a mesh file only", False),
    "holes with a mesh": (CUBE, CUBE_BODY, CUBE_BODY + "holes = []\n",
                          "body.holes cannot be combined with body.mesh", False),
    "depth with a mesh": (CUBE, CUBE_BODY, CUBE_BODY + "depth = 0.01\n",
                          "body.depth extrudes an outline; it cannot be combined with body.mesh", False),
    "centimetres": (CUBE, 'units = "mm"', 'units = "cm"', "body.units must be one of 'm', 'mm' (got 'cm')", False),
    "zero depth": (FINGER3D, "depth = 0.015", "depth = 0.0", "body.depth must be > 0 (got 0)", False),
    "negative edge": (FINGER3D, "edge_length = 0.004", "edge_length = -0.004",
                      "body.edge_length must be > 0 (got -0.004)", False),
    "no edge_length": (FINGER3D, "edge_length = 0.004\n", "",
                       "body.edge_length is required for an extruded body", False),
    "a surface file": (CUBE, "cube.vtu", "cube.stl", "tetrahedralizing a surface file is not available yet; give a "
                       "tetrahedral mesh (.msh, .vtu, .vtk) or an extruded outline", False),
    "a mesh file at level 2": (CUBE, "", "", "a tetrahedral mesh file is used at level 1 only for now", True),
    "a target outside": (FINGER3D, "[0.06, 0.0075, 0.0075]", "[0.06, 0.0075, 0.02]",
                         "targets[0].point [0.06, 0.0075, 0.02] lies outside the body", True),
    "the default exit": (FINGER3D, 'exit = "inside"', "",
                         'tendons.exit = "clamp" is not available for 3D bodies yet', True),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_3d_input_is_one_line_naming_the_key(case, tmp_path, cube_file):
    start, old, new, message, at_build = BAD[case]
    surface = cube_file.with_suffix(".stl")
    meshio.write(str(surface), meshio.Mesh(10 * np.eye(4, 3), [("triangle", np.array([[0, 2, 1], [0, 1, 3],
                                                                                      [0, 3, 2], [1, 2, 3]]))]))
    path = write_scene(tmp_path, start.replace(old, new) if old else start)
    with pytest.raises(SceneError) as err:
        scene = load_scene(path)
        assert at_build, "parsed"
        build_problem(scene, 2 if "level 2" in case else 1)
    said = str(err.value)
    assert message in said and "\n" not in said and said.startswith(str(path)), said


def test_a_3d_model_is_one_clear_line(levels):
    from tendon_taichi.physics.model import Model

    with pytest.raises(TendonError, match=re.escape(MSG_PHYSICS)):
        Model.from_problem(levels[0])


@pytest.mark.parametrize("command", [["optimize", "--record", "o/run.rrd"], ["design", "--out", "o"],
                                     ["simulate", "--uniform", "0.1", "--vtu", "o.vtu"]])
def test_the_command_line_says_3d_physics_is_not_built_in_one_line(command, tmp_path, monkeypatch, capsys):
    from tendon_taichi.cli.main import main

    monkeypatch.chdir(tmp_path)
    scene = write_scene(tmp_path, FINGER3D.replace('exit = "inside"', ""), "finger3d.toml")
    assert main([command[0], str(scene), *command[1:], "--quiet"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == f"tendon-taichi: error: {scene}: {MSG_PHYSICS}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["finger3d.toml"]
