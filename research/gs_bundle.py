"""Pack an evaluated run folder's folds for a 3D Gaussian splatting check on a GPU machine (research/gs_train.py).

The evaluation trained curate's own radiance field on each subset of each hold-out fold (``RUN/evaluate/fNN_<subset>``,
their ``metrics.json`` records the subset and the held-out views). Does the ranking hold for 3D Gaussian splatting?
This writes, into ``OUT`` (a folder the device machine receives):

* ``images/<name>``: every registered photo, its longer side shrunk to ``--side`` (JPEG, quality 92);
* ``cams.json``: per photo its name, OpenCV camera-to-world and pinhole intrinsics at that size;
* ``points.npz``: the SfM points (``xyz`` [P, 3], ``rgb`` [P, 3] uint8), 3DGS's initial cloud;
* ``folds.json``: per fold, the held-out photo indices and each subset's training indices.

Usage: python -m research.gs_bundle RUN OUT --folds 0 7 --subsets selection random_s0 fvs stride all
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    from PIL import Image
    from curate.sfm.io import image_paths, load_sfm
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--folds", type=int, nargs="+", default=[0, 7])
    ap.add_argument("--subsets", nargs="+", default=["selection", "random_s0", "fvs", "stride", "all"])
    ap.add_argument("--side", type=int, default=270)
    a = ap.parse_args(argv)
    sfm = load_sfm(a.run)
    cams = sfm.cameras
    paths = image_paths(a.run, list(cams.names), sfm.records)
    (a.out / "images").mkdir(parents=True, exist_ok=True)
    f = np.minimum(1.0, a.side / np.maximum(cams.width, cams.height))
    small = cams.scaled_images(f)
    out_cams = []
    for i, (name, p) in enumerate(zip(cams.names, paths)):
        fn = f"{i:04d}.jpg"
        with Image.open(p) as im:
            im.convert("RGB").resize((int(small.width[i]), int(small.height[i])), Image.Resampling.LANCZOS).save(
                a.out / "images" / fn, quality=92)
        out_cams.append({"name": name, "file": fn, "c2w": small.c2w[i].tolist(),
                         "K": [float(small.fx[i]), float(small.fy[i]), float(small.cx[i]), float(small.cy[i])],
                         "w": int(small.width[i]), "h": int(small.height[i])})
    (a.out / "cams.json").write_text(json.dumps(out_cams))
    rgb_file = a.run / "sfm" / "points_rgb.npy"
    rgb = np.load(rgb_file) if rgb_file.is_file() else np.full((len(sfm.points), 3), 128, np.uint8)
    np.savez_compressed(a.out / "points.npz", xyz=np.asarray(sfm.points, np.float32), rgb=np.asarray(rgb, np.uint8))
    index = {n: i for i, n in enumerate(cams.names)}
    folds = {}
    for fo in a.folds:
        fold = {}
        for sub in a.subsets:
            m = a.run / "evaluate" / f"f{fo:02d}_{sub}" / "metrics.json"
            if not m.is_file():
                continue
            rec = json.loads(m.read_text())
            fold[sub] = [int(i) for i in rec["subset"]]
            fold["holdout"] = [index[v["name"]] for v in rec["per_view"]]
            fold[f"field_psnr_{sub}"] = rec["psnr"]
        folds[f"f{fo:02d}"] = fold
    (a.out / "folds.json").write_text(json.dumps(folds))
    print(json.dumps({"photos": len(out_cams), "points": len(sfm.points),
                      "folds": {k: {s: len(v) for s, v in d.items() if isinstance(v, list)}
                                for k, d in folds.items()}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
