"""What every solve of an as-built robot is given (:class:`Context`): the problem,
the idealized state, the optimize settings and the linear solver, passed whole
from the design down to consolidation, the front and the finer mesh, and pickled
whole to the worker processes that share their solves."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

from ..body.problem import Problem
from ..objective.settings import OptimizeSettings
from ..tasks.pool import Pool
from .protocol import IdealizedState


@dataclass(frozen=True, eq=False)
class Context:
    """The ``problem`` (body, mesh, each pose's targets), the idealized ``state``
    (its equilibria and tensions, each pose's in ``state.poses``), the ``settings``
    of the soft IK and the linear ``solver`` an as-built robot is solved with; and,
    left behind when it is pickled (a worker process has neither), the ``log`` that
    hears of progress and the ``workers``, a pool of processes that share the
    independent solves."""

    problem: Problem
    state: IdealizedState
    settings: OptimizeSettings
    solver: str = "auto"
    log: Callable[[str], None] | None = field(default=None, repr=False)
    workers: Pool | None = field(default=None, repr=False)

    def say(self, text: str) -> None:
        """Tell the log, where there is one."""
        if self.log is not None:
            self.log(text)

    def on(self, problem: Problem, state: IdealizedState) -> "Context":
        """The same settings, solver, log and workers for another problem and state
        (one pose's, or a finer mesh's)."""
        return replace(self, problem=problem, state=state)

    def __getstate__(self) -> dict:
        return {**self.__dict__, "log": None, "workers": None}
