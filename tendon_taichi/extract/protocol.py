"""Tendon extraction: the plugin protocol (``docs/plugins.md``).

An extractor turns the fiber tensions of an optimized (idealized) run into a
few tendons. Plugins - the built-in ones in the top-level ``extractors``
package as well as third-party ones - subclass :class:`Extractor` and register
an entry point in the group ``tendon_taichi.extractors``::

    [project.entry-points."tendon_taichi.extractors"]
    my_extractor = "my_package.module:MyExtractor"

A plugin imports only :mod:`tendon_taichi.extraction`, which re-exports this
module, :class:`~tendon_taichi.extract.fiber_view.FiberView`, the metrics and
the plugin discovery; none of them loads Taichi. It receives the :class:`~tendon_taichi.body.problem.Problem`
(read-only: ``problem.fibers``, ``problem.mesh``, ``problem.fixed``), an
:class:`IdealizedState` and its options, and returns :class:`Tendon` objects;
:class:`FiberView` gives the graph queries most extractors need. Metrics are
computed the same way for every extractor by
:func:`~tendon_taichi.extract.metrics.tendon_metrics`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import TendonError

#: version of this protocol; an extractor declares the one it was written for
EXTRACTOR_API = 1


class PluginError(TendonError):
    """An extractor is unknown, fails to load, or is incompatible."""


@dataclass
class IdealizedState:
    """What an extractor works from: fiber tensions ``tau`` (f,) N and contractions
    ``ac`` (f,) m of one stage, the equilibrium ``x`` (n, dim) m, and the tension
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
    (k-1,), rest ``waypoints`` (k, dim) m, anchored at the first waypoint and pulled
    at the last; ``tension`` and ``tension_std`` (N) of its active source fibers.
    ``contraction`` (m) is set when the realizable robot is solved. A smooth
    route off the lattice (what consolidation makes of an extractor's tendons)
    has no ``nodes`` or ``fibers`` and its spline's ``control`` points (m, 2);
    one that leaves the body has its ``exit`` (dim,), the last waypoint, where it
    runs out through the outline (``docs/method.md``, exits)."""

    nodes: np.ndarray
    fibers: np.ndarray
    waypoints: np.ndarray
    tension: float
    tension_std: float
    contraction: float | None = None
    control: np.ndarray | None = None
    exit: np.ndarray | None = None

    @property
    def on_lattice(self) -> bool:
        """The waypoints are fiber nodes (an extractor's tendon, not a smooth route)."""
        return len(self.nodes) == len(self.waypoints)

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
        out = {"waypoints": self.waypoints.tolist(), "length": self.length, "tension": self.tension,
               "tension_std": self.tension_std, "contraction": self.contraction,
               "anchor": self.anchor.tolist(), "pull_end": self.pull_end.tolist()}
        if self.control is not None:
            out["control_points"] = self.control.tolist()
        if self.exit is not None:
            out["exit"] = self.exit.tolist()
        if self.on_lattice:
            out.update(fiber_nodes=[int(v) for v in self.nodes], fibers=[int(f) for f in self.fibers])
        return out


def turn_angles(points: np.ndarray) -> np.ndarray:
    """Turn angles at the interior points of a polyline (k, dim), radians in [0, pi]."""
    d = np.diff(np.asarray(points, dtype=float), axis=0)
    if len(d) < 2:
        return np.zeros(0)
    a, b = d[:-1], d[1:]
    cos = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.arccos(np.clip(cos, -1.0, 1.0))


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
        converted to each field's type. Unknown names, bad values and values outside
        the ``Options.ranges`` ``{name: (low, high)}`` (inclusive; None: open) raise
        PluginError."""
        known = {f.name: f for f in cls.option_fields()}
        kwargs = {}
        for key, raw in (values or {}).items():
            if key not in known:
                raise PluginError(f"extractor '{cls.name}' has no option '{key}' "
                                  f"(options: {', '.join(known) or 'none'})")
            kwargs[key] = _convert(cls.name, known[key], raw)
            _check_range(cls.name, key, kwargs[key], getattr(cls.Options, "ranges", {}).get(key))
        return cls.Options(**kwargs)


def _check_range(name: str, key: str, value, bounds: tuple | None) -> None:
    """PluginError when a number ``value`` lies outside ``bounds`` (low, high), None ends open."""
    if bounds is None or isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    low, high = bounds
    if (low is None or value >= low) and (high is None or value <= high):
        return
    want = (f"in [{low:g}, {high:g}]" if low is not None and high is not None
            else f">= {low:g}" if low is not None else f"<= {high:g}")
    raise PluginError(f"extractor '{name}': option '{key}' must be {want} (got {value:g})")


def _convert(name: str, fld: dataclasses.Field, raw):
    typ = fld.type if isinstance(fld.type, type) else {"float": float, "int": int, "bool": bool,
                                                        "str": str}.get(str(fld.type), str)
    if not isinstance(raw, str):
        value = raw
    else:
        value = _parse(name, fld, typ, raw)
    if isinstance(value, float) and not math.isfinite(value):
        raise PluginError(f"extractor '{name}': option '{fld.name}' must be a finite number (got {value})")
    return value


def _parse(name: str, fld: dataclasses.Field, typ: type, raw: str):
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
