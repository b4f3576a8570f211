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
argument: which process ran an item does not change what it gives. ``fn``
and the items are pickled in the calling thread as the map starts, not by
the executor's own thread while this process computes with the same objects.

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
from concurrent.futures import Future, ProcessPoolExecutor
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


def _start(setup: Callable[..., Any] | None, args: tuple) -> None:
    """A worker's start: Ctrl-C is for the process that runs the job (it stops the
    workers), the worker ends with that process (:func:`_end_with_parent`), then
    ``setup``, during which SIGTERM (:meth:`Pool.close`, :func:`_end_with_parent`)
    raises ``SystemExit`` so that ``setup`` cleans up; a set-up that fails or is
    stopped ends the worker quietly (the pool breaks, and the job goes on in its
    own process)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _end_with_parent()
    try:
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


class Pool:
    """``workers`` worker processes, each running ``setup(*setup_args)`` first
    (module docstring); a context manager that stops them on leaving."""

    def __init__(self, workers: int, setup: Callable[..., Any] | None = None, setup_args: tuple = ()):
        if workers < 0:
            raise ValueError(f"workers must be >= 0 (got {workers})")
        self.workers = workers
        self.broken: str | None = None
        self._executor: ProcessPoolExecutor | None = None
        if workers:
            self._executor = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=_start, initargs=(setup, setup_args))
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
        if self._executor is None or len(items) < 2:
            return [fn(item) for item in items]
        # pickled here, now: the executor pickles what it is handed in a thread of its own,
        # which would race this one's computing with the same objects (a cached property
        # filled in meanwhile: "dictionary changed size during iteration")
        fn_pickled = pickle.dumps(fn, protocol=pickle.HIGHEST_PROTOCOL)
        pickled = [pickle.dumps(item, protocol=pickle.HIGHEST_PROTOCOL) for item in items]
        lock = threading.Lock()
        taken = [0]
        futures: dict[int, Future] = {}

        def take() -> int | None:
            i = taken[0]
            if i == len(items):
                return None
            taken[0] += 1
            return i

        def feed(_done: Future | None = None) -> None:  # a worker is free: hand it the next item
            with lock:
                executor = self._executor
                i = take() if executor is not None else None
                if i is None:
                    return
                try:
                    futures[i] = executor.submit(_run, fn_pickled, pickled[i])
                except (BrokenProcessPool, RuntimeError):  # broken or closed meanwhile: this process runs it
                    futures[i] = Future()
                    futures[i].set_exception(BrokenProcessPool("the pool stopped"))
                    return
            futures[i].add_done_callback(feed)

        out: list[Any] = [None] * len(items)
        for _ in range(self.workers):
            feed()
        while True:
            with lock:
                i = take()
            if i is None:
                break
            out[i] = fn(items[i])
        for i, future in futures.items():
            out[i] = self._result(future, fn, items[i])
        return out

    def _result(self, future: Future, fn, item):
        try:
            return future.result()
        except BrokenProcessPool as exc:
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
        self._executor.shutdown(wait=False, cancel_futures=True)
        self._executor = None
        if terminate:
            for p in processes:
                p.terminate()
            for p in processes:  # one still setting up cleans up first (_start)
                p.join(CLEAN_UP_S)

    def __enter__(self) -> "Pool":
        return self

    def __exit__(self, kind, value, tb) -> None:
        self.close(terminate=kind is not None)
