"""Every script under benchmarks/ runs, at a tiny size, and writes what it says
(examples as tests); the documentation's generated tables are current."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tendon_taichi.solve import pardiso

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
#: a short optimization that still ends sparse (a dense pattern would make consolidation slow)
TINY = ("--set", "stage_iterations=30", "--beam", 1, "--no-converge")
#: the side-by-side scripts' design options (after SCENE LEVEL): short, one extractor, one round, beam 1
SHORT_DESIGN = ("--stage-iterations", 25, "--k0", 1, "--k-min", 0.1, "--extractors", "strands", "--refine", 1,
                "--beam", 1, "--no-converge")


def run(script: Path, *args, cwd=None, timeout=900):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, str(script), *map(str, args)], capture_output=True, text=True,
                       cwd=cwd or ROOT, timeout=timeout, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def test_every_script_has_a_test():
    scripts = {p.relative_to(BENCH).as_posix() for p in BENCH.rglob("*.py")}
    tested = {"simulate_levels.py", "how_it_works/make_figure.py", "planted/make_suite.py", "planted/reextract.py",
              "planted/counts_by_level.py", "sweeps/dask_overhead.py", "bench/make_bench.py",
              "planted_results/make_results.py", "hostile_input/make_table.py", "bench/versus_commit.py",
              "realizable_side_by_side.py", "planted/held_out.py", "routes_side_by_side.py",
              "secant_replay.py", "route_replay.py", "extension_screen.py", "_scene_args.py",
              "warm_newton.py", "warm_parts.py", "auto_solver.py", "assembly.py", "multigrid.py", "pardiso_modes.py",
              "route_gradients.py", "kernel_launch.py", "search_cost.py"}
    assert scripts == tested


def test_search_cost_counts_the_candidates_of_over_segmented_layouts(tmp_path):
    run(BENCH / "search_cost.py", "--counts", 3, 12, 24, "--json", tmp_path / "cost.json")
    rows = json.loads((tmp_path / "cost.json").read_text())
    assert [r["pieces"] for r in rows] == [3, 12, 24] and all(r["merged"] == 3 for r in rows)
    for r in rows:
        assert r["reductions_bounded"] <= r["reductions_every_pair"] and r["reductions_bounded"] <= 13 * r["pieces"]
    assert rows[-1]["pool_k1_bounded"] < rows[-1]["pool_k1_every_pair"]


def test_scene_args_splits_scene_level_flags_and_repeat():
    import importlib.util

    spec = importlib.util.spec_from_file_location("_scene_args", BENCH / "_scene_args.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    scene_args = module.scene_args
    assert scene_args(["t_shape"]) == ("t_shape", "1", [], None)
    assert scene_args(["t_shape", "3", "--refine", "1"]) == ("t_shape", "3", ["--refine", "1"], None)
    assert scene_args(["t_shape", "--beam", "1"]) == ("t_shape", "1", ["--beam", "1"], None)
    argv = ["t_shape", "2", "--repeat", "5", "--beam", "1"]
    assert scene_args(argv, repeat=2) == ("t_shape", "2", ["--beam", "1"], 5)
    assert argv == ["t_shape", "2", "--repeat", "5", "--beam", "1"]  # the caller's list untouched
    assert scene_args(["t_shape", "--beam", "1"], repeat=2) == ("t_shape", "1", ["--beam", "1"], 2)
    assert scene_args(["t_shape", "--repeat", "5"]) == ("t_shape", "1", ["--repeat", "5"], None)


def test_realizable_side_by_side_solves_each_robot_both_ways():
    out = run(BENCH / "realizable_side_by_side.py", "finger", 1, *SHORT_DESIGN).stdout.splitlines()[-4:]
    assert int(out[0].split()[2]) > 0 and out[0].startswith("realizable solves:")
    assert out[1].startswith("Gauss-Newton worse by > 1e-07 L:")
    lbfgsb, gn = (int(ln.split()[-4]) for ln in out[2:4])
    assert out[2].startswith("L-BFGS-B:") and out[3].startswith("Gauss-Newton:") and gn < lbfgsb


def test_routes_side_by_side_runs_each_route_optimization_both_ways():
    out = run(BENCH / "routes_side_by_side.py", "t_shape", 1, *SHORT_DESIGN, "--calls", 3).stdout.splitlines()[-4:]
    assert out[0].startswith("route optimizations:") and int(out[0].split()[2]) == 3
    assert out[1].startswith("SLSQP lower:")
    (old, new) = (int(ln.split(": ")[1].split()[0]) for ln in out[2:4])
    assert out[2].startswith("L-BFGS-B, penalty:") and out[3].startswith("SLSQP, constraint:") and old > 0 < new


def test_route_gradients_runs_route_optimizations_both_ways():
    out = run(BENCH / "route_gradients.py", "t_shape", 1, *SHORT_DESIGN, "--repeat", 1, "--calls", 3
              ).stdout.splitlines()[-4:]
    assert out[0].startswith("route optimizations:") and int(out[0].split()[2]) == 3
    assert out[1].startswith("gradient at every point:") and out[2].startswith("gradient where SLSQP asks:")
    (every_points, every_adjoints), (points, adjoints) = (
        [int(part.split()[0]) for part in ln.split(", ")[1:]] for ln in out[1:3])
    assert every_points > 0 and 0 < adjoints < min(points, every_adjoints)  # fewer adjoint solves where asked
    assert out[3].startswith("objective where asked / at every point: median")


def test_secant_replay_solves_the_same_evaluations_both_ways():
    out = run(BENCH / "secant_replay.py", "t_shape", 1, "--stage-iterations", 25, "--k-min", 0.1,
              "--repeat", 1).stdout.splitlines()[-4:]
    assert out[0].startswith("evaluations:") and int(out[0].split()[1]) > 0
    assert out[1].startswith("plain chord steps:") and out[2].startswith("secant-corrected:")
    assert all(int(part.split()[0]) > 0 for ln in out[1:3] for part in ln.split(", ")[1:])  # factorizations, chords
    # the equilibria agree to Newton's tolerance (1e-8 of the force scale), the pose term to ~1e-5
    assert out[3].startswith("objectives agree to:") and float(out[3].split()[3]) <= 1e-4


def test_route_replay_runs_route_optimizations_both_ways():
    lines = run(BENCH / "route_replay.py", "t_shape", 1, *SHORT_DESIGN, "--repeat", 1, "--calls", 3).stdout.splitlines()
    out = lines[next(i for i, ln in enumerate(lines) if ln.startswith("route optimizations:")):]
    assert out[0].startswith("route optimizations:") and int(out[0].split()[2]) == 3
    assert out[1].startswith("every pattern made anew:") and out[2].startswith("detached segments:")
    assert all(int(ln.split(", ")[1].split()[0]) > 0 for ln in out[1:3])  # evaluations
    assert out[3].startswith("summed objectives agree to:")
    # the Hessians equal to round-off: the same objective and gradient at every point the
    # optimizations asked for (their own paths split where SLSQP's steps amplify the round-off)
    words = out[4].replace(",", "").split()
    assert out[4].startswith("at the same points:") and int(words[-2].lstrip("(")) > 0
    assert float(words[7]) <= 1e-9 and float(words[10]) <= 1e-7
    if not pardiso.available():  # the indefinite factorization is PARDISO's: nothing to compare
        assert len(out) == 5
        return
    assert len(out) == 6 and out[5].startswith("not positive definite: PARDISO ")
    ways = dict(part.split(" ", 1) for part in out[5].split(": ", 1)[1].split(", "))
    assert sorted(ways) == ["PARDISO", "SuperLU"]
    for way in ways.values():  # "1.23 ms each (12)": each time > 0 where there were any
        ms, count = float(way.split()[0]), int(way.split("(")[1].rstrip(")"))
        assert count >= 0 and (ms > 0) == (count > 0)


def test_extension_screen_finishes_every_extension_in_full_too():
    out = run(BENCH / "extension_screen.py", "t_shape", 1, *SHORT_DESIGN).stdout.splitlines()[-5:]
    assert out[0].startswith("extensions:")
    tried, layouts = int(out[0].split()[1]), int(out[0].split()[3])
    assert tried >= layouts > 0
    assert out[1].startswith("solve's best finishes least:") and int(out[1].split()[4]) <= layouts
    assert out[2].startswith("screen's best finishes least:") and int(out[2].split()[4]) <= layouts
    assert out[3].startswith("front's finish / least full finish:")
    screens, ours, full = (int(part.split()[-1]) for part in out[4].split(": ", 1)[1].split(", "))
    assert out[4].startswith("route evaluations:") and 0 < screens and 0 < ours and 0 < full


def test_warm_newton_traces_both_warm_solves_per_level():
    out = run(BENCH / "warm_newton.py", "t_shape", "--levels", 1, 2, "--repeat", 1).stdout.splitlines()
    assert out[0].split()[:2] == ["level", "DOFs"] and out[-1].startswith("exponents: bench")
    for level, line in zip((1, 2), out[1:3]):
        cols = line.split()
        assert int(cols[0]) == level and int(cols[2]) >= int(cols[3]) >= 0
        steps, residuals = int(cols[5]), [float(v) for v in cols[12:]]
        assert len(residuals) == steps + 1 and residuals[-1] <= 1e-10 < residuals[0]
        assert all(b < a for a, b in zip(residuals, residuals[1:]))
        # to 1e-8: the residual before the steps the looser solve took was above it, after them below
        loose = int(cols[7])
        assert 1 <= loose <= steps and residuals[loose - 1] > 1e-8 >= residuals[loose]
        assert int(cols[9]) >= 1 and int(cols[10]) >= 0  # the optimizer's chord steps, factorizations


def test_warm_parts_splits_the_warm_equilibrium_into_parts_that_add_up():
    out = run(BENCH / "warm_parts.py", "t_shape", "--levels", 1, 2, "--repeat", 2).stdout.splitlines()
    head = out[0].split()
    assert head[:5] == ["level", "DOFs", "steps", "factors", "entries"] and head[5] == "total"
    for level, line in zip((1, 2), out[1:3]):
        cols = line.split()
        assert int(cols[0]) == level and int(cols[2]) >= 1
        assert int(cols[3]) == int(cols[2])  # plain exact Newton: one factorization per step
        total, parts = float(cols[5]), [float(v) for v in cols[6:]]
        assert len(parts) == 6 and all(v >= 0 for v in parts) and parts[0] > 0 and parts[2] > 0
        assert abs(sum(parts) - total) <= 0.04  # the rest is what the parts leave (to the printed 0.01 ms)
    assert out[3].startswith("exponents: total") and out[4].startswith("per factorization: ")
    assert "linear rest: " in out[4]


def test_kernel_launch_times_both_call_paths_and_a_parallel_loop():
    out = run(BENCH / "kernel_launch.py", "--launches", 50).stdout.splitlines()
    assert out[0].startswith("through Taichi: ") and ", through the launcher: " in out[0]
    taichi, launcher = (float(part.split()[0]) for part in out[0].split(": ")[1:3])
    assert out[1].startswith("parallel: ") and taichi > 0 < launcher and float(out[1].split()[1]) > 0


def test_simulate_levels_prints_each_level_and_solver():
    out = run(BENCH / "simulate_levels.py", "--levels", 1, "--repeat", 1).stdout.splitlines()
    rows = [ln.split() for ln in out[1:-1]]
    assert [r[5] for r in rows] == ["cg", "direct"] and all(r[0] == "1" for r in rows)
    assert rows[0][:5] == rows[1][:5] and int(rows[0][4]) > 0  # same problem for both backends
    assert out[-1].startswith("first solve in the process")


def test_auto_solver_times_direct_and_cg_on_the_same_optimization():
    out = run(BENCH / "auto_solver.py", "--levels", 1, "--iterations", 3, "--factorizations", "qdldl").stdout
    rows = [ln.split() for ln in out.splitlines()[1:]]
    assert [r[:4] for r in rows] == [["1", "3", "qdldl", "direct"], ["1", "3", "qdldl", "cg"]]
    walls = [float(r[4]) for r in rows]
    assert all(w > 0 for w in walls) and float(rows[1][8]) > 0 and len(rows[0]) == 8  # the ratio on cg's row
    errors = [float(r[6]) for r in rows]  # one problem, two linear backends: the same optimum nearly
    assert int(rows[0][5]) > 0 and abs(errors[0] - errors[1]) < 0.1 * errors[0]


def test_assembly_times_both_ways_and_finds_the_same_bits():
    out = run(BENCH / "assembly.py", "t_shape", "--levels", 1, 2, "--repeat", 3).stdout.splitlines()
    assert out[0].split()[:3] == ["level", "entries", "sparse"]
    rows = [ln.split() for ln in out[1:]]
    assert [r[0] for r in rows] == ["1", "2"] and all(r[-1] == "yes" for r in rows)
    for r in rows:
        assert int(r[1]) > int(r[2]) > 0 and float(r[3]) > 0 and float(r[4]) > 0


def test_multigrid_compares_the_v_cycles_with_the_factorization():
    out = run(BENCH / "multigrid.py", "t_shape", "--levels", 1, 3, "--repeat", 1).stdout.splitlines()
    assert out[0].split()[:4] == ["level", "DOFs", "backend", "levels"]
    rows = {(ln[:5].strip(), ln[13:37].strip()): ln[37:].split() for ln in out[1:]}
    names = ["cg-gmg forward-backward", "cg-gmg symmetric", "cg-amg", "direct"]
    assert sorted(rows) == sorted((lv, n) for lv in ("1", "3") for n in names)
    for sweeps in names[:2]:
        assert rows[("1", sweeps)][0] == "1" and rows[("1", sweeps)][2] == "1"  # one level: the exact inverse
        levels, _, it8, _, it10, _ = rows[("3", sweeps)]
        assert levels == "2" and 1 < int(it8) <= int(it10) <= 60  # level 3 over level 1
    assert float(rows[("3", "direct")][-1]) > 0


def test_pardiso_modes_times_both_modes_and_the_reproducible_one_keeps_its_bits():
    from tendon_taichi.solve import pardiso

    if not pardiso.available():
        pytest.skip("MKL PARDISO is not installed (the mkl extra)")
    out = run(BENCH / "pardiso_modes.py", "t_shape", "--levels", 1, 4, "--repeat", 3).stdout.splitlines()
    assert out[0].split()[:3] == ["level", "DOFs", "mode"]
    rows = [ln.split() for ln in out[1:]]
    assert [(r[0], r[2]) for r in rows] == [("1", "CNR"), ("1", "plain*"), ("4", "CNR*"), ("4", "plain")]
    assert int(rows[0][1]) < pardiso.PARALLEL_MIN <= int(rows[2][1])
    assert rows[0][-1] == rows[2][-1] == "yes"  # the mode: the same bits on one thread and two
    assert all(float(r[i]) > 0 for r in rows for i in (3, 5, 6, 8))


def test_how_it_works_draws_five_panels(tmp_path):
    png = tmp_path / "h.png"
    r = run(BENCH / "how_it_works" / "make_figure.py", "t_shape_planted_1t_s1", "--level", 1,
            "--stage-iterations", 30, "--beam", 1, "--no-converge", "--out", png)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "tendons from" in r.stderr and "as built" in r.stderr
    from PIL import Image
    with Image.open(png) as im:
        assert "commit" in im.info["Comment"]  # the picture records what made it


def _same(a, b, path="") -> None:
    """JSON values ``a`` and ``b`` equal, floats to 1e-9 relative: the last bits of
    a solve differ between CPUs (vector units, libm), the layout must not."""
    assert type(a) is type(b) or {type(a), type(b)} <= {int, float}, path
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-9, abs=1e-300), path
    else:
        assert a == b, path


def test_make_suite_regenerates_a_checked_in_case(tmp_path):
    """The scene file byte for byte, the layout (its JSON) to the last bits a CPU may change."""
    name = "t_shape_planted_1t_s1"
    run(BENCH / "planted" / "make_suite.py", "--out", tmp_path, "--only", name, "--no-gallery")
    assert (tmp_path / f"{name}.toml").read_bytes() == (BENCH / "planted" / f"{name}.toml").read_bytes()
    _same(json.loads((tmp_path / f"{name}.json").read_text()),
          json.loads((BENCH / "planted" / f"{name}.json").read_text()))


@pytest.fixture(scope="module")
def planted_results(tmp_path_factory):
    """make_results.py on one case at level 1 (tiny settings): its outputs and run."""
    out = tmp_path_factory.mktemp("results")
    run(BENCH / "planted_results" / "make_results.py", "--levels", 1, "--cases", "t_shape_planted_1t_s1",
        "--workers", 0, "--out", out / "page", "--runs", out / "runs", *TINY)
    return out


def test_make_results_writes_the_results_page(planted_results):
    page = (planted_results / "page" / "README.md").read_text()
    run_json = json.loads((planted_results / "runs" / "r1" / "planted_bench.json").read_text())
    (case,) = run_json["cases"]
    assert f"| {case['case']} | {case['count']}/{case['planted_count']} {case['best']}" in page
    assert run_json["provenance"]["commit"] in page or run_json["provenance"]["commit"] is None
    rows = list(csv.DictReader(open(planted_results / "page" / "planted_bench_level1.csv")))
    assert [r["case"] for r in rows] == [case["case"]] and int(rows[0]["count"]) == case["count"]
    assert "same count at every level: 1 of 1" in (planted_results / "page" / "counts_by_level.md").read_text()
    assert (planted_results / "page" / "worst_cases.png").read_bytes()[:4] == b"\x89PNG"
    assert f"{case['case']} at level 1" in page and "![the worst results](worst_cases.png)" in page
    assert "## The front across levels" in page and "![the fronts](fronts.png)" in page
    assert (planted_results / "page" / "fronts.png").read_bytes()[:4] == b"\x89PNG"


def test_reextract_reproduces_the_run(planted_results, tmp_path):
    src = planted_results / "runs" / "r1" / "planted_bench.json"
    run(BENCH / "planted" / "reextract.py", src, tmp_path / "re.json")
    (before,), (after,) = json.loads(src.read_text())["cases"], json.loads((tmp_path / "re.json").read_text())["cases"]
    for key in ("count", "best", "realizable_pose_error_rel", "kinks", "capstan_worst", "passed"):
        assert after[key] == before[key], key


def test_held_out_solves_each_front_entry_on_a_finer_mesh(planted_results):
    """Each front entry up to planted + 1 tendons, solved on the next mesh up: the
    error reported is the run's (level 1: the run had --no-converge), the one there
    is finite and differs from it (another mesh), and the summary counts them."""
    src = planted_results / "runs" / "r1"
    (case,) = json.loads((src / "planted_bench.json").read_text())["cases"]
    out = run(BENCH / "planted" / "held_out.py", src, "--above", 1).stdout.splitlines()
    front = [e for e in case["front"] if e["count"] <= case["planted_count"] + 1]
    assert len(out) == len(front) + 1 and out[-1].startswith(f"level 1: {len(front)} entries")
    for line, e in zip(out, front):
        words = line.split()
        assert words[0] == case["case"] and words[1] == f"k={e['count']}"
        reported, there = float(words[3].rstrip("%")), float(words[5].rstrip("%"))
        assert reported == pytest.approx(100 * e["realizable_pose_error_rel"], abs=1e-4)
        assert np.isfinite(there) and there != reported


def test_counts_by_level_tables_the_runs(planted_results):
    src = planted_results / "runs" / "r1" / "planted_bench.json"
    out = run(BENCH / "planted" / "counts_by_level.py", src, src).stdout
    case = json.loads(src.read_text())["cases"][0]
    assert f"| {case['case']} | {case['planted_count']} | {case['count']}" in out
    assert "same count at every level: 1 of 1" in out


def test_dask_overhead_runs_tasks_on_a_cluster():
    res = json.loads(run(BENCH / "sweeps" / "dask_overhead.py", "--workers", 1, "--tasks", 4).stdout)
    assert res["tasks"] == 4 and res["workers"] == 1 and res["overhead_per_task_ms"] > 0


def test_make_bench_writes_the_results_and_the_page(tmp_path):
    out, page = tmp_path / "bench", tmp_path / "docs" / "performance.md"
    run(BENCH / "bench" / "make_bench.py", "--levels", 1, "--repeat", 1, "--no-optimize", "--alone", 1,
        "--out", out, "--page", page)
    res = json.loads((out / "bench.json").read_text())
    text = page.read_text()
    alone = res["alone"]  # the whole optimization at level 1 in a process of its own
    assert alone["level"] == 1 and alone["evaluations"] > 0 and 0 < alone["time_s"] < alone["wall_s"]
    assert f"{alone['wall_s']:.1f} s wall" in text
    assert alone["peak_mb"] is None or 50 < alone["peak_mb"] < 5000  # Linux: read from /proc
    assert res["provenance"]["commit"] is None or res["provenance"]["commit"] in text
    table = (out / "table.txt").read_text().splitlines()
    assert table[0].split()[:4] == ["level", "DOFs", "fibers", "solver"] and len(table) == 5  # header + cg, cg-amg, cg-gmg, direct
    assert all(line in text for line in table) and "](../bench/bench.png)" in text
    assert np.isfinite(res["levels"][0]["solvers"]["direct"]["equilibrium_cold_s"]["median"])
    (out / "table.txt").unlink()
    again = tmp_path / "site" / "performance.md"  # the page again, from bench.json alone
    run(BENCH / "bench" / "make_bench.py", "--page-only", "--out", out, "--page", again)
    assert again.read_text() == text
    assert (out / "table.txt").read_text().splitlines() == table


def test_the_docs_generated_tables_are_current():
    run(ROOT / "docs" / "make_docs.py", "--check")


def test_the_hostile_input_table_runs_a_case_and_writes_its_row(tmp_path):
    """make_table.py's too-large cases (quick: refused before meshing) become table
    rows with the exit status, the error line and what was left on disk."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_table", BENCH / "hostile_input" / "make_table.py")
    mt = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mt)
    b = mt.Bench.__new__(mt.Bench)  # without installing the demo plugin: these cases use none
    b.work, b.env, b.rows = tmp_path, dict(os.environ), []
    mt.too_large(b)
    (first, second) = b.rows
    assert first[2] == "2" and "finger at level 99 would have about" in first[3] and first[4] == "nothing"
    assert second[2] == "2" and "degrees of freedom" in second[3] and second[4] == "`s.toml`"
    text = mt.table(b.rows).splitlines()
    assert text[0].startswith("| case |") and len(text) == 4 and text[2].startswith("| 9. `simulate finger")


def test_versus_commit_times_both_pipelines(tmp_path):
    """With this environment standing in for the earlier commit's (its optimize and
    compare), the script times both pipelines at a level and writes the run's ratio."""
    venv = Path(sys.executable).parent.parent
    if not (venv / "bin" / "tendon-taichi").exists():
        pytest.skip("the interpreter is not in a virtual environment with tendon-taichi installed")
    out = run(BENCH / "bench" / "versus_commit.py", venv, "--levels", 1, "--tiny", "--out", tmp_path,
              "--json", tmp_path / "v.json")
    row = json.loads((tmp_path / "v.json").read_text())["levels"][0]
    assert row["level"] == 1 and len(row["runs"]) == 1
    (r,) = row["runs"]
    assert r["old_s"] == pytest.approx(r["old_optimize_s"] + r["old_compare_s"])
    assert r["speedup"] == pytest.approx(r["old_s"] / r["design_s"]) == row["speedup"]
    assert (tmp_path / "design-r1" / "design.json").exists()
    assert "old / new" in out.stdout and "median of" not in out.stdout


def test_versus_commit_reports_the_median_of_repeated_runs(monkeypatch):
    """With --repeat N each figure is its own median over the runs, and the ratio's
    spread is reported (two runs here, their figures made up)."""
    monkeypatch.syspath_prepend(str(BENCH / "bench"))
    import versus_commit

    runs = [{"old_optimize_s": 4.0, "old_compare_s": 2.0, "old_s": 6.0, "design_s": 3.0, "speedup": 2.0},
            {"old_optimize_s": 6.0, "old_compare_s": 1.0, "old_s": 7.0, "design_s": 2.0, "speedup": 3.5}]
    row = versus_commit.summarized(2, runs)
    assert row["level"] == 2 and row["runs"] == runs
    assert (row["old_optimize_s"], row["old_compare_s"], row["old_s"], row["design_s"]) == (5.0, 1.5, 6.5, 2.5)
    assert (row["speedup"], row["speedup_min"], row["speedup_max"]) == (2.75, 2.0, 3.5)
    assert versus_commit.line(row).endswith("old / new 2.75 (median of 2 runs: 2.00-3.50)")
    assert "median of" not in versus_commit.line(versus_commit.summarized(2, runs[:1]))


def test_make_results_takes_generated_cases(tmp_path, monkeypatch):
    """With --generated N it runs N generated cases, written into RUNS/generated/
    first (the same files planted-bench --generated writes)."""
    import argparse

    monkeypatch.syspath_prepend(str(BENCH / "planted_results"))
    import make_results

    folder = make_results.suite_folder(argparse.Namespace(generated=1, seed=1, runs=tmp_path))
    assert folder == tmp_path / "generated"
    assert sorted(p.name for p in folder.iterdir()) == ["gen001_hook_planted_1t_s1.json",
                                                        "gen001_hook_planted_1t_s1.toml"]
    assert make_results.suite_folder(argparse.Namespace(generated=None, seed=0, runs=tmp_path)) == make_results.SUITE
    # drawn once: a second run with the same cases reuses them, as they are
    toml = folder / "gen001_hook_planted_1t_s1.toml"
    toml.write_text(toml.read_text() + "# kept\n")
    assert make_results.suite_folder(argparse.Namespace(generated=1, seed=1, runs=tmp_path)) == folder
    assert toml.read_text().endswith("# kept\n")
    make_results.copy_cases(folder, tmp_path / "out")
    assert sorted(p.name for p in (tmp_path / "out" / "cases").iterdir()) == sorted(p.name for p in folder.iterdir())
