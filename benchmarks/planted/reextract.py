"""Re-extract a finished planted-bench run with this code's consolidation.

Usage: python benchmarks/planted/reextract.py RUN.json OUT.json [--refine N] [--cases NAME ...]

RUN.json is the planted_bench.json of `tendon-taichi planted-bench`; its cases'
recordings are extracted again (every extractor, consolidation with the default
bounds and ``--refine N`` refinement steps), without optimizing again, and
scored by the bench's own rules (best extractor, pass). OUT.json has the same
shape (``cases``, ``totals``; ``time_s`` is the extraction time), so
counts_by_level.py reads it. Progress goes to stderr.
"""

import argparse
import json
import sys
import time

from tendon_taichi.consolidation import REFINE, ConsolidationSettings
from tendon_taichi.planted_bench import (MAX_EXTRA_TENDONS, MAX_LENGTH_RATIO, MAX_REALIZABLE_POSE_REL,
                                         best_extractor, totals)
from tendon_taichi.tendons import extract


def rescore(case: dict, consolidation: ConsolidationSettings) -> dict:
    """The case with its extractors re-run on its recording and re-scored."""
    t0 = time.perf_counter()
    ex = extract(case["recording"], record=False, consolidation=consolidation)
    per = {}
    for r in ex.results:
        if r.error is not None:
            per[r.name] = {"error": r.error}
            continue
        m = r.metrics
        per[r.name] = {"count": int(m["count"]), "extracted_count": int(m["extracted_count"]),
                       "realizable_pose_error_rel": m["realizable_pose_error_rel"],
                       "steps": [s.action for s in r.consolidation.steps] if r.consolidation else []}
    best = best_extractor(per, case["planted_count"])
    b = per.get(best, {})
    passed = bool(best is not None and b["count"] <= case["planted_count"] + MAX_EXTRA_TENDONS
                  and b["realizable_pose_error_rel"] <= MAX_REALIZABLE_POSE_REL
                  and case["length_ratio"] <= MAX_LENGTH_RATIO)
    return {**case, "extractors": per, "best": best, "count": b.get("count"),
            "extracted_count": b.get("extracted_count"),
            "count_ratio": b["count"] / case["planted_count"] if best else None,
            "realizable_pose_error_rel": b.get("realizable_pose_error_rel"), "passed": passed,
            "time_s": time.perf_counter() - t0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("out")
    ap.add_argument("--refine", type=int, default=REFINE)
    ap.add_argument("--cases", nargs="*")
    args = ap.parse_args(argv)
    src = json.load(open(args.run))
    consolidation = ConsolidationSettings(**{**src.get("consolidation", {}), "refine": args.refine})
    cases = []
    for c in src["cases"]:
        if "error" in c or (args.cases and c["case"] not in args.cases):
            continue
        cases.append(rescore(c, consolidation))
        n = cases[-1]
        print(f"{n['case']}: {n['count']}/{n['planted_count']} tendons ({n['best']}), realizable "
              f"{100 * n['realizable_pose_error_rel']:.2f}%, {'pass' if n['passed'] else 'miss'}, "
              f"{n['time_s']:.0f} s", file=sys.stderr, flush=True)
        out = {**src, "consolidation": {**src.get("consolidation", {}), "refine": args.refine},
               "cases": cases, "totals": totals(cases)}
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
