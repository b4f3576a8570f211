"""Planted layouts: scenes whose goals a known set of tendons reaches exactly.

:func:`plant` draws a few random but plausible tendons in a scene's body,
contracts them, solves the body with only those tendons as sliding cables
(the realizable robot of ``docs/method.md``) and writes where the scene's
target points went as their goals. The result is a benchmark with a known
answer: an optimizer and its extractors should find tendons like the planted
ones, and a realizable pose error near zero is attainable.

The tendons are drawn by the random walks of :mod:`.walk`. Every draw comes
from one ``numpy.random.Generator`` seeded by ``seed``, so a (scene, tendon
count, seed, level) gives byte-identical outputs.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from ..body.cables import CableSet
from ..body.problem import Problem, build_problem
from ..body.scene import EXITS, Scene, load_scene, parse_scene
from ..errors import ConvergenceError, InputError, SceneError
from ..files import atomic_path, file_stem
from ..physics.model import Model
from ..solve.newton import NewtonSolver
from .walk import PlantedTendon, PlantSettings, Region, Walker, draw_layout, path_segments

#: the most tendons a planted layout may have
MAX_TENDONS = 5


# ------------------------------------------------------------------ simulating
def solve_tendons(problem: Problem, tendons: list[PlantedTendon], ac=None):
    """The equilibrium of the body with only these tendons as sliding cables (EA =
    the scene's fiber stiffness), contracted by their ``contraction`` (or ``ac``) (m)."""
    cables = CableSet.polylines(problem.mesh, [t.waypoints for t in tendons],
                                problem.scene.fibers.stiffness)
    ac = np.array([t.contraction for t in tendons]) if ac is None else np.asarray(ac, dtype=float)
    return NewtonSolver(Model.from_problem(problem, cables=cables), "direct").solve(ac=ac)


def pose_ratios(rng: np.random.Generator, tendons: list[PlantedTendon], n_poses: int,
                st: PlantSettings) -> np.ndarray:
    """Contraction ratios (P, n) of the tendons in each pose: pose 0 contracts every
    tendon by its drawn ratio; each further pose contracts a random non-empty subset
    (a proper one when there are several tendons, so the poses need different
    tendons), with ratios drawn anew, and pays the others out by the largest
    contraction ratio (slack)."""
    n = len(tendons)
    out = [np.array([t.ratio for t in tendons])]
    for _ in range(1, n_poses):
        on = np.zeros(n, dtype=bool)
        while not on.any() or (n > 1 and on.all()):
            on = rng.random(n) < 0.5
        ratios = np.round(rng.uniform(*st.contraction, n), 4)
        out.append(np.where(on, ratios, -st.contraction[1]))
    return np.array(out)


# ------------------------------------------------------------------ writing
def planted_name(scene: Scene, n_tendons: int, seed: int, poses: int = 1) -> str:
    """``<scene>_planted_<n>t_s<seed>``, with ``_<P>p`` for several poses."""
    return f"{scene.name}_planted_{n_tendons}t_s{seed}" + (f"_{poses}p" if poses > 1 else "")


def _source_command(scene: Scene, n: int, seed: int, level: int, poses: int = 1, exit: str = "clamp") -> str:
    src = scene.origin[len("builtin:"):] if scene.origin.startswith("builtin:") else scene.origin
    return (f"tendon-taichi planted {src} --tendons {n} --seed {seed} --level {level}"
            + (f" --poses {poses}" if poses > 1 else "") + (f" --exit {exit}" if exit != "clamp" else ""))


def _strip_header(text: str) -> str:
    """The TOML text without its leading comment block (it describes the old goals)."""
    lines = text.splitlines()
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        i += 1
    return "\n".join(lines[i:]) + "\n"


def _fmt(v: float) -> str:
    return f"{v:.10f}"


def _poses_toml(scene: Scene, poses: list[np.ndarray]) -> str:
    """``[[poses]]`` tables, one per goal array (t, 2) m, over the scene's target points."""
    out = []
    for i, goals in enumerate(poses):
        out.append(f'\n[[poses]]\nname = "pose{i}"\n')
        for t, g in zip(scene.targets, goals):
            out.append("\n[[poses.targets]]\npoint = [{}, {}]\ngoal = [{}, {}]\n".format(
                *(repr(float(v)) for v in t.point), *map(_fmt, g)))
    return "".join(out)


def scene_text(scene: Scene, name: str, goals, header: list[str]) -> str:
    """A copy of the scene's TOML with ``name``, the target ``goals`` (t, 2) m written
    to 10 decimals, and the comment ``header`` lines in place of its own. A list of
    several goal arrays replaces the ``[[targets]]`` with one ``[[poses]]`` each."""
    body = _strip_header(scene.source)
    if isinstance(goals, list) and len(goals) > 1:
        blocks = re.split(r"(?m)^(?=\[)", body)
        body = "".join(b for b in blocks if not b.startswith("[[targets]]")).rstrip() + "\n"
        body += _poses_toml(scene, goals)
        goals = np.zeros((0, 2))
    elif isinstance(goals, list):
        goals = goals[0]
    hits = list(re.finditer(r"(?m)^(\s*goal\s*=\s*)\[[^\]]*\]", body))
    if len(hits) != len(goals) and len(goals):
        raise InputError(f"{scene.origin}: cannot rewrite the goals of its [[targets]] "
                         f"(found {len(hits)} 'goal = [x, y]' lines for {len(goals)} targets)")
    it = iter(goals)
    if len(goals):
        body = re.sub(r"(?m)^(\s*goal\s*=\s*)\[[^\]]*\]",
                      lambda m: m.group(1) + "[{}, {}]".format(*map(_fmt, next(it))), body)
    name_line = f'name = "{name}"'
    body, count = re.subn(r'(?m)^name\s*=\s*"[^"\n]*"', name_line, body, count=1)
    if not count:
        body = name_line + "\n" + body
    if scene.body.mesh_file is not None:
        body = re.sub(r'(?m)^(\s*mesh\s*=\s*)"[^"\n]*"',
                      lambda m: m.group(1) + json.dumps(str(scene.body.mesh_file)), body, count=1)
    return "".join(f"# {h}".rstrip() + "\n" for h in header) + body


def with_exit(text: str, exit: str) -> str:
    """A scene's TOML ``text`` with ``exit`` in its [tendons] table (the key replaced,
    added to the table, or the table added)."""
    line = f'exit = "{exit}"'
    table = re.search(r"(?m)^\[tendons\]\s*$", text)
    if table is None:
        return text.rstrip() + f"\n\n[tendons]\n{line}\n"
    end = re.search(r"(?m)^\[", text[table.end():])
    stop = len(text) if end is None else table.end() + end.start()
    body, n = re.subn(r'(?m)^[ \t]*exit[ \t]*=.*$', line, text[table.end():stop], count=1)
    if not n:
        body = "\n" + line + body
    return text[:table.end()] + body + text[stop:]


def _header(scene: Scene, name: str, tendons: list[PlantedTendon], n: int, seed: int, level: int,
            disp_rel: float, ratios: np.ndarray | None = None, exit: str = "inside") -> list[str]:
    P = 1 if ratios is None else len(ratios)
    rows = [f"Planted from '{scene.name}': its goals are where {n} random tendon"
            f"{'s' if n > 1 else ''} (seed {seed}, level {level}),",
            "contracted and solved as sliding cables, bring the target points"
            + (f" in each of {P} poses" if P > 1 else "") + ". Made by",
            f"  {_source_command(scene, n, seed, level, poses=P, exit=exit)}",
            f"The tendons (waypoints, contractions) are in {name}.json:"]
    for i, t in enumerate(tendons):
        rows.append(f"  {i + 1}: {100 * t.length:.2f} cm, contracted {100 * t.ratio:.2f} % "
                    f"({1e3 * t.contraction:.3f} mm), tension {t.tension:.4f} N")
    if P > 1:
        for q in range(1, P):
            rows.append(f"  pose{q}: contraction ratios "
                        + ", ".join(f"{100 * r:.2f} %" for r in ratios[q]) + " (negative: paid out, slack)")
    rows.append(f"Largest target displacement: {100 * disp_rel:.2f} % of L.")
    return rows


# ------------------------------------------------------------------ the entry point
def plant(scene: Scene | str, n_tendons: int, seed: int, level: int = 2,
          settings: PlantSettings | None = None, poses: int = 1) -> tuple[str, dict]:
    """Draw ``n_tendons`` (1..5) random tendons in ``scene`` (a Scene or a name/path),
    solve the body with only them at resolution ``level`` and return the scene's
    TOML text with their equilibrium as its goals, and the layout (dict, JSON-ready:
    ``scene``, ``name``, ``seed``, ``level``, ``tendons`` (each ``waypoints`` (m,
    rest, anchor first), ``length`` (m), ``contraction`` (m), ``contraction_ratio``,
    ``tension`` (N)), ``planted_length`` (m), ``pose`` (``max_target_displacement``
    m, ``body_size`` L m), ``targets``, ``draws``). Deterministic in its inputs.
    ``poses`` > 1: the same tendons make several poses (:func:`pose_ratios`); the
    scene gets one ``[[poses]]`` table each, the layout a ``poses`` list (per pose
    ``name``, ``contraction_ratios``, ``tensions``, ``max_target_displacement``,
    ``targets``); its tendons' contraction and tension are those of pose 0.
    A draw whose pose is too small (largest target displacement below
    ``min_displacement`` L), in which a tendon is slack (the others' pull shortened
    its path by more than its contraction) or whose solve fails is redrawn from the
    same stream.
    The tendons leave the body where ``settings.exit`` says (``[tendons] exit``,
    written into the scene unless it is "inside"): by default at the clamp, so that
    the planted answer is buildable and a design of the scene is asked for the same
    - inside the body where no clamp meets the outline (a body clamped in its
    middle); the layout's ``exit`` says which (none: inside)."""
    st = settings or PlantSettings()
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if isinstance(n_tendons, bool) or not isinstance(n_tendons, (int, np.integer)) \
            or not 1 <= n_tendons <= MAX_TENDONS:
        raise InputError(f"the number of tendons must be 1..{MAX_TENDONS} (got {n_tendons!r})")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"the seed must be an integer >= 0 (got {seed!r})")
    if isinstance(poses, bool) or not isinstance(poses, (int, np.integer)) or not 1 <= poses <= 4:
        raise InputError(f"the number of poses must be 1..4 (got {poses!r})")
    if len(scene.poses) > 1:
        raise InputError(f"{scene.origin}: plant from a one-pose scene (it has {len(scene.poses)} poses)")
    n_tendons, seed, poses = int(n_tendons), int(seed), int(poses)
    exit = st.exit
    if exit not in EXITS:
        raise InputError(f"the exit must be one of {', '.join(EXITS)} (got {exit!r})")
    try:
        problem = build_problem(scene.with_tendons(scene.origin, exit=exit), level)
    except SceneError:
        if exit != "clamp" or scene.tendons.exit != "inside":
            raise
        exit = "inside"  # no clamp meets the outline: the tendons end inside the body
        problem = build_problem(scene, level)
    scene = problem.scene
    region = Region(problem, st)
    walker = Walker(region, st)
    rng = np.random.default_rng(seed)
    if walker.start(rng, path_segments([]), 0.0, tries=2000) is None:
        raise InputError(f"{scene.origin}: no point of the body is {1e3 * walker.walk_margin:.2f} mm "
                         "from its boundary: no tendon fits")
    L = problem.size
    rest = problem.target_positions(problem.mesh.nodes)
    placed_any = False
    for draw in range(1, st.max_draws + 1):
        tendons = draw_layout(rng, walker, n_tendons, st)
        if tendons is None:
            continue
        placed_any = True
        ratios = pose_ratios(rng, tendons, poses, st) if poses > 1 else None
        lengths = np.array([t.length for t in tendons])
        try:
            eqs = [solve_tendons(problem, tendons, None if ratios is None else r * lengths)
                   for r in (ratios if ratios is not None else [None])]
        except ConvergenceError:
            continue
        if eqs[0].tau.min() <= 1e-9 * max(float(eqs[0].tau.max()), 1e-300):
            continue  # a tendon the others left slack does no work: the layout would not be the answer
        pose_goals = [problem.target_positions(eq.x) for eq in eqs]
        pose_disp = [np.linalg.norm(g - rest, axis=1) for g in pose_goals]
        if min(d.max() for d in pose_disp) < st.min_displacement * L:
            continue
        eq, disp = eqs[0], np.max(pose_disp, axis=0)
        for t, tau in zip(tendons, eq.tau):
            t.tension = float(tau)
        pose_goals = [np.array([[float(_fmt(v)) for v in g] for g in goals]) for goals in pose_goals]
        goals = pose_goals[0]
        name = planted_name(scene, n_tendons, seed, poses)
        text = scene_text(scene, name, pose_goals, _header(scene, name, tendons, n_tendons, seed, level=level,
                                                           disp_rel=disp.max() / L, ratios=ratios, exit=exit))
        if exit != "inside":
            text = with_exit(text, exit)
        parse_scene(text, origin=name, base_dir=None, default_name=name)  # it must load
        extra = {} if ratios is None else {"poses": [
            {"name": f"pose{q}", "contraction_ratios": ratios[q].tolist(),
             "tensions": eqs[q].tau.tolist(), "max_target_displacement": float(pose_disp[q].max()),
             "max_target_displacement_rel": float(pose_disp[q].max() / L),
             "targets": [{"point": list(tg.point), "goal": pose_goals[q][i].tolist(),
                          "displacement": float(pose_disp[q][i])} for i, tg in enumerate(scene.targets)]}
            for q in range(poses)]}
        layout = {
            "scene": scene.name, "name": name, "seed": seed, "level": int(level),
            "n_tendons": n_tendons,
            "tendons": [t.as_json() for t in tendons],
            "planted_length": float(sum(t.length for t in tendons)),
            "pose": {"max_target_displacement": float(disp.max()), "body_size": L,
                     "max_target_displacement_rel": float(disp.max() / L)},
            "targets": [{"point": list(tg.point), "goal": goals[i].tolist(), "displacement": float(disp[i])}
                        for i, tg in enumerate(scene.targets)],
            "margin": region.margin, "draws": draw, **({} if exit == "inside" else {"exit": exit}), **extra,
        }
        return text, layout
    why = ("the drawn tendons never moved the targets by " f"{100 * st.min_displacement:g} % of L"
           if placed_any else f"no {n_tendons} tendon(s) fit in the body")
    raise InputError(f"{scene.origin}: cannot plant a layout after {st.max_draws} draws: {why}")


def layout_json(layout: dict) -> str:
    """The layout as written to ``<name>.json`` (indented; each [x, y] on one line)."""
    text = json.dumps(layout, indent=2)
    return re.sub(r"\[\s+(-?[\d.eE+-]+),\s+(-?[\d.eE+-]+)\s+\]", r"[\1, \2]", text) + "\n"


def write_planted(out_dir, text: str, layout: dict):
    """Write ``DIR/<name>.toml`` and ``DIR/<name>.json`` atomically (both or neither),
    the name made one file's (:func:`~tendon_taichi.files.file_stem`: a scene named
    like a path writes inside ``DIR``); return their paths."""

    out, stem = Path(out_dir), file_stem(layout["name"])
    toml_path, json_path = out / f"{stem}.toml", out / f"{stem}.json"
    with atomic_path(toml_path) as tmp_toml, atomic_path(json_path) as tmp_json:
        tmp_toml.write_text(text)
        tmp_json.write_text(layout_json(layout))
    return toml_path, json_path
