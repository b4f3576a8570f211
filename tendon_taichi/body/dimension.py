"""The one place that decides a body's dimension, and what depends on it in this
layer: a :class:`Dimension` gives the body's mesh at a level (simplices of
``dim + 1`` nodes: triangles in 2D, tetrahedra in 3D), its walls (the :class:`~.walls.Walls`
protocol) and its fiber lattice. The layers above choose their own
dimension-dependent parts by ``problem.dim`` in the same way (the element
kernels: :mod:`tendon_taichi.physics.elements`; the fabrication export and the
design's picture: :mod:`tendon_taichi.io.outputs`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ..dimensions import PerDimension
from ..errors import SceneError
from .exits import ExitSet, plane_exits
from .fibers import FiberGraph, build_lattice
from .lattice3d import cubic_lattice
from .mesh import Mesh
from .plane import plane_mesh, plane_walls
from .scene import Scene
from .solid import solid_mesh, solid_walls
from .tets import TetMesh
from .walls import Walls


@dataclass(frozen=True)
class Dimension:
    """What a body of dimension ``dim`` is built from.

    Args:
        dim: the dimension; positions are (n, dim) arrays, m.
        simplex: the mesh's element ("triangle", "tetrahedron"), of ``dim + 1`` nodes.
        mesh: ``mesh(scene, level)``, the body meshed at a resolution level.
        walls: ``walls(scene, mesh)``, the body's boundary for route clearance.
        lattice: ``lattice(mesh, spacing, tol)``, the fiber lattice of ``spacing``
            (m) clipped to the body, ``tol`` (m) its closed-inside tolerance.
        exits: ``exits(scene, walls, clearance)``, where a route may leave the body
            (:class:`~.exits.ExitSet`; None for ``exit = "inside"``); None: this
            dimension's bodies have no exits yet.
    """

    dim: int
    simplex: str
    mesh: Callable[[Scene, int], Mesh | TetMesh]
    walls: Callable[[Scene, Mesh | TetMesh], Walls]
    lattice: Callable[[Mesh, float, float], FiberGraph]
    exits: Callable[[Scene, Walls, float], ExitSet | None] | None = None


#: 2D bodies: triangles, the polygon walls, the 8-neighbour lattice
PLANE = Dimension(2, "triangle", plane_mesh, plane_walls, build_lattice, exits=plane_exits)

#: 3D bodies: tetrahedra, the mesh's surface as walls, the 26-neighbour cubic lattice; no exits yet
SOLID = Dimension(3, "tetrahedron", solid_mesh, solid_walls, cubic_lattice)

#: the dimensions bodies may have, by ``dim``
DIMENSIONS = PerDimension("dimension", {PLANE.dim: PLANE, SOLID.dim: SOLID})


def register_dimension(dimension: Dimension) -> Dimension | None:
    """Make ``dimension`` the one of its ``dim``; returns the one it replaces, if any."""
    return DIMENSIONS.register(dimension.dim, dimension)


def dimension_of(scene: Scene) -> Dimension:
    """The :class:`Dimension` of ``scene``'s body (:attr:`~.scene.Body.dim`); one
    clear line where none is registered for it."""
    dim = scene.body.dim
    if dim not in DIMENSIONS:
        raise SceneError(f"{scene.origin}: a {dim}D body cannot be built (bodies may be {DIMENSIONS.known()})")
    return DIMENSIONS[dim]
