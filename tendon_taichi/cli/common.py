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


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", nargs="?", const="-", metavar="FILE",
                   help="machine-readable summary on stdout, or into FILE")
