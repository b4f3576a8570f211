"""The multigrid preconditioners of the matrix-free CG backend: one V-cycle of
a hierarchy of the Hessian at a reference state, in place of a factorization
of it - algebraic (``cg-amg``: smoothed aggregation, pyamg) or geometric
(``cg-gmg``: the body's own coarser meshes).

Building a hierarchy and applying a V-cycle cost time about linear in the DOFs
(no fill but the coarsest level's), which a factorization does not promise (in
3D its fill grows much faster than the DOFs). Both are built from the assembled
sparse part of the Hessian - elements and cable segments - in the free DOFs'
own numbering; the algebraic one is told the rigid motions of the body at its
current positions as the near-null space. A taut tendon's axial term ``kc g g^T`` (a dense rank-one
block, :mod:`.direct`) is left to CG: a rank-r change of the operator costs CG
at most r extra iterations, so the preconditioner need not see it.

The geometric hierarchy is the body meshed at every other coarser level
(:meth:`~tendon_taichi.body.problem.Problem.coarser_meshes`, about a quarter of
the nodes each). A coarse mesh is not nested in the finer one, but it covers
the same region: the prolongation ``P`` interpolates a coarse displacement
linearly (each finer node's barycentric weights in the coarse triangle that
holds it at rest), and the coarse operator is Galerkin's ``P^T A P``, so that
everything the finer Hessian holds - the fibers and tendons included - is
carried down. Building it costs two sparse products per level.

Like the factorization both are reused across nearby states: a solve that takes
more than ``refresh_iterations`` marks one stale and the next solve rebuilds it
at the state of the moment."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..body.mesh import Mesh
from ..physics.model import Model
from .preconditioner import ReusedPreconditioner


def rigid_modes(x: np.ndarray) -> np.ndarray:
    """The rigid motions of points ``x`` (k, 2), as (2k, 3) columns in the
    interleaved numbering (x0, y0, x1, y1, ...): two translations and the
    rotation about the origin, (-y, x)."""
    B = np.zeros((2 * len(x), 3))
    B[0::2, 0] = 1.0
    B[1::2, 1] = 1.0
    B[0::2, 2] = -x[:, 1]
    B[1::2, 2] = x[:, 0]
    return B


class MultigridPreconditioner(ReusedPreconditioner):
    """M^-1 = one V-cycle (symmetric Gauss-Seidel smoothing, a direct solve on
    the coarsest level) of a smoothed-aggregation AMG hierarchy of the Hessian's
    sparse part at a reference state; the same state gives the same hierarchy,
    bit for bit (replays rely on it).

    ``refresh_iterations``: a solve that takes more iterations than this marks
    the hierarchy stale. A fresh hierarchy preconditions a tight (1e-8) solve on
    t_shape to 26-64 iterations at levels 1-6, so the limit is higher than a
    factorization's."""

    def __init__(self, model: Model, refresh_iterations: int = 80):
        super().__init__(model, refresh_iterations, ordered=False)
        self.levels = 0

    def build(self, project: bool):
        import pyamg  # half a second to import: only where this backend runs

        m = self.direct.model
        A = self.direct.assemble_ordered(project=project).Hp.tocsr()
        B = rigid_modes(m.positions()[~m.fixed])
        # "local" weighting scales the prolongation smoother by row sums; the default
        # estimates a spectral radius from a random start, which would make replays differ
        ml = pyamg.smoothed_aggregation_solver(A, B=B, symmetry="hermitian",
                                               strength=("symmetric", {"theta": 0.0}),
                                               smooth=("jacobi", {"omega": 4.0 / 3.0, "weighting": "local"}))
        self.levels = len(ml.levels)
        return ml.aspreconditioner(cycle="V")

    def apply(self, operator, r: np.ndarray) -> np.ndarray:
        return operator @ r


#: barycentric weights below this are round-off of a node on a coarse edge or vertex
TINY_WEIGHT = 1e-12


def prolongation(points: np.ndarray, coarse: Mesh) -> tuple[sp.csr_matrix, np.ndarray]:
    """Linear interpolation from the nodes of the ``coarse`` mesh to ``points`` (q, 2)
    (rest positions, inside the region it covers): ``P`` (2q, 2k) in the interleaved
    numbering (x0, y0, x1, y1, ...), and ``kept`` (k,), the coarse nodes whose
    columns those are - those that carry weight at some point (the others only
    reach points left out, such as clamped nodes)."""
    emb, _ = coarse.locate(points)
    w = np.where(emb.bary < TINY_WEIGHT, 0.0, emb.bary)
    w /= w.sum(axis=1, keepdims=True)
    rows = np.repeat(np.arange(len(points)), 3)
    P = sp.csr_matrix((w.ravel(), (rows, coarse.triangles[emb.tri].ravel())), shape=(len(points), coarse.n_nodes))
    P.eliminate_zeros()
    kept = np.unique(P.indices)  # the columns with a nonzero
    return sp.kron(P[:, kept], sp.identity(2), format="csr"), kept


def prolongations(points: np.ndarray, meshes: list[Mesh]) -> list[sp.csr_matrix]:
    """The prolongations from each of ``meshes`` (finest first) to the level above,
    the first to ``points`` (q, 2) (the free nodes at rest)."""
    out = []
    for mesh in meshes:
        P, kept = prolongation(points, mesh)
        out.append(P)
        points = mesh.nodes[kept]
    return out


class GeometricMultigridPreconditioner(ReusedPreconditioner):
    """M^-1 = one V-cycle (Gauss-Seidel smoothing, :class:`VCycle`, a direct solve on
    the coarsest mesh) over the body's coarser meshes, each level's operator
    ``P^T A P`` from the Hessian's sparse part at a reference state (module
    docstring). The prolongations depend on the rest meshes alone and are made
    once; the same state gives the same hierarchy, bit for bit. A model not made
    from a problem (no coarser meshes) and a level-1 or level-2 body have none
    below their own: the V-cycle is then the direct solve.

    ``refresh_iterations``: a solve that takes more iterations than this marks
    the hierarchy stale. A fresh one preconditions the solves of t_shape's Newton
    steps to 4-40 iterations at levels 4 and 6, and rebuilding it costs about ten
    of them: of 20, 30, 45 and 80 (the algebraic one's), 30 gave the fastest warm
    equilibria at level 6, and cold ones about as fast as 20."""

    def __init__(self, model: Model, refresh_iterations: int = 30):
        super().__init__(model, refresh_iterations, ordered=False)
        self.levels = 0
        #: the V-cycle's Gauss-Seidel sweeps (:data:`SWEEPS`)
        self.sweeps = SWEEPS
        self._prolongations: list[sp.csr_matrix] | None = None

    @property
    def transfers(self) -> list[sp.csr_matrix]:
        """The prolongations, finest first (made on first use)."""
        if self._prolongations is None:
            m = self.direct.model
            meshes = m.coarser_meshes() if m.coarser_meshes is not None else []
            self._prolongations = prolongations(m.mesh.nodes[~m.fixed], meshes)
        return self._prolongations

    def build(self, project: bool) -> "VCycle":
        A = self.direct.assemble_ordered(project=project).Hp.tocsr()
        operators, transfers = [A], []
        for P in self.transfers:
            R = P.T.tocsr()
            transfers.append((P, R))
            operators.append((R @ operators[-1] @ P).tocsr())
        self.levels = len(operators)
        return VCycle(operators, transfers, self.sweeps)

    def apply(self, operator, r: np.ndarray) -> np.ndarray:
        return operator @ r


#: the Gauss-Seidel sweeps of the V-cycle before and after the coarse correction: a
#: forward one and its adjoint, a backward one, keep M^-1 symmetric at half the cost of
#: a symmetric sweep on each side, for a few more iterations (``benchmarks/multigrid.py``)
SWEEPS = ("forward", "backward")


class VCycle:
    """``M^-1 r`` by one V-cycle: on each level but the coarsest, a Gauss-Seidel
    sweep from zero (``sweeps[0]``), the residual restricted by ``R = P^T``, the
    coarser level's correction prolonged by ``P``, another sweep (``sweeps[1]``);
    the coarsest level solved by its LU factorization. A forward sweep before and
    a backward one after (or symmetric sweeps on both sides) make ``M^-1``
    symmetric, as PCG needs; on one level it is that level's exact inverse.
    (pyamg's own cycle, as a preconditioner, also forms the residual before and
    after it: two more products with the finest operator per application.)

    ``operators``: each level's matrix (CSR), finest first; ``transfers``: the
    ``(P, R)`` between each level and the next. Raises
    :class:`numpy.linalg.LinAlgError` when the coarsest is singular."""

    def __init__(self, operators: list[sp.csr_matrix], transfers: list[tuple[sp.csr_matrix, sp.csr_matrix]],
                 sweeps: tuple[str, str] = SWEEPS):
        from pyamg.relaxation.relaxation import gauss_seidel  # half a second to import: only where it runs

        self._smooth, self.sweeps = gauss_seidel, sweeps
        self.operators, self.transfers = operators, transfers
        try:
            self.coarsest = spla.splu(operators[-1].tocsc())
        except RuntimeError as exc:  # "Factor is exactly singular"
            raise np.linalg.LinAlgError(str(exc)) from None

    def __matmul__(self, r: np.ndarray) -> np.ndarray:
        return self._cycle(0, np.asarray(r, dtype=float))

    def _cycle(self, level: int, b: np.ndarray) -> np.ndarray:
        if level == len(self.transfers):
            return self.coarsest.solve(b)
        A = self.operators[level]
        P, R = self.transfers[level]
        x = np.zeros_like(b)
        self._smooth(A, x, b, iterations=1, sweep=self.sweeps[0])
        x += P @ self._cycle(level + 1, R @ (b - A @ x))
        self._smooth(A, x, b, iterations=1, sweep=self.sweeps[1])
        return x
