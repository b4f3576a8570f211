"""Finding and loading extractor plugins: the entry points of the group
``tendon_taichi.extractors`` (``importlib.metadata``), with one clear error for
an unknown, broken or incompatible plugin."""

from __future__ import annotations

from importlib.metadata import entry_points

from .protocol import EXTRACTOR_API, Extractor, PluginError

GROUP = "tendon_taichi.extractors"


def available_extractors() -> dict[str, object]:
    """Entry points of the installed extractors, by name (nothing is imported)."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def unknown_extractor(names) -> str | None:
    """The error for the first of ``names`` that is not installed (naming those that
    are), or None when every one is."""
    installed = sorted(available_extractors())
    missing = [name for name in names if name not in installed]
    return f"unknown extractor '{missing[0]}' (installed: {', '.join(installed) or 'none'})" if missing else None


def load_extractor(name: str) -> Extractor:
    """Import and instantiate an installed extractor; one clear PluginError if it is
    unknown, fails to import, or does not follow the protocol."""
    eps = available_extractors()
    if name not in eps:
        raise PluginError(unknown_extractor([name]))
    try:
        obj = eps[name].load()
    except Exception as exc:  # noqa: BLE001 - any import failure of a plugin
        raise PluginError(f"extractor '{name}' failed to load: {type(exc).__name__}: "
                          f"{str(exc).splitlines()[0] if str(exc) else ''}") from None
    try:
        ext = obj() if isinstance(obj, type) else obj
    except Exception as exc:  # noqa: BLE001
        raise PluginError(f"extractor '{name}' failed to start: {type(exc).__name__}: {exc}") from None
    if not callable(getattr(ext, "extract", None)):
        raise PluginError(f"extractor '{name}' has no extract(problem, state, options) method")
    api = getattr(ext, "api", None)
    if api != EXTRACTOR_API:
        raise PluginError(f"extractor '{name}' was written for extractor API {api}, "
                          f"this tendon-taichi speaks {EXTRACTOR_API}")
    if not getattr(ext, "name", None):
        ext.name = name
    return ext
