"""Intel MKL PARDISO's sparse Cholesky factorization, the direct backend's
factorization where it is installed (optional: the ``mkl`` extra;
:func:`available` says whether it loaded).

PARDISO factorizes a symmetric positive definite matrix (``mtype`` 2) by a
supernodal Cholesky: dense BLAS-3 blocks where qdldl's up-looking LDL^T works
entry by entry. Its analysis (the symbolic factorization) runs once per
sparsity pattern; each factorization after that computes only the numbers.

Indefinite matrices. Far from equilibrium (a route optimization's trial step,
a compressed body) the Hessian's sparse part may have negative eigenvalues:
the Cholesky stops at a pivot <= 0. Such a matrix is factorized by PARDISO's
symmetric indefinite LDL^T (``mtype`` -2, Bunch-Kaufman 1x1 and 2x2 pivots
within its supernodes, ``indefinite``), which counts the negative eigenvalues
(:attr:`PardisoLDL.negative`). Where even those pivots leave one too small
(``iparm[9]``: below 1e-8 of the matrix) it would perturb that pivot and solve
a slightly different matrix; it refuses instead, and the direct backend takes
SuperLU, which pivots across the whole matrix. On the 33 route optimizations of
``design t_shape --level 3`` (``python benchmarks/route_replay.py t_shape 3``,
at fe418fd) the 148 factorizations that were not positive definite took 7.52 ms
each this way (the failed Cholesky and the analysis once per pattern included),
9.84 ms with SuperLU.

The ordering. A fiber lattice's matrix comes in the direct backend's
fill-reducing order of its whole pattern (minimum degree, computed once per
model), and PARDISO keeps it (an identity ``perm``, ``iparm[4] = 1``): it then
factorizes as fast as in its own minimum degree order and faster than in its
METIS order, and its analysis is the cheapest. On t_shape's lattice (one
thread) one factorization takes 0.65 / 1.6 / 4.3 / 12 / 33 ms against qdldl's
1.2 / 3.8 / 12.5 / 40 / 122 ms at 1394 / 2716 / 5336 / 10504 / 20812 DOFs
(levels 2-6), on finger's 0.38 / 1.05 ms against 0.72 / 2.4 ms at 880 / 1702
DOFs (levels 2, 3): PARDISO's by benchmarks/pardiso_modes.py (plain, one
thread), qdldl's by ``benchmarks/warm_parts.py --qdldl`` (factor / factors).
A tendon robot's pattern comes in the elements' order alone (shared by every
tendon layout of a mesh), which does not see the couplings the segments add
along each route: in it the factors of a level-2 finger's robots held several
times the entries and took longer still, so those patterns are ordered by
PARDISO's own minimum degree (``reorder``), as qdldl orders every pattern by its
AMD. So the direct backend takes PARDISO at every size where it loads. Without
the extra the numbers are qdldl's: the same designs up to round-off, which the
search can turn into another layout here and there.

Threads. From :data:`PARALLEL_MIN` DOFs a factorization runs on the threads its
job gives (``threads``, from the job's
:class:`~tendon_taichi.solve.linear.LinearSettings`: one in ``design`` where its
worker processes hold the other cores, and in what it hands them), else on the
process's (:func:`~tendon_taichi.physics.runtime.factor_threads`: its cores where
it has them to itself - ``optimize``, ``simulate``, ``bench`` -, one in every
worker): at level 5 about 1.7x faster on two (benchmarks/pardiso_modes.py). Its
numbers do not depend on the threads: there PARDISO runs in its conditional
numerical reproducibility mode (:data:`CNR`), in
which the factors of t_shape's lattices at levels 4, 5 and 6 and of its tendon
patterns in PARDISO's own order solve to the same bits on one, two and three
threads, and whatever the mode's number - one right-hand side at a time: several
at once do not (:meth:`PardisoLDL.solve`). Without it they did on an AMD EPYC
(MKL's AVX2 code), but not on an Intel Xeon (its AVX-512 code): a level-3
lattice's solutions differed by about 1e-15 between one thread and two, so that
``optimize`` (the process's threads) and ``design`` (one) would not have made
the same run. The mode costs the factorization nothing measurable (level 5, two
threads: 7.3-8.1 ms, against 7.5 without), but it takes each solve off PARDISO's
sequential substitution onto its parallel one, a BLAS call per supernode: one
solve of t_shape's lattice at levels 2 / 3 / 5 takes 127 / 248 / 1354 us in
the mode against 51 / 111 / 824 us without, on one thread
(``python benchmarks/pardiso_modes.py``), and ``design t_shape --level 2``
spent much of its time in them. Below
:data:`PARALLEL_MIN` a factorization runs on one thread whatever the process,
the same bits without the mode, so it is on only from there
(:attr:`PardisoLDL.reproducible`). With MKL's Intel OpenMP layer (its GNU
layer gives other bits, even on one thread); ``tests/test_equilibrium.py``
checks it. A PARDISO handle runs every phase on the threads of its analysis (on
others it crashes).
"""

from __future__ import annotations

import ctypes
import glob
import os
import re
import sys
from ctypes.util import find_library

import numpy as np

from ..physics import runtime
from ..probes import probe
from ._csc import triangle

_lib: dict = {}

#: MKL's names of its threading layers
MKL_THREADING_INTEL, MKL_THREADING_SEQUENTIAL = 0, 1

#: the least order of a matrix that is factorized on several threads. From there
#: a whole optimization is faster (t_shape on 2 cores: level 4 43.5 s against
#: 48.5, level 5 about 15 % less; ``tendon-taichi optimize t_shape --level 4``
#: against the same with ``TENDON_TAICHI_FACTOR_THREADS=1``); at level 3 (2716 DOFs)
#: a factorization is faster too (0.96 against 1.55 ms) but the optimization is not
#: (the second thread's waits cost the kernels around it), at level 2 not even the
#: factorization (0.62 against 0.57 ms; the factorizations: benchmarks/pardiso_modes.py)
PARALLEL_MIN = 4000

#: ``iparm[33]`` from :data:`PARALLEL_MIN` DOFs: PARDISO's conditional numerical reproducibility
#: mode (CNR) on, the same bits on any number of threads (module docstring); any value above 0
#: gave the same bits and speed. Below, 0: one thread, and solves 2.2-2.5x faster (levels 2-3,
#: benchmarks/pardiso_modes.py)
CNR = 1


def _load():
    """The ``pardiso`` function of libmkl_rt, or None where MKL is not installed."""
    if "pardiso" in _lib:
        return _lib["pardiso"]
    fn = None
    names = [os.environ.get("TENDON_TAICHI_MKL_RT"), find_library("mkl_rt")]
    names += sorted(glob.glob(os.path.join(sys.prefix, "lib", "libmkl_rt.so*")), key=len)
    for name in filter(None, names):
        try:
            lib = ctypes.CDLL(name)
            lib.MKL_Set_Threading_Layer.argtypes = [ctypes.c_int]
            layer = _threading_layer(name)
            lib.MKL_Set_Threading_Layer(layer)
            lib.MKL_Set_Num_Threads_Local.argtypes = [ctypes.c_int]
            fn = lib.pardiso
        except (OSError, AttributeError):  # not there, or not an MKL runtime we know
            continue
        fn.restype = None
        _lib.update(set_threads=lib.MKL_Set_Num_Threads_Local, threaded=layer == MKL_THREADING_INTEL, mkl=lib)
        break
    _lib["pardiso"] = fn
    return fn


@probe("pardiso")
def available() -> bool:
    """Whether MKL PARDISO loaded (the ``mkl`` extra is installed)."""
    return _load() is not None


class _Version(ctypes.Structure):
    """MKL's ``MKLVersion``."""

    _fields_ = [("major", ctypes.c_int), ("minor", ctypes.c_int), ("update", ctypes.c_int), ("patch", ctypes.c_int),
                ("status", ctypes.c_char_p), ("build", ctypes.c_char_p), ("processor", ctypes.c_char_p),
                ("platform", ctypes.c_char_p)]


def describe() -> dict | None:
    """The MKL that loaded, as it reports itself: ``version`` (its release, e.g.
    "2026.2"), ``build`` (a date) and ``code_path`` (the instruction set it runs
    on here, e.g. "AVX-512"); None where it did not load. A factorization's
    round-off, and so a design's, depends on all three."""
    if _load() is None:
        return None
    lib = _lib["mkl"]
    text = ctypes.create_string_buffer(512)
    v = _Version()
    try:
        lib.MKL_Get_Version_String(text, len(text))
        lib.MKL_Get_Version(ctypes.byref(v))
    except AttributeError:  # an MKL runtime without them
        return {"version": None, "build": None, "code_path": None}
    words = text.value.decode(errors="replace")
    release = re.search(r"Version (\S+?)(?:-Product|\s|$)", words)
    processor = (v.processor or b"").decode(errors="replace")
    isa = re.search(r"\(Intel\(R\) ([A-Z][\w.-]*)\)", processor)
    return {"version": release.group(1) if release else words or None, "build": (v.build or b"").decode() or None,
            "code_path": isa.group(1) if isa else processor or None}


def threaded() -> bool:
    """Whether PARDISO can run on several threads (it loaded, with MKL's Intel
    OpenMP layer); else every factorization runs on one, whatever is asked."""
    return _load() is not None and _lib["threaded"]


def _threading_layer(mkl_rt: str) -> int:
    """MKL's threading layer: Intel OpenMP where its runtime loads (beside MKL's, as
    the ``mkl`` wheel installs it), else sequential (one thread, whatever is asked).
    The layer is chosen before MKL's first call; where it cannot load its runtime
    then, MKL ends the process."""
    if not os.environ.get("KMP_BLOCKTIME"):
        # an idle thread spins 1 ms, then sleeps: OpenMP's 200 ms holds a core the work
        # between factorizations needs, 0 wakes it too often (35-36 s against 40.6 and
        # 40.5: ``tendon-taichi optimize t_shape --level 5 --stage-iterations 60``
        # with KMP_BLOCKTIME 1, 200 and 0)
        os.environ["KMP_BLOCKTIME"] = "1"
    for name in (os.path.join(os.path.dirname(os.path.realpath(mkl_rt)), "libiomp5.so"), "libiomp5.so"):
        try:
            ctypes.CDLL(name)
            return MKL_THREADING_INTEL
        except OSError:
            continue
    return MKL_THREADING_SEQUENTIAL


def factor_threads(n: int, threads: int | None = None) -> int:
    """Threads a factorization of order ``n`` runs on: ``threads``, or where None the
    process's (:func:`~tendon_taichi.physics.runtime.factor_threads`), from
    :data:`PARALLEL_MIN` DOFs, else one."""
    if n < PARALLEL_MIN:
        return 1
    return runtime.factor_threads() if threads is None else threads


class PardisoLDL:
    """Cholesky factorizations by PARDISO of symmetric matrices of one sparsity
    pattern (CSC ``indptr``, ``indices``, n x n, both triangles): the analysis
    with the first, only the numbers after - the interface of the direct
    backend's qdldl :class:`~tendon_taichi.solve.cholesky.LDL`. The pattern is
    factorized in its own order, or with ``reorder`` in PARDISO's minimum degree
    order of it (module docstring), in the reproducible mode or not
    (``reproducible``, default: from :data:`PARALLEL_MIN` DOFs); with
    ``indefinite`` by the symmetric indefinite LDL^T instead of Cholesky (module
    docstring), on ``threads`` (:func:`factor_threads`: None, the process's). One
    factorization is current at a time (``generation`` counts them)."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, n: int, reorder: bool = False,
                 reproducible: bool | None = None, indefinite: bool = False, threads: int | None = None):
        self._pattern = (indptr, indices, n)
        # the lower triangle by columns is the upper triangle by rows, as PARDISO takes it
        self.lower, ja, self.ia = triangle(indptr, indices, n, lower=True)
        self.ja = np.ascontiguousarray(ja, dtype=np.int32)
        self.n = n
        self.reorder = reorder
        self.asked_threads = threads
        self.threads = factor_threads(n, threads)
        #: whether it runs in the reproducible mode (:data:`CNR`); by default from
        #: :data:`PARALLEL_MIN` DOFs, where a factorization may run on several threads
        self.reproducible = n >= PARALLEL_MIN if reproducible is None else bool(reproducible)
        self.generation = 0
        self._pt = np.zeros(64, dtype=np.int64)
        self._iparm = np.zeros(64, dtype=np.int32)
        # own settings, pivot eps, 0-based indices; the ordering: PARDISO's minimum
        # degree (iparm[1] = 0) or the pattern's own (an identity perm given, iparm[4] = 1)
        self._iparm[[0, 9, 34]] = (1, 13, 1)
        self._iparm[4] = 0 if reorder else 1
        self._iparm[17] = -1  # report the factor's entries (:attr:`entries`)
        self._iparm[33] = CNR if self.reproducible else 0
        #: the symmetric indefinite LDL^T (``mtype`` -2) instead of Cholesky
        self.indefinite = bool(indefinite)
        if self.indefinite:
            self._iparm[9] = 8  # a pivot below 1e-8 |A| would be perturbed: the factorization is refused
            self._iparm[20] = 1  # 1x1 and 2x2 Bunch-Kaufman pivots
        self._perm = np.arange(n, dtype=np.int32)
        self._data = np.zeros(len(self.ja))
        self._analyzed = False  # phase 11 done (and its memory to release)
        self._args = None  # the call's fixed arguments (:meth:`_fixed_args`)

    def blank(self) -> "PardisoLDL":
        """A handle of the same pattern and settings, neither analyzed nor factorized."""
        return PardisoLDL(*self._pattern, reorder=self.reorder, reproducible=self.reproducible,
                          indefinite=self.indefinite, threads=self.asked_threads)

    def _fixed_args(self) -> tuple:
        """The call's arguments that stay the same from call to call, made once (a
        small system otherwise spends as long converting them as PARDISO spends
        solving): those before ``phase`` (pt, maxfct, mnum, mtype), those between
        it and ``b`` (n, a, ia, ja, perm, nrhs, iparm, msglvl) and the stand-in
        for an absent ``b`` or ``x``."""
        if self._args is None:
            ptr, one = ctypes.c_void_p, ctypes.byref(ctypes.c_int32(1))
            mtype = ctypes.byref(ctypes.c_int32(-2 if self.indefinite else 2))
            self._args = ((ptr(self._pt.ctypes.data), one, one, mtype),
                          (ctypes.byref(ctypes.c_int32(self.n)), ptr(self._data.ctypes.data),
                           ptr(self.ia.ctypes.data), ptr(self.ja.ctypes.data), ptr(self._perm.ctypes.data), one,
                           ptr(self._iparm.ctypes.data), ctypes.byref(ctypes.c_int32(0))),
                          ctypes.byref(ctypes.c_double(0.0)))
        return self._args

    def _call(self, phase: int, b: np.ndarray | None = None) -> tuple[int, np.ndarray | None]:
        """One PARDISO phase; ``b`` (n,) or (n, r) in Fortran order: r right-hand sides at once."""
        before, between, absent = self._fixed_args()
        if b is not None and b.ndim == 2:
            between = between[:5] + (ctypes.byref(ctypes.c_int32(b.shape[1])),) + between[6:]
        pardiso = _load()
        # every phase on the analysis's threads (on others PARDISO crashes), set for the
        # calling thread: that wins over the process's MKL threads, which threadpoolctl caps
        _lib["set_threads"](self.threads)
        x = None if b is None else np.empty_like(b, order="F")
        err = ctypes.c_int32(0)
        pardiso(*before, ctypes.byref(ctypes.c_int32(phase)), *between,
                absent if b is None else ctypes.c_void_p(b.ctypes.data),
                absent if x is None else ctypes.c_void_p(x.ctypes.data), ctypes.byref(err))
        return err.value, x

    @property
    def entries(self) -> int:
        """The entries of the Cholesky factor as PARDISO counts them (its supernodes
        padded), from the first factorization on (0 before)."""
        return int(self._iparm[17]) if self._analyzed else 0

    @property
    def negative(self) -> int:
        """The negative eigenvalues of the last matrix factorized (its inertia), as the
        indefinite factorization counts them; 0 for a Cholesky that succeeded."""
        return int(self._iparm[22]) if self.indefinite else 0

    @property
    def threads_used(self) -> int:
        """The threads PARDISO ran its last phase on, as it reports them."""
        return int(self._iparm[2])

    @probe("factor")
    def factor(self, data: np.ndarray) -> bool:
        """Factorize the matrix of entries ``data`` (in the pattern's order); whether
        it is positive definite (PARDISO's Cholesky met no pivot <= 0: its error -4)
        - with ``indefinite``: whether no pivot was perturbed -, else the factors are
        not to be used (and the direct backend takes the next factorization, as it
        does where PARDISO fails otherwise, e.g. out of memory)."""
        np.take(data, self.lower, out=self._data, mode="clip")  # positions in range: no bounds check
        if not self._analyzed:
            if self._call(11)[0]:
                return False
            self._analyzed = True
        err, _ = self._call(22)
        self.generation += 1
        return err == 0 and not (self.indefinite and self._iparm[13] > 0)

    @probe("solves")
    def solve(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b with the current factorization, b (n,), or (n, r): r columns in one
        call, or in the reproducible mode one call per column - there PARDISO's
        solve of several columns at once gives other bits on one thread and on two
        (about 2e-15 relative for 2 or 3 columns at t_shape's level 4), one
        column's the same."""
        if np.ndim(b) == 2 and self.reproducible:
            x = np.empty(np.shape(b), order="F")
            for j in range(x.shape[1]):
                x[:, j] = self.solve(b[:, j])
            return x
        b = np.asfortranarray(b, dtype=np.float64) if np.ndim(b) == 2 else np.ascontiguousarray(b, dtype=np.float64)
        err, x = self._call(33, b)
        if err:
            raise np.linalg.LinAlgError(f"PARDISO solve failed (error {err})")
        return x

    def __getstate__(self) -> dict:
        """A copy (pickled) has no PARDISO handle: it analyzes again with its first
        factorization, and a factorization holding it factorizes a copy first."""
        state = dict(self.__dict__)
        state.update(_pt=np.zeros(64, dtype=np.int64), _analyzed=False, generation=-1, _args=None)
        return state

    def __setstate__(self, state: dict) -> None:
        """A copy analyzes on the threads it was made with, or where it was given none
        on those of the process it is in."""
        self.__dict__.update(state)
        self.threads = factor_threads(self.n, self.asked_threads)

    def __del__(self):
        try:
            if self._analyzed and _lib.get("pardiso") is not None:
                self._call(-1)  # release PARDISO's memory
        except Exception:  # noqa: BLE001 - at interpreter shutdown the module's names may be gone
            pass
