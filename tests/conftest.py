import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
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


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


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
