"""Independent cases as tasks on Dask distributed (the engine of ``sweep``,
``planted-bench`` and the optimizations of ``bench``).

A :class:`Task` is one case: a stable ``id`` (a hash of its inputs, see
:func:`case_id`), a ``label`` for progress lines, and a module-level function
that returns a JSON-able dict (workers import it by name). :func:`run_tasks`
runs a list of them:

- on a ``LocalCluster`` started for the run (``workers`` processes, one
  thread each; default: one per core), closed at the end;
- on an existing cluster (``scheduler="tcp://HOST:PORT"``, started with
  ``dask scheduler`` / ``dask worker``), which is left running;
- or, with ``workers=0``, one after the other in this process (no Dask).

The engine knows nothing of what the tasks compute: the caller passes, in its
:class:`Cluster`, a ``setup`` function that every worker process runs once before its first task
(the application starts Taichi and compiles its kernels there, see
:func:`tendon_taichi.apps.case.start_worker`), the exception types that
``stop`` the whole run when a task raises them (Ctrl-C inside an in-process
case), and to :func:`run_tasks` a ``progress`` reporter (:class:`LineProgress` by default).
With a ``store`` folder, a finished case's result is kept in
``store/<id>/result.json`` and a later run reuses it (``reused``); a case that
raises is reported with its ``error`` and the others go on (it is not stored,
so the next run tries it again); a case whose worker dies is retried on
another worker by the scheduler (up to Dask's ``allowed-failures``); Ctrl-C
cancels what is left and returns what finished.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from distributed.diagnostics.plugin import WorkerPlugin

from ..errors import InputError
from ..files import write_json
from ..version import __version__

RESULT_FILE = "result.json"
#: seconds to wait for an existing scheduler to answer, and for its first worker
CONNECT_TIMEOUT_S = 10.0

#: per worker process: what its ``setup`` returned (filled by WorkerSetup.setup)
_startup: dict = {}


@dataclass(frozen=True)
class Task:
    """One independent case. ``fn(*args)`` runs on a worker and returns a JSON-able
    dict; ``id`` names its folder in the store; ``label`` appears in progress lines."""

    id: str
    label: str
    fn: Callable[..., dict]
    args: tuple = ()


@dataclass(frozen=True)
class Cluster:
    """Where and how :func:`run_tasks` runs its tasks: on a local Dask cluster of
    ``workers`` processes (None: one per core; 0: one after the other in this
    process), or on the existing one at ``scheduler`` (``tcp://HOST:PORT``); every
    worker process runs ``setup(threads)`` once before its first task, and a task
    that raises one of the ``stop`` exception types stops the whole run."""

    workers: int | None = None
    scheduler: str | None = None
    setup: Callable[[int | None], dict] | None = None
    stop: tuple[type[BaseException], ...] = ()


@dataclass
class Outcome:
    """What became of a task: its ``value`` or its ``error`` (with the worker's
    ``traceback``); ``reused`` when an earlier run's stored result was kept;
    ``time_s`` on the worker; ``worker`` (host:pid)."""

    task: Task
    value: dict | None = None
    error: str | None = None
    reused: bool = False
    time_s: float = 0.0
    worker: str = ""
    traceback: str | None = None


@dataclass
class Report:
    """All outcomes (in task order; tasks cut off by Ctrl-C are missing) and the engine's figures."""

    outcomes: list[Outcome]
    interrupted: bool = False
    engine: dict = field(default_factory=dict)


def case_id(inputs: dict) -> str:
    """A stable 16-hex-digit id of a case's inputs (JSON-able) and the package version."""
    blob = json.dumps({"version": __version__, **inputs}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


# ---------------------------------------------------------------- workers
def worker_startup() -> dict:
    """This worker's start-up figures: what its ``setup`` returned (for ``client.run``)."""
    return dict(_startup)


class WorkerSetup(WorkerPlugin):
    """A Dask worker plugin: each worker process runs ``setup(threads)`` once, on
    the worker's main thread, and keeps what it returns (:func:`worker_startup`)."""

    name = "tendon-taichi"

    def __init__(self, setup: Callable[[int | None], dict], threads: int | None = None):
        self.fn, self.threads = setup, threads

    def setup(self, worker) -> None:
        if not _startup:
            _startup.update(pid=os.getpid(), **self.fn(self.threads))


def execute(fn: Callable[..., dict], args: tuple, stop: tuple[type[BaseException], ...] = ()) -> dict:
    """Run one task body; never raises (a failure comes back as ``error``), except
    for the ``stop`` exceptions, which become KeyboardInterrupt (the run stops)."""
    t0 = time.perf_counter()
    out = {"worker": f"{os.uname().nodename}:{os.getpid()}"}
    try:
        out["value"] = fn(*args)
    except stop:
        raise KeyboardInterrupt from None
    except Exception as exc:  # noqa: BLE001 - a failed case is data, the sweep goes on
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        out["error"] = f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__
        out["traceback"] = traceback.format_exc(limit=8)
    out["time_s"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------- clients
def check_address(scheduler: str) -> None:
    """Raise InputError when ``scheduler`` is no Dask address (``tcp://host:port``,
    ``host:port``...): found before any work, and before a client that could not
    start prints its own traceback when collected."""
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port

    try:
        protocol, location = parse_address(scheduler)
        if protocol != "inproc":
            parse_host_port(location)
    except ValueError as exc:
        raise InputError(f"--scheduler '{scheduler}' is not a Dask scheduler address (like "
                         f"tcp://host:8786): {exc}") from None


@contextlib.contextmanager
def connect(workers: int | None, scheduler: str | None, progress: Callable[[str], None],
            setup: Callable[[int | None], dict] | None = None):
    """A Dask client: on an existing cluster (``scheduler``), else on a new
    ``LocalCluster`` of ``workers`` processes (default: one per core), whose
    workers run ``setup`` once. Yields ``(client, info)``; closes what it started."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        if workers is not None:
            raise InputError("--workers sizes the local cluster; with --scheduler the cluster's own workers run")
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError (bad address)
            raise InputError(f"cannot reach the Dask scheduler at '{scheduler}': "
                             f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except Exception:  # noqa: BLE001
            client.close()
            raise InputError(f"the Dask scheduler at '{scheduler}' has no worker") from None
        n = len(client.scheduler_info()["workers"])
        progress(f"Dask scheduler {scheduler}: {n} worker(s), dashboard {client.dashboard_link}")
        try:
            if setup is not None:
                client.register_plugin(WorkerSetup(setup, None))
            yield client, {"kind": "scheduler", "address": scheduler, "workers": n}
        finally:
            client.close()
        return
    n = (os.cpu_count() or 1) if workers is None else workers
    if n < 1:
        raise InputError(f"--workers must be >= 0 (got {n})")
    threads = max(1, (os.cpu_count() or 1) // n)
    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.CRITICAL)
    client = Client(cluster, set_as_default=False)
    try:
        progress(f"local Dask cluster: {n} worker process(es), dashboard {client.dashboard_link}")
        if setup is not None:
            client.register_plugin(WorkerSetup(setup, threads))
        yield client, {"kind": "local", "address": cluster.scheduler_address, "workers": n,
                       "cluster_start_s": time.perf_counter() - t0}
    finally:
        with contextlib.suppress(Exception):
            client.close()
        with contextlib.suppress(Exception):
            cluster.close()


# ---------------------------------------------------------------- running
def _stored(store: Path | None, task: Task) -> dict | None:
    if store is None:
        return None
    path = store / task.id / RESULT_FILE
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _keep(store: Path | None, outcome: Outcome) -> None:
    if store is not None and outcome.error is None:
        write_json({**outcome.value, "time_s_worker": outcome.time_s}, store / outcome.task.id / RESULT_FILE)


def _outcome(task: Task, res: dict) -> Outcome:
    return Outcome(task, res.get("value"), res.get("error"), reused=False, time_s=res.get("time_s", 0.0),
                   worker=res.get("worker", ""), traceback=res.get("traceback"))


class LineProgress:
    """A progress reporter (what :func:`run_tasks` reports to): ``message`` for the
    engine's own lines, ``start`` with the number of cases, ``advance`` once per
    finished case with its line. This one prints every line (to stderr, or to
    ``emit``); :class:`tendon_taichi.io.progress.Progress` draws bars on a terminal."""

    def __init__(self, emit: Callable[[str], None] | None = None):
        self.emit = emit or (lambda msg: print(msg, file=sys.stderr, flush=True))

    def message(self, text: str) -> None:
        self.emit(text)

    def start(self, total: int) -> None:
        pass

    def advance(self, text: str) -> None:
        self.emit(text)


class _CaseLines:
    """``[done/total] label: text (failures, elapsed, time left)``, one per outcome."""

    def __init__(self, total: int, fresh: int, describe):
        self.total, self.fresh, self.describe = total, fresh, describe
        self.done = self.ran = self.failed = 0
        self.t0 = time.perf_counter()

    def __call__(self, o: Outcome) -> str:
        self.done += 1
        self.ran += not o.reused
        self.failed += o.error is not None
        el = time.perf_counter() - self.t0
        left = el / self.ran * (self.fresh - self.ran) if self.ran else 0.0
        what = ("reused" if o.reused else
                f"failed: {o.error}" if o.error else self.describe(o.value) if self.describe else "done")
        return (f"[{self.done}/{self.total}] {o.task.label}: {what} ({o.time_s:.1f} s; {self.failed} failed; "
                f"elapsed {el:.0f} s, about {left:.0f} s left)")


def run_tasks(tasks: list[Task], store: str | Path | None = None, cluster: Cluster = Cluster(), progress=None,
              on_outcome: Callable[[Outcome], None] | None = None,
              describe: Callable[[dict], str] | None = None) -> Report:
    """Run ``tasks`` (see the module docstring) where ``cluster`` says, keeping
    their results in ``store``; ``on_outcome`` sees each outcome as it arrives
    (write partial outputs there); ``describe(value)`` words a finished case's line;
    ``progress``: a reporter like :class:`LineProgress` (the default), or a function
    that prints one line. Returns every outcome in task order."""
    workers, scheduler, setup, stop = cluster.workers, cluster.scheduler, cluster.setup, cluster.stop
    if progress is None or not hasattr(progress, "advance"):
        progress = LineProgress(progress)
    if len({t.id for t in tasks}) != len(tasks):
        raise InputError("two cases have the same inputs (the same scene, level and settings)")
    store = Path(store) if store is not None else None
    t0 = time.perf_counter()
    done: dict[str, Outcome] = {}
    kept, fresh = [], []
    for t in tasks:
        value = _stored(store, t)
        if value is None:
            fresh.append(t)
        else:
            kept.append(Outcome(t, value, reused=True, time_s=value.pop("time_s_worker", 0.0)))
    line = _CaseLines(len(tasks), len(fresh), describe)
    progress.start(len(tasks))

    def finish(o: Outcome, keep: bool = True) -> None:
        done[o.task.id] = o
        if keep:
            _keep(store, o)
        progress.advance(line(o))
        if on_outcome:
            on_outcome(o)

    engine: dict = {"kind": "none", "workers": 0}
    interrupted = False
    try:
        with contextlib.ExitStack() as stack:
            client = None
            if fresh and (workers != 0 or scheduler is not None):
                client, where = stack.enter_context(connect(workers, scheduler, progress.message, setup))
                engine.update(where)
            for o in kept:  # only once the cluster answered: bad input writes nothing
                finish(o, keep=False)
            if client is not None:
                _run_on_client(client, fresh, finish, engine, stop)
            elif fresh:
                engine.update(kind="in-process", workers=1)
                for t in fresh:
                    finish(_outcome(t, execute(t.fn, t.args, stop)))
    except KeyboardInterrupt:
        interrupted = True
    engine.update(wall_s=time.perf_counter() - t0, cases=len(tasks), reused=len(kept))
    return Report([done[t.id] for t in tasks if t.id in done], interrupted, engine)


def _run_on_client(client, tasks: list[Task], finish, info: dict, stop: tuple) -> None:
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    t_sub = time.perf_counter()
    futures = [client.submit(execute, t.fn, t.args, stop, key=f"tendon-taichi-{t.id}-{os.urandom(4).hex()}",
                             pure=False) for t in tasks]
    task_of = {f.key: t for f, t in zip(futures, tasks)}
    try:
        for fut in as_completed(futures, loop=client.loop):
            try:
                res = fut.result()
            except KilledWorker:
                res = {"error": "KilledWorker: the workers running this case kept dying "
                                "(Dask gave up after its allowed retries)"}
            except Exception as exc:  # noqa: BLE001 - cancelled, lost, unpicklable
                res = {"error": f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"}
            finish(_outcome(task_of[fut.key], res))
    except KeyboardInterrupt:
        with contextlib.suppress(Exception):
            client.cancel(futures, force=True)
        raise
    info["tasks_s"] = time.perf_counter() - t_sub
    with contextlib.suppress(Exception):
        info["worker_startup"] = list(client.run(worker_startup).values())
