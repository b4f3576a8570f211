"""The worker-process pool (tendon_taichi/tasks/pool.py): a map gives what the
same calls give in this process, in order, with the work shared between the
workers and this process; a worker that dies or a set-up that fails leaves
the results complete (run here) and says so; an error a task raises reaches
the caller; with no workers nothing is started. Deferred jobs run on a worker
that has no map item to take, and collecting them gives what the same calls
give here, whichever process ran them and whether one ran them at all."""

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from functools import partial
from pathlib import Path

import pytest

from tendon_taichi.tasks.pool import Pool


def square(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def die_in_a_worker(x: int) -> int:
    if os.environ.get("POOL_TEST_PARENT") != str(os.getpid()):
        os._exit(3)  # the worker process is killed mid-task
    return -x


def fail(x: int) -> int:
    if x == 2:
        raise ValueError("two is bad")
    return x


def sleep_in_a_worker(folder: str) -> None:
    """Say which process took the item (a file named by its pid), then take long."""
    (Path(folder) / f"{os.getpid()}.pid").write_text("")
    time.sleep(120)


#: a job whose pool's worker and own process each take one long item
PARENT = """
import sys
sys.path.insert(0, {tests!r})
from tendon_taichi.tasks.pool import Pool
from test_pool import sleep_in_a_worker

if __name__ == "__main__":
    with Pool(1) as pool:
        pool.map(sleep_in_a_worker, [{folder!r}] * 2)
"""


def running(pid: int) -> bool:
    """Whether process ``pid`` exists and has not ended (a zombie has)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def broken_setup() -> None:
    raise RuntimeError("no Taichi here")


def setup_in_a_temporary_folder(folder: str) -> None:
    """A set-up that takes long inside a temporary folder of its own (under
    ``folder``), as ``design``'s warm-up does; says it is there by a file."""
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        (Path(tmp) / "started").write_text("")
        time.sleep(120)


#: a job whose worker is still setting up when the job is killed
SETTING_UP = """
import sys, time
sys.path.insert(0, {tests!r})
from tendon_taichi.tasks.pool import Pool
from test_pool import setup_in_a_temporary_folder

if __name__ == "__main__":
    with Pool(1, setup_in_a_temporary_folder, ({folder!r},)):
        time.sleep(120)
"""


def wait_for(condition, seconds: float) -> bool:
    """Whether ``condition()`` holds within ``seconds`` (polled every 0.1 s)."""
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.1)
    return condition()


#: the threads that pickled a Traced (in this process)
PICKLED_IN: list[str] = []


class Traced:
    """Records which thread pickles it."""

    def __reduce__(self):
        PICKLED_IN.append(threading.current_thread().name)
        return (Traced, ())


def both_traced(shared, item) -> bool:
    return isinstance(shared, Traced) and isinstance(item, Traced)


def test_a_map_is_the_same_calls_in_order_shared_with_a_worker():
    with Pool(1) as pool:
        got = pool.map(square, range(7))
        assert [v for v, _ in got] == [x * x for x in range(7)]
        pids = {pid for _, pid in got}
        assert os.getpid() in pids and len(pids) == 2  # this process and the worker both took items
        assert pool.map(square, [5]) == [(25, os.getpid())]  # one item: no hand-off
    assert pool.active == 0 and pool.broken is None
    assert pool.map(square, [2, 3]) == [(4, os.getpid()), (9, os.getpid())]  # closed: all here


def test_no_workers_runs_everything_here():
    pool = Pool(0)
    assert pool.active == 0
    assert pool.map(square, range(3)) == [(x * x, os.getpid()) for x in range(3)]


def test_a_worker_that_dies_leaves_the_results_complete(monkeypatch):
    monkeypatch.setenv("POOL_TEST_PARENT", str(os.getpid()))
    with Pool(1) as pool:
        assert pool.map(die_in_a_worker, [0, 1, 2, 3]) == [0, -1, -2, -3]
        assert pool.broken and "worker process stopped" in pool.broken
        assert pool.active == 0


def test_a_setup_that_fails_breaks_the_pool_and_the_work_is_done_here():
    with Pool(1, broken_setup) as pool:
        assert [v for v, _ in pool.map(square, range(4))] == [0, 1, 4, 9]
        assert pool.broken is not None


def test_an_error_a_task_raises_reaches_the_caller():
    with Pool(1) as pool:
        with pytest.raises(ValueError, match="two is bad"):
            pool.map(fail, [0, 1, 2, 3])
    with pytest.raises(ValueError, match="workers must be >= 0"):
        Pool(-1)


def test_what_the_workers_get_is_pickled_in_the_calling_thread():
    """The executor pickles what it is handed in a thread of its own, which would
    race the calling thread's computing with the same objects (a design failed
    with "dictionary changed size during iteration"): the pool pickles the
    function and every item in the calling thread, before it hands any out."""
    PICKLED_IN.clear()
    with Pool(1) as pool:
        assert pool.map(partial(both_traced, Traced()), [Traced() for _ in range(6)]) == [True] * 6
    assert len(PICKLED_IN) >= 2 and set(PICKLED_IN) == {threading.current_thread().name}


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_a_worker_ends_when_the_job_that_started_it_is_killed(tmp_path, sig):
    """A job killed from outside (a batch scheduler's SIGTERM, SIGKILL) runs no
    clean-up; its worker must not go on computing for no one."""
    (tmp_path / "job.py").write_text(PARENT.format(tests=str(Path(__file__).parent), folder=str(tmp_path)))
    job = subprocess.Popen([sys.executable, str(tmp_path / "job.py")], stderr=subprocess.DEVNULL)
    wait_for(lambda: len(list(tmp_path.glob("*.pid"))) >= 2, 60)  # both took their item
    workers = [int(f.stem) for f in tmp_path.glob("*.pid") if int(f.stem) != job.pid]
    assert len(workers) == 1 and running(workers[0])
    job.send_signal(sig)
    job.wait(timeout=30)
    assert wait_for(lambda: not running(workers[0]), 20)


def test_a_worker_stopped_while_it_sets_up_cleans_up_after_itself(tmp_path):
    """A job that ends early (an error, Ctrl-C) stops its workers at once: one
    still in its set-up leaves it through its ``with`` blocks, so that the
    temporary folder the set-up made is gone, not left behind."""
    with pytest.raises(KeyboardInterrupt):
        with Pool(1, setup_in_a_temporary_folder, (str(tmp_path),)):
            assert wait_for(lambda: list(tmp_path.glob("*/started")), 60)
            raise KeyboardInterrupt
    assert wait_for(lambda: not any(tmp_path.iterdir()), 20), list(tmp_path.iterdir())


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_a_worker_whose_job_is_killed_while_it_sets_up_cleans_up_after_itself(tmp_path, sig):
    """A job killed from outside stops nobody: its worker, still setting up, cleans
    up (its temporary folder is gone) and ends."""
    (tmp_path / "job.py").write_text(SETTING_UP.format(tests=str(Path(__file__).parent), folder=str(tmp_path)))
    job = subprocess.Popen([sys.executable, str(tmp_path / "job.py")], stderr=subprocess.DEVNULL)
    assert wait_for(lambda: list(tmp_path.glob("*/started")), 60)
    job.send_signal(sig)
    job.wait(timeout=30)
    assert wait_for(lambda: [p.name for p in tmp_path.iterdir()] == ["job.py"], 20), list(tmp_path.iterdir())


def test_leaving_the_pool_stops_its_idle_workers_rather_than_waiting_for_them():
    """Once the work is done, leaving the pool stops its workers (SIGTERM, as with
    an error): the process that ran the job does not wait at its own exit for
    them to shut down."""
    with Pool(1) as pool:
        assert [v for v, _ in pool.map(square, range(4))] == [x * x for x in range(4)]
        workers = list(pool._executor._processes.values())
    assert workers and wait_for(lambda: all(p.exitcode is not None for p in workers), 20)
    assert [p.exitcode for p in workers] == [-signal.SIGTERM]


def slow_square(x: int) -> tuple[int, int]:
    time.sleep(0.2)
    return x * x, os.getpid()


def test_deferred_jobs_run_on_an_idle_worker_and_are_collected_in_order():
    with Pool(1) as pool:
        jobs = [pool.defer(square, x) for x in range(5)]
        assert wait_for(lambda: all(job.future is not None and job.future.done() for job in jobs), 60)
        got = pool.collect(jobs)
        assert [v for v, _ in got] == [x * x for x in range(5)]
        assert {pid for _, pid in got} != {os.getpid()}  # the idle worker took them
        assert pool.collect([]) == []


def test_deferred_jobs_and_a_map_mixed_and_the_rest_shared_when_collected():
    """Jobs queued before a map and after it: the map gives its results, and the
    jobs the worker has not taken when they are collected run as a map, here and
    on the worker; everything gives what the calls give here."""
    with Pool(1) as pool:
        assert wait_for(lambda: all(f.done() for f in pool._starting), 60)
        jobs = [pool.defer(slow_square, x) for x in range(8)]
        assert [v for v, _ in pool.map(square, range(6))] == [x * x for x in range(6)]
        more = [pool.defer(square, x) for x in range(8, 10)]
        got = pool.collect(jobs + more)
        assert [v for v, _ in got] == [x * x for x in range(10)]
        assert os.getpid() in {pid for _, pid in got}  # not all taken by the worker before collect
        assert pool.broken is None


def test_deferred_jobs_without_workers_run_here_when_collected():
    pool = Pool(0)
    jobs = [pool.defer(square, x) for x in range(3)]
    assert all(job.future is None for job in jobs)
    assert pool.collect(jobs) == [(x * x, os.getpid()) for x in range(3)]


def test_a_worker_that_dies_in_a_deferred_job_leaves_the_results_complete(monkeypatch):
    monkeypatch.setenv("POOL_TEST_PARENT", str(os.getpid()))
    with Pool(1) as pool:
        jobs = [pool.defer(die_in_a_worker, x) for x in range(4)]
        assert wait_for(lambda: jobs[0].future is not None and jobs[0].future.done(), 60)
        assert pool.collect(jobs) == [0, -1, -2, -3]
        assert pool.broken and "worker process stopped" in pool.broken
        assert pool.map(square, [1, 2]) == [(1, os.getpid()), (4, os.getpid())]  # broken: all here


def test_an_error_a_deferred_job_raises_reaches_the_collector():
    with Pool(1) as pool:
        jobs = [pool.defer(fail, x) for x in range(4)]
        with pytest.raises(ValueError, match="two is bad"):
            pool.collect(jobs)


def started_at(seconds: float) -> tuple[float, int]:
    """When the call started, and in which process, after taking ``seconds``."""
    t = time.monotonic()
    time.sleep(seconds)
    return t, os.getpid()


def test_a_maps_items_go_before_the_deferred_jobs():
    """A worker busy with a deferred job when a map starts takes the map's items
    left when it is free, before the other queued jobs."""
    with Pool(1) as pool:
        assert wait_for(lambda: all(f.done() for f in pool._starting), 60)
        first = pool.defer(started_at, 0.5)  # the idle worker takes it at once
        queued = [pool.defer(started_at, 0.0) for _ in range(2)]
        got = pool.map(started_at, [0.3] * 12)  # this process alone until the worker is free
        in_worker = [t for t, pid in got if pid != os.getpid()]
        (t_first, _), *rest = pool.collect([first] + queued)
        assert in_worker and all(t < t_queued for t in in_worker for t_queued, _ in rest)
        assert min(in_worker) > t_first
