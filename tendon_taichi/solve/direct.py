"""The direct backend: the model's Hessian assembled as a scipy sparse matrix on
the free DOFs and factorized, with a fill-reducing ordering computed once per
sparsity pattern: by LDL^T (qdldl, its symbolic analysis once per pattern and
only the numbers afterwards; where MKL is installed, by PARDISO's supernodal
Cholesky instead - a fiber lattice in that order, a tendon robot in PARDISO's
own minimum degree order (:attr:`_Pattern.reorder`): :mod:`.pardiso`) where
the matrix is positive definite - at and near a stable equilibrium, almost
always - and where it is not (an LDL^T with a pivot <= 0 proves it: by
Sylvester's law of inertia D has as many negative entries as the matrix has
negative eigenvalues) by PARDISO's symmetric indefinite factorization where MKL
is installed, else - and where that would perturb a pivot - by SuperLU with
pivoting.

A many-segment cable (a tendon) couples every node along it through its axial
stiffness ``kc g g^T`` (``g = dL/dx``, ``L`` its weighted length): a dense
block per cable. It is kept out of the sparse matrix and applied as a low-rank
update (Woodbury: one extra solve per taut tendon), so the sparse pattern is
that of the elements and the segments alone, and its ordering - the
elements' - is computed once per mesh and shared by every tendon layout.

When a route moves (route optimization), a few of its points cross into other
triangles; a new pattern would need a new analysis of the factorization, which
costs more than its numbers. Where the current pattern lacks the entries of at
most :data:`DETACHED_MAX` segments it is kept, and those segments are *detached*
(:meth:`DirectSolver._reattach`): each one's rank-one block is split into a part
within its points' triangles, which every pattern holds, and one more column."""

from __future__ import annotations

import weakref
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import cached_property, partial
from typing import Callable, Iterable, Iterator

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ConvergenceError
from ..physics.capstan import perp
from ..physics.model import Model
from ..probes import probe
from ._newton_kernels import direction_from
from .cholesky import LDL, cholesky_class
from .linear import LinearSolver, LinearStats
from .pardiso import PardisoLDL


@dataclass
class Assembled:
    """An assembled Hessian in the fill-reducing order: ``H = Hp + U diag(K) U^T``,
    ``Hp`` sparse (CSC), ``U`` (nf, r) and ``K`` (r,) the taut tendons' axial terms
    (K > 0), then the detached segments' columns (K < 0, :meth:`DirectSolver._reattach`)."""

    Hp: sp.csc_matrix
    U: np.ndarray
    K: np.ndarray

    def product(self, y: np.ndarray) -> np.ndarray:
        """H y for y in the ordered numbering."""
        out = self.Hp @ y
        if len(self.K):
            out += self.U @ (self.K * (self.U.T @ y))
        return out


class Factorization:
    """A factorization of an :class:`Assembled` Hessian's sparse part - LDL^T
    (``ldl``, an :class:`LDL` of its pattern, or a
    :class:`~tendon_taichi.solve.pardiso.PardisoLDL`) where it is positive definite,
    else PARDISO's symmetric indefinite factorization (``indefinite()``, asked for
    only then: None where MKL is not installed) where it needs no perturbed pivot,
    else SuperLU - with the low-rank part by Woodbury's identity; :meth:`solve`
    works in the free-DOF numbering (``order`` maps it to the ordered one)."""

    @probe("factorization")
    def __init__(self, H: Assembled, order: np.ndarray, ldl: LDL | PardisoLDL | None = None,
                 indefinite: Callable[[], PardisoLDL | None] | None = None):
        self.Hp, self.ldl, self.lu = H.Hp, None, None
        if ldl is not None and H.Hp.shape[0] and ldl.factor(H.Hp.data):
            self.ldl, self.generation = ldl, ldl.generation
        else:
            other = indefinite() if indefinite is not None and H.Hp.shape[0] else None
            if other is not None and other.factor(H.Hp.data):
                self.ldl, self.generation = other, other.generation
            else:
                try:
                    self.lu = spla.splu(H.Hp, permc_spec="NATURAL", diag_pivot_thresh=0.1,
                                        options={"SymmetricMode": True})
                except RuntimeError as exc:  # exactly singular
                    raise np.linalg.LinAlgError(str(exc)) from None
        self.order = order
        self.U = H.U
        if len(H.K):
            self.AinvU = self._sparse_solve(H.U).reshape(H.U.shape)
            self.capacitance = np.diag(1.0 / H.K) + H.U.T @ self.AinvU

    def _sparse_solve(self, b: np.ndarray) -> np.ndarray:
        """Hp^-1 b, b (nf,) or (nf, r) in the ordered numbering."""
        if self.lu is not None:
            return self.lu.solve(b)
        if self.ldl.generation != self.generation:  # the shared factors moved on: factorize a copy of its own
            own = self.ldl.blank()
            own.factor(self.Hp.data)
            self.ldl, self.generation = own, own.generation
        return self.ldl.solve(b)

    def solve_ordered(self, bp: np.ndarray) -> np.ndarray:
        y = self._sparse_solve(bp)
        if self.U.shape[1]:
            y -= self.AinvU @ np.linalg.solve(self.capacitance, self.U.T @ y)
        return y

    def solve(self, b: np.ndarray) -> np.ndarray:
        """y with H y = b, b (nf,) on the free DOFs."""
        bp = np.empty_like(b)
        bp[self.order] = b
        return self.solve_ordered(bp)[self.order]


#: per mesh and clamp set, the elements' part of a tendon robot's pattern
#: (:class:`_ElementPattern`; shared by tendon layouts)
_ELEMENT_PATTERN: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()

#: sparsity patterns a direct solver keeps at hand (a route's points move back and
#: forth across the same triangle edges while its route is optimized)
PATTERNS_KEPT = 4

#: per mesh, the last tendon patterns made by any direct solver of it, by their
#: free DOFs, ordering and cable structure (without factors): the poses of one
#: robot, and the many robots a design solves of the same few routes, share them
#: (a fiber lattice's pattern is not kept: few solvers make it, and it is large)
_SHARED_PATTERNS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
PATTERNS_SHARED = 8

#: of a segment block's 144 entries (12 x 12, row-major) those within one of its two points' triangles
_SAME_HALF = (np.arange(144) // 12 < 6) == (np.arange(144) % 12 < 6)

#: a tendon robot's cables moved: the most segments whose entries its pattern lacks
#: that it keeps (their blocks in the low-rank part, one more column to solve per
#: factorization each) rather than make the new pattern and analyze it. On the route
#: optimizations of `design t_shape --level 3` (benchmarks/route_replay.py):
#: 13.95 ms per evaluation against 15.40 with every new pattern made when it was
#: chosen (16 was no faster), 14.70 against 15.88 at fe418fd
DETACHED_MAX = 8


@dataclass
class _ElementPattern:
    """The element entries' part of a tendon robot's pattern: ``keep`` (36 m,) which
    entries of the element blocks lie on free DOFs, ``rows``/``cols`` those entries
    in the free numbering, ``order`` (nf,) the fill-reducing ordering, ``keys`` the
    distinct sorted keys ``col nf + row`` of the kept entries in that order, ``pos``
    each kept entry's index in ``keys``."""

    keep: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    order: np.ndarray
    keys: np.ndarray
    pos: np.ndarray


@dataclass
class _Pattern:
    """A sparsity pattern of the Hessian on the free DOFs in the fill-reducing
    ``order``: ``scatter`` each element and segment entry's index among the ``nnz``
    CSC entries (``indices``, ``indptr``), or ``nnz`` for an entry on a fixed DOF (a
    bin the assembly drops), ``reorder`` whether ``order`` leaves couplings out (a
    tendon robot's: the elements' order), so that the Cholesky orders the pattern
    again, the :class:`LDL` of the pattern once one was made and its PARDISO
    indefinite factorization once one was needed."""

    order: np.ndarray
    scatter: np.ndarray
    indices: np.ndarray
    indptr: np.ndarray
    nnz: int
    reorder: bool
    ldl: LDL | None = None
    indefinite: PardisoLDL | None = None

    @cached_property
    def keys(self) -> np.ndarray:
        """The entries' sorted keys ``col nf + row`` (ordered numbering), (nnz,)."""
        nf = len(self.indptr) - 1
        return np.repeat(np.arange(nf, dtype=np.int64), np.diff(self.indptr)) * nf + self.indices


@probe("indefinite")
def _indefinite(pattern: _Pattern) -> PardisoLDL | None:
    """The pattern's PARDISO indefinite factorization (its Cholesky's threads), made the
    first time a matrix of it is not positive definite (a new pattern's Cholesky almost
    always succeeds); None where its Cholesky is qdldl's (no MKL)."""
    if pattern.indefinite is None and isinstance(pattern.ldl, PardisoLDL):
        pattern.indefinite = PardisoLDL(pattern.indptr, pattern.indices, len(pattern.indptr) - 1,
                                        pattern.reorder, indefinite=True, threads=pattern.ldl.asked_threads)
    return pattern.indefinite


class DirectSolver(LinearSolver):
    """The model's Hessian assembled as a scipy sparse matrix and factorized
    (:class:`Factorization`).

    The sparsity pattern (free DOFs only) and the scatter map from element and
    cable entries to it are built once; an assembly then only computes values.
    ``ordered=False`` keeps the free DOFs' own numbering (node by node, x then y)
    instead of a fill-reducing order, for assembly without factorization; its
    factorizations run on ``factor_threads`` (None: the process's)."""

    name = "direct"
    fresh_solves = True

    #: keep the last factorization for Newton's chord steps when the cables move (a
    #: route's small step barely changes the Hessian, and Newton's chord test refreshes
    #: it when it stops contracting); False forgets it, so that a robot whose cables
    #: moved solves bit for bit as a new robot of the same cables would
    chord_across_moves = True

    #: the most segments a moved tendon robot's pattern may lack before it is made
    #: anew (:meth:`_reattach`; 0: always made anew, so that the robot assembles bit
    #: for bit as a new one of the same cables)
    detached_max = DETACHED_MAX

    def __init__(self, model: Model, ordered: bool = True, factor_threads: int | None = None):
        self.model = model
        self.stats = LinearStats()
        self.free = np.repeat(~model.fixed, 2)
        self.ordered = ordered
        self.factor_threads = factor_threads
        self.factor = None  # the last factorization, reused by chord steps and predictors
        self.factor_exact = False
        self._patterns: dict[bytes, _Pattern] = {}  # by triangles of the cables' points, oldest first
        self._build_structure()

    def _build_structure(self) -> None:
        m = self.model
        cab = m.cables
        self._tri = cab.points.tri.copy()
        self.seg_coef = _segment_coefficients(cab)
        self.sdofs = _segment_dofs(m)
        self.shape = (int(self.free.sum()),) * 2
        key = self._tri.tobytes() + cab.segments.tobytes()
        pattern = _recent(self._patterns, key, lambda: self._shared_pattern(key), PATTERNS_KEPT)
        self._use(pattern)

    def _use(self, pattern: _Pattern) -> None:
        """Assemble into ``pattern``, the current segments' own."""
        self.pattern = pattern
        self.order, self.scatter = pattern.order, pattern.scatter
        self.indices, self.indptr, self.nnz = pattern.indices, pattern.indptr, pattern.nnz
        self._pattern_sdofs = self.sdofs
        self.detached = np.zeros(0, dtype=np.int64)

    def _shared_pattern(self, key: bytes) -> _Pattern:
        """The pattern of the cable structure ``key`` as any solver of this mesh last
        made it (:data:`_SHARED_PATTERNS`), else made here; with no factors (each
        solver factorizes into its own)."""
        if self.model.single:  # the fiber lattice
            return self._pattern()
        shared = _SHARED_PATTERNS.setdefault(self.model.mesh, {})
        made = _recent(shared, (self.free.tobytes(), self.ordered, key), self._pattern, PATTERNS_SHARED)
        return replace(made, ldl=None, indefinite=None)

    def _pattern(self) -> _Pattern:
        """The pattern of the element and segment entries (``self.sdofs``)."""
        m = self.model
        nf = self.shape[0]
        free_index = np.cumsum(self.free) - 1
        rs, cs = np.repeat(self.sdofs, 12, axis=1).ravel(), np.tile(self.sdofs, (1, 12)).ravel()
        keep_s = self.free[rs] & self.free[cs]
        rs, cs = free_index[rs[keep_s]], free_index[cs[keep_s]]
        tendons = self.ordered and not m.single
        elements = self._element_pattern(free_index, nf, tendons)
        keep = np.concatenate([elements.keep, keep_s])
        if tendons:  # the elements' ordering (the segments add local couplings)
            order = elements.order
            uniq, pos = _merged(elements, order[cs].astype(np.int64) * nf + order[rs])
        else:
            r, c = np.concatenate([elements.rows, rs]), np.concatenate([elements.cols, cs])
            if not self.ordered:  # the free DOFs' own numbering (for preconditioners that need no ordering)
                order = np.arange(nf)
            else:  # the fiber lattice: its own ordering
                order = _fill_reducing_order(r, c, nf)
            uniq, pos = np.unique(order[c].astype(np.int64) * nf + order[r], return_inverse=True)
        indices = (uniq % nf).astype(np.int32)
        indptr = np.searchsorted(uniq // nf, np.arange(nf + 1)).astype(np.int32)
        scatter = np.full(len(keep), len(uniq), dtype=np.int32)
        scatter[keep] = pos
        return _Pattern(order, scatter, indices, indptr, len(uniq), reorder=not (self.ordered and m.single))

    @property
    def ldl(self) -> LDL | None:
        """The LDL^T of the current pattern (made with its first factorization)."""
        return self.pattern.ldl

    def cables_moved(self) -> None:
        """The model's cables moved (:meth:`~tendon_taichi.physics.model.Model.move_cables`):
        new barycentric weights, and where a point moved to another triangle a new
        sparsity pattern (one of the last few again where it was one of theirs);
        the last factorization stays, a nearby state's for chord steps
        (:attr:`chord_across_moves`)."""
        if np.array_equal(self.model.cables.points.tri, self._tri):
            self.seg_coef = _segment_coefficients(self.model.cables)
        elif not self._reattach():
            self._build_structure()
        if not self.chord_across_moves:
            self.reset()

    def _reattach(self) -> bool:
        """Keep the current pattern after the cables' points moved to other
        triangles (the same segments, at most :data:`DETACHED_MAX` of them with
        entries the pattern lacks): each segment whose entries it holds assembles
        into it; the others are :attr:`detached`. A detached segment's block
        ``k u u^T`` (``u = ua + ub``, its parts on the start point's triangle and
        the end point's) is ``2k (ua ua^T + ub ub^T) - k (ua - ub)(ua - ub)^T``: the
        first part within one triangle each (entries every pattern holds, added twice
        - what the sparse part gets is the Hessian plus a positive semidefinite
        term, positive definite where the Hessian is), the second a column of the
        low-rank part. False (nothing changed) where more segments would be
        detached, or the pattern is the current segments' own (one of the last
        few, which :meth:`_build_structure` takes)."""
        m, cab = self.model, self.model.cables
        if m.single or not self.ordered or len(self._pattern_sdofs) != len(cab.segments):
            return False
        tri = cab.points.tri
        if (tri.tobytes() + cab.segments.tobytes()) in self._patterns:
            return False
        sdofs = _segment_dofs(m)
        moved = np.flatnonzero(np.any(sdofs != self._pattern_sdofs, axis=1))
        nf = self.shape[0]
        free_index = np.cumsum(self.free) - 1
        d = sdofs[moved]
        rs, cs = np.repeat(d, 12, axis=1), np.tile(d, (1, 12))  # (k, 144) each
        kept = self.free[rs] & self.free[cs]
        keys = self.order[free_index[cs]].astype(np.int64) * nf + self.order[free_index[rs]]
        at = np.minimum(np.searchsorted(self.pattern.keys, keys), self.nnz - 1)
        held = (self.pattern.keys[at] == keys) | ~kept
        loose = ~held.all(axis=1)
        if loose.sum() > self.detached_max:
            return False
        same = _SAME_HALF[None, :] | ~loose[:, None]  # what each moved segment assembles into the pattern
        scatter = self.pattern.scatter.copy()
        base = len(scatter) - 144 * len(sdofs)
        idx = base + 144 * moved[:, None] + np.arange(144)
        scatter[idx] = np.where(kept & same, at, self.nnz)
        twice = kept & same & loose[:, None]
        self._twice = (idx[twice], at[twice])
        self._tri = tri.copy()
        self.sdofs, self.seg_coef, self.scatter = sdofs, _segment_coefficients(cab), scatter
        self.detached = moved[loose]
        return True

    def _element_pattern(self, free_index: np.ndarray, nf: int, tendons: bool) -> _ElementPattern:
        """The elements' part of the pattern (``free_index``: each DOF's index among
        the free ones; ``tendons``: with the elements' fill-reducing ordering),
        computed once per mesh and clamp set."""
        cache = _ELEMENT_PATTERN.setdefault(self.model.mesh, {})
        key = (self.free.tobytes(), tendons)
        if key not in cache:
            T = self.model.mesh.triangles
            edofs = (2 * T[:, :, None] + np.arange(2)).reshape(-1, 6)  # (m, 6)
            re, ce = np.repeat(edofs, 6, axis=1).ravel(), np.tile(edofs, (1, 6)).ravel()
            keep = self.free[re] & self.free[ce]
            r, c = free_index[re[keep]], free_index[ce[keep]]
            order, keys, pos = None, None, None
            if tendons:
                order = _fill_reducing_order(r, c, nf)
                keys, pos = np.unique(order[c].astype(np.int64) * nf + order[r], return_inverse=True)
            cache[key] = _ElementPattern(keep, r, c, order, keys, pos=pos)
        return cache[key]

    def _low_rank(self) -> tuple[np.ndarray, np.ndarray]:
        """The taut many-segment cables' axial terms: U (nf, r) in the ordered
        numbering, its columns their dL/dx, and K (r,) their kc; then the detached
        segments' columns (:meth:`_detached_blocks`)."""
        m = self.model
        nf = self.shape[0]
        if m.single or m.C == 0:
            return np.zeros((nf, 0)), np.zeros(0)
        seg_n, seg_w, kc = m.read_many([("SEG_N", 2 * m.S), ("SEG_WT", m.S), ("KC", m.C)])
        # dL/dx of the (capstan-weighted) length, per segment
        grad = (self.seg_coef[:, :, None] * (seg_n.reshape(-1, 2) * seg_w[:, None])[:, None, :]).reshape(-1, 12)
        taut = np.flatnonzero(kc > 0.0)
        full = np.zeros((2 * m.n, len(taut)))
        st = m.cables.start
        for j, c in enumerate(taut):  # np.bincount adds in order, as np.add.at would
            full[:, j] = np.bincount(self.sdofs[st[c]:st[c + 1]].ravel(), grad[st[c]:st[c + 1]].ravel(),
                                     minlength=2 * m.n)
        K = kc[taut]
        if len(self.detached):
            block, k = self._detached_blocks(seg_n.reshape(-1, 2), seg_w)
            full, K = np.column_stack([full, block]), np.concatenate([K, k])
        U = np.empty((nf, len(K)))
        U[self.order] = full[self.free]
        return U, K

    def _detached_blocks(self, seg_n: np.ndarray, seg_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The detached segments' low-rank terms ``-k v v^T`` (:meth:`_reattach`),
        ``v = ua - ub``, from the segment block ``tau w / l (I - n n^T) = k p p^T``
        (p the unit normal) over its two points' nodes
        (:func:`~tendon_taichi.physics.forces.k_hessian_entries`): v (2n, d) and
        ``-k`` (d,); slack and zero-length segments left out."""
        m = self.model
        seg_l, tau = m.read_many([("SEG_L", m.S), ("TAU", m.C)])
        s = self.detached
        cable = np.searchsorted(m.cables.start, s, side="right") - 1
        length = seg_l[s]
        k = tau[cable] * seg_w[s] / np.where(length > 0.0, length, 1.0) * (length > 0.0)
        s, k = s[k > 0.0], k[k > 0.0]
        p = perp(seg_n[s])
        coef = self.seg_coef[s] * np.repeat([1.0, -1.0], 3)  # ua - ub: the end point's part negated
        v = (coef[:, :, None] * p[:, None, :]).reshape(-1, 12)
        full = np.zeros((2 * m.n, len(s)))
        for j in range(len(s)):
            full[:, j] = np.bincount(self.sdofs[s[j]], v[j], minlength=2 * m.n)
        return full, -k

    def assemble_ordered(self, project: bool = False, prepare: bool = True) -> Assembled:
        """``P H P^T``: the Hessian on the free DOFs in the fill-reducing order."""
        m = self.model
        if prepare:
            m.prepare_hessian(project, jacobi=False)
        # the entries on fixed DOFs add into one more bin, dropped: a kept entry's sums
        # are those of the kept entries alone, in the same order
        data = m.hessian_sums(self.scatter, self.nnz + 1)[:self.nnz]
        if len(self.detached):  # their blocks' parts within one triangle, once more (:meth:`_reattach`)
            data += np.bincount(self._twice[1], weights=m.hessian_entries()[self._twice[0]], minlength=self.nnz)
        U, K = self._low_rank()
        return Assembled(sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape), U, K)

    def assemble(self, project: bool = False, prepare: bool = True) -> sp.csc_matrix:
        """The Hessian of E_tot at x on the free DOFs (exact or projected), CSC."""
        H = self.assemble_ordered(project, prepare)
        full = H.Hp
        if len(H.K):
            full = full + sp.csc_matrix(H.U @ (H.K[:, None] * H.U.T))
        return full[self.order][:, self.order].tocsc()

    def factorize(self, H: Assembled) -> Factorization:
        """Factorize an ordered Hessian (:meth:`assemble_ordered`)."""
        pattern = self.pattern
        if pattern.ldl is None:
            pattern.ldl = cholesky_class()(self.indptr, self.indices, self.shape[0], pattern.reorder,
                                           threads=self.factor_threads)
        return Factorization(H, self.order, pattern.ldl, partial(_indefinite, pattern))

    def _factor_solve(self, H: Assembled, b: np.ndarray) -> np.ndarray:
        lu = self.factorize(H)
        y = lu.solve(b)
        res = b - self._ordered_product(H, y)
        if np.linalg.norm(res) > 1e-10 * np.linalg.norm(b):  # one step of iterative refinement
            y += lu.solve(res)
        if not np.all(np.isfinite(y)):
            raise np.linalg.LinAlgError("non-finite solution")
        self.stats.solves += 1
        self.factor = lu
        return y

    @probe("check")
    def _ordered_product(self, H: Assembled, y: np.ndarray) -> np.ndarray:
        """H y from the ordered matrix, in the free-DOF numbering."""
        yp = np.empty_like(y)
        yp[self.order] = y
        return H.product(yp)[self.order]

    def approx_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """Solve with the last factorization (the Hessian it was made from), full (n, 2);
        None before the first."""
        if self.factor is None:
            return None
        out = np.zeros(2 * self.model.n)
        out[self.free] = self.factor.solve(np.asarray(rhs, dtype=float).ravel()[self.free])
        return out.reshape(-1, 2)

    def chord_solve(self, rhs: np.ndarray) -> np.ndarray | None:
        """A chord step's solve with the last factorization, where it is of an exact Hessian."""
        if not self.factor_exact:
            return None
        out = self.approx_solve(rhs)
        if out is not None:
            self.stats.reused += 1
        return out

    def reset(self) -> None:
        """Forget the last factorization."""
        self.factor = None

    def checkpoint(self) -> tuple:
        """The last factorization and whether it is of the exact Hessian."""
        return self.factor, self.factor_exact

    def resume(self, state: tuple) -> None:
        self.factor, self.factor_exact = state

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

    def resolve(self, rhs: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """One triangular solve with the last factorization (that of the last solve)."""
        return self.approx_solve(rhs)

    def solve_many(self, rhs: Iterable[np.ndarray], tol: float) -> Iterator[np.ndarray]:
        """The first right-hand side factorizes the Hessian; the others reuse that
        factorization (one triangular solve each)."""
        for j, b in enumerate(rhs):
            yield self.solve(b, tol=tol) if j == 0 else self.resolve(b)


@contextmanager
def detached_at_most(n: int) -> Iterator[None]:
    """Within, every direct solver's :attr:`~DirectSolver.detached_max` is ``n`` (0: patterns made anew)."""
    before, DirectSolver.detached_max = DirectSolver.detached_max, n
    try:
        yield
    finally:
        DirectSolver.detached_max = before


def _recent(cache: dict, key, make, keep: int):
    """``cache[key]`` (``make()`` where it is absent), now the most recent entry of
    ``cache``, which keeps its last ``keep`` entries (insertion order: oldest first)."""
    value = cache.pop(key, None) or make()
    cache[key] = value
    while len(cache) > keep:
        cache.pop(next(iter(cache)))
    return value


def _merged(elements: _ElementPattern, seg_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What ``np.unique(concatenate([element keys, seg_keys]), return_inverse=True)``
    gives - the distinct sorted keys and each entry's index among them - without
    sorting the elements' keys again: the segments' new keys are inserted."""
    seg_uniq = np.unique(seg_keys)
    at = np.searchsorted(elements.keys, seg_uniq)
    known = (at < len(elements.keys)) & (elements.keys[np.minimum(at, len(elements.keys) - 1)] == seg_uniq)
    new = seg_uniq[~known]
    keys = np.insert(elements.keys, at[~known], new)
    shift = np.searchsorted(new, elements.keys)  # new keys below each element key
    pos = np.concatenate([elements.pos + shift[elements.pos], np.searchsorted(keys, seg_keys)])
    return keys, pos


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


def _segment_dofs(m: Model) -> np.ndarray:
    """(S, 12): each segment's DOFs, those of its start point's triangle then its end point's."""
    cab = m.cables
    pt_nodes = m.mesh.triangles[cab.points.tri] if m.P else np.zeros((0, 3), np.int64)
    seg_nodes = np.concatenate([pt_nodes[cab.segments[:, 0]], pt_nodes[cab.segments[:, 1]]], 1)
    return (2 * seg_nodes[:, :, None] + np.arange(2)).reshape(-1, 12)


def _segment_coefficients(cab) -> np.ndarray:
    """(S, 6): each segment's signed barycentric weights, -start point then +end point."""
    return np.concatenate([-cab.points.bary[cab.segments[:, 0]], cab.points.bary[cab.segments[:, 1]]], 1)
