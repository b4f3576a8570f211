"""The optimize settings: every registered term's settings and those of the
homotopy schedule, read from a scene's ``[optimize]`` table.

:class:`OptimizeSettings` and :class:`Homotopy` are made from the
declarations (:data:`SETTINGS`), so a new term's keys appear here, in the
scene format, on the command line and in the documentation without further
edits."""

from __future__ import annotations

from dataclasses import field, make_dataclass, replace

from ..errors import SceneError
from ..tables import TableReader
from .setting import Setting
from .terms import registered

#: the homotopy schedule, the inline table ``homotopy = { k0 = ..., factor = ..., k_min = ... }``
HOMOTOPY = (
    Setting("k0", 0.25, "first homotopy k", "N", gt=0.0, table="homotopy"),
    Setting("factor", 0.5, "k <- k * factor per stage", gt=0.0, lt=1.0, table="homotopy", flag_name="--k-factor"),
    Setting("k_min", 0.01, "stop once k falls below this (at most k0)", "N", gt=0.0, table="homotopy"),
)

#: what every run reads, whatever its terms: scales, the start, the schedule and its stopping rules
GENERAL = (
    Setting("tension_scale", 1.0, "tension scale tau_ref", "N", gt=0.0),
    Setting("initial_contraction", 0.005, "uniform starting ratio r0 = ac / a0", within_fiber_bounds=True),
    *HOMOTOPY,
    Setting("active_threshold", 0.01, "a fiber is active if tau > this x tau_ref", gt=0.0),
    Setting("stage_iterations", 500, "L-BFGS-B iteration cap per stage", kind=int, ge=1),
    Setting("settle_tol", 1.0e-4, "a stage ends when, over the settle window, the objective fell by less than "
            "this x its value after the stage's first iteration", ge=0.0),
    Setting("settle_window", 25, "iterations over which a stage must have settled", kind=int, ge=1),
)

#: every setting: the terms' (in the objective's order), then the general ones
SETTINGS: tuple[Setting, ...] = tuple(s for t in registered() for s in t.settings) + GENERAL


def _doc(title: str, settings) -> str:
    rows = "\n".join(f"    ``{s.name}`` = {s.default!r}{' ' + s.unit if s.unit else ''}: {s.text}" for s in settings)
    return f"{title}\n\n{rows}\n"


def _dataclass(name: str, fields: list):
    cls = make_dataclass(name, fields, frozen=True)
    cls.__module__ = __name__  # pickled by reference, as a class defined here
    return cls


Homotopy = _dataclass("Homotopy", [(s.name, s.kind, s.default) for s in HOMOTOPY])
Homotopy.__doc__ = _doc("The L0 homotopy schedule: k <- k * factor per stage, from k0 until below k_min.",
                        HOMOTOPY)


def _fields():
    out = []
    for s in SETTINGS:
        if s.table is None:
            out.append((s.name, s.kind, s.default))
        elif s.table == "homotopy" and all(name != "homotopy" for name, *_ in out):
            out.append(("homotopy", Homotopy, field(default_factory=Homotopy)))
    return out


OptimizeSettings = _dataclass("OptimizeSettings", _fields())
OptimizeSettings.__doc__ = _doc("Weights and schedule of the regularized soft IK (one per [optimize] key; "
                                "homotopy: a Homotopy).", SETTINGS)


def read_optimize(r: TableReader, fibers) -> OptimizeSettings:
    """The ``[optimize]`` table read by ``r`` (its keys validated, unknown ones
    rejected); ``fibers`` are the scene's fiber settings. A homotopy table
    without ``k0`` starts at the default k0 or at its ``k_min``, the larger
    (a ``k_min`` above the default still runs one homotopy stage)."""
    hom = Homotopy()
    if r.has("homotopy"):
        h = TableReader(r.raw("homotopy"), f"{r.where}.homotopy", r.origin)
        given = h.has("k0")
        hom = Homotopy(**{s.name: s.read(h, fibers) for s in HOMOTOPY})
        h.finish()
        if not given:
            hom = replace(hom, k0=max(hom.k0, hom.k_min))
        if hom.k_min > hom.k0:
            raise SceneError(f"{r.origin}: {r.where}.homotopy.k_min ({hom.k_min:g}) must be <= k0 "
                             f"({hom.k0:g}), else no homotopy stage runs")
    values = {s.name: s.read(r, fibers) for s in SETTINGS if s.table is None}
    r.finish()
    return OptimizeSettings(**values, homotopy=hom)


def settings_dict(s: OptimizeSettings) -> dict:
    """Optimize settings as plain JSON-able values."""
    d = dict(s.__dict__)
    d["homotopy"] = dict(s.homotopy.__dict__)
    return d


def settings_from_dict(d: dict) -> OptimizeSettings:
    """The inverse of :func:`settings_dict`."""
    d = dict(d)
    d["homotopy"] = Homotopy(**d["homotopy"])
    return OptimizeSettings(**d)
