"""Learning curves of curate's default selection on real captures: held-out PSNR against the budget.

For ``--budget auto`` (issue 34): how much held-out PSNR the default selection loses against
all photos, at several budgets, on the real captures of ``../shared/data`` (the office walk with
its ground-truth poses, office.mp4 through curate's own video + SfM path, the fox, the templering,
the skull), trained with the product's evaluation settings (:class:`curate.evaluate.units.EvalConfig`
defaults unless given). Per capture and hold-out fold: every ``every``-th photo held out (14 for a
walk, 7 for an object capture), the product's default selection at each budget fraction of the photos
left, one field trained per subset and one on all of them, scored on the held-out photos.

Units are run-folder stages (``RUN/evaluate/b<k>_o<fold>``, ``all_o<fold>`` of the capture's run
folder), so a re-run skips finished trainings. Writes ``<out>/<scene>/curve.json`` per capture: for every
trained subset its budget, the pool's spacing rho(k) (:mod:`curate.select.spacing`, the quantity
``--budget auto`` reads), the subset's own spacing and the per-view PSNRs of it and of all photos.
:mod:`research.budget_real_fit` fits and validates the law on them.

Captures: ``office``, ``fox``, ``templering`` import their published or ground-truth poses;
``skull`` and ``office_mp4`` read a run folder of ``curate sfm`` (``--run skull=RUN``).

    python3 -m research.budget_real --scenes office,fox --out /work/runs/breal --workers 2
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

DEFAULT_FRACTIONS = (0.07, 0.12, 0.2, 0.35, 0.55)
"""Budgets as fractions of the photos left after the hold-out (rounded, at least 3)."""
OBJECT_FRACTIONS = DEFAULT_FRACTIONS + (0.75,)
"""An object capture of 40-60 photos needs most of them: its curve goes further."""


def scene_run(scene: str, out: Path, runs: dict[str, Path]):
    """A run folder holding the capture's cameras (RUN/sfm): an import of its poses, or the given
    ``curate sfm`` run folder. Returns its path."""
    from curate.sfm.pose_import import import_poses
    from curate.sfm.config import SfmConfig
    if scene in runs:
        return runs[scene]
    from research.harness import scene_poses
    run = out / scene
    import_poses(SfmConfig(progress=False), scene_poses(scene, out, None), run)
    return run


def measure(scene: str, run: Path, out: Path, ev, fractions, every: int, folds: list[int]) -> dict:
    """Train the default selection at every budget of every fold of ``scene`` (run folder ``run``:
    its RUN/sfm and, after :func:`curate.occupancy.stage.occupancy`, RUN/occupancy) -> the curve record."""
    from curate.config import RunConfig
    from curate.core.stage import read_stage, stage_key
    from curate.core.stats import holdout_split
    from curate.evaluate.units import Unit, eval_cameras, run_units
    from curate.field.train import default_box
    from curate.core.run import load_node_grid
    from curate.occupancy.stage import occupancy
    from curate.select.auto_budget import pool_views
    from curate.select.config import SelectConfig
    from curate.select.methods import capture_kind
    from curate.select.select import select
    from curate.select.spacing import spacing_curve
    from curate.select.visibility import build_pair_index
    from curate.sfm.io import image_paths, load_sfm
    from research.budget_fit import subset_spacing
    work = out / scene
    work.mkdir(parents=True, exist_ok=True)
    cfg = RunConfig(evaluate=ev)
    from curate.core.runfolder import claimed
    with claimed(run):
        occupancy(cfg, run)
        sfm = load_sfm(run)
        cams, N = sfm.cameras, len(sfm.cameras)
        paths = image_paths(run, list(cams.names), sfm.records)
        grid = load_node_grid(run)
        nodes = grid.nodes()
        kind = capture_kind(cams)[0]
        ecams = eval_cameras(cams, ev.max_side)
        box = default_box(cams)
        sfm_key = read_stage(run / "sfm")["key"]
        rec = {"scene": scene, "kind": kind, "n": N, "every": every, "settings": {"max_side": ev.max_side,
                                                                                   "iters": ev.iters},
               "folds": []}
        for fold in folds:
            pool, hold = (v.tolist() for v in holdout_split(N, every, fold))
            pc = cams[pool]
            index = build_pair_index(pc, nodes, SelectConfig().energy.bins)
            c, a, depths = pool_views(pc, nodes, index)
            _, rho = spacing_curve(c, a, depths)
            ks = sorted({max(3, int(round(f * len(pool)))) for f in fractions if round(f * len(pool)) < len(pool)})
            units = []
            for k in ks:
                s = select(pc, grid, k, SelectConfig(), index=index)
                units.append(Unit(f"b{k}_o{fold}", "default", None, [pool[i] for i in s.chosen]))
            units.append(Unit(f"all_o{fold}", "all", None, list(pool)))
            train = replace(ev, workers=0, methods=(), random_seeds=0)
            keys = {u.key: stage_key({"train": train, "subset": u.subset, "holdout": hold}, [sfm_key]) for u in units}
            t = time.perf_counter()
            res = run_units(run, units, keys, ev, ecams, paths, hold, box, progress=True)
            all_pv = [v["psnr"] for v in res[f"all_o{fold}"]["per_view"]]
            rel = {g: i for i, g in enumerate(pool)}
            pts = []
            for u in units[:-1]:
                sub = [rel[g] for g in u.subset]
                pts.append({"k": len(sub), "subset": u.subset, "rho": float(rho[len(sub) - 1]),
                            "rho_sel": subset_spacing(c, a, depths, sub),
                            "psnr": [v["psnr"] for v in res[u.key]["per_view"]]})
            rec["folds"].append({"fold": fold, "pool": pool, "holdout": hold, "curve": rho.tolist(),
                                 "all": all_pv, "points": pts, "seconds": round(time.perf_counter() - t, 1)})
            print(json.dumps({"scene": scene, "fold": fold, "n_pool": len(pool),
                              "all": round(float(np.mean(all_pv)), 3),
                              "loss": {p["k"]: round(float(np.mean(all_pv) - np.mean(p["psnr"])), 3) for p in pts}}),
                  flush=True)
    (work / "curve.json").write_text(json.dumps(rec))
    return rec


def main(argv=None) -> None:
    from curate.evaluate.units import EvalConfig
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="office,fox,templering,skull,office_mp4")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--run", action="append", default=[], help="SCENE=RUN: a curate sfm run folder for SCENE")
    ap.add_argument("--fractions", default=",".join(map(str, DEFAULT_FRACTIONS)), help="a walk's budgets")
    ap.add_argument("--fractions-object", default=",".join(map(str, OBJECT_FRACTIONS)), help="an object's budgets")
    ap.add_argument("--folds-object", default="0", help="hold-out folds of an object capture (every 7th)")
    ap.add_argument("--folds-walk", default="0", help="hold-out folds of a walk (every 14th)")
    ap.add_argument("--iters", type=int, default=EvalConfig().iters)
    ap.add_argument("--max-side", type=int, default=EvalConfig().max_side)
    ap.add_argument("--workers", type=int, default=0)
    args = ap.parse_args(argv)
    runs = {k: Path(v) for k, v in (r.split("=", 1) for r in args.run)}
    ev = EvalConfig(iters=args.iters, max_side=args.max_side, workers=args.workers)
    for scene in [s for s in args.scenes.split(",") if s]:
        run = scene_run(scene, args.out, runs)
        from curate.select.methods import capture_kind
        from curate.sfm.io import load_sfm
        walk = capture_kind(load_sfm(run).cameras)[0] == "walk"
        every = 14 if walk else 7
        folds = [int(x) for x in (args.folds_walk if walk else args.folds_object).split(",") if x]
        fr = [float(x) for x in (args.fractions if walk else args.fractions_object).split(",") if x]
        measure(scene, run, args.out, ev, fr, every, folds)


if __name__ == "__main__":
    main()
