"""3D Gaussian splatting on the subsets of a bundle (research/gs_bundle.py), scored on the held-out photos.

Runs on a CUDA machine with gsplat (its ``rasterization`` and ``DefaultStrategy`` densification, as its
``simple_trainer`` uses them): per fold and subset, Gaussians start from the SfM points (scales from the mean
distance to the 3 nearest points, opacity 0.1, colour from the point's), are trained ``--iters`` steps on the
subset's photos (one random photo a step; loss 0.8 L1 + 0.2 (1 - SSIM); spherical harmonics up to degree 3, one
more every 1,000 steps; simple_trainer's learning rates), and rendered at every held-out photo: PSNR per view.
One JSON line per training to ``OUT/results.jsonl``; paired differences per held-out view are computed by
``--summary`` (here or there).

Usage (device): python research/gs_train.py .gs/office .gs/office_mp4 --out $OUT --iters 3000
          (here): python -m research.gs_train --summary OUT/results.jsonl
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np


def ssim(a, b):
    """SSIM of two [1, 3, H, W] images in [0, 1] (11 x 11 Gaussian window, sigma 1.5)."""
    import torch
    import torch.nn.functional as F
    g = torch.exp(-((torch.arange(11, device=a.device) - 5.0) ** 2) / (2 * 1.5 ** 2))
    g = g / g.sum()
    w = (g[:, None] * g[None, :]).expand(3, 1, 11, 11)
    mu_a, mu_b = F.conv2d(a, w, padding=5, groups=3), F.conv2d(b, w, padding=5, groups=3)
    saa = F.conv2d(a * a, w, padding=5, groups=3) - mu_a ** 2
    sbb = F.conv2d(b * b, w, padding=5, groups=3) - mu_b ** 2
    sab = F.conv2d(a * b, w, padding=5, groups=3) - mu_a * mu_b
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    return (((2 * mu_a * mu_b + c1) * (2 * sab + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (saa + sbb + c2))).mean()


def load_bundle(d: Path, device):
    import torch
    from PIL import Image
    cams = json.loads((d / "cams.json").read_text())
    imgs = [torch.from_numpy(np.asarray(Image.open(d / "images" / c["file"]).convert("RGB"), np.float32) / 255.0)
            for c in cams]
    c2w = torch.tensor(np.array([c["c2w"] for c in cams]), dtype=torch.float32, device=device)
    K = torch.zeros(len(cams), 3, 3, device=device)
    for i, c in enumerate(cams):
        fx, fy, cx, cy = c["K"]
        K[i] = torch.tensor([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    pts = np.load(d / "points.npz")
    folds = json.loads((d / "folds.json").read_text())
    return cams, [im.to(device) for im in imgs], c2w, K, pts["xyz"], pts["rgb"], folds


def init_params(xyz: np.ndarray, rgb: np.ndarray, scene_scale: float, device, sh_degree: int = 3):
    import torch
    from gsplat.strategy import DefaultStrategy  # noqa: F401   (imported here to fail early)
    x = torch.tensor(xyz, dtype=torch.float32, device=device)
    n = len(x)
    d2 = []
    for s in range(0, n, 4096):                          # mean distance to the 3 nearest points
        dd = torch.cdist(x[s:s + 4096], x)
        d2.append(dd.topk(4, largest=False).values[:, 1:].mean(1))
    dist = torch.cat(d2).clamp_min(1e-7)
    scales = torch.log(dist)[:, None].repeat(1, 3)
    quats = torch.rand(n, 4, device=device)
    opac = torch.logit(torch.full((n,), 0.1, device=device))
    C0 = 0.28209479177387814
    colors = torch.zeros(n, (sh_degree + 1) ** 2, 3, device=device)
    colors[:, 0, :] = (torch.tensor(rgb, dtype=torch.float32, device=device) / 255.0 - 0.5) / C0
    params = torch.nn.ParameterDict({
        "means": torch.nn.Parameter(x), "scales": torch.nn.Parameter(scales), "quats": torch.nn.Parameter(quats),
        "opacities": torch.nn.Parameter(opac), "sh0": torch.nn.Parameter(colors[:, :1, :].contiguous()),
        "shN": torch.nn.Parameter(colors[:, 1:, :].contiguous())})
    lrs = {"means": 1.6e-4 * scene_scale, "scales": 5e-3, "quats": 1e-3, "opacities": 5e-2, "sh0": 2.5e-3,
           "shN": 2.5e-3 / 20}
    opts = {k: torch.optim.Adam([{"params": params[k], "lr": lr, "name": k}], eps=1e-15) for k, lr in lrs.items()}
    return params, opts


def render(params, viewmat, K, w: int, h: int, sh_degree: int):
    import torch
    from gsplat import rasterization
    colors = torch.cat([params["sh0"], params["shN"]], 1)
    out, alpha, info = rasterization(params["means"], params["quats"], torch.exp(params["scales"]),
                                     torch.sigmoid(params["opacities"]), colors, viewmat[None], K[None], w, h,
                                     sh_degree=sh_degree, packed=False)
    return out[0].clamp(0, 1), info


def train_eval(bundle, train_idx: list[int], test_idx: list[int], iters: int, seed: int = 0) -> dict:
    import torch
    from gsplat.strategy import DefaultStrategy
    cams, imgs, c2w, K, xyz, rgb, _ = bundle
    dev = c2w.device
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    centres = c2w[train_idx, :3, 3]
    scene_scale = float((centres - centres.mean(0)).norm(dim=1).max()) * 1.1 or 1.0
    params, opts = init_params(xyz, rgb, scene_scale, dev)
    strategy = DefaultStrategy(verbose=False)
    strategy.check_sanity(params, opts)
    state = strategy.initialize_state(scene_scale=scene_scale)
    w2c = torch.linalg.inv(c2w)
    t0 = time.perf_counter()
    for step in range(iters):
        i = int(train_idx[rng.integers(len(train_idx))])
        sh = min(step // 1000, 3)
        img, info = render(params, w2c[i], K[i], cams[i]["w"], cams[i]["h"], sh)
        gt = imgs[i]
        strategy.step_pre_backward(params, opts, state, step, info)
        a, b = img.permute(2, 0, 1)[None], gt.permute(2, 0, 1)[None]
        loss = 0.8 * (img - gt).abs().mean() + 0.2 * (1 - ssim(a, b))
        loss.backward()
        strategy.step_post_backward(params, opts, state, step, info, packed=False)
        for o in opts.values():
            o.step()
            o.zero_grad(set_to_none=True)
    torch.cuda.synchronize()
    train_s = time.perf_counter() - t0
    psnr = []
    with torch.no_grad():
        for i in test_idx:
            img, _ = render(params, w2c[i], K[i], cams[i]["w"], cams[i]["h"], 3)
            mse = float(((img - imgs[i]) ** 2).mean())
            psnr.append(-10 * math.log10(max(mse, 1e-10)))
    return {"psnr": float(np.mean(psnr)), "per_view": psnr, "n_gaussians": int(len(params["means"])),
            "train_seconds": train_s}


def run(bundles: list[Path], out: Path, iters: int, subsets: list[str], deadline_s: float = 1e9) -> None:
    import torch
    dev = torch.device("cuda")
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    for d in bundles:
        b = load_bundle(d, dev)
        for fold, f in b[-1].items():
            for sub in subsets:
                if sub not in f:
                    continue
                if time.perf_counter() - t_start > deadline_s:
                    print(json.dumps({"stopped": "deadline", "capture": d.name, "fold": fold, "subset": sub}))
                    return
                row = {"capture": d.name, "fold": fold, "subset": sub, "n_train": len(f[sub]),
                       "holdout": f["holdout"], "field_psnr": f.get(f"field_psnr_{sub}"), "iters": iters}
                try:
                    row.update(train_eval(b, f[sub], f["holdout"], iters))
                except Exception as e:          # one training's failure is a row, the others go on
                    row["error"] = f"{type(e).__name__}: {e}"
                with open(out / "results.jsonl", "a") as fh:
                    fh.write(json.dumps(row) + "\n")
                print(json.dumps({k: v for k, v in row.items() if k not in ("per_view", "holdout")}), flush=True)


def summary(path: Path) -> list[dict]:
    """Per capture, the paired difference of selection against each rival over held-out views of every fold
    (t interval with the folds as clusters: each fold's mean difference is one draw)."""
    from scipy import stats
    rows = [json.loads(l) for l in path.read_text().splitlines() if l.strip()]
    out = []
    for cap in sorted({r["capture"] for r in rows}):
        rr = {(r["fold"], r["subset"]): r for r in rows if r["capture"] == cap and "per_view" in r}
        folds = sorted({f for f, _ in rr})
        for rival in ("random_s0", "fvs", "stride", "all"):
            per_fold = [np.mean(np.subtract(rr[(f, "selection")]["per_view"], rr[(f, rival)]["per_view"]))
                        for f in folds if (f, "selection") in rr and (f, rival) in rr]
            views = [d for f in folds if (f, "selection") in rr and (f, rival) in rr
                     for d in np.subtract(rr[(f, "selection")]["per_view"], rr[(f, rival)]["per_view"])]
            if not views:
                continue
            m, sd, n = float(np.mean(views)), float(np.std(views, ddof=1)), len(views)
            h = float(stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else float("inf")
            out.append({"capture": cap, "rival": rival, "folds": len(per_fold), "views": n, "mean": m,
                        "per_view_ci": [m - h, m + h], "per_fold": per_fold})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", nargs="*", type=Path)
    ap.add_argument("--out", type=Path, default=Path("gs_out"))
    ap.add_argument("--iters", type=int, default=3000)
    ap.add_argument("--subsets", nargs="+", default=["selection", "random_s0", "fvs", "stride", "all"])
    ap.add_argument("--summary", type=Path, default=None)
    ap.add_argument("--deadline-s", type=float, default=1e9, help="start no training after this many seconds")
    a = ap.parse_args(argv)
    if a.summary:
        for r in summary(a.summary):
            print(json.dumps(r))
        return 0
    run(a.bundles, a.out, a.iters, a.subsets, a.deadline_s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
