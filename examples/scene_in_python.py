"""Write a scene in Python and design its tendons.

    python examples/scene_in_python.py [--out DIR] [--quick]

The body is a tapered finger, 8 cm long, 2 cm wide at its clamped base and 1 cm
at its tip, with a round hole near the base; the goal lifts its tip by 2 cm. The
scene is the same TOML a file would hold (docs/scenes.md), made here as a
string. Prints the recommended tendon count and its as-built error as a share
of the body size L. ``--quick`` as in design_builtin.py.
"""

import argparse

import numpy as np

import tendon_taichi as tt
from tendon_taichi.apps.design import design
from tendon_taichi.apps.settings import DesignSettings
from tendon_taichi.body.scene import with_overrides
from tendon_taichi.extract.settings import FrontSettings

QUICK = {"stage_iterations": 10, "k_min": 0.4}


def tapered_finger(length=0.08, base=0.02, tip=0.01, hole=0.004, lift=0.02) -> str:
    """The scene as TOML text: lengths in m; ``hole`` the hole's radius, centred
    1.5 cm from the base; ``lift`` how far the goal raises the tip's centre."""
    outline = [[0.0, 0.0], [length, (base - tip) / 2], [length, (base + tip) / 2], [0.0, base]]
    angles = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    circle = np.c_[0.015 + hole * np.cos(angles), base / 2 + hole * np.sin(angles)]
    fmt = lambda pts: "[" + ", ".join(f"[{x:.6g}, {y:.6g}]" for x, y in pts) + "]"  # noqa: E731
    return f"""
name = "tapered_finger"
[body]
outline = {fmt(outline)}
holes = [{fmt(circle)}]
youngs_modulus = 5.0e4
poisson_ratio = 0.45
thickness = 0.01
max_triangle_area = 6.0e-6
[fibers]
spacing = 0.004
[[fixed]]
box = [[-0.0005, -0.0005], [0.0005, {base + 0.0005:g}]]
[[targets]]
point = [{length:g}, {base / 2:g}]
goal = [{length - 0.3 * lift:g}, {base / 2 + lift:g}]
"""


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="designs/tapered_finger")
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)

    scene = tt.parse_scene(tapered_finger(), origin="scene_in_python.py")
    if args.quick:
        scene = with_overrides(scene, QUICK)
    settings = DesignSettings(png=not args.quick, front=FrontSettings(converge=not args.quick))
    d = design(scene, level=1, out=args.out, settings=settings)
    rec = d.summary["recommended"]
    print(f"{scene.name}: {rec['count']} tendon(s), as built "
          f"{100 * rec['metrics']['realizable_pose_error_rel']:.2f}% of L, body size {100 * d.summary['body_size']:.2f} cm")
    return d.summary


if __name__ == "__main__":
    main()
