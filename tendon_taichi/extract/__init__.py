"""From strands to tendons: the extractor plugin protocol (:mod:`.protocol`,
:mod:`.fiber_view`, :mod:`.plugins`; re-exported for plugins by
:mod:`tendon_taichi.extraction`), the metrics every extractor is scored by
(:mod:`.metrics`), the realizable robot that validates tendons
(:mod:`.realizable`) and consolidation, fewer tendons for the same pose
(:mod:`.consolidation`)."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".protocol": ("EXTRACTOR_API", "Extractor", "IdealizedState", "PluginError", "Tendon", "prune", "turn_angles"),
    ".fiber_view": ("FiberView",),
    ".plugins": ("GROUP", "available_extractors", "load_extractor"),
    ".metrics": ("MetricSettings", "tendon_metrics"),
    ".realizable": ("RealizableResult", "solve_realizable", "solve_realizable_poses", "predict_realizable",
                    "tendon_cables"),
    ".settings": ("ConsolidationSettings", "FrontSettings"),
    ".context": ("Context",),
    ".consolidation": ("Consolidation", "consolidate"),
})
