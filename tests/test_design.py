"""``design`` end to end on a small scene, as a user runs it: every output there,
design.json as the contract says, the fabrication drawing an SVG with one
smooth path per tendon inside the body, the as-built equilibrium in force
balance from its export alone with its tensions following the capstan law,
the routes in the recording, progress on stderr; the recommendation rule; bad
values one clear line, nothing written."""

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import shapely

from reference import as_built_residual
from tendon_taichi.apps.design import recommend, unaccounted
from tendon_taichi.io.recording import read_chunks, read_recording
from tendon_taichi.solve.cholesky import cholesky_library

SCENE = """
name = "small finger"
[body]
outline = [[0.0, 0.0], [0.07, 0.0], [0.07, 0.016], [0.0, 0.016]]
max_triangle_area = 1.2e-5
[fibers]
spacing = 0.005
[[fixed]]
box = [[-0.001, -0.001], [0.004, 0.017]]
[[targets]]
point = [0.07, 0.008]
goal = [0.066, 0.02]
[tendons]
friction = 0.15
"""
SVG = "{http://www.w3.org/2000/svg}"
#: how far (x L) a front entry may be above the one with a tendon fewer: the as-built soft IK's
#: own precision (a pose reached within a few 1e-7 L at both counts differs in the last digits)
MONOTONE = 1e-6


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    from conftest import run_cli

    d = tmp_path_factory.mktemp("design")
    (d / "finger.toml").write_text(SCENE)
    r = run_cli("design", "finger.toml", "--out", "out", "--stage-iterations", "25", "--k-min", "0.1",
                "--extractors", "strands", "path_cover", "--refine", "1", "--min-capstan", "0.5", "--json", "out.json",
                cwd=d)
    assert r.returncode == 0, r.stderr
    return d, r


def test_design_writes_every_output_and_nothing_else(designed):
    d, r = designed
    assert sorted(p.name for p in (d / "out").iterdir()) == sorted(
        ["run.rrd", "run.npz", "as_built.npz", "design.json", "design.svg", "design.png", "front.png"])
    assert sorted(p.name for p in d.iterdir()) == ["finger.toml", "out", "out.json"]
    assert "worker process stopped" not in r.stderr  # its warm-up (a short design) ran through
    summary = json.loads((d / "out" / "design.json").read_text())
    assert summary == json.loads((d / "out.json").read_text())
    assert summary["provenance"]["cholesky"] == cholesky_library()  # what made the design's numbers
    assert read_recording(d / "out" / "run.rrd").meta["cholesky"] == cholesky_library()
    for key in ("scene", "resolution", "body_size", "friction", "clearance", "budget", "recommended", "front",
                "time_s"):
        assert key in summary
    assert summary["friction"] == 0.15 and summary["clearance"] == 0.02 and summary["budget"] == 0.005
    rec = summary["recommended"]
    assert summary["min_capstan"] == 0.5 and rec["meets_min_capstan"] is (rec["metrics"]["capstan_worst"] >= 0.5)
    assert rec["count"] == len(rec["tendons"]) >= 1
    for t in rec["tendons"]:
        assert len(t["contraction"]) == 1 and t["tension"] > 0 and 0 < t["capstan"] <= 1
        assert t["capstan"] == pytest.approx(np.exp(-0.15 * t["turning"]))
        assert t["waypoints"][0] == t["anchor"] and t["waypoints"][-1] == t["pull_end"]
        assert t["clearance_min"] >= 0.02 * summary["body_size"] * (1 - 1e-6)  # the finger is wide enough
    assert not any("clearance asked" in w for w in summary["warnings"])
    m = rec["metrics"]
    for key in ("count", "total_length", "total_turning", "max_turn", "kinks", "capstan_worst", "tension_cv",
                "coverage", "realizable_pose_error_rel", "realizable_pose_error_rel_frictionless", "clearance_min"):
        assert key in m
    assert m["clearance_min"] >= 0.02 * summary["body_size"] * (1 - 1e-6)
    assert [e["count"] for e in summary["front"]] == sorted({e["count"] for e in summary["front"]})
    for e in summary["front"]:
        assert set(e) >= {"count", "realizable_pose_error_rel", "realizable_pose_error_rel_level", "capstan_worst",
                          "kinks", "total_length", "source", "converged_resolution", "routes"}
        assert e["converged_resolution"] == 2  # re-solved on the level-2 mesh
        assert len(e["routes"]) == e["count"]  # what --routes-from reads back
        assert all(len(q["control_points"]) >= 2 and len(q["contraction_ratio"]) == 1 for q in e["routes"])
    counts = [e["count"] for e in summary["front"]]
    assert counts == list(range(1, len(counts) + 1))  # every count from 1
    errors = [e["realizable_pose_error_rel"] for e in summary["front"]]  # what is reported and recommended by
    assert all(b <= a + MONOTONE for a, b in zip(errors, errors[1:]))  # a tendon more never does worse
    chosen = next(e for e in summary["front"] if e["count"] == rec["count"])
    assert m["realizable_pose_error_rel"] == chosen["realizable_pose_error_rel"]
    assert summary["search"]["beam"] == 3 and summary["search"]["converged_resolution"] == 2
    outside = m["realizable_pose_error_rel"] > summary["budget"]
    assert any("within the budget" in w for w in summary["warnings"]) == outside
    assert all(f"tendon-taichi: warning: {w}" in r.stderr for w in summary["warnings"])
    # the table on stdout, the stages and the route optimization on stderr
    assert "recommended:" in r.stdout and re.search(r"tendon 1: .* cm, pull", r.stdout)
    assert "stage 0" in r.stderr and "design: strands" in r.stderr and "optimizing" in r.stderr


def test_the_drawing_has_one_smooth_path_per_tendon_inside_the_body(designed):
    d, _ = designed
    summary = json.loads((d / "out" / "design.json").read_text())
    root = ET.parse(d / "out" / "design.svg").getroot()
    assert root.tag == f"{SVG}svg" and root.get("width").endswith("mm")
    routes = [p for p in root.iter(f"{SVG}path") if p.get("class") == "route"]
    assert len(routes) == summary["recommended"]["count"]
    assert len([c for c in root.iter(f"{SVG}circle") if c.get("class") == "anchor"]) == len(routes)
    body_d = next(p for p in root.iter(f"{SVG}path") if p.get("id") == "body").get("d")
    outline = np.array([[float(v) for v in xy.split(",")] for xy in re.findall(r"-?[\d.]+,-?[\d.]+", body_d)])
    body = shapely.Polygon(outline)
    clearance_mm = 1e3 * 0.02 * summary["body_size"]
    for path in routes:
        cmd = path.get("d")
        assert cmd.startswith("M ") and " C " in cmd  # a smooth path: cubic Bezier segments
        pts = np.array([[float(v) for v in xy.split(",")] for xy in re.findall(r"-?[\d.]+,-?[\d.]+", cmd)])
        start, pieces = pts[0], pts[1:].reshape(-1, 3, 2)
        u = np.linspace(0, 1, 11)[:, None]
        p0 = start
        for c1, c2, p3 in pieces:
            curve = (1 - u) ** 3 * p0 + 3 * u * (1 - u) ** 2 * c1 + 3 * u * u * (1 - u) * c2 + u ** 3 * p3
            assert body.contains(shapely.MultiPoint(curve))
            assert shapely.distance(shapely.MultiPoint(curve), body.boundary) >= 0.99 * clearance_mm
            p0 = p3


def test_as_built_equilibrium_balances_forces_from_its_export_alone(designed):
    """The body's elastic forces (reference Neo-Hookean) and the exported segment
    tensions along the exported deformed waypoints sum to zero on the free nodes,
    and the tensions drop from the pull end by exp(-mu Theta_s), Theta_s the
    turning between segment s and the pull end (the export's positions)."""
    d, _ = designed
    assert as_built_residual(np.load(d / "out" / "as_built.npz")) <= 1e-7


def test_the_routes_are_in_the_recording(designed):
    d, _ = designed
    run = read_recording(d / "out" / "run.rrd")
    assert run.stages
    chunks, _ = read_chunks(d / "out" / "run.rrd")
    paths = {c.entity_path for c in chunks}
    assert {"/design/routes/rest", "/design/routes/realizable/tendons", "/design/summary"} <= paths


def test_every_extracted_tendon_is_accounted_for_in_design_json(designed):
    """From design.json alone: each extractor's tendons made its strands, each drop
    and join took one away, and its count are left - none went missing silently."""
    d, _ = designed
    rows = json.loads((d / "out" / "design.json").read_text())["extractors"]
    assert rows and all("error" not in r for r in rows)
    for r in rows:
        assert r["extracted_count"] >= r["strands"] >= r["count"] >= 1 and unaccounted(r) == 0, r
    lost = {**rows[0], "count": rows[0]["count"] - 1}  # one fewer than the steps leave: lost silently
    assert unaccounted(lost) == 1
    assert unaccounted({**rows[0], "strands": rows[0]["extracted_count"] + 1}) >= 1  # merging never adds
    assert unaccounted({"name": "x", "error": "it failed", "steps": None}) is None


def _entry(count, error, capstan, length):
    return {"count": count, "realizable_pose_error_rel": error, "capstan_worst": capstan, "total_length": length,
            "id": f"{count}-{error}-{capstan}-{length}"}


def test_recommendation_is_the_fewest_tendons_within_the_budget():
    entries = [_entry(3, 0.001, 0.9, 0.2), _entry(2, 0.004, 0.80, 0.15), _entry(2, 0.0045, 0.85, 0.18),
               _entry(2, 0.0046, 0.85, 0.12), _entry(1, 0.02, 1.0, 0.1)]
    assert recommend(entries, 0.005, None)["id"] == "2-0.0046-0.85-0.12"  # capstan first, then length
    assert recommend(entries, 0.0042, None)["id"] == "2-0.004-0.8-0.15"
    assert recommend(entries, 0.003, None)["id"] == "3-0.001-0.9-0.2"
    assert recommend(entries, 0.0005, None)["id"] == "3-0.001-0.9-0.2"  # none within: the lowest error
    assert recommend(entries, 0.005, 1)["id"] == "1-0.02-1.0-0.1"


def test_a_recommendation_outside_the_budget_comes_with_a_warning():
    from tendon_taichi.apps.design import _budget_warning

    summary = {"budget": 0.005, "recommended": {"metrics": {"realizable_pose_error_rel": 0.02}}}
    assert _budget_warning(summary) == ["no layout found is within the budget of 0.5% of L: the recommended one "
                                        "is the most accurate, 2.00% of L as built"]
    summary["recommended"]["metrics"]["realizable_pose_error_rel"] = 0.005
    assert _budget_warning(summary) == []


def test_outside_the_budget_a_tendon_that_buys_only_rounding_is_not_recommended():
    rows = [{"count": k, "realizable_pose_error_rel": e, "capstan_worst": 0.85, "total_length": 0.1 * k}
            for k, e in ((1, 0.00970543489401192), (2, 0.009705434894011909), (3, 0.0097054348940119))]
    assert recommend(rows, 0.005)["count"] == 1  # a slack second tendon, equal to the last bits
    rows[1]["realizable_pose_error_rel"] = 0.009
    assert recommend(rows, 0.005)["count"] == 2


def test_outside_the_budget_a_tendon_must_buy_the_consolidation_tolerance():
    """None within the budget: a tendon more is recommended only where it lowers the
    error by more than consolidation's tolerance (a generated case's front: 6
    tendons bought 0.014 % of L over 2)."""
    errors = {1: 0.00916, 2: 0.00705, 3: 0.00705, 4: 0.00693, 5: 0.00692, 6: 0.00691}
    rows = [{"count": k, "realizable_pose_error_rel": e, "capstan_worst": 0.85, "total_length": 0.1 * k}
            for k, e in errors.items()]
    assert recommend(rows, 0.005)["count"] == 6  # the soft IK's precision alone
    assert recommend(rows, 0.005, tolerance=0.001)["count"] == 2
    assert recommend(rows, 0.005, tolerance=0.0001)["count"] == 4
    assert recommend(rows, 0.005, max_tendons=3, tolerance=0.0001)["count"] == 2


def test_a_capstan_limit_takes_the_fewest_tendons_that_keep_it():
    """--min-capstan: within the budget, the fewest tendons whose worst capstan keeps
    the limit; when no layout within the budget keeps it, the rule without it."""
    entries = [_entry(3, 0.001, 0.9, 0.2), _entry(2, 0.004, 0.80, 0.15), _entry(2, 0.0045, 0.85, 0.18),
               _entry(2, 0.0046, 0.85, 0.12), _entry(1, 0.003, 0.7, 0.1), _entry(1, 0.02, 0.99, 0.1)]
    assert recommend(entries, 0.005, None)["id"] == "1-0.003-0.7-0.1"
    assert recommend(entries, 0.005, None, 0.7)["id"] == "1-0.003-0.7-0.1"  # the limit itself is kept
    assert recommend(entries, 0.005, None, 0.75)["id"] == "2-0.0046-0.85-0.12"
    assert recommend(entries, 0.005, None, 0.88)["id"] == "3-0.001-0.9-0.2"
    assert recommend(entries, 0.005, None, 0.95)["id"] == "1-0.003-0.7-0.1"  # none keeps it: set aside
    assert recommend(entries, 0.005, 2, 0.88)["id"] == "1-0.003-0.7-0.1"  # none of at most 2 keeps it
    assert recommend(entries, 0.0005, None, 0.88)["id"] == "3-0.001-0.9-0.2"  # none within: the lowest error


def test_the_table_marks_the_recommended_design_once():
    from tendon_taichi.cli.design import table

    def row(count, err, src):
        return {"count": count, "realizable_pose_error_rel": err, "realizable_pose_error_rel_level": err * 0.9,
                "capstan_worst": 0.99, "kinks": 0, "total_length": 0.1, "source": src}

    metrics = {**row(2, 0.003, "strands"), "realizable_pose_error_rel_frictionless": 0.003, "clearance_min": 0.002}
    summary = {"scene": "s", "resolution": 1, "body_size": 0.1, "friction": 0.1, "clearance": 0.02, "budget": 0.005,
               "front": [row(1, 0.02, "strands"), row(2, 0.003, "strands"), row(3, 0.001, "path_cover")],
               "files": {}, "search": {"converged_resolution": 2},
               "recommended": {"count": 2, "source": "strands", "metrics": metrics, "tendons": []}}
    text = table(summary)
    rows = [ln for ln in text if re.match(r"\s+\d+ [ *] ", ln)]
    assert [ln.split()[:2] for ln in rows] == [["1", "2.00%"], ["2", "*"], ["3", "0.10%"]]  # one row per count
    assert rows[1].split()[2:4] == ["0.30%", "0.27%"]  # re-solved at level 2, then at the design's level
    assert "re-solved at level 2" in text[1] and text[-2].startswith("recommended: 2 tendon(s)")
    assert not any("--min-capstan" in ln for ln in text) and "min capstan" not in text[0]
    summary.update(min_capstan=0.995)
    summary["recommended"]["meets_min_capstan"] = False
    text = table(summary)
    assert "min capstan 0.995" in text[0] and "keeps 0.995 of its pull" in text[-2]  # the limit set aside, said


@pytest.mark.parametrize("args, message", [
    (["--friction", "-0.1"], "--friction must be a number in [0, 2]"),
    (["--friction", "nan"], "--friction must be a number in [0, 2]"),
    (["--clearance", "0.5"], "--clearance must be a number in [0, 0.2]"),
    (["--budget", "0"], "--budget must be a fraction of L in (0, 1)"),
    (["--max-tendons", "0"], "--max-tendons must be an integer >= 1"),
    (["--max-tendons", "-3"], "--max-tendons must be an integer >= 1"),
    (["--budget", "nan"], "--budget must be a fraction of L in (0, 1)"),
    (["--budget", "1.5"], "--budget must be a fraction of L in (0, 1)"),
    (["--beam", "0"], "--beam must be an integer >= 1"),
    (["--workers", "-1"], "--workers must be >= 0"),
    (["--min-capstan", "1.5"], "--min-capstan must be a fraction in [0, 1]"),
    (["--min-capstan", "-0.1"], "--min-capstan must be a fraction in [0, 1]"),
    (["--min-capstan", "nan"], "--min-capstan must be a fraction in [0, 1]"),
])
def test_bad_values_give_one_line_and_write_nothing(cli, tmp_path, args, message):
    r = cli("design", "t_shape", "--out", "out", *args, cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tendon-taichi: error: ") and message in lines[0], r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("goal, budget_hint", [("[0.30, 0.30]", None), ("[0.10, 0.008]", "a --budget of ")])
def test_goals_out_of_reach_stop_before_extraction_and_keep_the_run(cli, tmp_path, goal, budget_hint):
    """Goals the optimized fibers miss by more than the budget (one 5 L away; one
    a stretch the contracting fibers cannot make) end the design after the
    optimization with one line: no layout is searched, the run is kept, and the
    budget that designs anyway is named where there is one below 1. The worker
    process, stopped as the design ends, leaves no warm-up folder behind."""
    (tmp_path / "s.toml").write_text(SCENE.replace("goal = [0.066, 0.02]", f"goal = {goal}"))
    (tmp_path / "tmp").mkdir()
    r = cli("design", "s.toml", "--out", "out", "--quiet", "--stage-iterations", "10", "--k-min", "0.4",
            "--workers", "1", cwd=tmp_path, env={"TMPDIR": str(tmp_path / "tmp")})
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tendon-taichi: error: the goals are out of reach: "), r.stderr
    error = float(re.search(r"\(([0-9.]+)% of L\), above the budget of 0.5% of L", lines[0]).group(1)) / 100
    assert error > 0.005 and "the run is kept in out/run.rrd" in lines[0]
    if budget_hint is None:
        assert error > 1.0 and "--budget" not in lines[0]
    else:
        enough = float(re.search(r"a --budget of ([0-9.]+) or more", lines[0]).group(1))
        assert error <= enough <= 1.01 * error and enough < 1.0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["run.npz", "run.rrd"]
    assert list((tmp_path / "tmp").iterdir()) == []
    recorded = [st.summary["pose_error_rel"] for st in read_recording(tmp_path / "out" / "run.rrd").stages]
    assert min(recorded) == pytest.approx(error, rel=1e-3)


def test_the_optimizations_warnings_come_before_the_search(cli, tmp_path):
    """A warning of the optimization (here: a sparsity weight so high that the
    regularizers give up the pose) is said as soon as it is known, before the
    search that may take long, and again with the design's result."""
    from tendon_taichi import load_scene

    (tmp_path / "s.toml").write_text(load_scene("finger").source.replace("goal = [0.0939, 0.0345]",
                                                                         "goal = [0.06, 0.05]"))
    r = cli("design", "s.toml", "--out", "out", "--stage-iterations", "10", "--k0", "1", "--k-min", "0.4",
            "--sparsity", "0.1", "--extractors", "strands", "--beam", "1", "--no-converge", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    said = "the regularizers gave up the pose"
    early = next(i for i, ln in enumerate(lines) if ln.startswith("design: warning: ") and said in ln)
    assert early < next(i for i, ln in enumerate(lines) if ln.startswith("design: strands: extracting"))
    assert any(ln.startswith("tendon-taichi: warning: ") and said in ln for ln in lines[early + 1:])
    assert any(said in w for w in json.loads((tmp_path / "out" / "design.json").read_text())["warnings"])


def test_a_pattern_too_sparse_for_a_tendon_is_read_at_the_stage_before(cli, tmp_path):
    """A sparsity weight that leaves one or two active fibers at the last stage: no
    layout from it, so the extractors read the stage before (said, with what the
    last keeps) and the design is made from there (``search.stage``)."""
    (tmp_path / "s.toml").write_text(SCENE)
    r = cli("design", "s.toml", "--out", "out", "--stage-iterations", "25", "--k0", "1", "--k-min", "0.4",
            "--sparsity", "0.1", "--extractors", "strands", "--beam", "1", "--no-converge", "--no-png", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    last = read_recording(tmp_path / "out" / "run.rrd").stages[-1].summary
    assert last["active_fibers"] <= 2
    said = re.search(r"no extractor's tendons make a layout from stage (\d+) \((\d+) active fibers\); reading stage "
                     r"(\d+)", r.stderr)
    assert said and int(said.group(1)) == last["stage"] and int(said.group(2)) == last["active_fibers"], r.stderr
    assert int(said.group(3)) == last["stage"] - 1
    summary = json.loads((tmp_path / "out" / "design.json").read_text())
    assert 1 <= summary["search"]["stage"] < last["stage"] and summary["recommended"]["count"] >= 1


def test_bad_tendons_table_is_a_scene_error(cli, tmp_path):
    (tmp_path / "s.toml").write_text(SCENE.replace("friction = 0.15", "friction = 3.0"))
    r = cli("design", "s.toml", "--out", "out", cwd=tmp_path)
    assert r.returncode == 2 and "tendons.friction must be <= 2" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_tendon_settings_given_on_the_command_line_reach_the_recording(tmp_path):
    """A --friction or --clearance that replaces the scene's is what the run's
    recording rebuilds its problem with (extraction and design read it back)."""
    from tendon_taichi import load_scene, optimize
    from tendon_taichi.body.scene import with_overrides

    scene = with_overrides(load_scene("finger"), {"stage_iterations": 3, "k_min": 0.5})
    run = optimize(scene.with_tendons(friction=0.0, clearance=0.05), 1, record=tmp_path / "run.rrd")
    ts = read_recording(run.recording).problem().scene.tendons
    assert (ts.friction, ts.clearance) == (0.0, 0.05) and scene.tendons.friction == 0.1


def _prior(size, **change):
    """A design.json of t_shape (body size ``size``) with a one-route front, ``change`` applied."""
    route = {"control_points": [[0.01, 0.05], [0.02, 0.06], [0.03, 0.07]], "samples": 12, "tension": 0.5,
             "contraction_ratio": [0.05], "source": "strands"}
    data = {"scene": "t_shape", "body_size": size, "front": [{"count": 1, "routes": [route]}]}
    for key, value in change.items():
        if key in data:
            data[key] = value
        else:
            route[key] = value
    return json.dumps(data)


@pytest.mark.parametrize("text, message", [
    (None, "--routes-from: no design at 'prior'"),
    ("not json", "is not a design.json"),
    ('{"scene": "t_shape"}', "is not a design.json (no 'front' list)"),
    (dict(scene="finger"), "is a design of scene 'finger', not of 't_shape'"),
    (dict(body_size=1.0), "is a design of another body"),
    (dict(front=[{"count": 1}]), "lists no routes with its front"),
    (dict(contraction_ratio=[0.05, 0.06]), "is a design for 2 pose(s); this scene has 1"),
    (dict(control_points=[[0.01, "x"]]), "has a malformed route in its front"),
    (dict(samples=None), "has a malformed route in its front"),
])
def test_a_bad_prior_design_gives_one_line_and_writes_nothing(cli, tmp_path, text, message):
    """``--routes-from`` is checked before anything is computed."""
    from tendon_taichi import build_problem, load_scene

    if isinstance(text, dict):
        text = _prior(build_problem(load_scene("t_shape"), 1).size, **text)
    if text is not None:
        (tmp_path / "prior").mkdir()
        (tmp_path / "prior" / "design.json").write_text(text)
    r = cli("design", "t_shape", "--out", "out", "--routes-from", "prior", cwd=tmp_path)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("tendon-taichi: error: ") and message in lines[0], r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ([] if text is None else ["prior"])


def test_a_design_searches_from_a_prior_designs_front(designed, tmp_path):
    """``--routes-from``: the prior design's front layouts join the seeds (said on
    stderr, counted in design.json's ``search`` with the file they came from)."""
    from conftest import run_cli

    d, _ = designed
    r = run_cli("design", d / "finger.toml", "--out", "again", "--stage-iterations", "25", "--k-min", "0.1",
                "--extractors", "strands", "path_cover", "--refine", "1", "--routes-from", d / "out", "--no-png",
                cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    first = json.loads((d / "out" / "design.json").read_text())
    again = json.loads((tmp_path / "again" / "design.json").read_text())
    n = len(first["front"])
    assert f"{n} of the {n} layouts of '{d / 'out' / 'design.json'}' join the front's seeds" in r.stderr
    assert again["search"]["priors"] == n and again["search"]["routes_from"] == str(d / "out" / "design.json")
    assert first["search"]["priors"] == 0 and first["search"]["routes_from"] is None


def test_above_level_1_a_design_searches_from_the_level_belows_front(designed, tmp_path):
    """At level 2 the design first designs the scene at level 1 (said on stderr) and
    that front's layouts join the seeds (``search.coarse``, ``search.priors``); the
    coarser design's recording goes into a temporary folder, removed: nothing else
    is written. A level-1 design has none."""
    import os

    from conftest import run_cli

    d, _ = designed
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    r = run_cli("design", d / "finger.toml", "--level", 2, "--out", "two", "--stage-iterations", "25", "--k-min",
                "0.1", "--extractors", "strands", "--refine", "1", "--no-png", "--no-converge", cwd=tmp_path,
                env={**os.environ, "TMPDIR": str(tmp)})
    assert r.returncode == 0, r.stderr
    two = json.loads((tmp_path / "two" / "design.json").read_text())
    coarse = two["search"]["coarse"]
    assert coarse["level"] == 1 and coarse["layouts"] >= 1 and 1 <= coarse["count"] <= coarse["layouts"]
    assert 0 < coarse["time_s"] == two["timing"]["coarse_s"] < two["time_s"]
    assert 1 <= two["search"]["priors"] <= coarse["layouts"] and two["search"]["routes_from"] is None
    assert "small finger at level 1 first" in r.stderr
    assert f"{two['search']['priors']} of the {coarse['layouts']} layouts of the level-1 design join" in r.stderr
    assert r.stderr.index("at level 1 first") < r.stderr.index("optimizing small finger at level 2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tmp", "two"] and list(tmp.iterdir()) == []
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == [
        "as_built.npz", "design.json", "design.svg", "run.npz", "run.rrd"]
    one = json.loads((d / "out" / "design.json").read_text())
    assert one["search"]["coarse"] is None and one["timing"]["coarse_s"] is None


def test_no_coarse_skips_the_coarser_level(monkeypatch, tmp_path):
    """``--no-coarse`` reaches the front's settings; with it, as at level 1, a design
    optimizes at its own level straight away (each design stopped there)."""
    import argparse

    from tendon_taichi.apps import design as design_module
    from tendon_taichi.apps.settings import DesignSettings
    from tendon_taichi.body.scene import load_scene
    from tendon_taichi.cli.tendons import add_front_flags, front_settings
    from tendon_taichi.extract.settings import FrontSettings

    ap = argparse.ArgumentParser()
    add_front_flags(ap)
    assert front_settings(ap.parse_args([]))["coarse"] is True
    assert front_settings(ap.parse_args(["--no-coarse"]))["coarse"] is False

    class Made(Exception):
        pass

    def coarse(*args, **kwargs):
        raise Made("coarse")

    def optimized(*args, **kwargs):
        raise Made(kwargs["record"])

    monkeypatch.setattr(design_module, "coarse_prior", coarse)
    monkeypatch.setattr(design_module, "optimize", optimized)
    scene = load_scene("finger")
    with pytest.raises(Made, match="coarse"):
        design_module.design(scene, 2, tmp_path / "a", DesignSettings())
    with pytest.raises(Made, match="run.rrd"):  # straight to the level-2 optimization
        design_module.design(scene, 2, tmp_path / "b", DesignSettings(front=FrontSettings(coarse=False)))
    with pytest.raises(Made, match="run.rrd"):
        design_module.design(scene, 1, tmp_path / "c", DesignSettings())


def test_a_coarser_level_out_of_reach_is_said_and_the_design_goes_on(monkeypatch):
    """Where the level below's fibers come no nearer the goals than the budget, no
    layout is searched there: no prior, and ``search.coarse`` says why."""
    from types import SimpleNamespace

    from tendon_taichi.apps import design as design_module
    from tendon_taichi.apps.settings import DesignSettings
    from tendon_taichi.body.scene import load_scene

    said = []
    run = SimpleNamespace(stages=[SimpleNamespace(figures=SimpleNamespace(pose_error_rel=e)) for e in (0.02, 0.008)])
    monkeypatch.setattr(design_module, "optimize", lambda *args, **kwargs: run)
    monkeypatch.setattr(design_module, "recommended", lambda *args, **kwargs: pytest.fail("searched"))
    progress = SimpleNamespace(message=said.append)
    prior, coarse = design_module.coarse_prior(load_scene("finger"), 1, DesignSettings(budget=0.005), progress,
                                               pool=None, threads=1)
    assert prior is None and coarse["level"] == 1 and coarse["layouts"] == 0 and coarse["count"] is None
    assert "no closer to the goals than 0.80% of L" in coarse["error"] and "going on without" in said[-1]


def test_a_last_stage_that_makes_no_layout_is_followed_by_the_one_before(monkeypatch):
    """Where the last stage's pattern makes no tendon (here: every extractor failed
    on it), the stage before is read, and so on down to stage 1, each said."""
    from types import SimpleNamespace

    from tendon_taichi.apps import design as design_module

    asked, said = [], []

    def extract(recording, how, log, workers):
        asked.append(how.stage)
        stage = 3 if how.stage is None else how.stage
        run = SimpleNamespace(stages=[SimpleNamespace(summary={"active_fibers": 10 - k}) for k in range(4)])
        return SimpleNamespace(stage=stage, run=run, problem=None, solver="direct",
                               results=[SimpleNamespace(error="no strand", consolidation=None)])

    monkeypatch.setattr(design_module, "extract", extract)
    progress = SimpleNamespace(message=said.append)
    with pytest.raises(design_module.InputError, match="no extractor produced tendons: no strand"):
        design_module.recommended("run.rrd", progress=progress)
    assert asked == [None, 2, 1]
    assert said == ["design: no extractor's tendons make a layout from stage 3 (7 active fibers); reading stage 2",
                    "design: no extractor's tendons make a layout from stage 2 (8 active fibers); reading stage 1"]


class _HereAsIfWorkers:
    """Stands in for ``design``'s pool of worker processes: it says it has one, and
    runs every piece here, pickled and unpickled as a worker would get it."""

    def __init__(self, workers, setup=None, setup_args=()):
        from tendon_taichi.tasks.pool import Pool

        self.pool = Pool(0)
        self.broken = None

    active = 1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    @staticmethod
    def _sent(value):
        import pickle

        return pickle.loads(pickle.dumps(value))

    def map(self, fn, items):
        return [self._sent(fn)(self._sent(item)) for item in items]

    def defer(self, fn, job):
        return self.pool.defer(self._sent(fn), self._sent(job))

    def collect(self, jobs):
        return self.pool.collect(jobs)


def test_a_design_hands_its_run_on_in_memory_and_its_thread_count_to_every_factorization(tmp_path, monkeypatch):
    """``design`` extracts from the run it holds, not from its recording read back
    (``read_recording`` is never called; the recording is still written and holds
    the same run, to the bit), and a design with workers runs every factorization
    on one thread - the pieces handed to its workers too - because it passes that
    count on, whatever the process's own (here 3, every matrix threaded)."""
    import sys

    from conftest import use_cholesky
    from tendon_taichi.apps import design as design_app
    from tendon_taichi.apps.settings import DesignSettings
    from tendon_taichi.body.scene import load_scene, with_overrides
    from tendon_taichi.extract.settings import FrontSettings
    from tendon_taichi.io import recording
    from tendon_taichi.physics import runtime
    from tendon_taichi.solve import pardiso

    handle = use_cholesky(monkeypatch, "pardiso")
    monkeypatch.setattr(pardiso, "PARALLEL_MIN", 0)
    monkeypatch.setattr(runtime, "factor_threads", lambda: 3)
    factored = []
    real_factor = handle.factor

    def factor(self, data):
        factored.append((self.asked_threads, self.threads))
        return real_factor(self, data)

    monkeypatch.setattr(handle, "factor", factor)
    reads = []

    def read_back(path):
        reads.append(path)
        raise AssertionError(f"the design read its recording '{path}' back")

    for module in [m for name, m in sys.modules.items() if name.startswith("tendon_taichi")]:
        if getattr(module, "read_recording", None) is recording.read_recording:
            monkeypatch.setattr(module, "read_recording", read_back)
    monkeypatch.setattr(design_app, "Pool", _HereAsIfWorkers)
    (tmp_path / "finger.toml").write_text(SCENE)
    scene = with_overrides(load_scene(tmp_path / "finger.toml"), {"stage_iterations": 25, "k_min": 0.1})
    settings = DesignSettings(extractors=("strands", "path_cover"), png=False,
                              front=FrontSettings(beam=1, converge=False))
    done = design_app.design(scene, 1, tmp_path / "out", settings, workers=1)
    assert reads == [] and factored and set(factored) == {(1, 1)}
    monkeypatch.undo()
    held, recorded = done.run.held, read_recording(tmp_path / "out" / "run.rrd")
    assert held.meta == recorded.meta and held.scene_toml == recorded.scene_toml and not recorded.truncated
    assert [st.summary for st in held.stages] == [st.summary for st in recorded.stages]
    for h, r in zip(held.stages, recorded.stages):
        assert all(np.array_equal(getattr(h, k), getattr(r, k)) for k in ("r", "ac", "tau", "xs"))
    assert all(np.array_equal(held.arrays[k], r) for k, r in recorded.arrays.items())


def test_a_worker_process_factorizes_on_one_thread_where_its_job_gives_none(monkeypatch):
    """A worker's set-up makes one thread its process's factorizations' default:
    the other processes hold the other cores."""
    from tendon_taichi.apps.design import start_worker
    from tendon_taichi.physics import runtime

    monkeypatch.setitem(runtime._settings, "factor_threads", None)
    monkeypatch.setenv("TENDON_TAICHI_FACTOR_THREADS", "2")
    assert runtime.factor_threads() == 2
    start_worker(None, warm=False)
    assert runtime.factor_threads() == 1
