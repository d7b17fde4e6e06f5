"""Mapping: COLMAP's incremental and global mappers with curate's options, and the choice between them
(:func:`map_capture`: the global model replaces the incremental parts only where it agrees with them,
:mod:`curate.sfm.parts`).
"""

from __future__ import annotations

import logging
import math
import shutil
import time
from pathlib import Path

from curate.sfm.config import SfmConfig
from curate.sfm.native import load as load_pycolmap
from curate.sfm.parts import join_parts, join_shared, part_agreement, verify_frames

logger = logging.getLogger(__name__)


MAPPING_THREADS = 1
"""Threads of the mappers and their bundle adjustments, whatever ``SfmConfig.num_threads`` says. Ceres sums a
multi-threaded adjustment in the order its threads finish: the same matches mapped twice on two threads gave poses
0.09 deg apart (office.mp4 at half its frame rate), and a difference that small decides which frame registers next
on a capture that is close to splitting (docs/sfm.md#same-model)."""


def seeded_pipeline_options(cfg: SfmConfig):
    """COLMAP's incremental pipeline options with one thread (:data:`MAPPING_THREADS`), ``cfg``'s seed (mapper and
    triangulation) and minimum matches: what mapping and the triangulation of known poses share."""
    pycolmap = load_pycolmap()
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = MAPPING_THREADS
    opts.random_seed = cfg.seed
    opts.mapper.random_seed = cfg.seed
    opts.triangulation.random_seed = cfg.seed
    opts.min_num_matches = cfg.min_num_matches
    return opts


def expected_observations(db: Path, min_num_matches: int = 15) -> int:
    """The observations the matches of ``db`` promise a model: keypoints with at least one verified inlier match,
    in the image pairs with at least ``min_num_matches`` inliers (what the incremental mapper reads). A model
    keeps 47-84% of them (the skull, office.mp4, the fox, the drone flight); the cost of a global adjustment
    follows the observations, not the photos (docs/sfm.md#large-pools)."""
    import numpy as np
    pycolmap = load_pycolmap()
    with pycolmap.Database.open(db) as dbh:
        seen = {im.image_id: np.zeros(dbh.num_keypoints_for_image(im.image_id), bool)
                for im in dbh.read_all_images()}
        ids, geoms = dbh.read_two_view_geometries()
    for pid, g in zip(ids, geoms):
        m = g.inlier_matches
        if m is None or len(m) < max(min_num_matches, 1):
            continue
        a, b = pycolmap.pair_id_to_image_pair(pid)
        if a in seen and b in seen:
            seen[a][m[:, 0]] = True
            seen[b][m[:, 1]] = True
    return int(sum(int(v.sum()) for v in seen.values()))


def incremental_options(cfg: SfmConfig, n_images: int, n_observations: int = 0):
    """The incremental mapper's options for a pool of ``n_images`` photos whose matches promise ``n_observations``
    (:func:`expected_observations`): :func:`seeded_pipeline_options`, the initial pair's inliers
    (``cfg.init_min_num_inliers``), the inliers that register a photo (``cfg.register_min_inliers``), the principal
    point held; past ``cfg.global_ba_above`` photos or
    ``cfg.global_ba_above_observations``, a global bundle adjustment each time the model grows by the factor
    ``cfg.global_ba_growth`` (COLMAP: 1.1), refined ``cfg.global_ba_refinements`` times at most (COLMAP: 5).
    Each new photo's local adjustment keeps COLMAP's two refinements (one folded office.mp4 cut into two
    takes: docs/sfm.md).

    The global adjustments are most of the incremental mapper's time on a long capture (the rendered
    1,000-frame walk: 79% of its mapping) and what makes it grow faster than the pool
    (docs/investigations/sfm.md#mapping-past-1000)."""
    opts = seeded_pipeline_options(cfg)
    opts.mapper.init_min_num_inliers = cfg.init_min_num_inliers
    opts.mapper.abs_pose_min_num_inliers = cfg.register_min_inliers
    opts.ba_refine_principal_point = False
    if n_images > cfg.global_ba_above or n_observations > cfg.global_ba_above_observations:
        opts.ba_global_frames_ratio = opts.ba_global_points_ratio = cfg.global_ba_growth
        opts.ba_global_max_refinements = cfg.global_ba_refinements
    return opts


def map_incremental(cfg: SfmConfig, db: Path, images: Path, out: Path, n_images: int, progress: bool,
         adjustments: list | None = None, schedule: dict | None = None):
    """{id: Reconstruction} of COLMAP's incremental mapper on the matches of ``db``, with curate's options
    (:func:`incremental_options`), run step by step by :func:`curate.sfm.mapping.incremental_mapping`: COLMAP's
    steps, the final refinement left out where it would repeat the one before (``cfg.repeat_final_refinement``),
    and in pools of more photos than Ceres' direct-solve limit (1,000) each global adjustment's solver chosen from
    the model's shape (``cfg.direct_ba_max_fill``); ``adjustments`` (when given) gets one record per
    global adjustment past the limit (photos, fill per photo, solver, seconds); ``schedule`` (when given) the
    observations the matches promise and the growth between global adjustments (``expected_observations``,
    ``global_ba_growth``: COLMAP's or ``cfg.global_ba_growth``)."""
    from tqdm import tqdm

    from curate.sfm import mapping
    n_obs = expected_observations(db, cfg.min_num_matches)
    opts = incremental_options(cfg, n_images, n_obs)
    logger.info("sfm: %d photos, the matches promise %d observations: a global adjustment each time the model grows "
                "by %g", n_images, n_obs, opts.ba_global_frames_ratio)
    if schedule is not None:
        schedule.update(expected_observations=n_obs, global_ba_growth=round(float(opts.ba_global_frames_ratio), 3))
    limit = mapping.ceres_direct_limit()
    bar = tqdm(total=n_images, desc="mapping", unit="img", disable=not progress, leave=False)
    count = [0]

    def on_image(k: int = 1):  # registrations over all models: the bar stops at the pool size
        k = min(k, n_images - count[0])
        count[0] += k
        bar.update(k)

    choice = mapping.SolverChoice(cfg.direct_ba_max_fill, limit) if n_images > limit and cfg.direct_ba_max_fill > 0 \
        else None
    try:
        models = mapping.incremental_mapping(db, images, out, opts, choice, on_pair=lambda: on_image(2),
                                             on_image=on_image, repeat_final_refinement=cfg.repeat_final_refinement)
        if adjustments is not None and choice is not None:
            adjustments.extend(choice.record)
    finally:
        bar.close()
    return models


def map_global(cfg: SfmConfig, db: Path, images: Path, out: Path):
    """{id: Reconstruction} of COLMAP's global mapper (rotation averaging, then global positioning)
    on the matches of ``db`` (written to: pass a copy to keep the original), on one thread and seeded in each
    step (:data:`MAPPING_THREADS`)."""
    pycolmap = load_pycolmap()
    opts = pycolmap.GlobalPipelineOptions()
    opts.num_threads = opts.mapper.num_threads = MAPPING_THREADS
    opts.random_seed = cfg.seed
    opts.min_num_matches = cfg.min_num_matches
    opts.mapper.random_seed = cfg.seed
    opts.mapper.rotation_averaging.random_seed = cfg.seed
    opts.mapper.global_positioning.random_seed = cfg.seed
    out.mkdir(parents=True, exist_ok=True)
    return pycolmap.global_mapping(db, images, out, options=opts)


def model_sizes(models: dict) -> list[int]:
    return sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)


def join_split(cfg: SfmConfig, db: Path, images: Path, out: Path, models: dict, record: dict) -> dict:
    """``models`` (the incremental mapper's {id: Reconstruction}) with the parts that share frames with the
    largest joined into it where they agree (:func:`curate.sfm.parts.join_shared`, within
    ``cfg.max_part_disagreement_deg``), the frames they add triangulated from the matches of ``db`` with every pose
    held (``pycolmap.triangulate_points``, one thread, seeded: :func:`seeded_pipeline_options`; no adjustment after:
    one moved two of the three joined models measured further from the truth, docs/investigations/sfm.md#joined-parts).
    ``record`` gets ``joins`` (one row per other part) and, where one joined, ``joined_sizes`` and ``join_seconds``.
    The joined model is the first of those returned."""
    t = time.perf_counter()
    joined, ids, record["joins"] = join_shared(models, cfg.max_part_disagreement_deg)
    if joined is None:
        return models
    pycolmap = load_pycolmap()
    out.mkdir(parents=True, exist_ok=True)
    rec = pycolmap.triangulate_points(joined, db, images, out, clear_points=False, options=seeded_pipeline_options(cfg),
                                      refine_intrinsics=False)
    anchor = max(models, key=lambda k: models[k].num_reg_images())
    rest = [r for k, r in models.items() if k != anchor and k not in ids]
    found = dict(enumerate([rec] + sorted(rest, key=lambda r: -r.num_reg_images())))
    record["joined_sizes"] = model_sizes(found)
    record["join_seconds"] = round(time.perf_counter() - t, 2)
    logger.warning("sfm: %d part(s) of the split capture share frames with the largest and agree on them: joined, "
                   "%d photos in one model (models %s)", len(ids), rec.num_reg_images(), record["joined_sizes"])
    return found


def map_capture(cfg: SfmConfig, db: Path, images: Path, work: Path, n_images: int, stats: dict):
    """{id: Reconstruction} of the mapper ``cfg.mapper`` chooses; ``stats`` gets ``mapper`` (the one
    kept), when both ran or a part joined ``mappers_tried`` ({mapper: model sizes, seconds}), for the incremental mapper
    ``ba_schedule`` (:func:`map_incremental`'s ``schedule``), and past 1,000 photos
    ``global_adjustments`` (the incremental mapper's solver of each global adjustment, :func:`map_incremental`).

    ``auto`` runs the incremental mapper; where it split, joins to its largest model the parts that share frames
    with it and agree on them (:func:`join_split`: ``mappers_tried.incremental.joins``); when the largest then
    holds less than ``cfg.min_registered_fraction`` of the ``n_images`` photos (the capture split, or frames
    were left out), the global mapper on a copy of the same matches. Its largest model is
    checked against every incremental part (:func:`curate.sfm.parts.part_agreement`, orientation
    disagreement <= ``cfg.max_part_disagreement_deg`` on 90% of the part's photos); where every part it could be
    checked against disagrees, none of it is kept (``mappers_tried.global.refuted``). Of it stay the parts
    it agrees with that :func:`curate.sfm.parts.join_parts` can tie to the largest of them, and the frames
    of no checked part that pass :func:`curate.sfm.parts.verify_frames` against those (against every other
    frame where no part could be checked).
    It replaces the incremental models when it then holds at least ``cfg.min_global_gain`` of the
    ``n_images`` photos (and at least one) more than their largest: on the real walks measured the
    global model is the less accurate, and a take that joins neither model (a foreign one) leaves the
    incremental model short of the pool whatever the mapper, so a gain of a few photos is not worth it.
    """
    tried: dict = {}
    work.mkdir(parents=True, exist_ok=True)
    if cfg.mapper != "global":
        t = time.perf_counter()
        adjustments: list = []
        schedule: dict = {}
        inc = map_incremental(cfg, db, images, work / "incremental", n_images, cfg.progress, adjustments, schedule)
        stats["ba_schedule"] = schedule
        tried["incremental"] = {"model_sizes": model_sizes(inc), "seconds": round(time.perf_counter() - t, 2)}
        if adjustments:
            stats["global_adjustments"] = adjustments
        if cfg.mapper == "auto" and len(inc) > 1:   # the parts that share frames with the largest and agree, joined
            inc = join_split(cfg, db, images, work / "joined", inc, tried["incremental"])
            if "joined_sizes" in tried["incremental"]:   # said where a part joined or the global mapper ran
                stats["mappers_tried"] = tried
        largest = model_sizes(inc)[:1] or [0]
        if cfg.mapper == "incremental" or largest[0] >= cfg.min_registered_fraction * n_images:
            stats["mapper"] = "incremental"
            return inc
        logger.warning("sfm: the largest incremental model holds %d of %d photos (models %s); "
                       "trying the global mapper on the same matches", largest[0], n_images, model_sizes(inc))
    t = time.perf_counter()
    gdb = work / "global.db"
    shutil.copy2(db, gdb)
    glob = map_global(cfg, gdb, images, work / "global")
    tried["global"] = {"model_sizes": model_sizes(glob), "seconds": round(time.perf_counter() - t, 2)}
    if cfg.mapper == "global":
        stats["mapper"] = "global"
        return glob
    stats["mappers_tried"] = tried
    i = (model_sizes(inc)[:1] or [0])[0]
    if not glob or tried["global"]["model_sizes"][0] <= i:
        logger.warning("sfm: the global mapper kept no more photos in one model; keeping the incremental models")
        stats["mapper"] = "incremental"
        return inc
    checks = part_agreement(glob, inc)
    tried["global"]["part_disagreement_deg"] = [d for d, _ in checks]
    ok = [d is not None and d <= cfg.max_part_disagreement_deg for d, _ in checks]
    dis = ", ".join("unchecked (under 10 photos in common)" if d is None else f"{d:g}" for d, _ in checks)
    if any(d is not None for d, _ in checks) and not any(ok):
        # every part it could be checked against says it is bent: none of it can be trusted, its frames' own
        # checks included (they lean on its points: the blurred walk kept 50 frames 141 deg off)
        tried["global"]["refuted"] = True
        logger.warning("sfm: the global mapper's model disagrees with every incremental part it shares 10 photos with "
                       "(deg: %s; limit %g): keeping the incremental models", dis, cfg.max_part_disagreement_deg)
        stats["mapper"] = "incremental"
        return inc
    best = max(glob.values(), key=lambda r: r.num_reg_images())
    refuted: set = set()
    if checks:  # keep of the global model the parts it agrees with and can tie together, and the frames that pass
        placed = {im.name for im in best.images.values() if im.has_pose}
        agreed = [names & placed for (_, names), good in zip(checks, ok) if good]
        refuted = set().union(*(names for (d, names), good in zip(checks, ok) if d is not None and not good))
        keep, joins = join_parts(best, [a for a in agreed if a], cfg.max_part_disagreement_deg)
        unchecked = sorted(placed - keep - refuted - set().union(*agreed))
        verdicts = verify_frames(best, unchecked, cfg.max_part_disagreement_deg, trusted=keep or None)
        passed = {n for n, v in verdicts.items() if v["ok"]}
        keep |= passed
        tried["global"]["verified"] = {"checked": len(unchecked), "kept": len(passed),
                                       "refused": {n: v["why"] for n, v in verdicts.items() if not v["ok"]}}
        tried["global"]["joins"] = joins
        for im in list(best.images.values()):
            if im.name not in keep and im.has_pose:
                best.deregister_frame(im.frame_id)
        tried["global"]["pruned_to"] = int(best.num_reg_images())
    need = max(1, math.ceil(cfg.min_global_gain * n_images - 1e-9)) if i else 1   # no incremental model: any will do
    tried["global"]["gain"], tried["global"]["gain_needed"] = int(best.num_reg_images() - i), need
    if best.num_reg_images() - i < need:
        logger.warning("sfm: the global model keeps %d photos (the incremental parts it agrees with, on "
                       "orientation (90%% of each part's photos, deg: %s; limit %g), where it can tie them "
                       "together, and the frames that pass a check of their own) against the largest incremental "
                       "model's %d: it must keep %d more (%g of the %d photos) to replace it; keeping the "
                       "incremental models", best.num_reg_images(), dis, cfg.max_part_disagreement_deg, i, need,
                       cfg.min_global_gain, n_images)
        stats["mapper"] = "incremental"
        return inc
    ver = tried["global"].get("verified")
    loose = [j for j in tried["global"].get("joins", []) if not j["joined"]]
    logger.warning("sfm: the global mapper keeps %d photos in one model (it agrees with the incremental parts: %s "
                   "deg%s%s)", best.num_reg_images(), dis,
                   "; the parts it disagrees with are left out" if refuted else "",
                   (f"; {len(loose)} part(s) of {sum(j['photos'] for j in loose)} photos left out: too few points "
                    f"tie them to the rest" if loose else "")
                   + (f"; of {ver['checked']} photos no part checks, {ver['kept']} pass a check of their own pose"
                      if ver and ver["checked"] else ""))
    stats["mapper"] = "global"
    return {0: best}
