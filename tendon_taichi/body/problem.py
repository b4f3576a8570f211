"""A problem: a scene at one resolution level, meshed, rigged and embedded.

:func:`build_problem` turns a :class:`~tendon_taichi.body.scene.Scene` into the
arrays every solver works on: the rest mesh, the clamped nodes, the fiber
graph and the embedded target points (``docs/method.md``, ``docs/scenes.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from .cables import CableSet
from ..errors import SceneError
from .dimension import Dimension, dimension_of
from .fibers import FiberGraph
from .level import level_scale
from .mesh import Embedding, Mesh
from .scene import Scene
from .exits import ExitSet
from .tets import TetMesh
from .walls import Walls


@dataclass(frozen=True, eq=False)
class Problem:
    """A scene at resolution ``level``: ``mesh`` (triangles in 2D, a
    :class:`~.tets.TetMesh` in 3D), ``fixed`` (bool per node),
    ``fibers``, and targets (``target`` embedding, ``target_goal`` (t, dim), m) -
    those of every pose, pose after pose (:attr:`target_pose`); :meth:`pose`
    gives one pose's problem."""

    scene: Scene
    level: int
    mesh: Mesh | TetMesh
    fixed: np.ndarray
    fibers: FiberGraph
    target: Embedding
    target_goal: np.ndarray

    @property
    def size(self) -> float:
        """Body size L (bounding-box diagonal), m."""
        return self.mesh.size

    @property
    def material(self):
        return self.scene.body.material

    @property
    def force_scale(self) -> float:
        """E h L in 2D, E L^2 in 3D, N: the scale of the equilibrium's force residual."""
        m = self.material
        width = m.thickness if self.dim == 2 else self.size
        return m.youngs_modulus * width * self.size

    @cached_property
    def fiber_cables(self) -> CableSet:
        """The fiber lattice as single-segment cables of EA = the scene's stiffness."""
        return CableSet.fibers(self.fibers.embedding, self.fibers.edges, self.fibers.a0,
                               self.scene.fibers.stiffness)

    @property
    def dim(self) -> int:
        """The body's dimension: positions are (n, dim) arrays."""
        return self.mesh.dim

    @cached_property
    def dimension(self) -> Dimension:
        """What depends on the dimension (:func:`~.dimension.dimension_of`)."""
        return dimension_of(self.scene)

    @cached_property
    def walls(self) -> Walls:
        """The body's walls (:class:`~.walls.Walls`): in 2D its outline and holes (from
        the scene, or the mesh's triangles), in 3D its mesh's surface."""
        return self.dimension.walls(self.scene, self.mesh)

    @cached_property
    def exits(self) -> ExitSet | None:
        """Where a route may leave the body (:class:`~.exits.ExitSet`, the scene's
        ``[tendons] exit``), None where its pull end stays inside (``"inside"``)."""
        if self.scene.tendons.exit == "inside":
            return None
        if self.dimension.exits is None:
            raise SceneError(f"{self.scene.origin}: tendons.exit = \"{self.scene.tendons.exit}\" is not "
                             f"available for {self.dim}D bodies yet")
        return self.dimension.exits(self.scene, self.walls, self.scene.tendons.clearance * self.size)

    def coarser_meshes(self) -> list[Mesh]:
        """The body meshed at every other coarser level, ``level - 2``, ``level - 4``,
        ... down to level 1 or 2 (each has about a quarter of the nodes of the one
        before; none at levels 1 and 2): the hierarchy of the geometric multigrid
        preconditioner (:mod:`tendon_taichi.solve.multigrid`). The meshes at two
        levels are not nested, but they cover the same region."""
        return list(self._coarser)

    @cached_property
    def _coarser(self) -> tuple[Mesh, ...]:
        return tuple(self.dimension.mesh(self.scene, lc) for lc in range(self.level - 2, 0, -2))

    @property
    def n_poses(self) -> int:
        return len(self.scene.poses)

    @property
    def pose_names(self) -> list[str]:
        return [p.name for p in self.scene.poses]

    @property
    def target_pose(self) -> np.ndarray:
        """int (t,): the pose each target belongs to."""
        return self.scene.target_pose

    def pose(self, i: int) -> "Problem":
        """The problem of pose ``i`` alone (same mesh and fibers, that pose's targets)."""
        return self if self.n_poses == 1 else self._pose_problems[i]

    @cached_property
    def _pose_problems(self) -> list["Problem"]:
        out = []
        for i, pose in enumerate(self.scene.poses):
            sel = self.target_pose == i
            out.append(replace(self, scene=replace(self.scene, poses=(pose,)),
                               target=Embedding(self.target.tri[sel], self.target.bary[sel]),
                               target_goal=self.target_goal[sel]))
        return out

    def with_tendons(self, **changes) -> "Problem":
        """The same problem with some [tendons] settings of its scene replaced
        (:meth:`~tendon_taichi.body.scene.Scene.with_tendons`)."""
        scene = self.scene.with_tendons(**changes)
        return self if scene is self.scene else replace(self, scene=scene)

    def embed_waypoints(self, nodes: np.ndarray, waypoints: np.ndarray, hint: np.ndarray | None = None) -> Embedding:
        """A tendon's waypoints (k, dim) embedded in the rest mesh: exactly as its fiber
        nodes are when it runs through them (``nodes`` (k,)), else located (in 2D
        trying the triangles ``hint`` (k,) first; a 3D mesh takes no hint)."""
        if len(nodes) == len(waypoints):
            emb = self.fibers.embedding
            return Embedding(emb.tri[nodes], emb.bary[nodes])
        if self.dim != 2:
            return self.mesh.locate(waypoints)[0]
        return self.mesh.locate(waypoints, hint=hint)[0]

    def target_positions(self, x: np.ndarray) -> np.ndarray:
        """Where the target points are (t, dim) for node positions ``x`` (n, dim)."""
        return self.target.positions(self.mesh.simplices, x)

    def counts(self) -> dict:
        """Nodes, elements ("triangles" in 2D, "tetrahedra" in 3D), fibers and free DOFs."""
        elements = "triangles" if self.dim == 2 else "tetrahedra"
        return {"nodes": self.mesh.n_nodes, elements: len(self.mesh.simplices),
                "fibers": self.fibers.n_fibers, "dofs": int(self.dim * (~self.fixed).sum())}


def build_problem(scene: Scene, level: int = 1) -> Problem:
    """Mesh, rig and embed ``scene`` at resolution ``level`` (1, 2, ...), its sizes
    scaled by :func:`level_scale`."""
    if not isinstance(level, (int, np.integer)) or level < 1:
        raise SceneError(f"the level must be an integer >= 1 (got {level!r})")
    dimension = dimension_of(scene)
    mesh = dimension.mesh(scene, int(level))
    L = mesh.size
    tol = 1e-9 * L
    fixed = np.zeros(mesh.n_nodes, dtype=bool)
    for box in scene.fixed:
        fixed |= box.contains(mesh.nodes, tol)
    if not fixed.any():
        raise SceneError(f"{scene.origin}: no mesh node lies in any [[fixed]] box: "
                         "the body is not clamped")
    if fixed.all():
        raise SceneError(f"{scene.origin}: every mesh node lies in a [[fixed]] box: nothing can move")
    spacing = scene.fibers.spacing / level_scale(level).length
    fibers = dimension.lattice(mesh, spacing, tol)
    if fibers.n_fibers == 0:
        raise SceneError(f"{scene.origin}: no fiber fits inside the body at spacing {spacing:g} m")
    points = np.array([t.point for t in scene.targets], dtype=float)
    target, dist = mesh.locate(points, max_dist=tol)
    outside = np.flatnonzero(dist > tol)
    if len(outside):
        i = int(outside[0])
        where = ", ".join(f"{c:g}" for c in points[i])
        raise SceneError(f"{scene.origin}: {scene.target_label(i)}.point [{where}] lies outside the body")
    goals = np.array([t.goal for t in scene.targets], dtype=float)
    problem = Problem(scene, int(level), mesh, fixed, fibers, target=target, target_goal=goals)
    problem.exits  # noqa: B018  (a clamp that does not meet the outline is bad input: said now)
    return problem
