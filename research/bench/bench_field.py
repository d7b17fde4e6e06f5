"""Benchmark the CPU radiance field: PSNR / SSIM on held-out views against training time.

One training run is evaluated at checkpoints along the way (at the first iteration past
each budget; evaluation time is not counted as training time), which is cheaper than one
run per budget and gives the same curve for a deterministic schedule.

    python3 -m research.bench.bench_field --data ../shared/data/fox                 # 1/8 res
    python3 -m research.bench.bench_field --data ../shared/data/office              # 1/4 res
    python3 -m research.bench.bench_field --data ../shared/data/templering --scale 0.5

Every ``--holdout``-th image (indices 0, 14, 28, ... by default) is a test view, the rest
train. The last printed line is one JSON object (``curve``, ``psnr_at_300s``, ...).
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np


from curate.core.cameras import Cameras  # noqa: E402
from curate.field.model import FieldConfig  # noqa: E402
from curate.field.metrics import evaluate  # noqa: E402
from curate.field.train import load_images, train_field  # noqa: E402

DEFAULT_SCALE = {"fox": 1 / 8, "office": 1 / 4, "templering": 1 / 2}


def load_dataset(folder: Path) -> tuple[Cameras, list[str]]:
    """Cameras (full resolution) and image paths of fox / office / templering (or any transforms.json)."""
    from research import datasets
    if (folder / "transforms.json").is_file():
        from curate.core.transforms_json import read_transforms
        return read_transforms(folder / "transforms.json")
    cams = datasets.load_ground_truth(folder)
    if cams is None:
        raise SystemExit(f"{folder}: no poses found (transforms.json, *_par.txt or poses.txt + K.txt)")
    imgdir = datasets.image_folder(folder)
    return cams, [str(imgdir / n) for n in cams.names]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", required=True, type=Path)
    ap.add_argument("--scale", type=float, default=None,
                    help="image scale (default: fox 1/8, office 1/4, templering 1/2)")
    ap.add_argument("--budgets", default="30,60,120,300", help="training seconds at which to evaluate")
    ap.add_argument("--holdout", type=int, default=14, help="every n-th image is a test view")
    ap.add_argument("--out", type=Path, default=None, help="run folder (default runs/bench_field/<data name>)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sh-degree", type=int, default=None)
    ap.add_argument("--sparsity", type=float, default=None, help="FieldConfig.sparsity")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="override any FieldConfig field, e.g. --set prune_thresh=0.01 --set res_schedule=64,96")
    ap.add_argument("--patience", type=int, default=0, help="early-stopping patience (0: train to the last budget)")
    ap.add_argument("--iters", type=int, default=None)
    ap.add_argument("-v", "--verbose", action="store_true")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, format="%(asctime)s %(name)s %(message)s")

    name = a.data.resolve().name
    scale = a.scale if a.scale is not None else DEFAULT_SCALE.get(name, 1 / 4)
    budgets = sorted(float(b) for b in a.budgets.split(","))
    out = a.out or Path("runs/bench_field") / name
    out.mkdir(parents=True, exist_ok=True)

    cams, paths = load_dataset(a.data)
    cams = cams.scaled_images(scale)
    test = np.arange(0, len(cams), a.holdout)
    train = np.setdiff1d(np.arange(len(cams)), test)
    t0 = time.perf_counter()
    test_imgs = load_images([paths[i] for i in test], cams[test])
    cfg = FieldConfig(patience=a.patience)
    for kv in a.set:
        k, v = kv.split("=", 1)
        cur = getattr(cfg, k)
        setattr(cfg, k, tuple(int(x) for x in v.split(",")) if isinstance(cur, tuple) else type(cur)(v))
    if a.sparsity is not None:
        cfg.sparsity = a.sparsity
    if a.sh_degree is not None:
        cfg.sh_degree = a.sh_degree

    curve: list[dict] = []
    pending = list(budgets)

    def cb(it: int, train_s: float, field) -> None:
        while pending and train_s >= pending[0]:
            b = pending.pop(0)
            ev = evaluate(field, cams[test], test_imgs)
            curve.append({"budget_s": b, "train_seconds": round(train_s, 2), "iters": it,
                          "psnr": round(ev["psnr"], 3), "ssim": round(ev["ssim"], 4)})
            print(f"[{name}] {train_s:7.1f}s it {it:6d}  test PSNR {ev['psnr']:.2f}  SSIM {ev['ssim']:.3f}",
                  file=sys.stderr, flush=True)

    field, st = train_field(cfg, cams[train], [paths[i] for i in train], run_dir=out,
                            time_budget_s=budgets[-1], iters=a.iters, seed=a.seed, callback=cb)
    final = evaluate(field, cams[test], test_imgs, out_dir=out / "renders", prefix="test")
    if not curve or curve[-1]["iters"] != st.iters:
        curve.append({"budget_s": None, "train_seconds": round(st.train_seconds, 2), "iters": st.iters,
                      "psnr": round(final["psnr"], 3), "ssim": round(final["ssim"], 4)})
    at300 = [c for c in curve if c["budget_s"] == 300.0]
    res = {
        "data": str(a.data), "scale": scale, "n_train": int(len(train)), "n_test": int(len(test)),
        "image_size": [int(cams.width[0]), int(cams.height[0])],
        "curve": curve,
        "psnr_at_300s": at300[0]["psnr"] if at300 else None,
        "ssim_at_300s": at300[0]["ssim"] if at300 else None,
        "final": {"psnr": round(final["psnr"], 3), "ssim": round(final["ssim"], 4),
                  "per_view_psnr": [round(v["psnr"], 2) for v in final["per_view"]]},
        "train": {"iters": st.iters, "train_seconds": round(st.train_seconds, 1), "rays_per_s": round(st.rays_per_s),
                  "density_samples_per_ray": round(st.samples_per_ray, 1), "stop_reason": st.stop_reason,
                  "occupancy": st.occupancy[-1:] if st.occupancy else None},
        "config": cfg.to_dict(), "wall_seconds": round(time.perf_counter() - t0, 1),
        "note": "one training run evaluated at checkpoints; evaluation time excluded from train_seconds",
        "run_dir": str(out),
    }
    (out / "bench.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res))
    return res


if __name__ == "__main__":
    main()
