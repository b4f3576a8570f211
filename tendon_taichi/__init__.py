"""tendon-taichi: design the tendon layout of a 2D soft robot.

The package is layered, one folder per layer, each importing only the layers
below it (``docs/architecture.md``), bottom first: :mod:`.tasks` (cases as Dask
tasks; it imports nothing of the application), :mod:`.objective` (the
objective's terms and settings), :mod:`.body` (scene files, meshes, the fiber
lattice, cables, problems), :mod:`.io` (recordings, exports, pictures,
progress), :mod:`.physics` (the Taichi model), :mod:`.solve` (Newton and the
linear backends), :mod:`.optimizer` (soft IK and the homotopy), :mod:`.extract`
(the plugin protocol, metrics, the realizable robot, consolidation),
:mod:`.apps` (the commands' workflows), :mod:`.planted` (benchmarks with a
known answer) and :mod:`.cli`.

The names below are imported on first use (PEP 562): importing the package,
or the plugin protocol :mod:`tendon_taichi.extraction`, does not start Taichi;
Taichi is initialised lazily (:mod:`.physics.runtime`), never at import.
"""

from ._lazy import lazy_exports
from .version import __version__

__getattr__, __dir__, _names = lazy_exports(__name__, {
    ".errors": ("ConvergenceError", "InputError", "SceneError", "TendonError"),
    ".body.cables": ("CableSet",),
    ".body.fibers": ("FiberGraph", "FiberPairs", "build_lattice"),
    ".body.mesh": ("Embedding", "Mesh"),
    ".body.problem": ("Problem", "build_problem"),
    ".body.scene": ("Scene", "builtin_scenes", "load_scene", "parse_scene"),
    ".io.export": ("write_export", "write_vtu"),
    ".io.recording": ("RecordingError", "read_recording"),
    ".physics.model": ("Model",),
    ".solve.cg": ("CGSolver",),
    ".solve.direct": ("DirectSolver",),
    ".solve.newton": ("Equilibrium", "NewtonSolver"),
    ".optimizer.soft_ik": ("SoftIK",),
    ".optimizer.homotopy": ("StageResult",),
    ".apps.simulate": ("Simulation", "simulate"),
    ".apps.optimize": ("RunResult", "optimize"),
    ".apps.replay": ("replay",),
}, modules={"sweep": ".apps.sweep"})
__all__ = [*_names, "sweep", "__version__"]
