"""Recordings: the JSON summary, replay, rerun's own verifier, killed runs and resume,
and bad recordings - all through the command line."""

import json
import os
import shutil
import signal
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tendon_taichi import build_problem, load_scene
from tendon_taichi.io.recording import Recorder, read_recording

# five short stages (k = -, 0.25, 0.125, 0.0625, 0.03125) on t_shape level 1
SHORT = ["--stage-iterations", "15", "--k-min", "0.02"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted short run: its recording and JSON summary."""
    from conftest import run_cli

    d = tmp_path_factory.mktemp("ref")
    r = run_cli("optimize", "t_shape", *SHORT, "--record", d / "ref.rrd", "--json", cwd=d)
    assert r.returncode == 0, r.stderr
    return d / "ref.rrd", json.loads(r.stdout)


def test_optimize_summary_follows_the_contract(reference):
    path, s = reference
    for key in ("scene", "resolution", "nodes", "triangles", "fibers", "body_size", "stages", "final",
                "recording", "export", "time_s"):
        assert key in s
    assert [st["stage"] for st in s["stages"]] == [0, 1, 2, 3, 4]
    assert s["stages"][0]["k"] is None and s["stages"][1]["k"] == 0.25
    for st in s["stages"]:
        for key in ("stage", "k", "iterations", "pose_error", "pose_error_rel", "pose_error_max",
                    "active_fibers", "active_length", "tau_max", "objective", "time_s"):
            assert key in st
        assert set(st["objective"]) == {"pose", "sparsity", "continuity", "strand_end", "contraction", "effort"}
        assert st["pose_error_rel"] == pytest.approx(st["pose_error"] / s["body_size"])
    for term in ("sparsity", "strand_end"):  # off in plain soft IK, on in the homotopy
        assert s["stages"][0]["objective"][term] == 0.0 < s["stages"][1]["objective"][term]
    assert s["final"] == s["stages"][-1]
    d = np.load(s["export"])
    assert np.allclose(d["ac"], read_recording(path).stages[-1].ac, rtol=0, atol=0)


def test_each_stage_keeps_its_equilibrium(reference):
    """/stages/x holds each stage's equilibrium losslessly: the export's final state
    bit for bit, and a state the extraction takes instead of solving again."""
    from tendon_taichi.apps.extract import idealized_state

    path, s = reference
    run = read_recording(path)
    problem = run.problem()
    assert all(st.xs is not None and st.xs.shape == (1, problem.mesh.n_nodes, 2) for st in run.stages)
    assert np.array_equal(run.stages[-1].xs[0], np.load(s["export"])["x"])
    recorded = idealized_state(run, problem, 2, "auto")
    run.stages[2].xs = None  # what a format-1 recording gives: solved again from rest
    solved = idealized_state(run, problem, 2, "auto")
    assert np.array_equal(recorded.x, solved.x) and np.array_equal(recorded.tau, solved.tau)


def test_replay_notices_an_equilibrium_that_does_not_reproduce(reference, monkeypatch):
    import tendon_taichi.apps.replay as rp

    path, _ = reference
    real = rp.read_recording

    def shifted(p):
        run = real(p)
        run.stages[1].xs = run.stages[1].xs + 1e-6 * run.problem().size  # a recorded state moved by 1e-6 L
        return run

    monkeypatch.setattr(rp, "read_recording", shifted)
    out = rp.replay(path)
    assert [r["reproduces"] for r in out["stages"]] == [True, False, True, True, True] and not out["reproduces"]
    assert out["stages"][1]["x_rel_diff"] == pytest.approx(1e-6, rel=1e-6)


def test_replay_reproduces_every_stage(reference, cli):
    path, s = reference
    r = cli("replay", path, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["reproduces"] and len(out["stages"]) == 5
    for rec, row in zip(s["stages"], out["stages"]):
        assert row["pose_error_rel_diff"] <= 1e-8
        assert row["active_fibers"] == rec["active_fibers"]
        assert row["recorded_pose_error"] == rec["pose_error"]
    one = json.loads(cli("replay", path, "--stage", 2, "--json").stdout)
    assert [row["stage"] for row in one["stages"]] == [2]


def test_rerun_verifies_the_file(reference):
    path, _ = reference
    exe = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    assert exe, "the rerun CLI ships with rerun-sdk"
    r = subprocess.run([exe, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr + r.stdout


def test_recording_holds_the_layout(reference):
    path, s = reference
    run = read_recording(path)
    p = run.problem()
    ref = build_problem(load_scene("t_shape"), 1)
    assert np.array_equal(p.mesh.nodes, ref.mesh.nodes) and np.array_equal(p.fibers.edges, ref.fibers.edges)
    assert len(run.stages) == 5 and run.meta["resolution"] == 1
    assert run.stages[1].ac.dtype == np.float64 and len(run.stages[1].tau) == ref.fibers.n_fibers
    from rerun.chunk import RrdReader
    entities = {c.entity_path for c in RrdReader(path).stream()}
    for e in ("/meta/run", "/meta/scene", "/problem/nodes", "/world/rest_mesh", "/world/rest_fibers",
              "/world/mesh", "/world/fibers",
              "/world/targets", "/world/goals", "/metrics/objective/pose", "/metrics/figures/pose_error_rel",
              "/metrics/figures/active_fibers", "/metrics/figures/k", "/stages/ac", "/stages/tau"):
        assert e in entities, e


def test_geometry_is_logged_log_spaced_and_scalars_every_iteration(reference):
    """By default each stage's geometry is at its iterations 1, 2, 4, 8, ... and its
    end; the scalars are at every iteration."""
    from rerun.chunk import RrdReader

    path, _ = reference
    steps: dict[str, set] = {"/world/mesh": set(), "/world/fibers": set(), "/metrics/objective/pose": set()}
    for ch in RrdReader(path).stream():
        if ch.entity_path in steps:
            steps[ch.entity_path].update(ch.to_record_batch().column("iteration").to_pylist())
    ends = [int(st.summary["step"]) for st in read_recording(path).stages]
    expect = set()
    for before, end in zip([0] + ends, ends):
        expect |= {before + 2 ** j for j in range(12) if before + 2 ** j <= end} | {end}
    assert steps["/world/mesh"] == steps["/world/fibers"] == expect
    assert steps["/metrics/objective/pose"] == set(range(1, ends[-1] + 1))
    assert len(expect) < ends[-1] / 2  # far fewer frames than iterations


def _start(args, cwd):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # a shell's background job inherits SIGINT ignored; the child must see Ctrl-C as a user would
    return subprocess.Popen([sys.executable, "-m", "tendon_taichi", *map(str, args)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["SIGINT", "SIGTERM", "SIGKILL"])
def test_killed_run_keeps_its_stages_and_resumes_exactly(reference, tmp_path, cli, sig):
    _, ref = reference
    rec = tmp_path / "killed.rrd"
    proc = _start(["optimize", "t_shape", *SHORT, "--record", rec], tmp_path)
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if line.startswith("stage 1 done"):
            proc.send_signal(sig)
            break
    rest = proc.stderr.read()
    rc = proc.wait(timeout=120)
    if sig != signal.SIGKILL:  # SIGTERM (timeout, a batch scheduler) stops it as Ctrl-C does
        assert rc == 128 + sig and "interrupted after" in rest and "Traceback" not in rest, rest
    else:
        assert rc == -signal.SIGKILL
    r = cli("replay", rec, "--json")
    assert r.returncode == 0, r.stderr
    kept = json.loads(r.stdout)
    assert 2 <= len(kept["stages"]) < 5 and kept["reproduces"]
    r = cli("optimize", "--resume", rec, "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    resumed = json.loads(r.stdout)
    assert [st["stage"] for st in resumed["stages"]] == [0, 1, 2, 3, 4]
    for a, b in zip(resumed["stages"], ref["stages"]):
        for key in ("pose_error", "active_fibers", "active_length", "tau_max"):
            assert a[key] == pytest.approx(b[key], rel=1e-6, abs=0), key
        for term in a["objective"]:
            assert a["objective"][term] == pytest.approx(b["objective"][term], rel=1e-6, abs=1e-300)
    assert json.loads(cli("replay", rec, "--json").stdout)["reproduces"]


def _one_line_error(r, text):
    lines = r.stderr.strip().splitlines()
    assert r.returncode != 0 and len(lines) == 1 and text in lines[0], r.stderr
    assert lines[0].startswith("tendon-taichi: error:") and "Traceback" not in r.stderr


def test_bad_recordings(tmp_path, cli, reference):
    path, _ = reference
    _one_line_error(cli("replay", tmp_path / "missing.rrd"), "does not exist")
    (tmp_path / "text.rrd").write_text("hello")
    _one_line_error(cli("replay", tmp_path / "text.rrd"), "not a rerun recording")
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(path.read_bytes()[:300])
    _one_line_error(cli("replay", cut), "recording")
    import rerun as rr
    other = rr.RecordingStream("someone_else")
    other.save(str(tmp_path / "foreign.rrd"))
    other.log("/points", rr.Points2D([[0, 0]]))
    other.flush()
    other.disconnect()
    _one_line_error(cli("replay", tmp_path / "foreign.rrd"), "not a tendon-taichi recording")
    # a run that recorded its header but no completed stage
    p = build_problem(load_scene("finger"), 1)
    empty = Recorder(tmp_path / "empty.rrd", p, p.scene.optimize, {"run_id": "e", "resolution": 1})
    empty.write_header()
    empty.close()
    _one_line_error(cli("replay", tmp_path / "empty.rrd"), "no completed stage")
    _one_line_error(cli("optimize", "--resume", tmp_path / "empty.rrd"), "no completed stage to resume")
    _one_line_error(cli("replay", tmp_path), "is a folder, not a file")


def test_a_recording_that_cannot_be_read_is_one_line(reference, monkeypatch, capsys):
    """As for a file the user may not read (which root, running these tests, could)."""
    import tendon_taichi.io.recording as recording
    from tendon_taichi.cli.main import main

    def refuse(path, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(recording, "open", refuse, raising=False)
    path, _ = reference
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"tendon-taichi: error: cannot read recording '{path}': Permission denied"]


def test_damaged_stage_data_is_one_line(reference, tmp_path, cli):
    """Bytes flipped inside a stage's stored contractions: every reader refuses the file."""
    path, _ = reference
    run = read_recording(path)
    data = bytearray(path.read_bytes())
    at = data.find(np.ascontiguousarray(run.stages[2].ac[:4]).tobytes())
    assert at > 0
    for k in range(8, 48):
        data[at + k] ^= 0xFF
    bad = tmp_path / "damaged.rrd"
    bad.write_bytes(bytes(data))
    why = f"'{bad}' is damaged: stage 2's contractions (/stages/ac)"
    _one_line_error(cli("replay", bad), why)
    _one_line_error(cli("extract", bad, "--extractor", "strands", "--no-record"), why)
    _one_line_error(cli("optimize", "--resume", bad, "--record", tmp_path / "new.rrd"), why)
    assert sorted(os.listdir(tmp_path)) == ["damaged.rrd"]


def test_unwritable_outputs_are_refused_before_any_work(tmp_path, cli):
    (tmp_path / "afile").write_text("")
    _one_line_error(cli("optimize", "t_shape", "--record", tmp_path / "afile" / "run.rrd", cwd=tmp_path),
                    f"cannot write the recording '{tmp_path / 'afile' / 'run.rrd'}': '{tmp_path / 'afile'}' is a file")
    _one_line_error(cli("optimize", "t_shape", "--record", tmp_path / "run.rrd", "--export", tmp_path, cwd=tmp_path),
                    f"the export '{tmp_path}' is a folder")
    assert os.listdir(tmp_path) == ["afile"]


def test_resume_refuses_another_resolution_solver_or_scene(tmp_path, cli, reference):
    """Before any work, and the recording untouched; a SCENE given must be the
    recorded one, by name and TOML text."""
    path, ref = reference
    rec = tmp_path / "run.rrd"
    rec.write_bytes(path.read_bytes())
    other = "cg" if ref["solver"] != "cg" else "direct"
    _one_line_error(cli("optimize", "--resume", rec, "--level", "2", cwd=tmp_path),
                    f"--level 2 cannot be changed when resuming (the run is at level {ref['resolution']})")
    _one_line_error(cli("optimize", "--resume", rec, "--solver", other, cwd=tmp_path),
                    f"--solver {other} cannot be changed when resuming (the run used {ref['solver']})")
    _one_line_error(cli("optimize", "finger", "--resume", rec, cwd=tmp_path),
                    f"'{rec}' is a run of scene 't_shape', not 'finger' (leave SCENE out to resume the recorded one)")
    edited = tmp_path / "t_shape.toml"
    edited.write_text(read_recording(rec).scene_toml + "\n[optimize]\nstage_iterations = 7\n")
    _one_line_error(cli("optimize", edited, "--resume", rec, cwd=tmp_path),
                    f"scene 't_shape' is not the one '{rec}' ran: its TOML text differs "
                    "(leave SCENE out to resume the recorded one)")
    assert rec.read_bytes() == path.read_bytes() and sorted(tmp_path.iterdir()) == [rec, edited]


def frame_starts(data: bytes) -> list[int]:
    """Where an .rrd's frames start (rerun's framing: a 12-byte "RRF2" stream header,
    then frames of a 16-byte header - kind, length - and that many bytes), up to and
    with its end-of-stream frame (kind 0), which the file's footer follows."""
    off, starts = 12, []
    while off + 16 <= len(data):
        kind, length = struct.unpack_from("<QQ", data, off)
        starts.append(off)
        if kind == 0:
            break
        off += 16 + length
    return starts


@pytest.mark.parametrize("into", [8, 100])
def test_torn_last_frame_is_tolerated(reference, tmp_path, cli, into):
    """A run killed while writing leaves a torn last frame: the complete part is read,
    and said to be torn - also where the tear is within the frame's 16-byte header,
    which rerun's own reader takes for a clean end (the frame cut here is the one
    three quarters into the file, ``into`` bytes from its start)."""
    path, _ = reference
    torn = tmp_path / "torn.rrd"
    data = path.read_bytes()
    starts = frame_starts(data)
    i = max(i for i, o in enumerate(starts) if o <= len(data) * 3 // 4)
    assert starts[i] + into < starts[i + 1]  # within that frame
    torn.write_bytes(data[: starts[i] + into])
    r = cli("replay", torn, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["truncated"] and 1 <= len(out["stages"]) <= 5 and out["reproduces"]
    r = cli("extract", torn, "--extractor", "strands", "--no-consolidate", "--no-record", "--json")
    assert r.returncode == 0, r.stderr
    last = len(out["stages"]) - 1
    assert json.loads(r.stdout)["truncated"] and json.loads(r.stdout)["stage"] == last
    assert f"is truncated (an interrupted run?): only its complete stages 0..{last} were read" in r.stderr


def test_unreachable_goal_gives_a_best_effort_and_a_warning(tmp_path, cli):
    text = load_scene("finger").source.replace("goal = [0.0939, 0.0345]", "goal = [0.30, 0.30]")
    (tmp_path / "far.toml").write_text(text)
    r = cli("optimize", tmp_path / "far.toml", "--stage-iterations", "10", "--k-min", "0.4",
            "--record", tmp_path / "far.rrd", "--json", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    s = json.loads(r.stdout)
    assert "warning: the goals are out of reach" in r.stderr
    assert s["final"]["pose_error_rel"] > 0.05 and s["warnings"]
    assert (tmp_path / "far.npz").exists()


def test_optimize_bad_input(cli, tmp_path):
    _one_line_error(cli("optimize", "t_shape", "--sparsity", "-1", cwd=tmp_path), "sparsity must be >= 0")
    _one_line_error(cli("optimize", cwd=tmp_path), "a SCENE is required")
    _one_line_error(cli("optimize", "t_shape", "--record", "x.txt", cwd=tmp_path), "must be an .rrd")
    assert not (tmp_path / "recordings").exists() or not any((tmp_path / "recordings").iterdir())
