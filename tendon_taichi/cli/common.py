"""What every command shares: the one-line usage errors, ``--json`` output and
the flags that several commands take."""

from __future__ import annotations

import argparse
import json

from ..errors import InputError
from ..files import write_json
from ..solve.linear import SOLVERS

PROG = "tendon-taichi"
SOLVER_CHOICES = SOLVERS


class Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line."""

    def error(self, message: str):
        raise InputError(f"{message} (see '{self.prog} --help')")


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
