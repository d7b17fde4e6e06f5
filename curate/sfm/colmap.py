"""SfM stage: photos -> registered cameras + sparse points (COLMAP through pycolmap).

This module runs the steps; each lives in its own module of :mod:`curate.sfm`, the only package of curate
that imports pycolmap (lazily, inside functions). Later stages read the results with
``curate.sfm.io.load_sfm`` without pycolmap.

Pipeline (``run_sfm``): ingest (``curate.sfm.ingest``: decode, orient, downscale into
working copies) -> quality (``curate.sfm.quality``: sharpness, near-duplicates; drop per
config) -> SIFT extraction (:mod:`curate.sfm.features`; one shared camera when every photo comes
from the same camera model at the same size, else one camera per photo) -> matching
(:mod:`curate.sfm.matching`: exhaustive for small pools, sequential for ordered frames, spatial with
GPS, retrieval for photos in no order, with a second round for the photos its model leaves out; loop
detection with visual words learned from the capture itself (seeded), never a download, so it works offline;
with several videos, each video's frames are also matched with their most similar frames of the other
videos; a video with photos is matched exhaustively) -> mapping
(:func:`curate.sfm.reconstruction.map_capture`: incremental, initial pair with >=
``init_min_num_inliers`` verified inliers; when its largest model leaves more than 5% of the photos
out, COLMAP's global mapper on the same matches, kept where it agrees with the incremental parts and
holds more photos: :mod:`curate.sfm.parts`) -> optional dense reconstruction (CUDA only).
Verification RANSAC, the mapper and the tree's training sample are seeded (``SfmConfig.seed``): the
same photos and config give the same matches and, up to multi-threaded bundle adjustment, the same
model. :func:`curate.sfm.pose_import.import_poses` produces the same outputs from known poses (a
transforms.json, a cameras.json, a COLMAP model; each pose's photo looked up in the photo folder
given); poses that come without 3D points get points triangulated from the photos with the poses
held fixed (:mod:`curate.sfm.triangulation`: the same SIFT extraction and matching, then COLMAP's
point triangulator).

What ``RUN/sfm/`` holds, file by file: docs/architecture.md#run-sfm.
"""

from __future__ import annotations

import logging
import shutil
import time
from dataclasses import replace
from pathlib import Path

from curate.core.cameras import Cameras
from curate.core.graph import BY_NAME
from curate.core.stage import begin_stage, finish_stage
from curate.sfm.config import RETRIEVAL_REMATCH_BELOW, TAKE_MIN_FRACTION, SfmConfig
from curate.sfm.continuity import drop_off_path, drop_refuted, jumps_along, unexplained_steps
from curate.sfm.features import extract
from curate.sfm.io import sfm_dir as _sfm_dir
from curate.sfm.matching import match, pair_counts, rematch_left_out, weak_first
from curate.sfm.model import cameras_from_reconstruction, write_model
from curate.sfm.native import colmap_log, load as load_pycolmap
from curate.sfm.parts import without_contained
from curate.sfm.prep import (check_free_space, choose_camera_mode, choose_guided, choose_matcher, input_key,
                             prepare_photos, take_counts, takes_not_joined, takes_of, too_few_message,
                             write_outputs)
from curate.sfm.reconstruction import map_capture, model_sizes

logger = logging.getLogger(__name__)

__all__ = ["run_sfm"]

SFM = BY_NAME["sfm"]
"""The stage's row of the graph: what it writes (``owns``) and what nothing reads again (``spare``)."""


def _dense(sfm: Path, sparse: Path, images: Path) -> dict:
    pycolmap = load_pycolmap()
    if not pycolmap.has_cuda:
        return {"status": "skipped", "reason": "pycolmap has no CUDA (patch-match stereo needs it)"}
    dense = sfm / "dense"
    t0 = time.perf_counter()
    pycolmap.undistort_images(dense, sparse, images)
    pycolmap.patch_match_stereo(dense)
    pycolmap.stereo_fusion(dense / "fused.ply", dense)
    return {"status": "done", "path": "dense/fused.ply", "seconds": round(time.perf_counter() - t0, 2)}


def _second_round(cfg: SfmConfig, db: Path, images: Path, out: Path, names: list[str], models: dict,
                  stats: dict) -> dict:
    """Retrieval matching's second round: when the largest model holds under ``RETRIEVAL_REMATCH_BELOW`` of
    the photos, those it left out are matched again with more of their most similar photos
    (:func:`curate.sfm.matching.rematch_left_out`) and the capture is mapped again; the larger largest model
    is kept. ``stats["retrieval_second_round"]`` says what it did."""
    largest = max(models.values(), key=lambda r: r.num_reg_images())
    first = largest.num_reg_images()
    if first >= RETRIEVAL_REMATCH_BELOW * len(names):
        return models
    held = {largest.image(i).name for i in largest.reg_image_ids()}
    info = rematch_left_out(cfg, db, [n for n in names if n not in held])
    shutil.rmtree(out / "mapper", ignore_errors=True)
    again = map_capture(cfg, db, images, out / "mapper", len(names), stats)
    info.update(model_sizes_before=model_sizes(models), model_sizes_after=model_sizes(again) if again else [])
    stats["retrieval_second_round"] = info
    logger.warning("sfm: retrieval matching left %d of %d photos out of the model; matched again with their %d "
                   "most similar photos (%d new verified pairs): models %s -> %s", info["photos"], len(names),
                   info["num_images"], info["verified"], info["model_sizes_before"], info["model_sizes_after"])
    return again if again and max(r.num_reg_images() for r in again.values()) > first else models


def run_sfm(cfg: SfmConfig, photos: str | Path, run_dir: str | Path, force: bool = False) -> Path:
    """:func:`sfm_in_claimed` in the run folder, claimed and locked here (:mod:`curate.core.runfolder`): for a
    caller that runs SfM alone. Returns ``RUN/sfm``."""
    from curate.core.runfolder import claimed  # runsafe
    with claimed(run_dir, [photos]):
        return sfm_in_claimed(cfg, photos, run_dir, force)[0]


def sfm_in_claimed(cfg: SfmConfig, photos: str | Path, run_dir: str | Path, force: bool = False) -> tuple[Path, bool]:
    """Run the SfM stage on the photos of ``photos`` in a run folder its caller claimed; returns (``RUN/sfm``,
    whether it ran). Skipped when ``RUN/sfm/stage.json`` has the same key: same config (``num_threads`` and
    ``progress`` excluded) and same photo files (names and content).
    """
    pycolmap = load_pycolmap()

    photos, run_dir = Path(photos).resolve(), Path(run_dir).resolve()
    out = _sfm_dir(run_dir)
    key = input_key(cfg, photos)
    if begin_stage(out, key, force, owns=SFM.owns, spare=SFM.spare):
        logger.info("sfm: up to date (%s), skipped", out)
        return out, False
    started = time.perf_counter()
    timings: dict[str, float] = {}
    records, kept, t_ingest = prepare_photos(cfg, photos, out)
    videos = t_ingest.pop("videos", [])
    timings.update(t_ingest)
    names = [r.working for r in kept]
    if len(names) < 2:
        write_outputs(out, Cameras.empty(), None, None, None, records, [], cfg.normalize_percentile)
        raise RuntimeError(too_few_message(photos, records, videos, out / "images.json"))
    single = choose_camera_mode(cfg, kept)
    matcher = choose_matcher(cfg, kept)
    guided = choose_guided(cfg, kept)
    check_free_space(out, len(names), matcher, cfg)     # COLMAP aborts the process on a full disk
    db, images = out / "database.db", out / "images"
    stats: dict = {"n_input_files": len(records), "n_kept": len(names), "camera_mode": "single" if single else
                   "per_image", "matcher": matcher, "guided_matching": guided, **({"videos": videos} if videos else {})}
    pycolmap.set_random_seed(cfg.seed)
    with colmap_log(out / "colmap.log"):
        logger.info("sfm: extracting SIFT features (%s camera, %s) ...", stats["camera_mode"], cfg.camera_model)
        t = time.perf_counter()
        stats["sift"] = extract(cfg, db, images, names, single)
        timings["extract"] = round(time.perf_counter() - t, 2)
        logger.info("sfm: features extracted for %d images in %.1f s", len(names), timings["extract"])
        logger.info("sfm: %s matching ...", matcher)
        t = time.perf_counter()
        below = weak_first(cfg, db) if guided and cfg.guided_matching == "auto" else 0
        stats["guided_only_below_inliers"] = below
        match(replace(cfg, guided_matching="on" if guided else "off"), db, matcher, takes_of(kept), stats, below)
        timings["match"] = round(time.perf_counter() - t, 2)
        stats["n_pairs_matched"], stats["n_pairs_verified"] = pair_counts(db, cfg.min_num_matches)
        logger.info("sfm: %s matching, %d of %d pairs verified in %.1f s", matcher, stats["n_pairs_verified"],
                    stats["n_pairs_matched"], timings["match"])
        t = time.perf_counter()
        models = map_capture(cfg, db, images, out / "mapper", len(names), stats)
        if matcher == "retrieval" and models:
            models = _second_round(cfg, db, images, out, names, models, stats)
        timings["map"] = round(time.perf_counter() - t, 2)
    if not models:
        raise RuntimeError(f"sfm: COLMAP registered no images (see {out / 'colmap.log'})")
    models = without_contained(models)
    off = drop_off_path(models, kept)
    if off:
        stats["off_path"] = off
        logger.warning("sfm: %d frames were placed off their video's path (a stretch that jumps away and back), "
                       "left out: %s", sum(map(len, off.values())),
                       "; ".join(f"{tk}: {len(n)} ({n[0]}..{n[-1]})" if len(n) > 1 else f"{tk}: {n[0]}"
                                 for tk, n in off.items()))
    t = time.perf_counter()
    refuted = drop_refuted(models, kept, db)
    timings["step_check"] = round(time.perf_counter() - t, 2)
    if refuted:
        stats["refuted_frames"] = refuted
        k = sum(map(len, refuted.values()))
        logger.warning("sfm: %s placed where %s own matches with the next frames refute %s, left out: %s",
                       "1 frame was" if k == 1 else f"{k} frames were", "its" if k == 1 else "their",
                       "it" if k == 1 else "them", "; ".join(f"{tk}: {', '.join(n)}" for tk, n in refuted.items()))
    best = max(models.values(), key=lambda r: r.num_reg_images())
    jumps = jumps_along(best, kept)
    if jumps:
        stats["path_jumps"] = jumps
    stats["model_sizes"] = model_sizes(models)
    sparse = out / "sparse" / "0"
    write_model(best, sparse)
    others = sorted((r for r in models.values() if r is not best and r.num_reg_images() >= 2),
                    key=lambda r: -r.num_reg_images())
    for k, r in enumerate(others, 1):  # the other parts of a split capture, for --on-split each
        write_model(r, out / "sparse" / str(k))
    stats["parts"] = [{"model": f"sparse/{k}", "n_registered": int(r.num_reg_images())}
                      for k, r in enumerate([best] + others)]
    for part, r in zip(stats["parts"][1:], others):   # --on-split each curates them: a fold there is named too
        if j := jumps_along(r, kept):
            part["path_jumps"] = j
    t = time.perf_counter()
    for part, r in zip(stats["parts"], [best] + others):   # each step against its frames' own matches
        steps = unexplained_steps(r, kept, db)
        part["steps_checked"] = {tk: v["checked"] for tk, v in steps.items()}
        if bad := {tk: v["unexplained"] for tk, v in steps.items() if v["unexplained"]}:
            part["unexplained_steps"] = bad
    timings["step_check"] = round(timings["step_check"] + time.perf_counter() - t, 2)
    shutil.rmtree(out / "mapper", ignore_errors=True)
    in_model = {best.image(i).name for i in best.reg_image_ids()}
    in_others = {r.image(i).name for r in models.values() if r is not best for i in r.reg_image_ids()}
    stats["takes"] = take_counts(kept, in_model, in_others)
    for t in takes_not_joined(stats["takes"], TAKE_MIN_FRACTION):
        logger.info("sfm: take %s: %d of %d frames in the model (%d in other models)", t["take"], t["n_in_model"],
                    t["n_frames"], t["n_in_other_parts"])
    stats["mean_reprojection_error_px"] = float(best.compute_mean_reprojection_error())
    stats["mean_track_length"] = float(best.compute_mean_track_length())
    logger.info("sfm: %d / %d images registered, %d points, reprojection error %.2f px, mapping %.1f s",
                best.num_reg_images(), len(names), best.num_points3D(), stats["mean_reprojection_error_px"],
                timings["map"])
    cams, xyz, rgb, err = cameras_from_reconstruction(best)
    t = time.perf_counter()
    if cfg.dense == "auto":
        with colmap_log(out / "colmap.log"):
            dense = _dense(out, sparse, images)
    else:
        dense = {"status": "off"}
    timings["dense"] = round(time.perf_counter() - t, 2)
    paths = [f"images/{n}" for n in cams.names]
    stats.update(write_outputs(out, cams, xyz, rgb, err, records, paths, cfg.normalize_percentile))
    stats["dense"] = dense
    finish_stage(out, key, cfg, started, outputs={"sparse": "sparse/0", "cameras": "cameras.json"}, owns=SFM.owns,
                 seed=cfg.seed, mode="sfm", photos=str(photos), timings=timings, stats=stats)
    return out, True
