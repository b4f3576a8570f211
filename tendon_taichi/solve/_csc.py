"""A sparsity-pattern helper of this layer's factorizations (:mod:`.direct`, :mod:`.pardiso`)."""

import numpy as np


def triangle(indptr: np.ndarray, indices: np.ndarray, n: int, lower: bool = False):
    """The upper (``lower``: lower) triangle of an n x n CSC pattern: which of its
    entries lie there (their positions in the pattern's order, ascending), their
    row indices and the triangle's column pointers (int32)."""
    col = np.repeat(np.arange(n), np.diff(indptr))
    keep = indices >= col if lower else indices <= col
    pointers = np.concatenate([[0], np.cumsum(np.bincount(col[keep], minlength=n))]).astype(np.int32)
    return np.flatnonzero(keep), indices[keep], pointers
