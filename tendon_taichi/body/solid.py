"""Solids: what is three-dimensional about a 3D body, behind the functions of a
:class:`~.dimension.Dimension` - its tetrahedral mesh at a level (the outline
extruded to its depth, or a mesh file of tetrahedra), its walls (the mesh's
surface, :class:`~.surface.SurfaceWalls`) and its fiber lattice
(:func:`~.lattice3d.cubic_lattice`, 26 neighbours). Routes cannot leave a 3D
body yet (no exits), and its physics is not built (:mod:`tendon_taichi.physics.elements`).

The size estimate (:func:`estimate_solid`) counts tetrahedra in regular ones of
the target edge e, of volume e^3 / (6 sqrt 2). Measured on two extrusions - the
finger (6 x 1.5 cm, depth 1.5 cm) and a 4 cm L with a square hole (depth 1 cm) -
at edges 4, 2.8 and 2 mm: 1.28-1.54 times that many tetrahedra (1.4 on average:
:data:`TETS_PER_REGULAR`) and 0.21-0.27 nodes per tetrahedron (more on coarser
meshes, whose surface holds more of the nodes; :data:`NODES_PER_TET` 0.25), so the
nodes estimated are within 25 % of the mesh's. A cubic lattice of spacing s has
about V / s^3 nodes and at most 13 fibers per node.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from .geometry import signed_area
from .lattice3d import OFFSETS
from .level import level_scale
from .scene import Scene
from .size import max_dofs
from .surface import SurfaceWalls
from .tets import TetMesh, extrude, read_tet_mesh

#: tetrahedra of an extrusion per regular tetrahedron of the target edge (measured: module docstring)
TETS_PER_REGULAR = 1.4
#: nodes per tetrahedron of an extrusion (measured: module docstring)
NODES_PER_TET = 0.25
#: fibers per lattice node at most: one per neighbour offset
FIBERS_PER_NODE = len(OFFSETS)


def regular_tet_volume(edge: float) -> float:
    """The volume (m^3) of a regular tetrahedron of ``edge`` (m): e^3 / (6 sqrt 2)."""
    return edge ** 3 / (6.0 * np.sqrt(2.0))


def estimate_solid(volume: float, edge: float, spacing: float) -> tuple[float, float]:
    """(free DOFs, fibers) expected for a body of ``volume`` (m^3) meshed with
    tetrahedra of ``edge`` (m) and a cubic lattice of ``spacing`` (m): 3 DOFs per
    node (clamped ones included: an upper bound)."""
    tets = TETS_PER_REGULAR * volume / regular_tet_volume(edge)
    return 3.0 * NODES_PER_TET * tets, FIBERS_PER_NODE * volume / spacing ** 3


def check_solid_size(name: str, level: int, dofs: float, fibers: float) -> None:
    """Raise SceneError when a 3D body at ``level`` would have more DOFs or fibers
    than :func:`~.size.max_dofs` allows."""
    limit, source = max_dofs()
    if limit is not None and max(dofs, fibers) > limit:
        raise SceneError(f"{name} at level {level} would have about {dofs:.2g} degrees of freedom and "
                         f"{fibers:.2g} fibers, more than {limit} ({source}); lower the resolution, "
                         f"raise edge_length or spacing, or give --max-dofs")


def extruded_volume(scene: Scene) -> float:
    """The volume (m^3) of an extruded body: its outline's area less its holes', times its depth."""
    body = scene.body
    area = abs(signed_area(body.outline)) - sum(abs(signed_area(h)) for h in body.holes)
    return area * body.depth


def solid_mesh(scene: Scene, level: int) -> TetMesh:
    """The 3D body meshed at ``level``: the outline extruded with tetrahedra of
    edge_length / sqrt(2) ** (level - 1), once :func:`check_solid_size` allows it;
    or the mesh file's tetrahedra, in metres (level 1 only, for now)."""
    body = scene.body
    scale = level_scale(level)
    spacing = scene.fibers.spacing / scale.length
    if body.mesh_file is not None:
        if level > 1:
            raise SceneError(f"{scene.origin}: a tetrahedral mesh file is used at level 1 only for now "
                             f"(got level {level})")
        mesh = read_tet_mesh(body.mesh_file, body.scale)
        volume = float(mesh.volumes.sum())
        check_solid_size(scene.name, level, 3.0 * mesh.n_nodes, FIBERS_PER_NODE * volume / spacing ** 3)
        return mesh
    edge = body.edge_length / scale.length
    check_solid_size(scene.name, level, *estimate_solid(extruded_volume(scene), edge, spacing))
    return extrude(body.outline, body.holes, body.depth, edge)


def solid_walls(scene: Scene, mesh: TetMesh) -> SurfaceWalls:
    """The body's walls: the surface of its tetrahedral mesh."""
    return SurfaceWalls.of(mesh)
