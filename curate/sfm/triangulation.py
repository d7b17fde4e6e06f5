"""3D points for known poses: the SfM stage's extraction and matching on working copies of the photos, then
COLMAP's point triangulator with the poses and intrinsics held fixed.
"""

from __future__ import annotations

import logging
import re
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras
from curate.sfm.config import SfmConfig
from curate.sfm.features import extract
from curate.sfm.io import colmap_from_intrinsics
from curate.sfm.matching import match, pair_counts
from curate.sfm.model import reconstruction_from_cameras
from curate.sfm.native import colmap_log, load as load_pycolmap
from curate.sfm.prep import choose_matcher
from curate.sfm.reconstruction import seeded_pipeline_options

logger = logging.getLogger(__name__)


def _working_copy(src: str, dst: Path, size: tuple[int, int]) -> None:
    """``dst``: the photo ``src`` upright at ``size`` (width, height), JPEG (quality 95) or PNG by ``dst``'s
    suffix; the original's bytes when nothing changes."""
    from PIL import Image

    from curate.core.images import RAW_EXTS, decode_upright, read_image
    if Path(src).suffix.lower() in RAW_EXTS:
        rgb, _ = read_image(src)
        if (rgb.shape[1], rgb.shape[0]) != size:
            rgb = np.asarray(Image.fromarray(rgb).resize(size, Image.LANCZOS))
    else:
        with Image.open(src) as im:
            same = im.size == size and im.getexif().get(0x0112, 1) in (0, 1)
            if same and (im.format, dst.suffix) in (("JPEG", ".jpg"), ("PNG", ".png")):
                shutil.copyfile(src, dst)
                return
            rgb = decode_upright(im, size)
    if dst.suffix == ".png":
        Image.fromarray(rgb).save(dst, format="PNG", compress_level=1)
    else:
        Image.fromarray(rgb).save(dst, format="JPEG", quality=95)


def working_sizes(cams: Cameras, max_size: int) -> tuple[np.ndarray, np.ndarray]:
    """([N] widths, [N] heights) of the cameras' images with the longer side at most ``max_size``
    (the SfM stage's working size; never enlarged)."""
    s = np.minimum(1.0, max_size / np.maximum(cams.width, cams.height))
    return (np.maximum(1, np.round(cams.width * s)).astype(int),
            np.maximum(1, np.round(cams.height * s)).astype(int))


def triangulate_known_poses(cfg: SfmConfig, cams: Cameras, originals: list[str], out: Path):
    """3D points for cameras whose poses are known: (a ``pycolmap.Reconstruction`` of ``cams`` with
    the points, statistics). Never raises for what the photos hold: a failure is a status.

    The SfM stage's own steps on working copies of the photos (``out/triangulation/images``, upright,
    longer side at most ``cfg.max_image_size``, removed afterwards): SIFT features
    (:func:`curate.sfm.features.extract`, one camera when every image has the same intrinsics), matches
    verified as SfM verifies them (:func:`curate.sfm.matching.match`, the matcher
    :func:`curate.sfm.prep.choose_matcher` picks; in one thread, so that the same
    photos and poses give the same points on every run: COLMAP's verification draws its random samples in the
    order its threads take the pairs, and the sample's 160 photos gave 3,398 to 3,403 points over three runs
    with two threads, 3,401 every time with one), then COLMAP's point
    triangulator (``pycolmap.triangulate_points``) with the poses and the known intrinsics (scaled to
    the working size) held fixed: bundle adjustment moves the points only. The database
    (``out/database.db``) is written with the model's image and camera ids, so the two agree.

    The model returned describes the photos at the poses' own size (``cams``' intrinsics, keypoints
    scaled back), image names = ``cams.names``, as the import writes it. Statistics: ``status``
    (``done``, ``failed``), ``n_points``, ``mean_track_length``, ``mean_reprojection_error_px``
    (at the working size), ``working_max_side``, seconds per step.
    """
    pycolmap = load_pycolmap()

    from curate.core.images import PhotoRecord
    from tqdm import tqdm

    t0 = time.perf_counter()
    usable = [i for i, o in enumerate(originals) if Path(o).is_absolute()]
    stats: dict = {"status": "failed", "n_images": len(usable)}
    work = out / "triangulation"
    images = work / "images"
    images.mkdir(parents=True)
    ww, hh = working_sizes(cams, cfg.max_image_size)
    sx, sy = ww / cams.width, hh / cams.height
    stats["working_max_side"] = int(max(ww.max(), hh.max()))
    names = {}
    for i in usable:
        stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(cams.names[i]).stem)[:60]
        ext = ".png" if Path(originals[i]).suffix.lower() in (".png", ".tif", ".tiff") else ".jpg"
        names[i] = f"{i:05d}_{stem}{ext}"
    threads = cfg.num_threads if cfg.num_threads > 0 else 2
    try:
        with ThreadPoolExecutor(threads) as pool:
            list(tqdm(pool.map(lambda i: _working_copy(originals[i], images / names[i], (int(ww[i]), int(hh[i]))),
                               usable), total=len(usable), desc="working copies", unit="img",
                      disable=not cfg.progress, leave=False))
    except (OSError, ValueError) as e:
        stats["reason"] = f"a photo could not be decoded: {e}"
        shutil.rmtree(work, ignore_errors=True)
        return reconstruction_from_cameras(cams), stats
    stats["copies_seconds"] = round(time.perf_counter() - t0, 2)
    wk = {i: (cams.fx[i] * sx[i], cams.fy[i] * sy[i], cams.cx[i] * sx[i], cams.cy[i] * sy[i]) for i in usable}
    intr = {i: colmap_from_intrinsics(*wk[i], cams.dist[i]) + (int(ww[i]), int(hh[i])) for i in usable}
    single = len({(m, tuple(p), w, h) for m, p, w, h in intr.values()}) == 1
    matcher = choose_matcher(cfg, [PhotoRecord(original=originals[i], rel=cams.names[i]) for i in usable])
    stats.update(matcher=matcher, camera_mode="single" if single else "per_image")
    db = out / "database.db"
    try:
        pycolmap.set_random_seed(cfg.seed)
        with colmap_log(out / "colmap.log"):
            t = time.perf_counter()
            stats["sift"] = extract(cfg, db, images, [names[i] for i in usable], single)
            stats["extract_seconds"] = round(time.perf_counter() - t, 2)
            dbh = pycolmap.Database.open(db)
            dbim = {im.name: im for im in dbh.read_all_images()}
            kept = [i for i in usable if names[i] in dbim]
            for cid in sorted({dbim[names[i]].camera_id for i in kept}):
                i = next(k for k in kept if dbim[names[k]].camera_id == cid)
                model, params, w, h = intr[i]
                dbh.update_camera(pycolmap.Camera(camera_id=cid, model=model, width=w, height=h, params=params))
            dbh.close()
            if len(kept) < 2:
                raise RuntimeError(f"features of only {len(kept)} photos")
            t = time.perf_counter()
            # one thread, COLMAP's own matcher, as before the pieces (the pieces were not measured on this path);
            # guided matching only when asked (its "auto" is for SfM, where a sequence that splits loses frames:
            # with known poses nothing can split)
            match(replace(cfg, num_threads=1, guided_matching="on" if cfg.guided_matching == "on" else "off"),
                  db, matcher)
            stats["match_seconds"] = round(time.perf_counter() - t, 2)
            stats["n_pairs_verified"] = pair_counts(db, cfg.min_num_matches)[1]
            sub = cams[kept]
            work_cams = Cameras(sub.c2w, np.array([wk[i][0] for i in kept]), np.array([wk[i][1] for i in kept]),
                                np.array([wk[i][2] for i in kept]), np.array([wk[i][3] for i in kept]),
                                ww[kept], hh[kept], sub.dist, tuple(names[i] for i in kept))
            rec = reconstruction_from_cameras(work_cams, image_ids=[dbim[names[i]].image_id for i in kept],
                                              camera_ids=[dbim[names[i]].camera_id for i in kept])
            opts = seeded_pipeline_options(replace(cfg, num_threads=1))   # its adjustment too: the same bytes
            t = time.perf_counter()
            (work / "model").mkdir()
            tri = pycolmap.triangulate_points(rec, db, images, work / "model", clear_points=True, options=opts,
                                              refine_intrinsics=False)
            stats["triangulate_seconds"] = round(time.perf_counter() - t, 2)
    except Exception as e:  # noqa: BLE001 - pycolmap's errors: the import goes on without points, and says so
        stats["reason"] = f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
        logger.warning("sfm import: triangulating points failed (%s); the poses are imported without points",
                       stats["reason"])
        shutil.rmtree(work, ignore_errors=True)
        return reconstruction_from_cameras(cams), stats
    stats.update(status="done", n_points=int(tri.num_points3D()),
                 mean_track_length=round(float(tri.compute_mean_track_length()), 3),
                 mean_reprojection_error_px=round(float(tri.compute_mean_reprojection_error()), 3))
    # the same model at the poses' own size and names: keypoints scaled back, points and tracks kept
    pos = {dbim[names[i]].image_id: k for k, i in enumerate(kept)}
    kps = [None] * len(cams)
    for iid, k in pos.items():
        i = kept[k]
        xy = np.array([p.xy for p in tri.image(iid).points2D], np.float64).reshape(-1, 2)
        kps[i] = xy / [sx[i], sy[i]]
    final = reconstruction_from_cameras(cams, keypoints=kps)
    new_id = {iid: kept[k] + 1 for iid, k in pos.items()}
    seen: set[int] = set()
    for p in tri.points3D.values():
        els = [pycolmap.TrackElement(new_id[e.image_id], e.point2D_idx) for e in p.track.elements]
        seen.update(e.image_id for e in els)
        final.add_point3D(p.xyz, pycolmap.Track(els), p.color)
    final.update_point_3d_errors()
    stats["n_images_with_points"] = len(seen)
    stats["seconds"] = round(time.perf_counter() - t0, 2)
    shutil.rmtree(work, ignore_errors=True)
    logger.info("sfm import: %d points triangulated from %d photos with the known poses (track %.2f, %.2f px) in "
                "%.1f s", stats["n_points"], len(kept), stats["mean_track_length"],
                stats["mean_reprojection_error_px"], stats["seconds"])
    return final, stats
