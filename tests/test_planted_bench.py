"""planted-bench: scoring rules, suite loading, and the command end to end on one case."""

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tendon_taichi.errors import InputError
from tendon_taichi.planted.bench import CSV_COLUMNS, best_extractor, load_suite, totals

SUITE = Path(__file__).resolve().parents[1] / "benchmarks" / "planted"


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "tendon_taichi", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=900)


def test_best_extractor_prefers_few_tendons_then_the_realizable_pose():
    ex = {"a": {"count": 5, "realizable_pose_error_rel": 0.001},
          "b": {"count": 2, "realizable_pose_error_rel": 0.02},
          "c": {"count": 3, "realizable_pose_error_rel": 0.008},
          "d": {"error": "crashed"}}
    assert best_extractor(ex, planted_count=2) == "c"  # a finds too many tendons
    assert best_extractor(ex, planted_count=1) == "b"  # only b finds <= 2
    assert best_extractor({"a": ex["a"]}, planted_count=1) == "a"  # none qualifies: the best of all
    assert best_extractor({"d": ex["d"]}, planted_count=1) is None


def test_totals_count_passes_and_failures():
    rows = [{"passed": True, "count": 2, "planted_count": 2, "length_ratio": 1.0, "count_ratio": 1.0,
             "realizable_pose_error_rel": 0.005, "time_s": 10.0},
            {"passed": False, "count": 4, "planted_count": 2, "length_ratio": 3.0, "count_ratio": 2.0,
             "realizable_pose_error_rel": 0.02, "time_s": 20.0},
            {"passed": False, "error": "ConvergenceError: ...", "time_s": 1.0}]
    t = totals(rows)
    assert (t["cases"], t["failed"], t["passed"], t["count_within_planted_plus_one"]) == (3, 1, 1, 1)
    assert t["median_length_ratio"] == 2.0 and t["time_s"] == 31.0


def test_the_checked_in_suite_loads():
    cases = load_suite(SUITE)
    assert len(cases) >= 12
    assert {c.layout["scene"] for c in cases} >= {"t_shape", "finger", "gripper", "cross", "snake"}
    assert all(1 <= c.planted_count <= 3 and c.planted_length > 0 for c in cases)


def test_bad_suites_are_input_errors(tmp_path):
    with pytest.raises(InputError, match="not a folder"):
        load_suite(tmp_path / "missing")
    with pytest.raises(InputError, match="no case"):
        load_suite(tmp_path)
    shutil.copy(SUITE / "t_shape_planted_1t_s1.toml", tmp_path / "c.toml")
    (tmp_path / "c.json").write_text("{not json")
    with pytest.raises(InputError, match="unreadable"):
        load_suite(tmp_path)


def test_planted_bench_command_on_one_case(tmp_path):
    out = tmp_path / "pb"
    r = _cli("planted-bench", SUITE, "--cases", "t_shape_planted_1t_s1", "--resolution", "1",
             "--stage-iterations", "30", "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert "[1/1] t_shape_planted_1t_s1" in r.stderr
    (case,) = res["cases"]
    assert res["settings"] == {"stage_iterations": 30} and res["totals"]["cases"] == 1
    assert set(case["extractors"]) >= {"strands", "network_discovery", "path_cover"}
    best = case["extractors"][case["best"]]
    assert case["count"] == best["count"] and case["realizable_pose_error_rel"] == best["realizable_pose_error_rel"]
    assert case["length_ratio"] == pytest.approx(case["active_length"] / case["planted_length"])
    assert case["passed"] == (case["count"] <= 2 and case["realizable_pose_error_rel"] <= 0.01
                              and case["length_ratio"] <= 2.0)
    assert Path(case["recording"]).exists() and (out / "gallery.png").read_bytes()[:4] == b"\x89PNG"
    from tendon_taichi.planted.gallery import gallery_figure

    panel = gallery_figure(res, {c.name: c for c in load_suite(SUITE)}).axes[0]
    dashed = [ln for ln in panel.get_lines() if ln.get_linestyle() == "--"]
    found = [ln for ln in panel.get_lines() if ln.get_linewidth() == 2.0]
    assert len(dashed) == case["planted_count"] and len(found) == case["count"]
    assert panel.get_title().startswith(f"{case['case']} ({'pass' if case['passed'] else 'miss'})")
    with open(out / "planted_bench.csv") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == 2
    assert json.loads((out / "planted_bench.json").read_text())["cases"][0]["case"] == "t_shape_planted_1t_s1"


@pytest.mark.parametrize("args, message", [
    (["/no/such/suite"], "not a folder"),
    ([str(SUITE), "--cases", "nope"], "no such case"),
    ([str(SUITE), "--sparsity", "-1"], "sparsity"),
])
def test_planted_bench_bad_input_is_one_line(tmp_path, args, message):
    r = _cli("planted-bench", *args, "--out", tmp_path / "pb")
    assert r.returncode == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "pb").exists()


def _distance_to_polyline(points, line):
    """Distance (q,) from points (q, 2) to a polyline (k, 2)."""
    a, b = line[:-1][None], line[1:][None]
    p = points[:, None]
    t = np.clip(((p - a) * (b - a)).sum(-1) / ((b - a) ** 2).sum(-1), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1).min(axis=1)


def test_a_one_tendon_planted_case_is_recovered_end_to_end(tmp_path):
    """snake_planted_1t_s1 at level 1 with the default settings: the best extractor
    finds at most planted + 1 tendons, one of them lies along the planted tendon,
    and the realizable robot with only the found tendons reaches the goals."""
    from tendon_taichi.planted.bench import run_case

    layout = json.loads((SUITE / "snake_planted_1t_s1.json").read_text())
    res = run_case(SUITE / "snake_planted_1t_s1.toml", layout, 1, tmp_path)
    assert res["passed"], res
    assert res["count"] <= 2 and res["realizable_pose_error_rel"] <= 0.01 and res["length_ratio"] <= 2.0
    planted = np.array(layout["tendons"][0]["waypoints"])
    found = [np.array(w) for w in res["extractors"][res["best"]]["tendons"]]
    longest = max(found, key=lambda w: np.linalg.norm(np.diff(w, axis=0), axis=1).sum())
    spacing = 0.005  # the scene's fiber spacing at level 1
    d = _distance_to_polyline(longest, planted)
    assert np.median(d) < spacing, d  # along the planted path, not somewhere else
    covered = np.min([_distance_to_polyline(planted, w) for w in found], axis=0) < 2 * spacing
    assert covered.mean() >= 0.5, covered  # and covering most of it
    print(f"median distance {1e3 * np.median(d):.2f} mm, planted path covered {100 * covered.mean():.0f} %")
