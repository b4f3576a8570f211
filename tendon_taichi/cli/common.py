"""What every command shares: the one-line usage errors, ``--json`` output and
the flags that several commands take."""

from __future__ import annotations

import argparse
import json

from ..errors import InputError
from ..files import check_folder, check_writable, write_json
from ..solve.linear import SOLVERS

PROG = "tendon-taichi"
SOLVER_CHOICES = SOLVERS


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line."""

    def error(self, message: str):
        raise InputError(f"{message} (see '{self.prog} --help')")


#: the flags that name a file a command writes ("-": stdout, or the default place), and what it
#: is; ``--record`` is checked by the commands themselves (a tendons file must also be an .rrd of
#: the same run)
OUTPUT_FILES = {"json": "--json file", "png": "picture", "svg": "drawing", "export": "export",
                "vtu": "VTU file"}


def check_before_work(args) -> None:
    """Raise InputError, before any work, for what a command would otherwise find bad
    only after it: an output it cannot write, an extractor that is not installed."""
    check_outputs(args)
    check_extractor_names(args)


def check_extractor_names(args) -> None:
    """Raise InputError when ``--extractor``/``--extractors`` names one that is not installed."""
    from ..extract.plugins import unknown_extractor

    names = getattr(args, "extractors", None) or []
    if getattr(args, "extractor", None) is not None:
        names = [args.extractor]
    unknown = unknown_extractor(names)
    if unknown:
        raise InputError(unknown)


def check_outputs(args) -> None:
    """Raise InputError, before any work, when a file a flag names (:data:`OUTPUT_FILES`)
    or the ``--out`` folder cannot be written; makes nothing."""
    for flag, what in OUTPUT_FILES.items():
        value = getattr(args, flag, None)
        if isinstance(value, str) and value != "-":
            check_writable(value, what, make=False)
    if getattr(args, "out", None) is not None:
        check_folder(args.out)


def json_out(args, data: dict) -> None:
    """Print JSON to stdout (``--json``) or write it to a file (``--json FILE``)."""
    if args.json is None:
        return
    if args.json == "-":
        print(json.dumps(data, indent=2))
    else:
        write_json(data, args.json)


#: the flag that names the resolution level in every command, and its former name, still accepted
LEVEL_FLAG, LEVEL_ALIAS = "--level", "--resolution"


def add_level_flag(p, default: int | list[int] | None, help: str, many: bool = False, aliases=()) -> None:
    """``--level N`` (with ``many``, ``--level N [N ...]``) into ``args.level``: the
    resolution level (:func:`~tendon_taichi.body.problem.level_scale`); ``--resolution``
    and ``aliases`` are other names for it. :func:`levels_given` checks it."""
    p.add_argument(LEVEL_FLAG, LEVEL_ALIAS, *aliases, dest="level", type=int, default=default,
                   nargs="+" if many else None, metavar="N", help=f"{help}; {LEVEL_ALIAS} is its former name")


def levels_given(args) -> list[int]:
    """The levels a command was given (``--level``, or planted-bench's ``--levels``;
    none where it takes neither); raises InputError for one below 1."""
    level = getattr(args, "levels", None) or getattr(args, "level", None)
    levels = [] if level is None else list(level) if isinstance(level, list) else [level]
    for lv in levels:
        if lv < 1:
            raise InputError(f"{LEVEL_FLAG} must be >= 1 (got {lv})")
    return levels


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", nargs="?", const="-", metavar="FILE",
                   help="machine-readable summary on stdout, or into FILE")
