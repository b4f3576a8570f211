"""One key of a scene's ``[optimize]`` table: its name, default, unit and
bounds, declared once; the scene reader, the command-line flags and the
documentation's tables are made from these declarations."""

from __future__ import annotations

from dataclasses import dataclass

from ..tables import TableReader


@dataclass(frozen=True)
class Setting:
    """A setting of the optimization.

    ``name``: its key in ``[optimize]`` (or in the inline ``table``, e.g.
    ``homotopy``); ``default``; ``text``: what it is, one line; ``unit``: SI
    unit ("" for dimensionless); ``kind``: ``float``, ``int`` or ``str``;
    ``gt``/``ge``/``lt``/``le``: bounds of a number; ``choices`` of a string;
    ``within_fiber_bounds``: a contraction ratio, so it must lie in
    ``[-max_payout, max_contraction]`` of the scene's ``[fibers]``; ``flag``:
    the command-line flag (default ``--`` and the name with dashes)."""

    name: str
    default: float | int | str
    text: str
    unit: str = ""
    kind: type = float
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] = ()
    within_fiber_bounds: bool = False
    table: str | None = None
    flag_name: str | None = None

    @property
    def flag(self) -> str:
        return self.flag_name or "--" + self.name.replace("_", "-")

    @property
    def key(self) -> str:
        """The key as the scene file spells it, e.g. ``homotopy.k0``."""
        return f"{self.table}.{self.name}" if self.table else self.name

    def read(self, reader: TableReader, fibers) -> float | int | str:
        """The validated value from ``reader`` (its default where absent); ``fibers``
        are the scene's fiber settings (for ``within_fiber_bounds``)."""
        if self.kind is str:
            return reader.choice(self.name, self.default, self.choices)
        if self.kind is int:
            return reader.integer(self.name, self.default, ge=int(self.ge))
        ge, le = self.ge, self.le
        if self.within_fiber_bounds:
            ge, le = -fibers.max_payout, fibers.max_contraction
        return reader.number(self.name, self.default, gt=self.gt, ge=ge, lt=self.lt, le=le)

    def bounds_text(self) -> str:
        """The admissible values, for the documentation."""
        if self.choices:
            return " / ".join(f"`{c}`" for c in self.choices)
        if self.within_fiber_bounds:
            return "[-max_payout, max_contraction]"
        parts = [f"{word} {bound:g}" for bound, word in ((self.gt, ">"), (self.ge, ">="), (self.lt, "<"),
                                                         (self.le, "<=")) if bound is not None]
        return (("integer " if self.kind is int else "") + ", ".join(parts)).strip()
