"""Tendon extraction: the public plugin protocol (DESIGN.md section 5).

An extractor turns the fiber tensions of an optimized (idealized) run into a
few tendons. Plugins - the built-in ones in the top-level ``extractors``
package as well as third-party ones - subclass :class:`Extractor` and register
an entry point in the group ``tendon_taichi.extractors``::

    [project.entry-points."tendon_taichi.extractors"]
    my_extractor = "my_package.module:MyExtractor"

A plugin imports only this module. It receives the :class:`~tendon_taichi.problem.Problem`
(read-only: ``problem.fibers``, ``problem.mesh``, ``problem.fixed``), an
:class:`IdealizedState` and its options, and returns :class:`Tendon` objects;
:class:`FiberView` gives the graph queries most extractors need. Metrics are
computed the same way for every extractor by :func:`tendon_metrics`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from importlib.metadata import entry_points

import numpy as np

from .errors import TendonError

#: version of this protocol; an extractor declares the one it was written for
EXTRACTOR_API = 1
GROUP = "tendon_taichi.extractors"


class PluginError(TendonError):
    """An extractor is unknown, fails to load, or is incompatible."""


@dataclass
class IdealizedState:
    """What an extractor works from: fiber tensions ``tau`` (f,) N and contractions
    ``ac`` (f,) m of one stage, the equilibrium ``x`` (n, 2) m, and the tension
    above which a fiber counts as active, ``active_threshold`` (N). With several
    target poses, ``tau`` is the union tension sqrt(sum_p tau_p^2), ``ac`` the
    largest contraction over the poses, ``x`` the first pose's equilibrium, and
    ``poses`` holds each pose's own state."""

    tau: np.ndarray
    ac: np.ndarray
    x: np.ndarray | None
    active_threshold: float
    stage: int = 0
    k: float | None = None
    poses: list["IdealizedState"] | None = None

    @property
    def active(self) -> np.ndarray:
        """bool (f,): fibers carrying more than the threshold."""
        return self.tau > self.active_threshold


@dataclass
class Tendon:
    """A tendon: a path through fiber nodes ``nodes`` (k,) along fibers ``fibers``
    (k-1,), rest ``waypoints`` (k, 2) m, anchored at the first waypoint and pulled
    at the last; ``tension`` and ``tension_std`` (N) of its active source fibers.
    ``contraction`` (m) is set when the realizable robot is solved."""

    nodes: np.ndarray
    fibers: np.ndarray
    waypoints: np.ndarray
    tension: float
    tension_std: float
    contraction: float | None = None

    @property
    def length(self) -> float:
        """Rest length of the polyline, m."""
        return float(np.linalg.norm(np.diff(self.waypoints, axis=0), axis=1).sum())

    @property
    def anchor(self) -> np.ndarray:
        return self.waypoints[0]

    @property
    def pull_end(self) -> np.ndarray:
        return self.waypoints[-1]

    def turn_angles(self) -> np.ndarray:
        """Turn angles (k-2,) at the interior waypoints, radians (0 = straight on)."""
        return turn_angles(self.waypoints)

    def as_json(self) -> dict:
        return {"waypoints": self.waypoints.tolist(), "length": self.length, "tension": self.tension,
                "tension_std": self.tension_std, "contraction": self.contraction,
                "anchor": self.anchor.tolist(), "pull_end": self.pull_end.tolist(),
                "fiber_nodes": [int(v) for v in self.nodes], "fibers": [int(f) for f in self.fibers]}


def turn_angles(points: np.ndarray) -> np.ndarray:
    """Turn angles at the interior points of a polyline (k, 2), radians in [0, pi]."""
    d = np.diff(np.asarray(points, dtype=float), axis=0)
    if len(d) < 2:
        return np.zeros(0)
    a, b = d[:-1], d[1:]
    cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


class FiberView:
    """Graph queries on a problem's fiber lattice (read-only)."""

    def __init__(self, problem):
        f = problem.fibers
        self.problem = problem
        self.nodes, self.edges, self.a0 = f.nodes, f.edges, f.a0
        self.spacing = f.spacing
        ends = np.concatenate([self.edges[:, 0], self.edges[:, 1]])
        fib = np.concatenate([np.arange(len(self.edges))] * 2)
        order = np.argsort(ends, kind="stable")
        self._start = np.searchsorted(ends[order], np.arange(len(self.nodes) + 1))
        self._inc = fib[order]
        fixed_pts = problem.mesh.nodes[problem.fixed]
        self._to_clamp = np.min(np.linalg.norm(self.nodes[:, None, :] - fixed_pts[None, :, :], axis=2), axis=1) \
            if len(fixed_pts) else np.zeros(len(self.nodes))

    def incident(self, v: int) -> np.ndarray:
        """Fiber ids meeting at fiber node v."""
        return self._inc[self._start[v]:self._start[v + 1]]

    def other(self, fiber: int, v: int) -> int:
        """The end of ``fiber`` that is not node v."""
        a, b = self.edges[fiber]
        return int(b if a == v else a)

    def turn(self, f_in: int, v: int, f_out: int) -> float:
        """Turn angle (radians) at node v when a path arrives along ``f_in`` and
        leaves along ``f_out``: 0 straight on, pi straight back."""
        u, w = self.other(f_in, v), self.other(f_out, v)
        a = self.nodes[v] - self.nodes[u]
        b = self.nodes[w] - self.nodes[v]
        c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
        return math.acos(max(-1.0, min(1.0, c)))

    def distance_to_clamp(self, v: int) -> float:
        """Rest distance from fiber node v to the nearest clamped mesh node, m."""
        return float(self._to_clamp[v])

    def grow(self, seed: int, extend) -> tuple[int, list[int]]:
        """A path grown from fiber ``seed`` at both ends: ``extend(node, fiber)``
        returns, in order, the fibers to add beyond ``node`` (which the path reached
        along ``fiber``). Returns the path's start node and its fibers in order."""
        a, b = (int(v) for v in self.edges[seed])
        back = extend(b, seed)
        front = extend(a, seed)
        start = a
        for f in front:  # walk the front extension out to its far end
            start = self.other(f, start)
        return start, front[::-1] + [seed] + back

    def greedy_tendons(self, state: IdealizedState, used: np.ndarray, stepper) -> list[Tendon]:
        """Tendons grown greedily: every fiber not yet ``used`` seeds one, strongest
        tension first, grown at both ends by :meth:`grow`. ``stepper(seed, visited)``
        returns that seed's ``extend(node, fiber)``; ``visited`` (the path's fiber
        nodes, seeded with the seed's two ends) and ``used`` (bool per fiber) are
        shared with it and updated by it."""
        tendons = []
        for seed in sorted(range(len(state.tau)), key=lambda f: -state.tau[f]):
            if used[seed]:
                continue
            used[seed] = True
            visited = {int(v) for v in self.edges[seed]}
            start, fibers = self.grow(seed, stepper(seed, visited))
            tendons.append(self.tendon(start, fibers, state))
        return tendons

    def tendon(self, start: int, fibers: list[int], state: IdealizedState) -> Tendon:
        """The tendon following ``fibers`` from node ``start``, oriented so that its
        pull end is the end nearer to the clamped region (where motors sit)."""
        nodes = [int(start)]
        for f in fibers:
            nodes.append(self.other(int(f), nodes[-1]))
        nodes_a, fibers_a = np.array(nodes), np.array(fibers, dtype=np.int64)
        if self._to_clamp[nodes_a[0]] < self._to_clamp[nodes_a[-1]]:
            nodes_a, fibers_a = nodes_a[::-1].copy(), fibers_a[::-1].copy()
        src = fibers_a[state.active[fibers_a]] if len(fibers_a) else fibers_a
        t = state.tau[src] if len(src) else np.zeros(1)
        return Tendon(nodes_a, fibers_a, self.nodes[nodes_a].copy(), float(t.mean()), float(t.std()))


class Extractor:
    """Base class of extraction plugins.

    Subclasses set ``name`` (the entry-point name), a one-line ``description``,
    ``api`` (the :data:`EXTRACTOR_API` they were written for), an ``Options``
    dataclass whose fields (with types and defaults) are the options, and
    implement :meth:`extract`.
    """

    name: str = ""
    description: str = ""
    api: int = EXTRACTOR_API

    @dataclass
    class Options:
        pass

    def extract(self, problem, state: IdealizedState, options) -> list[Tendon]:
        """Return the tendons found in ``state`` (a list, possibly empty)."""
        raise NotImplementedError

    # ------------------------------------------------------------ options
    @classmethod
    def option_fields(cls) -> list[dataclasses.Field]:
        return list(dataclasses.fields(cls.Options))

    @classmethod
    def make_options(cls, values: dict[str, str | float | int | bool] | None = None):
        """Options from ``{name: value}``; strings (from the command line) are
        converted to each field's type. Unknown names or bad values raise PluginError."""
        known = {f.name: f for f in cls.option_fields()}
        kwargs = {}
        for key, raw in (values or {}).items():
            if key not in known:
                raise PluginError(f"extractor '{cls.name}' has no option '{key}' "
                                  f"(options: {', '.join(known) or 'none'})")
            kwargs[key] = _convert(cls.name, known[key], raw)
        return cls.Options(**kwargs)


def _convert(name: str, fld: dataclasses.Field, raw):
    typ = fld.type if isinstance(fld.type, type) else {"float": float, "int": int, "bool": bool,
                                                        "str": str}.get(str(fld.type), str)
    if not isinstance(raw, str):
        return raw
    try:
        if typ is bool:
            if raw.lower() in ("1", "true", "yes", "on"):
                return True
            if raw.lower() in ("0", "false", "no", "off"):
                return False
            raise ValueError(raw)
        return typ(raw)
    except ValueError:
        raise PluginError(f"extractor '{name}': option '{fld.name}' expects {typ.__name__} "
                          f"(got '{raw}')") from None


def prune(tendons: list[Tendon], options) -> list[Tendon]:
    """Drop tendons shorter than ``options.min_length`` (m) and, if the options have
    ``min_tension``, weaker than that fraction of the strongest tendon's tension."""
    kept = [t for t in tendons if t.length >= options.min_length]
    frac = getattr(options, "min_tension", 0.0)
    if kept and frac > 0:
        strongest = max(t.tension for t in kept)
        kept = [t for t in kept if t.tension >= frac * strongest]
    return kept


# ---------------------------------------------------------------- discovery
def available_extractors() -> dict[str, object]:
    """Entry points of the installed extractors, by name (nothing is imported)."""
    return {ep.name: ep for ep in entry_points(group=GROUP)}


def load_extractor(name: str) -> Extractor:
    """Import and instantiate an installed extractor; one clear PluginError if it is
    unknown, fails to import, or does not follow the protocol."""
    eps = available_extractors()
    if name not in eps:
        raise PluginError(f"unknown extractor '{name}' (installed: {', '.join(sorted(eps)) or 'none'})")
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


# ---------------------------------------------------------------- metrics
@dataclass
class MetricSettings:
    """``kink_angle`` (degrees) above which a turn is a kink; ``mu`` the friction
    coefficient of the capstan factor exp(-mu Theta)."""

    kink_angle: float = 30.0
    mu: float = 0.1


def tendon_metrics(problem, state: IdealizedState, tendons: list[Tendon],
                   settings: MetricSettings | None = None) -> dict:
    """The metrics of DESIGN.md section 5, the same for every extractor (SI units,
    angles in radians): ``count``, ``total_length``, ``lengths``, ``total_turning``
    (sum of |turn angles| over all tendons), ``max_turn``, ``kinks``, ``capstan``
    (exp(-mu Theta) per tendon) and ``capstan_worst``, ``tension_cv`` (the largest
    coefficient of variation of the tension along a source strand, over the
    tendons; ``tension_cvs`` per tendon) and ``coverage`` (the share of the
    idealized active tension-length sum tau_i a0_i that the tendons' fibers carry)."""
    s = settings or MetricSettings()
    a0 = problem.fibers.a0
    turns = [t.turn_angles() for t in tendons]
    theta = np.array([tt.sum() for tt in turns]) if tendons else np.zeros(0)
    all_turns = np.concatenate(turns) if turns else np.zeros(0)
    capstan = np.exp(-s.mu * theta)
    cvs = np.array([t.tension_std / t.tension if t.tension > 0 else 0.0 for t in tendons])
    active = state.active
    total = float((state.tau[active] * a0[active]).sum())
    used = np.zeros(len(a0), dtype=bool)
    for t in tendons:
        used[t.fibers] = True
    covered = float((state.tau[active & used] * a0[active & used]).sum())
    return {
        "count": len(tendons),
        "total_length": float(sum(t.length for t in tendons)),
        "lengths": [t.length for t in tendons],
        "total_turning": float(theta.sum()),
        "max_turn": float(all_turns.max()) if len(all_turns) else 0.0,
        "kinks": int((all_turns > math.radians(s.kink_angle)).sum()),
        "capstan": capstan.tolist(),
        "capstan_worst": float(capstan.min()) if len(capstan) else 1.0,
        "tension_cv": float(cvs.max()) if len(cvs) else 0.0,
        "tension_cvs": cvs.tolist(),
        "coverage": covered / total if total > 0 else 0.0,
    }


__all__ = ["EXTRACTOR_API", "GROUP", "PluginError", "IdealizedState", "Tendon", "FiberView", "Extractor",
           "MetricSettings", "tendon_metrics", "turn_angles", "prune", "available_extractors",
           "load_extractor"]
