"""How far the matches agree with a model (issue 58): each verified pair's inlier matches against the model's
relative pose of the two frames.

For a model (a pycolmap Reconstruction) and the database its matches come from: for every verified image pair
with both frames registered, the angle between each inlier match's second ray and the rays the first one can
reach under the model's relative pose (the arc from the baseline's direction to the rotated first ray: exact for
any baseline, pure rotation included), in pixels (times the focal length). A pair agrees when most of its matches
lie within the threshold; a frame is confirmed when most of its pairs' matches (weighted by inliers) do.

    python3 -m research.model_check RUN [--global] [--truth CASE.truth.json]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-15)


def arc_error(r1: np.ndarray, r2: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """[n] angles (radians) from each ray ``r2`` (camera 2) to the rays camera 2 can see of the points on ray
    ``r1`` (camera 1) under x2 = R x1 + t: the arc of directions normalize(d R r1 + t), d > 0."""
    a = _unit(r1 @ R.T)                               # d -> infinity
    tn = float(np.linalg.norm(t))
    if tn < 1e-12:
        return np.arccos(np.clip(np.sum(a * _unit(r2), 1), -1, 1))
    b = np.broadcast_to(t / tn, a.shape)              # d -> 0
    r2 = _unit(r2)
    n = np.cross(b, a)
    nn = np.linalg.norm(n, axis=1)
    ang_a = np.arccos(np.clip(np.sum(r2 * a, 1), -1, 1))
    ang_b = np.arccos(np.clip(np.sum(r2 * b, 1), -1, 1))
    ends = np.minimum(ang_a, ang_b)
    ok = nn > 1e-12
    n = n / np.maximum(nn, 1e-15)[:, None]
    s = np.sum(r2 * n, 1)
    plane = np.arcsin(np.clip(np.abs(s), 0, 1))
    p = _unit(r2 - s[:, None] * n)                    # projection on the plane of the arc
    # inside the arc from b to a (shorter than pi): p between b and a
    inside = (np.sum(np.cross(b, p) * n, 1) >= 0) & (np.sum(np.cross(p, a) * n, 1) >= 0)
    return np.where(ok & inside, plane, ends)


def pair_agreement(db_path: Path, rec, min_inliers: int = 15) -> list[dict]:
    """One dict per verified pair with both frames in ``rec``: names, inliers, median error (px), share within
    4 px."""
    import pycolmap
    db = pycolmap.Database.open(db_path)
    try:
        by_name = {im.name: im for im in rec.images.values() if im.has_pose}
        dbimgs = {im.image_id: im for im in db.read_all_images()}
        kp = {}
        pair_ids, counts = db.read_two_view_geometry_num_inliers()
        out = []
        for pid, c in zip(pair_ids, counts):
            if c < min_inliers:
                continue
            i1, i2 = pycolmap.pair_id_to_image_pair(pid)
            n1, n2 = dbimgs[i1].name, dbimgs[i2].name
            if n1 not in by_name or n2 not in by_name:
                continue
            g = db.read_two_view_geometry(i1, i2)
            m = np.asarray(g.inlier_matches)
            if len(m) < min_inliers:
                continue
            for i in (i1, i2):
                if i not in kp:
                    kp[i] = np.asarray(db.read_keypoints(i))[:, :2]
            a, b = by_name[n1], by_name[n2]
            ca, cb = rec.camera(a.camera_id), rec.camera(b.camera_id)
            x1 = np.asarray(ca.cam_from_img(kp[i1][m[:, 0]]))
            x2 = np.asarray(cb.cam_from_img(kp[i2][m[:, 1]]))
            r1 = np.concatenate([x1, np.ones((len(x1), 1))], 1)
            r2 = np.concatenate([x2, np.ones((len(x2), 1))], 1)
            Ta, Tb = a.cam_from_world(), b.cam_from_world()
            Ra, Rb = np.asarray(Ta.rotation.matrix()), np.asarray(Tb.rotation.matrix())
            R = Rb @ Ra.T
            t = np.asarray(Tb.translation) - R @ np.asarray(Ta.translation)
            err = arc_error(r1, r2, R, t) * float(cb.mean_focal_length())
            out.append({"a": n1, "b": n2, "inliers": int(len(m)), "median_px": float(np.median(err)),
                        "within": float(np.mean(err < 4.0))})
        return out
    finally:
        db.close()


def frame_scores(pairs: list[dict]) -> dict[str, float]:
    """{frame: share of its pairs' inlier matches (all pairs, inlier-weighted) within 4 px}."""
    num: dict = {}
    den: dict = {}
    for p in pairs:
        for n in (p["a"], p["b"]):
            num[n] = num.get(n, 0.0) + p["within"] * p["inliers"]
            den[n] = den.get(n, 0.0) + p["inliers"]
    return {n: num[n] / den[n] for n in num}


def summary(pairs: list[dict]) -> dict:
    fs = frame_scores(pairs)
    w = np.array([p["within"] for p in pairs]) if pairs else np.zeros(0)
    v = np.array(list(fs.values())) if fs else np.zeros(0)
    return {"pairs": len(pairs), "pairs_agreeing": int(np.sum(w >= 0.5)),
            "pairs_disagreeing": int(np.sum(w < 0.5)),
            "inliers_within": round(float(np.sum([p["within"] * p["inliers"] for p in pairs]) /
                                          max(1, sum(p["inliers"] for p in pairs))), 4),
            "frames": len(fs), "frames_confirmed": int(np.sum(v >= 0.5)),
            "frame_score_p10": round(float(np.percentile(v, 10)), 3) if len(v) else None}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--global", dest="glob", action="store_true", help="also map the matches globally and check")
    ap.add_argument("--parts", action="store_true", help="check every incremental part (mapped again)")
    ap.add_argument("--truth", type=Path, default=None)
    ap.add_argument("--office", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/office")
    a = ap.parse_args(argv)
    import pycolmap

    from curate.sfm.config import SfmConfig
    from curate.sfm.model import cameras_from_reconstruction
    from curate.sfm.reconstruction import map_global, map_incremental
    from research.takes import errors_against_truth
    sfm = a.run / "sfm"
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    tj = json.loads(a.truth.read_text()) if a.truth else None
    models = {"kept": pycolmap.Reconstruction(sfm / "sparse" / "0")}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cfg = SfmConfig(progress=False, num_threads=1)
        if a.parts:
            db = tmp / "inc.db"
            copy_database(sfm / "database.db", db)
            for k, r in map_incremental(cfg, db, sfm / "images", tmp / "inc", len(recs), False).items():
                models[f"part{k}"] = r
        if a.glob:
            db = tmp / "g.db"
            copy_database(sfm / "database.db", db)
            g = map_global(cfg, db, sfm / "images", tmp / "g")
            models["global"] = max(g.values(), key=lambda r: r.num_reg_images())
        for name, rec in models.items():
            row = {"model": name, "registered": int(rec.num_reg_images()),
                   **summary(pair_agreement(sfm / "database.db", rec))}
            if tj is not None:
                e = errors_against_truth(cameras_from_reconstruction(rec, warn=False)[0], recs, tj, a.office)
                if e is not None:
                    row.update(rot_median=round(e["rotation_deg_median"], 2),
                               over_5=int(sum(x > 5 for x in e["rotation_deg"])))
            print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
