"""The parts of a split capture: which models to report, and how far a global model may be trusted against
the incremental parts (its orientation against each part's, each unconfirmed frame's pose against its own PnP).
"""

from __future__ import annotations

import numpy as np

from curate.core.cameras import Cameras, rotation_angle_deg
from curate.sfm.model import cameras_from_reconstruction
from curate.sfm.native import load as load_pycolmap


def without_contained(models: dict) -> dict:
    """``models`` ({id: Reconstruction}) without those whose registered photos all lie in the largest
    model: COLMAP keeps a first model that stopped at a few photos when the next one grows past it, and
    such a part loses nothing, so it must not be reported as a split (the 3,000-frame walk: models of
    2,998 and 3 photos, every photo in the first)."""
    if len(models) < 2:
        return models
    best = max(models, key=lambda k: models[k].num_reg_images())
    names = lambda r: {r.image(i).name for i in r.reg_image_ids()}  # noqa: E731
    inside = names(models[best])
    return {k: r for k, r in models.items() if k == best or not names(r) <= inside}


JOIN_MIN_FRAMES = 2
""":func:`join_parts`: the fewest frames of a part that must pass :func:`verify_frames` against the frames
already kept for the part to join them. Two frames apart fix where a rigid part sits, its scale included."""


def join_parts(rec, parts: list[set], max_rot_deg: float) -> tuple[set, list[dict]]:
    """The frames of ``rec`` (the global model) that one tied-together whole of ``parts`` covers.

    ``parts``: names of incremental parts the global model agrees with, largest first. Agreeing
    with a part says its frames sit right *among themselves*; where the global model put the part
    against the others rests on the matches between them, and a seam of a few points can place it
    wrong (a rendered walk filmed in two takes: the 15-frame start of the second take tied to the
    rest by 22 points, none of its frames passing the check below; here the global model
    put it right, on a CI machine a quarter of the walk off, the model 37 deg off the walk after
    alignment, every part still agreeing). So the largest part anchors the model, and each other
    part joins once :data:`JOIN_MIN_FRAMES` of its frames pass :func:`verify_frames` on the points
    the frames already joined see (repeated until no part joins).

    Returns (names kept, [{"photos", "frames_passed", "joined"} per part after the first]).
    """
    if not parts:
        return set(), []
    keep, left = set(parts[0]), list(range(1, len(parts)))
    passed = {k: 0 for k in left}
    while left:
        joined = []
        for k in left:
            v = verify_frames(rec, sorted(parts[k]), max_rot_deg, trusted=keep)
            passed[k] = sum(x["ok"] for x in v.values())
            if passed[k] >= JOIN_MIN_FRAMES:
                joined.append(k)
        if not joined:
            break
        for k in joined:
            keep |= parts[k]
        left = [k for k in left if k not in joined]
    return keep, [{"photos": len(parts[k]), "frames_passed": passed[k], "joined": k not in left}
                  for k in range(1, len(parts))]


VERIFY_MIN_POINTS = 30
""":func:`verify_frames`: the fewest 2D-3D matches to points the other frames see, and the fewest PnP inliers."""
VERIFY_MAX_STEP = 0.05
""":func:`verify_frames`: the largest distance between a frame's own pose and the model's, as a fraction
of the median depth of the points it sees."""


def verify_frames(rec, names: list[str], max_rot_deg: float, trusted: set[str] | None = None
                  ) -> dict[str, dict]:
    """Check frames of the model ``rec`` that no mapper part confirms, each by its own evidence: its
    pose estimated again (PnP with LO-RANSAC, then refined: pycolmap) from its matches to the 3D points
    the *other* frames see (tracks of at least two other frames), with the model held fixed, must agree
    with the pose the model gives it: within ``max_rot_deg`` degrees and :data:`VERIFY_MAX_STEP` of its
    scene depth, with at least :data:`VERIFY_MIN_POINTS` inliers, half of its matches or more.

    ``trusted`` (names): only these frames count as "other" frames (default: every other frame), so a
    frame, or a part it belongs to, cannot vouch for itself (:func:`join_parts`).

    Returns {name: {"ok", "why", "inliers", "rot_deg", "step"}}."""
    pycolmap = load_pycolmap()
    by_name = {im.name: im for im in rec.images.values() if im.has_pose}
    ok_ids = None if trusted is None else {by_name[m].image_id for m in trusted if m in by_name}
    out: dict[str, dict] = {}
    for n in names:
        im = by_name.get(n)
        if im is None:
            continue
        xy, xyz = [], []
        for p in im.points2D:
            if not p.has_point3D():
                continue
            pt = rec.point3D(p.point3D_id)
            others = {e.image_id for e in pt.track.elements} - {im.image_id}
            if len(others if ok_ids is None else others & ok_ids) >= 2:
                xy.append(p.xy)
                xyz.append(pt.xyz)
        if len(xy) < VERIFY_MIN_POINTS:
            out[n] = {"ok": False, "why": f"{len(xy)} matches to points other frames see (< {VERIFY_MIN_POINTS})",
                      "inliers": 0, "rot_deg": None, "step": None}
            continue
        xy, xyz = np.asarray(xy, np.float64), np.asarray(xyz, np.float64)
        res = pycolmap.estimate_and_refine_absolute_pose(xy, xyz, rec.camera(im.camera_id))
        if res is None:
            out[n] = {"ok": False, "why": "no pose from its matches", "inliers": 0, "rot_deg": None, "step": None}
            continue
        mine, model = res["cam_from_world"], im.cam_from_world()
        Rm, Rg = np.asarray(mine.rotation.matrix()), np.asarray(model.rotation.matrix())
        rot = float(rotation_angle_deg(Rm @ Rg.T))                                   # same world frame
        cm, cg = -Rm.T @ np.asarray(mine.translation), -Rg.T @ np.asarray(model.translation)
        depth = float(np.median(np.linalg.norm(xyz - cg, axis=1)))
        step = float(np.linalg.norm(cm - cg) / max(depth, 1e-12))
        inl = int(res["num_inliers"])
        ok = inl >= max(VERIFY_MIN_POINTS, len(xy) // 2) and rot <= max_rot_deg and step <= VERIFY_MAX_STEP
        why = "" if ok else (f"{inl} of {len(xy)} matches agree" if inl < max(VERIFY_MIN_POINTS, len(xy) // 2) else
                             f"its own pose is {rot:.1f} deg and {step:.2f} x depth from the model's")
        out[n] = {"ok": ok, "why": why, "inliers": inl, "rot_deg": round(rot, 2), "step": round(step, 4)}
    return out


PART_AGREEMENT_PERCENTILE = 90
""":func:`part_agreement`: the percentile of the per-frame disagreement that stands for a part. Not the
median: a global model can agree with most of a part and bend its end (office.mp4 without loop
detection: the largest part's median 2.1 deg, its 90th percentile 12.3 deg; docs/sfm.md)."""


def part_agreement(glob: dict, parts: dict, min_images: int = 10) -> list[tuple[float | None, set]]:
    """For each model of ``parts`` (largest first): how far the largest model of ``glob`` disagrees
    with it on the orientation of their common images, in degrees, once one rotation aligns them
    (:func:`curate.core.cameras.rotation_disagreement`): the :data:`PART_AGREEMENT_PERCENTILE`-th
    percentile over the images (None under ``min_images`` of them), and its image names.

    The incremental mapper's parts are each locally sound where a global model of a weakly
    connected capture can register every photo and still bend pieces of it. office.mp4 without
    loop detection: five incremental parts (171, 146, 24, 20, 13 frames; the largest 1.2 deg
    from the truth); the global model of all 371 frames turned the 24 and 13 frames by 16 and
    20 deg (median) and the first 10% of the largest part's by more than 12 deg.
    """
    out = []
    for d, pc in part_disagreements(glob, parts):
        q = round(float(np.percentile(d, PART_AGREEMENT_PERCENTILE)), 2) if len(d) >= min_images else None
        out.append((q, set(pc.names)))
    return out


def part_disagreements(glob: dict, parts: dict) -> list[tuple[np.ndarray, Cameras]]:
    """For each model of ``parts`` (largest first): [n] degrees by which the largest model of ``glob``
    disagrees with it on the orientation of each of their n common images, once one rotation aligns
    them (:func:`curate.core.cameras.rotation_disagreement`), and the part's cameras."""
    from curate.core.cameras import rotation_disagreement
    g = max(glob.values(), key=lambda r: r.num_reg_images())
    gc = cameras_from_reconstruction(g, warn=False)[0]
    gi = {n: k for k, n in enumerate(gc.names)}
    out = []
    for rec in sorted(parts.values(), key=lambda r: -r.num_reg_images()):
        pc = cameras_from_reconstruction(rec, warn=False)[0]
        both = np.array([(gi[n], k) for k, n in enumerate(pc.names) if n in gi], dtype=int).reshape(-1, 2)
        out.append((rotation_disagreement(gc.rotations[both[:, 0]], pc.rotations[both[:, 1]]), pc))
    return out
