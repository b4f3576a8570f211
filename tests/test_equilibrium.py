"""The equilibrium: force balance from the export alone, backends agree, warm starts,
Newton iteration counts, determinism, and clear non-convergence."""

import numpy as np
import pytest
from conftest import small_scene_toml, use_cholesky
from reference import body_forces, fiber_forces, gravity_forces

from tendon_taichi import (ConvergenceError, Model, NewtonSolver, build_problem, load_scene,
                           parse_scene)
from tendon_taichi.solve import DirectSolver
from tendon_taichi.solve.multigrid import prolongation, rigid_modes


def _residual_from_export(path):
    """Free-DOF force residual / largest nodal force, from the .npz alone (numpy)."""
    d = np.load(path)
    X, T, x = d["nodes"], d["triangles"], d["x"]
    fb = body_forces(X, T, x, float(d["youngs_modulus"]), float(d["poisson_ratio"]),
                     float(d["thickness"]))
    ff = fiber_forces(T, x, d["fiber_nodes_tri"], d["fiber_nodes_bary"], d["fibers"], d["tau"])
    fg = gravity_forces(X, T, float(d["thickness"]), float(d["density"]), d["gravity"])
    total = fb + ff + fg
    free = ~d["fixed"]
    scale = max(np.linalg.norm(f, axis=1).max() for f in (fb, ff, fg))
    return np.linalg.norm(total[free], axis=1).max() / scale, scale


@pytest.mark.parametrize("level", [1, 3])
def test_force_balance_from_export(cli, tmp_path, level):
    out = tmp_path / f"t{level}.npz"
    r = cli("simulate", "t_shape", "--resolution", level, "--uniform", 0.1, "--export", out)
    assert r.returncode == 0, r.stderr
    res, scale = _residual_from_export(out)
    assert scale > 0.1  # real forces, newtons
    assert res <= 1e-8, res
    d = np.load(out)
    # and no inverted triangle
    X, T, x = d["nodes"], d["triangles"], d["x"]
    det = lambda p: np.linalg.det(np.stack([p[T[:, 1]] - p[T[:, 0]], p[T[:, 2]] - p[T[:, 0]]], -1))  # noqa: E731
    assert det(x).min() > 0 and det(X).min() > 0


def test_force_balance_with_gravity(tmp_path, cli):
    toml = small_scene_toml(11, extra="density = 1100.0\ngravity = [0.0, -9.81]")
    scene = tmp_path / "grav.toml"
    scene.write_text(toml)
    out = tmp_path / "grav.npz"
    r = cli("simulate", scene, "--uniform", 0.05, "--export", out, "--solver", "direct")
    assert r.returncode == 0, r.stderr
    res, _ = _residual_from_export(out)
    assert res <= 1e-8
    d = np.load(out)
    assert np.abs(gravity_forces(d["nodes"], d["triangles"], 0.01, 1100.0, d["gravity"])).max() > 0


@pytest.mark.parametrize("scene,level", [("t_shape", 1), ("t_shape", 2), ("gripper", 1)])
def test_cg_and_direct_agree(scene, level):
    p = build_problem(load_scene(scene), level)
    m = Model.from_problem(p)
    ac = 0.08 * p.fibers.a0
    xs = {}
    for solver in ("cg", "cg-amg", "cg-gmg", "cg-jacobi", "direct"):
        m.reset()
        eq = NewtonSolver(m, solver).solve(ac=ac)
        assert eq.residual <= 1e-10
        xs[solver] = eq.x
    for solver in ("cg", "cg-amg", "cg-gmg", "cg-jacobi"):
        assert np.abs(xs[solver] - xs["direct"]).max() <= 1e-8 * p.size


@pytest.mark.parametrize("solver", ["cg", "cg-amg", "cg-jacobi", "direct"])
def test_warm_start_takes_fewer_newton_iterations(solver):
    p = build_problem(load_scene("t_shape"), 1)
    m = Model.from_problem(p)
    newton = NewtonSolver(m, solver)
    rng = np.random.default_rng(0)
    ac1 = rng.uniform(0.0, 0.1, p.fibers.n_fibers) * p.fibers.a0
    ac2 = ac1 * (1 + 0.01 * rng.uniform(-1, 1, len(ac1)))
    newton.solve(ac=ac1, x0=p.mesh.nodes)
    warm = newton.solve(ac=ac2)  # from the previous equilibrium
    cold = newton.solve(ac=ac2, x0=p.mesh.nodes)
    assert warm.newton_iterations < cold.newton_iterations
    assert np.abs(warm.x - cold.x).max() <= 1e-8 * p.size


@pytest.mark.parametrize("solver", ["cg", "cg-amg", "cg-gmg", "cg-jacobi", "direct"])
def test_newton_from_rest_iteration_count(solver):
    """Exact Hessian first (docs/method.md, numerics): t_shape level 2, uniform 0.05."""
    p = build_problem(load_scene("t_shape"), 2)
    m = Model.from_problem(p)
    eq = NewtonSolver(m, solver).solve(ac=0.05 * p.fibers.a0)
    assert eq.newton_iterations <= 20
    assert eq.residual <= 1e-10


@pytest.mark.parametrize("solver", ["cg", "cg-amg", "cg-jacobi", "direct"])
def test_serial_and_parallel_loops_agree(solver):
    p = build_problem(load_scene("gripper"), 1)
    ac = 0.06 * p.fibers.a0
    xs = []
    for parallel in (False, True):
        m = Model.from_problem(p, parallel=parallel)
        assert m.parallel == parallel
        xs.append(NewtonSolver(m, solver).solve(ac=ac).x)
    assert np.abs(xs[0] - xs[1]).max() <= 1e-9 * p.size


def test_models_run_parallel_loops_only_where_there_are_threads_to_spare(monkeypatch):
    """By default a model runs its CPU loops in parallel from the threshold on only
    where Taichi has 3 threads or more; with 1 or 2 every model serializes them (on 2
    cores parallel loops were never faster). A threshold set by hand holds whatever
    the threads."""
    from tendon_taichi.physics import runtime

    monkeypatch.delenv("TENDON_TAICHI_PARALLEL_THRESHOLD", raising=False)
    p = build_problem(load_scene("gripper"), 1)
    size = p.mesh.n_triangles + p.fibers.n_fibers
    for threads, expected in ((1, None), (2, None), (3, runtime.DEFAULT_PARALLEL_THRESHOLD),
                              (8, runtime.DEFAULT_PARALLEL_THRESHOLD)):
        monkeypatch.setattr(runtime, "cpu_threads", lambda threads=threads: threads)
        assert runtime.parallel_threshold() == expected
        assert runtime.info()["parallel_threshold"] == expected
        assert not Model.from_problem(p).parallel  # below the threshold, or no threshold
        monkeypatch.setenv("TENDON_TAICHI_PARALLEL_THRESHOLD", str(size))
        assert runtime.parallel_threshold() == size and Model.from_problem(p).parallel
        monkeypatch.setenv("TENDON_TAICHI_PARALLEL_THRESHOLD", str(size + 1))
        assert not Model.from_problem(p).parallel
        monkeypatch.delenv("TENDON_TAICHI_PARALLEL_THRESHOLD")
    monkeypatch.setattr(runtime, "DEFAULT_PARALLEL_THRESHOLD", size)  # a model at the default threshold
    monkeypatch.setattr(runtime, "cpu_threads", lambda: 3)
    assert Model.from_problem(p).parallel
    monkeypatch.setattr(runtime, "cpu_threads", lambda: 2)
    assert not Model.from_problem(p).parallel


def test_preconditioners_agree_and_factor_needs_few_iterations():
    """The reused-factorization PCG and block-Jacobi PCG give the same equilibrium; a
    solve at a nearby design needs few factorization-preconditioned iterations."""
    p = build_problem(load_scene("t_shape"), 2)
    m = Model.from_problem(p)
    rng = np.random.default_rng(1)
    ac = rng.uniform(0.02, 0.08, p.fibers.n_fibers) * p.fibers.a0
    fac, jac = NewtonSolver(m, "cg"), NewtonSolver(m, "cg-jacobi")
    assert (fac.linear.name, jac.linear.name) == ("cg", "cg-jacobi")  # what a recording keeps
    x_f = fac.solve(ac=ac, x0=p.mesh.nodes).x
    x_j = jac.solve(ac=ac, x0=p.mesh.nodes).x
    assert np.abs(x_f - x_j).max() <= 1e-8 * p.size
    warm = fac.solve(ac=ac * (1 + 0.005 * rng.uniform(-1, 1, len(ac))))
    assert warm.linear_iterations <= 15 * warm.newton_iterations
    assert fac.linear.pre.refreshes >= 1


def test_rigid_modes_are_the_unclamped_hessians_null_space():
    """The multigrid preconditioner's near-null space: at rest, with nothing
    clamped, the Hessian maps every rigid motion of the nodes to zero."""
    p = build_problem(load_scene("t_shape"), 1)
    m = Model(p.mesh, np.zeros(p.mesh.n_nodes, dtype=bool), p.material, p.fiber_cables)
    H = DirectSolver(m, ordered=False).assemble_ordered().Hp
    B = rigid_modes(p.mesh.nodes)
    scale = abs(H).sum(axis=1).max() * np.abs(B).max()
    assert np.abs(H @ B).max() <= 1e-10 * scale
    assert np.linalg.matrix_rank(B) == 3


def test_multigrid_preconditioner_solves_to_the_direct_solution():
    """cg-amg: PCG with the V-cycle of the Hessian at the same state converges in
    few iterations to the factorization's solution;
    the adjoint-type solve is exact to its tolerance."""
    p = build_problem(load_scene("t_shape"), 2)
    rng = np.random.default_rng(3)
    ac = rng.uniform(0.02, 0.08, p.fibers.n_fibers) * p.fibers.a0
    amg, direct = NewtonSolver(Model.from_problem(p), "cg-amg"), NewtonSolver(Model.from_problem(p), "direct")
    x = amg.solve(ac=ac, x0=p.mesh.nodes).x
    assert np.abs(x - direct.solve(ac=ac, x0=p.mesh.nodes).x).max() <= 1e-8 * p.size
    b = rng.standard_normal((p.mesh.n_nodes, 2))
    amg.linear.pre.reset()
    y = amg.linear.solve(b, tol=1e-10)
    assert amg.linear.last.iterations <= 60
    assert amg.linear.pre.levels >= 2
    y_direct = direct.linear.solve(b)
    assert np.abs(y - y_direct).max() <= 1e-8 * np.abs(y_direct).max()
    amg.linear.pre.reset()
    assert np.array_equal(amg.linear.solve(b, tol=1e-10), y)  # the same hierarchy again: replays rely on it


def test_prolongation_interpolates_linear_fields_exactly():
    """The geometric multigrid's transfer from a coarser mesh (not nested in the finer
    one, the same region) reproduces every linear displacement field at the finer
    free nodes; each row's weights add up to one, and no kept coarse node is idle."""
    p = build_problem(load_scene("t_shape"), 3)
    coarse = p.coarser_meshes()[0]
    assert len(p.coarser_meshes()) == 1 and coarse.n_nodes < p.mesh.n_nodes / 3
    points = p.mesh.nodes[~p.fixed]
    P, kept = prolongation(points, coarse)
    assert P.shape == (2 * len(points), 2 * len(kept))
    A, c = np.array([[0.3, -1.2], [0.7, 0.4]]), np.array([0.05, -0.02])
    u_coarse = (coarse.nodes[kept] @ A.T + c).ravel()  # interleaved (x0, y0, x1, ...)
    u_fine = (points @ A.T + c).ravel()
    assert np.abs(P @ u_coarse - u_fine).max() <= 1e-12 * np.abs(u_fine).max()
    assert np.allclose(np.asarray(P.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-14)
    assert np.all(np.diff(P.tocsc().indptr) > 0)
    # a coarse node that reaches none of the points (here: those of the upper half) has no column
    upper = points[points[:, 1] > np.median(points[:, 1])]
    P_up, kept_up = prolongation(upper, coarse)
    assert len(kept_up) < len(kept) and np.all(np.diff(P_up.tocsc().indptr) > 0)
    assert coarse.nodes[kept_up][:, 1].min() < upper[:, 1].min()  # ... but those just below it stay


def test_geometric_multigrid_solves_to_the_direct_solution():
    """cg-gmg at level 3 (one coarser mesh, level 1): PCG with the V-cycle of the
    Hessian at the same state reaches the factorization's solution in few
    iterations; the same state gives the same hierarchy, to the bit."""
    p = build_problem(load_scene("t_shape"), 3)
    rng = np.random.default_rng(3)
    ac = rng.uniform(0.02, 0.08, p.fibers.n_fibers) * p.fibers.a0
    gmg, direct = NewtonSolver(Model.from_problem(p), "cg-gmg"), NewtonSolver(Model.from_problem(p), "direct")
    assert gmg.linear.name == "cg-gmg"  # what a recording keeps
    x = gmg.solve(ac=ac, x0=p.mesh.nodes).x
    assert np.abs(x - direct.solve(ac=ac, x0=p.mesh.nodes).x).max() <= 1e-8 * p.size
    b = rng.standard_normal((p.mesh.n_nodes, 2))
    gmg.linear.pre.reset()
    y = gmg.linear.solve(b, tol=1e-10)
    assert gmg.linear.pre.levels == 2
    assert gmg.linear.last.iterations <= 40  # 34 (one forward and one backward sweep per level)
    y_direct = direct.linear.solve(b)
    assert np.abs(y - y_direct).max() <= 1e-8 * np.abs(y_direct).max()
    gmg.linear.pre.reset()
    assert np.array_equal(gmg.linear.solve(b, tol=1e-10), y)
    # the V-cycle is a symmetric positive definite M^-1, as PCG needs
    cycle, nf = gmg.linear.pre.build(project=False), 2 * int((~p.fixed).sum())
    u, v = rng.standard_normal(nf), rng.standard_normal(nf)
    assert abs(u @ (cycle @ v) - v @ (cycle @ u)) <= 1e-10 * abs(u @ (cycle @ v))
    assert u @ (cycle @ u) > 0.0


def test_geometric_multigrid_without_coarser_meshes_is_the_direct_solve():
    """A model not made from a problem has no coarser meshes: the V-cycle is the
    direct solve of its one level, and PCG converges at once."""
    p = build_problem(load_scene("t_shape"), 3)
    m = Model(p.mesh, p.fixed, p.material, p.fiber_cables)
    newton = NewtonSolver(m, "cg-gmg")
    newton.solve(ac=0.05 * p.fibers.a0)
    newton.linear.pre.reset()
    newton.linear.solve(np.ones((p.mesh.n_nodes, 2)), tol=1e-10)
    assert newton.linear.pre.levels == 1 and newton.linear.last.iterations <= 3


def test_solve_many_after_a_long_cg_solve():
    """A CG solve that takes long resets its factorization preconditioner; the next
    right-hand side of solve_many (which does not prepare the Hessian again) must
    refresh it, and every solution must still be the direct one."""
    p = build_problem(load_scene("t_shape"), 1)
    ac = 0.05 * p.fibers.a0
    cg, direct = NewtonSolver(Model.from_problem(p), "cg"), NewtonSolver(Model.from_problem(p), "direct")
    for newton in (cg, direct):
        newton.solve(ac=ac, x0=p.mesh.nodes, tol=1e-12)  # both models at the same equilibrium
    cg.linear.pre.refresh_iterations = 0  # every solve counts as long
    rng = np.random.default_rng(3)
    rhs = [rng.normal(size=p.mesh.nodes.shape) * ~p.fixed[:, None] for _ in range(3)]
    got = list(cg.linear.solve_many(rhs, 1e-10))
    want = list(direct.linear.solve_many(rhs, 1e-10))
    assert len(got) == 3 and cg.linear.pre.refreshes >= 3
    for a, b in zip(got, want):
        assert np.abs(a - b).max() <= 1e-7 * np.abs(b).max()


def test_solves_are_deterministic():
    p = build_problem(load_scene("t_shape"), 1)
    m = Model.from_problem(p)
    newton = NewtonSolver(m, "cg")
    a = newton.solve(ac=0.07 * p.fibers.a0, x0=p.mesh.nodes)
    b = newton.solve(ac=0.07 * p.fibers.a0, x0=p.mesh.nodes)
    assert np.array_equal(a.x, b.x) and a.newton_iterations == b.newton_iterations


def test_non_convergence_is_a_clear_error():
    p = build_problem(load_scene("t_shape"), 1)
    m = Model.from_problem(p)
    with pytest.raises(ConvergenceError, match=r"did not converge: relative force residual .* after 2 Newton"):
        NewtonSolver(m, "cg", max_iter=2).solve(ac=0.1 * p.fibers.a0)


def test_a_residual_stalled_by_round_off_near_the_tolerance_is_converged():
    """Round-off puts a floor under the force residual (t_shape's lattice at level 8:
    1.2e-12, above the 1e-12 of a stage state). A residual within the round-off
    factor of the tolerance that STALL_STEPS steps do not halve is converged, as
    ``Equilibrium.residual`` says; one that stalls further from it is still an error.
    Here the tolerance is set below this lattice's floor instead."""
    from tendon_taichi.solve import newton as newton_module

    p = build_problem(load_scene("t_shape"), 1)
    m = Model.from_problem(p)
    ac = 0.05 * p.fibers.a0
    reference = NewtonSolver(m, "direct", tol=1e-12).solve(ac=ac, x0=p.mesh.nodes)
    newton = NewtonSolver(m, "direct", tol=1e-19)
    newton.roundoff_factor = 1e6  # a window up to 1e-13, above the floor here
    eq = newton.solve(ac=ac, x0=p.mesh.nodes)
    assert 1e-19 < eq.residual <= 1e-13
    assert reference.newton_iterations < eq.newton_iterations < 100
    assert np.abs(eq.x - reference.x).max() <= 1e-12 * p.size  # the same equilibrium
    floor = eq.residual
    newton.roundoff_factor = 0.5 * floor / 1e-19  # the floor lies beyond the window: no stall taken
    with pytest.raises(ConvergenceError, match="did not converge"):
        newton.solve(ac=ac, x0=p.mesh.nodes)
    assert newton_module._stalled([8.0, 6.0, 5.0, 5.0, 4.5, 4.1], 10.0)  # 5 steps, not halved
    assert not newton_module._stalled([8.0, 6.0, 5.0, 5.0, 4.5, 3.9], 10.0)  # halved
    assert not newton_module._stalled([11.0, 6.0, 5.0, 5.0, 4.5, 6.0], 10.0)  # not all within the window
    assert not newton_module._stalled([6.0, 5.0, 5.0, 4.5, 4.1], 10.0)  # fewer steps


def test_large_contraction_keeps_triangles_valid():
    p = build_problem(parse_scene(small_scene_toml(21)), 1)
    m = Model.from_problem(p)
    eq = NewtonSolver(m, "cg").solve(ac=0.33 * p.fibers.a0)
    T = p.mesh.triangles
    x = eq.x
    assert np.linalg.det(np.stack([x[T[:, 1]] - x[T[:, 0]], x[T[:, 2]] - x[T[:, 0]]], -1)).min() > 0
    assert eq.residual <= 1e-10


@pytest.mark.parametrize("cholesky", ["qdldl", "pardiso"])
def test_the_direct_factorization_is_ldl_where_positive_definite_else_lu(monkeypatch, cholesky):
    """At a stable equilibrium the Hessian is positive definite and factorized by
    LDL^T or PARDISO's Cholesky (its symbolic analysis kept for the next); shifted
    to be indefinite it is factorized by PARDISO's symmetric indefinite
    factorization (with qdldl: SuperLU), which counts its one negative eigenvalue;
    both solve their own matrix, and a factorization still solves its own matrix
    after a newer one of the same pattern replaced the shared factors."""
    from dataclasses import replace

    import scipy.sparse as sp

    from tendon_taichi.solve.direct import DirectSolver

    kind = use_cholesky(monkeypatch, cholesky)
    p = build_problem(load_scene("t_shape"), 1)
    m = Model.from_problem(p)
    NewtonSolver(m, "direct").solve(ac=0.05 * p.fibers.a0, x0=p.mesh.nodes)
    d = DirectSolver(m)
    H = d.assemble_ordered()
    n = H.Hp.shape[0]
    b = np.random.default_rng(0).standard_normal(n)

    def residual(fac, Hp):
        y = fac.solve_ordered(b)
        return np.linalg.norm(Hp @ y - b) / np.linalg.norm(b)

    spd = d.factorize(H)
    assert isinstance(spd.ldl, kind) and spd.lu is None and residual(spd, H.Hp) < 1e-10
    lowest = sp.linalg.eigsh(H.Hp, k=1, sigma=0, which="LM", return_eigenvectors=False)[0]
    data = H.Hp.data.copy()  # the same pattern, shifted by twice the lowest eigenvalue: one negative
    data[H.Hp.indices == np.repeat(np.arange(n), np.diff(H.Hp.indptr))] -= 2 * abs(lowest)
    shifted = sp.csc_matrix((data, H.Hp.indices, H.Hp.indptr), shape=(n, n))
    indefinite = d.factorize(replace(H, Hp=shifted))
    if cholesky == "pardiso":
        assert indefinite.ldl.indefinite and indefinite.lu is None and indefinite.ldl.negative == 1
    else:
        assert indefinite.ldl is None and indefinite.lu is not None
    assert residual(indefinite, shifted) < 1e-8
    if cholesky == "pardiso":  # a newer indefinite one replaces the shared factors: the older makes its own
        newer = d.factorize(replace(H, Hp=2.0 * shifted))
        assert newer.ldl.indefinite and residual(newer, 2.0 * shifted) < 1e-8 and residual(indefinite, shifted) < 1e-8
        assert indefinite.ldl is not newer.ldl and indefinite.ldl.indefinite
    again = d.factorize(replace(H, Hp=sp.csc_matrix((2.0 * H.Hp.data, H.Hp.indices, H.Hp.indptr))))
    assert again.ldl is spd.ldl  # the same symbolic analysis, new numbers
    assert residual(again, 2.0 * H.Hp) < 1e-10 and residual(spd, H.Hp) < 1e-10  # spd made its own copy


def test_pardisos_indefinite_factorization_counts_the_inertia_and_refuses_a_perturbed_pivot(monkeypatch):
    """PARDISO's symmetric indefinite factorization solves an indefinite matrix and
    counts its negative eigenvalues (numpy's count); where it would have to perturb a
    pivot (a singular matrix) it refuses, and the direct backend takes SuperLU."""
    import scipy.sparse as sp

    from tendon_taichi.solve import pardiso
    from tendon_taichi.solve.direct import Assembled, Factorization

    use_cholesky(monkeypatch, "pardiso")
    rng = np.random.default_rng(3)
    Q = np.linalg.qr(rng.standard_normal((6, 6)))[0]
    dense = Q @ np.diag([3.0, -2.0, 1.0, -0.5, 4.0, 2.0]) @ Q.T
    A = sp.csc_matrix(dense)
    ldl = pardiso.PardisoLDL(A.indptr, A.indices, 6, indefinite=True)
    assert ldl.factor(A.data) and ldl.negative == int((np.linalg.eigvalsh(dense) < 0).sum()) == 2
    b = rng.standard_normal(6)
    assert np.linalg.norm(dense @ ldl.solve(b) - b) <= 1e-12 * np.linalg.norm(b)
    cholesky = pardiso.PardisoLDL(A.indptr, A.indices, 6)
    assert not cholesky.factor(A.data)  # not positive definite

    singular = sp.csc_matrix(np.array([[1.0, 1.0, 0.0], [1.0, 1.0 + 1e-13, 0.0], [0.0, 0.0, -1.0]]))
    handles = [pardiso.PardisoLDL(singular.indptr, singular.indices, 3, indefinite=flag) for flag in (False, True)]
    assert not handles[1].factor(singular.data)  # a pivot of 1e-13: perturbed, so refused
    fac = Factorization(Assembled(singular, np.zeros((3, 0)), np.zeros(0)), np.arange(3), handles[0],
                        lambda: handles[1])
    assert fac.ldl is None and fac.lu is not None


def test_pardiso_solves_as_qdldl_does_and_the_same_every_time(monkeypatch):
    """The soft IK's objective and adjoint gradient at level 1 with PARDISO's
    Cholesky agree with qdldl's LDL^T to round-off, and two runs with PARDISO
    agree to the bit (one thread: reproducible)."""
    from tendon_taichi.optimizer.soft_ik import SoftIK

    p = build_problem(load_scene("t_shape"), 1)
    r = np.random.default_rng(1).uniform(0.02, 0.08, p.fibers.n_fibers)

    def gradient(name):
        with monkeypatch.context() as m:
            kind = use_cholesky(m, name)
            ik = SoftIK(p, p.scene.optimize, "direct")
            ik.restart(r)
            out = ik.evaluate(r)
            assert isinstance(ik.linear.ldl, kind)
        return out

    (f0, g0), (f1, g1), (f2, g2) = gradient("qdldl"), gradient("pardiso"), gradient("pardiso")
    assert abs(f1 - f0) <= 1e-10 * abs(f0) and np.abs(g1 - g0).max() <= 1e-8 * np.abs(g0).max()
    assert f1 == f2 and np.array_equal(g1, g2)


@pytest.mark.parametrize("cholesky", ["qdldl", "pardiso"])
def test_the_cholesky_library_is_named_with_its_version(monkeypatch, cholesky):
    """``cholesky_library`` names what the direct backend factorizes with and its
    version as the installed package gives it (MKL reports its release, which the
    wheel's version starts with: 2026.2 of 2026.2.1), and MKL's code path."""
    import importlib.metadata as md
    import os

    from tendon_taichi.solve.cholesky import cholesky_library

    use_cholesky(monkeypatch, cholesky)
    lib = cholesky_library()
    if cholesky == "qdldl":
        assert lib == {"name": "qdldl", "version": md.version("qdldl")}
        return
    assert lib["name"] == "MKL PARDISO" and lib["build"].isdigit() and lib["code_path"]
    if not os.environ.get("TENDON_TAICHI_MKL_RT"):  # the mkl extra's own runtime
        assert md.version("mkl").startswith(lib["version"]) and lib["version"][:4].isdigit()


@pytest.mark.parametrize("cholesky", ["qdldl", "pardiso"])
def test_several_right_hand_sides_solve_in_one_call_as_one_by_one(monkeypatch, cholesky):
    """A factorization solves the columns of an (n, r) right-hand side in one call
    (the Woodbury columns of a tendon robot) as it solves each alone, to
    round-off, and each to the residual of the matrix it factorized."""
    from scipy import sparse

    kind = use_cholesky(monkeypatch, cholesky)
    n = 200
    A = sparse.random(n, n, 0.03, random_state=2)
    A = (A + A.T + 8.0 * sparse.eye(n)).tocsc()
    A.sort_indices()
    ldl = kind(A.indptr, A.indices, n, True)
    assert ldl.factor(A.data)
    B = np.random.default_rng(3).normal(size=(n, 4))
    X = ldl.solve(B)
    one_by_one = np.column_stack([ldl.solve(b) for b in B.T])
    assert X.shape == B.shape and np.abs(X - one_by_one).max() <= 1e-13 * np.abs(X).max()
    assert np.abs(A @ X - B).max() <= 1e-12 * np.abs(B).max()


def test_every_blas_is_capped_however_late_it_loads():
    """Starting the runtime caps every BLAS thread pool to one thread, scipy's own
    too when it is imported afterwards: an idle BLAS thread that spins holds the
    core a factorization's second thread waits for (a level-4 tendon robot's
    factorization took 33 ms instead of 1.5)."""
    import subprocess
    import sys

    code = ("from tendon_taichi.physics import runtime; runtime.init(); import scipy.sparse.linalg; "
            "from threadpoolctl import threadpool_info; "
            "print([d['num_threads'] for d in threadpool_info() if d['user_api'] == 'blas'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    counts = eval(out.stdout.strip().splitlines()[-1])
    assert counts and all(c == 1 for c in counts)


def test_pardiso_factorizes_to_the_same_bits_on_any_number_of_threads(monkeypatch):
    """A lattice's Hessian (t_shape at level 4, 5336 DOFs: above the parallel
    threshold, in the reproducible mode) factorized by PARDISO on 1, 2 and 3
    threads, in its own order or PARDISO's, and shifted to be indefinite by its
    indefinite factorization, solves to the same bits, one
    right-hand side or several at once (a tendon robot's low-rank columns); a matrix
    above the threshold is factorized on the threads the job gives (a handle keeps
    them in its blank copies and its pickled ones), else on the process's, and
    one below it on one thread, outside the mode."""
    import pickle

    import scipy.sparse as sp

    from tendon_taichi.physics import runtime
    from tendon_taichi.solve import pardiso
    from tendon_taichi.solve.backends import make_linear_solver
    from tendon_taichi.solve.linear import LinearSettings

    use_cholesky(monkeypatch, "pardiso")
    p = build_problem(load_scene("t_shape"), 4)
    m = Model.from_problem(p)
    NewtonSolver(m, "direct").solve(ac=0.05 * p.fibers.a0, x0=p.mesh.nodes)
    H = DirectSolver(m).assemble_ordered().Hp
    n = H.shape[0]
    assert n >= pardiso.PARALLEL_MIN
    rng = np.random.default_rng(0)
    rhs = [rng.standard_normal(n), rng.standard_normal((n, 2)), rng.standard_normal((n, 3))]
    lowest = sp.linalg.eigsh(H, k=1, sigma=0, which="LM", return_eigenvectors=False)[0]
    shifted = (H - 2.0 * abs(lowest) * sp.identity(n, format="csc")).tocsc()  # one negative eigenvalue
    shifted.sort_indices()
    # the pattern's order (a lattice's), PARDISO's own (a tendon robot's); the indefinite factorization
    for reorder, indefinite, M in ((False, False, H), (True, False, H), (True, True, shifted)):
        assert np.array_equal(M.indptr, H.indptr) and np.array_equal(M.indices, H.indices)
        solutions = []
        for threads in (1, 2, 3):
            ldl = pardiso.PardisoLDL(M.indptr, M.indices, n, reorder=reorder, indefinite=indefinite)
            assert ldl.reproducible
            ldl.threads = threads
            assert ldl.factor(M.data) and ldl.factor(M.data)
            assert ldl.threads_used == (threads if pardiso.threaded() else 1) and ldl.negative == indefinite
            solutions.append([ldl.solve(b) for b in rhs])
            for b, y in zip(rhs, solutions[-1]):
                assert y.shape == b.shape and np.linalg.norm(M @ y - b) <= 1e-10 * np.linalg.norm(b)
        assert all(np.array_equal(y0, y) for ys in solutions[1:] for y0, y in zip(solutions[0], ys))

    monkeypatch.setenv("TENDON_TAICHI_FACTOR_THREADS", "3")
    large = pardiso.PARALLEL_MIN
    assert pardiso.factor_threads(large) == 3 and pardiso.factor_threads(large - 1) == 1
    eye = sp.identity(large - 1, format="csc")
    below = pardiso.PardisoLDL(eye.indptr, eye.indices, large - 1)
    assert not below.reproducible and below.threads == 1  # one thread: the same bits without the mode
    assert below.factor(2.0 * eye.data)
    assert np.allclose(below.solve(np.ones(large - 1)), 0.5, rtol=1e-14, atol=0.0)
    assert pardiso.factor_threads(large, 2) == 2 and pardiso.factor_threads(large - 1, 2) == 1
    eye = sp.identity(large, format="csc")
    given = pardiso.PardisoLDL(eye.indptr, eye.indices, large, threads=1)
    assert given.threads == 1 and given.blank().threads == 1 and pickle.loads(pickle.dumps(given)).threads == 1
    assert pardiso.PardisoLDL(eye.indptr, eye.indices, large).threads == 3
    settings = LinearSettings("direct", factor_threads=2)
    assert make_linear_solver(settings, m).factor_threads == 2
    assert make_linear_solver("direct", m).factor_threads is None
    with runtime.cores_shared(True):  # what a script that replays a design's pieces asks (route_replay.py)
        assert pardiso.factor_threads(large) == 1 and pardiso.factor_threads(large, 2) == 2
        with runtime.cores_shared(False):
            assert pardiso.factor_threads(large) == 1
    assert pardiso.factor_threads(large) == 3


@pytest.mark.parametrize("robot", ["lattice", "tendons"])
def test_pardisos_factor_is_about_as_small_as_in_a_minimum_degree_order(monkeypatch, robot):
    """PARDISO factorizes a fiber lattice in the direct backend's order of its
    whole pattern, and a tendon robot in its own minimum degree order: the
    elements' order, which every tendon layout of a mesh shares, does not see the
    couplings the segments add along each route (with it, two tendons along a
    finger's length give a factor of 2.8x the entries). Either way the factor
    holds at most 1.5x the entries of qdldl's in its own AMD order (PARDISO pads
    its supernodes)."""
    from tendon_taichi.extract.realizable import tendon_cables
    from tendon_taichi.extract.routes import fit_route
    from tendon_taichi.solve.direct import LDL

    use_cholesky(monkeypatch, "pardiso")
    p = build_problem(load_scene("finger"), 1)
    cables = None
    if robot == "tendons":
        t = np.linspace(0, 1, 12)
        paths = [np.stack([0.005 + 0.085 * t, np.full_like(t, y)], 1) for y in (0.004, 0.016)]
        cables = tendon_cables(p, [fit_route(q, p.size, 0.4).tendon() for q in paths])
    m = Model.from_problem(p, cables=cables)
    NewtonSolver(m, "direct").solve(ac=0.03 * m.cables.a0, x0=p.mesh.nodes)
    d = DirectSolver(m)
    H = d.assemble_ordered()
    n = H.Hp.shape[0]
    fac = d.factorize(H)
    amd = LDL(H.Hp.indptr, H.Hp.indices, n)
    assert amd.factor(H.Hp.data) and fac.lu is None
    assert 0 < fac.ldl.entries <= 1.5 * (amd.solver.factors()[0].nnz + n)


def test_a_tendon_robots_sparse_hessian_holds_every_entry_once():
    """The direct backend's pattern of a tendon robot (the elements' part kept per
    mesh, the segments' merged into it) assembles the same matrix as every element
    and segment entry scattered and summed by scipy on the free DOFs, and holds
    each distinct entry once."""
    import scipy.sparse as sp

    from tendon_taichi.extract.realizable import tendon_cables
    from tendon_taichi.extract.routes import fit_route

    p = build_problem(load_scene("t_shape"), 1)
    t = np.linspace(0, 1, 12)
    paths = [np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1),
             np.stack([0.004 * np.sin(3 * t), 0.01 + 0.05 * t], 1)]
    m = Model.from_problem(p, cables=tendon_cables(p, [fit_route(q, p.size, 0.4).tendon() for q in paths]))
    NewtonSolver(m, "direct").solve(ac=0.05 * m.cables.a0, x0=p.mesh.nodes)
    d = DirectSolver(m)
    H = d.assemble_ordered()
    T = p.mesh.triangles
    edofs = (2 * T[:, :, None] + np.arange(2)).reshape(-1, 6)
    rows = np.concatenate([np.repeat(edofs, 6, 1).ravel(), np.repeat(d.sdofs, 12, 1).ravel()])
    cols = np.concatenate([np.tile(edofs, (1, 6)).ravel(), np.tile(d.sdofs, (1, 12)).ravel()])
    n = 2 * m.n
    free = np.flatnonzero(d.free)
    expect = sp.coo_matrix((m.hessian_entries(), (rows, cols)), shape=(n, n)).tocsc()[free][:, free]
    got = H.Hp[d.order][:, d.order]  # back to the free DOFs' own numbering
    assert abs(got - expect).max() <= 1e-12 * abs(expect).max()
    kept = d.free[rows] & d.free[cols]
    assert d.nnz == len(np.unique(rows[kept] * n + cols[kept]))


def _lattice_and_tendon_robot():
    """t_shape at level 1 near equilibrium: its fiber lattice, and a robot of two
    tendons with capstan friction."""
    from tendon_taichi.body.cables import CableSet

    p = build_problem(load_scene("t_shape"), 1)
    lattice = Model.from_problem(p)
    NewtonSolver(lattice, "direct").solve(ac=0.02 * lattice.cables.a0, x0=p.mesh.nodes)
    t = np.linspace(0, 1, 12)
    paths = [np.stack([0.04 * t, 0.075 - 0.004 * np.sin(np.pi * t)], 1),
             np.stack([0.004 * np.sin(3 * t), 0.01 + 0.05 * t], 1)]
    robot = Model.from_problem(p, cables=CableSet.polylines(p.mesh, paths, 50.0, friction=0.3))
    assert robot.capstan is not None
    NewtonSolver(robot, "direct").solve(ac=0.05 * robot.cables.a0, x0=p.mesh.nodes)
    return lattice, robot


def test_hessian_sums_are_the_bincount_of_the_entries_to_the_bit():
    """The direct backend's assembly sums the element and segment entries in Taichi
    (``Model.hessian_sums``); each sum takes its terms in the entries' order, so it
    is ``np.bincount`` of ``hessian_entries`` bit for bit - for the backend's own
    scatter (entries on clamped DOFs into one more bin) and for a random one."""
    rng = np.random.default_rng(3)
    for m in _lattice_and_tendon_robot():
        d = DirectSolver(m)
        m.prepare_hessian()
        entries = m.hessian_entries()
        for scatter, bins in [(d.scatter, d.nnz + 1), (rng.integers(0, 97, len(entries)).astype(np.int32), 100)]:
            got = m.hessian_sums(scatter, bins)
            expect = np.bincount(scatter, weights=entries, minlength=bins)
            assert got.tobytes() == expect.tobytes()
        assert np.any(d.scatter == d.nnz) and len(np.unique(d.scatter)) > 1000
    with pytest.raises(ValueError, match="int32"):
        m.hessian_sums(d.scatter.astype(np.int64), d.nnz + 1)
    with pytest.raises(ValueError, match="a bin outside"):  # the kernel would write out of bounds
        m.hessian_sums(d.scatter, d.nnz)


def test_the_direct_backend_prepares_no_block_jacobi():
    """``prepare_hessian(jacobi=False)`` (the direct backend's) makes the same element
    tangents and cable stiffnesses and leaves the block-Jacobi preconditioner, which
    only CG uses, as it was."""
    for m in _lattice_and_tendon_robot():
        names = [("D", 16 * m.m), ("KC", m.C), ("TAU", m.C)]
        m.write("MINV", np.full(4 * m.n, 7.0))
        m.prepare_hessian(jacobi=False)
        without = m.read_many(names)
        assert np.all(m.read("MINV", 4 * m.n) == 7.0)
        m.prepare_hessian()
        assert all(a.tobytes() == b.tobytes() for a, b in zip(without, m.read_many(names)))
        assert not np.any(m.read("MINV", 4 * m.n) == 7.0)
