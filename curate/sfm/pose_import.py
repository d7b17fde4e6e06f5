"""Known poses instead of SfM (:func:`import_poses`): each pose's photo found and checked, the stage's outputs
written from the poses, with the source's points, points triangulated for them, or none.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from curate.core.cameras import Cameras
from curate.core.graph import BY_NAME
from curate.core.stage import begin_stage, finish_stage, hash_files, stage_key
from curate.sfm.config import SfmConfig
from curate.sfm.io import sfm_dir as _sfm_dir
from curate.sfm.model import (cameras_from_reconstruction, pycolmap_reconstruction, reconstruction_from_cameras,
                               write_model)
from curate.sfm.prep import write_outputs
from curate.sfm.subset_model import write_subset_model
from curate.sfm.triangulation import triangulate_known_poses

logger = logging.getLogger(__name__)

SFM = BY_NAME["sfm"]
"""The stage's row of the graph: what it writes (``owns``) and what nothing reads again (``spare``)."""


def read_cameras(source: str | Path, photos: str | Path | None = None) -> tuple[Cameras, list[str]]:
    """Cameras of a pose source (:func:`curate.sfm.poses.read_poses`), without writing anything:
    (cameras, image paths)."""
    from curate.sfm.poses import read_poses
    p = read_poses(source, photos)
    return p.cameras, p.files


def import_poses(cfg: SfmConfig, source: str | Path, run_dir: str | Path, photos: str | Path | None = None,
                 force: bool = False) -> Path:
    """:func:`import_in_claimed` in the run folder, claimed and locked here (:mod:`curate.core.runfolder`): for a
    caller that imports poses alone. Returns ``RUN/sfm``."""
    from curate.core.runfolder import claimed  # runsafe
    with claimed(run_dir, [source, photos]):
        return import_in_claimed(cfg, source, run_dir, photos, force)[0]


ASPECT_TOL = 0.01
""":func:`check_photos`: largest relative difference of aspect ratio between a photo and its camera."""


def check_photos(cams: Cameras, originals: list[str], source: Path) -> tuple[list[dict], list[int]]:
    """Every posed photo decoded (reduced, fast) before any training: (images.json records, indices of
    the usable cameras). An unreadable photo (missing, a dangling link, empty, truncated, not an image)
    is skipped and listed with its reason, as SfM ingest does. A photo whose upright size has the
    aspect of its camera but another size is used as it is (the loader resizes it to the camera's
    size: the intrinsics hold); another aspect is an error naming the file and both sizes (the poses
    do not describe that image, e.g. an EXIF-rotated photo under a landscape camera). Relative names
    (a COLMAP model without a photo folder) are not checked."""
    from curate.core.images import probe_image
    records, keep = [], []
    for i, (n, o) in enumerate(zip(cams.names, originals)):
        rec = {"original": o, "rel": n, "status": "kept", "reason": "", "working": "", "registered": True}
        if Path(o).is_absolute():
            try:
                w, h = probe_image(o)
            except (OSError, ValueError) as e:
                rec.update(status="skipped", reason=str(e), registered=False)
                logger.warning("sfm import: %s skipped: %s", o, e)
                records.append(rec)
                continue
            cw, ch = int(cams.width[i]), int(cams.height[i])
            if abs((w / h) / (cw / ch) - 1.0) > ASPECT_TOL:
                raise ValueError(f"{o}: the photo is {w}x{h} (upright) but its pose in {source} describes a "
                                 f"{cw}x{ch} image: another aspect ratio (a rotated or cropped photo?)")
            rec.update(orig_width=w, orig_height=h)
        records.append(rec)
        keep.append(i)
    if not keep:
        raise ValueError(f"{source}: none of its {len(cams)} photos can be read (see the log)")
    return records, keep


def photo_sizes_said(cams: Cameras, records: list[dict]) -> dict | None:
    """When photos have another size than the one their poses describe (same aspect: poses written for the
    full-size images, photos downscaled, as nerfstudio's ``images_2``, ``images_4``): ``n`` such photos, the
    commonest pair of sizes and its factor, and one line saying so (the export's cameras are scaled to the
    photos: :func:`curate.sfm.io.original_cameras`); None when every photo has its pose's size."""
    from collections import Counter
    pairs = Counter((int(cams.width[i]), int(cams.height[i]), int(r["orig_width"]), int(r["orig_height"]))
                    for i, r in enumerate(records) if r.get("orig_width")
                    and (int(r["orig_width"]), int(r["orig_height"])) != (int(cams.width[i]), int(cams.height[i])))
    if not pairs:
        return None
    (cw, ch, w, h), _ = pairs.most_common(1)[0]
    f = w / cw
    factor = f"1/{1 / f:.3g}" if f < 1 else f"{f:.3g}"
    n = sum(pairs.values())
    return {"n": n, "poses": f"{cw}x{ch}", "photos": f"{w}x{h}", "factor": f,
            "said": f"poses are for {cw}x{ch}, photos are {w}x{h}: intrinsics scaled by {factor}"
                    + (f" ({n} of {len(cams)} photos)" if n < len(cams) else "")}


def _check_photo_folder(photos: Path, source: Path) -> None:
    """The photo folder given with poses must be a folder: a video's frames (or one photo) have no names
    the poses could refer to."""
    from curate.sfm.video import VIDEO_EXTS
    if not photos.exists():
        raise FileNotFoundError(f"photo folder {photos} does not exist")
    if photos.is_file() and photos.suffix.lower() in VIDEO_EXTS:
        raise ValueError(f"{photos}: a video cannot be given with --poses {source}: its frames have no names the "
                         "poses could refer to. Give the folder of the photos the poses describe, or the video "
                         "alone (SfM finds its cameras)")
    if not photos.is_dir():
        raise NotADirectoryError(f"{photos}: not a folder; with --poses give the folder of the photos the poses "
                                 "describe (or no photo folder: the pose file's own image paths are used)")


def _examples(names, k: int = 3) -> str:
    names = list(names)
    return ", ".join(names[:k]) + (f" (and {len(names) - k} more)" if len(names) > k else "")


def _pose_photos(cfg: SfmConfig, poses, source: Path, photos: Path | None):
    """(indices of the poses kept, their photos, images.json records of what was left out, the match's
    statistics or None): each pose's photo looked up in the photo folder (:func:`curate.sfm.poses.match_photos`),
    the one given or the usual one beside a COLMAP model (:func:`curate.sfm.poses.default_photos`); without
    either, the pose file's own image paths."""
    from curate.sfm.poses import default_photos, match_photos
    folder = photos if photos is not None else default_photos(source)
    if folder is None:
        return list(range(len(poses.cameras))), list(poses.files), [], None
    folder = Path(folder).resolve()
    names = list(poses.cameras.names)
    m = match_photos(names, poses.files, folder, cfg.recursive, source)
    idx = m.matched
    if not idx:
        if m.n_photos == 0:
            raise ValueError(f"{folder} holds no photos for the {len(names)} poses of {source}")
        raise ValueError(f"no pose of {source} names a photo of {folder}: the poses name e.g. "
                         f"{_examples(names)}; the folder holds e.g. {_examples(p.name for p in m.unposed)}")
    left = [{"original": str(folder / n) if n and not Path(n).is_absolute() else n, "rel": n, "status": "skipped",
             "reason": f"pose without a photo: {m.how[i]}", "working": "", "registered": False}
            for i, n in enumerate(names) if m.files[i] is None]
    unposed = m.unposed if photos is not None else []  # a folder found by the layout, not given: not listed
    from curate.sfm.ingest import NOT_UTF8, printable, text_name
    from curate.sfm.video import VIDEO_EXTS
    left += [{"original": printable(p), "rel": printable(p.relative_to(folder).as_posix()), "status": "skipped",
              "reason": ("a video: its frames have no names the poses could refer to" if p.suffix.lower() in VIDEO_EXTS
                         else NOT_UTF8 if not text_name(p) else f"no pose in {source} names this photo"),
              "working": "", "registered": False}
             for p in unposed]
    stats = {"folder": str(folder), "given": photos is not None, "n_poses": len(names), "n_matched": len(idx),
             "n_by_name": sum(m.how[i] == "name" for i in idx), "n_photos": m.n_photos if photos is not None else None,
             "n_unposed": len(unposed) if photos is not None else None,
             "poses_without_photo": [names[i] for i in range(len(names)) if m.files[i] is None][:50],
             "photos_without_pose": [printable(p.relative_to(folder).as_posix()) for p in unposed][:50]}
    if len(idx) < len(names):
        logger.warning("sfm import: %d of the %d poses of %s have no photo in %s (left out), e.g. %s",
                       len(names) - len(idx), len(names), source, folder, _examples(stats["poses_without_photo"]))
    if unposed:
        logger.warning("sfm import: %d of the %d photos of %s have no pose in %s (left out), e.g. %s", len(unposed),
                       m.n_photos, folder, source, _examples(stats["photos_without_pose"]))
    return idx, [m.files[i] for i in idx], left, stats


def _import_key(cfg: SfmConfig, source: Path, photos: Path | None, originals: list[str], left: list[dict],
                triangulate: bool) -> str:
    """The import stage's key: the pose files, the photos used (names and content), what was left out,
    and the options that shape the result (SfM's feature and matching options when triangulating)."""
    import dataclasses
    from curate.sfm.poses import pose_files
    from curate.sfm.prep import _NOT_IN_KEY
    conf: dict = {"mode": "import", "source": str(source), "photos": str(photos),
                  "normalize_percentile": cfg.normalize_percentile, "recursive": cfg.recursive,
                  "triangulate": triangulate}
    if triangulate:
        conf.update({k: v for k, v in dataclasses.asdict(cfg).items() if k not in _NOT_IN_KEY + ("video", "dense")})
    photos_used = [o for o in originals if Path(o).is_absolute()]
    return stage_key(conf, [hash_files(pose_files(source)), hash_files(photos_used),
                            "\n".join(f"{r['rel']}:{r['reason']}" for r in left)])


def import_in_claimed(cfg: SfmConfig, source: str | Path, run_dir: str | Path, photos: str | Path | None = None,
                      force: bool = False) -> tuple[Path, bool]:
    """Fill ``RUN/sfm`` of a run folder its caller claimed from known poses instead of running SfM; returns
    (``RUN/sfm``, whether it ran: False when its record had the same key).

    Args:
        source: a pose source (:func:`curate.sfm.poses.read_poses`: a transforms.json, a cameras.json, a
            COLMAP model folder, a folder holding one of them).
        photos: the folder of the photos the poses describe: each pose's photo is looked up there
            (:func:`curate.sfm.poses.match_photos`); poses without a photo, and photos without a pose,
            are left out and listed in ``images.json``; none matching is an error. Without it, a COLMAP
            model's usual ``images/`` folder, else the pose file's own image paths.

    With no 3D points in the source and ``cfg.triangulate == "auto"``, points are triangulated from
    the photos with the poses held fixed (:func:`curate.sfm.triangulation.triangulate_known_poses`).
    """
    from curate.sfm.poses import read_poses
    source = Path(source).resolve()
    photos = Path(photos).resolve() if photos is not None else None
    run_dir = Path(run_dir).resolve()
    out = _sfm_dir(run_dir)
    if photos is not None:
        _check_photo_folder(photos, source)
    poses = read_poses(source, photos)
    idx, originals, left, match = _pose_photos(cfg, poses, source, photos)
    cams = poses.cameras[idx]
    records, keep = check_photos(cams, originals, source)
    cams, originals = cams[keep], [originals[i] for i in keep]
    rescaled = photo_sizes_said(cams, [records[i] for i in keep])
    if rescaled:
        logger.warning("sfm import: %s", rescaled["said"])
    has_points = poses.points is not None and len(poses.points) > 0
    readable = sum(Path(o).is_absolute() for o in originals)
    triangulate = cfg.triangulate == "auto" and not has_points and readable >= 2
    key = _import_key(cfg, source, photos, originals, left, triangulate)
    if begin_stage(out, key, force, owns=SFM.owns, spare=SFM.spare):
        logger.info("sfm import: up to date (%s), skipped", out)
        return out, False
    started = time.perf_counter()
    sparse = out / "sparse" / "0"
    stats: dict = {"n_poses": len(poses.cameras)}
    if match is not None:
        stats["pose_match"] = match
    if rescaled:
        stats["rescaled"] = rescaled
    if has_points:
        if len(cams) < len(poses.cameras):  # the model of the photos kept, with the points they see
            write_subset_model(poses.reconstruction, list(cams.names), sparse, min_track=2)
            rec = pycolmap_reconstruction(sparse)
        else:
            rec = poses.reconstruction
            write_model(rec, sparse)
        _, xyz, rgb, err = cameras_from_reconstruction(rec)
        stats["triangulation"] = {"status": "source", "reason": "the source has 3D points"}
    elif triangulate:
        rec, stats["triangulation"] = triangulate_known_poses(cfg, cams, originals, out)
        write_model(rec, sparse)
        _, xyz, rgb, err = cameras_from_reconstruction(rec)
    else:
        reason = ("--triangulate off" if cfg.triangulate == "off" else
                  "fewer than 2 readable photos (image names without a photo folder)")
        stats["triangulation"] = {"status": "off" if cfg.triangulate == "off" else "skipped", "reason": reason}
        rec = reconstruction_from_cameras(cams)
        write_model(rec, sparse)
        xyz = rgb = err = None
    stats.update(write_outputs(out, cams, xyz, rgb, err, records + left, originals, cfg.normalize_percentile))
    finish_stage(out, key, cfg, started, outputs={"sparse": "sparse/0", "cameras": "cameras.json"}, owns=SFM.owns,
                 mode="import", source=str(source), photos=str(photos) if photos else None, stats=stats)
    logger.info("sfm import: %d cameras, %d points from %s", len(cams), stats["n_points"], source)
    return out, True
