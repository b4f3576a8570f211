"""Progress on stderr: live bars on a terminal (rich: the cases of a run and the
homotopy stages inside them, nested, with rate and time left), one plain line
per event otherwise (logs, pipes, CI).

One :class:`Progress` serves both levels: the optimizer reports stages to it
(``stage_start``, ``iteration``, ``stage_done``) and the task engine reports
cases (``message``, ``start``, ``advance``: the reporter protocol of
:class:`tendon_taichi.tasks.engine.LineProgress`). A case run in this process
finds the live display with :func:`active` and nests its stage bar under the
cases bar.
"""

from __future__ import annotations

import sys

#: the live terminal display of this process, if any
_active: list["Progress"] = []


def active() -> "Progress | None":
    """The progress display that is live on this process's terminal, or None."""
    return _active[-1] if _active else None


def _k_text(k: float | None) -> str:
    return "k = -" if k is None else f"k = {k:.4g}"


class Progress:
    """Progress on ``stream`` (default stderr); ``enabled=False`` shows nothing."""

    def __init__(self, stream=None, enabled: bool = True):
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = enabled and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.cap = 1
        self._bars = None  # rich.progress.Progress while any bar is live
        self._tasks: dict[str, int] = {}

    # ------------------------------------------------------------ terminal bars
    def _bar(self, key: str, description: str, total: int) -> None:
        if self._bars is None:
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress as Bars, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                       TextColumn("{task.fields[info]}"), TimeElapsedColumn(), TimeRemainingColumn())
            self._bars = Bars(*columns, console=Console(file=self.stream), transient=True)
            self._bars.start()
            _active.append(self)
        self._tasks[key] = self._bars.add_task(description, total=total, info="")

    def _drop(self, key: str) -> None:
        """Remove a bar; the display stops with the last one."""
        if key in self._tasks:
            self._bars.remove_task(self._tasks.pop(key))
        if not self._tasks and self._bars is not None:
            self._bars.stop()
            self._bars = None
            _active.remove(self)

    def _print(self, text: str) -> None:
        """One line, above the bars while they are live."""
        if self._bars is not None:
            self._bars.console.print(text, markup=False, highlight=False, soft_wrap=True)
        else:
            print(text, file=self.stream, flush=True)

    # ------------------------------------------------------------ the stages of an optimization
    def stage_start(self, stage: int, k: float | None, cap: int) -> None:
        """Stage ``stage`` (homotopy parameter ``k``, None for stage 0) starts; it runs
        at most ``cap`` iterations."""
        self.cap = cap
        if not self.enabled:
            return
        if self.tty:
            self._bar("stage", f"stage {stage} ({_k_text(k)})", cap)
        else:
            print(f"stage {stage} ({_k_text(k)}) ...", file=self.stream, flush=True)

    def iteration(self, it) -> None:
        """One L-BFGS-B iteration (an :class:`~tendon_taichi.optimizer.soft_ik.Iterate`)."""
        if "stage" not in self._tasks:
            return
        f = it.figures
        self._bars.update(self._tasks["stage"], completed=min(it.iteration, self.cap),
                          info=f"pose {100 * f.pose_error_rel:6.3f}%  active {f.active_fibers:4d}")

    def stage_done(self, st) -> None:
        """A finished stage (a :class:`~tendon_taichi.optimizer.homotopy.StageResult`)."""
        if not self.enabled:
            return
        f = st.figures
        self._print(f"stage {st.stage} done: {_k_text(st.k)}, {st.iterations} iterations, pose error "
                    f"{100 * f.pose_error_rel:.3f}% of L, {f.active_fibers} active fibers "
                    f"({100 * f.active_length:.1f} cm), {st.time_s:.1f} s")
        self._drop("stage")

    # ------------------------------------------------------------ the cases of a run (task engine)
    def message(self, text: str) -> None:
        """A line of the engine's (cluster start-up, dashboard address)."""
        if self.enabled:
            self._print(text)

    def start(self, total: int) -> None:
        """A run of ``total`` cases starts."""
        if self.tty and total:
            self._bar("cases", "cases", total)

    def advance(self, text: str) -> None:
        """A case finished; ``text`` is its line."""
        if not self.enabled:
            return
        self._print(text)
        if "cases" in self._tasks:
            task = self._tasks["cases"]
            self._bars.advance(task)
            if self._bars.tasks[[t.id for t in self._bars.tasks].index(task)].finished:
                self._drop("cases")
