"""Files and folders the user may not use: one ``tendon-taichi: error:`` line naming
the problem, exit status 2, and nothing written. The commands run as an
unprivileged user (root reads and writes everywhere): as ``nobody`` through
``setpriv`` under root, as the user running the tests otherwise."""

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

NOBODY = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]


def _prefix() -> list[str]:
    """What runs a command as a user that a folder with mode 0o700 of root's (or
    0o000 of one's own) locks out; skips where there is none."""
    if os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: no unprivileged user to run the commands as")
    r = subprocess.run(NOBODY + [sys.executable, "-c", "import tendon_taichi.cli"], capture_output=True,
                       text=True, cwd="/")
    if r.returncode != 0:
        pytest.skip(f"'nobody' cannot import the package from this checkout: {r.stderr.strip()[-200:]}")
    return NOBODY


@pytest.fixture(scope="module")
def place():
    """A folder every user may write into (the working folder of the commands),
    holding ``locked/``, a folder only its owner may enter, with a recording and a
    design folder in it."""
    prefix = _prefix()
    top = Path(tempfile.mkdtemp(prefix="tendon-taichi-perm-"))
    top.chmod(0o777)
    locked = top / "locked"
    (locked / "d").mkdir(parents=True)
    (locked / "run.rrd").write_bytes(b"RRF2")
    (locked / "d" / "design.json").write_text("{}")
    locked.chmod(0o700 if prefix else 0o000)
    if not prefix and os.access(locked, os.X_OK):
        shutil.rmtree(top)
        pytest.skip("this user enters a folder of mode 0o000: no way to lock one")
    yield top, prefix
    locked.chmod(0o700)
    shutil.rmtree(top)


def _files(top: Path) -> set[str]:
    return {str(p.relative_to(top)) for p in top.rglob("*")}


@pytest.mark.parametrize("args, message", [
    (["compare", "locked/run.rrd"], "cannot read recording 'locked/run.rrd'"),
    (["extract", "locked/run.rrd", "--extractor", "strands"], "cannot read recording 'locked/run.rrd'"),
    (["replay", "locked/run.rrd"], "cannot read recording 'locked/run.rrd'"),
    (["optimize", "--resume", "locked/run.rrd"], "cannot read recording 'locked/run.rrd'"),
    (["optimize", "finger", "--record", "locked/x.rrd"], "cannot write the recording 'locked/x.rrd'"),
    (["simulate", "finger", "--uniform", "0.05", "--export", "locked/e.npz"], "cannot write the export"),
    (["design", "finger", "--out", "locked/new"], "cannot write the output folder 'locked/new'"),
    (["design", "finger", "--routes-from", "locked/d", "--out", "mine"], "--routes-from: cannot read 'locked/d'"),
    (["planted-bench", "locked", "--out", "mine"], "cannot read the planted suite 'locked'"),
])
def test_a_folder_the_user_cannot_enter_is_one_error_line(place, args, message):
    top, prefix = place
    before = _files(top)
    r = subprocess.run(prefix + [sys.executable, "-m", "tendon_taichi", *args], capture_output=True, text=True,
                       cwd=top, timeout=300)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0].startswith("tendon-taichi: error: ") and message in lines[0], lines[0]
    assert "denied" in lines[0].lower() and "internal error" not in lines[0]
    assert _files(top) == before  # nothing written, no folder made
