"""The direct backend: the model's Hessian assembled as a scipy sparse matrix on
the free DOFs and factorized by SuperLU, with a fill-reducing ordering
computed once per sparsity pattern."""

from __future__ import annotations

from typing import Iterable, Iterator

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ConvergenceError
from ..physics.model import Model
from ._newton_kernels import direction_from
from .linear import LinearSolver, LinearStats


class Factorization:
    """A SuperLU factorization of ``P H P^T``, ``P`` the fill-reducing ordering of
    the backend's sparsity pattern (computed once, not per factorization);
    :meth:`solve` works in the free-DOF numbering of ``H``."""

    def __init__(self, Hp: sp.csc_matrix, order: np.ndarray):
        try:
            self.lu = spla.splu(Hp, permc_spec="NATURAL", diag_pivot_thresh=0.1,
                                options={"SymmetricMode": True})
        except RuntimeError as exc:  # exactly singular
            raise np.linalg.LinAlgError(str(exc)) from None
        self.order = order

    def solve(self, b: np.ndarray) -> np.ndarray:
        """y with H y = b, b (nf,) on the free DOFs."""
        bp = np.empty_like(b)
        bp[self.order] = b
        return self.lu.solve(bp)[self.order]


class DirectSolver(LinearSolver):
    """The model's Hessian assembled as a scipy sparse matrix, factorized by SuperLU.

    The sparsity pattern (free DOFs only) and the scatter map from element and
    cable entries to it are built once; an assembly then only computes values."""

    name = "direct"

    def __init__(self, model: Model):
        self.model = model
        self.stats = LinearStats()
        self.free = np.repeat(~model.fixed, 2)
        self.factor = None  # the last factorization, reused by chord steps and predictors
        self.factor_exact = False
        self._build_structure()

    def _build_structure(self) -> None:
        m = self.model
        T = m.mesh.triangles
        cab = m.cables
        edofs = (2 * T[:, :, None] + np.arange(2)).reshape(-1, 6)  # (m, 6)
        pt_nodes = T[cab.points.tri] if m.P else np.zeros((0, 3), np.int64)
        seg_nodes = np.concatenate([pt_nodes[cab.segments[:, 0]], pt_nodes[cab.segments[:, 1]]], 1)
        self.seg_coef = np.concatenate([-cab.points.bary[cab.segments[:, 0]],
                                        cab.points.bary[cab.segments[:, 1]]], 1)  # (S, 6)
        sdofs = (2 * seg_nodes[:, :, None] + np.arange(2)).reshape(-1, 12)  # (S, 12)
        rows = [np.repeat(edofs, 6, axis=1).ravel(), np.repeat(sdofs, 12, axis=1).ravel()]
        cols = [np.tile(edofs, (1, 6)).ravel(), np.tile(sdofs, (1, 12)).ravel()]
        # the axial part couples all the segments of a cable (one block per cable;
        # single-segment cables add it to their segment's block)
        if not m.single:
            for c in range(m.C):
                g = sdofs[cab.start[c]:cab.start[c + 1]].ravel()
                rows.append(np.repeat(g, len(g)))
                cols.append(np.tile(g, len(g)))
        r, c = np.concatenate(rows), np.concatenate(cols)
        free_index = np.cumsum(self.free) - 1
        self.keep = self.free[r] & self.free[c]
        r, c = free_index[r[self.keep]], free_index[c[self.keep]]
        nf = int(self.free.sum())
        self.order = _fill_reducing_order(r, c, nf)
        r, c = self.order[r], self.order[c]
        key = c.astype(np.int64) * nf + r
        uniq, self.pos = np.unique(key, return_inverse=True)
        self.indices = (uniq % nf).astype(np.int32)
        self.indptr = np.searchsorted(uniq // nf, np.arange(nf + 1)).astype(np.int32)
        self.shape = (nf, nf)
        self.nnz = len(uniq)

    def _values(self) -> np.ndarray:
        """Every Hessian entry in pattern order: element and segment blocks from
        Taichi, then (multi-segment cables) one axial block per cable."""
        m = self.model
        vals = [m.hessian_entries()]
        if not m.single:
            d = m.hessian_data()
            grad = (self.seg_coef[:, :, None] * d["seg_n"][:, None, :]).reshape(-1, 12)  # dL/dx
            st = m.cables.start
            for c in range(m.C):
                gv = grad[st[c]:st[c + 1]].ravel()
                vals.append(d["kc"][c] * np.outer(gv, gv).ravel())
        return np.concatenate(vals)

    def assemble_ordered(self, project: bool = False, prepare: bool = True) -> sp.csc_matrix:
        """``P H P^T``: the Hessian on the free DOFs in the fill-reducing order, CSC."""
        if prepare:
            self.model.prepare_hessian(project)
        vals = self._values()[self.keep]
        data = np.bincount(self.pos, weights=vals, minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)

    def assemble(self, project: bool = False, prepare: bool = True) -> sp.csc_matrix:
        """The Hessian of E_tot at x on the free DOFs (exact or projected), CSC."""
        return self.assemble_ordered(project, prepare)[self.order][:, self.order].tocsc()

    def factorize(self, Hp: sp.csc_matrix) -> Factorization:
        """Factorize an ordered Hessian (:meth:`assemble_ordered`)."""
        return Factorization(Hp, self.order)

    def _factor_solve(self, Hp: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
        lu = self.factorize(Hp)
        y = lu.solve(b)
        res = b - self._ordered_product(Hp, y)
        if np.linalg.norm(res) > 1e-10 * np.linalg.norm(b):  # one step of iterative refinement
            y += lu.solve(res)
        if not np.all(np.isfinite(y)):
            raise np.linalg.LinAlgError("non-finite solution")
        self.stats.solves += 1
        self.factor = lu
        return y

    def _ordered_product(self, Hp: sp.csc_matrix, y: np.ndarray) -> np.ndarray:
        """H y from the ordered matrix, in the free-DOF numbering."""
        yp = np.empty_like(y)
        yp[self.order] = y
        return (Hp @ yp)[self.order]

    def approx_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """Solve with the last factorization (the Hessian it was made from), full (n, 2);
        None before the first."""
        if self.factor is None:
            return None
        out = np.zeros(2 * self.model.n)
        out[self.free] = self.factor.solve(np.asarray(rhs, dtype=float).ravel()[self.free])
        return out.reshape(-1, 2)

    def reset(self) -> None:
        """Forget the last factorization."""
        self.factor = None

    def newton_direction(self, eta: float, project: bool, fresh: bool = True) -> tuple[float, bool, int]:
        """With ``fresh=False`` and a factorization at hand (of the exact Hessian at a
        nearby state), reuse it: a chord step costing one triangular solve."""
        m = self.model
        g = m.last_gradient[self.free]
        if not fresh and not project and self.factor is not None and self.factor_exact:
            y = self.factor.solve(-g)
            self.stats.reused += 1
        else:
            try:
                y = self._factor_solve(self.assemble_ordered(project), -g)
            except np.linalg.LinAlgError:
                return 0.0, True, 0
            self.factor_exact = not project
        dx = np.zeros(2 * m.n)
        dx[self.free] = y
        return direction_from(m, dx), False, 0

    def solve(self, rhs: np.ndarray, tol: float = 0.0, warm: bool = False,
              prepare: bool = True) -> np.ndarray:
        """A fresh factorization of the exact Hessian (``prepare=False``: of the
        element tangents as last prepared) and one refined solve; ``tol`` and
        ``warm`` do not apply."""
        H = self.assemble_ordered(False, prepare)
        b = np.asarray(rhs, dtype=float).ravel()[self.free]
        try:
            y = self._factor_solve(H, b)
        except np.linalg.LinAlgError as exc:
            raise ConvergenceError(f"the Hessian is singular: {exc}") from None
        self.factor_exact = True
        out = np.zeros(2 * self.model.n)
        out[self.free] = y
        return out.reshape(-1, 2)

    def solve_many(self, rhs: Iterable[np.ndarray], tol: float) -> Iterator[np.ndarray]:
        """The first right-hand side factorizes the Hessian; the others reuse that
        factorization (one triangular solve each)."""
        for j, b in enumerate(rhs):
            yield self.solve(b, tol=tol) if j == 0 else self.approx_solve(b)


def _fill_reducing_order(rows: np.ndarray, cols: np.ndarray, n: int) -> np.ndarray:
    """A symmetric fill-reducing ordering of a sparsity pattern (entries rows, cols
    in 0..n-1): ``order[i]`` is the new index of DOF i. SuperLU's minimum degree
    on A^T + A, run once on a diagonally dominant matrix of the pattern, so that
    each later factorization skips the ordering (a third of its time)."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    A = sp.csc_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    A = A + sp.diags(np.asarray(abs(A).sum(axis=1)).ravel() + 1.0)
    lu = spla.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                   options={"SymmetricMode": True})
    return np.asarray(lu.perm_c, dtype=np.int64)
