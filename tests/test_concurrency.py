"""Several processes on one recording: concurrent extractions each keep their
tendons, a writer waits for another's lock, and a compare killed at any moment
leaves the recording as it was or fully updated, and no temporary file."""

import fcntl
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tendon_taichi.io.recording import read_chunks

COMPARE = ("compare", "--no-consolidate", "--extractors", "strands", "--json")


def _start(rec, stage, into=None):
    """A compare logging strands' tendons into the recording (or the file ``into``)."""
    record = ["--record"] if into is None else ["--record", str(into)]
    return subprocess.Popen([sys.executable, "-m", "tendon_taichi", COMPARE[0], str(rec), *COMPARE[1:],
                             "--stage", str(stage), *record], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _logged_stages(rec) -> set[int]:
    """The stages at which strands' tendons are in the recording (which must read whole)."""
    chunks, truncated = read_chunks(rec)
    assert not truncated
    return {s for ch in chunks if ch.entity_path == "/tendons/strands/summary"
            for s in ch.to_record_batch().column("stage").to_pylist()}


def _copy(run_rrd, folder):
    folder.mkdir()
    return shutil.copyfile(run_rrd, folder / "run.rrd")


@pytest.mark.parametrize("trial,own_file", [(0, False), (1, True)])
def test_concurrent_compares_keep_every_result(run_rrd, tmp_path, trial, own_file):
    rec = _copy(run_rrd, tmp_path / "d")
    into = rec.parent / "tendons.rrd" if own_file else None
    a = _start(rec, 3, into)
    time.sleep(0.1)
    b = _start(rec, 4, into)
    for p in (a, b):
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    assert _logged_stages(into or rec) == {3, 4}
    assert sorted(os.listdir(rec.parent)) == (["run.rrd", "tendons.rrd"] if own_file else ["run.rrd"])
    if own_file:
        assert rec.read_bytes() == run_rrd.read_bytes()


def test_a_writer_waits_for_the_lock(run_rrd, tmp_path):
    rec = _copy(run_rrd, tmp_path / "d")
    before = rec.read_bytes()
    fd = os.open(rec, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    p = _start(rec, 4)
    try:
        line = p.stderr.readline()
        while line and "waiting for another process" not in line:
            line = p.stderr.readline()
        assert "waiting for another process to finish writing" in line
        time.sleep(0.5)
        assert p.poll() is None and rec.read_bytes() == before  # it waits, and has written nothing
    finally:
        os.close(fd)
    p.communicate(timeout=300)
    assert p.returncode == 0 and _logged_stages(rec) == {4}


def test_a_killed_compare_leaves_the_recording_whole(run_rrd, tmp_path):
    """10 kills at seeded random moments over the second half of a compare's run time
    (when it writes): each leaves the original bytes or a whole recording with the
    new tendons, and nothing else."""
    rec = _copy(run_rrd, tmp_path / "timed")
    t0 = time.perf_counter()
    p = _start(rec, 4)
    p.communicate(timeout=300)
    duration = time.perf_counter() - t0
    assert p.returncode == 0 and _logged_stages(rec) == {4}
    original = run_rrd.read_bytes()
    outcomes = {"original": 0, "updated": 0}
    for i, at in enumerate(np.random.default_rng(7).uniform(0.5, 1.0, 10) * duration):
        rec = _copy(run_rrd, tmp_path / f"k{i}")
        p = _start(rec, 4)
        time.sleep(at)
        p.send_signal(signal.SIGKILL)
        p.communicate(timeout=60)
        assert os.listdir(rec.parent) == ["run.rrd"], i
        if rec.read_bytes() == original:
            outcomes["original"] += 1
        else:
            assert _logged_stages(rec) == {4}, i
            outcomes["updated"] += 1
    assert sum(outcomes.values()) == 10
