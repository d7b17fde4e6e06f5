"""What one evaluation training costs, and where its time goes (issue 59, item 1).

For a run folder (SfM, occupancy and selection done), fold ``--fold``'s units are planned as the product plans
them (:func:`curate.evaluate.folds.plan_fold`), and the unit ``--unit`` (selection, random, fvs, stride, all) is
trained and scored on the fold's held-out photos with each variant, as the evaluation's worker does
(:func:`curate.evaluate.units.train_unit`, without writing a unit folder). Variants are ``name:key=value,...``
over :class:`curate.evaluate.config.EvalConfig` (``iters``, ``max_side``) and its ``FieldConfig``
(``field.batch_rays``, ...); the first is the reference. They are run alternately, ``--repeats`` times, in this
one process (one torch thread), so that a shared machine's load falls on all of them alike: the figure that
carries over is each variant's CPU seconds over the reference's in the same repeat.

Printed per run: CPU seconds (``time.process_time``: this process, all threads) of loading, training and
scoring, the mean held-out PSNR; last, one JSON line with every run and each variant's median ratio to the
reference. ``--profile`` prints cProfile's top functions of one training of the first variant instead.

    python -m research.bench.bench_training RUN --unit selection --variants today:,half:field.batch_rays=2048
    python -m research.bench.bench_training RUN --unit all --profile
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def parse_variant(text: str) -> tuple[str, dict]:
    """'half:field.batch_rays=2048,iters=300' -> ('half', {'field.batch_rays': 2048, 'iters': 300})."""
    name, _, rest = text.partition(":")
    sets = {}
    for kv in filter(None, rest.split(",")):
        k, v = kv.split("=")
        try:
            val = json.loads(v)
        except json.JSONDecodeError:
            val = v
        sets[k.strip()] = tuple(val) if isinstance(val, list) else val
    return name, sets


def configured(ev, sets: dict):
    """``ev`` (an EvalConfig) with ``sets`` applied (``field.X`` keys go to its FieldConfig)."""
    fld = {k[6:]: v for k, v in sets.items() if k.startswith("field.")}
    top = {k: v for k, v in sets.items() if not k.startswith("field.")}
    return replace(ev, field=replace(ev.field, **fld), **top)


def plan(run: Path, fold: int):
    """(cams at full size, image paths, the fold, the field's box) of ``run``'s fold ``fold``."""
    from curate.pipeline import saved_config
    from curate.evaluate.folds import fold_order, in_capture_order, plan_fold
    from curate.field.train import default_box
    from curate.core.run import load_node_grid
    from curate.core.run import read_selection
    from curate.sfm.io import image_paths, load_sfm
    cfg, _ = saved_config(run)
    sfm = load_sfm(run)
    cams = sfm.cameras
    grid = load_node_grid(run)
    exported = read_selection(run)["chosen"]
    ordered = in_capture_order(cams, grid.nodes())
    order = fold_order(cfg.evaluate.holdout_every, len(cams))
    f = plan_fold(cfg.evaluate, cfg.select, cams, grid, len(exported), order[fold], ordered, with_all=True)
    return cfg, cams, image_paths(run, list(cams.names), sfm.records), f, default_box(cams)


def train_once(ev, cams, paths, unit, holdout, box, profile: bool = False) -> dict:
    """Train ``unit`` with ``ev`` and score ``holdout`` as the evaluation's worker does; CPU seconds per part."""
    import torch
    from curate.evaluate.units import eval_cameras
    from curate.field.metrics import psnr, render_image, ssim
    from curate.field.train import load_image, train_field
    torch.set_num_threads(max(ev.field.threads, 1))
    ec = eval_cameras(cams, ev.max_side)
    sub = list(unit.subset)
    c0 = time.process_time()
    prof = None
    if profile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    fld, st = train_field(ev.field, ec[sub], [paths[i] for i in sub], None, iters=ev.iters, seed=ev.train_seed,
                          box=box, time_budget_s=ev.time_budget_s)
    c1 = time.process_time()
    test = ec[list(holdout)]
    per = []
    with torch.no_grad():
        for k, i in enumerate(holdout):
            gt = load_image(paths[i], int(test.width[k]), int(test.height[k]))
            pred = render_image(fld, test, k)
            per.append({"name": cams.names[i], "psnr": psnr(pred, gt), "ssim": ssim(pred, gt)})
    c2 = time.process_time()
    if prof is not None:
        prof.disable()
        import pstats
        pstats.Stats(prof).sort_stats("tottime").print_stats(35)
    return {"train_cpu_s": round(c1 - c0, 2), "score_cpu_s": round(c2 - c1, 2), "cpu_s": round(c2 - c0, 2),
            "train_s": round(st.train_seconds, 2), "iters": st.iters, "samples_per_ray": round(st.samples_per_ray, 2),
            "occupancy": st.occupancy,
            "psnr": float(np.mean([p["psnr"] for p in per])), "per_view": [round(p["psnr"], 4) for p in per]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--fold", type=int, default=0, help="the fold's rank in the evaluation's order (0: offset 0)")
    ap.add_argument("--unit", default="selection", help="selection, random, fvs, stride or all")
    ap.add_argument("--variants", default="today:", help="NAME:key=value,...;NAME:... (';'-separated), the "
                    "first the reference")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--profile", action="store_true")
    a = ap.parse_args(argv)
    cfg, cams, paths, fold, box = plan(a.run, a.fold)
    unit = next(u for u in fold.units if u.method == a.unit)
    variants = [parse_variant(v) for v in a.variants.split(";")]
    if a.profile:
        train_once(configured(cfg.evaluate, variants[0][1]), cams, paths, unit, fold.holdout, box, profile=True)
        return 0
    rows = []
    for r in range(a.repeats):
        for name, sets in variants:
            res = train_once(configured(cfg.evaluate, sets), cams, paths, unit, fold.holdout, box)
            rows.append({"repeat": r, "variant": name, "sets": {k: v for k, v in sets.items()}, **res})
            print(f"{a.run.name} {unit.key} ({len(unit.subset)} photos) {name:12s} cpu {res['cpu_s']:7.1f} s "
                  f"(train {res['train_cpu_s']:.1f}, score {res['score_cpu_s']:.1f}) psnr {res['psnr']:.3f} "
                  f"spr {res['samples_per_ray']}", flush=True)
    ref = variants[0][0]
    ratios = {}
    for name, _ in variants:
        rs = [next(x for x in rows if x["repeat"] == r and x["variant"] == ref)["cpu_s"] /
              next(x for x in rows if x["repeat"] == r and x["variant"] == name)["cpu_s"] for r in range(a.repeats)]
        ratios[name] = {"median": float(np.median(rs)), "min": float(np.min(rs)), "max": float(np.max(rs))}
    print(json.dumps({"run": str(a.run), "unit": unit.key, "n_train": len(unit.subset), "holdout": len(fold.holdout),
                      "speedup_vs_ref": ratios, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
