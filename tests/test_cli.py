"""The command line as a user runs it: outputs, formats and bad input."""

import importlib
import json
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np
import pytest
from test_scene import BAD

from tendon_taichi import load_scene
from tendon_taichi.files import file_stem
from tendon_taichi.io.export import EXPORT_KEYS


def test_console_script_is_installed():
    eps = [e for e in entry_points(group="console_scripts") if e.name == "tendon-taichi"]
    assert eps and eps[0].value == "tendon_taichi.cli:main"


def test_a_reader_that_stops_early_ends_the_command_quietly():
    """``tendon-taichi scenes --json | head -c0``: exit status 141 (SIGPIPE's), no traceback, no
    'internal error'."""
    p = subprocess.Popen([sys.executable, "-m", "tendon_taichi", "scenes", "--json"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # before the command prints
    err = p.stderr.read().decode()
    assert p.wait(120) == 141
    assert err == "", err


def test_a_broken_pipe_that_is_not_stdout_is_an_internal_error(monkeypatch, capsys):
    cli_main = importlib.import_module("tendon_taichi.cli.main")

    def broken():
        raise BrokenPipeError("a worker's pipe")
    monkeypatch.setattr(cli_main.runtime, "check", broken)
    assert cli_main.main(["scenes"]) == 1
    assert "internal error: BrokenPipeError: a worker's pipe" in capsys.readouterr().err


def test_scenes_lists_builtins(cli):
    r = cli("scenes")
    assert r.returncode == 0
    names = [line.split()[0] for line in r.stdout.splitlines()]
    assert {"t_shape", "finger", "gripper"} <= set(names)
    data = json.loads(cli("scenes", "--json").stdout)
    assert {s["name"] for s in data["scenes"]} >= {"t_shape", "finger", "gripper"}


def test_simulate_writes_export_vtu_and_json(cli, tmp_path):
    import meshio

    out, vtu = tmp_path / "o.npz", tmp_path / "o.vtu"
    r = cli("simulate", "finger", "--uniform", 0.05, "--export", out, "--vtu", vtu, "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)  # stdout holds only the JSON
    for key in ("scene", "resolution", "nodes", "triangles", "fibers", "dofs", "newton_iterations",
                "linear_iterations", "residual", "pose_error", "time_s", "export"):
        assert key in summary
    assert summary["residual"] <= 1e-10 and summary["scene"] == "finger"
    d = np.load(out)
    assert set(EXPORT_KEYS) <= set(d.files)
    assert d["x"].shape == d["nodes"].shape and len(d["tau"]) == len(d["fibers"]) == len(d["a0"])
    assert np.allclose(d["ac"], 0.05 * d["a0"])
    assert float(d["youngs_modulus"]) == 5e4 and float(d["eps"]) == 0.01
    m = meshio.read(vtu)
    types = [c.type for c in m.cells]
    assert types == ["triangle", "line"]
    assert np.allclose(m.cell_data["tension"][1], d["tau"])
    assert np.allclose(m.point_data["displacement"][: len(d["x"]), :2], d["x"] - d["nodes"])


def test_simulate_quiet_says_nothing_on_stderr(cli, tmp_path):
    loud = cli("simulate", "finger", "--uniform", 0.05, "--export", tmp_path / "a.npz")
    quiet = cli("simulate", "finger", "--uniform", 0.05, "--export", tmp_path / "b.npz", "--quiet")
    assert loud.returncode == quiet.returncode == 0
    assert "solving" in loud.stderr and quiet.stderr == "" and "export:" in quiet.stdout


def test_contract_file_equals_uniform(cli, tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert cli("simulate", "finger", "--uniform", 0.04, "--export", a).returncode == 0
    ratios = np.full(len(np.load(a)["a0"]), 0.04)
    np.save(tmp_path / "r.npy", ratios)
    r = cli("simulate", "finger", "--contract", tmp_path / "r.npy", "--export", b, "--solver", "direct")
    assert r.returncode == 0, r.stderr
    assert np.abs(np.load(a)["x"] - np.load(b)["x"]).max() <= 1e-9


def _assert_one_line_error(r, message):
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("tendon-taichi: error:") and message in lines[0], lines[0]
    assert "Traceback" not in r.stderr and r.stdout == ""


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_scene_gives_one_line_and_writes_nothing(cli, tmp_path, case):
    text, message = BAD[case]
    (tmp_path / "bad.toml").write_text(text)
    out = tmp_path / "out.npz"
    r = cli("simulate", tmp_path / "bad.toml", "--uniform", 0.05, "--export", out)
    _assert_one_line_error(r, message)
    assert list(tmp_path.iterdir()) == [tmp_path / "bad.toml"]


@pytest.mark.parametrize("args,message", [
    (["simulate", "nope", "--uniform", 0.1], "unknown scene 'nope'"),
    (["simulate", "t_shape", "--uniform", 0.5], "must lie in [-0.5, 0.33]"),
    (["simulate", "t_shape", "--uniform", 0.1, "--level", 0], "--level must be >= 1"),
    (["simulate", "t_shape", "--uniform", 0.1, "--resolution", 0], "--level must be >= 1"),
    (["simulate", "t_shape"], "one of the arguments --uniform --contract is required"),
    (["simulate", "t_shape", "--contract", "missing.npy"], "does not exist"),
    (["simulate", "t_shape", "--uniform", 0.1, "--solver", "lu"], "invalid choice"),
    (["frobnicate"], "invalid choice"),
    (["simulate", "finger", "--resolution", 99, "--uniform", 0.05], "finger at level 99 would have about 1.4e+32"),
    (["--max-dofs", 100, "simulate", "finger", "--uniform", 0.05], "more than 100 (--max-dofs 100)"),
    (["--max-dofs", 0, "simulate", "finger", "--uniform", 0.05], "--max-dofs must be >= 1"),
    (["--threads", 100000, "simulate", "finger", "--uniform", 0.05], "threads must be 1.."),
    (["optimize", "t_shape", "--k0", 1, "--k-min", 5], "homotopy.k_min (5) must be <= k0 (1)"),
    (["bench", "--forward-max-fibers", -1], "--forward-max-fibers must be >= 0"),
    (["sweep", "s.toml", "--scheduler", "not a url"], "--scheduler 'not a url' is not a Dask scheduler address"),
])
def test_bad_command_lines(cli, tmp_path, args, message):
    _assert_one_line_error(cli(*args, cwd=tmp_path), message)
    assert not (tmp_path / "recordings").exists()


@pytest.mark.parametrize("args,message", [
    (["scenes", "--json", "{file}/x.json"], "cannot write the --json file"),
    (["simulate", "t_shape", "--uniform", 0.05, "--export", "{folder}"], "the export '{folder}' is a folder"),
    (["simulate", "t_shape", "--uniform", 0.05, "--vtu", "{folder}"], "the VTU file '{folder}' is a folder"),
    (["optimize", "t_shape", "--png", "{file}/sub/x.png"], "'{file}' is a file, not a folder"),
    (["extract", "{file}", "--extractor", "strands", "--svg", "{folder}"], "the drawing '{folder}' is a folder"),
    (["bench", "t_shape", "--levels", 1, "--out", "{file}"], "'{file}' is a file, not a folder"),
    (["design", "t_shape", "--out", "{file}/d"], "'{file}' is a file, not a folder"),
])
def test_an_output_that_cannot_be_written_is_refused_before_any_work(cli, tmp_path, args, message):
    """Every flag that names an output (a file, or --out's folder) is tried first:
    one line, exit 2, and nothing computed or written (no recording, no folders)."""
    (tmp_path / "file").write_text("x")
    (tmp_path / "folder").mkdir()
    names = {"file": tmp_path / "file", "folder": tmp_path / "folder"}
    r = cli(*[str(a).format(**names) for a in args], cwd=tmp_path)
    _assert_one_line_error(r, message.format(**names))
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["file", "folder"]


@pytest.mark.parametrize("args", [["design", "t_shape", "--extractors", "strands", "bogus"],
                                  ["planted-bench", "--extractors", "bogus"]])
def test_an_unknown_extractor_is_refused_before_any_work(cli, tmp_path, args):
    _assert_one_line_error(cli(*args, cwd=tmp_path), "unknown extractor 'bogus' (installed: ")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["TENDON_TAICHI_FACTOR_THREADS", "TENDON_TAICHI_THREADS",
                                  "TENDON_TAICHI_PARALLEL_THRESHOLD", "TENDON_TAICHI_BLAS_THREADS"])
def test_a_bad_runtime_variable_is_refused_before_any_work(cli, tmp_path, name):
    r = cli("optimize", "t_shape", "--quiet", cwd=tmp_path, env={name: "two"})
    _assert_one_line_error(r, f"{name} must be an integer (got 'two')")
    assert list(tmp_path.iterdir()) == []


def test_wrong_length_contract_file(cli, tmp_path):
    np.save(tmp_path / "r.npy", np.zeros(7))
    r = cli("simulate", "t_shape", "--contract", tmp_path / "r.npy", cwd=tmp_path)
    _assert_one_line_error(r, "has 548 fibers")


def test_a_contract_file_must_be_a_1d_npy_array(cli, tmp_path):
    np.save(tmp_path / "square.npy", np.zeros((3, 3)))
    (tmp_path / "text.npy").write_text("0.1 0.2\n")
    _assert_one_line_error(cli("simulate", "t_shape", "--contract", tmp_path / "square.npy", cwd=tmp_path),
                           "holds a (3, 3) array: give one ratio per fiber")
    _assert_one_line_error(cli("simulate", "t_shape", "--contract", tmp_path / "text.npy", cwd=tmp_path),
                           "is not a .npy file")


@pytest.mark.parametrize("name,stem", [("t_shape", "t_shape"), ("../../escaped", "_.._escaped"),
                                       ("a/b", "a_b"), (".hidden", "hidden"), ("...", "unnamed"),
                                       ("fingér 2", "fingér_2")])
def test_file_stem_names_one_file(name, stem):
    assert file_stem(name) == stem


def test_a_scene_name_cannot_steer_default_outputs(cli, tmp_path):
    """A scene named like a path writes its default output inside recordings/, as one file."""
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    text = load_scene("finger").source.replace('name = "finger"', 'name = "../../escaped/x"')
    (work / "s.toml").write_text(text)
    r = cli("simulate", "s.toml", "--uniform", 0.05, cwd=work)
    assert r.returncode == 0, r.stderr
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file())
    assert written == ["a/b/recordings/_.._escaped_x-r1-simulate.npz", "a/b/s.toml"]


def test_a_scene_name_cannot_steer_where_planted_writes(cli, tmp_path):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    text = load_scene("t_shape").source.replace('name = "t_shape"', 'name = "../../escaped"')
    (work / "s.toml").write_text(text)
    r = cli("planted", "s.toml", "--level", 1, "--tendons", 1, cwd=work)
    assert r.returncode == 0, r.stderr
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if p.is_file())
    assert written == ["a/b/_.._escaped_planted_1t_s0.json", "a/b/_.._escaped_planted_1t_s0.toml", "a/b/s.toml"]


def test_a_kernel_cache_that_cannot_be_written_is_a_warning_not_a_crash(tmp_path, monkeypatch, capsys):
    """Taichi aborts the process when it cannot save its kernel cache (a home folder
    that is not the user's); the runtime then starts without the cache and says so."""
    import taichi as ti

    from tendon_taichi.physics import runtime

    (tmp_path / "afile").write_text("x")
    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", str(tmp_path / "afile" / "ticache"))
    moved = runtime._kernel_cache(ti)
    assert moved["offline_cache"] and Path(moved["offline_cache_file_path"]).is_dir()  # a temporary one
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("tendon-taichi: warning: Taichi's kernel cache")
    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", str(tmp_path / "cache"))
    assert runtime._kernel_cache(ti) == {"offline_cache": True} and capsys.readouterr().err == ""


def test_a_stale_kernel_cache_lock_is_removed_and_a_fresh_one_kept(tmp_path, monkeypatch):
    """A run killed while Taichi held its cache's lock leaves the lock file; every
    later process would then fail to lock the cache and compile all its kernels
    again. One older than STALE_LOCK_S is removed; a fresh one (another process
    reading the cache now) is left alone."""
    import os
    import time

    import taichi as ti

    from tendon_taichi.physics import runtime

    monkeypatch.setenv("TI_OFFLINE_CACHE_FILE_PATH", str(tmp_path))
    lock = tmp_path / "ticache.lock"
    lock.write_text("")
    old = time.time() - runtime.STALE_LOCK_S - 5
    os.utime(lock, (old, old))
    assert runtime._kernel_cache(ti) == {"offline_cache": True} and not lock.exists()
    lock.write_text("")
    assert runtime._kernel_cache(ti) == {"offline_cache": True} and lock.exists()
