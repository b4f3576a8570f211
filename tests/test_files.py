"""Where outputs go: written atomically, through symbolic links, and into devices
and named pipes (``--json /dev/null``) without replacing them."""

import json
import os
import stat
import threading

import pytest

from tendon_taichi.files import atomic_path, check_writable, replace_with_bytes, write_json

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


def _reading(fifo):
    """Start a thread that reads the named pipe ``fifo`` to its end; returns (thread, chunks)."""
    got = []

    def read():
        with open(fifo, "rb") as fh:
            got.append(fh.read())

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t, got


def test_a_named_pipe_is_written_into_not_replaced(tmp_path):
    fifo = tmp_path / "out.json"
    os.mkfifo(fifo)
    check_writable(fifo)
    t, got = _reading(fifo)
    write_json({"a": 1}, fifo)
    t.join(10)
    assert json.loads(got[0]) == {"a": 1}
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]  # no temporary left beside it
    t, got = _reading(fifo)
    replace_with_bytes(fifo, b"recording")
    t.join(10)
    assert got == [b"recording"] and stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_failed_write_leaves_the_link_and_its_target_alone(tmp_path):
    target = tmp_path / "results" / "run7.json"
    target.parent.mkdir()
    target.write_text("{}\n")
    link = tmp_path / "latest.json"
    link.symlink_to(target)
    write_json({"b": 2}, link)
    assert link.is_symlink() and json.loads(target.read_text()) == {"b": 2}
    with pytest.raises(RuntimeError), atomic_path(link) as tmp:
        tmp.write_text("half")
        raise RuntimeError
    assert link.is_symlink() and json.loads(target.read_text()) == {"b": 2}
    replace_with_bytes(link, b"new")
    assert link.is_symlink() and target.read_bytes() == b"new"


def test_the_command_line_writes_json_into_a_named_pipe(cli, tmp_path):
    fifo = tmp_path / "scenes.json"
    os.mkfifo(fifo)
    t, got = _reading(fifo)
    r = cli("scenes", "--json", fifo)
    t.join(30)
    assert r.returncode == 0, r.stderr
    assert "t_shape" in {s["name"] for s in json.loads(got[0])["scenes"]}
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


@pytest.mark.skipif(not os.path.exists("/dev/stdout"), reason="no /dev/stdout")
def test_json_into_dev_stdout_reaches_the_pipe_behind_it(cli):
    """/dev/stdout is a link to /proc/self/fd/1, whose own link names no path where stdout
    is a pipe: written into as a stream, it is not resolved."""
    r = cli("scenes", "--json", "/dev/stdout")
    assert r.returncode == 0, r.stderr
    data, _ = json.JSONDecoder().raw_decode(r.stdout)  # then the command's "wrote /dev/stdout"
    assert "t_shape" in {s["name"] for s in data["scenes"]}
