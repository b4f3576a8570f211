"""Typed access to one TOML table, with errors that name the key (scene and
sweep files). Every problem raises :class:`~tendon_taichi.errors.SceneError`
with one line: ``<origin>: <table>.<key> <what is wrong>``."""

from __future__ import annotations

import math

import numpy as np

from .errors import SceneError


class TableReader:
    """Reads the keys of ``table`` (a dict from TOML) at ``where`` in ``origin``;
    :meth:`finish` rejects the keys nobody read."""

    def __init__(self, table: dict, where: str, origin: str):
        if not isinstance(table, dict):
            raise SceneError(f"{origin}: {where} must be a table")
        self.table, self.where, self.origin = table, where, origin
        self.used: set[str] = set()

    def fail(self, key: str, msg: str):
        raise SceneError(f"{self.origin}: {self.where}.{key} {msg}")

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str):
        self.used.add(key)
        return self.table[key]

    def number(self, key: str, default: float | None = None, *, gt=None, ge=None, lt=None,
               le=None) -> float | None:
        if key not in self.table:
            return default
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.fail(key, f"must be a finite number (got {v!r})")
        v = float(v)
        for bound, ok, word in ((gt, lambda b: v > b, ">"), (ge, lambda b: v >= b, ">="),
                                (lt, lambda b: v < b, "<"), (le, lambda b: v <= b, "<=")):
            if bound is not None and not ok(bound):
                self.fail(key, f"must be {word} {bound:g} (got {v:g})")
        return v

    def integer(self, key: str, default: int, *, ge: int) -> int:
        if key not in self.table:
            return default
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, int) or v < ge:
            self.fail(key, f"must be an integer >= {ge} (got {v!r})")
        return v

    def choice(self, key: str, default: str, options: tuple[str, ...]) -> str:
        if key not in self.table:
            return default
        v = self.raw(key)
        if v not in options:
            self.fail(key, f"must be one of {', '.join(repr(o) for o in options)} (got {v!r})")
        return v

    def point(self, key: str, default=None, required: bool = False, dim: int | None = None,
              unit: str = "coordinates") -> tuple[float, ...] | None:
        """The point at ``key`` (:func:`as_point`; ``dim`` the body's dimension, ``unit``
        what its numbers are called in the error for one of the other dimension)."""
        if key not in self.table:
            if required:
                self.fail(key, "is required")
            return default
        return as_point(self.raw(key), f"{self.origin}: {self.where}.{key}", dim, unit)

    def polygon(self, value, name: str) -> np.ndarray:
        where = f"{self.origin}: {self.where}.{name}"
        if not isinstance(value, list) or len(value) < 3:
            raise SceneError(f"{where} must be a list of at least 3 [x, y] points")
        return np.array([as_point(p, where) for p in value], dtype=float)

    def finish(self) -> None:
        unknown = sorted(set(self.table) - self.used)
        if unknown:
            raise SceneError(f"{self.origin}: unknown key{'s' if len(unknown) > 1 else ''} "
                             f"{', '.join(repr(k) for k in unknown)} in {self.where}")


#: the largest magnitude of a point's coordinate (m, or m/s^2 for gravity): far beyond any
#: robot, and far below where squaring it (lengths, areas) overflows
MAX_COORDINATE = 1e6


#: the names of a point's coordinates in each dimension, for messages
_AXES = {2: ("[x, y]", "two"), 3: ("[x, y, z]", "three")}


def _numbers(v) -> bool:
    """Whether ``v`` is a list of finite numbers (not booleans)."""
    return isinstance(v, list) and all(not isinstance(c, bool) and isinstance(c, (int, float)) and math.isfinite(c)
                                       for c in v)


def as_point(v, where: str, dim: int | None = None, unit: str = "coordinates") -> tuple[float, ...]:
    """``[x, y]`` (``[x, y, z]`` for ``dim`` 3) with finite numbers of magnitude at most
    :data:`MAX_COORDINATE` as a tuple; SceneError naming ``where`` otherwise. Given the
    body's ``dim``, a point of the other dimension is said to be one: "must have 3
    ``unit`` for a 3D body"."""
    n = 2 if dim is None else dim
    if dim is not None and _numbers(v) and len(v) in _AXES and len(v) != dim:
        raise SceneError(f"{where} must have {dim} {unit} for a {dim}D body (got {v!r})")
    names, count = _AXES[n]
    if not _numbers(v) or len(v) != n:
        raise SceneError(f"{where} must be {names} with {count} finite numbers (got {v!r})")
    if max(abs(c) for c in v) > MAX_COORDINATE:
        raise SceneError(f"{where} must be {names} with numbers of magnitude at most {MAX_COORDINATE:g} (got {v!r})")
    return tuple(float(c) for c in v)
