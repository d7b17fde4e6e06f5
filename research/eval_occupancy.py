"""Occupancy from the radiance field on the office walk, scored against ground-truth depth.

    python research/eval_occupancy.py --data ../shared/data/office --ckpt runs/bench_field/office/field.pt
    python research/eval_occupancy.py --data ../shared/data/office --budget 300     # trains a field first

Ground truth: the depth maps (uint16 mm, 0 invalid) back-projected with K.txt and poses.txt.
Printed as the last line, one JSON object per occupancy grid (``field`` = the field's own,
``prior`` / ``refined`` when ``--points`` gives SfM points):

* ``depth_recall``: fraction of back-projected depth points inside the box whose voxel
  (nearest node) is occupied; ``depth_recall_1vox`` allows one voxel of slack;
* ``free_violation``: fraction of occupied voxels that lie in front of the observed surface
  (depth < GT depth - 2 voxels) in at least half of the views that see them with valid depth;
  ``free_violation_any``: ... in at least one such view;
* ``occupied_fraction``: occupied voxels / all voxels (what a trivial grid would trade off).
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import numpy as np


from curate.core.cameras import Cameras  # noqa: E402
from research.datasets import image_folder, load_office  # noqa: E402
from curate.field.model import FieldConfig, RadianceField  # noqa: E402
from curate.core.grid import NodeGrid  # noqa: E402
from curate.occupancy.masks import (OccupancyConfig, RefineConfig, dilate, occupancy_from_points,  # noqa: E402
                              refine_occupancy)


def load_depths(folder: Path, cams: Cameras, frames: np.ndarray) -> list[np.ndarray]:
    from PIL import Image
    out = []
    for i in frames:
        name = Path(cams.names[i]).with_suffix(".png").name
        out.append(np.asarray(Image.open(folder / "depth" / name), np.float64) / 1000.0)  # [H, W] metres
    return out


def backproject(cams: Cameras, frames: np.ndarray, depths: list[np.ndarray], step: int = 4) -> np.ndarray:
    """[P, 3] world points of every ``step``-th pixel with valid depth."""
    pts = []
    for k, i in enumerate(frames):
        d = depths[k]
        v, u = np.mgrid[0:d.shape[0]:step, 0:d.shape[1]:step]
        z = d[v, u]
        ok = z > 0
        x = (u[ok] + 0.5 - cams.cx[i]) / cams.fx[i] * z[ok]
        y = (v[ok] + 0.5 - cams.cy[i]) / cams.fy[i] * z[ok]
        pc = np.stack([x, y, z[ok]], 1)
        pts.append(pc @ cams.rotations[i].T + cams.centres[i])
    return np.concatenate(pts)


def score(grid: NodeGrid, gt_pts: np.ndarray, cams: Cameras, frames: np.ndarray, depths: list[np.ndarray]) -> dict:
    r, m = grid.res, grid.mask
    span = grid.box_max - grid.box_min
    vox = float(np.max(span / (r - 1)))
    idx = np.round((gt_pts - grid.box_min) / span * (r - 1)).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < r), axis=1)
    hit = m[tuple(idx[inside].T)]
    hit1 = dilate(m, 1)[tuple(idx[inside].T)]
    occ_nodes = grid.nodes()  # [M, 3]
    seen = np.zeros(len(occ_nodes), np.int64)
    free = np.zeros(len(occ_nodes), np.int64)
    for k, i in enumerate(frames):
        uv, z = cams[int(i)].project(occ_nodes)
        u, v = np.floor(uv[0, :, 0]).astype(np.int64), np.floor(uv[0, :, 1]).astype(np.int64)
        d = depths[k]
        ok = (z[0] > 0) & (u >= 0) & (v >= 0) & (u < d.shape[1]) & (v < d.shape[0])
        gd = np.zeros(len(occ_nodes))
        gd[ok] = d[v[ok], u[ok]]
        ok &= gd > 0
        seen += ok
        free += ok & (z[0] < gd - 2 * vox)
    vis = seen > 0
    return {
        "res": r, "voxel": round(vox, 4), "occupied_voxels": int(m.sum()),
        "occupied_fraction": round(float(m.mean()), 4),
        "gt_points_in_box": round(float(inside.mean()), 4),
        "depth_recall": round(float(hit.mean()), 4), "depth_recall_1vox": round(float(hit1.mean()), 4),
        "occupied_seen_by_depth": int(vis.sum()),
        "free_violation": round(float(np.mean(free[vis] >= 0.5 * seen[vis])) if vis.any() else float("nan"), 4),
        "free_violation_any": round(float(np.mean(free[vis] > 0)) if vis.any() else float("nan"), 4),
    }


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=Path("../shared/data/office"))
    ap.add_argument("--ckpt", type=Path, default=None, help="a trained field (default: train one)")
    ap.add_argument("--budget", type=float, default=300.0, help="training seconds when no --ckpt")
    ap.add_argument("--scale", type=float, default=0.25)
    ap.add_argument("--res", type=int, default=64, help="occupancy grid resolution")
    ap.add_argument("--threshold", type=float, default=0.1, help="opacity across one voxel")
    ap.add_argument("--points", type=Path, default=None, help="SfM points.npy (world frame of poses.txt) for the prior")
    ap.add_argument("--sfm", type=Path, default=None,
                    help="an SfM stage folder (cameras.json + points.npy): its points, aligned to the ground-truth "
                         "poses by a similarity of the matched camera centres, give the prior")
    ap.add_argument("--frame-step", type=int, default=6, help="use every n-th depth map")
    ap.add_argument("--out", type=Path, default=Path("runs/eval_occupancy"))
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    t0 = time.perf_counter()
    cams = load_office(a.data)
    if a.ckpt is not None:
        field = RadianceField.load(a.ckpt)
        trained = {"ckpt": str(a.ckpt)}
    else:
        from curate.field.train import train_field
        small = cams.scaled_images(a.scale)
        imgdir = image_folder(a.data)
        field, st = train_field(FieldConfig(patience=0), small, [str(imgdir / n) for n in cams.names],
                                run_dir=a.out, time_budget_s=a.budget)
        trained = {"train_seconds": round(st.train_seconds, 1), "iters": st.iters, "val": st.val[-1:]}
    frames = np.arange(0, len(cams), a.frame_step)
    depths = load_depths(a.data, cams, frames)
    gt = backproject(cams, frames, depths)
    lo = (field.centre - field.half_size).cpu().numpy()
    hi = (field.centre + field.half_size).cpu().numpy()
    base = NodeGrid(lo, hi, a.res)
    results = {}
    rcfg = RefineConfig(threshold=a.threshold, mode="field")
    field_grid = refine_occupancy(field, base, cfg=rcfg)
    results["field"] = score(field_grid, gt, cams, frames, depths)
    pts = np.load(a.points) if a.points is not None else None
    if a.sfm is not None:
        from research.align import match_names, umeyama
        est = Cameras.load(a.sfm / "cameras.json")
        ie, ig = match_names(est, cams)
        s_, R_, t_ = umeyama(est.centres[ie], cams.centres[ig])
        pts = s_ * np.load(a.sfm / "points.npy").astype(np.float64) @ R_.T + t_
        resid = np.linalg.norm(s_ * est.centres[ie] @ R_.T + t_ - cams.centres[ig], axis=1)
        trained["sfm"] = {"dir": str(a.sfm), "matched_cameras": int(len(ie)), "points": int(len(pts)),
                          "align_median_err": round(float(np.median(resid)), 4)}
    if pts is not None:
        prior = occupancy_from_points(pts, cams, OccupancyConfig(res=a.res), box=(lo, hi))
        results["prior"] = score(prior, gt, cams, frames, depths)
        for mode in ("intersect_dilated", "union"):
            g = refine_occupancy(field, prior, cfg=RefineConfig(threshold=a.threshold, mode=mode))
            results[f"refined_{mode}"] = score(g, gt, cams, frames, depths)
    # context: a grid of the same occupied fraction drawn at random
    rng = np.random.default_rng(0)
    rand = rng.random(base.res ** 3).reshape((base.res,) * 3) < field_grid.mask.mean()
    results["random_same_fraction"] = score(base.with_mask(rand), gt, cams, frames, depths)
    a.out.mkdir(parents=True, exist_ok=True)
    np.save(a.out / "field_occupancy.npy", field_grid.mask)
    res = {"data": str(a.data), "box_min": lo.round(3).tolist(), "box_max": hi.round(3).tolist(),
           "threshold": a.threshold, "depth_frames": int(len(frames)), "gt_points": int(len(gt)),
           "field": trained, "grids": results, "wall_seconds": round(time.perf_counter() - t0, 1)}
    (a.out / "eval_occupancy.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res))
    return res


if __name__ == "__main__":
    main()
