"""Does a model's turn between consecutive frames agree with their own matches? (issue 58, found on the way)

For each run folder's kept model (``RUN/sfm/sparse/0``) and each pair of consecutive registered frames (name
order) with at least ``--min-inliers`` verified inliers in ``RUN/sfm/database.db``: the relative rotation estimated
from those inliers alone (pycolmap's ``estimate_relative_pose``, LO-RANSAC, 2 px, seeded) against the model's, in
degrees. A step the model turns far more than its matches say marks a stretch placed wrong (office.mp4's end:
21.4 deg where the truth and the matches say 5.5). Prints one JSON line per run: the percentiles and the largest
disagreements.

    python3 -m research.step_check RUN [RUN ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def step_disagreements(run: Path, min_inliers: int = 30, seed: int = 0) -> list[dict]:
    """One dict per consecutive pair: names, inliers, the model's turn and its disagreement with the matches' (deg)."""
    import pycolmap

    from curate.core.cameras import rotation_angle_deg
    rec = pycolmap.Reconstruction(run / "sfm" / "sparse" / "0")
    by = {im.name: im for im in rec.images.values() if im.has_pose}
    names = sorted(by)
    opt = pycolmap.RANSACOptions()
    opt.max_error, opt.random_seed = 2.0, seed
    out = []
    from research.rundb import database_copy
    with database_copy(run / "sfm" / "database.db") as copy:
        db = pycolmap.Database.open(copy)
        try:
            for na, nb in zip(names, names[1:]):
                a, b = by[na], by[nb]
                if not db.exists_two_view_geometry(a.image_id, b.image_id):
                    continue
                g = db.read_two_view_geometry(a.image_id, b.image_id).inlier_matches
                m = np.zeros((0, 2), int) if g is None else np.asarray(g)
                if len(m) < min_inliers:
                    continue
                k1 = np.asarray(db.read_keypoints(a.image_id))[m[:, 0], :2].astype(np.float64)
                k2 = np.asarray(db.read_keypoints(b.image_id))[m[:, 1], :2].astype(np.float64)
                r = pycolmap.estimate_relative_pose(rec.camera(a.camera_id), k1, rec.camera(b.camera_id), k2, opt)
                if r is None:
                    continue
                Rm = np.asarray((b.cam_from_world() * a.cam_from_world().inverse()).rotation.matrix())
                Re = np.asarray(r["cam2_from_cam1"].rotation.matrix())
                out.append({"a": na, "b": nb, "inliers": int(len(m)),
                            "model_turn_deg": round(rotation_angle_deg(Rm), 2),
                            "disagreement_deg": round(rotation_angle_deg(Re @ Rm.T), 2)})
        finally:
            db.close()
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--min-inliers", type=int, default=30)
    a = ap.parse_args(argv)
    for run in a.runs:
        d = step_disagreements(run, a.min_inliers)
        v = np.array([x["disagreement_deg"] for x in d]) if d else np.zeros(1)
        print(json.dumps({"run": str(run), "pairs": len(d),
                          "p50_p90_p99_max": [round(float(x), 2) for x in np.percentile(v, [50, 90, 99, 100])],
                          "largest": sorted(d, key=lambda x: -x["disagreement_deg"])[:3]}), flush=True)


if __name__ == "__main__":
    main()
