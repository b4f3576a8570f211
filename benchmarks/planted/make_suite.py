"""Regenerate the planted-layout suite listed in suite.toml (beside this file).

Usage: python benchmarks/planted/make_suite.py [--out DIR] [--only NAME ...] [--no-gallery]
Writes, per case, <scene>_planted_<n>t_s<seed>[_<p>p].toml and .json (exactly
what `tendon-taichi planted SCENE --tendons N --seed S --level L [--poses P]
--out benchmarks/planted` writes), README.md (the table of cases and the
commands) and gallery.png (every layout on its planted equilibrium, pose 0)
into DIR (default: this folder). ``--only`` makes only the named cases (and
no README). The README and the gallery record the commit that made them.
"""

import argparse
import tomllib
from pathlib import Path

from tendon_taichi import load_scene, parse_scene
from tendon_taichi.planted.gallery import plot_layouts
from tendon_taichi.planted.plant import plant, write_planted
from tendon_taichi.planted.walk import PlantSettings
from tendon_taichi.version import provenance

HERE = Path(__file__).resolve().parent

README = """# Planted-layout suite

Scenes whose goals a known set of tendons reaches exactly: each case draws
random smooth tendons in a built-in scene's body, contracts them by 5-10 %,
solves the body with only those tendons (sliding cables, level {level}) and
writes where the targets went as the goals. `<case>.toml` is the scene (it
loads with `tendon-taichi optimize <case>.toml`), `<case>.json` the planted
layout (per tendon: rest waypoints in m, anchor first; length; contraction;
tension at the planted equilibrium). `gallery.png` shows every case: rest
outline grey, planted equilibrium black, tendons in colour (dot: anchor),
targets blue, goals green. A case with `poses = 2` has two target poses made by
the same tendons (in the second, a random subset of them contracts and the
others are paid out); its gallery panel shows the first pose.

| case | scene | tendons | poses | seed | planted length (cm) | max target displacement (% of L) |
|---|---|---|---|---|---|---|
{rows}

Two scripts work on a finished `tendon-taichi planted-bench` run of this suite:
`benchmarks/planted/reextract.py` designs again from its cases' recordings with this code
(extraction, consolidation and the front, without optimizing again) and scores the designs by the
bench's rules; `benchmarks/planted/counts_by_level.py` tables each case's recommended count across
resolution levels from the runs' `planted_bench.json` files.

Regenerate everything (files, this README, the gallery):

```bash
python benchmarks/planted/make_suite.py
```

or one case:

```bash
{commands}
```

Made by `python benchmarks/planted/make_suite.py` at commit {commit}.
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--only", nargs="+", metavar="NAME", help="make only these cases")
    ap.add_argument("--no-gallery", action="store_true")
    args = ap.parse_args()
    suite = tomllib.loads((HERE / "suite.toml").read_text())
    level = suite["level"]
    exit = suite.get("exit", "clamp")
    rows, commands, cases = [], [], []
    for case in suite["cases"]:
        scene = load_scene(case["scene"])
        poses = case.get("poses", 1)
        name = f"{case['scene']}_planted_{case['tendons']}t_s{case['seed']}" + (f"_{poses}p" if poses > 1 else "")
        if args.only and name not in args.only:
            continue
        text, layout = plant(scene, case["tendons"], case["seed"], level, poses=poses,
                             settings=PlantSettings(exit=exit))
        toml_path, _ = write_planted(args.out, text, layout)
        cases.append((parse_scene(text, origin=str(toml_path)), layout))
        rows.append(f"| {layout['name']} | {case['scene']} | {case['tendons']} | {poses} | {case['seed']} | "
                    f"{100 * layout['planted_length']:.1f} | "
                    f"{100 * layout['pose']['max_target_displacement_rel']:.1f} |")
        commands.append(f"tendon-taichi planted {case['scene']} --tendons {case['tendons']} "
                        f"--seed {case['seed']} --level {level}" + (f" --poses {poses}" if poses > 1 else "")
                        + (f" --exit {exit}" if exit != "clamp" else "") + " --out benchmarks/planted")
        print(rows[-1], flush=True)
    if args.only:
        return
    (args.out / "README.md").write_text(README.format(level=level, rows="\n".join(rows), commands="\n".join(commands),
                                                      commit=provenance()["commit"]))
    if not args.no_gallery:
        plot_layouts(args.out / "gallery.png", cases, columns=5, dpi=80)


if __name__ == "__main__":
    main()
