"""Tendon extraction: extractors on hand-made tension fields, metrics, the
strand-tendon equivalence, planted tendons with and without noise, and the
realizable robot."""

import math
import re

import numpy as np
import pytest
from conftest import PLANTED, lattice_path

from tendon_taichi import Model, NewtonSolver, build_problem, load_scene, parse_scene
from tendon_taichi.extraction import (FiberView, IdealizedState, MetricSettings, PluginError, Tendon,
                                      available_extractors, load_extractor, tendon_metrics)
from tendon_taichi.extract.context import Context
from tendon_taichi.extract.realizable import solve_realizable, tendon_cables

BUILTIN = ["network_discovery", "path_cover", "strands"]

SQUARE = """
name = "sq"
[body]
outline = [[0, 0], [0.06, 0], [0.06, 0.04], [0, 0.04]]
max_triangle_area = 2e-5
[[fixed]]
box = [[-1, -0.0001], [1, 0.0001]]
[[targets]]
point = [0.03, 0.04]
goal = [0.03, 0.045]
"""


@pytest.fixture(scope="module")
def square():
    return build_problem(parse_scene(SQUARE), 1)


def row(x0, x1, y, s=0.005):
    return [np.array([x, y]) for x in np.arange(x0, x1 + s / 2, s)]


def state_of(problem, tau, threshold=0.01):
    return IdealizedState(np.asarray(tau, float), np.zeros(problem.fibers.n_fibers), problem.mesh.nodes, threshold)


def run(name, problem, state, **options):
    ext = load_extractor(name)
    return ext.extract(problem, state, ext.make_options({k: str(v) for k, v in options.items()}))


def test_builtins_are_registered_entry_points():
    eps = available_extractors()
    assert set(BUILTIN) <= set(eps)
    for name in BUILTIN:
        assert eps[name].value.startswith("extractors.")
        ext = load_extractor(name)
        assert ext.name == name and ext.description and ext.api == 1


def test_unknown_extractor_and_bad_options():
    with pytest.raises(PluginError, match="unknown extractor 'nope'"):
        load_extractor("nope")
    with pytest.raises(PluginError, match="has no option 'speed'"):
        load_extractor("strands").make_options({"speed": "1"})
    with pytest.raises(PluginError, match="expects float"):
        load_extractor("strands").make_options({"max_turn": "steep"})
    for bad in ("nan", "inf", float("nan")):
        with pytest.raises(PluginError, match="must be a finite number"):
            load_extractor("strands").make_options({"max_turn": bad})
    assert load_extractor("strands").make_options({"bridge_gaps": "no"}).bridge_gaps is False


@pytest.mark.parametrize("name,key,value,message", [
    ("strands", "min_length", "-5", "option 'min_length' must be >= 0 (got -5)"),
    ("strands", "max_turn", -5.0, "option 'max_turn' must be in [0, 180] (got -5)"),
    ("path_cover", "tension_tol", "-3", "option 'tension_tol' must be >= 0 (got -3)"),
    ("path_cover", "min_tension", "1.5", "option 'min_tension' must be in [0, 1] (got 1.5)"),
    ("network_discovery", "threshold", "-1", "option 'threshold' must be in [0, 1] (got -1)"),
])
def test_an_option_outside_its_range_is_refused(name, key, value, message):
    with pytest.raises(PluginError, match=re.escape(f"extractor '{name}': {message}")):
        load_extractor(name).make_options({key: value})
    ends = load_extractor(name).Options.ranges[key]
    edge = ends[0] if ends[0] is not None else ends[1]
    assert getattr(load_extractor(name).make_options({key: str(edge)}), key) == edge  # the ends are allowed


@pytest.mark.parametrize("name", BUILTIN)
def test_straight_strand_is_one_straight_tendon(square, name):
    tau = np.zeros(square.fibers.n_fibers)
    fibers = lattice_path(square, row(0.005, 0.045, 0.02))
    tau[fibers] = 1.0
    st = state_of(square, tau)
    ts = run(name, square, st)
    assert len(ts) == 1 and sorted(ts[0].fibers) == sorted(fibers)
    m = tendon_metrics(square, st, ts)
    assert m["kinks"] == 0 and m["total_turning"] == pytest.approx(0, abs=1e-12)
    assert m["total_length"] == pytest.approx(0.04) and m["capstan_worst"] == pytest.approx(1.0)
    assert m["coverage"] == pytest.approx(1.0) and m["tension_cv"] == pytest.approx(0.0, abs=1e-12)


def test_parallel_strands_are_two_tendons_for_path_cover(square):
    """Two strands one spacing apart with strong diagonal rungs between them: a greedy
    search that follows the strongest neighbour zig-zags, path_cover keeps straight."""
    tau = np.zeros(square.fibers.n_fibers)
    a = lattice_path(square, row(0.005, 0.055, 0.015))
    b = lattice_path(square, row(0.005, 0.055, 0.02))
    rng = np.random.default_rng(3)
    tau[a] = 1.0 + 0.05 * rng.uniform(-1, 1, len(a))
    tau[b] = 1.0 + 0.05 * rng.uniform(-1, 1, len(b))
    for x in (0.015, 0.03, 0.045):  # rungs, as tense as the strands
        tau[lattice_path(square, [np.array([x, 0.015]), np.array([x + 0.005, 0.02])])] = 1.06
    st = state_of(square, tau)
    ts = run("path_cover", square, st)
    assert len(ts) == 2
    assert {frozenset(t.fibers) for t in ts} == {frozenset(a), frozenset(b)}
    assert tendon_metrics(square, st, ts)["kinks"] == 0
    greedy = run("network_discovery", square, st)
    assert tendon_metrics(square, st, greedy)["kinks"] > 0  # the baseline does zig-zag


@pytest.mark.parametrize("name", BUILTIN)
def test_l_shaped_strand(square, name):
    tau = np.zeros(square.fibers.n_fibers)
    fibers = lattice_path(square, row(0.005, 0.03, 0.01) + [np.array([0.03, y]) for y in (0.015, 0.02, 0.025, 0.03)])
    tau[fibers] = 1.0
    st = state_of(square, tau)
    opts = {} if name == "network_discovery" else {"max_turn": 95}
    ts = run(name, square, st, **opts)
    assert len(ts) == 1
    m = tendon_metrics(square, st, ts)
    assert m["kinks"] == 1 and math.degrees(m["max_turn"]) == pytest.approx(90)
    assert m["total_turning"] == pytest.approx(math.pi / 2)
    assert m["capstan_worst"] == pytest.approx(math.exp(-0.1 * math.pi / 2))
    assert tendon_metrics(square, st, ts, MetricSettings(kink_angle=95, mu=0.3))["kinks"] == 0
    if name != "network_discovery":  # by default a sharp corner ends a strand
        assert len(run(name, square, st)) == 2


@pytest.mark.parametrize("name", ["strands", "path_cover"])
def test_one_fiber_gap_is_bridged_per_option(square, name):
    tau = np.zeros(square.fibers.n_fibers)
    fibers = lattice_path(square, row(0.005, 0.055, 0.02))
    tau[fibers] = 1.0
    tau[fibers[5]] = 0.0  # a slack fiber in the middle
    st = state_of(square, tau)
    bridged = run(name, square, st)
    assert len(bridged) == 1 and fibers[5] in bridged[0].fibers and bridged[0].length == pytest.approx(0.05)
    split = run(name, square, st, bridge_gaps=False)
    assert len(split) == 2 and all(fibers[5] not in t.fibers for t in split)


def test_metrics_by_hand(square):
    """Tension spread, coverage and lengths computed by hand."""
    tau = np.zeros(square.fibers.n_fibers)
    fibers = lattice_path(square, row(0.01, 0.03, 0.02))  # 4 fibers
    tau[fibers] = [1.0, 2.0, 1.0, 2.0]
    extra = lattice_path(square, [np.array([0.05, 0.03]), np.array([0.055, 0.035])])  # a lone diagonal
    tau[extra] = 4.0
    st = state_of(square, tau)
    view = FiberView(square)
    start = int(np.argmin(np.linalg.norm(square.fibers.nodes - [0.01, 0.02], axis=1)))
    t = view.tendon(start, fibers, st)
    assert t.tension == pytest.approx(1.5) and t.tension_std == pytest.approx(0.5)
    m = tendon_metrics(square, st, [t])
    a0 = square.fibers.a0
    assert m["tension_cv"] == pytest.approx(0.5 / 1.5)
    assert m["coverage"] == pytest.approx(6 * 0.005 / (6 * 0.005 + 4.0 * a0[extra[0]]))
    assert m["lengths"] == [pytest.approx(0.02)] and m["count"] == 1
    # the pull end is the end nearer to the clamped bottom edge (both ends are equally near here)
    assert np.allclose(sorted([t.anchor[0], t.pull_end[0]]), [0.01, 0.03])


def test_strand_and_sliding_tendon_are_the_same_robot():
    """A straight chain of fibers at equal tension gives the equilibrium of one
    frictionless sliding cable through the same nodes pulled with that tension."""
    p = build_problem(load_scene("t_shape"), 1).with_tendons(friction=0.0)
    pts = [np.array([-0.005, y]) for y in np.arange(0.01, 0.0551, 0.005)]
    fibers = lattice_path(p, pts)
    view = FiberView(p)
    start = int(np.argmin(np.linalg.norm(p.fibers.nodes - pts[0], axis=1)))
    tendon = view.tendon(start, fibers, state_of(p, np.ones(p.fibers.n_fibers)))
    cable = Model.from_problem(p, cables=tendon_cables(p, [tendon]))
    xT = NewtonSolver(cable, "direct").solve(ac=np.array([0.08 * tendon.length])).x
    tau = cable.tensions()[0]
    # each fiber of the chain contracted so that it carries tau at xT; all others paid out
    fs = p.scene.fibers
    c = p.fibers.embedding.positions(p.mesh.triangles, xT)
    lengths = np.linalg.norm(c[p.fibers.edges[:, 1]] - c[p.fibers.edges[:, 0]], axis=1)
    z1 = tau / fs.stiffness
    e = z1 + fs.eps / 2 if z1 >= fs.eps / 2 else math.sqrt(2 * fs.eps * z1)
    ac = -fs.max_payout * p.fibers.a0
    ac[fibers] = p.fibers.a0[fibers] - lengths[fibers] / (1 + e)
    lattice = Model.from_problem(p)
    eq = NewtonSolver(lattice, "direct").solve(ac=ac)
    assert np.allclose(eq.tau[fibers], tau, rtol=1e-6) and tau > 0.1
    assert np.abs(eq.tau[np.setdiff1d(np.arange(len(ac)), fibers)]).max() == 0.0
    assert np.abs(eq.x - xT).max() <= 1e-6 * p.size


# ------------------------------------------------------------------ planted tendons on t_shape
def _hausdorff(a, b):
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    return max(d.min(0).max(), d.min(1).max())


@pytest.mark.parametrize("name", BUILTIN)
def test_planted_tendons_are_found_exactly(planted, name):
    p, paths, eq = planted
    tau = np.zeros(p.fibers.n_fibers)
    for f in paths:
        tau[f] = 0.4
    ts = run(name, p, IdealizedState(tau, np.zeros_like(tau), eq.x, 0.01))
    assert len(ts) == 2
    assert {frozenset(t.fibers) for t in ts} == {frozenset(f) for f in paths}


def test_noisy_planted_tendons_with_path_cover(planted):
    p, paths, eq = planted
    rng = np.random.default_rng(11)
    tau = np.zeros(p.fibers.n_fibers)
    for f in paths:
        tau[f] = 0.4 * (1 + rng.uniform(-0.15, 0.15, len(f)))  # +-15 % jitter along the strands
    tau[paths[0][10]] = 0.0  # a one-fiber gap
    on = np.zeros(len(tau), bool)
    on[np.concatenate(paths)] = True
    noise = rng.choice(np.flatnonzero(~on), 40, replace=False)
    tau[noise] = 0.4 * rng.uniform(0.05, 0.10, len(noise))  # scattered weak activations
    st = IdealizedState(tau, np.zeros_like(tau), eq.x, 0.01)
    ts = run("path_cover", p, st)
    assert len(ts) == 2
    planted_xy = [np.array(path) for path in PLANTED]
    for t in ts:
        assert min(_hausdorff(t.waypoints, q) for q in planted_xy) <= p.fibers.spacing + 1e-12
    real = solve_realizable(Context(p, st, p.scene.optimize, "direct"), ts)
    assert real.pose_error_rel <= 0.01, real.pose_error_rel
    assert np.all(real.contraction > 0)


def test_realizable_robot_without_tendons_stays_at_rest(planted):
    p, _, eq = planted
    st = IdealizedState(np.zeros(p.fibers.n_fibers), np.zeros(p.fibers.n_fibers), eq.x, 0.01)
    real = solve_realizable(Context(p, st, p.scene.optimize, "direct"), [])
    assert np.allclose(real.x, p.mesh.nodes)
    rest_error = np.sqrt(((p.target_positions(p.mesh.nodes) - p.target_goal) ** 2).sum())
    assert real.pose_error == pytest.approx(rest_error) and real.pose_error_rel > 0.01


def test_tendon_json_and_types(square):
    tau = np.zeros(square.fibers.n_fibers)
    tau[lattice_path(square, row(0.005, 0.025, 0.02))] = 1.0
    t = run("strands", square, state_of(square, tau))[0]
    assert isinstance(t, Tendon)
    d = t.as_json()
    assert set(d) >= {"waypoints", "length", "tension", "contraction", "anchor", "pull_end"}
    assert np.allclose(d["waypoints"][0], d["anchor"]) and np.allclose(d["waypoints"][-1], d["pull_end"])


def test_a_plugins_tendons_are_checked_against_the_lattice(square):
    from tendon_taichi.extract.checks import check_tendons, read_only_copy

    view = FiberView(square)
    tau = np.zeros(square.fibers.n_fibers)
    good = view.tendon(int(view.edges[0][0]), [0], state_of(square, tau))
    assert check_tendons("p", [good], square) == [good]

    def bad(**change):
        t = Tendon(good.nodes, good.fibers, good.waypoints, 1.0, 0.0)
        for k, v in change.items():
            setattr(t, k, v)
        return t

    cases = [(bad(nodes=good.nodes[:1], fibers=good.fibers[:0], waypoints=good.waypoints[:1]), "at least two"),
             (bad(fibers=np.array([square.fibers.n_fibers])), "out of range"),
             (bad(fibers=np.array([next(f for f in range(square.fibers.n_fibers)
                                        if set(view.edges[f]) != set(good.nodes.tolist()))])), "does not join"),
             (bad(waypoints=good.waypoints[:, :1]), "waypoints must be (2, 2)"),
             (bad(waypoints=good.waypoints + 1e-3), "from its nodes' rest positions")]
    for t, why in cases:
        with pytest.raises(PluginError, match=re.escape(f"extractor 'p' returned a malformed tendon (tendon 0: ")):
            check_tendons("p", [t], square)
        with pytest.raises(PluginError, match=re.escape(why)):
            check_tendons("p", [t], square)
    with pytest.raises(PluginError, match="did not return a list of Tendon"):
        check_tendons("p", good, square)
    frozen = read_only_copy(state_of(square, tau))
    with pytest.raises(ValueError, match="read-only"):
        frozen.tau[0] = 1.0
    assert read_only_copy(square).fibers.nodes.flags.writeable is False and square.fibers.nodes.flags.writeable
