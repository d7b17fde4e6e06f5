"""Do the selections avoid the frames next to the held-out ones? (a bias of the hold-out protocol)

Holding out every n-th frame of a video leaves a hole in the pool at each held-out frame,
and the test is exactly in those holes. A selection that centres its frames on where the
pool is dense (view medoids) may drift away from the holes; one blind to the pool's
density (every n-th frame) does not. For each hold-out fold of a harness run folder
(``python3 -m research.harness --out DIR`` writes ``DIR/<scene>``), this prints, per
method:

* ``adjacent``: the share of chosen frames whose neighbour in capture order is held out
  (cameras sorted by name, as curate stores them: frame numbers in capture order), and
  ``adjacent_pool``: the same share over the whole pool (what an unbiased choice gives);
* ``view``: the mean view-medoids distance from a held-out view to its nearest chosen view;
* the capture-order share of the whole sequence (:func:`curate.select.medoids.path_order_share`).

Besides the methods and the harness's variants, ``medoids_path_full`` is a diagnostic (it
sees the held-out frames, so it is no method): view medoids weighted by the path weights
of the *whole* sequence, held-out frames included, so the holes give the frames beside
them no extra weight. Against ``medoids_path`` it tells how much of what the path weights
change comes from the holes.

The last line is JSON. Example::

    python research/holdout_holes.py --run .gpudata/quality/office --budget 17%
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def beside_holes(pool: np.ndarray, hold: np.ndarray) -> np.ndarray:
    """[len(pool)] bool: pool frame (an index in capture order) has a held-out frame next to it."""
    return np.isin(pool, np.r_[hold - 1, hold + 1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="a harness run folder (with sfm/ and occupancy/)")
    ap.add_argument("--every", type=int, default=14, help="hold out every n-th frame (default 14)")
    ap.add_argument("--budget", default="17%", help="frames to choose: a count or a share of the pool")
    ap.add_argument("--folds", default="all", help="hold-out offsets: comma list or 'all'")
    ap.add_argument("--methods", default="medoids,stride,fvs,random",
                    help="comma list of methods or the harness's variants (e.g. medoids_path)")
    args = ap.parse_args(argv)

    from curate.core.budget import parse_budget, resolve_budget
    from curate.select.medoids import (PATH_ORDER_MIN, MedoidsConfig, embed, medoids_select, path_order_share,
                                path_weights, view_depths, view_distance)
    from curate.core.run import load_node_grid
    from curate.sfm.io import load_sfm
    from curate.select.config import SelectConfig
    from curate.select.select import select
    from curate.core.stats import holdout_split
    from curate.select.visibility import build_pair_index

    from research.harness import _variants                  # the harness's named variants
    variants = _variants()
    run = Path(args.run)
    sfm = load_sfm(run)
    cams = sfm.cameras
    grid = load_node_grid(run)
    bins = SelectConfig().energy.bins                                # every method and variant here uses these
    c, a = embed(cams, view_depths(cams, grid.nodes(), build_pair_index(cams, grid.nodes(), bins)))
    w_all = path_weights(c, a) if "medoids_path_full" in args.methods.split(",") else None   # [K]
    folds = range(args.every) if args.folds == "all" else [int(x) for x in args.folds.split(",") if x]
    methods = [m for m in args.methods.split(",") if m]
    per: dict[str, dict[str, list]] = {m: {"adjacent": [], "adjacent_pool": [], "view": []} for m in methods}
    for f in folds:
        pool, hold = holdout_split(len(cams), args.every, f)
        B = resolve_budget(parse_budget(args.budget), len(pool))
        near_hole = beside_holes(pool, hold)                        # [pool]
        vd = view_distance(c, a, hold, pool)                         # [H, pool]
        pc = cams[pool.tolist()]
        idx = build_pair_index(pc, grid.nodes(), bins)              # once per fold, for every method
        for m in methods:
            if m == "medoids_path_full":                            # a diagnostic, not a method: the
                if w_all is None:                                   # weights of the whole sequence, so the
                    raise SystemExit(f"{run}: the cameras are not in capture order: no medoids_path_full")
                chosen = np.asarray(medoids_select(pc, B, MedoidsConfig(), (), grid.nodes(), idx,   # held-out
                                                   weights=w_all[pool])[0], int)                  # frames leave no hole
            else:
                cfg = variants[m] if m in variants else SelectConfig(m)
                assert cfg.energy.bins == bins
                chosen = np.asarray(select(pc, grid, B, cfg, index=idx).chosen, int)
            per[m]["adjacent"].append(float(near_hole[chosen].mean()))
            per[m]["adjacent_pool"].append(float(near_hole.mean()))
            per[m]["view"].append(float(vd[:, chosen].min(1).mean()))
    share = path_order_share(c, a)                                   # the whole sequence, in name order
    print(f"{run.name}: budget {args.budget}, folds {list(folds)}; capture-order share {share:.3f} "
          f"(path weights need >= {PATH_ORDER_MIN})")
    print(f"{'method':10s} {'adjacent':>9s} {'(pool)':>7s} {'view':>7s}   per fold: adjacent")
    out = {}
    for m, v in per.items():
        out[m] = {k: round(float(np.mean(x)), 4) for k, x in v.items()}
        out[m]["adjacent_per_fold"] = [round(x, 3) for x in v["adjacent"]]
        print(f"{m:10s} {out[m]['adjacent']:9.3f} {out[m]['adjacent_pool']:7.3f} {out[m]['view']:7.3f}   "
              + " ".join(f"{x:.2f}" for x in v["adjacent"]))
    print(json.dumps({"run": str(run), "budget": args.budget, "every": args.every, "folds": list(folds),
                      "order_share": round(share, 4), "methods": out}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
