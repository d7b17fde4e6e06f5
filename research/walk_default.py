"""Is the walk default (path spacing) ahead of its rivals on real walks? (issue 48, part 5)

For a run folder (SfM, occupancy done), every hold-out fold of the product's evaluation (each holds out every
``--holdout-every``-th photo from its own offset; all of them: every photo held out once) trains the
product's evaluation field (:class:`curate.evaluate.config.EvalConfig` defaults, or ``--iters``/``--eval-size``)
on the subset each method chooses at the exported share of the photos left (as the product's evaluation
does; ``--share`` another): the candidates (``--methods``: any selection method of
:data:`curate.select.methods.REGISTRY`, and the variants of :data:`VARIANTS`), random subsets and all photos.
The units the product's evaluation trains too (the run's own method, random, fvs, stride, all) keep its
names (``f<offset>_selection``, ...), so that each is trained once for both; the others are
``f<offset>_w_<method>``. Then, per
pair (the first method against each other), the per-photo differences pooled over the folds with the
product's interval (:func:`curate.core.stats.folds_paired`, 95%, one look), the gap closed, and where along
the walk the first method loses: the first and last 5% of the frames (the walk's ends) against the rest.

Usage:
  python -m research.walk_default RUN --share 0.15 --methods path,fvs,stride,medoids,random
Prints a table and one JSON line last.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

VARIANTS: dict = {}
"""Selection variants measured here, beside the product's methods: name -> fn(cams, grid, budget, select_cfg)
-> pool indices."""


def _path_ends(cams, grid, budget, scfg):
    """Path spacing with the walk's first and last frames always chosen (the rest evenly between them)."""
    from curate.select.medoids import embed, view_depths
    from curate.select.path import arc_length, spaced
    from curate.select.visibility import build_pair_index
    index = build_pair_index(cams, grid.nodes(), scfg.energy.bins)
    s = arc_length(*embed(cams, scfg.path.look_scale * view_depths(cams, grid.nodes(), index)))
    if s is None or budget < 3:
        return None
    ends = [0, len(s) - 1]
    return ends + spaced(s, budget - 2, ends)


VARIANTS["path_ends"] = _path_ends


def choose(method: str, cams, grid, budget: int, scfg, seed: int) -> list[int]:
    """Pool indices ``method`` chooses (a product method, a variant, or 'random' with ``seed``)."""
    from curate.select.baselines import random_subset
    from curate.select.select import select
    if method == "random":
        return random_subset(len(cams), budget, seed)
    if method in VARIANTS:
        got = VARIANTS[method](cams, grid, budget, scfg)
        if got is not None:
            return got
        method = "path"
    return select(cams, grid, budget, replace(scfg, method=method)).chosen


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run")
    ap.add_argument("--share", type=float, default=0.0, help="0: the run's exported share")
    ap.add_argument("--methods", default="path,fvs,stride,medoids,random")
    ap.add_argument("--holdout-every", type=int, default=14)
    ap.add_argument("--folds", type=int, default=0, help="0: every fold")
    ap.add_argument("--iters", type=int, default=0, help="0: the evaluation's default")
    ap.add_argument("--eval-size", type=int, default=0, help="0: the evaluation's default")
    a = ap.parse_args(argv)
    from curate.pipeline import saved_config
    from curate.core import runfolder
    from curate.core.stage import current_key, stage_key
    from curate.core.stats import folds_paired, holdout_split
    from curate.evaluate.folds import FOLD_SEED, Fold, eval_budget, fold_order
    from curate.select.methods import resolve_method
    from curate.core.run import read_selection
    from curate.evaluate.schedule import run_folds
    from curate.evaluate.units import Unit, eval_cameras
    from curate.field.train import default_box
    from curate.core.run import load_node_grid
    from curate.sfm.io import image_paths, load_sfm
    run = Path(a.run)
    cfg, _ = saved_config(run)
    ev = replace(cfg.evaluate, holdout_every=a.holdout_every, workers=0,
                 **({"iters": a.iters} if a.iters else {}), **({"max_side": a.eval_size} if a.eval_size else {}))
    sfm = load_sfm(run)
    cams = sfm.cameras
    n = len(cams)
    grid = load_node_grid(run)
    methods = a.methods.split(",")
    order = fold_order(a.holdout_every)[:a.folds or a.holdout_every]
    n_exported = int(round(a.share * n)) if a.share else len(read_selection(run)["chosen"])
    own = resolve_method(cams, cfg.select.method)[0]       # the run's method: its units are the product's
    shared = {own: "selection", "random": "random_s0", "fvs": "fvs", "stride": "stride"}
    sfm_key = current_key(run, "sfm") or ""

    def name(o: int, m: str) -> str:
        return f"f{o:02d}_{shared[m]}" if m in shared and not a.share else f"f{o:02d}_w{n_exported}_{m}"

    def make_fold(o: int) -> Fold:
        pool, hold = (v.tolist() for v in holdout_split(n, a.holdout_every, o))
        k = eval_budget(n_exported, n, len(pool))
        units = [Unit(name(o, m), m, FOLD_SEED * o if m == "random" else None,
                      [pool[i] for i in choose(m, cams[pool], grid, k, cfg.select, FOLD_SEED * o)], o) for m in methods]
        units.append(Unit(f"f{o:02d}_all", "all", None, list(pool), o))      # the evaluation's own 'all' unit
        return Fold(o, hold, pool, k, methods[0], units[0].subset, units)

    def keyed(u, f):
        return stage_key({"train": ev.training(), "subset": u.subset, "holdout": f.holdout}, [sfm_key])
    with runfolder.claimed(run, writes=("evaluate",)):
        folds, res, _ = run_folds(run, ev, make_fold, order, [len(order)], lambda f, r: False,
                                  eval_cameras(cams, ev.max_side), image_paths(run, list(cams.names), sfm.records),
                                  default_box(cams), keyed, False)
    per = {m: {} for m in methods + ["all"]}
    for f in folds:
        for u in f.units:
            for c, v in zip(f.holdout, res[u.key]["per_view"]):
                per[u.method][c] = v["psnr"]
    first = methods[0]
    ends = set(range(0, max(1, n // 20))) | set(range(n - max(1, n // 20), n))
    rows = []
    print(f"\n{run.name}: {n} photos, {len(folds)} folds, {n_exported} exported, fold budget ~{folds[0].budget}, "
          f"{ev.max_side} px x {ev.iters} it")
    print("  " + "  ".join(f"{m} {np.mean(list(per[m].values())):.2f}" for m in per))
    for m in methods[1:] + ["all"]:
        diffs = [np.array([per[first][c] - per[m][c] for c in f.holdout]) for f in folds]
        p = folds_paired(diffs)
        e = [per[first][c] - per[m][c] for c in sorted(per[first]) if c in ends]
        rest = [per[first][c] - per[m][c] for c in sorted(per[first]) if c not in ends]
        print(f"  {first} - {m:10s} {p['mean']:+.2f} dB ({p['lo']:+.2f} to {p['hi']:+.2f}; sd {p['sd']:.2f}, "
              f"{p['n']} photos)  ends {np.mean(e) if e else float('nan'):+.2f} ({len(e)}), "
              f"rest {np.mean(rest):+.2f}")
        rows.append({"pair": f"{first}-{m}", **{k: p[k] for k in ("mean", "lo", "hi", "sd", "n", "n_folds")},
                     "ends": float(np.mean(e)) if e else None, "n_ends": len(e), "rest": float(np.mean(rest))})
    if "random" in per:
        r, al = np.mean(list(per["random"].values())), np.mean(list(per["all"].values()))
        for m in methods:
            if m != "random" and al - r > 1e-6:
                rows.append({"pair": f"gap_closed_{m}", "mean": float((np.mean(list(per[m].values())) - r) / (al - r))})
    print(json.dumps({"run": str(run), "exported": n_exported, "budget": folds[0].budget, "n": n, "folds": len(folds),
                      "iters": ev.iters, "max_side": ev.max_side,
                      "psnr": {m: float(np.mean(list(per[m].values()))) for m in per}, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
