import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]

if os.environ.get("PYTEST_XDIST_WORKER"):  # the test processes share the cores (and the CLIs they run)
    os.environ.setdefault("TENDON_TAICHI_FACTOR_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))


def run_cli(*args, cwd=None, timeout=600, env=None):
    """Run ``python -m tendon_taichi ARGS`` as a subprocess; return CompletedProcess."""
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([sys.executable, "-m", "tendon_taichi", *map(str, args)],
                          capture_output=True, text=True, cwd=cwd, timeout=timeout, env=e)


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture(scope="session")
def run_rrd(tmp_path_factory):
    """The recording of a short t_shape optimization (5 stages, sparse at the end),
    shared by the tests that extract from a recording; they read it or copy it."""
    d = tmp_path_factory.mktemp("run")
    r = run_cli("optimize", "t_shape", "--stage-iterations", "25", "--k-min", "0.02", "--record", d / "run.rrd",
                "--quiet", cwd=d)
    assert r.returncode == 0, r.stderr
    return d / "run.rrd"


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def use_cholesky(monkeypatch, name: str):
    """Make the direct backend factorize with ``name`` ("qdldl" or "pardiso", the test
    skipped where MKL is not installed); its class."""
    from tendon_taichi.solve import cholesky, pardiso

    if name == "pardiso" and not pardiso.available():
        pytest.skip("MKL PARDISO is not installed (the mkl extra)")
    monkeypatch.setattr(cholesky, "pardiso_available", lambda: name == "pardiso")
    return pardiso.PardisoLDL if name == "pardiso" else cholesky.LDL


def small_scene_toml(seed: int, extra: str = "") -> str:
    """A random star-shaped polygon body, clamped on its lowest part, with one target."""
    r = np.random.default_rng(seed)
    k = int(r.integers(5, 9))
    ang = np.sort(r.uniform(0, 2 * np.pi, k))
    rad = r.uniform(0.015, 0.03, k)
    pts = np.stack([rad * np.cos(ang), rad * np.sin(ang) + 0.03], axis=1)
    ymin = pts[:, 1].min()
    outline = ", ".join(f"[{p[0]:.6f}, {p[1]:.6f}]" for p in pts)
    cx, cy = pts.mean(axis=0)
    E = float(r.uniform(2e4, 1e5))
    nu = float(r.uniform(0.2, 0.48))
    return f"""
name = "random{seed}"
[body]
outline = [{outline}]
youngs_modulus = {E}
poisson_ratio = {nu}
thickness = 0.01
max_triangle_area = 2.0e-5
{extra}
[fibers]
spacing = 0.006
stiffness = {float(r.uniform(20, 80))}
[[fixed]]
box = [[-1, {ymin - 1e-3}], [1, {ymin + 4e-3}]]
[[targets]]
point = [{cx:.6f}, {cy:.6f}]
goal = [{cx:.6f}, {cy + 0.005:.6f}]
"""


def lattice_path(problem, points):
    """Fiber ids along consecutive lattice points (each pair must be a fiber)."""
    nodes, edges = problem.fibers.nodes, problem.fibers.edges
    ids = []
    for a, b in zip(points[:-1], points[1:]):
        ia = int(np.argmin(np.linalg.norm(nodes - a, axis=1)))
        ib = int(np.argmin(np.linalg.norm(nodes - b, axis=1)))
        k = np.flatnonzero(((edges[:, 0] == ia) & (edges[:, 1] == ib)) | ((edges[:, 0] == ib) & (edges[:, 1] == ia)))
        assert len(k) == 1, (a, b)
        ids.append(int(k[0]))
    return ids


# ------------------------------------------------------------------ planted tendons on t_shape
PLANTED = [
    [(-0.045, 0.065), (-0.04, 0.065), (-0.035, 0.065), (-0.03, 0.065), (-0.025, 0.065), (-0.02, 0.065),
     (-0.015, 0.065), (-0.01, 0.065), (-0.005, 0.06)] + [(-0.005, y) for y in np.arange(0.055, 0.0099, -0.005)],
    [(0.045, 0.075), (0.04, 0.075), (0.035, 0.075), (0.03, 0.075), (0.025, 0.075), (0.02, 0.075), (0.015, 0.075),
     (0.01, 0.075), (0.005, 0.075)],
]


@pytest.fixture(scope="module")
def planted():
    """t_shape with its goals made by two lattice-path tendons at 8 % contraction,
    frictionless (the problem's tendon friction is 0): (problem, fiber ids per
    tendon, the planted equilibrium)."""
    from dataclasses import replace

    from tendon_taichi import Model, NewtonSolver, build_problem, load_scene
    from tendon_taichi.extraction import FiberView, IdealizedState
    from tendon_taichi.extract.realizable import tendon_cables

    base = build_problem(load_scene("t_shape"), 1).with_tendons(friction=0.0)
    paths = [lattice_path(base, [np.array(q) for q in path]) for path in PLANTED]
    view = FiberView(base)
    n = base.fibers.n_fibers
    ones = IdealizedState(np.ones(n), np.zeros(n), base.mesh.nodes, 0.01)
    tendons = [view.tendon(int(np.argmin(np.linalg.norm(base.fibers.nodes - np.array(path[0]), axis=1))), f, ones)
               for path, f in zip(PLANTED, paths)]
    model = Model.from_problem(base, cables=tendon_cables(base, tendons))
    eq = NewtonSolver(model, "direct").solve(ac=0.08 * np.array([t.length for t in tendons]))
    p = replace(base, target_goal=base.target_positions(eq.x))
    return p, paths, eq
