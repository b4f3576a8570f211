"""Independent cases as tasks on Dask distributed (:mod:`.engine`): the engine
of ``sweep``, ``planted-bench`` and the optimizations of ``bench``; and a few
worker processes that share the independent pieces of one job (:mod:`.pool`,
``design``'s). It imports nothing of the application; what the workers set up
and what stops a run are its arguments."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".engine": ("Task", "Cluster", "Outcome", "Report", "LineProgress", "case_id", "run_tasks", "execute", "connect",
                "worker_startup"),
    ".pool": ("Pool",),
})
