"""The sparse Cholesky factorization the direct backend (:mod:`.direct`) runs:
Intel MKL PARDISO's (:mod:`.pardiso`) where the ``mkl`` extra is installed,
else qdldl's LDL^T (:class:`LDL`); both factorize one sparsity pattern's
matrices, the symbolic analysis with the first and only the numbers after.
:func:`cholesky_library` names the one in use, for the records of what made a
result: its round-off moves every direct solve's numbers."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import numpy as np
import qdldl
import scipy.sparse as sp

from ..probes import probe
from ._csc import triangle
from .pardiso import PardisoLDL
from .pardiso import available as pardiso_available
from .pardiso import describe as describe_mkl


class LDL:
    """LDL^T factorizations (qdldl) of symmetric matrices of one sparsity pattern
    (CSC ``indptr``, ``indices``, n x n): the symbolic analysis with the first,
    only the numbers after. qdldl orders every pattern by its own AMD, so
    ``reorder`` (:class:`~tendon_taichi.solve.pardiso.PardisoLDL`'s) changes
    nothing here, nor ``threads``: qdldl runs on one. One factorization is
    current at a time (``generation`` counts them)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, n: int, reorder: bool = False,
                 threads: int | None = None):
        self._pattern = (indptr, indices, n)
        self.upper, self.indices, self.indptr = triangle(indptr, indices, n)
        self.n = n
        self.reorder = reorder
        self.solver = None
        self.generation = 0

    def blank(self) -> "LDL":
        """An LDL of the same pattern, not factorized."""
        return LDL(*self._pattern, reorder=self.reorder)

    @probe("factor")
    def factor(self, data: np.ndarray) -> bool:
        """Factorize the matrix of entries ``data`` (in the pattern's order); whether
        it is positive definite (every pivot > 0), else the factors are not to be used."""
        A = sp.csc_matrix((np.take(data, self.upper), self.indices, self.indptr), shape=(self.n, self.n))
        if self.solver is None:
            self.solver = qdldl.Solver(A, upper=True)
        else:
            self.solver.update(A, upper=True)
        self.generation += 1
        return bool(np.all(self.solver.factors()[1] > 0.0))

    @probe("solves")
    def solve(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b with the current factorization, b (n,) or (n, r)."""
        if np.ndim(b) == 2:
            return np.column_stack([self.solver.solve(c) for c in np.asarray(b).T]) if b.shape[1] else b.copy()
        return self.solver.solve(b)


def cholesky_class() -> type:
    """The factorization class of this process: :class:`~.pardiso.PardisoLDL` where
    MKL PARDISO loads, else :class:`LDL`."""
    return PardisoLDL if pardiso_available() else LDL


def cholesky_library() -> dict:
    """The sparse Cholesky this process factorizes with (:func:`cholesky_class`):
    ``name`` ("MKL PARDISO" or "qdldl") and its ``version``, with MKL's ``build``
    and ``code_path`` (:func:`~tendon_taichi.solve.pardiso.describe`). Its round-off
    moves the numbers of every direct solve, and a search can turn that into
    another design: results are reproducible to the bit with the same library,
    version and code path."""
    if pardiso_available():
        return {"name": "MKL PARDISO", **describe_mkl()}
    try:
        return {"name": "qdldl", "version": version("qdldl")}
    except PackageNotFoundError:
        return {"name": "qdldl", "version": None}
