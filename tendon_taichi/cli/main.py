"""The ``tendon-taichi`` command line (``docs/cli.md``): the parser and the
one place where errors become exit statuses.

Results go to stdout (``--json`` for machines, to stdout or a file), progress
and warnings to stderr. Bad input gives one ``tendon-taichi: error: ...`` line
and exit status 2; an unexpected failure one ``internal error`` line and 1
(``--debug`` shows the traceback); a file or folder the user may not read or write
one ``error`` line and 2 wherever it is met; Ctrl-C exits 130, and SIGTERM (``timeout``,
a batch scheduler) stops the command the same way, keeping what Ctrl-C keeps,
with 143; a reader of stdout that
stops early (``tendon-taichi scenes --json | head``) ends the command quietly
with 141, as SIGPIPE ends other tools (the files it wrote stay).
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import threading

from ..errors import InputError, Stopped, TendonError
from ..physics import runtime
from . import batch, design, runs, tendons
from .common import PROG, Parser, check_before_work, levels_given


#: the exit status when stdout's reader went away (128 + SIGPIPE, as a shell reports it)
BROKEN_PIPE = 141
#: the exit statuses of a command stopped by Ctrl-C and by SIGTERM (128 + the signal)
INTERRUPTED, TERMINATED = 130, 143


#: whether this command received SIGTERM (its exit status is then TERMINATED)
_sigterm = [False]


def _terminate(signum, frame):
    """SIGTERM raises Ctrl-C's KeyboardInterrupt: what stops a run on Ctrl-C
    (recordings closed, completed stages kept, workers stopped) stops it here too;
    the flag tells the exit status apart."""
    _sigterm[0] = True
    raise KeyboardInterrupt


def _on_sigterm():
    """Stop on SIGTERM as on Ctrl-C, from the main thread only (where Python runs
    signal handlers); returns the handler to put back."""
    _sigterm[0] = False
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, _terminate)


def _stopped() -> int:
    """The exit status of a command stopped from outside."""
    return TERMINATED if _sigterm[0] else INTERRUPTED


def _stdout_reader_gone() -> bool:
    """Whether stdout is a pipe or socket whose reading end was closed (a broken pipe
    elsewhere - a worker's - is a bug to report, not this)."""
    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (OSError, ValueError, AttributeError):  # no file descriptor behind sys.stdout, no poll
        return False


def _stdout_to_devnull() -> None:
    """Point stdout at /dev/null, so that flushing it at exit does not fail again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)


def _denied(exc: PermissionError) -> str:
    """The one line for a file or folder this user may not use."""
    if exc.filename is None:
        return f"permission denied ({exc})"
    return f"permission denied: '{exc.filename}'"


def _internal_error(exc: Exception, debug: bool) -> int:
    if debug:
        raise exc
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    print(f"{PROG}: internal error: {type(exc).__name__}: {msg} "
          f"(run with --debug for the traceback)", file=sys.stderr)
    return 1


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog=PROG, description="Design the tendon layout of a 2D soft robot.")
    p.add_argument("--arch", default=None, help="Taichi backend: cpu (default), cuda, vulkan, gpu")
    p.add_argument("--threads", type=int, default=None, help="CPU threads for Taichi")
    p.add_argument("--max-dofs", type=int, default=None, metavar="N",
                   help="refuse problems larger than N degrees of freedom or fibers (default: what half "
                        "of this machine's memory holds)")
    p.add_argument("--debug", action="store_true", help="show tracebacks of internal errors")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    for group in (runs, design, tendons, batch):
        group.add_commands(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv or os.environ.get("TENDON_TAICHI_DEBUG") == "1"
    previous = _on_sigterm()
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help(sys.stderr)
            return 2
        levels_given(args)
        if args.max_dofs is not None:
            if args.max_dofs < 1:
                raise InputError(f"--max-dofs must be >= 1 (got {args.max_dofs})")
            os.environ["TENDON_TAICHI_MAX_DOFS"] = str(args.max_dofs)  # worker processes read it too
        check_before_work(args)
        runtime.configure(arch=args.arch, threads=args.threads)
        runtime.check()
        return int(args.func(args) or 0)
    except TendonError as exc:
        if isinstance(exc, Stopped):
            print(f"{PROG}: {exc}", file=sys.stderr)
            return _stopped()
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{PROG}: {'terminated' if _sigterm[0] else 'interrupted'}", file=sys.stderr)
        return _stopped()
    except BrokenPipeError as exc:
        if not _stdout_reader_gone():
            return _internal_error(exc, debug)
        _stdout_to_devnull()
        return BROKEN_PIPE
    except PermissionError as exc:  # a file or folder the user may not read or write: not a bug
        print(f"{PROG}: error: {_denied(exc)}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # --help
        return int(exc.code or 0)
    except Exception as exc:  # noqa: BLE001 - the one place that turns bugs into one line
        return _internal_error(exc, debug)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
