"""The headless resolution-scaling benchmark (``tendon-taichi bench``).

Per resolution level and linear solver it measures (medians, and min/max over
``repeat`` runs, after a warm-up so that compiling the Taichi kernels is
excluded and reported separately as ``compile_s``): problem sizes; one
equilibrium from rest and one warm-started from a nearby design (contraction
ratios moved by +-0.5 %); Newton and CG iterations; one adjoint solve; one full
gradient (warm equilibrium + adjoint); the gradient by forward sensitivities
(one solve per fiber, the method of Bern et al. 2017) where that finishes in
reasonable time; the same gradient by a plain numpy/scipy implementation
(:mod:`.baseline`), timed in the same run, and how many times faster the
pipeline's is; the process's peak memory; and the whole regularized
optimization with the quality of each installed extractor's tendons.
"""

from __future__ import annotations

import csv
import os
import platform
import resource
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..body.problem import build_problem
from ..body.scene import Scene
from ..errors import InputError, Stopped
from ..files import atomic_path, file_stem, write_json
from ..io.plots import plot_bench
from ..io.progress import Progress
from ..objective.term import State
from ..optimizer.soft_ik import ADJOINT_TOL, SoftIK
from ..physics import runtime
from ..physics.elements import check_elements
from ..solve.linear import resolve_solver
from ..solve.newton import NewtonSolver
from ..solve.pardiso import available as pardiso_available
from ..solve.pardiso import threaded as pardiso_threaded
from ..tasks.engine import Cluster, Task, case_id, run_tasks
from .baseline import BaselineGradient
from .case import STOP, CaseSettings, run_case, worker_setup
from .provenance import result_provenance

#: seconds-valued figures, in the order of the table and the plot
TIMINGS = ("equilibrium_cold_s", "equilibrium_warm_s", "adjoint_s", "gradient_s", "forward_sensitivity_s",
           "optimize_s")


def machine() -> dict:
    model = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            model = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), model)
    except OSError:
        pass
    return {"cores": os.cpu_count(), "cpu": model, "python": platform.python_version(),
            "platform": platform.platform(), "pardiso": pardiso_available(),
            "pardiso_threaded": pardiso_threaded(), **runtime.info()}


def peak_memory_mb() -> float:
    """Peak resident memory of this process so far, MB."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 1024.0 if sys.platform != "darwin" else rss / 2 ** 20


def _stats(values: list[float]) -> dict:
    return {"median": statistics.median(values), "min": min(values), "max": max(values)}


def design_pair(problem, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A design and a nearby one, the contraction ratios ``bench``'s warm equilibrium
    goes between (and the benchmarks beside it): ``r0`` (n_fibers,) drawn from 2-8 %
    by ``seed``, and ``r1``, each ratio of ``r0`` moved by at most +-0.5 % of itself."""
    rng = np.random.default_rng(seed)
    r0 = rng.uniform(0.02, 0.08, problem.fibers.n_fibers)
    return r0, r0 * (1 + 0.005 * rng.uniform(-1, 1, len(r0)))


def measure_solver(problem, solver: str, repeat: int, forward_max_fibers: int, progress) -> dict:
    """Equilibria, adjoint, gradient and forward sensitivities with one backend."""
    a0 = problem.fibers.a0
    r0, r1 = design_pair(problem)
    ik = SoftIK(problem, problem.scene.optimize, solver)
    ik.configure(None)  # pose + contraction: what soft IK differentiates
    m, lin = ik.model, ik.linear
    exact = NewtonSolver(m, lin)  # plain exact Newton, as `simulate` solves
    t = time.perf_counter()
    exact.solve(ac=r0 * a0, x0=problem.mesh.nodes)  # warm-up: compiles what this backend needs
    out = {"solver": lin.name, "first_solve_s": time.perf_counter() - t}
    cold, warm, nit, cgit = [], [], {}, {}
    for _ in range(repeat):
        lin.reset()
        it0 = lin.stats.iterations
        t = time.perf_counter()
        eq = exact.solve(ac=r0 * a0, x0=problem.mesh.nodes)
        cold.append(time.perf_counter() - t)
        nit["cold"], cgit["cold"] = eq.newton_iterations, lin.stats.iterations - it0
        x_eq = eq.x
        it0 = lin.stats.iterations
        t = time.perf_counter()
        eq = exact.solve(ac=r1 * a0)  # warm: from the equilibrium of the nearby design
        warm.append(time.perf_counter() - t)
        nit["warm"], cgit["warm"] = eq.newton_iterations, lin.stats.iterations - it0
        m.set_positions(x_eq)
    out["equilibrium_cold_s"], out["equilibrium_warm_s"] = _stats(cold), _stats(warm)
    out["newton_iterations"], out["cg_iterations"] = nit, cgit
    progress(f"  {lin.name}: equilibrium cold {statistics.median(cold):.3f} s, warm {statistics.median(warm):.3f} s")

    # the adjoint solve and one full gradient, at the design r0
    exact.solve(ac=r0 * a0, x0=problem.mesh.nodes)
    ik.evaluate(r0)
    rhs = ik.objective.evaluate(_states(ik, r0)).dx[0]
    rhs[problem.fixed] = 0.0
    adj, grad = [], []
    for _ in range(repeat):
        t = time.perf_counter()
        lin.solve(rhs, tol=ADJOINT_TOL)
        adj.append(time.perf_counter() - t)
    for _ in range(repeat):
        ik.restart(r0)
        ik.evaluate(r0)
        t = time.perf_counter()
        _, g = ik.evaluate(r1)
        grad.append(time.perf_counter() - t)
    out["adjoint_s"], out["gradient_s"] = _stats(adj), _stats(grad)
    progress(f"  {lin.name}: adjoint {statistics.median(adj):.4f} s, gradient {statistics.median(grad):.4f} s")

    # forward sensitivities: one solve per fiber for dx/dac (Bern et al. 2017)
    out["forward_sensitivity_s"] = None
    if problem.fibers.n_fibers <= forward_max_fibers:
        t = time.perf_counter()
        g_fwd = forward_gradient(ik, r1)
        dt = time.perf_counter() - t
        out["forward_sensitivity_s"] = {"median": dt, "min": dt, "max": dt}
        out["forward_vs_adjoint_rel_diff"] = float(np.linalg.norm(g_fwd - g) / np.linalg.norm(g))
        progress(f"  {lin.name}: forward sensitivities {dt:.2f} s ({problem.fibers.n_fibers} solves)")
    return out


def measure_baseline(problem, repeat: int, progress) -> dict:
    """The gradient of :func:`measure_solver` (warm equilibrium at the nearby design
    from the first's, then the adjoint) by the numpy/scipy baseline (:mod:`.baseline`)."""
    base = BaselineGradient(problem, problem.scene.optimize.contraction_reg)
    r0, r1 = design_pair(problem)
    x0 = base.equilibrium(r0 * problem.fibers.a0, problem.mesh.nodes)
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        base.objective_gradient(r1, x0)
        times.append(time.perf_counter() - t)
    progress(f"  numpy/scipy baseline: gradient {statistics.median(times):.4f} s")
    return _stats(times)


def speedups(entry: dict) -> dict:
    """Per backend, the baseline's gradient time over the backend's (medians)."""
    base = entry.get("baseline_gradient_s")
    return {s: base["median"] / f["gradient_s"]["median"] for s, f in entry["solvers"].items()
            if base and f.get("gradient_s")}


def _states(ik: SoftIK, r: np.ndarray):
    """The last evaluated point as the objective's per-pose states (one pose here)."""
    xs, taus = ik.state()
    return [State(xs[0], r * ik.a0, taus[0])]


def forward_gradient(ik: SoftIK, r: np.ndarray) -> np.ndarray:
    """dO/dr by forward sensitivities at the equilibrium of r: for each fiber i,
    H s_i = -(d2E/dx dac) e_i, then dO/dac_i = explicit_i + dO/dx . s_i."""
    ik.evaluate(r)
    m, lin = ik.model, ik.linear
    cab = m.cable_state()
    ev = ik.objective.evaluate(_states(ik, r))
    dOdx = ev.dx[0] + m.length_jacobian_product(ev.dtau[0] * cab["kc"])
    dOdx[ik.problem.fixed] = 0.0
    n_f = len(r)
    grad = ev.dac[0] + ev.dtau[0] * cab["tau_ac"]
    def rhs():
        yield dOdx  # the first solve prepares (direct: factorizes) the Hessian once
        for i in range(n_f):
            yield -m.mixed_product(np.eye(1, n_f, i).ravel())

    sols = lin.solve_many(rhs(), ADJOINT_TOL)
    next(sols)
    for i, s in enumerate(sols):
        grad[i] += float((dOdx * s).sum())
    return grad * ik.a0


def optimize_case(scene: Scene, level: int, solver: str, out_dir: str) -> dict:
    """The whole design pipeline - the regularized optimization, every installed
    extractor on its last stage with consolidation and route optimization, the
    recommended design - (a task of :func:`~tendon_taichi.tasks.engine.run_tasks`)."""
    out = Path(out_dir) / f"{file_stem(scene.name)}-r{level}-{solver}"
    case = run_case(scene, level, out, CaseSettings(solver=solver))
    run, timing = case.run, case.summary["timing"]
    dt = timing["optimize_s"]
    final = run.summary["final"]
    rec = case.summary["recommended"]
    res = {"optimize_s": {"median": dt, "min": dt, "max": dt}, "design_s": case.summary["time_s"],
           "stages": len(run.stages), "pose_error_rel": final["pose_error_rel"],
           "active_fibers": final["active_fibers"], "active_length": final["active_length"],
           "evaluations": run.summary.get("evaluations"),
           "recording_mb": (out / "run.rrd").stat().st_size / 1e6,
           "design": {"tendons": rec["count"], "kinks": rec["metrics"]["kinks"],
                      "capstan_worst": rec["metrics"]["capstan_worst"],
                      "realizable_pose_error_rel": rec["metrics"]["realizable_pose_error_rel"]}}
    res["extractors"] = {r.name: ({"error": r.error} if r.error else
                                  {"tendons": r.metrics["count"], "kinks": r.metrics["kinks"],
                                   "capstan_worst": r.metrics["capstan_worst"],
                                   "realizable_pose_error_rel": r.metrics["realizable_pose_error_rel"]})
                         for r in case.extraction.results}
    res["peak_memory_mb"] = peak_memory_mb()
    return res


def _describe_optimize(res: dict) -> str:
    tendons = ", ".join(f"{n} {e.get('tendons', 'failed')}" for n, e in res["extractors"].items())
    return (f"optimize {res['optimize_s']['median']:.1f} s, {res['stages']} stages, pose "
            f"{100 * res['pose_error_rel']:.2f} %, active {100 * res['active_length']:.1f} cm; tendons: {tendons}")


@dataclass(frozen=True)
class BenchSettings:
    """What the benchmark measures: the resolution ``levels`` and linear ``solvers``,
    each timing the median of ``repeat`` runs; the forward sensitivities only up to
    ``forward_max_fibers`` fibers; the whole design pipeline at ``optimize_levels``
    (None: every level), with every measured solver (``optimize_solver`` ``each``) or
    once per level with the backend ``--solver auto`` picks at that size (``auto``,
    what a user gets by default, reported under that backend)."""

    levels: tuple[int, ...]
    solvers: tuple[str, ...]
    repeat: int = 3
    optimize_levels: tuple[int, ...] | None = None
    forward_max_fibers: int = 2500
    optimize_solver: str = "each"


def run_bench(scene: Scene, settings: BenchSettings, out_dir: str | Path = "recordings/bench",
              cluster: Cluster = Cluster(workers=0), progress=None, cases_dir: str | Path | None = None) -> dict:
    """Run the benchmark ``settings`` describe and write bench.json, bench.csv and
    bench.png into ``out_dir`` (the design pipeline's folders into ``cases_dir``,
    default ``out_dir``). The optimizations run after all other measurements, as
    tasks of :func:`tendon_taichi.tasks.engine.run_tasks` on ``cluster`` (its
    ``workers`` 0, the default: in this process, one after the other; else on a
    local or an existing Dask cluster)."""
    levels, solvers, repeat = settings.levels, settings.solvers, settings.repeat
    optimize_levels, optimize_solver = settings.optimize_levels, settings.optimize_solver
    forward_max_fibers = settings.forward_max_fibers
    if len(scene.poses) > 1:
        raise InputError(f"bench measures one-pose scenes; '{scene.name}' has {len(scene.poses)} poses")
    check_elements(scene.body.dim, scene.origin)
    reporter = Progress() if progress is None else progress
    progress = reporter.message if progress is None else progress
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    optimize_levels = levels if optimize_levels is None else optimize_levels
    rows, jobs = [], []
    for level in levels:
        p = build_problem(scene, level)
        entry = {"level": level, **p.counts(), "solvers": {}}
        progress(f"level {level}: {entry['nodes']} nodes, {entry['triangles']} triangles, {entry['fibers']} fibers, "
                 f"{entry['dofs']} DOFs")
        picked = resolve_solver("auto", entry["dofs"])
        for solver in solvers:
            fig = measure_solver(p, solver, repeat, forward_max_fibers, progress)
            fig["peak_memory_mb"] = peak_memory_mb()
            name = fig.pop("solver") if solver == "auto" else solver
            entry["solvers"][name] = fig
            optimize_here = optimize_solver == "each" or resolve_solver(solver, entry["dofs"]) == picked
            if level in optimize_levels and optimize_here:
                jobs.append((fig, Task(case_id({"kind": "bench", "scene": scene.source, "level": level,
                                                "solver": solver}),
                                       f"level {level} {solver}", optimize_case,
                                       (scene, level, solver, str(cases_dir or out_dir)))))
        entry["baseline_gradient_s"] = measure_baseline(p, repeat, progress)
        entry["gradient_speedup"] = speedups(entry)
        rows.append(entry)
    report = run_tasks([t for _, t in jobs], None, replace(cluster, setup=worker_setup(), stop=STOP), reporter,
                       describe=_describe_optimize)
    figs = {t.id: fig for fig, t in jobs}
    for o in report.outcomes:
        fig = figs[o.task.id]
        if o.error is not None:
            fig["optimize_error"] = o.error
            continue
        res = dict(o.value)
        fig["peak_memory_mb"] = max(fig["peak_memory_mb"], res.pop("peak_memory_mb"))
        fig.update(res)
    # each backend's first solve in the process included compiling its kernels
    comp = sum(f["first_solve_s"] - f["equilibrium_cold_s"]["median"] for f in rows[0]["solvers"].values())
    result = {"scene": scene.name, "machine": machine(), "compile_s": comp, "repeat": repeat, "levels": rows,
              "exponents": exponents(rows), "optimize_engine": report.engine, "provenance": result_provenance()}
    write_outputs(result, out_dir)
    if report.interrupted:
        raise Stopped(f"interrupted during the optimizations; {len(report.outcomes)} of {len(jobs)} finished "
                      f"are in '{out_dir}'")
    return result


def exponents(rows: list[dict]) -> dict:
    """Least-squares slopes of log(time) against log(DOFs), per solver and timing,
    over the levels from the second on when there are three or more (the first is
    dominated by fixed costs)."""
    out = {}
    solvers = {s for r in rows for s in r["solvers"]}
    fit_rows = rows[1:] if len(rows) >= 3 else rows
    for s in solvers:
        for key in TIMINGS:
            pts = [(r["dofs"], r["solvers"][s][key]["median"]) for r in fit_rows
                   if s in r["solvers"] and r["solvers"][s].get(key)]
            if len(pts) >= 2:
                x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
                out.setdefault(s, {})[key] = float(np.polyfit(x, y, 1)[0])
    return out


def write_outputs(result: dict, out_dir: Path) -> None:
    write_json(result, out_dir / "bench.json")
    with atomic_path(out_dir / "bench.csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            head = ["level", "nodes", "triangles", "fibers", "dofs", "solver"] + list(TIMINGS) + \
                   ["newton_cold", "newton_warm", "cg_cold", "cg_warm", "peak_memory_mb", "stages",
                    "pose_error_rel", "active_length", "active_fibers", "baseline_gradient_s", "gradient_speedup",
                    "design_s", "recording_mb"]
            w.writerow(head)
            for r in result["levels"]:
                for s, f in r["solvers"].items():
                    w.writerow([r["level"], r["nodes"], r["triangles"], r["fibers"], r["dofs"], s]
                               + [f[k]["median"] if f.get(k) else "" for k in TIMINGS]
                               + [f["newton_iterations"]["cold"], f["newton_iterations"]["warm"],
                                  f["cg_iterations"]["cold"], f["cg_iterations"]["warm"], f["peak_memory_mb"],
                                  f.get("stages", ""), f.get("pose_error_rel", ""), f.get("active_length", ""),
                                  f.get("active_fibers", ""), r.get("baseline_gradient_s", {}).get("median", ""),
                                  r.get("gradient_speedup", {}).get(s, ""), f.get("design_s", ""),
                                  f.get("recording_mb", "")])
    plot_bench(out_dir / "bench.png", result, TIMINGS)


def table(result: dict) -> list[str]:
    """The human-readable table of a bench result."""
    rows = [f"{'level':>5} {'DOFs':>6} {'fibers':>6} {'solver':>9} {'eq cold':>8} {'eq warm':>8} {'Newton':>7} "
            f"{'CG it':>9} {'adjoint':>8} {'gradient':>8} {'numpy x':>8} {'forward':>8} {'optimize':>8} "
            f"{'mem MB':>7}"]
    fmt = lambda v: f"{v['median']:.3f}" if v else "-"  # noqa: E731
    speed = lambda r, s: f"{r['gradient_speedup'][s]:.1f}" if s in r.get("gradient_speedup", {}) else "-"  # noqa: E731
    for r in result["levels"]:
        for s, f in r["solvers"].items():
            rows.append(f"{r['level']:>5} {r['dofs']:>6} {r['fibers']:>6} {s:>9} {fmt(f['equilibrium_cold_s']):>8} "
                        f"{fmt(f['equilibrium_warm_s']):>8} "
                        f"{f['newton_iterations']['cold']:>3}/{f['newton_iterations']['warm']:<3} "
                        f"{f['cg_iterations']['cold']:>4}/{f['cg_iterations']['warm']:<4} {fmt(f['adjoint_s']):>8} "
                        f"{fmt(f['gradient_s']):>8} {speed(r, s):>8} {fmt(f.get('forward_sensitivity_s')):>8} "
                        f"{fmt(f.get('optimize_s')):>8} {f['peak_memory_mb']:>7.0f}")
    return rows
