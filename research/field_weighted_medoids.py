"""Does weighting view medoids by where a field renders the pool badly help? (an experiment)

View medoids weigh every pool view by the stretch of path it stands for. A pool view
that is hard to render (fine texture, close surfaces) might deserve more weight, and an
easy one less, so that chosen frames crowd where the field needs them. This tries it on a
harness run folder (``python3 -m research.harness --out DIR ... --extra
medoids_path`` trains ``DIR/<scene>/evaluate/q_medoids_path_b<B>_t0[_o<fold>]``, `auto`'s
subset on a walk, and keeps its field):

1. render every pool view of the fold with that field: the chosen views' training error
   and every other view's leave-out error (MSE) [K];
2. smooth it: each pool view takes the geometric mean MSE of its ``--neighbours`` nearest
   unchosen pool views (view medoids' distance), so a chosen frame gets its stretch's
   difficulty, not its own training error;
3. weights ``path_weight * (smoothed / mean) ** beta``; view medoids with these weights;
4. train that subset with the harness's settings (600 iterations, 160 px, training seed 0)
   into ``q_medfitloo<beta>_b<B>_t0[_o<fold>]`` and pair its held-out PSNR, view by view,
   with `auto`'s.

``beta`` > 0 crowds frames where the field is worst; ``beta`` < 0 where it is best
(PSNR is a log: a view with little error loses more dB for the same added error). Pooled
over the folds, the last line is JSON. Example::

    python research/field_weighted_medoids.py --run .gpudata/quality/office --folds 0,1,2,3 --beta 1
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def error_weights(D: np.ndarray, err: np.ndarray, base: np.ndarray, beta: float, k: int) -> np.ndarray:
    """[K] weights ``base * (e / mean e) ** beta``, ``e`` the geometric mean of ``err`` over each
    view's ``k`` nearest reference views.

    D: [K, U] view distances from each pool view to the U reference views (the unchosen ones);
    err: [U] their MSE (clipped at 1e-12, so a perfect render does not give log 0);
    base: [K] the path weights. beta 0 gives ``base``."""
    if D.shape[1] == 0:
        return np.asarray(base, np.float64).copy()
    k = max(1, min(int(k), D.shape[1]))
    nb = np.argpartition(D, k - 1, axis=1)[:, :k]                  # [K, k] nearest reference views
    e = np.exp(np.log(np.maximum(np.asarray(err, np.float64), 1e-12))[nb].mean(1))   # [K]
    return np.asarray(base, np.float64) * (e / e.mean()) ** beta


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="a harness scene folder with q_medoids_path_* units")
    ap.add_argument("--folds", default="0", help="hold-out folds (every 14th frame), comma list")
    ap.add_argument("--budget", type=int, default=59)
    ap.add_argument("--beta", type=float, default=1.0)
    ap.add_argument("--neighbours", type=int, default=6)
    args = ap.parse_args(argv)

    import torch
    from research.harness import train_key, unit_key       # the harness's unit names and keys
    from curate.evaluate.units import EvalConfig, Unit, eval_cameras, train_unit
    from curate.field.model import RadianceField
    from curate.select.config import MedoidsConfig
    from curate.select.medoids import embed, medoids_select, path_weights, view_depths, view_distance
    from curate.field.metrics import render_image
    from curate.core.run import load_node_grid
    from curate.sfm.io import image_paths, load_sfm
    from curate.select.config import SelectConfig
    from curate.core.stats import holdout_split, paired_difference
    from curate.field.train import default_box, load_image
    from curate.select.visibility import build_pair_index
    torch.set_num_threads(1)
    run, B = Path(args.run), args.budget
    ev = EvalConfig(holdout_every=14, max_side=160, iters=600, workers=1)   # the harness's settings
    sfm = load_sfm(run)
    paths = image_paths(run, list(sfm.cameras.names), sfm.records)
    cams = eval_cameras(sfm.cameras, ev.max_side)
    grid = load_node_grid(run)
    tag = f"medfitloo{args.beta:g}"                 # loo: weights from leave-out errors
    diffs, per_fold = [], []
    for fold in [int(x) for x in args.folds.split(",") if x]:
        pool, hold = (x.tolist() for x in holdout_split(len(sfm.cameras), ev.holdout_every, fold))
        sfx = f"_o{fold}" if fold else ""
        base = run / "evaluate" / unit_key("medoids_path", B, 0, fold)
        auto = json.loads((base / "metrics.json").read_text())
        pc = sfm.cameras[pool]
        idx = build_pair_index(pc, grid.nodes(), SelectConfig().energy.bins)
        c, a = embed(pc, view_depths(pc, grid.nodes(), idx))
        s0 = medoids_select(pc, B, MedoidsConfig(path_weights=True), (), grid.nodes(), idx)[0]
        if sorted(pool[k] for k in s0) != sorted(auto["subset"]):
            raise SystemExit(f"{base}: its subset is not view medoids with path weights on this pool")
        cache = run / "evaluate" / f"loo_err_b{B}{sfx}.npy"             # [K] the field's MSE on every pool view
        t0 = time.perf_counter()
        if cache.is_file():
            err = np.load(cache)
        else:
            fld = RadianceField.load(base / "field.pt")
            err = np.empty(len(pool))
            with torch.no_grad():
                for k, i in enumerate(pool):
                    gt = load_image(paths[i], int(cams.width[i]), int(cams.height[i]))
                    err[k] = float(np.mean((render_image(fld, cams, i).astype(np.float64) - gt) ** 2))
            np.save(cache, err)
        chosen = np.zeros(len(pool), bool)
        chosen[s0] = True
        un = np.flatnonzero(~chosen)
        w = error_weights(view_distance(c, a, np.arange(len(pool)), un), err[un], path_weights(c, a),
                          args.beta, args.neighbours)
        s1 = medoids_select(pc, B, MedoidsConfig(path_weights=True), (), grid.nodes(), idx, weights=w)[0]
        sub = [pool[k] for k in s1]
        key = train_key(ev, sub, hold, [tag])
        m = train_unit(str(run), Unit(unit_key(tag, B, 0, fold), tag, 0, sub), ev, cams, paths, hold,
                       default_box(sfm.cameras), key)
        p0 = np.array([v["psnr"] for v in auto["per_view"]])
        p1 = np.array([v["psnr"] for v in m["per_view"]])
        diffs.append(p1 - p0)
        rec = {"fold": fold, "auto": round(float(p0.mean()), 3), tag: round(float(p1.mean()), 3),
               "frames_changed": len(set(s1) - set(s0)),
               "psnr_unchosen": round(float(np.mean(-10 * np.log10(err[un]))), 2),
               "weight_cv": round(float((w / w.mean()).std()), 3), "seconds": round(time.perf_counter() - t0, 1)}
        per_fold.append(rec)
        print(json.dumps(rec), flush=True)
    d = paired_difference(np.concatenate(diffs), np.zeros(sum(len(x) for x in diffs)))
    print(f"{tag} - auto: {d['mean']:+.2f} dB (95% CI {d['lo']:+.2f} to {d['hi']:+.2f}, {d['n']} views, "
          f"{len(per_fold)} folds)")
    print(json.dumps({"run": str(run), "budget": B, "beta": args.beta, "neighbours": args.neighbours,
                      "folds": per_fold, "paired": {k: (round(v, 3) if isinstance(v, float) else v)
                                                    for k, v in d.items()}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
