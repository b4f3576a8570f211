"""Design the tendons of a built-in scene, as ``tendon-taichi design SCENE`` does.

    python examples/design_builtin.py [SCENE] [--level N] [--out DIR] [--quick]

Prints the recommended design: its tendon count and its as-built pose error
(with capstan friction, on the next finer mesh) as a share of the body size L,
then one line per tendon. ``--quick`` runs a short homotopy (10 L-BFGS-B
iterations per stage, k down to 0.4 N) and skips the finer mesh's check and the
pictures: a smoke run in seconds, not a design to build.
"""

import argparse

import tendon_taichi as tt
from tendon_taichi.apps.design import design
from tendon_taichi.apps.settings import DesignSettings
from tendon_taichi.body.scene import with_overrides
from tendon_taichi.extract.settings import FrontSettings

#: the short homotopy of ``--quick``: [optimize] settings of the scene replaced
QUICK = {"stage_iterations": 10, "k_min": 0.4}


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="t_shape")
    p.add_argument("--level", type=int, default=1)
    p.add_argument("--out", default=None, help="default designs/<scene>-r<N>")
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)

    scene = tt.load_scene(args.scene)
    if args.quick:
        scene = with_overrides(scene, QUICK)
    settings = DesignSettings(png=not args.quick, front=FrontSettings(converge=not args.quick))
    d = design(scene, level=args.level, out=args.out, settings=settings)
    rec = d.summary["recommended"]
    error = rec["metrics"]["realizable_pose_error_rel"]
    print(f"{scene.name} level {args.level}: {rec['count']} tendon(s), as built {100 * error:.2f}% of L")
    for i, t in enumerate(rec["tendons"], 1):
        print(f"  tendon {i}: {100 * t['length']:.1f} cm, tension {t['tension']:.3f} N, capstan {t['capstan']:.3f}")
    return d.summary


if __name__ == "__main__":
    main()
