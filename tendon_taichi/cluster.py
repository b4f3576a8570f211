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

Every worker process starts Taichi once (:class:`TaichiWorker`, a Dask worker
plugin) and compiles the kernels by a short warm-up run, so tasks reuse them.
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
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from distributed.diagnostics.plugin import WorkerPlugin

from . import __version__
from .errors import InputError

RESULT_FILE = "result.json"
#: seconds to wait for an existing scheduler to answer, and for its first worker
CONNECT_TIMEOUT_S = 10.0

#: per worker process: Taichi start-up and warm-up times (filled by TaichiWorker.setup)
_startup: dict = {}


@dataclass(frozen=True)
class Task:
    """One independent case. ``fn(*args)`` runs on a worker and returns a JSON-able
    dict; ``id`` names its folder in the store; ``label`` appears in progress lines."""

    id: str
    label: str
    fn: Callable[..., dict]
    args: tuple = ()


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
def warm_up() -> float:
    """Compile the kernels an optimize + extract case uses, by a short run on the
    built-in ``t_shape`` at level 1 in a temporary folder; returns seconds."""
    from .runs import optimize
    from .scene import load_scene, with_overrides
    from .tendons import extract

    t0 = time.perf_counter()
    scene = with_overrides(load_scene("t_shape"), {"stage_iterations": 3, "k_min": 0.5})
    with tempfile.TemporaryDirectory(prefix="tendon-taichi-warmup-") as tmp:
        rec = Path(tmp) / "warm.rrd"
        optimize(scene, 1, "auto", record=rec)
        extract(rec, record=False)
    return time.perf_counter() - t0


def start_worker(arch: str | None, threads: int | None, warm: bool) -> dict:
    """Start Taichi in this process (once) and optionally warm it up; the times
    are kept for :func:`worker_startup`."""
    from . import runtime

    if not _startup:
        t0 = time.perf_counter()
        runtime.configure(arch=arch, threads=threads)
        runtime.init()
        _startup.update(pid=os.getpid(), init_s=time.perf_counter() - t0, warm_up_s=None)
        if warm:
            _startup["warm_up_s"] = warm_up()
    return dict(_startup)


def worker_startup() -> dict:
    """This worker's start-up figures (for ``client.run``)."""
    return dict(_startup)


class TaichiWorker(WorkerPlugin):
    """A Dask worker plugin: each worker process starts Taichi once, on the
    worker's main thread, with the client's arch and a thread count, then warms up."""

    name = "tendon-taichi"

    def __init__(self, arch: str | None = None, threads: int | None = None, warm: bool = True):
        self.arch, self.threads, self.warm = arch, threads, warm

    def setup(self, worker) -> None:
        start_worker(self.arch, self.threads, self.warm)


def execute(fn: Callable[..., dict], args: tuple) -> dict:
    """Run one task body; never raises (a failure comes back as ``error``)."""
    from .runs import Interrupted

    t0 = time.perf_counter()
    out = {"worker": f"{os.uname().nodename}:{os.getpid()}"}
    try:
        out["value"] = fn(*args)
    except Interrupted:  # Ctrl-C inside an in-process optimization stops the whole run
        raise KeyboardInterrupt from None
    except Exception as exc:  # noqa: BLE001 - a failed case is data, the sweep goes on
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        out["error"] = f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__
        out["traceback"] = traceback.format_exc(limit=8)
    out["time_s"] = time.perf_counter() - t0
    return out


# ---------------------------------------------------------------- clients
@contextlib.contextmanager
def connect(workers: int | None, scheduler: str | None, progress: Callable[[str], None]):
    """A Dask client: on an existing cluster (``scheduler``), else on a new
    ``LocalCluster`` of ``workers`` processes (default: one per core). Yields
    ``(client, info)``; closes what it started."""
    from distributed import Client, LocalCluster

    from . import runtime

    arch = runtime.info()["arch"]
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
            client.register_plugin(TaichiWorker(arch, None))
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
        client.register_plugin(TaichiWorker(arch, threads))
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
    from .export import write_json

    if store is not None and outcome.error is None:
        write_json({**outcome.value, "time_s_worker": outcome.time_s}, store / outcome.task.id / RESULT_FILE)


def _outcome(task: Task, res: dict) -> Outcome:
    return Outcome(task, res.get("value"), res.get("error"), False, res.get("time_s", 0.0), res.get("worker", ""),
                   res.get("traceback"))


class _Progress:
    """``[done/total] label: text (failures, elapsed, time left)`` lines on stderr."""

    def __init__(self, total: int, fresh: int, emit: Callable[[str], None], describe):
        self.total, self.fresh, self.emit, self.describe = total, fresh, emit, describe
        self.done = self.ran = self.failed = 0
        self.t0 = time.perf_counter()

    def __call__(self, o: Outcome) -> None:
        self.done += 1
        self.ran += not o.reused
        self.failed += o.error is not None
        el = time.perf_counter() - self.t0
        left = el / self.ran * (self.fresh - self.ran) if self.ran else 0.0
        what = ("reused" if o.reused else
                f"failed: {o.error}" if o.error else self.describe(o.value) if self.describe else "done")
        self.emit(f"[{self.done}/{self.total}] {o.task.label}: {what} ({o.time_s:.1f} s; {self.failed} failed; "
                  f"elapsed {el:.0f} s, about {left:.0f} s left)")


def run_tasks(tasks: list[Task], store: str | Path | None = None, workers: int | None = None,
              scheduler: str | None = None, progress: Callable[[str], None] | None = None,
              on_outcome: Callable[[Outcome], None] | None = None,
              describe: Callable[[dict], str] | None = None) -> Report:
    """Run ``tasks`` (see the module docstring); ``on_outcome`` sees each outcome as
    it arrives (write partial outputs there); returns them all in task order."""
    progress = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
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
            kept.append(Outcome(t, value, None, True, value.pop("time_s_worker", 0.0), ""))
    show = _Progress(len(tasks), len(fresh), progress, describe)

    def finish(o: Outcome, keep: bool = True) -> None:
        done[o.task.id] = o
        if keep:
            _keep(store, o)
        show(o)
        if on_outcome:
            on_outcome(o)

    engine: dict = {"kind": "none", "workers": 0}
    interrupted = False
    try:
        with contextlib.ExitStack() as stack:
            client = None
            if fresh and (workers != 0 or scheduler is not None):
                client, where = stack.enter_context(connect(workers, scheduler, progress))
                engine.update(where)
            for o in kept:  # only once the cluster answered: bad input writes nothing
                finish(o, keep=False)
            if client is not None:
                _run_on_client(client, fresh, finish, engine)
            elif fresh:
                engine.update(kind="in-process", workers=1)
                for t in fresh:
                    finish(_outcome(t, execute(t.fn, t.args)))
    except KeyboardInterrupt:
        interrupted = True
    engine.update(wall_s=time.perf_counter() - t0, cases=len(tasks), reused=len(kept))
    return Report([done[t.id] for t in tasks if t.id in done], interrupted, engine)


def _run_on_client(client, tasks: list[Task], finish, info: dict) -> None:
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    t_sub = time.perf_counter()
    futures = [client.submit(execute, t.fn, t.args, key=f"tendon-taichi-{t.id}-{os.urandom(4).hex()}", pure=False)
               for t in tasks]
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
