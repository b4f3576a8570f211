"""Progress on stderr: plain lines in a log, live bars (rich) on a terminal, the
stages of an in-process case nested under the cases bar."""

import io
from types import SimpleNamespace

from tendon_taichi.io import progress
from tendon_taichi.io.progress import Progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


def _stage(stage, k=None):
    figures = SimpleNamespace(pose_error_rel=0.0123, active_fibers=42, active_length=0.05)
    return SimpleNamespace(stage=stage, k=k, iterations=7, figures=figures, time_s=1.5)


def test_a_log_gets_one_line_per_event():
    log = io.StringIO()
    p = Progress(log)
    p.start(2)
    p.stage_start(0, None, 10)
    p.iteration(SimpleNamespace(iteration=3, figures=_stage(0).figures))
    p.stage_done(_stage(0))
    p.advance("[1/2] case a: done")
    p.message("cluster up")
    assert log.getvalue().splitlines() == [
        "stage 0 (k = -) ...",
        "stage 0 done: k = -, 7 iterations, pose error 1.230% of L, 42 active fibers (5.0 cm), 1.5 s",
        "[1/2] case a: done", "cluster up"]
    quiet = io.StringIO()
    Progress(quiet, enabled=False).stage_done(_stage(0))
    assert quiet.getvalue() == ""


def test_a_terminal_gets_nested_bars_that_end_with_the_run():
    term = Terminal()
    cases = Progress(term)
    cases.start(2)
    assert progress.active() is cases  # an in-process case finds the live display ...
    cases.stage_start(1, 0.5, 10)  # ... and nests its stage bar under the cases bar
    cases.iteration(SimpleNamespace(iteration=4, figures=_stage(1).figures))
    assert set(cases._tasks) == {"cases", "stage"}
    cases.stage_done(_stage(1, 0.5))
    cases.advance("[1/2] case a: done")
    cases.advance("[2/2] case b: done")
    assert progress.active() is None and cases._bars is None  # the last bar stops the display
    out = term.getvalue()
    for line in ("stage 1 done: k = 0.5", "[1/2] case a: done", "[2/2] case b: done"):
        assert line in out
