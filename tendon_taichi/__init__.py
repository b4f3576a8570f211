"""tendon-taichi: design the tendon layout of a 2D soft robot.

The public API, one module per concept (DESIGN.md): :mod:`.scene` (scene
files), :mod:`.mesh`, :mod:`.fibers`, :mod:`.cables`, :mod:`.problem`,
:mod:`.model` (Taichi energies and derivatives), :mod:`.solvers` (Newton,
PCG and direct backends), :mod:`.simulation`, :mod:`.objectives`,
:mod:`.optimizer` (adjoint gradients, homotopy), :mod:`.recording` (rerun),
:mod:`.runs` (optimize / resume / replay), :mod:`.plots`, :mod:`.export`.
Taichi is initialised lazily (:mod:`.runtime`), never at import.
"""

__version__ = "0.1.0"  # keep equal to pyproject.toml

from .cables import CableSet
from .errors import ConvergenceError, InputError, SceneError, TendonError
from .export import write_export, write_vtu
from .fibers import FiberGraph, FiberPairs, build_lattice
from .mesh import Embedding, Mesh
from .model import Model
from .problem import Problem, build_problem
from .scene import Scene, builtin_scenes, load_scene, parse_scene
from .optimizer import SoftIK, StageResult
from .recording import RecordingError, read_recording
from .runs import RunResult, optimize, replay
from .simulation import Simulation, simulate
from .solvers import CGSolver, DirectSolver, Equilibrium, NewtonSolver

__all__ = [
    "CableSet", "ConvergenceError", "InputError", "SceneError", "TendonError", "write_export",
    "write_vtu", "FiberGraph", "FiberPairs", "build_lattice", "Embedding", "Mesh", "Model",
    "Problem", "build_problem", "Scene", "builtin_scenes", "load_scene", "parse_scene",
    "Simulation", "simulate", "CGSolver", "DirectSolver", "Equilibrium", "NewtonSolver",
    "SoftIK", "StageResult", "RecordingError", "read_recording", "RunResult", "optimize", "replay",
    "__version__",
]
