"""The objective of the regularized soft IK: its terms (one class each, see
:mod:`.terms`), their sum (:mod:`.objective`) and the settings they read
(:mod:`.settings`). Pure numpy on the arrays a problem supplies."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".term": ("Term", "TermValue", "State"),
    ".setting": ("Setting",),
    ".terms": ("PoseTerm", "SparsityTerm", "ContinuityTerm", "StrandEndTerm", "ContractionTerm", "EffortTerm",
               "smoothstep"),
    ".objective": ("Objective", "Evaluation", "union_tension"),
    ".settings": ("OptimizeSettings", "Homotopy", "SETTINGS", "read_optimize", "settings_dict", "settings_from_dict"),
})
