"""The commands' workflows, one module each: :mod:`.simulate`, :mod:`.optimize`
(optimize and resume), :mod:`.replay`, :mod:`.extract` (extract and compare),
:mod:`.case` (one optimize + extract case, as ``bench``, ``sweep`` and
``planted-bench`` run it), :mod:`.bench` and :mod:`.sweep`."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".simulate": ("Simulation", "simulate", "contraction_ratios"),
    ".optimize": ("RunResult", "RunOptions", "Interrupted", "optimize"),
    ".replay": ("replay",),
    ".extract": ("Extraction", "ExtractorResult", "extract"),
    ".case": ("CaseResult", "CaseSettings", "run_case"),
})
