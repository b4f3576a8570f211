"""Run recordings in rerun's ``.rrd`` format (rerun-sdk 0.41; ``docs/formats.md``).

Layout (entity paths), timelines ``stage`` and ``iteration`` (the L-BFGS-B
iteration counted over the whole run):

* static: ``/meta/run`` (JSON: package version, scene name, resolution,
  effective [optimize] settings, the [tendons] ones, solver), ``/meta/scene``
  (the scene TOML), ``/problem/*``
  (the rest mesh, clamps, fiber graph, embeddings and targets as f64 tensors,
  so a run can be rebuilt from the file alone), ``/world/rest_mesh`` and
  ``/world/rest_fibers`` (the fiber graph);
* per logged iteration: ``/world/mesh`` (deformed edges), ``/world/fibers``
  (coloured by tension on a fixed scale, slack fibers faint), ``/world/targets``,
  ``/world/goals`` (with several poses: the same under ``/world/poses/<name>/``),
  and scalars ``/metrics/objective/<term>``, ``/metrics/figures/pose_error_rel``,
  ``/metrics/figures/active_fibers``, ``/metrics/figures/k``;
* per completed stage (then flushed to disk): ``/stages/ac``, ``/stages/r``
  (the poses' vectors one after the other, (P f,)), ``/stages/tau`` (the union
  tension, (f,)), ``/stages/x`` (each pose's equilibrium, (P, n, 2); f64
  tensors, bit-exact) and ``/stages/summary`` (JSON). A stage counts as
  completed when its summary is in the file. Recordings of format 1 have no
  ``/stages/x``; their equilibria are solved again from rest.
"""

from __future__ import annotations

import json
import os
import struct
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..body.fibers import FiberGraph
from ..body.mesh import Embedding, Mesh
from ..body.problem import Problem
from ..body.scene import parse_scene
from ..body.size import check_built
from ..errors import TendonError
from ..files import locked, replace_with_bytes
from ..objective.settings import OptimizeSettings, settings_dict, settings_from_dict

APP_ID = "tendon_taichi"
#: 2: with each stage's equilibria (``/stages/x``)
FORMAT = 2
#: static JSON of a file that holds only tendons logged from a run (``extract --record FILE``):
#: ``recording`` (the run's file name) and ``run_id``
TENDONS_OF = "/meta/tendons_of"


class RecordingError(TendonError):
    """A recording is missing, corrupt, foreign or incomplete."""


def default_blueprint():
    """The viewer layout: the body (2D) beside the objective and figure time series."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial2DView(origin="/", name="body", contents=["/world/**", "/tendons/**", "/design/**"]),
        rrb.Vertical(rrb.TimeSeriesView(origin="/metrics/objective", name="objective terms"),
                     rrb.TimeSeriesView(origin="/metrics/figures", name="pose error, active fibers")),
        column_shares=[3, 2]))


def mesh_edges(triangles: np.ndarray) -> np.ndarray:
    """The unique edges (e, 2) of a triangle mesh."""
    e = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), 1)
    return np.unique(e, axis=0)


def tension_colors(tau: np.ndarray, scale: float, threshold: float) -> np.ndarray:
    """RGBA (C, 4) uint8 on a fixed scale: 0 .. 2 scale N mapped on 'inferno'; slack
    fibers (tau <= threshold) faint grey."""
    from matplotlib import colormaps

    cmap = colormaps["inferno"]
    t = np.clip(np.asarray(tau) / (2.0 * scale), 0.0, 1.0)
    rgba = (cmap(0.15 + 0.8 * t) * 255).astype(np.uint8)
    slack = np.asarray(tau) <= threshold
    rgba[slack] = (160, 160, 160, 40)
    return rgba


def batcher():
    """rerun's chunk batching for our files: a chunk per entity per flush (each stage
    end is flushed explicitly) rather than one every 200 ms, which keeps a
    recording several times smaller (every chunk carries its own schema)."""
    import rerun as rr

    return rr.ChunkBatcherConfig(flush_tick=60.0, flush_num_bytes=64 * 2 ** 20, flush_num_rows=2 ** 32)


def geometry_due(i: int, log_every: int) -> bool:
    """Whether the ``i``-th iteration of a stage (from 1) has its geometry logged:
    every ``log_every``-th, or with ``log_every`` 0 the iterations 1, 2, 4, 8, ...
    (a stage's early iterations change the shape most; its end is logged anyway)."""
    return i % log_every == 0 if log_every > 0 else i > 0 and i & (i - 1) == 0


class Recorder:
    """Writes a run to ``path`` as it goes; each completed stage is flushed to disk.
    Scalars are recorded at every iteration (held, and sent as columns with the
    stage), the geometry where :func:`geometry_due` says (``log_every``; 0:
    log-spaced) and at every stage's end."""

    def __init__(self, path: str | Path, problem: Problem, settings: OptimizeSettings,
                 meta: dict, log_every: int = 0):
        import rerun as rr

        self.rr = rr
        self.path = Path(path)
        self.problem, self.settings = problem, settings
        self.log_every = max(0, int(log_every))
        self.edges = mesh_edges(problem.mesh.triangles)
        #: per-iteration scalars not yet sent: entity -> [(stage, iteration, value)]
        self._scalars: dict[str, list[tuple[int, int, float]]] = {}
        self.rec = rr.RecordingStream(APP_ID, recording_id=meta.get("run_id"), batcher_config=batcher())
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.rec.save(str(self.path), default_blueprint=default_blueprint())
        ts = problem.scene.tendons
        self.meta = {"format": FORMAT, **meta, "settings": settings_dict(settings),
                     "tendons": {"friction": ts.friction, "clearance": ts.clearance}}

    def write_header(self) -> None:
        """The static part: run metadata, scene, problem arrays, rest geometry."""
        rr, rec, p = self.rr, self.rec, self.problem
        rec.log("/meta/run", rr.TextDocument(json.dumps(self.meta, indent=1), media_type="text/plain"),
                static=True)
        rec.log("/meta/scene", rr.TextDocument(p.scene.source, media_type="text/plain"), static=True)
        for name, arr in problem_tensors(p).items():
            rec.log(f"/problem/{name}", rr.Tensor(np.asarray(arr, dtype=np.float64)), static=True)
        X = p.mesh.nodes
        rec.log("/world/rest_mesh", rr.LineStrips2D(X[self.edges].astype(np.float32),
                                                    colors=[(200, 200, 200, 60)], radii=-0.5),
                static=True)
        rec.log("/world/rest_fibers", rr.LineStrips2D(p.fibers.nodes[p.fibers.edges].astype(np.float32),
                                                      colors=[(150, 150, 150, 30)], radii=-0.5),
                static=True)
        self.rec.flush()

    def copy_from(self, chunks) -> None:
        """Re-send chunks read from an earlier recording (resume into a new file)."""
        self.rec.send_chunks(chunks)
        self.rec.flush()

    def iteration(self, step: int, state, local: int = 0, force: bool = False) -> None:
        """Log one L-BFGS-B iteration (``step`` counts over the whole run, ``local``
        within its stage, from 1): ``state``, an iterate or a finished stage, with its
        ``stage``, ``k``, ``figures``, per-pose positions ``xs`` (P, n, 2) and
        tensions ``taus`` (P, C); ``force`` logs the geometry whatever ``local``."""
        stage, k, figures, xs, taus = state.stage, state.k, state.figures, state.xs, state.taus
        scalars = {**{f"/metrics/objective/{name}": value for name, value in figures.objective.items()},
                   "/metrics/figures/pose_error_rel": figures.pose_error_rel,
                   "/metrics/figures/active_fibers": figures.active_fibers,
                   "/metrics/figures/k": k if k is not None else float("nan")}
        for entity, value in scalars.items():
            self._scalars.setdefault(entity, []).append((stage, step, float(value)))
        if not force and not geometry_due(local, self.log_every):
            return
        self.rec.set_time("stage", sequence=stage)
        self.rec.set_time("iteration", sequence=step)
        names = self.problem.pose_names
        for i, (x, tau) in enumerate(zip(xs, taus)):
            self._body(f"/world/poses/{names[i]}" if len(names) > 1 else "/world", self.problem.pose(i), x, tau)

    def _body(self, base: str, p: Problem, x: np.ndarray, tau: np.ndarray) -> None:
        """The deformed mesh, fibers by tension, targets and goals of one pose under ``base``."""
        rr, rec = self.rr, self.rec
        rec.log(f"{base}/mesh", rr.LineStrips2D(x[self.edges].astype(np.float32),
                                                colors=[(120, 140, 170, 90)], radii=-0.5))
        c = p.fibers.embedding.positions(p.mesh.triangles, x)
        strips = c[p.fibers.edges].astype(np.float32)
        thr = self.settings.active_threshold * self.settings.tension_scale
        rec.log(f"{base}/fibers", rr.LineStrips2D(strips, colors=tension_colors(tau, self.settings.tension_scale,
                                                                                thr), radii=-1.5))
        rec.log(f"{base}/targets", rr.Points2D(p.target_positions(x), colors=[(40, 120, 255)], radii=-4.0))
        rec.log(f"{base}/goals", rr.Points2D(p.target_goal, colors=[(40, 200, 80)], radii=-4.0))

    def _send_scalars(self) -> None:
        """Send the scalars held since the last call, a column per entity (one
        ``rr.log`` per value would cost more than the iteration it records)."""
        rr = self.rr
        for entity, rows in self._scalars.items():
            stage, step, value = zip(*rows)
            self.rec.send_columns(entity, indexes=[rr.TimeColumn("stage", sequence=stage),
                                                   rr.TimeColumn("iteration", sequence=step)],
                                  columns=rr.Scalars.columns(scalars=np.array(value)))
        self._scalars = {}

    def stage(self, result, step: int) -> None:
        """Log a completed stage losslessly and flush it to disk."""
        rr, rec = self.rr, self.rec
        self._send_scalars()
        rec.set_time("stage", sequence=result.stage)
        rec.set_time("iteration", sequence=step)
        rec.log("/stages/r", rr.Tensor(np.asarray(result.r, dtype=np.float64)))
        rec.log("/stages/ac", rr.Tensor(np.asarray(result.ac, dtype=np.float64)))
        rec.log("/stages/tau", rr.Tensor(np.asarray(result.tau, dtype=np.float64)))
        if result.xs is not None:
            rec.log("/stages/x", rr.Tensor(np.asarray(result.xs, dtype=np.float64)))
        rec.log("/stages/summary", rr.TextDocument(json.dumps(stage_summary(result, step)), media_type="text/plain"))
        rec.flush()

    def log(self, entity: str, archetype, static: bool = False) -> None:
        self.rec.log(entity, archetype, static=static)

    def close(self) -> None:
        self._send_scalars()
        self.rec.flush()
        self.rec.disconnect()


def stage_summary(result, step: int) -> dict:
    """A completed stage's ``/stages/summary``: its figures (``result.summary()``),
    ``step`` (the run's iteration count at its end) and its ``message``."""
    return {**result.summary(), "step": step, "message": result.message}


def problem_tensors(p: Problem) -> dict[str, np.ndarray]:
    """The arrays that rebuild a Problem without meshing (all stored as f64)."""
    return {"nodes": p.mesh.nodes, "triangles": p.mesh.triangles, "fixed": p.fixed,
            "fiber_nodes": p.fibers.nodes, "fiber_nodes_tri": p.fibers.embedding.tri,
            "fiber_nodes_bary": p.fibers.embedding.bary, "fibers": p.fibers.edges,
            "spacing": np.array([p.fibers.spacing]), "target_tri": p.target.tri,
            "target_bary": p.target.bary, "target_goal": p.target_goal}


# ---------------------------------------------------------------- reading
@dataclass
class RecordedStage:
    """One completed stage as recorded: its ``summary`` (the optimize summary's
    stage figures), ``r`` and ``ac`` (m) (P f,), the union tension ``tau`` (f,) N
    and each pose's equilibrium ``xs`` (P, n, 2) m (None in format-1 recordings)."""

    summary: dict
    r: np.ndarray
    ac: np.ndarray
    tau: np.ndarray
    xs: np.ndarray | None = None


@dataclass
class RecordedRun:
    """What a recording holds: metadata, scene TOML, problem arrays and completed stages."""

    path: Path
    meta: dict
    scene_toml: str
    arrays: dict[str, np.ndarray]
    stages: list[RecordedStage] = field(default_factory=list)
    truncated: bool = False

    @property
    def settings(self) -> OptimizeSettings:
        return settings_from_dict(self.meta["settings"])

    def problem(self) -> Problem:
        """Rebuild the problem exactly as it was run (no scene file or meshing needed),
        with the run's effective [optimize] and [tendons] settings."""
        a = self.arrays
        scene = parse_scene(self.scene_toml, origin=f"{self.path} (recorded scene)", check_files=False)
        scene = scene.with_optimize(**{k: v for k, v in self.settings.__dict__.items()})
        scene = scene.with_tendons(f"{self.path} (recorded settings)", **self.meta.get("tendons", {}))
        mesh = Mesh(a["nodes"], a["triangles"].astype(np.int64))
        fibers = FiberGraph(a["fiber_nodes"], Embedding(a["fiber_nodes_tri"].astype(np.int64),
                                                        a["fiber_nodes_bary"]),
                            a["fibers"].astype(np.int64), float(a["spacing"][0]))
        fixed = a["fixed"].astype(bool)
        check_built(scene.name, int(self.meta["resolution"]), int(2 * (~fixed).sum()), fibers.n_fibers)
        return Problem(scene, int(self.meta["resolution"]), mesh, fixed, fibers,
                       target=Embedding(a["target_tri"].astype(np.int64), a["target_bary"]),
                       target_goal=a["target_goal"])


@dataclass
class HeldRun(RecordedRun):
    """A run as its recording holds it, handed on in memory by the process that ran
    it (``design``): the values :func:`read_recording` would give back
    (:func:`held_stage`, :func:`as_read`) and ``built``, the problem that ran,
    rather than one rebuilt from the arrays."""

    built: Problem | None = None

    def problem(self) -> Problem:
        """The problem that ran (the one :meth:`RecordedRun.problem` rebuilds)."""
        return self.built


def as_read(value):
    """A JSON-able ``value`` as the recording gives it back: through JSON (tuples
    become lists, float subclasses floats, keys strings)."""
    return json.loads(json.dumps(value))


def held_stage(result, step: int) -> RecordedStage:
    """A completed stage (a :class:`~tendon_taichi.optimizer.homotopy.StageResult`
    ending at iteration ``step``) as :func:`read_recording` gives it back: its
    summary through JSON, its vectors copied as f64."""
    def f64(a):
        return None if a is None else np.array(a, dtype=np.float64)

    return RecordedStage(as_read(stage_summary(result, step)), f64(result.r), f64(result.ac), f64(result.tau),
                         f64(result.xs))


def _whole_frames(path: Path) -> tuple[int, bool]:
    """The length of the longest prefix of an .rrd made of whole frames (a run killed
    while writing leaves a torn last frame), and whether the file is whole: its
    frames end at its end, or at the end-of-stream frame (kind 0) that a closed
    recording writes before its footer. Reads the frames' headers only."""
    size = path.stat().st_size
    off, good = 0, 0
    with open(path, "rb") as fh:
        while off + 12 <= size:
            fh.seek(off)
            head = fh.read(16)
            if head[:4] == b"RRF2":
                off += 12
                good = off
                continue
            if off + 16 > size:
                break
            kind, length = struct.unpack("<QQ", head)
            if kind == 0:
                return good, True
            if off + 16 + length > size:
                break
            off += 16 + length
            good = off
    return good, good == size


def read_chunks(path: Path):
    """All chunks of the first recording store, tolerating a torn tail, and whether
    it was torn. Rerun's reader rejects a tail torn within a frame but reads one
    torn within a frame's 16-byte header as a clean end, so the frames are checked
    here too."""
    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            chunks = list(RrdReader(path).stream())
            return chunks, not _whole_frames(path)[1]
        except (RuntimeError, ValueError, OSError):
            pass
        n = _whole_frames(path)[0]
        if n <= 12:
            raise RecordingError(f"'{path}' is not a readable rerun recording")
        fd, tmp = tempfile.mkstemp(suffix=".rrd")
        try:
            with open(path, "rb") as src, os.fdopen(fd, "wb") as dst:
                dst.write(src.read(n))
            try:
                return list(RrdReader(tmp).stream()), True
            except (RuntimeError, ValueError, OSError) as exc:
                raise RecordingError(f"'{path}' is corrupt: {str(exc).splitlines()[0]}") from None
        finally:
            os.unlink(tmp)


def _text(rb) -> list[str]:
    return [t for t in rb.column("TextDocument:text").to_pylist() for t in (t if isinstance(t, list) else [t])]


def _tensors(rb) -> list[np.ndarray]:
    out = []
    for row in rb.column("Tensor:data").to_pylist():
        t = row[0]
        out.append(np.array(t["buffer"], dtype=np.float64).reshape([int(d) for d in t["shape"]]))
    return out


def _stage_values(rb) -> list[int]:
    return [int(v) for v in rb.column("stage").to_pylist()]


def read_recording(path: str | Path) -> RecordedRun:
    """Read a recording (see the module docstring); raise RecordingError if it is
    missing, not an .rrd, not a tendon-taichi run, or has no readable header."""
    path = Path(path)
    try:  # a folder on the way that cannot be entered makes even is_dir fail
        if path.is_dir():
            raise RecordingError(f"recording '{path}' is a folder, not a file")
        if not path.is_file():
            raise RecordingError(f"recording '{path}' does not exist")
        with open(path, "rb") as fh:
            if fh.read(4) != b"RRF2":
                raise RecordingError(f"'{path}' is not a rerun recording (.rrd)")
    except OSError as exc:
        raise RecordingError(f"cannot read recording '{path}': {exc.strerror or exc}") from None
    chunks, truncated = read_chunks(path)
    meta, scene, arrays, tendons_of = None, None, {}, None
    stages: dict[int, dict] = {}
    for ch in chunks:
        ent = ch.entity_path
        rb = ch.to_record_batch()
        if ent == "/meta/run":
            meta = json.loads(_text(rb)[0])
        elif ent == "/meta/scene":
            scene = _text(rb)[0]
        elif ent == TENDONS_OF:
            tendons_of = json.loads(_text(rb)[0])
        elif ent.startswith("/problem/"):
            arrays[ent[len("/problem/"):]] = _tensors(rb)[0]
        elif ent in ("/stages/r", "/stages/ac", "/stages/tau", "/stages/x", "/stages/summary"):
            key = ent.rsplit("/", 1)[1]
            values = _text(rb) if key == "summary" else _tensors(rb)
            for s, v in zip(_stage_values(rb), values):
                stages.setdefault(s, {})[key] = json.loads(v) if key == "summary" else v
    if meta is None and tendons_of is not None:
        raise RecordingError(f"'{path}' holds only the tendons extracted from the run '{tendons_of['recording']}';"
                             f" give that run's recording")
    if meta is None or meta.get("format") is None or scene is None:
        raise RecordingError(f"'{path}' is not a tendon-taichi recording (no run metadata)")
    missing = {"nodes", "triangles", "fixed", "fibers", "fiber_nodes_tri", "fiber_nodes_bary"} - set(arrays)
    if missing:
        raise RecordingError(f"'{path}' is incomplete: no {', '.join(sorted(missing))}")
    done = []
    for s in sorted(stages):
        d = stages[s]
        if s != len(done) or not {"summary", "r", "ac", "tau"} <= set(d):
            break
        done.append(RecordedStage(d["summary"], d["r"], d["ac"], d["tau"], d.get("x")))
    for i, st in enumerate(done):
        why = _stage_fault(st, arrays)
        if why:
            raise RecordingError(f"'{path}' is damaged: stage {i}'s {why}")
    return RecordedRun(path, meta, scene, arrays, done, truncated=truncated)


def _stage_fault(st: RecordedStage, arrays: dict) -> str | None:
    """What is wrong with a recorded stage's vectors, or None: every value finite,
    ``r`` and ``ac`` of P x f values with ac = r a0, ``tau`` of f, ``x`` (P, n, 2)."""
    ends = arrays["fiber_nodes"][arrays["fibers"].astype(int)]
    a0 = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    f, n = len(a0), len(arrays["nodes"])
    for key, v in (("ratios (/stages/r)", st.r), ("contractions (/stages/ac)", st.ac),
                   ("tensions (/stages/tau)", st.tau), ("equilibria (/stages/x)", st.xs)):
        if v is not None and not np.isfinite(v).all():
            return f"{key} are not all finite numbers"
    if st.r.ndim != 1 or len(st.r) == 0 or len(st.r) % f or st.ac.shape != st.r.shape or st.tau.shape != (f,):
        return f"vectors have the wrong lengths for {f} fibers"
    poses = len(st.r) // f
    if np.abs(st.ac - st.r * np.tile(a0, poses)).max() > 1e-9 * a0.max():
        return "contractions (/stages/ac) do not match its ratios (/stages/r)"
    if st.xs is not None and st.xs.shape != (poses, n, 2):
        return f"equilibria (/stages/x) are not ({poses}, {n}, 2)"
    return None


def completed_chunks(path: str | Path, stages: int):
    """The chunks of a recording that belong to its header and first ``stages`` stages
    (what a resumed run copies)."""
    chunks, _ = read_chunks(Path(path))
    keep = []
    for ch in chunks:
        if "stage" not in ch.timeline_names:
            if ch.entity_path.startswith(("/meta", "/problem", "/world/rest_")):
                keep.append(ch)
            continue
        vals = _stage_values(ch.to_record_batch())
        if vals and max(vals) < stages:
            keep.append(ch)
    return keep


def tendons_owner(path: str | Path) -> str | None:
    """The run id a tendons file (:data:`TENDONS_OF`) names, or None when ``path`` is
    not a readable tendons file."""
    try:
        chunks, _ = read_chunks(Path(path))
    except (RecordingError, OSError):
        return None
    for ch in chunks:
        if ch.entity_path == TENDONS_OF:
            return json.loads(_text(ch.to_record_batch())[0]).get("run_id")
    return None


def chunk_at_stage(chunk, stage: int) -> bool:
    """Whether a chunk holds rows at ``stage`` of the stage timeline."""
    return "stage" in chunk.timeline_names and stage in chunk.to_record_batch().column("stage").to_pylist()


def rewrite(path: str | Path, run_id: str | None, keep, add, on_wait=None, lock: str | Path | None = None) -> None:
    """Rewrite a recording with the chunks ``keep(chunk)`` accepts, then what
    ``add(rr, stream)`` logs (a file that does not exist yet is made). rerun files
    cannot be appended to, so the file is rewritten, under a lock on the existing
    file ``lock`` (default: the file itself; ``on_wait`` is called while another writer holds
    it) and from what it holds then, so that concurrent writers all keep what they
    add; the new file replaces the old atomically. Raises OSError when it cannot
    be written (the original is then unchanged)."""
    import rerun as rr

    path = Path(path)
    with locked(path if lock is None else lock, on_wait):
        chunks = read_chunks(path)[0] if path.exists() else []
        rec = rr.RecordingStream(APP_ID, recording_id=run_id)
        memory = rec.memory_recording()
        rec.send_blueprint(default_blueprint(), make_active=False, make_default=True)  # as save() does
        try:
            rec.send_chunks([ch for ch in chunks if keep(ch)])
            add(rr, rec)
            rec.flush()
            data = memory.drain_as_bytes()
        finally:
            rec.disconnect()
        replace_with_bytes(path, data)
