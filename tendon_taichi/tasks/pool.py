"""A few worker processes that share the independent pieces of one job with
the process that runs it (``design`` shares its extractors' consolidations and
its front's solves and route optimizations, which are independent of each
other and take most of its time).

:class:`Pool` starts ``workers`` processes (``spawn``: a fresh interpreter, no
copy of a running Taichi) that each run ``setup`` once, at once - they warm up
while the job goes on. :meth:`Pool.map` then runs ``fn(item)`` for every item:
each worker is handed the next item as soon as it finishes one, and this
process takes the next one itself whenever it is free, so ``workers = cores -
1`` keeps every core busy.
The results come back in the items' order and are those of
``[fn(item) for item in items]`` whenever ``fn`` depends only on its
argument: which process ran an item does not change what it gives (each
worker's BLAS thread pools are sized as this process's were when the pool
started: a product summed by another number of threads can differ in its last
bits). ``fn``
and the items are pickled in the calling thread as the map starts, not by
the executor's own thread while this process computes with the same objects.

:meth:`Pool.defer` queues a job whose result is wanted later (``design``: each
layout the front finishes, solved on the finer mesh): a worker that has no
item of a map to take runs the queued jobs meanwhile - between maps, while
this process computes alone, and at a map's end -, and :meth:`Pool.collect`
returns their results, the jobs no worker took shared between the workers and
this process like a map's items. A map's items go first: a worker takes a
queued job only when the running map has none left to hand out. The results
are those of the calls made here.

With ``workers = 0`` everything runs in this process. A worker that dies (its
process killed, out of memory) or a ``setup`` that fails (the worker then ends
quietly) breaks the pool: the items it had are run again here and the pool
runs everything here from then on (``broken`` says why). An exception ``fn``
raises in a worker is raised here, as it would be in-process. Workers ignore
Ctrl-C: the process that runs the job stops them. A worker whose job process
is gone (killed, so that it stopped nobody) ends at once. A worker stopped
while its ``setup`` runs (the job ended early: an error, Ctrl-C, a kill)
leaves ``setup`` by ``SystemExit``, so that what ``setup`` wrote in ``with``
blocks (``design``'s warm-up: a temporary folder) is cleaned up.

Spawned workers import the main module again: a script that makes a pool (or
calls ``design`` with workers) does so under ``if __name__ == "__main__":``.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.connection
import os
import pickle
import signal
import threading
import time
from collections import deque
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterable


def _run(fn_pickled: bytes, item_pickled: bytes) -> Any:
    """What a worker runs: ``fn(item)``, both pickled by the process that runs the job."""
    return pickle.loads(fn_pickled)(pickle.loads(item_pickled))


def _ready() -> bool:
    """What a worker answers once its ``setup`` has run."""
    return True


#: seconds a worker whose job process is gone gives its ``setup`` to clean up before it ends anyway
CLEAN_UP_S = 10.0


def blas_threads() -> int | None:
    """The size of this process's BLAS thread pools (the smallest; None where none
    is loaded)."""
    from threadpoolctl import threadpool_info

    sizes = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return min(sizes) if sizes else None


def _limit_blas(threads: int | None) -> None:
    """This worker's BLAS thread pools (numpy's and scipy's, loaded now) at the job
    process's size: a product summed by another number of threads can differ in its
    last bits, which an iterative solve can grow (a route's clearance fit did, by
    5e-13 m, before the worker's own Taichi set-up capped them)."""
    if threads is None:
        return
    import numpy  # noqa: F401 - their BLAS loaded now, so that the cap reaches it
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=threads, user_api="blas")


def _start(setup: Callable[..., Any] | None, args: tuple, blas: int | None = None) -> None:
    """A worker's start: Ctrl-C is for the process that runs the job (it stops the
    workers), the worker ends with that process (:func:`_end_with_parent`), its
    BLAS thread pools are sized as the job process's (``blas``), then ``setup``,
    during which SIGTERM (:meth:`Pool.close`, :func:`_end_with_parent`) raises
    ``SystemExit`` so that ``setup`` cleans up; a set-up that fails or is
    stopped ends the worker quietly (the pool breaks, and the job goes on in its
    own process)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _end_with_parent()
    try:
        _limit_blas(blas)
        signal.signal(signal.SIGTERM, _leave_setup)
        try:
            if setup is not None:
                setup(*args)
        finally:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a task stopped midway has nothing to clean up
    except BaseException:  # noqa: BLE001 - reported by the pool as broken, not as a traceback here
        os._exit(1)


def _leave_setup(signum: int, frame: Any) -> None:
    """SIGTERM during a worker's ``setup``: leave it by ``SystemExit``, through its
    ``with`` and ``finally`` blocks; a second SIGTERM (:func:`_end_with_parent`
    after :meth:`Pool.close`) would interrupt that clean-up, so it is ignored."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise SystemExit(1)


def _end_with_parent() -> None:
    """End this worker as soon as the process that started it is gone: one killed
    (SIGTERM from ``timeout`` or a batch scheduler, SIGKILL, out of memory) stops
    no workers, and a worker would otherwise compute its task to the end - many
    minutes of a front search - for no one. A daemon thread waits on the parent's
    sentinel, which becomes ready when the parent process ends, then sends this
    process SIGTERM (a ``setup`` still running cleans up, :func:`_start`) and ends
    it after :data:`CLEAN_UP_S` if that has not."""
    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def wait() -> None:
        multiprocessing.connection.wait([parent.sentinel])
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(CLEAN_UP_S)
        os._exit(1)

    threading.Thread(target=wait, name="end-with-parent", daemon=True).start()


class Deferred:
    """A job queued by :meth:`Pool.defer`: ``fn(item)``, both pickled as it was
    queued; ``future`` once a worker took it."""

    def __init__(self, fn: Callable[[Any], Any], item: Any, fn_pickled: bytes):
        self.fn, self.item = fn, item
        self.fn_pickled = fn_pickled
        self.item_pickled = pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL)
        self.future: Future | None = None


class _Items:
    """A running map's items as the workers are handed them: the next one not taken
    (:meth:`take`) and the futures of those handed out, by index."""

    def __init__(self, fn_pickled: bytes, pickled: list[bytes]):
        self.fn_pickled, self.pickled = fn_pickled, pickled
        self.taken = 0
        self.futures: dict[int, Future] = {}

    def take(self) -> int | None:
        if self.taken == len(self.pickled):
            return None
        self.taken += 1
        return self.taken - 1


class Pool:
    """``workers`` worker processes, each running ``setup(*setup_args)`` first
    (module docstring); a context manager that stops them on leaving."""

    def __init__(self, workers: int, setup: Callable[..., Any] | None = None, setup_args: tuple = ()):
        if workers < 0:
            raise ValueError(f"workers must be >= 0 (got {workers})")
        self.workers = workers
        self.broken: str | None = None
        self._executor: ProcessPoolExecutor | None = None
        # the hand-out (_hand_out) runs in this thread and in the executor's, as tasks end
        self._lock = threading.RLock()
        self._busy = 0  # tasks handed to the workers and not ended: at most one per worker
        self._items: _Items | None = None  # the running map's
        self._queued: deque[Deferred] = deque()  # deferred jobs no worker has taken
        self._pickled: tuple[Any, bytes] | None = None  # the last deferred function, pickled
        if workers:
            self._executor = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=_start, initargs=(setup, setup_args, blas_threads()))
            # one call per worker starts them all now (a spawning pool starts a process per call waiting)
            self._starting = [self._executor.submit(_ready) for _ in range(workers)]

    @property
    def active(self) -> int:
        """The worker processes in use (0 once the pool broke or was closed)."""
        return 0 if self._executor is None else self.workers

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
        """``[fn(item) for item in items]``, the items shared between the workers and
        this process (module docstring): each worker is handed the next item as it
        finishes one, and this process takes the next one whenever it is free."""
        items = list(items)
        if self._executor is None or len(items) < 2 or self._items is not None:
            return [fn(item) for item in items]
        # pickled here, now: the executor pickles what it is handed in a thread of its own,
        # which would race this one's computing with the same objects (a cached property
        # filled in meanwhile: "dictionary changed size during iteration")
        fn_pickled = pickle.dumps(fn, protocol=pickle.HIGHEST_PROTOCOL)
        run = _Items(fn_pickled, [pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL) for item in items])
        out: list[Any] = [None] * len(items)
        with self._lock:
            self._items = run
            self._hand_out()
        try:
            while True:
                with self._lock:
                    i = run.take()
                if i is None:
                    break
                out[i] = fn(items[i])
        finally:
            with self._lock:
                self._items = None  # every item is taken: a worker that ends its own takes a deferred job
                self._hand_out()
        for i, future in run.futures.items():
            out[i] = self._result(future, fn, items[i])
        return out

    def defer(self, fn: Callable[[Any], Any], item: Any) -> Deferred:
        """Queue ``fn(item)`` for a worker to run when it has no map item to take
        (module docstring); its result comes from :meth:`collect`. Both are pickled
        now (in this thread; ``fn`` once for a run of jobs with the same function).
        With no workers it is only queued, and :meth:`collect` runs it here."""
        with self._lock:
            if self._pickled is None or self._pickled[0] is not fn:
                self._pickled = (fn, pickle.dumps(fn, protocol=pickle.HIGHEST_PROTOCOL))
            job = Deferred(fn, item, self._pickled[1])
            self._queued.append(job)
            self._hand_out()
        return job

    def collect(self, jobs: list[Deferred]) -> list[Any]:
        """The results of deferred ``jobs``, in order: those no worker has taken are
        run now as a map (shared between the workers and this process), those a
        worker runs are waited for."""
        with self._lock:
            waiting = [job for job in jobs if job.future is None]
            for job in waiting:
                self._queued.remove(job)
        by_fn: dict[int, list[Deferred]] = {}
        for job in waiting:
            by_fn.setdefault(id(job.fn), []).append(job)
        done: dict[int, Any] = {}
        for group in by_fn.values():
            done.update(zip(map(id, group), self.map(group[0].fn, [job.item for job in group])))
        return [done[id(job)] if id(job) in done else self._result(job.future, job.fn, job.item) for job in jobs]

    def _hand_out(self) -> None:
        """Hand each free worker the running map's next item, else the next deferred
        job (under the lock)."""
        while self._executor is not None and self._busy < self.workers:
            run, i = self._items, None
            if run is not None:
                i = run.take()
            if i is not None:
                fn_pickled, item_pickled, job = run.fn_pickled, run.pickled[i], None
            elif self._queued:
                job = self._queued.popleft()
                fn_pickled, item_pickled = job.fn_pickled, job.item_pickled
            else:
                return
            try:
                future = self._executor.submit(_run, fn_pickled, item_pickled)
                handed = True
            except (BrokenProcessPool, RuntimeError):  # broken or closed meanwhile: this process runs it
                future, handed = Future(), False
                future.set_exception(BrokenProcessPool("the pool stopped"))
            if job is None:
                run.futures[i] = future
            else:
                job.future, job.item_pickled = future, b""  # handed out: its bytes are no longer needed
            if not handed:
                return
            self._busy += 1
            future.add_done_callback(self._ended)  # at once if it has ended already

    def _ended(self, _future: Future) -> None:
        """A task handed out ended: its worker is free for the next (executor's thread)."""
        with self._lock:
            self._busy -= 1
            self._hand_out()

    def _result(self, future: Future, fn, item):
        try:
            return future.result()
        except (BrokenProcessPool, CancelledError) as exc:
            self._break(exc)
            return fn(item)

    def _break(self, exc: BaseException) -> None:
        self.broken = self.broken or f"a worker process stopped ({exc}); the rest runs in this process"
        self.close()

    def close(self, terminate: bool = False) -> None:
        """Stop the workers - idle ones at once, busy ones after their item, or
        at once with ``terminate`` (which waits for them to end) -; later maps
        run here."""
        if self._executor is None:
            return
        processes = list((getattr(self._executor, "_processes", None) or {}).values())
        manager = getattr(self._executor, "_executor_manager_thread", None)
        self._executor.shutdown(wait=False, cancel_futures=True)
        self._executor = None
        if terminate:
            for p in processes:
                p.terminate()
            for p in processes:  # one still setting up cleans up first (_start)
                p.join(CLEAN_UP_S)
            if manager is not None:  # its pipe closed before the interpreter's exit wakes it (Python 3.11
                manager.join(CLEAN_UP_S)  # otherwise races it: "Exception ignored ... Bad file descriptor")

    def __enter__(self) -> "Pool":
        return self

    def __exit__(self, kind, value, tb) -> None:
        """Leaving stops the workers at once (:meth:`close` with ``terminate``), the
        work done or not: every result asked for is in, and the job's process need not
        wait at its own exit for idle workers to shut down; one still setting up cleans
        up first."""
        self.close(terminate=True)
