"""A small sweep from Python: every case a design, as ``tendon-taichi sweep`` runs it.

    python examples/small_sweep.py [SWEEP.toml] [--out DIR] [--workers N]

Runs examples/small_sweep.toml (the finger with two sparsity weights, docs/cli.md
'sweep') and prints one line per case: its settings, its final pose error and
its recommended tendon count, as shares of the body size L. ``--workers 0``
(the default here) runs the cases one after the other in this process; N > 0
on a local Dask cluster of N worker processes. Finished cases are kept in
``--out`` and reused by the next run.
"""

import argparse
from pathlib import Path

from tendon_taichi import sweep

HERE = Path(__file__).resolve().parent


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sweep", nargs="?", default=str(HERE / "small_sweep.toml"))
    p.add_argument("--out", default="recordings/sweeps/small")
    p.add_argument("--workers", type=int, default=0)
    args = p.parse_args(argv)
    result = sweep.run(args.sweep, args.out, workers=args.workers)
    for case in sorted(result["cases"], key=lambda c: str(c["settings"])):
        if "error" in case:
            print(f"{case['case']}: failed: {case['error']}")
            continue
        final, rec = case["optimize"], case["design"]
        print(f"sparsity {case['settings']['sparsity']:g}: pose error {100 * final['pose_error_rel']:.2f}% of L, "
              f"{final['active_fibers']} active fibers, recommended {rec['count']} tendon(s)")
    return result


if __name__ == "__main__":
    main()
