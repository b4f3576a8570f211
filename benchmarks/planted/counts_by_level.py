"""Tendon counts of the recommended design per case across resolution levels.

Usage: python benchmarks/planted/counts_by_level.py L1.json L2.json L3.json
(each the planted_bench.json of `tendon-taichi planted-bench --level N`).
Prints a markdown table (count / planted per level, pass per level) and how
many cases keep the same count at every level, and within +-1.
"""

import json
import sys


def table(runs: list[dict]) -> list[str]:
    """The markdown table and its summary lines for planted-bench results ``runs``."""
    levels = [r["level"] for r in runs]
    by = [{c["case"]: c for c in r["cases"]} for r in runs]
    names = sorted(set.intersection(*(set(b) for b in by)))
    out = ["| case | planted | " + " | ".join(f"level {lv}" for lv in levels) + " | same |",
           "|---|---|" + "---|" * len(levels) + "---|"]
    same = close = 0
    for n in names:
        cs = [b[n] for b in by]
        counts = [c.get("count") for c in cs]
        ok = len(set(counts)) == 1
        near = None not in counts and max(counts) - min(counts) <= 1
        same += ok
        close += near
        cells = [f"{c.get('count')}{'' if c.get('passed') else ' (miss)'}" for c in cs]
        out.append(f"| {n} | {cs[0]['planted_count']} | " + " | ".join(cells) + f" | {'yes' if ok else 'no'} |")
    out.append(f"\nsame count at every level: {same} of {len(names)}; within +-1: {close} of {len(names)}")
    for lv, r in zip(levels, runs):
        t = r["totals"]
        out.append(f"level {lv}: passed {t['passed']} of {t['cases']}, count <= planted + 1 in "
                   f"{t['count_within_planted_plus_one']}, time {t['time_s']:.0f} s")
    return out


def main(paths):
    print("\n".join(table([json.load(open(p)) for p in paths])))


if __name__ == "__main__":
    main(sys.argv[1:])
