"""The one place where Taichi is initialised.

Importing this module neither imports Taichi nor calls ``ti.init``: the
command line configures the runtime before it knows whether a command needs
Taichi. ``ti`` (the ``taichi`` module, for the kernel modules) is imported on
first use; :func:`init` starts Taichi, once per process, with f64 defaults.
:func:`ensure_init` initialises lazily with the settings chosen by
:func:`configure`, the environment variables ``TENDON_TAICHI_ARCH`` (``cpu``
default, ``cuda``, ``vulkan``, ``gpu``...) and ``TENDON_TAICHI_THREADS``, or
the defaults.
"""

from __future__ import annotations

import atexit
import contextlib
import io
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

from ..errors import InputError

os.environ.setdefault("ENABLE_TAICHI_HEADER_PRINT", "0")  # before taichi is imported

ARCHES = ("cpu", "cuda", "vulkan", "metal", "opengl", "gpu")

#: Models with at least this many elements + cable segments run their loops
#: in parallel; smaller ones run them serialized, because a parallel loop
#: costs a fixed ~0.1 ms to dispatch on the CPU backend (benchmarks/kernel_launch.py).
DEFAULT_PARALLEL_THRESHOLD = 20000

#: ... where Taichi's loops have at least this many threads (:func:`cpu_threads`); with
#: fewer, every model runs them serialized. On 2 cores parallel loops were slower at every
#: size measured (``tendon-taichi bench``, with ``TENDON_TAICHI_PARALLEL_THRESHOLD=0`` and
#: without): t_shape at level 6 (36k elements + segments: a direct gradient
#: 0.085 s serialized against 0.109 s, a cg equilibrium from rest 0.64 s against 0.97 s), as
#: fast at level 7 (73k) and level 8 (146k; a warm direct equilibrium 0.80-0.84 s against
#: 0.84-0.85 s). With more threads they were not measured: the threshold above stays there
PARALLEL_MIN_THREADS = 3

#: BLAS threads (numpy, scipy): our vectors are short (<= ~1e5) and threaded
#: OpenBLAS made a level-5 warm CG solve 3.5x slower (72 vs 250 ms, ``tendon-taichi bench``
#: with ``TENDON_TAICHI_BLAS_THREADS`` 1 and 2)
DEFAULT_BLAS_THREADS = 1

_settings = {
    "arch": None,
    "threads": None,
    "parallel_threshold": None,
    "factor_threads": None,
}
_state = {"initialized": False, "arch": None, "init_s": None}


def configure(arch: str | None = None, threads: int | None = None,
              parallel_threshold: int | None = None, factor_threads: int | None = None) -> None:
    """Choose the backend before Taichi starts, and the threads of this process's
    sparse factorizations where a job does not give its own (:func:`factor_threads`;
    a worker process: one). Unset values keep defaults."""
    if arch is not None:
        if arch not in ARCHES:
            raise InputError(f"unknown Taichi arch '{arch}' (choose from {', '.join(ARCHES)})")
        if _state["initialized"] and arch != _state["arch"]:
            raise InputError(f"Taichi already runs on '{_state['arch']}'; cannot switch to '{arch}'")
        _settings["arch"] = arch
    if threads is not None:
        _settings["threads"] = _checked_threads(threads, "threads")
    if parallel_threshold is not None:
        _settings["parallel_threshold"] = int(parallel_threshold)
    if factor_threads is not None:
        _settings["factor_threads"] = _checked_threads(factor_threads, "factor threads")


def _requested_arch() -> str:
    arch = _settings["arch"] or os.environ.get("TENDON_TAICHI_ARCH", "cpu")
    if arch not in ARCHES:
        raise InputError(f"unknown Taichi arch '{arch}' (choose from {', '.join(ARCHES)})")
    return arch


def _env_int(name: str) -> int | None:
    """The integer in the environment variable ``name`` (None where it is unset or
    empty); InputError where it is not an integer."""
    env = os.environ.get(name)
    if not env:
        return None
    try:
        return int(env)
    except ValueError:
        raise InputError(f"{name} must be an integer (got '{env}')") from None


#: the most CPU threads allowed per core: far more only starves the machine (100000 hung it)
MAX_THREADS_PER_CORE = 4


def _checked_threads(n: int, name: str) -> int:
    """``n`` CPU threads, or InputError naming ``name`` when not 1 .. MAX_THREADS_PER_CORE x cores."""
    most = MAX_THREADS_PER_CORE * cores()
    if not 1 <= n <= most:
        raise InputError(f"{name} must be 1..{most} ({MAX_THREADS_PER_CORE} per core of this machine's "
                         f"{cores()}; got {n})")
    return n


def _requested_threads() -> int | None:
    if _settings["threads"] is not None:
        return _settings["threads"]
    n = _env_int("TENDON_TAICHI_THREADS")
    return None if n is None else _checked_threads(max(1, n), "TENDON_TAICHI_THREADS")


def __getattr__(name: str):
    if name == "ti":  # PEP 562: ``from .runtime import ti`` imports Taichi here, not before
        import taichi
        return taichi
    raise AttributeError(f"module '{__name__}' has no attribute '{name}'")


def init() -> str:
    """Start Taichi (f64, CPU by default) once; return the arch it runs on."""
    import taichi as ti

    if _state["initialized"]:
        return _state["arch"]
    arch = _requested_arch()
    kwargs = dict(arch=getattr(ti, arch), default_fp=ti.f64, default_ip=ti.i32,
                  log_level=ti.WARN, random_seed=0, **_kernel_cache(ti))
    threads = _requested_threads()
    if threads is not None:
        kwargs["cpu_max_num_threads"] = threads
    t0 = time.perf_counter()
    _plain_source_positions()
    # ti.init prints "[Taichi] Starting on arch=..." on stdout; keep stdout for results.
    with contextlib.redirect_stdout(io.StringIO()):
        ti.init(**kwargs)
    actual = str(ti.lang.impl.current_cfg().arch).split(".")[-1]
    actual = "cpu" if actual in ("x64", "arm64") else actual
    if arch not in ("cpu", "gpu") and actual != arch:
        print(f"tendon-taichi: warning: Taichi arch '{arch}' is not available, running on '{actual}'",
              file=sys.stderr)
    _state.update(initialized=True, arch=actual, init_s=time.perf_counter() - t0)
    _limit_blas()
    return actual


def _plain_source_positions() -> None:
    """Taichi's compiler describes the source position of every syntax node it
    visits, word-wrapping the line and a caret under it for an error message that
    is almost never shown: about 0.6 s of every process's kernel compilation
    (``py-spy record -- tendon-taichi design t_shape --level 2``), whether or not the kernels come from the
    cache. Describe it by file, line and that line's text alone; the compiled
    kernels are the same."""
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext

    def plain(ctx, node) -> str:
        line = ctx.src[node.lineno - 1] if 0 < node.lineno <= len(ctx.src) else ""
        return (f'File "{ctx.file}", line {node.lineno + ctx.lineno_offset}, in {ctx.func.func.__name__}:\n'
                f"{line}\n")

    ASTTransformerContext.get_pos_info = plain


#: s after which Taichi's kernel-cache lock file is stale: Taichi holds it while it reads or writes
#: the cache (well under a second) and removes it after; a process killed meanwhile leaves it, and
#: then every later process fails to take it (three warnings), skips the cache and compiles every
#: kernel again, in every process, each worker included
STALE_LOCK_S = 60.0


def _clear_stale_lock(path: Path) -> None:
    """Remove the kernel cache ``path``'s lock file when it is older than
    :data:`STALE_LOCK_S` (and still the same file)."""
    lock = path / "ticache.lock"
    try:
        st = lock.stat()
        if time.time() - st.st_mtime > STALE_LOCK_S:
            again = lock.stat()
            if (again.st_ino, again.st_mtime_ns) == (st.st_ino, st.st_mtime_ns):
                lock.unlink()
    except OSError:
        pass


def _kernel_cache(ti) -> dict:
    """Taichi's compiled-kernel cache settings: its usual folder when it can be
    written (a stale lock in it removed, :func:`_clear_stale_lock`); otherwise (a
    home folder that is not the user's, a read-only one), where Taichi would abort
    the process, a temporary folder removed at exit, and a warning."""
    path = Path(os.environ.get("TI_OFFLINE_CACHE_FILE_PATH") or ti.lang.impl.default_cfg().offline_cache_file_path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
        _clear_stale_lock(path)
        if all(os.access(f, os.R_OK | os.W_OK) for f in path.glob("ticache.*")):
            return {"offline_cache": True}
    except OSError:
        pass
    tmp = tempfile.mkdtemp(prefix="tendon-taichi-kernels-")
    atexit.register(shutil.rmtree, tmp, True)
    print(f"tendon-taichi: warning: Taichi's kernel cache '{path}' cannot be written: kernels are compiled "
          f"again in every run (set TI_OFFLINE_CACHE_FILE_PATH to a writable folder)", file=sys.stderr)
    return {"offline_cache": True, "offline_cache_file_path": tmp}


def _limit_blas() -> None:
    """Cap the BLAS thread pools (``TENDON_TAICHI_BLAS_THREADS``, default 1)."""
    import scipy.linalg  # noqa: F401 - scipy's own BLAS loaded now, so that the cap reaches it too
    from threadpoolctl import threadpool_limits

    n = _env_int("TENDON_TAICHI_BLAS_THREADS")
    n = DEFAULT_BLAS_THREADS if n is None else max(1, n)
    threadpool_limits(limits=n, user_api="blas")
    _state["blas_threads"] = n


def ensure_init() -> str:
    """Initialise Taichi if nobody has yet; return the arch."""
    return init()


def is_cpu() -> bool:
    return ensure_init() == "cpu"


def host_view(arr) -> "np.ndarray | None":
    """A numpy array that *is* the memory of the 1-D Taichi ndarray ``arr`` (no
    copy), where that memory is the host's (the CPU backend), else None. Reads
    and writes through it cost no kernel launch; CPU launches are synchronous,
    so it always shows what the last kernel wrote. Valid while ``arr`` lives."""
    import ctypes

    import numpy as np

    if not is_cpu():
        return None
    import taichi as ti

    dtype = {ti.f64: np.float64, ti.i32: np.int32}[arr.dtype]
    n = int(arr.shape[0])
    address = ti.lang.impl.get_runtime().prog.get_ndarray_data_ptr_as_int(arr.arr)
    if n == 0:
        return np.zeros(0, dtype=dtype)
    if not address:  # no host memory to show: the copy kernels it is
        return None
    raw = (ctypes.c_byte * (n * np.dtype(dtype).itemsize)).from_address(address)
    return np.frombuffer(raw, dtype=dtype)


def cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def cpu_threads() -> int:
    """Threads a process's parallel CPU work may use: ``--threads`` (or
    ``TENDON_TAICHI_THREADS``) where given, else :func:`cores`."""
    requested = _requested_threads()
    return cores() if requested is None else requested


def factor_threads() -> int:
    """Threads a sparse factorization may use (:mod:`~tendon_taichi.solve.pardiso`)
    where the job that makes it gives none
    (:class:`~tendon_taichi.solve.linear.LinearSettings`): the ones
    :func:`configure` set (a worker process: one), else
    ``TENDON_TAICHI_FACTOR_THREADS`` where given, else :func:`cpu_threads`.
    A process that shares its cores with others passes one: threads that wait
    for a core another process holds make a factorization many times slower."""
    if _settings["factor_threads"] is not None:
        return _settings["factor_threads"]
    n = _env_int("TENDON_TAICHI_FACTOR_THREADS")
    return cpu_threads() if n is None else max(1, n)


@contextlib.contextmanager
def cores_shared(shared: bool = True):
    """Within, where ``shared``: :func:`factor_threads` is one. For scripts that
    replay a piece of a job whose processes shared the cores
    (``benchmarks/route_replay.py``); the package passes its thread counts."""
    before = _settings["factor_threads"]
    if shared:
        _settings["factor_threads"] = 1
    try:
        yield
    finally:
        _settings["factor_threads"] = before


def parallel_threshold() -> int | None:
    """The least elements + cable segments of a model that runs its CPU loops in
    parallel: the one set (:func:`configure`, ``TENDON_TAICHI_PARALLEL_THRESHOLD``),
    else :data:`DEFAULT_PARALLEL_THRESHOLD` with :data:`PARALLEL_MIN_THREADS` threads
    or more, else None (every model serialized)."""
    if _settings["parallel_threshold"] is not None:
        return _settings["parallel_threshold"]
    n = _env_int("TENDON_TAICHI_PARALLEL_THRESHOLD")
    if n is not None:
        return n
    return DEFAULT_PARALLEL_THRESHOLD if cpu_threads() >= PARALLEL_MIN_THREADS else None


def check() -> None:
    """Refuse a bad setting (an environment variable above) with one clear error,
    before any work."""
    _requested_arch()
    factor_threads()
    cpu_threads()
    parallel_threshold()
    _env_int("TENDON_TAICHI_BLAS_THREADS")


def info() -> dict:
    """What the runtime runs on (for summaries and the benchmark)."""
    import taichi as ti

    return {
        "arch": _state["arch"] if _state["initialized"] else _requested_arch(),
        "threads": _requested_threads(),
        "parallel_threshold": parallel_threshold(),
        "taichi": ti.__version__ if hasattr(ti, "__version__") else None,
        "init_s": _state["init_s"],
        "blas_threads": _state.get("blas_threads"),
        "factor_threads": factor_threads(),
    }


__all__ = ["ti", "configure", "init", "ensure_init", "is_cpu", "host_view", "cores", "cpu_threads", "factor_threads",
           "cores_shared", "parallel_threshold", "check", "info"]
