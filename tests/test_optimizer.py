"""The regularized soft IK: adjoint gradients, and the optimizer on a planted layout."""

import re
from dataclasses import replace

import numpy as np
import pytest

from tendon_taichi import CableSet, Model, NewtonSolver, build_problem, load_scene, parse_scene
from tendon_taichi.apps.optimize import optimize
from tendon_taichi.objective import State, StrandEndTerm, smoothstep
from tendon_taichi.objective.terms import registered
from tendon_taichi.optimizer import SoftIK, schedule_done, settled, stage_k

from reference import objective_fd

#: every registered term gets its adjoint gradient checked, alone and with all the others
TERMS = [t.name for t in registered()]


def test_the_registry_holds_the_documented_terms():
    assert TERMS[:6] == ["pose", "sparsity", "continuity", "strand_end", "contraction", "effort"]


def test_every_term_setting_is_a_setting_a_scene_key_and_a_flag():
    """What a term declares is what the settings, the scene reader and the command
    line know: nothing more, nothing less."""
    from dataclasses import fields

    from tendon_taichi.cli import build_parser
    from tendon_taichi.errors import SceneError
    from tendon_taichi.objective.settings import GENERAL, HOMOTOPY

    declared = [s for t in registered() for s in t.settings] + [s for s in GENERAL if s.table is None]
    assert [f.name for f in fields(load_scene("t_shape").optimize) if f.name != "homotopy"] == \
        [s.name for s in declared]
    optimize = build_parser()._subparsers._group_actions[0].choices["optimize"]
    flags = {o for a in optimize._actions for o in a.option_strings}
    assert {s.flag for s in declared + list(HOMOTOPY)} <= flags
    base = load_scene("t_shape").source
    for setting in declared:
        value = {float: "0.5", int: "3", str: repr(setting.default)}[setting.kind]
        value = "0.001" if setting.within_fiber_bounds else value
        sc = parse_scene(base + f"\n[optimize]\n{setting.name} = {value}\n".replace("'", '"'))
        assert getattr(sc.optimize, setting.name) == setting.kind(eval(value)), setting.name
    with pytest.raises(SceneError, match="unknown key 'not_a_term' in optimize"):
        parse_scene(base + "\n[optimize]\nnot_a_term = 1.0\n")


def test_two_terms_cannot_share_a_name():
    from tendon_taichi.objective.term import Term

    with pytest.raises(TypeError, match="two objective terms are named 'pose'"):
        type("AnotherPose", (Term,), {"name": "pose"})


@pytest.fixture(scope="module")
def t_shape_1():
    return build_problem(load_scene("t_shape"), 1)


@pytest.mark.parametrize("solver", ["cg", "cg-jacobi", "direct"])
@pytest.mark.parametrize("terms", [[t] for t in TERMS] + [TERMS], ids=lambda t: "+".join(t))
def test_adjoint_gradient_matches_finite_differences(t_shape_1, solver, terms):
    _check_adjoint_gradient(t_shape_1, dict(strand_end=1e-4, effort=1e-3), solver, terms)


def test_adjoint_gradient_with_the_multigrid_backend(t_shape_1):
    _check_adjoint_gradient(t_shape_1, dict(strand_end=1e-4, effort=1e-3), "cg-amg", TERMS)


def _check_adjoint_gradient(p, settings, solver, terms):
    """The objective's adjoint gradient (only ``terms`` on, at k = 0.4) against
    central differences along two random directions; returns the SoftIK and the objective."""
    ik = SoftIK(p, replace(p.scene.optimize, **settings), solver)
    ik.eval_tol = 1e-13
    ik.configure(0.4)  # a k inside the range of the tensions: the smoothstep is curved there
    ik.objective.active = set(terms)
    rng = np.random.default_rng(7)
    r = rng.uniform(-0.05, 0.12, p.fibers.n_fibers)
    ik.restart(r)
    f, g = ik.evaluate(r)
    tau = ik.model.tensions()
    assert (tau > 0.4).any() and ((tau > 0) & (tau < 0.4)).any()  # both sides of k
    for trial in range(2):
        d = rng.standard_normal(len(r))
        fd = objective_fd(ik, r, d)
        assert abs(fd - np.dot(g, d)) <= 1e-5 * abs(fd), (terms, fd, np.dot(g, d))
        assert abs(fd) > 1e-9
    return ik, f


def _arm_strand(p):
    """The fiber ids of a straight horizontal strand of 4 fibers in the t_shape's
    arm, far from the clamp."""
    fib = p.fibers
    y = fib.nodes[:, 1].max() - fib.spacing
    row = np.flatnonzero((np.abs(fib.nodes[:, 1] - y) < 1e-9) & (fib.nodes[:, 0] > 0))
    row = row[np.argsort(fib.nodes[row, 0])][:5]
    return [int(np.flatnonzero((fib.edges == [a, b]).all(1) | (fib.edges == [b, a]).all(1))[0])
            for a, b in zip(row[:-1], row[1:])]


def _check_tension_gradient(term, x, tau, rng):
    """The term's dtau against central differences along a random direction that
    keeps slack fibers slack (tau' = 0 there)."""
    tv = term.evaluate(State(x, tau, tau))
    d, h = rng.standard_normal(len(tau)) * (tau > 0), 1e-7
    fd = (term.evaluate(State(x, tau, tau + h * d)).value - term.evaluate(State(x, tau, tau - h * d)).value) / (2 * h)
    assert np.dot(tv.dtau, d) == pytest.approx(fd, rel=1e-6)
    return fd


def test_strand_end_term_counts_ends_stars_and_jumps(t_shape_1):
    p = t_shape_1
    term = StrandEndTerm(p, 2.0, 0.5)  # weight / tau_ref^2 = 8
    fib = p.fibers
    strand = _arm_strand(p)
    x = p.mesh.nodes
    tau = np.zeros(fib.n_fibers)
    tau[strand] = 0.3
    assert term.evaluate(State(x, tau, tau)).value == pytest.approx(8 * 2 * 0.3 ** 2)  # two ends
    tau[strand[2]] = 0.5  # a jump at two inner nodes: 2 (0.2)^2 more, ends unchanged
    assert term.evaluate(State(x, tau, tau)).value == pytest.approx(8 * (2 * 0.3 ** 2 + 2 * 0.2 ** 2))
    rng = np.random.default_rng(3)
    _check_tension_gradient(term, x, rng.uniform(0, 1, fib.n_fibers) * (rng.uniform(size=fib.n_fibers) < 0.3), rng)


def test_strand_end_count_measure_counts_ends_whatever_their_tension(t_shape_1):
    """The smooth L0 form: an end out of balance by at least k costs the weight, an
    inner node of a clean strand nothing; below k the smoothstep of E / k^2."""
    p = t_shape_1
    term = StrandEndTerm(p, 2.0, 0.5, "count", k=0.2)
    fib = p.fibers
    strand = _arm_strand(p)
    x = p.mesh.nodes
    for t in (0.3, 3.0):  # two ends cost 2 x weight, at any tension above k
        tau = np.zeros(fib.n_fibers)
        tau[strand] = t
        assert term.evaluate(State(x, tau, tau)).value == pytest.approx(2 * 2.0)
    tau[strand] = 0.1  # E = 0.01 = k^2 / 4: each end costs s(1/4) = 5/32
    assert term.evaluate(State(x, tau, tau)).value == pytest.approx(2 * 2.0 * 5 / 32)
    rng = np.random.default_rng(3)
    tau = rng.uniform(0, 0.3, fib.n_fibers) * (rng.uniform(size=fib.n_fibers) < 0.3)
    assert abs(_check_tension_gradient(term, x, tau, rng)) > 1e-3  # many nodes on the curved part


@pytest.mark.parametrize("solver", ["cg", "direct"])
def test_adjoint_gradient_of_the_strand_end_count(t_shape_1, solver):
    p = t_shape_1
    ik, f = _check_adjoint_gradient(p, dict(strand_end=1e-4, strand_end_measure="count"), solver, ["strand_end"])
    assert ik.objective.term("strand_end").k == 0.4  # configure sets the stage's k on the strand-end term too
    assert 0 < f < 1e-4 * len(p.fibers.nodes)  # at most w_end per counted node


def test_strand_end_linear_measure_charges_ends_by_their_tension(t_shape_1):
    """The magnitude form: an end costs its tension (smoothed by eps), so an end at
    twice the tension costs twice as much, not four times; a jump costs its size."""
    p = t_shape_1
    term = StrandEndTerm(p, 2.0, 0.5, "linear")  # weight / tau_ref = 4, eps = 0.005 N
    eps = 0.01 * 0.5

    def mag(t):
        return np.sqrt(t * t + eps * eps) - eps

    fib = p.fibers
    strand = _arm_strand(p)
    x = p.mesh.nodes
    tau = np.zeros(fib.n_fibers)
    for t in (0.3, 0.6):
        tau[strand] = t
        assert term.evaluate(State(x, tau, tau)).value == pytest.approx(4 * 2 * mag(t))
    tau[strand] = 0.3
    tau[strand[2]] = 0.5  # a jump of 0.2 at two inner nodes
    assert term.evaluate(State(x, tau, tau)).value == pytest.approx(4 * (2 * mag(0.3) + 2 * mag(0.2)))
    rng = np.random.default_rng(3)
    _check_tension_gradient(term, x, rng.uniform(0, 1, fib.n_fibers) * (rng.uniform(size=fib.n_fibers) < 0.3), rng)


@pytest.mark.parametrize("solver", ["cg", "direct"])
def test_adjoint_gradient_of_the_strand_end_linear_measure(t_shape_1, solver):
    _check_adjoint_gradient(t_shape_1, dict(strand_end=1e-4, strand_end_measure="linear"), solver, ["strand_end"])


def test_smoothstep():
    t = np.array([-1.0, 0.0, 0.25, 0.5, 1.0, 2.0])
    s, ds = smoothstep(t, 1.0)
    assert np.allclose(s, [0, 0, 3 / 16 - 2 / 64, 0.5, 1, 1])
    h = 1e-7
    fd = (smoothstep(t + h, 1.0)[0] - smoothstep(t - h, 1.0)[0]) / (2 * h)
    assert np.allclose(ds[2:4], fd[2:4], rtol=1e-6) and ds[0] == ds[-1] == 0


def test_homotopy_schedule():
    s = load_scene("t_shape").optimize
    assert stage_k(s, 0) is None and stage_k(s, 1) == 0.25 and stage_k(s, 3) == 0.0625
    ks = [stage_k(s, i) for i in range(1, 7)]
    assert ks[-2] >= 0.01 > ks[-1]  # 1/4 .. 1/128: the last stage run is k = 1/64

    class St:
        def __init__(self, tau):
            self.tau = np.asarray(tau)
    assert schedule_done([St([0, 1])] * 6, s)  # next k below k_min
    assert schedule_done([St([0, 0]), St([1, 1]), St([1, 1]), St([1, 1])], s)  # unchanged twice
    assert not schedule_done([St([0, 0]), St([0, 1]), St([1, 1]), St([1, 1])], s)


def test_a_stage_settles_when_objective_and_active_set_stop_moving():
    s = load_scene("t_shape").optimize.__class__(settle_tol=1e-3, settle_window=3)
    a, b = b"\x01\x00", b"\x01\x01"
    flat = [(1.0, a), (0.5, a), (0.4999, a), (0.4998, a), (0.4998, a)]
    assert settled(flat, 1, s)
    assert not settled(flat[:3], 1, s)  # not enough iterations yet
    falling = [(1.0, a), (0.9, a), (0.8, a), (0.7, a), (0.6, a)]
    assert not settled(falling, 1, s)
    switching = [(1.0, a), (0.5, a), (0.5, b), (0.5, a), (0.5, a)]
    assert not settled(switching, 1, s) and settled(switching, 0, s)  # stage 0 ignores the set


# ------------------------------------------------------------------ planted layout
PLANTED = [[(-0.045, 0.0625), (-0.015, 0.0625), (-0.0075, 0.055), (-0.0075, 0.01)],
           [(0.045, 0.0775), (0.005, 0.0775)]]


def planted_scene(level: int = 2):
    """t_shape with goals made by two sliding-cable tendons at 8% contraction."""
    base = load_scene("t_shape")
    p = build_problem(base, level)
    cab = CableSet.polylines(p.mesh, [np.array(q) for q in PLANTED], base.fibers.stiffness)
    eq = NewtonSolver(Model.from_problem(p, cables=cab), "direct").solve(ac=0.08 * cab.a0)
    goals = iter(p.target_positions(eq.x))
    text = re.sub(r"goal = \[[^\]]*\]", lambda _: "goal = [{:.10f}, {:.10f}]".format(*next(goals)),
                  base.source)
    return parse_scene(text.replace('name = "t_shape"', 'name = "t_planted"'), origin="planted")


@pytest.fixture(scope="module")
def planted_runs(tmp_path_factory):
    scene = planted_scene()
    out = tmp_path_factory.mktemp("planted")
    return {lv: optimize(scene, lv, record=out / f"r{lv}.rrd") for lv in (1, 2)}


@pytest.mark.parametrize("level", [1, 2])
def test_planted_layout_is_reached_sparsely(planted_runs, level):
    run = planted_runs[level]
    s0, last = run.stages[0].figures, run.stages[-1].figures
    assert run.stages[0].k is None and len(run.stages) >= 5
    assert last.pose_error_rel <= 0.01
    assert s0.active_length >= 3 * last.active_length
    assert run.summary["final"]["active_length"] == last.active_length


@pytest.mark.parametrize("solver", ["direct", "cg"])
def test_a_stage_settled_where_it_is_reports_the_settled_state(solver):
    """A stage that ends where it is (``settle``, the warm path of the realizable
    robot) reports the state solved to the stage tolerance: the evaluation that
    reads its figures does not move it by a prediction made at an earlier point."""
    from tendon_taichi.optimizer.soft_ik import STATE_TOL

    p = build_problem(load_scene("t_shape"), 1)
    line = np.array([(0.045 - 0.005 * i, 0.075) for i in range(9)])
    ik = SoftIK(p, p.scene.optimize, solver, cables=CableSet.polylines(p.mesh, [line], p.scene.fibers.stiffness))
    ik.restart(np.array([0.02]))
    ik.evaluate(np.array([0.05]))  # the last evaluation, at another point
    ik.settle(np.array([0.08]))
    ik.figures(np.array([0.08]))
    ps = ik.poses[0]
    ps.model.set_positions(ik.state()[0][0])
    g = ps.model.gradient()[~p.fixed]
    assert np.linalg.norm(g) <= STATE_TOL * ps.state_newton.force_scale


@pytest.mark.parametrize("solver", ["direct", "cg"])
def test_a_restart_at_the_last_restarts_contractions_is_a_solve_from_rest(t_shape_1, solver):
    """A stage's final state is solved from rest, and so is the next stage's start,
    at the same contractions: the direct backend takes the last restart's equilibrium
    again (its solves start afresh), and the run goes on exactly as after a new
    solve from rest - here, as a new soft IK's; cg (a reused preconditioner) solves again."""
    p = t_shape_1
    rng = np.random.default_rng(3)

    def soft_ik():
        ik = SoftIK(p, p.scene.optimize, solver)
        ik.configure(0.5)
        ps = ik.poses[0]
        solve = ps.state_newton.solve
        ps.state_solves = 0

        def counted(*args, **kwargs):
            ps.state_solves += 1
            return solve(*args, **kwargs)
        ps.state_newton.solve = counted
        return ik

    ik = soft_ik()
    r1 = rng.uniform(0.0, 0.03, len(ik.a0))
    r2 = r1 * (1 + 0.05 * rng.uniform(-1, 1, len(r1)))
    ik.restart(r1)
    ik.evaluate(r2)  # the run moves on, then comes back to r1
    again = ik.restart(r1)[0]
    f, g = ik.evaluate(r2)
    new = soft_ik()
    first = new.restart(r1)[0]
    f_new, g_new = new.evaluate(r2)
    assert ik.poses[0].state_solves == (1 if solver == "direct" else 2)
    assert np.array_equal(again.x, first.x) and np.array_equal(again.tau, first.tau)
    assert f == f_new and np.array_equal(g, g_new)
    assert np.array_equal(ik.state()[0], new.state()[0])
