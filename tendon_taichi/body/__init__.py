"""The body and what is built on it: scene files (:mod:`.scene`), plane geometry
(:mod:`.geometry`), triangle meshes and embeddings (:mod:`.mesh`), the fiber
lattice (:mod:`.fibers`), cables (:mod:`.cables`) and the problem - a scene
meshed and rigged at one resolution level (:mod:`.problem`)."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".scene": ("Scene", "Material", "Body", "FiberSettings", "Box", "Target", "Pose", "parse_scene",
               "load_scene", "builtin_scenes", "with_overrides"),
    ".mesh": ("Mesh", "Embedding", "triangulate_polygon", "read_mesh", "refine"),
    ".fibers": ("FiberGraph", "FiberPairs", "build_lattice"),
    ".cables": ("CableSet",),
    ".problem": ("Problem", "build_problem"),
    ".level": ("level_scale", "LevelScale"),
    ".walls": ("Walls",),
    ".dimension": ("Dimension", "DIMENSIONS", "dimension_of", "register_dimension"),
})
