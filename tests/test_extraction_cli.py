"""extract / compare / extractors from the command line, a third-party plugin, and
bad input."""

import json
import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tendon_taichi.io.recording import TENDONS_OF, read_recording, rewrite

PLUGIN = Path(__file__).parent / "plugins" / "demo_extractor"


@pytest.fixture(scope="module")
def plugin_path(tmp_path_factory):
    """The demo plugin installed (pip, no build isolation) into a folder of its own."""
    target = tmp_path_factory.mktemp("site")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                        "--no-index", "--target", str(target), str(PLUGIN)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return target


def test_extractors_lists_the_builtins(cli):
    r = cli("extractors", "--json")
    assert r.returncode == 0, r.stderr
    names = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    assert {"strands", "network_discovery", "path_cover"} <= set(names)
    assert names["path_cover"]["options"]["max_turn"] == 60.0


def test_extract_writes_json_svg_and_logs_into_the_recording(run_rrd, cli, tmp_path):
    rec = tmp_path / "copy.rrd"
    rec.write_bytes(run_rrd.read_bytes())
    svg = tmp_path / "t.svg"
    r = cli("extract", rec, "--extractor", "path_cover", "--option", "min_length=0.005", "--svg", svg, "--record",
            "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["stage"] == 4 and len(out["extractors"]) == 1
    e = out["extractors"][0]
    assert e["name"] == "path_cover"
    for key in ("count", "total_length", "total_turning", "max_turn", "kinks", "capstan_worst", "tension_cv",
                "coverage", "realizable_pose_error", "realizable_pose_error_rel", "idealized_pose_error_rel"):
        assert key in e["metrics"]
    assert e["metrics"]["count"] == len(e["tendons"]) >= 1
    assert e["metrics"]["clearance_min"] >= 0.02 * out["body_size"] * (1 - 1e-6)
    assert e["metrics"]["realizable_pose_error_rel_frictionless"] > 0
    # consolidation (default on) reports where it started and every step it took
    cons = e["consolidation"]
    assert cons["extracted_count"] == e["metrics"]["extracted_count"] >= e["metrics"]["count"]
    counts = [cons["extracted_count"]] + [s["count"] for s in cons["steps"]]
    for before, s, after in zip(counts, cons["steps"], counts[1:]):  # drop and join remove one; the others none
        assert after == before - (s["action"] in ("drop", "join"))
    assert counts[-1] == e["metrics"]["count"]
    # within the default bound: the extracted error + 0.1 % of L, or the 0.5 % budget
    bound = max(cons["extracted_realizable_pose_error_rel"] + 1e-3, 5e-3)
    assert e["metrics"]["realizable_pose_error_rel"] <= bound + 1e-12
    for t in e["tendons"]:
        assert set(t) >= {"waypoints", "length", "tension", "contraction"}
    root = ET.parse(svg).getroot()
    routes = [p for p in root.iter("{http://www.w3.org/2000/svg}path") if p.get("class") == "route"]
    assert len(routes) == len(e["tendons"]) and all(" C " in p.get("d") for p in routes)  # smooth paths
    # logged at the stage it came from; the file stays a valid recording of the run
    from rerun.chunk import RrdReader
    ents = {c.entity_path for c in RrdReader(rec).stream()}
    assert "/tendons/path_cover/summary" in ents and "/tendons/path_cover/rest" in ents
    assert out["record"] == str(rec) and len(read_recording(rec).stages) == 5
    assert json.loads(cli("replay", rec, "--json").stdout)["reproduces"]
    r2 = cli("extract", rec, "--extractor", "path_cover", "--stage", 2, "--no-record", "--no-consolidate", "--json")
    assert json.loads(r2.stdout)["stage"] == 2


def test_reading_a_recording_changes_it_only_when_asked(run_rrd, cli, tmp_path):
    """Without --record the recording is only read and nothing is written beside it;
    --record FILE puts the tendons in a file of their own with the run's recording
    id (the viewer shows the two as one recording), and never into a stranger's."""
    from rerun.chunk import RrdReader

    folder = tmp_path / "d"
    folder.mkdir()
    rec = folder / "run.rrd"
    rec.write_bytes(run_rrd.read_bytes())
    quick = ("--no-consolidate", "--extractors", "strands")
    r = cli("compare", rec, *quick)
    assert r.returncode == 0, r.stderr
    assert "tendons logged" not in r.stdout
    assert rec.read_bytes() == run_rrd.read_bytes() and os.listdir(folder) == ["run.rrd"]

    own = folder / "tendons.rrd"
    for stage in (3, 4):
        r = cli("compare", rec, *quick, "--stage", stage, "--record", own)
        assert r.returncode == 0, r.stderr
        assert f"tendons logged into: {own}" in r.stdout
    assert rec.read_bytes() == run_rrd.read_bytes()
    run_id = RrdReader(rec).recordings()[0].recording_id
    assert RrdReader(own).recordings()[0].recording_id == run_id
    chunks = list(RrdReader(own).stream())
    stages = {s for ch in chunks if ch.entity_path == "/tendons/strands/summary"
              for s in ch.to_record_batch().column("stage").to_pylist()}
    assert stages == {3, 4}  # the second run kept the first one's tendons
    assert sum(ch.entity_path == "/meta/tendons_of" for ch in chunks) == 1
    assert not any(ch.entity_path.startswith(("/stages", "/problem")) for ch in chunks)  # tendons only
    _one_line(cli("extract", own, "--extractor", "strands"), "holds only the tendons extracted from the run")

    other = folder / "other.rrd"
    other.write_bytes(run_rrd.read_bytes())  # a run's recording, not a tendons file
    stranger = folder / "stranger.rrd"  # the tendons of another run
    rewrite(stranger, "another-run", lambda ch: True,
            lambda rr, rec: rec.log(TENDONS_OF, rr.TextDocument(json.dumps({"recording": "x.rrd",
                                                                          "run_id": "another-run"})), static=True),
            lock=rec)
    for target, text in ((other, "does not hold tendons of"), (stranger, "does not hold tendons of"),
                         (folder / "t.txt", "must name an .rrd file"), (folder, "must name an .rrd file")):
        before = sorted(os.listdir(folder))
        _one_line(cli("compare", rec, *quick, "--record", target), text)
        assert sorted(os.listdir(folder)) == before
    _one_line(cli("compare", rec, *quick, "--record", "--no-record"), "contradict")


def test_compare_runs_every_extractor_with_a_picture(run_rrd, cli, tmp_path):
    png = tmp_path / "c.png"
    r = cli("compare", run_rrd, "--png", png, "--no-record", "--refine", "0", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert {e["name"] for e in out["extractors"]} >= {"strands", "network_discovery", "path_cover"}
    assert all("error" not in e for e in out["extractors"]) and png.read_bytes()[:4] == b"\x89PNG"
    r = cli("compare", run_rrd, "--no-record", "--no-consolidate", "--extractors", "strands", "path_cover")
    assert "strands" in r.stdout and "path_cover" in r.stdout and "as built" in r.stdout
    progress = r.stderr.splitlines()  # a line as each extractor starts and one with its result
    assert progress[0] == "compare: strands: extracting" and progress[1].startswith("compare: strands: ")
    assert "compare: path_cover: extracting" in progress and "as built" in progress[-1]
    quiet = cli("compare", run_rrd, "--no-record", "--no-consolidate", "--extractors", "strands", "--quiet")
    assert quiet.returncode == 0 and quiet.stderr == "" and "strands" in quiet.stdout
    raw = json.loads(cli("compare", run_rrd, "--no-record", "--no-consolidate", "--json").stdout)
    for e in raw["extractors"]:
        assert e["consolidation"]["steps"] == [] and e["consolidation"]["evaluations"] == 0
        assert e["metrics"]["count"] == e["metrics"]["extracted_count"]


def test_third_party_plugin_is_listed_and_used(run_rrd, cli, plugin_path):
    env = {"PYTHONPATH": os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")])}
    r = cli("extractors", "--json", env=env)
    names = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    assert names["strongest"]["distribution"] == "demo-extractor"
    assert "error" in names["broken"]  # a plugin that cannot be imported is reported, not fatal
    r = cli("compare", run_rrd, "--no-record", "--refine", "0", "--extractors", "strongest", "strands", "--json",
            env=env)
    assert r.returncode == 0, r.stderr
    out = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    assert out["strongest"]["metrics"]["count"] == 1 and "error" not in out["strands"]


def test_failing_plugins_do_not_stop_the_others(run_rrd, cli, plugin_path):
    env = {"PYTHONPATH": os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")])}
    r = cli("compare", run_rrd, "--no-record", "--refine", "0", "--extractors", "raises", "broken", "path_cover",
            "--json", env=env)
    assert r.returncode == 4
    out = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    assert "raised RuntimeError: this plugin always fails" in out["raises"]["error"]
    assert "failed to load" in out["broken"]["error"]
    errors = [line for line in r.stderr.splitlines() if line.startswith("tendon-taichi: error:")]
    assert len(errors) == 2 and "Traceback" not in r.stderr
    alone = json.loads(cli("compare", run_rrd, "--no-record", "--refine", "0", "--extractors", "path_cover",
                           "--json").stdout)
    (expected,) = alone["extractors"]
    assert out["path_cover"]["metrics"] == expected["metrics"]  # the failures changed nothing of the others
    assert [t["waypoints"] for t in out["path_cover"]["tendons"]] == [t["waypoints"] for t in expected["tendons"]]


def test_plugins_that_break_the_rules_are_named_and_harm_no_other(run_rrd, cli, plugin_path):
    """A plugin that edits the state in place, or returns waypoints off its nodes
    (1 m outside the body) or NaN, fails by name; the extractor after it is unharmed."""
    env = {"PYTHONPATH": os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")])}
    r = cli("compare", run_rrd, "--no-record", "--no-consolidate", "--extractors", "mutates", "outside",
            "nan_waypoints", "strands", "--json", env=env)
    assert r.returncode == 4, r.stderr
    out = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    assert "raised ValueError: assignment destination is read-only" in out["mutates"]["error"]
    assert "returned a malformed tendon (tendon 0: its waypoints are up to 1 m" in out["outside"]["error"]
    assert "a waypoint is not a finite number" in out["nan_waypoints"]["error"]
    errors = [line for line in r.stderr.splitlines() if line.startswith("tendon-taichi: error:")]
    assert len(errors) == 3 and "Traceback" not in r.stderr
    alone = json.loads(cli("compare", run_rrd, "--no-record", "--no-consolidate", "--extractors", "strands",
                           "--json").stdout)
    assert out["strands"]["metrics"] == alone["extractors"][0]["metrics"]
    assert out["strands"]["tendons"] == alone["extractors"][0]["tendons"]


def test_a_plugin_that_hangs_is_given_up(run_rrd, cli, plugin_path):
    env = {"PYTHONPATH": os.pathsep.join([str(plugin_path), os.environ.get("PYTHONPATH", "")])}
    t0 = time.perf_counter()
    r = cli("compare", run_rrd, "--no-record", "--no-consolidate", "--extractors", "sleeps", "strands",
            "--plugin-timeout", "1", "--json", env=env)
    assert r.returncode == 4 and time.perf_counter() - t0 < 300, r.stderr  # the plugin sleeps 600 s
    out = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    assert out["sleeps"]["error"] == "extractor 'sleeps' did not finish within 1 s (--plugin-timeout)"
    assert "compare: sleeps: extracting" in r.stderr.splitlines()  # the user sees what it is waiting for
    assert "error" not in out["strands"] and out["strands"]["metrics"]["count"] >= 1
    _one_line(cli("compare", run_rrd, "--no-record", "--plugin-timeout", "0"), "--plugin-timeout must be")


def test_a_recording_that_cannot_be_rewritten_keeps_the_results(run_rrd, tmp_path, monkeypatch, capsys):
    """As in a read-only folder (which root, running these tests, could still write):
    the results reach stdout, one error line says why, the recording is unchanged."""
    import tendon_taichi.io.recording as recording
    from tendon_taichi.cli.main import main

    def refuse(path, data):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(recording, "replace_with_bytes", refuse)
    rec = tmp_path / "run.rrd"
    rec.write_bytes(run_rrd.read_bytes())
    assert main(["compare", str(rec), "--no-consolidate", "--extractors", "strands", "--record", "--json"]) == 2
    got = capsys.readouterr()
    out = json.loads(got.out)
    assert out["extractors"][0]["metrics"]["count"] >= 1
    assert out["record_error"].startswith(f"the tendons were not logged into '{rec}' (Permission denied)")
    lines = [ln for ln in got.err.strip().splitlines() if not ln.startswith("compare: ")]  # progress aside
    assert len(lines) == 1 and lines[0].startswith("tendon-taichi: error: the tendons were not logged into")
    assert rec.read_bytes() == run_rrd.read_bytes() and os.listdir(tmp_path) == ["run.rrd"]


def test_the_compare_picture_draws_each_extractors_tendons(run_rrd):
    from tendon_taichi.apps.extract import extract
    from tendon_taichi.apps.settings import ExtractSettings
    from tendon_taichi.extract.settings import ConsolidationSettings
    from tendon_taichi.io.plots import compare_figure

    ex = extract(run_rrd, ExtractSettings(names=("strands", "path_cover"), consolidation=ConsolidationSettings(-1.0)))
    fig = compare_figure(ex)
    idealized, *panels, _colorbar = fig.axes
    assert len(panels) == 2 and "idealized" in idealized.get_title()
    for ax, r in zip(panels, ex.results):
        assert ax.get_title().startswith(f"{r.name}: {r.metrics['count']} tendons")
        paths = [ln for ln in ax.get_lines() if ln.get_linewidth() == 2.2]  # one polyline per tendon
        assert len(paths) == len(r.tendons) >= 1
        for ln, t in zip(paths, r.tendons):
            assert len(ln.get_xdata()) == len(t.waypoints)


def _one_line(r, text):
    lines = r.stderr.strip().splitlines()
    assert r.returncode != 0 and len(lines) == 1 and text in lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_extract_bad_input(run_rrd, cli, tmp_path):
    _one_line(cli("extract", run_rrd, "--extractor", "nope", "--no-record"), "unknown extractor 'nope'")
    _one_line(cli("--max-dofs", 10, "replay", run_rrd), "has 714 degrees of freedom and 548 fibers, more than 10")
    _one_line(cli("extract", run_rrd, "--extractor", "strands", "--option", "speed=3", "--no-record"),
              "has no option 'speed'")
    _one_line(cli("extract", run_rrd, "--extractor", "strands", "--stage", 9, "--no-record"), "--stage 9")
    _one_line(cli("compare", run_rrd, "--consolidate-tol", "-0.1", "--no-record"), "--consolidate-tol")
    _one_line(cli("compare", run_rrd, "--join-gap", "nan", "--no-record"), "--join-gap")
    _one_line(cli("compare", run_rrd, "--consolidate-budget", "-inf", "--no-record"), "--consolidate-budget")
    _one_line(cli("compare", run_rrd, "--refine", "-1", "--no-record"), "--refine must be an integer >= 0")
    _one_line(cli("extract", run_rrd, "--extractor", "strands", "--screen", "-2", "--no-record"),
              "--screen must be an integer >= 0")
    _one_line(cli("extract", tmp_path / "none.rrd", "--extractor", "strands"), "does not exist")
    _one_line(cli("compare", run_rrd, "--friction", "-1", "--no-record"), "--friction must be a number in [0, 2]")
    _one_line(cli("compare", run_rrd, "--clearance", "inf", "--no-record"), "--clearance must be a number in")
    from tendon_taichi import build_problem, load_scene
    from tendon_taichi.io.recording import Recorder
    p = build_problem(load_scene("finger"), 1)
    empty = Recorder(tmp_path / "empty.rrd", p, p.scene.optimize, {"run_id": "e", "resolution": 1})
    empty.write_header()
    empty.close()
    _one_line(cli("compare", tmp_path / "empty.rrd"), "no completed stage")


def test_a_worker_process_consolidates_to_the_same_results(run_rrd):
    """With a worker process consolidating the extractors' tendons beside this one,
    every extractor's tendons, consolidation and figures are the same."""
    from tendon_taichi.apps.extract import extract
    from tendon_taichi.apps.settings import ExtractSettings
    from tendon_taichi.extract.settings import ConsolidationSettings
    from tendon_taichi.tasks.pool import Pool

    names = ["strands", "path_cover", "network_discovery"]
    cons = ConsolidationSettings(refine=0)
    alone = extract(run_rrd, ExtractSettings(names=tuple(names), consolidation=cons))
    with Pool(1) as pool:
        shared = extract(run_rrd, ExtractSettings(names=tuple(names), consolidation=cons), workers=pool)
        assert pool.broken is None
    assert [r.name for r in shared.results] == names
    for a, b in zip(alone.results, shared.results):
        assert a.error is None and b.error is None
        assert [t.waypoints.tolist() for t in a.tendons] == [t.waypoints.tolist() for t in b.tendons]
        assert a.metrics == b.metrics
        ja, jb = a.consolidation.as_json(), b.consolidation.as_json()
        assert {**ja, "route_s": 0} == {**jb, "route_s": 0}
        assert a.consolidation.layout.source == b.consolidation.layout.source
