"""Writing files safely: every output is written to a temporary name beside its
destination and renamed into place, so an interrupted or failed run never
leaves a half-written file."""

from __future__ import annotations

import json
import os
import re
import tempfile
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError


@contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path in the destination's folder; rename it to ``path``
    when the block succeeds, delete it when it fails."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder '{path.parent}': {exc}") from None
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes it private; a plain open would not
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def file_stem(name: str) -> str:
    """``name`` (a scene's or sweep's, from its file) made safe to name one file
    or folder: characters other than letters, digits, ``.``, ``_`` and ``-``
    become ``_`` and leading dots are dropped, so a default output path never
    leaves its folder, makes folders or hides a file."""
    return re.sub(r"[^\w.-]", "_", name).lstrip(".") or "unnamed"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_json(data: dict, path: str | Path) -> None:
    """``data`` as indented JSON at ``path``, written atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n")
