"""Design again from a finished planted-bench run's recordings, with this code.

Usage: python benchmarks/planted/reextract.py RUN.json OUT.json [--refine N] [--screen N] [--budget F]
       [--cases NAME ...] [--bench-dir DIR]

RUN.json is the planted_bench.json of `tendon-taichi planted-bench`; its cases'
recordings are extracted again (every extractor, consolidation and route
optimization with the run's settings, or ``--budget F`` as the pose budget,
``--refine N`` rounds of route optimization and ``--screen N``), and the
design is recommended again (the count/error front searched with the run's
``beam`` and ``converge``), without optimizing again, and scored by the
bench's own rules. OUT.json has the same shape (``cases``, ``totals``;
``time_s`` is the extraction time), so counts_by_level.py reads it.
``--bench-dir DIR`` also writes the result as a planted-bench run
(planted_bench.json, .csv, gallery.png), each case's ``time_s`` its recorded
optimize time plus the new extraction time (``extract_s``): what
`tendon-taichi planted-bench` would give with this code, as the optimizer's
output does not change. Nothing is written into the recordings. Progress goes
to stderr.
"""

import argparse
import json
import sys
import time
from pathlib import Path

from tendon_taichi.apps.design import recommended
from tendon_taichi.apps.settings import DesignSettings
from tendon_taichi.extract.settings import FRONT_DEFAULTS, REFINE, SCREEN, ConsolidationSettings, FrontSettings
from tendon_taichi.planted.bench import load_suite, score_design, totals, write_outputs


def rescore(case: dict, consolidation: ConsolidationSettings, front: dict | None = None) -> dict:
    """The case designed again from its recording (``front``: the front's ``beam``
    and ``converge``) and scored again."""
    t0 = time.perf_counter()
    settings = DesignSettings(consolidation=consolidation, budget=consolidation.budget or 0.005,
                              front=FrontSettings(**{**FRONT_DEFAULTS, **(front or {})}))
    _, _, summary = recommended(case["recording"], settings)
    figures = score_design(summary, case["planted_count"], case["length_ratio"])
    return {**case, **figures, "time_s": time.perf_counter() - t0}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("out")
    ap.add_argument("--refine", type=int, default=REFINE)
    ap.add_argument("--screen", type=int, default=SCREEN)
    ap.add_argument("--budget", type=float, help="consolidation's pose budget (fraction of L; default: the run's)")
    ap.add_argument("--cases", nargs="*")
    ap.add_argument("--bench-dir", type=Path)
    args = ap.parse_args(argv)
    src = json.load(open(args.run))
    chosen = {**src.get("consolidation", {}), "refine": args.refine, "screen": args.screen}
    if args.budget is not None:
        chosen["budget"] = args.budget
    consolidation = ConsolidationSettings(**chosen)
    cases = []
    for c in src["cases"]:
        if "error" in c or (args.cases and c["case"] not in args.cases):
            continue
        cases.append(rescore(c, consolidation, src.get("front_search")))
        n = cases[-1]
        print(f"{n['case']}: {n['count']}/{n['planted_count']} tendons ({n['best']}), as built "
              f"{100 * n['realizable_pose_error_rel']:.2f}%, capstan {n['capstan_worst']:.2f} (planted "
              f"{n['planted_capstan_worst']:.2f}), {'pass' if n['passed'] else 'miss'}, {n['time_s']:.0f} s",
              file=sys.stderr, flush=True)
        out = {**src, "consolidation": chosen,
               "cases": cases, "totals": totals(cases)}
        with open(args.out, "w") as f:
            json.dump(out, f, indent=1)
    if args.bench_dir and cases:
        write_bench(out, args.bench_dir, Path(src["suite"]))


def write_bench(result: dict, out_dir: Path, suite: Path) -> None:
    """``result`` written out as a planted-bench run in ``out_dir`` (module docstring)."""
    cases = [{**c, "extract_s": c["time_s"], "time_s": c.get("optimize_s", 0.0) + c["time_s"]}
             for c in result["cases"]]
    out_dir.mkdir(parents=True, exist_ok=True)
    write_outputs({**result, "cases": cases, "totals": totals(cases)}, out_dir, load_suite(suite))


if __name__ == "__main__":
    main()
