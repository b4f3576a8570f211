"""sweep: cases as Dask tasks give the figures of the same cases run one by one in
this process; a re-run reuses them; an existing cluster (scheduler + workers on
127.0.0.1) gives the same figures; a worker killed mid-case is retried; Ctrl-C
keeps the finished cases; bad input is one line and writes nothing."""

import json
import math
import os
import signal
import subprocess
import sys
import time
import tomllib

import pytest
from distributed import Client

from conftest import run_cli
from tendon_taichi.tasks.engine import case_id
from tendon_taichi.errors import InputError, SceneError
from tendon_taichi.apps.sweep import load_sweep, parse_sweep, run_case

TINY = """
name = "tiny"
scenes = ["finger"]
levels = [1]
extractors = ["strands", "path_cover"]
[grid]
sparsity = [1.0e-4, 3.0e-4]
[set]
stage_iterations = 15
[consolidation]
refine = 0
[front]
beam = 1
converge = false
"""


def _leaves(prefix, value, out):
    if isinstance(value, dict):
        for k, v in value.items():
            _leaves(f"{prefix}.{k}", v, out)
    elif isinstance(value, (int, float)) and not isinstance(value, bool) and "time" not in prefix:
        out[prefix] = float(value)
    return out


def figures(row: dict) -> dict:
    """Every number of a case's optimize, extract and design figures, except timings."""
    return _leaves("optimize", row["optimize"], _leaves("extract", row["extract"], _leaves("design", row["design"], {})))


def assert_same_figures(rows: list[dict], reference: dict[str, dict]) -> None:
    assert {r["case"] for r in rows} == set(reference)
    for r in rows:
        assert "error" not in r, r["error"]
        got, want = figures(r), reference[r["case"]]
        assert got.keys() == want.keys()
        for k in want:
            assert math.isclose(got[k], want[k], rel_tol=1e-9, abs_tol=1e-300), (r["case"], k, got[k], want[k])


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    (d / "tiny.toml").write_text(TINY)
    return d / "tiny.toml"


@pytest.fixture(scope="module")
def in_process(sweep_file, tmp_path_factory):
    """The figures of every case, each run by sweep.run_case in this process."""
    sw = load_sweep(sweep_file)
    out = tmp_path_factory.mktemp("one-by-one")
    return {c.id: figures(run_case(c.scene, c.level, str(out / c.id), sw.case_settings())) for c in sw.cases}


def _sweep(sweep_file, out, *extra, timeout=600):
    r = run_cli("sweep", sweep_file, "--out", out, "--json", *extra, timeout=timeout)
    assert r.returncode == 0, r.stderr
    result = json.loads(r.stdout)
    assert result == json.loads((out / "sweep.json").read_text())
    return result, r.stderr


def test_a_sweep_may_vary_the_tendon_friction():
    sw = parse_sweep({"scenes": ["finger"], "grid": {"friction": [0.0, 0.2]}, "set": {"clearance": 0.03}})
    assert [(c.scene.tendons.friction, c.scene.tendons.clearance) for c in sw.cases] == [(0.0, 0.03), (0.2, 0.03)]
    assert sw.cases[0].scene.optimize == sw.cases[1].scene.optimize and sw.cases[0].id != sw.cases[1].id
    over = parse_sweep({"scenes": ["finger"]}, tendons={"friction": 0.3, "clearance": None})
    assert over.cases[0].scene.tendons.friction == 0.3 and over.cases[0].id != sw.cases[0].id


def test_expansion_and_ids(tmp_path):
    sweep_file = tmp_path / "two.toml"  # two scenes x two sparsities
    sweep_file.write_text(TINY.replace('scenes = ["finger"]', 'scenes = ["t_shape", "finger"]'))
    sw = load_sweep(sweep_file)
    assert sw.consolidation == {"refine": 0} and sw.front == {"beam": 1, "converge": False, "coarse": True}
    assert len(sw.cases) == 4
    front = TINY[TINY.index("[front]"):]
    plain = parse_sweep(tomllib.loads(TINY.replace(front, "")), "plain.toml")
    default = parse_sweep(tomllib.loads(TINY.replace(front, "[front]\nbeam = 3\nconverge = true\n")), "d.toml")
    assert plain.front == default.front == {"beam": 3, "converge": True, "coarse": True}
    assert [c.id for c in plain.cases] == [c.id for c in default.cases]  # the defaults leave the ids as they were
    assert not {c.id for c in plain.cases} & {c.id for c in load_sweep(sweep_file).cases if c.scene.name == "finger"}
    assert [(c.scene.name, c.settings["sparsity"]) for c in sw.cases] == [
        ("t_shape", 1e-4), ("t_shape", 3e-4), ("finger", 1e-4), ("finger", 3e-4)]
    assert all(c.settings["stage_iterations"] == 15 and c.scene.optimize.stage_iterations == 15 for c in sw.cases)
    assert [c.scene.optimize.sparsity for c in sw.cases] == [1e-4, 3e-4, 1e-4, 3e-4]
    assert len({c.id for c in sw.cases}) == 4
    assert [c.id for c in load_sweep(sweep_file).cases] == [c.id for c in sw.cases]  # stable
    assert case_id({"a": 1, "b": 2.0}) == case_id({"b": 2.0, "a": 1})
    assert case_id({"a": 1, "b": 2.0}) != case_id({"a": 1, "b": 2.5})


@pytest.mark.parametrize("doc, message", [
    ({"scenes": ["t_shape"], "colour": 1}, "unknown key 'colour'"),
    ({"scenes": []}, "'scenes' must be a non-empty list"),
    ({"scenes": ["no_such_scene"]}, "unknown scene 'no_such_scene'"),
    ({"scenes": ["t_shape"], "levels": [0]}, "'levels' must be"),
    ({"scenes": ["t_shape"], "extractors": ["nope"]}, "unknown extractor 'nope'"),
    ({"scenes": ["t_shape"], "grid": {"sparsity": 1e-4}}, "grid.sparsity must be a non-empty list"),
    ({"scenes": ["t_shape"], "grid": {"sparsty": [1e-4]}}, "unknown optimize setting 'sparsty'"),
    ({"scenes": ["t_shape"], "grid": {"sparsity": [-1.0]}}, "sparsity"),
    ({"scenes": ["t_shape"], "grid": {"sparsity": [1e-4]}, "set": {"sparsity": 1e-4}}, "both in [grid] and in [set]"),
    ({"scenes": ["t_shape"], "solver": "lu"}, "'solver' must be one of"),
    ({"scenes": ["t_shape"], "consolidation": {"refine": -1}}, "consolidation.refine must be an integer >= 0"),
    ({"scenes": ["t_shape"], "consolidation": {"rounds": 1}}, "unknown consolidation setting 'rounds'"),
    ({"scenes": ["t_shape"], "front": {"beam": 0}}, "front.beam must be an integer >= 1"),
    ({"scenes": ["t_shape"], "front": {"beam": 1.5}}, "front.beam must be an integer >= 1"),
    ({"scenes": ["t_shape"], "front": {"converge": "no"}}, "front.converge must be true or false"),
    ({"scenes": ["t_shape"], "front": {"coarse": 1}}, "front.coarse must be true or false"),
    ({"scenes": ["t_shape"], "front": {"width": 2}}, "unknown front setting 'width'"),
    ({"scenes": ["t_shape"], "front": 3}, "[front] must be a table"),
    ({"scenes": ["t_shape"], "grid": {"friction": [0.1, -0.1]}}, "tendons.friction must be"),
])
def test_bad_sweep_files_are_rejected(doc, message):
    with pytest.raises((InputError, SceneError), match=message.replace("[", r"\[").replace("]", r"\]")):
        parse_sweep(doc, "bad.toml")


@pytest.mark.parametrize("text, extra, message", [
    ("scenes = [", (), "invalid TOML"),
    ('scenes = ["t_shape"]\n[grid]\nwobble = [1]\n', (), "unknown optimize setting 'wobble'"),
    ('scenes = ["nowhere.toml"]\n', (), "does not exist"),
    ('scenes = ["t_shape"]\n', ("--scheduler", "tcp://127.0.0.1:9"), "cannot reach the Dask scheduler"),
    ('scenes = ["t_shape"]\n', ("--workers", "-1"), "--workers must be >= 0"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, text, extra, message):
    (tmp_path / "s.toml").write_text(text)
    r = run_cli("sweep", tmp_path / "s.toml", "--out", tmp_path / "out", *extra, timeout=120)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "out" / "sweep.json").exists()


def test_local_cluster_matches_one_by_one_and_reruns_reuse(sweep_file, in_process, tmp_path):
    out = tmp_path / "out"
    result, err = _sweep(sweep_file, out, "--workers", "2")
    assert result["engine"]["kind"] == "local" and result["engine"]["workers"] == 2
    assert "dashboard" in err and "[2/2]" in err
    assert result["failed"] == 0 and not any(r["reused"] for r in result["cases"])
    assert_same_figures(result["cases"], in_process)
    assert len({r["worker"] for r in result["cases"]}) == 2  # both workers took cases
    startup = result["engine"]["worker_startup"]  # Taichi started once per worker process, then warmed up
    assert len({w["pid"] for w in startup}) == 2 and all(w["warm_up_s"] > 0 for w in startup)
    assert {r["worker"].rsplit(":", 1)[1] for r in result["cases"]} == {str(w["pid"]) for w in startup}
    for r in result["cases"]:
        d = out / "cases" / r["case"]
        assert {"run.rrd", "run.npz", "optimize.json", "compare.json", "result.json"} <= {p.name for p in d.iterdir()}
        compare = json.loads((d / "compare.json").read_text())
        assert [e["name"] for e in compare["extractors"]] == ["strands", "path_cover"]
        search = json.loads((d / "design.json").read_text())["search"]
        assert search["beam"] == 1 and search["converged_resolution"] is None  # the [front] table reached it
    header = (out / "sweep.csv").read_text().splitlines()[0].split(",")
    assert {"case", "settings.sparsity", "optimize.pose_error_rel", "extract.strands.count",
            "extract.path_cover.realizable_pose_error_rel", "design.count", "design.capstan_worst",
            "time_s"} <= set(header)
    assert (out / "sweep.png").read_bytes()[:4] == b"\x89PNG"
    _check_figure(result)

    again, _ = _sweep(sweep_file, out, "--workers", "2")
    assert all(r["reused"] for r in again["cases"]) and again["engine"]["kind"] == "none"
    assert_same_figures(again["cases"], in_process)


@pytest.fixture(scope="module")
def dask_cluster(tmp_path_factory):
    """`dask scheduler` and two `dask worker` processes on 127.0.0.1."""
    d = tmp_path_factory.mktemp("cluster")
    sched_file = d / "scheduler.json"
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--dashboard-address", ":0", "--scheduler-file", str(sched_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(600):
            if sched_file.exists() and sched_file.stat().st_size:
                break
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        for _ in range(2):
            procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", "--scheduler-file",
                                           str(sched_file), "--nthreads", "1", "--nworkers", "1",
                                           "--host", "127.0.0.1"],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout=30) as c:  # both workers registered, so the engine sees 2
            c.wait_for_workers(2, timeout=120)
        yield address
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()


def test_existing_cluster_gives_the_same_figures(sweep_file, in_process, dask_cluster, tmp_path):
    result, err = _sweep(sweep_file, tmp_path / "out", "--scheduler", dask_cluster)
    assert result["engine"]["kind"] == "scheduler" and result["engine"]["workers"] == 2
    assert_same_figures(result["cases"], in_process)
    with Client(dask_cluster, timeout=10) as c:  # the command left the cluster running
        assert len(c.scheduler_info()["workers"]) == 2


def test_a_worker_killed_mid_case_is_retried(sweep_file, in_process, dask_cluster, tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "tendon_taichi", "sweep", str(sweep_file), "--out", str(out),
                             "--scheduler", dask_cluster, "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed = None
    with Client(dask_cluster, timeout=10) as c:
        deadline = time.time() + 300
        while killed is None and time.time() < deadline and proc.poll() is None:
            busy = {w: ts for w, ts in c.processing().items() if ts}
            if busy and list(out.glob("cases/*/run.rrd")):  # a case is under way
                pids = c.run(os.getpid)
                killed = pids[next(iter(busy))]
                os.kill(killed, signal.SIGKILL)
            time.sleep(0.2)
    stdout, stderr = proc.communicate(timeout=600)
    assert killed is not None, "no case was seen running"
    assert proc.returncode == 0, stderr
    result = json.loads(stdout)
    assert len(result["cases"]) == 2 and result["failed"] == 0
    assert_same_figures(result["cases"], in_process)
    with Client(dask_cluster, timeout=10) as c:  # the nanny restarted the killed worker
        c.wait_for_workers(2, timeout=60)


def test_ctrl_c_keeps_the_finished_cases(sweep_file, in_process, tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "tendon_taichi", "sweep", str(sweep_file), "--out", str(out),
                             "--workers", "1"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 300
    while not list(out.glob("cases/*/result.json")) and time.time() < deadline and proc.poll() is None:
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr.strip().splitlines()[-1]
    result = json.loads((out / "sweep.json").read_text())
    assert result["interrupted"] and len(result["cases"]) == 1
    assert_same_figures(result["cases"], {r["case"]: in_process[r["case"]] for r in result["cases"]})
    assert (out / "sweep.csv").read_text().count("\n") == len(result["cases"]) + 1


def test_a_failing_case_is_recorded_and_the_sweep_goes_on(tmp_path):
    from tendon_taichi.body.scene import load_scene

    text = load_scene("finger").source
    assert "point = [0.10, 0.01]" in text
    (tmp_path / "bad.toml").write_text(text.replace("point = [0.10, 0.01]", "point = [0.50, 0.01]")
                                       .replace('name = "finger"', 'name = "finger_bad"'))
    (tmp_path / "s.toml").write_text('scenes = ["finger", "bad.toml"]\nextractors = ["strands"]\n'
                                     '[set]\nstage_iterations = 5\n[consolidation]\nrefine = 0\n'
                                     '[front]\nbeam = 1\nconverge = false\n')
    out = tmp_path / "out"
    r = run_cli("sweep", tmp_path / "s.toml", "--out", out, "--workers", "0", "--json")
    assert r.returncode == 4, r.stderr  # finished, with a failed case
    result = json.loads(r.stdout)
    good, bad = result["cases"]
    assert "error" not in good and good["extract"]["strands"]["count"] >= 1
    assert "lies outside the body" in bad["error"] and "Traceback" in bad["traceback"]
    assert result["failed"] == 1 and result["engine"]["kind"] == "in-process"
    assert not (out / "cases" / bad["case"] / "result.json").exists()
    again = json.loads(run_cli("sweep", tmp_path / "s.toml", "--out", out, "--workers", "0", "--json").stdout)
    assert [c["reused"] for c in again["cases"]] == [True, False]  # the failed one is tried again
    assert again["cases"][0]["optimize"] == good["optimize"]


def _check_figure(result):
    """The sweep's picture: a column per swept setting, a row per figure, and in the
    tendon-count row one point per case for each scene and extractor."""
    from tendon_taichi.io.plots import sweep_figure

    fig = sweep_figure(result)
    dims = [k for k, v in result["grid"].items() if len(set(v)) > 1] + (["level"] if len(result["levels"]) > 1 else [])
    assert len(fig.axes) == 4 * len(dims)
    counts = fig.axes[0].get_lines()  # the first row, first column: tendon counts
    assert {ln.get_label() for ln in counts} == {f"{c['scene']} / {n}" for c in result["cases"]
                                                for n in result["extractors"]}
    points = sorted(y for ln in counts for y in ln.get_ydata())
    assert points == sorted(c["extract"][n]["count"] for c in result["cases"] for n in result["extractors"])
