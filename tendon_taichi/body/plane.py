"""The plane: what is two-dimensional about a 2D body, behind the functions of a
:class:`~.dimension.Dimension` - its triangle mesh at a level (from the outline
and holes, or a mesh file), its walls (the polygon set) and its fiber lattice
(:func:`~.fibers.build_lattice`, 8 neighbours)."""

from __future__ import annotations

import numpy as np

from .geometry import PolygonWalls, signed_area
from .level import level_scale
from .mesh import Mesh, read_mesh, refine, triangulate_polygon
from .scene import Scene
from .size import check_size


def plane_mesh(scene: Scene, level: int) -> Mesh:
    """The body meshed at ``level``, once :func:`~tendon_taichi.body.size.check_size` allows it."""
    body = scene.body
    scale = level_scale(level)
    spacing = scene.fibers.spacing / scale.length
    if body.mesh_file is None:
        area = abs(signed_area(body.outline)) - sum(abs(signed_area(h)) for h in body.holes)
        check_size(scene.name, level, area, body.max_triangle_area / scale.area, spacing)
        return triangulate_polygon(body.outline, body.holes, body.max_triangle_area / scale.area)
    mesh = read_mesh(body.mesh_file)
    base = body.max_triangle_area or float(np.abs(mesh.areas).max())
    area = base / scale.area
    check_size(scene.name, level, float(np.abs(mesh.areas).sum()), area, spacing)
    if level > 1 or np.abs(mesh.areas).max() > area * (1 + 1e-9):
        mesh = refine(mesh, area)
    return mesh


def plane_walls(scene: Scene, mesh: Mesh) -> PolygonWalls:
    """The body's outline and holes (from the scene, or the union of the mesh's
    triangles for a mesh file)."""
    body = scene.body
    if body.outline is not None:
        return PolygonWalls.from_outline(body.outline, body.holes)
    return PolygonWalls.from_triangles(mesh.nodes[mesh.triangles])
