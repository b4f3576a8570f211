"""Try every case of the hostile-input issue against the installed tool and write
what each now prints: ``benchmarks/hostile_input/README.md``.

    python benchmarks/hostile_input/make_table.py [--out FILE]

Each case runs the real command line in a scratch folder (removed at the end):
malformed scenes, damaged and truncated recordings, two writers at once, kills,
read-only folders, plugins that break the rules (the test suite's demo plugin,
installed into the scratch folder). The table gives the exit status, the line
the user reads, and what the case left on disk. About 6 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import meshio
import numpy as np

from tendon_taichi.io.recording import read_recording
from tendon_taichi.version import provenance

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = ROOT / "tests" / "plugins" / "demo_extractor"
QUICK = ("--no-consolidate", "--extractors")
SQUARE = ("name = '{name}'\n[body]\noutline = {outline}\n{extra}[[fixed]]\nbox = {box}\n"
          "[[targets]]\npoint = {point}\ngoal = {goal}\n")


class Bench:
    """The scratch folder, the environment (the demo plugin on PYTHONPATH) and the rows."""

    def __init__(self, work: Path):
        self.work = work
        site = work / "site"
        subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                        "--no-index", "--target", str(site), str(PLUGIN)], check=True)
        self.env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
        self.rows: list[tuple[str, str, str, str, str]] = []

    def start(self, *args, cwd: Path | None = None) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-m", "tendon_taichi", *map(str, args)], cwd=cwd or self.work,
                                env=self.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def cli(self, *args, cwd: Path | None = None) -> subprocess.CompletedProcess:
        p = self.start(*args, cwd=cwd)
        out, err = p.communicate(timeout=900)
        return subprocess.CompletedProcess(p.args, p.returncode, out, err)

    def folder(self, name: str) -> Path:
        d = self.work / name
        d.mkdir()
        return d

    def row(self, case: str, shown: str, r: subprocess.CompletedProcess | str, left: str, said: str | None = None):
        """One table row: ``said`` or the error/warning lines of ``r`` (progress aside)."""
        code = r if isinstance(r, str) else str(r.returncode)
        if said is None:
            lines = [ln for ln in r.stderr.splitlines() if ln.startswith("tendon-taichi:") or "Traceback" in ln]
            said = " / ".join(lines) or "(no error line)"
        self.rows.append((case, shown, code, said, left))
        print(f"{case}: exit {code}: {said}", file=sys.stderr, flush=True)


def files(d: Path) -> str:
    """The files under ``d``, relative, or 'nothing'."""
    got = sorted(str(p.relative_to(d)) for p in d.rglob("*") if p.is_file())
    return ", ".join(f"`{g}`" for g in got) or "nothing"


def logged_stages(path: Path, extractor: str = "strands") -> list[int]:
    from rerun.chunk import RrdReader

    return sorted({s for ch in RrdReader(path).stream() if ch.entity_path == f"/tendons/{extractor}/summary"
                   for s in ch.to_record_batch().column("stage").to_pylist()})


def scene(d: Path, name: str = "s", outline: str = "[[0, 0], [0.04, 0], [0.04, 0.04], [0, 0.04]]",
          box: str = "[[-1, -0.001], [1, 0.001]]", point: str = "[0.02, 0.04]", goal: str = "[0.02, 0.05]",
          extra: str = "") -> Path:
    path = d / "s.toml"
    path.write_text(SQUARE.format(name=name, outline=outline, box=box, point=point, goal=goal, extra=extra))
    return path


# ------------------------------------------------------------------ the cases, in the order
def concurrent_writers(b: Bench, run: Path):
    last = len(read_recording(run).stages) - 1  # the two writers log the last two stages
    for trial in range(3):
        d = b.folder(f"c{trial}")
        rec = Path(shutil.copyfile(run, d / "run.rrd"))
        p = b.start("compare", rec, *QUICK, "strands", "--stage", last - 1, "--record", "--quiet")
        time.sleep(0.1)
        q = b.start("compare", rec, *QUICK, "strands", "--stage", last, "--record", "--quiet")
        codes = [x.wait(timeout=600) for x in (p, q)]
        b.row(f"1. two `compare --record` 0.1 s apart (trial {trial + 1})",
              f"`compare R --stage {last - 1} --record` and `--stage {last} --record`", " and ".join(map(str, codes)),
              files(d), said=f"both finish; stages logged: {logged_stages(rec)}")


def plugin_edits_state(b: Bench, run: Path):
    r = b.cli("compare", run, *QUICK, "mutates", "strands", "--json")

    out = {e["name"]: e for e in json.loads(r.stdout)["extractors"]}
    alone = {e["name"]: e for e in json.loads(b.cli("compare", run, *QUICK, "strands", "--json").stdout)["extractors"]}
    same = out["strands"]["metrics"]["count"] == alone["strands"]["metrics"]["count"] and \
        out["strands"]["metrics"]["realizable_pose_error_rel"] == alone["strands"]["metrics"]["realizable_pose_error_rel"]
    b.row("2. a plugin that writes into `state.tau`", "`compare R --extractors mutates strands`", r,
          "nothing new", said=" / ".join(ln for ln in r.stderr.splitlines() if ln.startswith("tendon-taichi:"))
          + f" (strands after it: {'the same as alone' if same else 'DIFFERENT from alone'})")


def scene_name_paths(b: Bench):
    d = b.folder("name")
    (d / "a" / "b").mkdir(parents=True)
    for name in ("../../escaped", "a/b"):
        sub = d / "a" / "b"
        scene(sub, name=name)
        r = b.cli("simulate", "s.toml", "--uniform", 0.05, cwd=sub)
        b.row(f"3. scene `name = \"{name}\"`", "`simulate s.toml --uniform 0.05`", r, files(d),
              said="(no error line; the default output is one file under recordings/)" if r.returncode == 0
              else None)
        shutil.rmtree(sub / "recordings", ignore_errors=True)


def waypoints_outside(b: Bench, run: Path):
    r = b.cli("compare", run, *QUICK, "outside", "strands")
    b.row("4. a plugin's waypoints 1 m outside the body", "`compare R --no-consolidate --extractors outside strands`",
          r, "nothing new")


def unprivileged(b: Bench) -> tuple[list[str], str | None]:
    """The command prefix that runs as an unprivileged user (uid 65534) where this
    script runs as root, which the permission cases need (root reads and writes
    anything), and why that user cannot run this Python and the package (None
    where it can): a home folder that only root may enter, for one."""
    if os.geteuid() != 0:
        return [], None
    as_user = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
    r = subprocess.run([*as_user, sys.executable, "-c", "import tendon_taichi"], env=b.env, capture_output=True,
                       text=True, cwd="/")
    if r.returncode == 0:
        return as_user, None
    why = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
    return as_user, f"not run: uid 65534 cannot run {sys.executable} ({why})"


def read_only_folder(b: Bench, run: Path):
    d = b.folder("ro")
    rec = Path(shutil.copyfile(run, d / "run.rrd"))
    before = rec.read_bytes()
    as_user, cannot = unprivileged(b)
    if cannot:
        for extra in ("", " --record"):
            b.row(f"5. `compare` in a read-only folder{' with --record' if extra else ''}", f"`compare R{extra}`",
                  "-", files(d), said=cannot)
        return
    os.chmod(d, 0o555)
    os.chmod(b.work, 0o755)  # the scratch folder is private: let the unprivileged user in
    try:
        for extra in ((), ("--record",)):
            cmd = [*as_user, sys.executable, "-m", "tendon_taichi", "compare", str(rec), *QUICK, "strands",
                   *extra]
            r = subprocess.run(cmd, env=b.env, capture_output=True, text=True, cwd=b.work)
            table = "the table printed" if "strands" in r.stdout else "NO table"
            b.row(f"5. `compare` in a read-only folder{' with --record' if extra else ''}",
                  f"`compare R{' --record' if extra else ''}`", r,
                  ("recording unchanged" if rec.read_bytes() == before else "recording CHANGED") + f"; {files(d)}",
                  said=(" / ".join(ln for ln in r.stderr.splitlines() if ln.startswith("tendon-taichi:"))
                        or "(no error line)") + f"; {table}")
    finally:
        os.chmod(d, 0o755)
        os.chmod(b.work, 0o700)


def unreadable(b: Bench, run: Path):
    d = b.folder("unreadable")
    rec = Path(shutil.copyfile(run, d / "run.rrd"))
    os.chmod(rec, 0o000)
    as_user, cannot = unprivileged(b)
    if cannot:
        os.chmod(rec, 0o644)
        b.row("5. a recording the user may not read", "`replay R` (mode 000)", "-", files(d), said=cannot)
        return
    os.chmod(b.work, 0o755)
    try:
        r = subprocess.run([*as_user, sys.executable, "-m", "tendon_taichi", "replay", str(rec)], env=b.env,
                           capture_output=True, text=True, cwd=b.work)
    finally:
        os.chmod(b.work, 0o700)
        os.chmod(rec, 0o644)
    b.row("5. a recording the user may not read", "`replay R` (mode 000)", r, files(d))


def resume_and_truncated(b: Bench, run: Path):
    d = b.folder("resume")
    rec = Path(shutil.copyfile(run, d / "run.rrd"))
    r = b.cli("optimize", "--resume", rec, "--level", 2, cwd=d)
    b.row("6. `--resume` with another `--level`", "`optimize --resume R --level 2`", r, files(d))
    other = "finger" if read_recording(rec).meta["scene"] != "finger" else "t_shape"
    r = b.cli("optimize", other, "--resume", rec, cwd=d)
    b.row("6. `--resume` with another scene", f"`optimize {other} --resume R`", r, files(d))
    torn = d / "torn.rrd"
    data = run.read_bytes()
    torn.write_bytes(data[: int(len(data) * 0.8)])
    r = b.cli("extract", torn, "--extractor", "strands", "--no-consolidate")
    b.row("6. `extract` on a truncated recording", "`extract torn.rrd --extractor strands`", r, "nothing new")


def nan_plugin(b: Bench, run: Path):
    r = b.cli("compare", run, *QUICK, "nan_waypoints", "strands")
    b.row("7. a plugin returning NaN waypoints", "`compare R --extractors nan_waypoints strands`", r, "nothing new")


def internal_errors(b: Bench, run: Path):
    d = b.folder("tiny")
    scene(d, outline="[[0, 0], [1e-6, 0], [1e-6, 1e-6], [0, 1e-6]]", box="[[-1, -1e-8], [1, 1e-8]]",
          point="[5e-7, 1e-6]", goal="[5e-7, 1.1e-6]")
    b.row("8. a 1 um body", "`simulate tiny.toml --uniform 0.05`", b.cli("simulate", "s.toml", "--uniform", 0.05, cwd=d),
          files(d))
    d = b.folder("damaged")
    bad = d / "bad.rrd"
    data = bytearray(run.read_bytes())
    at = data.find(np.ascontiguousarray(read_recording(run).stages[2].ac[:4]).tobytes())
    for k in range(8, 48):
        data[at + k] ^= 0xFF
    bad.write_bytes(bytes(data))
    b.row("8. flipped bytes in `/stages/ac`", "`replay bad.rrd`", b.cli("replay", bad), files(d))
    d = b.folder("unwritable")
    (d / "afile").write_text("x")
    r = b.cli("optimize", "t_shape", "--record", d / "afile" / "run.rrd", cwd=d)
    b.row("8. an unwritable `--record` path", "`optimize t_shape --record afile/run.rrd`", r, files(d))
    d = b.folder("vtu")
    pts = np.array([[0, 0, 0], [0.04, 0, 0], [0, 0.04, 0.0]])
    meshio.write(str(d / "ok.vtu"), meshio.Mesh(pts, [("triangle", np.array([[0, 1, 2]]))]))
    raw = (d / "ok.vtu").read_bytes()
    (d / "body.vtu").write_bytes(raw[: len(raw) // 2])
    (d / "ok.vtu").unlink()
    (d / "s.toml").write_text('name = "cut"\n[body]\nmesh = "body.vtu"\n[[fixed]]\nbox = [[-1, -1], [1, 0]]\n'
                              "[[targets]]\npoint = [0.01, 0.01]\ngoal = [0.01, 0.02]\n")
    b.row("8. a corrupt `.vtu` body", "`simulate s.toml --uniform 0.05` (half a VTU file)",
          b.cli("simulate", "s.toml", "--uniform", 0.05, cwd=d), files(d))


def too_large(b: Bench):
    d = b.folder("large")
    b.row("9. `simulate finger --level 99`", "`simulate finger --level 99 --uniform 0.05`",
          b.cli("simulate", "finger", "--level", 99, "--uniform", 0.05, cwd=d), files(d))
    scene(d, outline="[[0, 0], [1000, 0], [1000, 1000], [0, 1000]]", box="[[-1, -1], [1001, 1]]",
          point="[500, 1000]", goal="[500, 1001]")
    b.row("9. a 1 km outline with default sizes", "`simulate km.toml --uniform 0.05`",
          b.cli("simulate", "s.toml", "--uniform", 0.05, cwd=d), files(d))


def the_rest(b: Bench, run: Path):
    d = b.folder("clamped")
    scene(d, box="[[-1, -1], [1, 1]]")
    b.row("10. every node clamped", "`optimize s.toml`", b.cli("optimize", "s.toml", cwd=d), files(d))
    r = b.cli("compare", run, *QUICK, "sleeps", "strands", "--plugin-timeout", 2)
    b.row("10. a plugin that sleeps", "`compare R --extractors sleeps strands --plugin-timeout 2`", r, "nothing new")
    r = b.cli("extract", run, "--extractor", "strands", "--option", "max_turn=nan")
    b.row("10. `--option max_turn=nan`", "`extract R --extractor strands --option max_turn=nan`", r, "nothing new")
    r = b.cli("compare", run, "--friction", -1)
    b.row("10. numbers in messages", "`compare R --friction -1`", r, "nothing new")
    d = b.folder("reach")
    scene(d, goal="[0.02, 0.4]")
    t0 = time.perf_counter()
    r = b.cli("design", "s.toml", "--out", "out", cwd=d)
    b.row("10. `design` with a goal out of reach", f"`design s.toml`, its goal 6 L away ({time.perf_counter() - t0:.0f} s)",
          r, files(d))
    d = b.folder("timed")
    t0 = time.perf_counter()
    b.cli("compare", Path(shutil.copyfile(run, d / "run.rrd")), *QUICK, "strands", "--record", "--quiet")
    duration = time.perf_counter() - t0
    left = []
    for i, at in enumerate(np.linspace(0.4, 1.0, 6) * duration):
        d = b.folder(f"kill{i}")
        rec = Path(shutil.copyfile(run, d / "run.rrd"))
        p = b.start("compare", rec, *QUICK, "strands", "--record", "--quiet")
        time.sleep(at)
        p.send_signal(signal.SIGKILL)
        p.wait()
        state = "original" if rec.read_bytes() == run.read_bytes() else \
            "updated" if logged_stages(rec) else "DAMAGED"
        left.append(f"{at:.1f} s: {state}, {files(d)}")
    b.row("10. `compare --record` killed (SIGKILL)",
          f"`compare R --record` (a whole run: {duration:.1f} s), killed after 40-100 % of that", "-9",
          "; ".join(left), said="(killed)")
    design_killed(b)


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(stat.parent.name))
    return out


def running(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def design_killed(b: Bench):
    """``design`` with a worker process, killed from outside (as ``timeout`` or a
    batch scheduler does) while both compute: are its processes gone after it?"""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        d = b.folder(f"design-{sig.name}")
        p = b.start("design", "t_shape", "--out", "out", "--workers", 1, "--quiet", cwd=d)
        time.sleep(15)  # past the optimization (about 10 s), before the end (25 s): consolidations, shared
        workers = [c for c in children(p.pid) if "resource_tracker" not in Path(f"/proc/{c}/cmdline").read_text()]
        p.send_signal(sig)
        _, err = p.communicate()
        said = " / ".join(ln for ln in err.splitlines() if ln.startswith("tendon-taichi:")) or "(killed)"
        time.sleep(5)
        left = [w for w in workers if running(w)]
        for w in left:
            os.kill(w, signal.SIGKILL)
        b.row(f"10. `design` killed ({sig.name}) while its worker computes",
              "`design t_shape --workers 1`, killed after 15 s", str(p.returncode), files(d),
              said=f"{said}; {len(workers)} worker process(es) then, {len(left)} still running 5 s later")


def made_at(p: dict) -> str:
    dirty = " (with uncommitted changes)" if p["dirty"] else ""
    return f"<sub>Made at commit `{(p['commit'] or 'unknown')[:7]}`{dirty} on {p['date']}, tendon-taichi {p['version']}.</sub>"


def table(rows) -> str:
    out = ["| case | command (R: a short t_shape recording) | exit | what it prints | left on disk |",
           "|---|---|---|---|---|"]
    for case, shown, code, said, left in rows:
        out.append(f"| {case} | {shown} | {code} | {said.replace('|', '/')} | {left} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(Path(__file__).with_name("README.md")))
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        b = Bench(Path(tmp))
        run = b.work / "run.rrd"
        r = b.cli("optimize", "t_shape", "--stage-iterations", 25, "--k-min", 0.1, "--record", run, "--quiet")
        assert r.returncode == 0, r.stderr
        concurrent_writers(b, run)
        plugin_edits_state(b, run)
        scene_name_paths(b)
        waypoints_outside(b, run)
        read_only_folder(b, run)
        unreadable(b, run)
        resume_and_truncated(b, run)
        nan_plugin(b, run)
        internal_errors(b, run)
        too_large(b)
        the_rest(b, run)
        text = table(b.rows).replace(str(b.work), "WORK")
    Path(args.out).write_text(
        "# Hostile input: what each case of the issue prints now\n\n"
        "Every case of the hostile-input issue, run against the command line by\n"
        "`python benchmarks/hostile_input/make_table.py` in a scratch folder (`WORK`).\n"
        "Exit statuses: 0 done, 2 bad input or a file that could not be written, 4 an\n"
        "extractor failed (the others' results are printed), -9 killed by the script\n"
        "(SIGKILL), 143 stopped by its SIGTERM.\n\n"
        + text + "\n\n" + made_at(provenance()) + "\n")
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
