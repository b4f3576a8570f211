"""The package version (keep equal to ``pyproject.toml``) and the provenance of
a result: the commit of the code that made it."""

from __future__ import annotations

import subprocess
import sys
from datetime import datetime, timezone
from pathlib import Path

__version__ = "0.1.0"


def _git(*args: str) -> str | None:
    try:
        r = subprocess.run(["git", *args], cwd=Path(__file__).resolve().parent, capture_output=True, text=True,
                           timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout.strip() if r.returncode == 0 else None


def provenance(made_by: str | None = None) -> dict:
    """What made a result: ``version``, ``commit`` (None outside a git checkout),
    ``dirty`` (uncommitted changes to tracked files), ``made_by`` (the command,
    default this process's), ``date`` (UTC, ISO 8601)."""
    program = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "python"
    program = "tendon-taichi" if program == "__main__.py" else program
    commit = _git("rev-parse", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no")) if commit else None
    return {"version": __version__, "commit": commit, "dirty": dirty,
            "made_by": made_by or " ".join([program, *sys.argv[1:]]),
            "date": datetime.now(timezone.utc).replace(microsecond=0).isoformat()}
