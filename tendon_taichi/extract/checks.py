"""The rules a plugin's call obeys: it sees a read-only copy of the problem and
the state (so it cannot change what the next extractor sees), it has a time
limit, and what it returns is checked before anything is solved or written."""

from __future__ import annotations

import copy
import dataclasses
import threading
from typing import Callable

import numpy as np

from .protocol import PluginError, Tendon

#: waypoints may differ from their nodes' rest positions by this fraction of the body size
WAYPOINT_TOL = 1e-6
#: seconds a plugin's extract() may take (``--plugin-timeout``)
PLUGIN_TIMEOUT = 300.0


def call_plugin(name: str, fn: Callable, timeout: float = PLUGIN_TIMEOUT):
    """``fn()`` (extractor ``name``'s call) in a thread of its own: its result or
    its exception, or PluginError when it runs longer than ``timeout`` s (the
    thread is then left behind, and ends with the process)."""
    box: dict = {}

    def target():
        try:
            box["value"] = fn()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller
            box["error"] = exc

    worker = threading.Thread(target=target, name=f"extractor {name}", daemon=True)
    worker.start()
    worker.join(timeout)
    if worker.is_alive():
        raise PluginError(f"extractor '{name}' did not finish within {timeout:g} s (--plugin-timeout)")
    if "error" in box:
        raise box["error"]
    return box["value"]


def read_only_copy(obj):
    """A deep copy of ``obj`` whose arrays (in dataclass fields, attributes, lists
    and tuples, at any depth) cannot be written: a plugin that edits one in
    place raises instead of corrupting what the others see."""
    dup = copy.deepcopy(obj)
    _freeze(dup, set())
    return dup


def _freeze(obj, seen: set) -> None:
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        obj.setflags(write=False)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            _freeze(v, seen)
    elif isinstance(obj, dict):
        for v in obj.values():
            _freeze(v, seen)
    elif not isinstance(obj, type):
        fields = [getattr(obj, f.name) for f in dataclasses.fields(obj)] if dataclasses.is_dataclass(obj) else []
        for v in fields + list(getattr(obj, "__dict__", {}).values()):  # __dict__: cached properties too
            _freeze(v, seen)


def check_tendons(name: str, tendons, problem) -> list[Tendon]:
    """``tendons`` as a list after checking what extractor ``name`` returned
    against ``problem``: a list of :class:`Tendon`, each with at least two fiber
    nodes joined by the fibers between them, finite waypoints at those nodes'
    rest positions (so inside the body). Raises PluginError naming the extractor."""
    if not isinstance(tendons, (list, tuple)) or not all(isinstance(t, Tendon) for t in tendons):
        raise PluginError(f"extractor '{name}' did not return a list of Tendon")
    for i, t in enumerate(tendons):
        why = _fault(t, problem)
        if why:
            raise PluginError(f"extractor '{name}' returned a malformed tendon (tendon {i}: {why})")
    return list(tendons)


def _fault(t: Tendon, problem) -> str | None:
    """Why tendon ``t`` breaks the rules, or None."""
    graph = problem.fibers
    nodes, fibers = np.asarray(t.nodes), np.asarray(t.fibers)
    if nodes.ndim != 1 or len(nodes) < 2 or not np.issubdtype(nodes.dtype, np.integer):
        return "it needs at least two integer fiber nodes"
    if fibers.shape != (len(nodes) - 1,) or not np.issubdtype(fibers.dtype, np.integer):
        return "it needs one integer fiber between each two nodes"
    if nodes.min() < 0 or nodes.max() >= len(graph.nodes) or fibers.min() < 0 or fibers.max() >= graph.n_fibers:
        return "a node or fiber index is out of range"
    ends = np.sort(graph.edges[fibers], axis=1)
    if not np.array_equal(ends, np.sort(np.stack([nodes[:-1], nodes[1:]], 1), axis=1)):
        return "a fiber does not join the nodes beside it"
    w = np.asarray(t.waypoints, dtype=float)
    if w.shape != (len(nodes), 2):
        return f"waypoints must be ({len(nodes)}, 2), one per node (got {w.shape})"
    if not np.isfinite(w).all():
        return "a waypoint is not a finite number"
    off = float(np.abs(w - graph.nodes[nodes]).max())
    if off > WAYPOINT_TOL * problem.size:
        return (f"its waypoints are up to {off:.3g} m from its nodes' rest positions "
                f"(the body is {problem.size:.3g} m across)")
    return None
