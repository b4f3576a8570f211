"""The examples and the README's Python block run as a user runs them, each
checked by the numbers it prints. They run in this process (``runpy``), so the
Taichi kernels compiled by one are reused by the next; ``--quick`` gives a
design's short homotopy."""

import json
import re
import runpy
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def run_example(name: str, args: list[str], monkeypatch, capsys, cwd: Path) -> str:
    """Run ``examples/NAME`` with ``args`` as ``python examples/NAME ARGS`` would, in
    the folder ``cwd``; what it printed."""
    monkeypatch.chdir(cwd)
    monkeypatch.setattr(sys, "argv", [str(EXAMPLES / name), *args])
    runpy.run_path(str(EXAMPLES / name), run_name="__main__")
    return capsys.readouterr().out


def test_every_example_is_run_here():
    """A script in examples/ that this file does not run would rot unseen."""
    here = Path(__file__).read_text()
    scripts = sorted(p.name for p in EXAMPLES.glob("*.py"))
    assert len(scripts) >= 4 and all(f'"{s}"' in here for s in scripts), scripts


@pytest.mark.slow
def test_design_builtin_designs_the_finger_with_one_tendon(tmp_path, monkeypatch, capsys):
    """The finger's goal is what one tendon along its top side makes: the design
    recommends one, within the 0.5 % budget as built, and design.json says the same."""
    out = run_example("design_builtin.py", ["finger", "--quick", "--out", "d"], monkeypatch, capsys, tmp_path)
    m = re.search(r"finger level 1: (\d+) tendon\(s\), as built ([\d.]+)% of L", out)
    assert m, out
    count, error = int(m[1]), float(m[2])
    assert count == 1 and error <= 0.5, out
    summary = json.loads((tmp_path / "d" / "design.json").read_text())
    assert summary["recommended"]["count"] == count
    assert abs(100 * summary["recommended"]["metrics"]["realizable_pose_error_rel"] - error) <= 0.005


@pytest.mark.slow
def test_scene_in_python_reaches_its_goal_as_built(tmp_path, monkeypatch, capsys):
    out = run_example("scene_in_python.py", ["--quick", "--out", "d"], monkeypatch, capsys, tmp_path)
    m = re.search(r"tapered_finger: (\d+) tendon\(s\), as built ([\d.]+)% of L, body size ([\d.]+) cm", out)
    assert m, out
    assert 1 <= int(m[1]) <= 2 and float(m[2]) <= 1.0, out
    assert abs(float(m[3]) - 100 * (0.08 ** 2 + 0.02 ** 2) ** 0.5) < 0.01  # L, the bounding box's diagonal
    assert (tmp_path / "d" / "design.svg").is_file()


@pytest.mark.slow
def test_the_example_plugin_finds_the_finger_s_straight_tendon(tmp_path, monkeypatch, capsys):
    """Its tendons are straight (no turn at all), and the finger's optimized tension
    runs mostly straight along its sides: they carry most of the active tension-length."""
    out = run_example("extractor_plugin.py", ["finger", "--quick"], monkeypatch, capsys, tmp_path)
    m = re.search(r"straight_runs: (\d+) tendon\(s\), ([\d.]+) cm, largest turn ([\d.]+) deg, "
                  r"coverage ([\d.]+)%", out)
    assert m, out
    assert int(m[1]) >= 1 and float(m[2]) >= 1.0 and float(m[3]) == 0.0 and float(m[4]) >= 50.0, out
    assert list(tmp_path.iterdir()) == []  # its run went into a temporary folder


def _readme_block() -> str:
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert len(blocks) == 1, "the README has one Python block"
    return blocks[0]


@pytest.mark.slow
def test_the_readme_python_block_and_the_small_sweep_example_run(tmp_path, monkeypatch, capsys):
    """Run as written, in a folder that has the repository's examples/; then the
    values it printed are checked. Then examples/small_sweep.py there (it runs the
    same sweep into the same folder)."""
    (tmp_path / "examples").symlink_to(EXAMPLES)
    monkeypatch.chdir(tmp_path)
    space: dict = {"__name__": "__main__"}
    exec(compile(_readme_block(), "README.md", "exec"), space)
    out = capsys.readouterr().out
    assert space["d"].summary["recommended"]["count"] == 1
    assert "True" in out.splitlines()[2]                        # the replay reproduces every stage
    assert space["eq"].residual < 1e-8 and space["eq"].tau.max() > 0
    assert len(space["result"]["cases"]) == 2 and not space["result"]["failed"]
    # the small-sweep example, run where the block ran its sweep (the same file, the same
    # default folder): it designs both cases - reusing the block's, as a sweep reruns
    out = run_example("small_sweep.py", [], monkeypatch, capsys, tmp_path)
    rows = re.findall(r"sparsity ([\d.e-]+): pose error ([\d.]+)% of L, (\d+) active fibers, "
                      r"recommended (\d+) tendon\(s\)", out)
    assert sorted(float(r[0]) for r in rows) == [1e-4, 3e-4], out
    assert all(float(r[1]) < 1.0 and int(r[3]) == 1 for r in rows), out
    again = json.loads((tmp_path / "recordings" / "sweeps" / "small" / "sweep.json").read_text())
    assert all(c["reused"] for c in again["cases"])
    assert [c["design"]["count"] for c in again["cases"]] == [c["design"]["count"] for c in space["result"]["cases"]]
