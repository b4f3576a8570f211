"""The ``tendon-taichi`` command line: :func:`main` (the console script), the
parser in :mod:`.main`, the commands by group in :mod:`.runs`, :mod:`.tendons`
and :mod:`.batch`."""

from .main import build_parser, main

__all__ = ["main", "build_parser"]
