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


SHARE_MIN_FRAMES = 10
""":func:`join_shared`: the fewest frames two parts must both have registered to be joined (the incremental
mapper registers frames of an earlier model again in a later one, up to COLMAP's ``max_model_overlap``, 20)."""
SHARE_MAX_STEP = VERIFY_MAX_STEP
""":func:`join_shared`: the largest distance between a shared frame's centre in the two aligned parts (90% of the
shared frames), as a fraction of the scene depth: the median over the shared frames of the median depth of the
points each sees."""


def _frames(rec, names: list[str], known: dict | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """[n, 3, 3] camera-to-world rotations, [n, 3] centres and [n] median depths of the points each sees (NaN
    where none and ``known`` has none for it), of the registered frames ``names`` of ``rec``."""
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    R, c, d = [], [], []
    for n in names:
        im = by_name[n]
        w2c = np.asarray(im.cam_from_world().rotation.matrix())
        centre = np.asarray(im.projection_center())
        xyz = np.array([rec.point3D(p.point3D_id).xyz for p in im.points2D if p.has_point3D()]).reshape(-1, 3)
        R.append(w2c.T)
        c.append(centre)
        d.append(float(np.median(np.linalg.norm(xyz - centre, axis=1))) if len(xyz) else (known or {}).get(n, np.nan))
    return np.asarray(R), np.asarray(c), np.asarray(d)


def shared_frame_alignment(anchor, part, names: list[str], depths: dict | None = None):
    """The similarity (``pycolmap.Sim3d``) that brings ``part`` onto ``anchor`` by the frames ``names`` both
    registered, and how far each of those frames then disagrees: ([n] degrees of orientation, [n] centre
    distance as a fraction of the scene depth in ``anchor``). None where no frame sees a point in either model.
    ``depths`` ({name: depth}): of frames of ``anchor`` that see no point (joined before, not yet triangulated).

    Least squares (Umeyama, ``pycolmap.estimate_sim3d``: closed form, no random sample) over each frame's
    centre and the three points one scene depth along its axes (the median over the frames of each model's
    depths: one length per model, as the points each part triangulated differ): the orientations count as much
    as the centres, so a stretch of frames in a line (a walk's) still fixes the roll about it."""
    pycolmap = load_pycolmap()
    Ra, ca, da = _frames(anchor, names, depths)
    Rp, cp, dp = _frames(part, names)
    da, dp = da[np.isfinite(da)], dp[np.isfinite(dp)]
    if not len(da) or not len(dp) or not np.median(da) > 0 or not np.median(dp) > 0:
        return None
    da, dp = float(np.median(da)), float(np.median(dp))
    axes = lambda R, c, d: np.concatenate([c[:, None], c[:, None] + d * np.swapaxes(R, 1, 2)],  # noqa: E731
                                          axis=1).reshape(-1, 3)
    sim = pycolmap.estimate_sim3d(axes(Rp, cp, dp), axes(Ra, ca, da))
    if sim is None:
        return None
    M = np.asarray(sim.matrix())
    Q = M[:, :3] / float(sim.scale)
    rot = rotation_angle_deg(Ra @ np.swapaxes(Q @ Rp, 1, 2))
    step = np.linalg.norm(cp @ M[:, :3].T + M[:, 3] - ca, axis=1) / da
    return sim, rot, step


def join_shared(models: dict, max_rot_deg: float, max_step: float = SHARE_MAX_STEP,
                min_shared: int = SHARE_MIN_FRAMES):
    """The incremental parts of ``models`` ({id: Reconstruction}) joined where they share frames, the way
    COLMAP's model merger joins two models (align them by what they share, keep the first's poses, add the
    second's other frames); pycolmap exposes the alignment, not the merge.

    The largest part anchors; each other part, largest first and again until none joins, that shares at
    least ``min_shared`` registered frames with it is aligned to it by those frames
    (:func:`shared_frame_alignment`) and joins when they agree: on 90% of them within ``max_rot_deg`` degrees
    of orientation and ``max_step`` of their depth (:data:`SHARE_MAX_STEP`), and on every one within twice that.
    A wrong part disagrees on the frames it shares (office.mp4, an earlier build: a 35-frame part, 13.5 deg at
    the 90th percentile, its other frames 16 deg from the truth); a right one agrees (a third of its frame rate:
    81 and 50 frames sharing 16, 1.6 deg; docs/investigations/sfm.md#joined-parts).
    Its frames the anchor lacks are added at their aligned poses, with their keypoints and no points:
    the caller triangulates them (``pycolmap.triangulate_points``).

    Returns (the anchor with the frames added, a copy, or None when no part joined; the ids of the parts
    joined; [{"photos", "shared", "rot_deg", "step", "joined", "added"} per other part, largest first]).
    """
    pycolmap = load_pycolmap()
    order = sorted(models, key=lambda k: -models[k].num_reg_images())
    if len(order) < 2:
        return None, [], []
    anchor = models[order[0]]   # copied at the first join
    names = lambda r: {r.image(i).name: i for i in r.reg_image_ids()}  # noqa: E731
    records = {k: {"photos": int(models[k].num_reg_images()), "shared": 0, "rot_deg": None, "step": None,
                   "joined": False, "added": 0} for k in order[1:]}
    left, joined, depths = list(order[1:]), [], {}
    while left:
        done = []
        for k in left:
            part, held = models[k], names(anchor)
            mine = names(part)
            shared = sorted(set(held) & set(mine))
            rec = records[k]
            rec["shared"] = len(shared)
            if len(shared) < min_shared or len(shared) == len(mine):   # too few to align, or nothing to add
                continue
            fit = shared_frame_alignment(anchor, part, shared, depths)
            if fit is None:
                continue
            sim, rot, step = fit
            rec["rot_deg"] = [round(float(x), 2) for x in np.percentile(rot, [50, 90, 100])]
            rec["step"] = [round(float(x), 4) for x in np.percentile(step, [50, 90, 100])]
            if not (np.percentile(rot, 90) <= max_rot_deg and rot.max() <= 2 * max_rot_deg
                    and np.percentile(step, 90) <= max_step and step.max() <= 2 * max_step):
                continue
            if not joined and not done:
                anchor = pycolmap.Reconstruction(anchor)
            moved = pycolmap.Reconstruction(part)
            moved.transform(sim)
            new = sorted(n for n in mine if n not in held)
            dmoved = _frames(moved, new, depths)[2]
            for n, d in zip(new, dmoved):
                _add_frame(anchor, moved, mine[n])
                depths[n] = d
            rec["joined"], rec["added"] = True, len(new)
            done.append(k)
        if not done:
            break
        joined += done
        left = [k for k in left if k not in done]
    return (anchor if joined else None), joined, [records[k] for k in order[1:]]


def _add_frame(out, src, image_id: int) -> None:
    """Add the registered image ``image_id`` of ``src`` to ``out`` at its pose in ``src``: same id, name and
    camera (added when missing), every keypoint, no 3D point; where ``out`` holds the image unregistered, its
    frame is registered at that pose."""
    pycolmap = load_pycolmap()
    im = src.image(image_id)
    if out.exists_image(image_id):
        mine = out.image(image_id)
        out.frame(mine.frame_id).set_cam_from_world(mine.camera_id, im.cam_from_world())
        out.register_frame(mine.frame_id)
        return
    if not out.exists_camera(im.camera_id):
        out.add_camera_with_trivial_rig(src.camera(im.camera_id))
    kp = np.array([p.xy for p in im.points2D], np.float64).reshape(-1, 2)
    out.add_image_with_trivial_frame(pycolmap.Image(name=im.name, camera_id=im.camera_id, image_id=image_id,
                                                    keypoints=kp), im.cam_from_world())
