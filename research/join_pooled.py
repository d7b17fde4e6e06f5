"""Tie a part by its pooled evidence, not frame by frame? (issue 52, item 4)

`--mapper auto` keeps a part of COLMAP's global model only where :func:`curate.sfm.parts.join_parts` ties it
to the largest part: 2 of its frames, each posed again from 30 matches to points the kept frames see. On the
rendered office room in two sessions the global model was right within 3.3 deg and its parts were refused, each
frame having 0-3 such matches (docs/investigations/sfm.md#join-rule).
:func:`verify_part` (here: measured, not adopted) pools them: the part, rigid, posed again from all its frames'
matches.

For each run folder (``curate sfm`` done; ``RUN/sfm/database.db``), this maps the matches again with both
mappers (curate's options), takes the parts the global model agrees with (:func:`part_agreement`) and, for each
part after the anchor (the largest), in the order :func:`join_parts` ties them, prints both checks (the frames
that pass :func:`verify_frames`, the pooled check's points, inliers, rotation, step) and, with ``--truth``, the
part's frames' rotation error against the truth once the global model is aligned to it (largest and median),
so a join each check would make is judged. One JSON line per run::

    python -m research.join_pooled /tmp/w/takes_runs/sessions_office \\
        --truth /tmp/w/takes/sessions_office.truth.json [--office ../shared/data/office]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def verify_part(rec, names: list[str], max_rot_deg: float, trusted: set[str]) -> dict:
    """Check where the model ``rec`` put a part (``names``, sound among themselves) against the frames
    ``trusted``, on the part's evidence pooled: the part, held rigid at the model's relative poses, posed
    again as one generalized camera (LO-RANSAC, then refined: pycolmap) from all its frames' matches to
    points that at least two trusted frames see, with those points fixed, must land where the model put it
    (within ``max_rot_deg`` degrees and ``VERIFY_MAX_STEP`` of the scene depth), with at least
    ``VERIFY_MIN_POINTS`` distinct points among its inliers, half of its matches or more, seen from at
    least ``JOIN_MIN_FRAMES`` of its frames (the constants of :mod:`curate.sfm.parts`). Where
    :func:`curate.sfm.parts.verify_frames` asks each frame for 30 matches, this asks the part for 30 points.

    Returns {"ok", "why", "points", "matches", "inliers", "frames", "rot_deg", "step"}."""
    from curate.core.cameras import rotation_angle_deg
    from curate.sfm.native import load as load_pycolmap
    from curate.sfm.parts import JOIN_MIN_FRAMES, VERIFY_MAX_STEP, VERIFY_MIN_POINTS
    pycolmap = load_pycolmap()
    by_name = {im.name: im for im in rec.images.values() if im.has_pose}
    ok_ids = {by_name[m].image_id for m in trusted if m in by_name}
    ims = [by_name[n] for n in names if n in by_name and n not in trusted]
    xy, xyz, cam_idx, pid = [], [], [], []
    for k, im in enumerate(ims):
        for p in im.points2D:
            if p.has_point3D():
                pt = rec.point3D(p.point3D_id)
                if len({e.image_id for e in pt.track.elements} & ok_ids) >= 2:
                    xy.append(p.xy)
                    xyz.append(pt.xyz)
                    cam_idx.append(k)
                    pid.append(p.point3D_id)
    out = {"ok": False, "points": len(set(pid)), "matches": len(xy), "inliers": 0, "frames": len(set(cam_idx)),
           "rot_deg": None, "step": None}
    if out["points"] < VERIFY_MIN_POINTS:
        return {**out, "why": f"{out['points']} points that the frames kept see (< {VERIFY_MIN_POINTS})"}
    xy, xyz = np.asarray(xy, np.float64), np.asarray(xyz, np.float64)
    res = pycolmap.estimate_and_refine_generalized_absolute_pose(
        xy, xyz, cam_idx, [im.cam_from_world() for im in ims], [rec.camera(im.camera_id) for im in ims],
        pycolmap.RANSACOptions(max_error=12.0))      # pixels: COLMAP's default for one camera's pose
    if res is None:
        return {**out, "why": "no pose from its matches"}
    rig = res["rig_from_world"]     # the rig is the model's world: where the model put the part, the identity
    R, t = np.asarray(rig.rotation.matrix()), np.asarray(rig.translation)
    centres = np.stack([np.asarray(im.projection_center()) for im in ims])
    mask = np.asarray(res["inlier_mask"], bool)
    depth = float(np.median(np.linalg.norm(xyz - centres[np.asarray(cam_idx)], axis=1)))
    moved = np.linalg.norm((centres - t) @ R - centres, axis=1)         # each frame's centre: R^T (c - t) - c
    rot, step = float(rotation_angle_deg(R)), float(np.median(moved) / max(depth, 1e-12))
    n_pts, n_frames = len({p for p, m in zip(pid, mask) if m}), len({c for c, m in zip(cam_idx, mask) if m})
    out.update(inliers=int(mask.sum()), rot_deg=round(rot, 2), step=round(step, 4))
    enough = n_pts >= VERIFY_MIN_POINTS and mask.sum() >= len(xy) // 2 and n_frames >= JOIN_MIN_FRAMES
    ok = enough and rot <= max_rot_deg and step <= VERIFY_MAX_STEP
    why = "" if ok else (f"{n_pts} points, {int(mask.sum())} of {len(xy)} matches from {n_frames} frames agree"
                         if not enough else f"its own pose is {rot:.1f} deg and {step:.2f} x depth from the model's")
    return {**out, "ok": ok, "why": why}


def part_errors(best, parts: list[set], run: Path, truth_json: Path | None, office: Path | None) -> list[dict]:
    """Per part (names), the rotation error of its frames in the global model ``best`` after one alignment of
    the whole model to the truth: {"median", "max", "n"}; {} without a truth."""
    if truth_json is None:
        return [{} for _ in parts]
    from curate.sfm.model import cameras_from_reconstruction
    from research.takes import errors_against_truth, truth_of
    recs = [r for r in json.loads((run / "sfm" / "images.json").read_text())["photos"] if r["status"] == "kept"]
    cams = cameras_from_reconstruction(best, warn=False)[0]
    tj = json.loads(truth_json.read_text())
    e = errors_against_truth(cams, recs, tj, office)
    if e is None:
        return [{} for _ in parts]
    have = truth_of(recs, tj)
    with_truth = [n for n in cams.names if n in have]   # the order errors_against_truth keeps
    err = dict(zip(with_truth, e["rotation_deg"]))
    out = []
    for p in parts:
        v = [err[n] for n in p if n in err]
        out.append({"median": round(float(np.median(v)), 2), "max": round(float(np.max(v)), 2), "n": len(v),
                    "without_truth": len(p) - len(v)} if v else {"without_truth": len(p)})
    return out


def measure(run: Path, truth: Path | None, office: Path | None) -> dict:
    from curate.sfm.config import SfmConfig
    from curate.sfm.parts import part_agreement, verify_frames
    from curate.sfm.reconstruction import map_global, map_incremental, model_sizes
    sfm = run / "sfm"
    n = sum(r["status"] == "kept" for r in json.loads((sfm / "images.json").read_text())["photos"])
    cfg = SfmConfig(progress=False)
    with tempfile.TemporaryDirectory() as tmp:
        t = Path(tmp)
        t0 = time.perf_counter()
        inc = map_incremental(cfg, Path(copy_database(sfm / "database.db", t / "i.db")), sfm / "images", t / "inc", n,
                              False)
        glob = map_global(cfg, Path(copy_database(sfm / "database.db", t / "g.db")), sfm / "images", t / "glob")
        seconds = time.perf_counter() - t0
    best = max(glob.values(), key=lambda r: r.num_reg_images())
    placed = {im.name for im in best.images.values() if im.has_pose}
    checks = part_agreement(glob, inc)
    agreed = [names & placed for d, names in checks if d is not None and d <= cfg.max_part_disagreement_deg]
    agreed = [a for a in agreed if a]
    errs = part_errors(best, agreed, run, truth, office)
    rows, keep_f, keep_p = [], set(agreed[0]) if agreed else set(), set(agreed[0]) if agreed else set()
    left = list(range(1, len(agreed)))
    while left:                                  # tie in turn, each check against what it has kept so far
        moved = False
        for k in list(left):
            f = verify_frames(best, sorted(agreed[k]), cfg.max_part_disagreement_deg, trusted=keep_f)
            p = verify_part(best, sorted(agreed[k]), cfg.max_part_disagreement_deg, keep_p)
            frames_ok = sum(v["ok"] for v in f.values()) >= 2
            rows.append({"part": k, "photos": len(agreed[k]), "error": errs[k],
                         "frames_passed": sum(v["ok"] for v in f.values()), "frames_join": frames_ok,
                         "pooled": p})
            if frames_ok:
                keep_f |= agreed[k]
            if p["ok"]:
                keep_p |= agreed[k]
            if frames_ok or p["ok"]:
                left.remove(k)
                moved = True
        if not moved:
            break
    return {"run": str(run), "n": n, "incremental": model_sizes(inc), "global": model_sizes(glob),
            "part_disagreement_deg": [d for d, _ in checks], "anchor": {"photos": len(agreed[0]) if agreed else 0,
                                                                        "error": errs[0] if errs else {}},
            "parts": rows, "kept_by_frames": len(keep_f), "kept_pooled": len(keep_p),
            "seconds": round(seconds, 1)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--truth", type=Path, nargs="*", default=None, help="one <case>.truth.json per run")
    ap.add_argument("--office", type=Path, default=None)
    a = ap.parse_args(argv)
    for i, run in enumerate(a.runs):
        print(json.dumps(measure(run, a.truth[i] if a.truth else None, a.office)), flush=True)


if __name__ == "__main__":
    main()
