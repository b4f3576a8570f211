"""How the search's candidates grow with the extracted count, on over-segmented layouts.

Three strands along a built-in body, each cut into pieces (n pieces in all), are
what an extractor that breaks its strands where the fibers thin out hands the
search. Per n the script counts, without solving anything:

- ``merged``: the routes left after ``merge_pieces`` (what consolidation and the
  front search from);
- ``reductions``: the drops and joins of one round of the greedy consolidation
  and the beam on the n pieces as they are, with each route joined to its
  ``JOIN_PARTNERS`` nearest (``bounded``) and to every other (``every pair``);
- ``pool k=1``: the single routes and joins the front screens for one tendon
  (joins up to the front's gap, 0.5 L, apart).

The front's 2-tendon sets from a pool of n > ``PAIR_POOL`` routes are the pairs
among the ``PAIR_POOL`` the screen ranks best alone and each with the best (n
singles screened, then at most PAIR_POOL (PAIR_POOL - 1) / 2 + n - 1 sets) in
place of every pair (``tests/test_search_cost.py``).

Usage: python benchmarks/search_cost.py [--scene finger] [--counts 3 6 12 24 48] [--json FILE]
"""

import argparse
import json

import numpy as np

from tendon_taichi.body.problem import build_problem
from tendon_taichi.body.scene import load_scene
from tendon_taichi.extract.consolidation import JOIN_PARTNERS, merge_pieces, partner_pairs, smooth_joins
from tendon_taichi.extract.front import JOIN_GAP, PAIR_POOL
from tendon_taichi.extract.routes import fit_route
from tendon_taichi.extract.settings import GAP


def strands(problem, n: int) -> list:
    """Three strands along the body's long axis (at 1/4, 1/2 and 3/4 of its width),
    each cut into n / 3 pieces 4 % of the strand apart, as routes."""
    lo, hi = problem.mesh.nodes.min(axis=0), problem.mesh.nodes.max(axis=0)
    axis = int(np.argmax(hi - lo))
    out = []
    for f in (0.25, 0.5, 0.75):
        across = lo[1 - axis] + f * (hi - lo)[1 - axis]
        edges = np.linspace(lo[axis] + 0.1 * (hi - lo)[axis], hi[axis] - 0.1 * (hi - lo)[axis], n // 3 + 1)
        gap = 0.04 * (edges[-1] - edges[0]) / (n // 3)
        for a, b in zip(edges[:-1], edges[1:]):
            pts = np.zeros((6, 2))
            pts[:, axis] = np.linspace(a + gap / 2, b - gap / 2, 6)
            pts[:, 1 - axis] = across
            if problem.walls.inside(pts).all():
                out.append(fit_route(pts, problem.size, tension=0.3))
    return out


def counts(problem, routes) -> dict:
    c = problem.scene.tendons.clearance * problem.size
    n = len(routes)

    def joins(pairs, gap):
        return sum(len(smooth_joins(routes[i], routes[j], problem, gap * problem.size, c)) for i, j in pairs)

    merged, _ = merge_pieces(routes, np.full((1, n), 0.3), problem, c)
    return {"pieces": n, "merged": len(merged),
            "reductions_bounded": n + joins(partner_pairs(routes), GAP),
            "reductions_every_pair": n + joins(partner_pairs(routes, partners=n), GAP),
            "pool_k1_bounded": n + joins(partner_pairs(routes), JOIN_GAP),
            "pool_k1_every_pair": n + joins(partner_pairs(routes, partners=n), JOIN_GAP)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="finger")
    ap.add_argument("--counts", type=int, nargs="+", default=[3, 6, 12, 24, 48])
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    problem = build_problem(load_scene(args.scene), 1)
    rows = [counts(problem, strands(problem, n)) for n in args.counts]
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(str(r[k]) for k in keys) + " |")
    print(f"(JOIN_PARTNERS {JOIN_PARTNERS}, PAIR_POOL {PAIR_POOL}, scene {args.scene})")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
