"""The worker-process pool (tendon_taichi/tasks/pool.py): a map gives what the
same calls give in this process, in order, with the work shared between the
workers and this process; a worker that dies or a set-up that fails leaves
the results complete (run here) and says so; an error a task raises reaches
the caller; with no workers nothing is started."""

import os

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


def broken_setup() -> None:
    raise RuntimeError("no Taichi here")


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
