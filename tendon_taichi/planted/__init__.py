"""Planted layouts, benchmarks with a known answer: random smooth tendons drawn
in a body (:mod:`.walk`), their equilibrium written as a scene's goals
(:mod:`.plant`), a suite scored against what was planted (:mod:`.bench`) and
its pictures (:mod:`.gallery`)."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".plant": ("plant", "write_planted", "solve_tendons", "MAX_TENDONS"),
    ".walk": ("PlantSettings", "PlantedTendon"),
    ".bench": ("run_suite", "load_suite", "route_rule"),
})
