"""The dimension seams: one place decides a body's dimension (body.dimension),
and each dimension-dependent part - mesh, walls, fiber lattice (body), element
kernels (physics), fabrication export and design picture (io) - is chosen by
it behind one interface. A tiny stub of a second implementation plugs in
without any change to the layers above."""

import types
from types import SimpleNamespace

import numpy as np
import pytest

import tendon_taichi as tt
from tendon_taichi.body import dimension as dimension_module
from tendon_taichi.body.dimension import PLANE, SOLID, Dimension, dimension_of, register_dimension
from tendon_taichi.body.walls import Walls
from tendon_taichi.errors import SceneError
from tendon_taichi.extract.metrics import tendon_metrics
from tendon_taichi.extraction import IdealizedState, Tendon
from tendon_taichi.io import outputs
from tendon_taichi.physics import elements, forces


class DiscWalls:
    """A stub of the walls protocol: a disc of ``radius`` (m) about ``centre``."""

    def __init__(self, centre, radius):
        self.centre, self.radius = np.asarray(centre, float), float(radius)

    def distance(self, points):
        p = np.asarray(points, float).reshape(-1, 2)
        return self.radius - np.linalg.norm(p - self.centre, axis=1)

    def distance_gradient(self, points):
        p = np.asarray(points, float).reshape(-1, 2)
        away = self.centre - p
        return self.distance(p), away / np.linalg.norm(away, axis=1)[:, None]

    def inside(self, points):
        return self.distance(points) >= 0.0

    def polyline_distance(self, points):
        p = np.asarray(points, float)
        dense = np.concatenate([np.linspace(a, b, 50) for a, b in zip(p[:-1], p[1:])])
        return float(self.distance(dense).min())


def test_the_plane_is_the_dimension_of_every_built_in_scene():
    for name in tt.builtin_scenes():
        scene = tt.load_scene(name)
        assert dimension_of(scene) is PLANE and scene.body.dim == 2
    p = tt.build_problem(tt.load_scene("finger"), 1)
    assert p.dim == 2 and p.mesh.simplices.shape[1] == p.dim + 1
    assert isinstance(p.walls, Walls) and p.counts()["dofs"] == p.dim * int((~p.fixed).sum())


def test_a_second_implementation_of_the_walls_plugs_in_below_extraction(monkeypatch):
    """A stub dimension whose walls are a disc: the problem, and the extraction
    layer's clearance metric above it, use the stub's walls unchanged."""
    calls = []

    def mesh(scene, level):
        calls.append(("mesh", level))
        return PLANE.mesh(scene, level)

    disc = DiscWalls([0.05, 0.01], 0.04)
    stub = Dimension(2, "triangle", mesh, lambda scene, m: disc, PLANE.lattice)
    monkeypatch.setitem(dimension_module.DIMENSIONS, 2, stub)
    p = tt.build_problem(tt.load_scene("finger"), 1)
    assert p.walls is disc and calls == [("mesh", 1)]
    nodes = np.array([0, 1])
    points = np.array([[0.03, 0.01], [0.06, 0.01]])
    tendon = Tendon(nodes, np.array([0]), points, 1.0, 0.0)
    f = p.fibers.n_fibers
    state = IdealizedState(np.ones(f), np.zeros(f), None, 0.0)
    got = tendon_metrics(p, state, [tendon])["clearance_min"]
    assert got == pytest.approx(disc.radius - 0.02, abs=1e-12)  # the disc's, not the finger's 1 cm


def test_a_body_of_an_unregistered_dimension_is_one_clear_error(monkeypatch):
    """2D and 3D bodies are registered (3D: :data:`SOLID`); a fourth dimension is one
    clear line, and a stub registered for it is the one found."""
    assert dimension_of(SimpleNamespace(body=SimpleNamespace(dim=3), origin="solid.toml")) is SOLID
    hyper = SimpleNamespace(body=SimpleNamespace(dim=4), origin="hyper.toml")
    with pytest.raises(SceneError, match=r"hyper.toml: a 4D body cannot be built \(bodies may be 2D, 3D\)"):
        dimension_of(hyper)
    stub = Dimension(4, "pentachoron", None, None, None)
    monkeypatch.setitem(dimension_module.DIMENSIONS, 4, PLANE)
    assert register_dimension(stub) is PLANE and dimension_of(hyper) is stub


def test_the_element_kernels_are_chosen_by_the_mesh_s_dimension(monkeypatch):
    """A stub element set (the triangles' kernels, counting energy launches) is the
    one a model of a 2D mesh launches."""
    launches = []
    stub = types.ModuleType("stub_elements")
    stub.__dict__.update({k: v for k, v in vars(forces).items() if k.startswith("k_")})

    def k_energy(*args):
        launches.append(1)
        return forces.k_energy(*args)

    stub.k_energy = k_energy
    p = tt.build_problem(tt.load_scene("finger"), 1)
    x = p.mesh.nodes + 1e-3 * np.sin(40.0 * p.mesh.nodes[:, ::-1])  # a deformed state
    plain = tt.Model.from_problem(p)
    assert plain.kernels is forces
    monkeypatch.setitem(elements.ELEMENTS, 2, stub)
    model = tt.Model.from_problem(p)
    assert model.kernels is stub and model.energy(x) == plain.energy(x) > 0 and launches == [1]
    with pytest.raises(KeyError, match=r"no element kernels for a 3D body \(registered: 2D\)"):
        elements.element_kernels(3)


def test_the_design_outputs_are_chosen_by_the_dimension(monkeypatch, tmp_path):
    plane = outputs.design_outputs(2)
    assert plane.fabrication == "design.svg"
    p = tt.build_problem(tt.load_scene("finger"), 1)
    svg = plane.write_fabrication(tmp_path / plane.fabrication, p, [], "empty")
    assert svg.read_text().startswith("<svg")
    stub = outputs.DesignOutputs(3, "design.stl", lambda *a: None, lambda *a: None)
    monkeypatch.setitem(outputs.OUTPUTS, 3, None)
    assert outputs.register_outputs(stub) is None and outputs.design_outputs(3) is stub
