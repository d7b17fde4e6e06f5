"""Are a verified pair's matches right? Each inlier match of the pair, lifted to 3D by the office set's true depth in
its first frame and projected into the second by the true poses, against the keypoint it was matched to (pixels).
Pairs of a run's office.mp4 frames, named by truth index. Prints one JSON line per pair.

    python -m research.pair_truth RUN CASE.truth.json --office ../shared/data/office 222,343 100,101
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def pair_truth(db, ids: dict, names: dict, office: Path, ta: int, tb: int) -> dict:
    """``ids``: {working name: image id}; ``names``: {truth index: working name}; office's depth is uint16 mm."""
    from PIL import Image

    from curate.core.cameras import rotation_angle_deg
    poses = np.loadtxt(office / "poses.txt").reshape(-1, 4, 4)
    K = np.loadtxt(office / "K.txt").reshape(3, 3)
    depth = sorted((office / "depth").iterdir())
    ia, ib = ids[names[ta]], ids[names[tb]]
    g = db.read_two_view_geometry(ia, ib)
    m = g.inlier_matches
    pa = np.asarray(db.read_keypoints(ia), float)[m[:, 0], :2]
    pb = np.asarray(db.read_keypoints(ib), float)[m[:, 1], :2]
    D = np.asarray(Image.open(depth[ta]), float) / 1000.0
    h, w = D.shape
    u = np.clip(pa[:, 0].astype(int), 0, w - 1)
    v = np.clip(pa[:, 1].astype(int), 0, h - 1)
    z = D[v, u]
    ray = np.c_[(pa[:, 0] - 0.5 - K[0, 2]) / K[0, 0], (pa[:, 1] - 0.5 - K[1, 2]) / K[1, 1], np.ones(len(pa))]
    X = (ray * z[:, None]) @ poses[ta][:3, :3].T + poses[ta][:3, 3]
    w2c = np.linalg.inv(poses[tb])
    xb = X @ w2c[:3, :3].T + w2c[:3, 3]
    ok = (z > 0) & (xb[:, 2] > 0)
    proj = np.c_[K[0, 0] * xb[:, 0] / xb[:, 2] + K[0, 2], K[1, 1] * xb[:, 1] / xb[:, 2] + K[1, 2]] + 0.5
    err = np.linalg.norm(proj - pb, axis=1)[ok]
    return {"frames": [ta, tb], "config": int(g.config), "inliers": int(len(m)), "with_depth": int(ok.sum()),
            "err_px_median": round(float(np.median(err)), 1) if len(err) else None,
            "within_5px": int((err < 5).sum()), "within_20px": int((err < 20).sum()),
            "truth_turn_deg": round(float(rotation_angle_deg(poses[tb][:3, :3].T @ poses[ta][:3, :3])), 1),
            "truth_distance_m": round(float(np.linalg.norm(poses[ta][:3, 3] - poses[tb][:3, 3])), 2)}


def main(argv=None) -> None:
    import pycolmap

    from research.takes import truth_of
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("pairs", nargs="+", help="A,B: truth indices")
    ap.add_argument("--office", type=Path, required=True)
    a = ap.parse_args(argv)
    recs = [r for r in json.loads((a.run / "sfm/images.json").read_text())["photos"] if r["status"] == "kept"]
    names = {t: n for n, t in truth_of(recs, json.loads(a.truth.read_text())).items()}
    from research.rundb import database_copy
    with database_copy(a.run / "sfm/database.db") as copy, pycolmap.Database.open(copy) as db:
        ids = {im.name: im.image_id for im in db.read_all_images()}
        for p in a.pairs:
            ta, tb = map(int, p.split(","))
            print(json.dumps(pair_truth(db, ids, names, a.office, ta, tb)))


if __name__ == "__main__":
    main()
