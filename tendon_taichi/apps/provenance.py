"""What made a result file (``design.json``, ``bench.json``, ``planted_bench.json``,
``sweep.json``; ``docs/cli.md``, Provenance): the package's provenance record and
the sparse Cholesky library, whose round-off moves the numbers."""

from __future__ import annotations

from ..solve.cholesky import cholesky_library
from ..version import provenance


def result_provenance() -> dict:
    """:func:`~tendon_taichi.version.provenance` (``version``, ``commit``, ``dirty``,
    ``made_by``, ``date``) with ``cholesky``
    (:func:`~tendon_taichi.solve.cholesky.cholesky_library`)."""
    return {**provenance(), "cholesky": cholesky_library()}
