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
from tendon_taichi.planted.bench import CSV_COLUMNS, load_suite, planted_figures, route_rule, totals

SUITE = Path(__file__).resolve().parents[1] / "benchmarks" / "planted"


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "tendon_taichi", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=900)


def test_route_rule_and_totals():
    rows = [{"passed": True, "count": 2, "planted_count": 2, "length_ratio": 1.0, "count_ratio": 1.0,
             "realizable_pose_error_rel": 0.005, "capstan_worst": 0.86, "planted_capstan_worst": 0.9, "kinks": 0,
             "planted_kinks": 0, "time_s": 10.0},
            {"passed": False, "count": 4, "planted_count": 2, "length_ratio": 3.0, "count_ratio": 2.0,
             "realizable_pose_error_rel": 0.02, "capstan_worst": 0.84, "planted_capstan_worst": 0.9, "kinks": 0,
             "planted_kinks": 0, "time_s": 20.0},
            {"passed": True, "count": 1, "planted_count": 2, "length_ratio": 1.0, "count_ratio": 0.5,
             "realizable_pose_error_rel": 0.001, "capstan_worst": 1.0, "planted_capstan_worst": 0.9, "kinks": 1,
             "planted_kinks": 0, "time_s": 5.0},
            {"passed": False, "error": "ConvergenceError: ...", "time_s": 1.0}]
    assert [route_rule(r) for r in rows[:3]] == [True, False, False]  # capstan 0.05 below; a kink too many
    fewer = {**rows[2], "kinks": 0, "capstan_worst": 0.5}  # one tendon for two planted: the capstan is not asked
    assert route_rule(fewer) and not route_rule({**fewer, "count": 2})
    t = totals(rows)
    assert (t["cases"], t["failed"], t["passed"], t["count_within_planted_plus_one"]) == (4, 1, 2, 2)
    assert (t["within_one_percent"], t["route_rule"], t["kinks"], t["planted_kinks"]) == (2, 1, 1, 0)
    assert t["median_length_ratio"] == 1.0 and t["time_s"] == 36.0


def test_planted_figures_score_the_planted_tendons_with_the_same_friction():
    """A planted layout's own capstan and kinks (its rest waypoints, the scene's mu)
    and its as-built error: its tendons reach their goals exactly without friction,
    and miss them a little with it."""
    from tendon_taichi import build_problem, load_scene

    layout = json.loads((SUITE / "finger_planted_1t_s1.json").read_text())
    scene = load_scene(str(SUITE / "finger_planted_1t_s1.toml"))
    w = np.array(layout["tendons"][0]["waypoints"])
    d = np.diff(w, axis=0)
    theta = np.abs(np.arctan2(d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], (d[:-1] * d[1:]).sum(1))).sum()
    level = layout["level"]
    bare = planted_figures(build_problem(scene.with_tendons(friction=0.0), level), layout)
    rough = planted_figures(build_problem(scene.with_tendons(friction=0.3), level), layout)
    assert bare["planted_capstan_worst"] == 1.0 and bare["planted_as_built_error_rel"] < 1e-5
    assert rough["planted_capstan_worst"] == pytest.approx(np.exp(-0.3 * theta))
    assert rough["planted_as_built_error_rel"] > 10 * bare["planted_as_built_error_rel"]
    assert rough["planted_kinks"] == bare["planted_kinks"] == 0


def test_a_planted_layout_of_several_poses_is_scored_from_each_pose_s_contractions():
    """Each pose starts from its own planted contractions: at the level it was planted
    at, the planted tendons reach both poses' goals exactly without friction, and
    within 0.5 % of L with the scene's (started from the first pose's ratios for
    both poses, the frictional soft IK stopped at 3.3 %)."""
    from tendon_taichi import build_problem, load_scene
    from tendon_taichi.planted.bench import planted_ratios

    name = "snake_planted_2t_s2_2p"
    layout = json.loads((SUITE / f"{name}.json").read_text())
    ratios = planted_ratios(layout, 2)
    assert ratios.tolist() == [p["contraction_ratios"] for p in layout["poses"]] and ratios[0, 0] != ratios[1, 0]
    assert planted_ratios({"tendons": layout["tendons"]}, 2).tolist() == [
        [t["contraction_ratio"] for t in layout["tendons"]]] * 2
    scene = load_scene(str(SUITE / f"{name}.toml"))
    assert scene.tendons.friction == 0.1
    bare = planted_figures(build_problem(scene.with_tendons(friction=0.0), layout["level"]), layout)
    rough = planted_figures(build_problem(scene, layout["level"]), layout)
    assert bare["planted_as_built_error_rel"] < 1e-5 and rough["planted_as_built_error_rel"] < 0.005


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


def _distance_to_polyline(points, line):
    """Distance (q,) from points (q, 2) to a polyline (k, 2)."""
    a, b = line[:-1][None], line[1:][None]
    p = points[:, None]
    t = np.clip(((p - a) * (b - a)).sum(-1) / ((b - a) ** 2).sum(-1), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1).min(axis=1)


def test_planted_bench_command_on_one_case(tmp_path):
    """snake_planted_1t_s1 at level 1 with the default settings: the design has at
    most planted + 1 tendons, its as-built robot reaches the goals within 1 % of L,
    it meets the route rule, and the outputs are all there."""
    out = tmp_path / "pb"
    r = _cli("planted-bench", SUITE, "--cases", "snake_planted_1t_s1", "--level", "1", "--out", out, "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert "[1/1] snake_planted_1t_s1" in r.stderr
    (case,) = res["cases"]
    assert res["settings"] == {} and res["totals"]["cases"] == 1
    assert res["front_search"] == {"beam": 3, "converge": True, "coarse": True}
    assert set(case["extractors"]) >= {"strands", "network_discovery", "path_cover"}
    assert case["passed"] and route_rule(case), case
    assert case["count"] <= 2 and case["realizable_pose_error_rel"] <= 0.01 and case["length_ratio"] <= 2.0
    assert case["count"] == len(case["tendons"])
    assert case["dropped"] == 0 and res["totals"]["dropped"] == 0  # every extracted tendon accounted for
    assert all(s in case["extractors"] or s == "join" for s in case["best"].split("+"))  # where its routes came from
    assert case["length_ratio"] == pytest.approx(case["active_length"] / case["planted_length"])
    assert case["front"] and case["planted_as_built_error_rel"] is not None
    assert case["clearance_min"] >= 0.02 * 0.9 * 0.128  # 2 % of L (this snake is about 13 cm across)
    planted = np.array(json.loads((SUITE / "snake_planted_1t_s1.json").read_text())["tendons"][0]["waypoints"])
    found = [np.array(w) for w in case["tendons"]]
    print("median distance from the planted tendon (mm):",
          [round(1e3 * float(np.median(_distance_to_polyline(w, planted))), 2) for w in found])
    folder = Path(case["recording"]).parent
    assert {p.name for p in folder.iterdir()} >= {"run.rrd", "design.json", "design.svg", "as_built.npz"}
    assert (out / "gallery.png").read_bytes()[:4] == b"\x89PNG"
    from tendon_taichi.planted.gallery import gallery_figure

    panel = gallery_figure(res, {c.name: c for c in load_suite(SUITE)}).axes[0]
    dashed = [ln for ln in panel.get_lines() if ln.get_linestyle() == "--"]
    found = [ln for ln in panel.get_lines() if ln.get_linewidth() == 2.0]
    assert len(dashed) == case["planted_count"] and len(found) == case["count"]
    assert panel.get_title().startswith(f"{case['case']} ({'pass' if case['passed'] else 'miss'})")
    with open(out / "planted_bench.csv") as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS and len(rows) == 2
    assert json.loads((out / "planted_bench.json").read_text())["cases"][0]["case"] == "snake_planted_1t_s1"


@pytest.mark.parametrize("args, message", [
    (["/no/such/suite"], "not a folder"),
    ([str(SUITE), "--cases", "nope"], "no such case"),
    ([str(SUITE), "--sparsity", "-1"], "sparsity"),
    ([str(SUITE), "--levels", "1", "0"], "--level must be >= 1 (got 0)"),
    ([str(SUITE), "--level", "1", "0"], "--level must be >= 1 (got 0)"),
    ([str(SUITE), "--levels", "1", "--resolution", "3"], "not allowed with argument"),
    ([str(SUITE), "--beam", "0"], "--beam must be an integer >= 1"),
])
def test_planted_bench_bad_input_is_one_line(tmp_path, args, message):
    r = _cli("planted-bench", *args, "--out", tmp_path / "pb")
    assert r.returncode == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "pb").exists()


def test_levels_compare_the_recommended_count_and_the_fronts():
    from tendon_taichi.planted.levels import compare_levels, fronts_figure, table

    def case(name, count, errors, planted=0.001, tendons=None):
        front = [{"count": k + 1, "realizable_pose_error_rel": e, "source": "strands"} for k, e in enumerate(errors)]
        return {"case": name, "planted_count": 2, "count": count, "front": front, "planted_as_built_error_rel": planted,
                "tendons": tendons, "body_size": 0.1}

    def routes(lv, lift):
        """Two straight routes (m), the lower one lifted by ``lift``; at level 2 listed the other
        way round, at level 3 the lower one drawn from its other end."""
        low, high = [[0.0, lift], [0.05, lift], [0.1, lift]], [[0.0, 0.05], [0.1, 0.05]]
        return [high, low] if lv == 2 else [low[::-1] if lv == 3 else low, high]

    runs = {lv: {"cases": [case("a", 2, [0.02, 0.001], tendons=routes(lv, 0.001 * lv)),
                           case("b", 2 if lv < 3 else 1, [0.004 * lv, 0.001]),
                           {"case": "c", "error": "failed"} if lv == 2 else case("c", 1, [0.001]),
                           case("d", 2, [0.007 + 0.003 * lv, 0.002, 0.001][:3 if lv < 3 else 2],
                                planted=[0.002, 0.006, 0.009][lv - 1], tendons=routes(lv, 0.01 * (lv == 3)))],
                 "totals": {"passed": lv}} for lv in (1, 2, 3)}
    res = compare_levels(runs)
    assert res["levels"] == [1, 2, 3] and [c["case"] for c in res["cases"]] == ["a", "b", "d"]  # c failed at level 2
    a, b, d = res["cases"]
    assert a["same_count"] and a["counts"] == {"1": 2, "2": 2, "3": 2}
    assert not b["same_count"] and b["counts"]["3"] == 1 and res["same_count"] == 2
    assert b["fronts"]["2"][0]["realizable_pose_error_rel"] == 0.008 and res["totals"]["3"] == {"passed": 3}
    # the errors: a's are equal; b's one-tendon errors 0.4 / 0.8 / 1.2 % spread 0.8 % > max(0.1 %, 25 % of
    # 1.2 %); d's 1.0 / 1.3 / 1.6 % spread 0.6 % > 0.4 %, but the planted tendons' own errors spread 0.7 %:
    # the window is 0.75 %; d's third count is missing at level 3, so it is not compared
    assert a["agreement"]["agree"] and a["agreement"]["compared"] == [1, 2]
    bk = b["agreement"]["counts"]["1"]
    assert bk["spread"] == pytest.approx(0.008) and bk["window"] == pytest.approx(0.003) and not bk["agree"]
    assert not b["agreement"]["agree"] and b["agreement"]["counts"]["2"]["agree"]
    dk = d["agreement"]["counts"]["1"]
    assert d["agreement"]["planted_spread"] == pytest.approx(0.007)
    assert dk["window"] == pytest.approx(0.0075) and dk["agree"] and d["agreement"]["agree"]
    assert d["agreement"]["compared"] == [1, 2] and d["agreement"]["counts"]["3"]["errors"]["3"] is None
    assert res["errors_agree"] == 2
    # the routes: a's lower one moved 2 mm between levels 1 and 3 (0.02 L; matched whatever the order or the
    # direction), d's 10 mm (0.1 L); b's count differs
    assert a["route_shift"] == pytest.approx(0.02) and d["route_shift"] == pytest.approx(0.1)
    assert b["route_shift"] is None and res["same_routes"] == 1
    text = table(res)
    assert text[-1] == ("the same recommended count at every level in 2 of 3 cases, the same routes (moved at "
                        "most 0.05 L) in 1; the front's errors agree up to planted + 1 tendons in 2 of 3; each "
                        "level searched on its own")
    assert text[1].rstrip().endswith("0.020 L") and text[2].rstrip().endswith("-")
    assert table({**res, "coarse_to_fine": True})[-1].endswith(
        "; each level after the first also searched from the one before's designs")
    assert text[2].split()[5:7] == ["no", "differ"] and text[2].split()[7] == "0.800%"
    assert text[1].split()[1:7] == ["2", "2", "2", "2", "yes", "agree"] and text[3].split()[-3] == "0.700%"
    fig = fronts_figure(res)
    assert len(fig.axes[0].get_lines()) == 3 + 2  # a line per level, the planted count and the budget
    assert fig.axes[1].get_title() == "b (count moves)"


@pytest.mark.parametrize("coarse_to_fine", [True, False])
def test_each_level_searches_from_the_level_befores_designs(tmp_path, monkeypatch, coarse_to_fine):
    """``--levels``: from the coarsest up, each level's cases get the level before's
    design.json of the same case as their prior design (where one was written);
    ``--independent-levels``: none, and no case designs its coarser level either."""
    import tendon_taichi.planted.levels as levels
    from tendon_taichi.planted.bench import case_folder

    seen, coarse = {}, {}

    def fake_suite(directory, level, out_dir, settings, **kwargs):
        seen[level] = settings.priors
        coarse[level] = settings.front.coarse
        for c in load_suite(directory)[:2]:  # two cases designed, the rest failed
            folder = case_folder(Path(out_dir) / "cases", c.name, level)
            folder.mkdir(parents=True)
            (folder / "design.json").write_text("{}")
        return {"cases": [], "totals": {}}

    monkeypatch.setattr(levels, "run_suite", fake_suite)
    res = levels.run_levels(SUITE, [3, 1, 2], tmp_path, coarse_to_fine=coarse_to_fine)
    assert list(seen) == [1, 2, 3] and seen[1] is None and res["coarse_to_fine"] == coarse_to_fine
    assert coarse == {lv: coarse_to_fine for lv in (1, 2, 3)}  # a level with priors ignores its own
    if not coarse_to_fine:
        assert seen[2] is None and seen[3] is None
        return
    names = [c.name for c in load_suite(SUITE)[:2]]
    for lv in (2, 3):
        assert seen[lv] == {n: tmp_path / f"level{lv - 1}" / "cases" / f"{n}-r{lv - 1}" / "design.json"
                            for n in names}
