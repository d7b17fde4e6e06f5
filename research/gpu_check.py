"""Both trainers on a GPU: curate's field on CUDA and ``--trainer gsplat``, on two real captures (issue 59, item 4).

A prepared check for a session that is lent a GPU (at most 10 minutes there). Here, on the CPU machine, ``pack``
plans the first ``--folds`` hold-out folds of each run folder exactly as the evaluation plans them
(:func:`curate.evaluate.folds.plan_fold`) and writes what the device needs into one folder (a few MB a capture:
the photos shrunk to ``--side`` px, the cameras at that size, the sparse points, the folds' subsets):

    echo /.gpu/ >> .git/info/exclude
    python -m research.gpu_check pack RUN_office RUN_fox --out .gpu --folds 2 --side 540
    python3 -m pip download --no-deps gsplat==1.5.3 -d .gpu/whl      # gsplat: not on the device image

There (``run`` tool: ``carry: [".gpu"]``), each unit is trained by the evaluation's own worker
(:func:`curate.evaluate.units.train_unit`) with each trainer, one at a time, fold by fold (each fold of every
capture under both trainers before the next fold), and the verdicts are read as the evaluation reads them
(:func:`curate.evaluate.folds.summarize`, one look at 95%, as ``--folds 2`` does):

    python3 -m pip install -q --no-index --no-deps --target /tmp/site .gpu/whl/*.whl && export PYTHONPATH=/tmp/site:.
    export TORCH_CUDA_ARCH_LIST=9.0 TQDM_DISABLE=1 PYTHONUNBUFFERED=1
    python3 research/gpu_check.py run .gpu --out $OUT --splat-steps 2000 --deadline 490

Printed: per capture and trainer, the seconds of each training (median, on the GPU's wall clock), then per
rival the mean difference, interval and decision under each trainer and whether they agree; ``$OUT/gpu_check.json``
holds every training. gsplat compiles its CUDA code at its first use (73-77 s on an H200); ``--deadline``
(seconds) starts no training after it, so the check ends within the device's 10 minutes whatever the machine.
The same ``run`` with ``--trainers field`` here on the CPU trains the same units on the CPU. ``table`` reads a saved
GPU run and, optionally, a CPU run of the same bundles, and prints the per-view agreement (the figures of
docs/evaluation.md#gpu):

    python -m research.gpu_check table docs/evidence/gpu_check_issue59.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):                    # run as a script on the device: the repository root on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def pack(runs: list[Path], out: Path, folds: int, side: int) -> None:
    """Write ``out/<capture>/``: ``bundle.json`` (cameras at ``side``, the scene box, the folds' units),
    ``images/``, ``run/`` (a run folder holding the sparse points, where the units are written)."""
    from PIL import Image
    from curate.pipeline import saved_config
    from curate.evaluate.folds import ALL_FOLDS, fold_order, in_capture_order, plan_fold
    from curate.field.train import default_box, load_image
    from curate.core.run import load_node_grid
    from curate.core.run import read_selection
    from curate.sfm.io import image_paths, load_sfm
    for run in runs:
        cfg, _ = saved_config(run)
        sfm = load_sfm(run)
        cams = sfm.cameras
        grid = load_node_grid(run)
        exported = read_selection(run)["chosen"]
        ordered = in_capture_order(cams, grid.nodes())
        order = fold_order(cfg.evaluate.holdout_every, len(cams))[:folds]
        plan = [plan_fold(cfg.evaluate, cfg.select, cams, grid, len(exported), o, ordered, with_all=i < ALL_FOLDS)
                for i, o in enumerate(order)]
        small = cams.at_most(side)
        d = out / run.name
        (d / "images").mkdir(parents=True, exist_ok=True)
        (d / "run" / "sfm").mkdir(parents=True, exist_ok=True)
        files = []
        for i, p in enumerate(image_paths(run, list(cams.names), sfm.records)):
            fn = f"{i:04d}.jpg"
            img = load_image(p, int(small.width[i]), int(small.height[i]))
            Image.fromarray((img * 255 + 0.5).astype(np.uint8)).save(d / "images" / fn, quality=92)
            files.append(fn)
        np.save(d / "run" / "sfm" / "points.npy", np.asarray(sfm.points, np.float32))
        rgb = run / "sfm" / "points_rgb.npy"
        if rgb.is_file():
            np.save(d / "run" / "sfm" / "points_rgb.npy", np.load(rgb))
        lo, hi = default_box(cams)
        bundle = {"capture": run.name, "side": side, "cameras": small.to_dict(), "files": files,
                  "box": [np.asarray(lo).tolist(), np.asarray(hi).tolist()],
                  "folds": [{"offset": f.offset, "holdout": f.holdout, "pool": f.pool, "budget": f.budget,
                             "method": f.method, "chosen": f.chosen,
                             "units": [{"key": u.key, "method": u.method, "seed": u.seed, "subset": u.subset}
                                       for u in f.units]} for f in plan]}
        (d / "bundle.json").write_text(json.dumps(bundle))
        mb = sum(p.stat().st_size for p in d.rglob("*") if p.is_file()) / 2 ** 20
        print(f"{run.name}: {len(cams)} photos at {side} px, {len(plan)} folds, "
              f"{sum(len(f.units) for f in plan)} units, {mb:.1f} MB -> {d}", flush=True)


def run(root: Path, out: Path, splat_steps: int, deadline: float, trainers: list[str],
        field_iters: int | None = None) -> int:
    """Train every unit of every bundle under ``root`` with each trainer; the verdicts side by side."""
    from dataclasses import replace

    from curate.core.cameras import Cameras
    from curate.core.stats import decision
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.folds import Fold, summarize
    from curate.evaluate.units import Unit, resolved, train_unit
    from curate.field.config import SplatConfig
    import torch
    t_start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    print(f"torch {torch.__version__}, "
          f"{torch.cuda.get_device_name(0) if torch.cuda.is_available() else 'no CUDA device'}", flush=True)
    rows, verdicts = [], []
    jobs = {}                                     # (capture, trainer) -> its bundle, config, run folder, folds, results
    for bdir in sorted(p.parent for p in root.glob("*/bundle.json")):
        b = json.loads((bdir / "bundle.json").read_text())
        for trainer in trainers:
            ev = EvalConfig(trainer=trainer, splat=SplatConfig(steps=splat_steps, max_side=b["side"]))
            ev = resolved(ev if field_iters is None else replace(ev, iters=field_iters))
            _runfolder(bdir / "run", bdir / f"run_{trainer}")
            key = hashlib.sha1(repr(ev.training()).encode()).hexdigest()[:12]  # units reused at this setting only
            jobs[b["capture"], trainer] = {"b": b, "ev": ev, "run": bdir / f"run_{trainer}", "folds": [], "results": {},
                                           "key": key,
                                           "cams": Cameras.from_dict(b["cameras"]),
                                           "paths": [str(bdir / "images" / f) for f in b["files"]],
                                           "box": (np.array(b["box"][0]), np.array(b["box"][1]))}
    # fold-major: each fold of every capture under every trainer before the next fold, so that a deadline
    # leaves both trainers compared on every capture (on fewer folds) rather than one capture compared on all
    n_folds = max(len(j["b"]["folds"]) for j in jobs.values()) if jobs else 0
    for fi in range(n_folds):
        for (cap, trainer), j in jobs.items():
            if fi >= len(j["b"]["folds"]):
                continue
            fd = j["b"]["folds"][fi]
            units = [Unit(u["key"], u["method"], u["seed"], u["subset"], fd["offset"]) for u in fd["units"]]
            fold = Fold(fd["offset"], fd["holdout"], fd["pool"], fd["budget"], fd["method"], fd["chosen"], units)
            for u in units:
                if time.perf_counter() - t_start > deadline:
                    print(f"deadline: {cap} {trainer} {u.key} not trained", flush=True)
                    break
                t0 = time.perf_counter()
                m = train_unit(str(j["run"]), u, j["ev"], j["cams"], j["paths"], fold.holdout, j["box"],
                               f"gpu-check-{trainer}-{j['key']}")
                wall = time.perf_counter() - t0
                j["results"][u.key] = m
                rows.append({"capture": cap, "trainer": trainer, "fold": fd["offset"], "unit": u.key,
                             "n_train": len(u.subset), "wall_s": round(wall, 2), "train_s": m["train_seconds"],
                             "psnr": m["psnr"], "per_view": [v["psnr"] for v in m["per_view"]]})
                print(f"{cap:12s} {trainer:7s} {u.key:18s} {len(u.subset):4d} photos  {wall:6.1f} s  "
                      f"PSNR {m['psnr']:.2f}", flush=True)
            if all(u.key in j["results"] for u in units):
                j["folds"].append(fold)
    for (cap, trainer), j in jobs.items():
        if j["folds"]:
            _, paired, _ = summarize(j["results"], j["folds"], 0.95, 0.3)
            for k, p in paired.items():
                verdicts.append({"capture": cap, "trainer": trainer, "rival": k.split("-", 1)[1],
                                 "folds": len(j["folds"]), "mean": p["mean"], "lo": p["lo"], "hi": p["hi"],
                                 "decision": decision(p, 0.3)})
    print(f"\nseconds per training (median wall, {'GPU' if torch.cuda.is_available() else 'CPU'})")
    for cap in sorted({r["capture"] for r in rows}):
        for tr in trainers:
            s = [r["wall_s"] for r in rows if r["capture"] == cap and r["trainer"] == tr]
            if s:
                print(f"  {cap:12s} {tr:7s} {np.median(s):6.1f} s over {len(s)} trainings")
    print("\nverdicts (selection - rival, dB, 95% interval): field | gsplat | agree")
    agree = []
    for cap in sorted({v["capture"] for v in verdicts}):
        for rival in ("random", "fvs", "stride"):
            vs = {v["trainer"]: v for v in verdicts if v["capture"] == cap and v["rival"] == rival}
            if len(vs) < 2:
                continue
            a, g = vs["field"], vs["gsplat"]
            same = a["decision"] == g["decision"]
            sign = np.sign(a["mean"]) == np.sign(g["mean"])
            agree.append({"capture": cap, "rival": rival, "same_decision": bool(same), "same_sign": bool(sign)})
            print(f"  {cap:12s} {rival:7s} {a['mean']:+.2f} [{a['lo']:+.2f}, {a['hi']:+.2f}] {a['decision']:9s} | "
                  f"{g['mean']:+.2f} [{g['lo']:+.2f}, {g['hi']:+.2f}] {g['decision']:9s} | "
                  f"{'same' if same else 'differ'}{'' if sign else ' (sign differs)'}")
    res = {"rows": rows, "verdicts": verdicts, "agree": agree, "seconds": round(time.perf_counter() - t_start, 1)}
    (out / "gpu_check.json").write_text(json.dumps(res))
    print(json.dumps({k: v for k, v in res.items() if k != "rows"}))
    return 0


def table(evidence: Path) -> int:
    """Per capture, rival and fold: the per-view differences (selection - rival) under gsplat against the GPU's
    field (correlation, same sign), and the GPU's field against the CPU's (largest per-view difference); the
    seconds per training under each."""
    e = json.loads(evidence.read_text())
    gpu, cpu = e["gpu"]["rows"], (e.get("cpu") or {}).get("rows", [])
    by = {(r["capture"], r["trainer"], r["unit"]): r for r in gpu}
    on_cpu = {(r["capture"], r["unit"]): r for r in cpu}
    print("seconds per training: capture, trainer, trainings, median wall s, median training s")
    for src, rows in (("GPU", gpu), ("CPU", cpu)):
        for cap, tr in sorted({(r["capture"], r["trainer"]) for r in rows}):
            w = [r["wall_s"] for r in rows if r["capture"] == cap and r["trainer"] == tr]
            t = [r["train_s"] for r in rows if r["capture"] == cap and r["trainer"] == tr]
            print(f"  {src} {cap:12s} {tr:7s} {len(w):2d}  {np.median(w):6.1f}  {np.median(t):6.1f}")
    if on_cpu:
        d = [np.abs(np.subtract(r["per_view"], by[c, "field", u]["per_view"])).max() for (c, u), r in on_cpu.items()]
        print(f"field, GPU against CPU: {len(d)} trainings, largest per-view PSNR difference {max(d):.4f} dB")
    print("selection - rival, per view: fold, views, field mean, gsplat mean, correlation, same sign")
    for cap in sorted({r["capture"] for r in gpu}):
        for rival in ("random_s0", "fvs", "stride", "all"):
            for fold in sorted({r["unit"].split("_")[0] for r in gpu if r["capture"] == cap}):
                keys = [(cap, tr, f"{fold}_{m}") for tr in ("field", "gsplat") for m in ("selection", rival)]
                if not all(k in by for k in keys):
                    continue
                a, ar, g, gr = (np.asarray(by[k]["per_view"]) for k in keys)
                da, dg = a - ar, g - gr
                r = float(np.corrcoef(da, dg)[0, 1]) if len(da) > 2 and da.std() > 0 and dg.std() > 0 else float("nan")
                print(f"  {cap:12s} {rival:9s} {fold} {len(da):3d}  {da.mean():+6.2f}  {dg.mean():+6.2f}  {r:+5.2f}  "
                      f"{int((np.sign(da) == np.sign(dg)).sum())}/{len(da)}")
    return 0


def _runfolder(src: Path, dst: Path) -> None:
    """A run folder for one trainer's units: the sparse points, and the marker curate writes into a run folder it
    created (so that the units' folders may be written and cleared)."""
    import shutil
    from curate.core.runfolder import claim
    claim(dst)
    shutil.copytree(src / "sfm", dst / "sfm", dirs_exist_ok=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("pack", help="here: plan the folds and pack what the device needs")
    p.add_argument("runs", nargs="+", type=Path)
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--folds", type=int, default=2)
    p.add_argument("--side", type=int, default=540, help="the photos' longer side in the pack (px)")
    r = sub.add_parser("run", help="on the GPU machine: train every unit with each trainer")
    r.add_argument("root", type=Path)
    r.add_argument("--out", type=Path, required=True)
    r.add_argument("--splat-steps", type=int, default=2000)
    r.add_argument("--deadline", type=float, default=480.0, help="seconds after which no training starts")
    r.add_argument("--trainers", default="field,gsplat")
    r.add_argument("--field-iters", type=int, default=None, help="the field's iterations (default: the evaluation's)")
    t = sub.add_parser("table", help="here: the agreement tables from a saved GPU (and CPU) run")
    t.add_argument("evidence", type=Path, help="JSON: {'gpu': gpu_check.json, 'cpu': gpu_check.json of a CPU run}")
    a = ap.parse_args(argv)
    if a.cmd == "table":
        return table(a.evidence)
    if a.cmd == "pack":
        pack(a.runs, a.out, a.folds, a.side)
        return 0
    return run(a.root, a.out, a.splat_steps, a.deadline, a.trainers.split(","), a.field_iters)


if __name__ == "__main__":
    sys.exit(main())
