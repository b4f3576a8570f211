"""A few worker processes that share the independent pieces of one job with
the process that runs it (``design`` uses it for the front's route
optimizations, which are independent of each other and take most of its time).

:class:`Pool` starts ``workers`` processes (``spawn``: a fresh interpreter, no
copy of a running Taichi) that each run ``setup`` once, at once - they warm up
while the job goes on. :meth:`Pool.map` then runs ``fn(item)`` for every item:
each worker is handed one item at a time and this process takes the next
item itself while they work, so ``workers = cores - 1`` keeps every core busy.
The results come back in the items' order and are those of
``[fn(item) for item in items]`` whenever ``fn`` depends only on its
argument: which process ran an item does not change what it gives.

With ``workers = 0`` everything runs in this process. A worker that dies (its
process killed, out of memory) or a ``setup`` that fails (the worker then ends
quietly) breaks the pool: the items it had are run again here and the pool
runs everything here from then on (``broken`` says why). An exception ``fn``
raises in a worker is raised here, as it would be in-process. Workers ignore
Ctrl-C: the process that runs the job stops them.

Spawned workers import the main module again: a script that makes a pool (or
calls ``design`` with workers) does so under ``if __name__ == "__main__":``.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Iterable


def _ready() -> bool:
    """What a worker answers once its ``setup`` has run."""
    return True


def _start(setup: Callable[..., Any] | None, args: tuple) -> None:
    """A worker's start: Ctrl-C is for the process that runs the job (it stops the
    workers), then ``setup``; a set-up that fails ends the worker quietly (the
    pool breaks, and the job goes on in its own process)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        if setup is not None:
            setup(*args)
    except BaseException:  # noqa: BLE001 - reported by the pool as broken, not as a traceback here
        os._exit(1)


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
        this process (module docstring)."""
        items = list(items)
        if self._executor is None or len(items) < 2:
            return [fn(item) for item in items]
        out: list[Any] = [None] * len(items)
        running: dict[Future, int] = {}
        nxt = 0
        while nxt < len(items) or running:
            while self._executor is not None and len(running) < self.workers and nxt < len(items):
                running[self._submit(fn, items[nxt])] = nxt
                nxt += 1
            if nxt < len(items):  # this process's share: the next item, while the workers have theirs
                out[nxt] = fn(items[nxt])
                nxt += 1
            else:
                wait(list(running), return_when=FIRST_COMPLETED)
            for future in [f for f in running if f.done()]:
                i = running.pop(future)
                out[i] = self._result(future, fn, items[i])
        return out

    def _submit(self, fn, item) -> Future:
        try:
            return self._executor.submit(fn, item)
        except BrokenProcessPool as exc:  # broken since the last call: a future that runs it here
            self._break(exc)
            done: Future = Future()
            done.set_result(fn(item))
            return done

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
        at once with ``terminate`` -; later maps run here."""
        if self._executor is None:
            return
        processes = list((getattr(self._executor, "_processes", None) or {}).values())
        self._executor.shutdown(wait=False, cancel_futures=True)
        self._executor = None
        if terminate:
            for p in processes:
                p.terminate()

    def __enter__(self) -> "Pool":
        return self

    def __exit__(self, kind, value, tb) -> None:
        self.close(terminate=kind is not None)
