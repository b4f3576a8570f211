"""The public plugin protocol of tendon extraction: everything an extractor
plugin imports (``docs/plugins.md``). It loads neither Taichi nor the solvers.

A plugin subclasses :class:`Extractor` and registers an entry point in the
group ``tendon_taichi.extractors``; :class:`FiberView` gives the graph queries
most extractors need; :func:`tendon_metrics` scores every extractor's tendons
the same way.
"""

from .extract.fiber_view import FiberView
from .extract.metrics import MetricSettings, tendon_metrics
from .extract.plugins import GROUP, available_extractors, load_extractor
from .extract.protocol import EXTRACTOR_API, Extractor, IdealizedState, PluginError, Tendon, prune, turn_angles

__all__ = ["EXTRACTOR_API", "GROUP", "PluginError", "IdealizedState", "Tendon", "FiberView", "Extractor",
           "MetricSettings", "tendon_metrics", "turn_angles", "prune", "available_extractors",
           "load_extractor"]
