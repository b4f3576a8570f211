"""What running cases as Dask tasks costs, apart from the cases themselves.

    python benchmarks/sweeps/dask_overhead.py [--workers 2] [--tasks 200]

Prints the local cluster's start-up, each worker's Taichi start-up and
warm-up (compile) time, and the per-task overhead of tendon_taichi.tasks.engine.run_tasks:
the wall time of N tasks that do nothing, per task, with and without Dask.
"""

import argparse
import json
import time

from tendon_taichi.tasks.engine import Cluster, Task, run_tasks


def nothing(i: int) -> dict:
    return {"i": i}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--tasks", type=int, default=200)
    args = ap.parse_args()
    tasks = [Task(f"noop{i}", f"noop {i}", nothing, (i,)) for i in range(args.tasks)]
    quiet = lambda msg: None  # noqa: E731
    t = time.perf_counter()
    local = run_tasks(tasks, None, Cluster(workers=0), quiet)
    in_process = (time.perf_counter() - t) / args.tasks
    t = time.perf_counter()
    rep = run_tasks(tasks, None, Cluster(workers=args.workers), quiet)
    wall = time.perf_counter() - t
    e = rep.engine
    assert len(rep.outcomes) == args.tasks and all(o.error is None for o in rep.outcomes + local.outcomes)
    print(json.dumps({
        "workers": args.workers, "tasks": args.tasks, "wall_s": wall,
        "cluster_start_s": e["cluster_start_s"],
        "worker_startup": e.get("worker_startup"),
        "tasks_s": e["tasks_s"],
        "overhead_per_task_ms": 1e3 * e["tasks_s"] / args.tasks,
        "in_process_per_task_ms": 1e3 * in_process,
    }, indent=2))


if __name__ == "__main__":
    main()
