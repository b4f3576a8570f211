"""The benchmark runs headless and writes its JSON, CSV and PNG (timings are not
asserted: machines are noisy; the figures that do not depend on speed are)."""

import csv
import json

import numpy as np

SMALL = """
name = "small_finger"
[body]
outline = [[0.0, 0.0], [0.06, 0.0], [0.06, 0.015], [0.0, 0.015]]
max_triangle_area = 1.6e-5
[fibers]
spacing = 0.005
[[fixed]]
box = [[-0.0005, -0.0005], [0.0005, 0.0155]]
[[targets]]
point = [0.06, 0.0075]
goal = [0.058, 0.015]
[optimize]
stage_iterations = 8
homotopy = { k0 = 1.0, factor = 0.5, k_min = 0.3 }
"""


def test_bench_writes_its_outputs(tmp_path, cli):
    (tmp_path / "small.toml").write_text(SMALL)
    out = tmp_path / "bench"
    r = cli("bench", tmp_path / "small.toml", "--levels", 1, 2, "--solver", "cg", "direct", "--repeat", 1,
            "--optimize-levels", 1, "--out", out, "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert [lv["level"] for lv in res["levels"]] == [1, 2] and res["machine"]["cores"] >= 1
    assert res["compile_s"] > 0
    for lv in res["levels"]:
        for key in ("nodes", "triangles", "fibers", "dofs"):
            assert lv[key] > 0
        assert set(lv["solvers"]) == {"cg", "direct"}
        for s, f in lv["solvers"].items():
            for key in ("equilibrium_cold_s", "equilibrium_warm_s", "adjoint_s", "gradient_s",
                        "forward_sensitivity_s"):
                assert 0 < f[key]["min"] <= f[key]["median"] <= f[key]["max"]
            assert f["newton_iterations"]["warm"] < f["newton_iterations"]["cold"]
            assert f["forward_vs_adjoint_rel_diff"] < 1e-6  # both give the same gradient
            assert f["peak_memory_mb"] > 0
        base = lv["baseline_gradient_s"]
        assert 0 < base["min"] <= base["median"] <= base["max"]
        assert set(lv["gradient_speedup"]) == {"cg", "direct"}
        for s, f in lv["solvers"].items():  # the baseline's time over the backend's, as reported
            assert lv["gradient_speedup"][s] == base["median"] / f["gradient_s"]["median"]
    one = res["levels"][0]["solvers"]
    for s in ("cg", "direct"):
        assert one[s]["stages"] == 3 and one[s]["optimize_s"]["median"] > 0
        assert set(one[s]["extractors"]) >= {"strands", "path_cover", "network_discovery"}
        rrd = out / f"small_finger-r1-{s}" / "run.rrd"
        assert one[s]["recording_mb"] == rrd.stat().st_size / 1e6 > 0
        assert one[s]["design_s"] >= one[s]["optimize_s"]["median"]
    assert "optimize_s" not in res["levels"][1]["solvers"]["cg"]
    rows = list(csv.DictReader(open(out / "bench.csv")))
    assert len(rows) == 4 and {r["solver"] for r in rows} == {"cg", "direct"}
    assert all(float(r["gradient_speedup"]) > 0 for r in rows)
    assert {float(r["recording_mb"]) for r in rows if r["recording_mb"]} == \
        {one[s]["recording_mb"] for s in ("cg", "direct")}
    assert (out / "bench.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for s in ("cg", "direct"):
        assert np.isfinite(res["exponents"][s]["equilibrium_cold_s"])
    _check_figure(res)


def _check_figure(res):
    """The plot draws one time series per backend and timing that has figures, with its
    exponent in the legend, and the quality of the one optimized level per extractor."""
    from tendon_taichi.apps.bench import TIMINGS
    from tendon_taichi.io.plots import bench_figure

    fig = bench_figure(res, TIMINGS)
    times, quality, tendons, realizable = fig.axes
    expected = {f"{s}: {k[:-2]}" for lv in res["levels"] for s, f in lv["solvers"].items() for k in TIMINGS
                if f.get(k)}
    labels = [ln.get_label() for ln in times.get_lines()]
    assert {lab.split(" (")[0] for lab in labels} == expected and len(labels) == len(expected)
    assert all("~DOFs^" in lab for lab in labels if lab.startswith(("cg: equilibrium", "direct: equilibrium")))
    cold = next(ln for ln in times.get_lines() if ln.get_label().startswith("cg: equilibrium_cold"))
    assert list(cold.get_xdata()) == [lv["dofs"] for lv in res["levels"]]
    names = set(res["levels"][0]["solvers"]["cg"]["extractors"])
    assert {ln.get_label().split("/")[-1] for ln in tendons.get_lines()} == names
