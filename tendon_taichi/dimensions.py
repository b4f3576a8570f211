"""``PerDimension``: what a layer gives per body dimension, chosen by ``dim``
(the body layer decides a body's dimension: :mod:`tendon_taichi.body.dimension`)."""

from __future__ import annotations


class PerDimension(dict):
    """``dim`` -> the item a layer uses for bodies of that dimension; ``what`` names
    the items in the error for a dimension none is registered for."""

    def __init__(self, what: str, items: dict | None = None):
        super().__init__(items or {})
        self.what = what

    def register(self, dim: int, item):
        """Make ``item`` the one of ``dim``; returns the one it replaces, if any."""
        before = self.get(dim)
        self[dim] = item
        return before

    def known(self) -> str:
        """The registered dimensions, as "2D, 3D"."""
        return ", ".join(f"{d}D" for d in sorted(self))

    def of(self, dim: int):
        """The item of ``dim``; KeyError, naming the registered dimensions, where there is none."""
        if dim not in self:
            raise KeyError(f"no {self.what} for a {dim}D body (registered: {self.known()})")
        return self[dim]
