"""SfM stage: photos -> registered cameras + sparse points (COLMAP through pycolmap).

The only module of curate that imports pycolmap (lazily, inside functions). Later
stages read the results with ``curate.sfm.io.load_sfm`` without pycolmap.

Pipeline (``run_sfm``): ingest (``curate.sfm.ingest``: decode, orient, downscale into
working copies) -> quality (``curate.sfm.quality``: sharpness, near-duplicates; drop per
config) -> SIFT extraction (one shared camera when every photo comes from the same
camera model at the same size, else one camera per photo) -> matching (exhaustive for
small pools, sequential for ordered frames, spatial with GPS; loop detection with a
vocabulary tree trained on the capture itself, never a download, so it works offline; with
several videos, each video's frames are also matched with their most similar frames of the
other videos, ``_match_across_takes``; a video with photos is matched exhaustively) ->
mapping (``map_capture``: incremental, initial pair with >= ``init_min_num_inliers``
verified inliers; when its largest model leaves more than 5% of the photos out, COLMAP's
global mapper on the same matches, kept where it agrees with the incremental parts and holds
more photos) -> optional dense reconstruction (CUDA only). Verification RANSAC, the
mapper and the tree's training sample are seeded (``SfmConfig.seed``): the same photos
and config give the same matches and, up to multi-threaded bundle adjustment, the same
model. ``import_poses`` produces the same outputs from known poses (a transforms.json, a
cameras.json, a COLMAP model; each pose's photo looked up in the photo folder given); poses
that come without 3D points get points triangulated from the photos with the poses held fixed
(``triangulate_known_poses``: the same SIFT extraction and matching, then COLMAP's point
triangulator).

Run-folder contract, ``RUN/sfm/``:

* ``stage.json``: stage record (key, config, versions, timings, statistics); written
  last, a run killed half-way has none and is redone.
* ``images/``: working copies (SfM only), longer side <= ``max_image_size``.
* ``sparse/0/``: COLMAP binary model of the registered images, COLMAP's world frame
  (for an import: the imported cameras at their own intrinsics and names, with the source's points,
  or the points triangulated for them; none with ``triangulate='off'``).
  ``sparse/1/``, ...: the other models of a capture that split, largest first, each in its
  own frame (``stats.parts`` lists them; ``--on-split each`` curates them too).
* ``cameras.json``: the same cameras as ``curate.core.cameras.Cameras`` (OpenCV c2w, same
  world frame), sorted by name; names are the working-copy names (SfM) or the image
  names of the imported model / the ``file_path`` of the imported transforms.json.
  Intrinsics are those of the working copies (SfM) or of the source (import).
* ``transforms.json``: the same cameras in the nerfstudio convention. SfM: file paths
  relative to ``RUN/sfm`` (``images/<working name>``), so ``RUN/sfm`` is a complete
  nerfstudio dataset; import: absolute paths of the original photos.
  ``curate.sfm.io.original_cameras`` maps cameras to the full-resolution originals.
* ``points.npy`` [P, 3] float32 sparse points, ``points_rgb.npy`` [P, 3] uint8,
  ``points_error.npy`` [P] float32 reprojection errors (absent for an import without points).
* ``normalization.json``: ``x_canonical = scale * (x - centre)`` maps the scene into
  [-1, 1]^3 (``curate.sfm.io.normalization``).
* ``images.json``: per input file: original path, working name, status (``kept``,
  ``dropped`` or ``skipped`` with ``reason``), quality metrics, ``registered``, its take
  (``extra.take``: its video, or ``photos`` / ``photos in a/b/`` for the photos of a folder).
  ``stage.json``'s ``stats.takes`` counts per take its frames and those in the model. An import
  lists each pose (its photo, or ``skipped``: no photo in the folder) and the folder's photos no
  pose names (``skipped``).
* ``colmap.log``: COLMAP's own log; ``database.db``: COLMAP's feature database (an import's:
  of the triangulation, at the working size).
* ``dense/fused.ply``: dense point cloud, only with CUDA (``dense='auto'``).
"""

from __future__ import annotations

import contextlib
import logging
import math
import re
import shutil
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras, rotation_angle_deg
from curate.sfm.config import TAKE_MIN_FRACTION, SfmConfig
from curate.sfm.native import load as load_pycolmap
from curate.sfm.io import colmap_from_intrinsics, intrinsics_from_colmap, sfm_dir as _sfm_dir
from curate.sfm.prep import (check_free_space, choose_camera_mode, choose_matcher, input_key, prepare_photos, refuse_inside, take_counts,
                             takes_not_joined, takes_of, too_few_message, write_outputs)
from curate.core.stage import begin_stage, finish_stage, hash_files, stage_key

logger = logging.getLogger(__name__)

__all__ = ["SfmConfig", "run_sfm", "import_poses", "cameras_from_reconstruction"]


# ------------------------------------------------------------------ COLMAP's log
@contextlib.contextmanager
def colmap_log(path: Path):
    """Send COLMAP's (glog) messages to ``path`` instead of the terminal while inside.

    glog appends a timestamp and pid to the destination name, so it writes to
    ``path.part.*`` files that are appended to ``path`` on exit. Errors still reach stderr.
    """
    pycolmap = load_pycolmap()
    L = pycolmap.logging
    saved = (L.logtostderr, L.alsologtostderr, L.stderrthreshold)
    prefix = str(path) + ".part."
    # COLMAP's errors go to the log too: the global mapper logs "Global mapping failed" for parts of
    # runs that succeed; a real failure reaches the user as curate's own error
    L.logtostderr, L.alsologtostderr, L.stderrthreshold = False, False, 3
    for lvl in (L.WARNING, L.ERROR, L.FATAL):
        L.set_log_destination(lvl, "")
    L.set_log_destination(L.INFO, prefix)
    try:
        yield
    finally:
        L.set_log_destination(L.INFO, "")  # closes (and flushes) the file
        L.logtostderr, L.alsologtostderr, L.stderrthreshold = saved
        with open(path, "ab") as dst:
            for part in sorted(path.parent.glob(path.name + ".part.*")):
                dst.write(part.read_bytes())
                part.unlink()


@contextlib.contextmanager
def _stdout_to(path: Path):
    """Redirect the process's stdout file descriptor (C/C++ printf included) to ``path``, appending."""
    import os
    import sys
    sys.stdout.flush()
    saved = os.dup(1)
    with open(path, "ab") as f:
        os.dup2(f.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)


# ------------------------------------------------------------------ conversions
def cameras_from_reconstruction(rec, warn: bool = True) -> tuple[Cameras, np.ndarray, np.ndarray, np.ndarray]:
    """Registered images of a ``pycolmap.Reconstruction`` as project cameras, sorted by name.

    A camera model the project does not hold (fisheye, ...) keeps its pinhole part; that is
    logged as one warning per model with the count of images (``warn``; off for the mapper's
    internal comparisons, which read the same models again).

    pycolmap 4 exposes ``image.cam_from_world()`` (a ``Rigid3d``, world-to-camera); its
    rotation is read as a matrix (``rotation.matrix()``), avoiding the quaternion order
    question (pycolmap stores Eigen ``x y z w``, COLMAP's text files ``w x y z``).

    Returns:
        cameras, points [P, 3] float32, colours [P, 3] uint8, errors [P] float32.
    """
    from curate.core.cameras import c2w_from_w2c

    ids = sorted(rec.reg_image_ids(), key=lambda i: rec.image(i).name)
    R, t, fx, fy, cx, cy, w, h, dist, names = [], [], [], [], [], [], [], [], [], []
    pinhole_only: dict[str, list[str]] = {}           # unsupported model's message -> its images: one line each
    for i in ids:
        im = rec.image(i)
        T = im.cam_from_world()
        R.append(np.asarray(T.rotation.matrix(), np.float64))
        t.append(np.asarray(T.translation, np.float64))
        cam = rec.camera(im.camera_id)
        try:
            f_x, f_y, c_x, c_y, d = intrinsics_from_colmap(cam.model_name, cam.params)
        except ValueError as e:
            pinhole_only.setdefault(str(e), []).append(im.name)
            f_x, f_y, c_x, c_y, d = cam.focal_length_x, cam.focal_length_y, cam.principal_point_x, \
                cam.principal_point_y, np.zeros(4)
        fx.append(f_x), fy.append(f_y), cx.append(c_x), cy.append(c_y), dist.append(d)
        w.append(cam.width), h.append(cam.height), names.append(im.name)
    if warn:
        for msg, ims in pinhole_only.items():
            logger.warning("%d of %d images (%s%s): %s; using the pinhole part only", len(ims), len(ids),
                           ", ".join(ims[:3]), ", ..." if len(ims) > 3 else "", msg)
    if not ids:
        cams = Cameras.empty()
    else:
        cams = Cameras(c2w_from_w2c(np.stack(R), np.stack(t)), np.array(fx), np.array(fy), np.array(cx),
                       np.array(cy), np.array(w), np.array(h), np.array(dist), tuple(names))
    pts3 = list(rec.points3D.values())
    if pts3:
        xyz = np.array([p.xyz for p in pts3], np.float32)
        rgb = np.array([p.color for p in pts3], np.uint8)
        err = np.array([p.error for p in pts3], np.float32)
    else:
        xyz, rgb, err = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), np.zeros(0, np.float32)
    return cams, xyz, rgb, err


def reconstruction_from_cameras(cams: Cameras, keypoints: list | None = None, image_ids: list[int] | None = None,
                                camera_ids: list[int] | None = None):
    """A ``pycolmap.Reconstruction`` holding ``cams`` (no points); cameras with equal intrinsics share one.

    ``keypoints``: per camera, its [K_i, 2] keypoints (pixels) or None. ``image_ids`` / ``camera_ids``:
    per camera, the COLMAP ids to use (default: ``i + 1``, and one per distinct intrinsics).
    """
    pycolmap = load_pycolmap()

    from curate.core.cameras import w2c_from_c2w

    rec = pycolmap.Reconstruction()
    Rw, tw = w2c_from_c2w(cams.c2w)
    cam_ids: dict = {}
    for i in range(len(cams)):
        model, params = colmap_from_intrinsics(cams.fx[i], cams.fy[i], cams.cx[i], cams.cy[i], cams.dist[i])
        key = (model, tuple(params), int(cams.width[i]), int(cams.height[i]))
        if camera_ids is not None:
            key = (camera_ids[i],) + key
        if key not in cam_ids:
            cam_ids[key] = camera_ids[i] if camera_ids is not None else len(cam_ids) + 1
            rec.add_camera_with_trivial_rig(pycolmap.Camera(
                camera_id=cam_ids[key], model=model, width=key[-2], height=key[-1], params=params))
        kw = {} if keypoints is None or keypoints[i] is None else \
            {"keypoints": np.asarray(keypoints[i], np.float64).reshape(-1, 2)}
        im = pycolmap.Image(name=cams.names[i] or f"{i:06d}", camera_id=cam_ids[key],
                            image_id=image_ids[i] if image_ids is not None else i + 1, **kw)
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(Rw[i]), tw[i]))
    return rec


# ------------------------------------------------------------------ SfM
def _extract(cfg: SfmConfig, db: Path, images: Path, names: list[str], single: bool) -> None:
    pycolmap = load_pycolmap()
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = cfg.camera_model
    ext = pycolmap.FeatureExtractionOptions()
    ext.max_image_size = cfg.max_image_size
    ext.num_threads = cfg.num_threads
    ext.sift.max_num_features = cfg.max_num_features
    ext.sift.peak_threshold = cfg.sift_peak_threshold
    mode = pycolmap.CameraMode.SINGLE if single else pycolmap.CameraMode.PER_IMAGE
    # The photos enter the database in name order first, so their ids are too: the extractor's threads
    # finish in any order and number the photos as they finish, and the ids break ties in matching and
    # mapping (office.mp4's same frames, mapped whole in one run and split 357 + 21 in the next).
    pycolmap.Database.open(db).close()
    pycolmap.import_images(db, images, camera_mode=mode, image_names=sorted(names), options=reader)
    pycolmap.extract_features(db, images, image_names=names, camera_mode=mode, reader_options=reader,
                              extraction_options=ext, device=pycolmap.Device.cpu if not pycolmap.has_cuda
                              else pycolmap.Device.auto)


def tree_sample(per_image, n_images: int, max_descriptors: int, rng) -> np.ndarray:
    """[<= max_descriptors, D] float32: an even sample of the descriptors of ``n_images`` images
    (``per_image`` yields each image's [n_i, D] array): at most ``max_descriptors // n_images``
    (8 at least) from each, then at most ``max_descriptors`` in all."""
    cap = max(8, max_descriptors // max(n_images, 1))
    parts = []
    for d in per_image:
        if len(d) > cap:
            d = d[rng.choice(len(d), cap, replace=False)]
        parts.append(d)
    desc = np.concatenate(parts) if parts else np.zeros((0, 128), np.float32)
    if len(desc) > max_descriptors:
        desc = desc[rng.choice(len(desc), max_descriptors, replace=False)]
    return desc


def _build_vocab_tree(db: Path, path: Path, seed: int, max_descriptors: int = 100_000) -> Path:
    """A vocabulary tree (COLMAP ``VisualIndex``) trained on this capture's own SIFT descriptors.

    COLMAP's published trees are downloads; for loop detection within one capture a small
    tree trained on a sample of the capture's own descriptors does as well and keeps the
    stage offline. The sample is at most ``max_descriptors``, drawn evenly from every image,
    and the tree has one visual word per ~40 of them (256 to 2048 for the default), so
    training takes the same time for any pool size; indexing and querying grow linearly
    with the pool. (Training on every image's 1,000 descriptors, with words growing with
    the pool, took 158 s of the office's 210 s of matching, and grows with its square.)
    """
    pycolmap = load_pycolmap()
    rng = np.random.default_rng(seed)
    dbh = pycolmap.Database.open(db)
    images = dbh.read_all_images()

    def descriptors():
        for im in images:
            d = dbh.read_descriptors(im.image_id).to_float()
            yield np.asarray(getattr(d, "data", d), np.float32)

    desc = tree_sample(descriptors(), len(images), max_descriptors, rng)
    dbh.close()
    words = int(np.clip(2 ** np.floor(np.log2(max(len(desc) // 40, 1))), 256, 65536))
    index = pycolmap.VisualIndex.create(128, 64)
    bo = pycolmap.VisualIndex.BuildOptions()
    bo.num_visual_words, bo.num_iterations, bo.num_rounds = words, 25, 1
    t = time.perf_counter()
    with _stdout_to(db.parent / "colmap.log"):  # faiss prints clustering warnings on stdout
        index.build(bo, pycolmap.FeatureDescriptorsFloat(pycolmap.FeatureExtractorType.SIFT, desc))
    index.write(path)
    logger.info("sfm: vocabulary tree of %d words from %d descriptors in %.1f s", words, len(desc),
                time.perf_counter() - t)
    return path


def _match(cfg: SfmConfig, db: Path, matcher: str, takes: dict[str, list[str]] | None = None,
           stats: dict | None = None) -> None:
    """Match and verify the image pairs of ``matcher``; verification RANSAC is seeded by ``cfg.seed``.

    COLMAP's default verification seed (-1) draws a new one per run: the office walk then got
    a different set of verified pairs, and a different model, on every run.

    ``takes`` ({take: image names}, :func:`curate.sfm.prep.takes_of`): with ``sequential`` and two or
    more takes, the frames of each take are also matched with their most similar frames of the other
    takes (:func:`_match_across_takes`; ``stats["cross_take"]`` says how many pairs).
    """
    pycolmap = load_pycolmap()
    mo = pycolmap.FeatureMatchingOptions()
    mo.num_threads = cfg.num_threads
    mo.guided_matching = cfg.guided_matching
    vo = pycolmap.TwoViewGeometryOptions()
    vo.ransac.random_seed = cfg.seed
    vo.min_num_inliers = cfg.min_num_matches
    dev = pycolmap.Device.auto if pycolmap.has_cuda else pycolmap.Device.cpu
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(db, matching_options=mo, verification_options=vo, device=dev)
    elif matcher == "sequential":
        po = pycolmap.SequentialPairingOptions()
        po.overlap = cfg.sequential_overlap
        po.quadratic_overlap = cfg.sequential_quadratic
        po.loop_detection = False
        tree = None
        if cfg.loop_detection:  # with a vocabulary tree built from this capture's own features: offline
            tree = _build_vocab_tree(db, db.parent / "vocab_tree.bin", cfg.seed, cfg.vocab_tree_descriptors)
            po.loop_detection = True
            po.vocab_tree_path = str(tree)
            po.loop_detection_period = cfg.loop_detection_period
            po.loop_detection_num_images = cfg.loop_detection_num_images
        pycolmap.match_sequential(db, matching_options=mo, pairing_options=po, verification_options=vo,
                                  device=dev)
        if cfg.cross_take_matching and takes and len(takes) >= 2:
            if tree is None:
                tree = _build_vocab_tree(db, db.parent / "vocab_tree.bin", cfg.seed, cfg.vocab_tree_descriptors)
            info = _match_across_takes(cfg, db, takes, tree, mo, vo, dev)
            if stats is not None:
                stats["cross_take"] = info
    elif matcher == "spatial":
        po = pycolmap.SpatialPairingOptions()
        po.max_num_neighbors = cfg.spatial_neighbors
        po.ignore_z = True
        pycolmap.match_spatial(db, matching_options=mo, pairing_options=po, verification_options=vo,
                               device=dev)
    else:
        raise ValueError(f"unknown matcher {matcher!r}")


def _match_across_takes(cfg: SfmConfig, db: Path, takes: dict[str, list[str]], tree: Path, mo, vo, dev) -> dict:
    """Match every ``cfg.cross_take_period``-th frame of each take with its ``cfg.cross_take_num_images``
    most similar frames of each other take (:func:`curate.sfm.prep.cross_take_pairs`).

    Sequential matching pairs neighbours in name order, which are frames of one take; its loop
    detection ranks every frame against all others, so a frame's most similar ones are its own take's
    neighbours and a second take seldom gets in. Here the ranking (COLMAP's vocabulary-tree retrieval with
    the capture's own ``tree``, all frames indexed) is read to its end for each queried frame and only
    the other takes' best frames are kept: (frames / period) x num_images x (takes - 1) pairs at most,
    linear in the frames. Returns {"queries", "pairs", "new_pairs", "verified", "unlisted", "seconds"}.
    """
    pycolmap = load_pycolmap()

    from curate.sfm.prep import cross_take_pairs
    t0 = time.perf_counter()
    take_of = {n: t for t, names in takes.items() for n in names}
    dbh = pycolmap.Database.open(db)
    try:
        ids = {im.name: im.image_id for im in dbh.read_all_images() if im.name in take_of}
        name_of = {i: n for n, i in ids.items()}
        queries = [ids[n] for names in takes.values() for n in names[::cfg.cross_take_period] if n in ids]
        opts = pycolmap.VocabTreePairingOptions()
        opts.vocab_tree_path = str(tree)
        opts.num_images = len(ids)          # the whole ranking: the other takes' best may rank after the own take
        opts.num_threads = cfg.num_threads
        with _stdout_to(db.parent / "colmap.log"):
            gen = pycolmap.VocabTreePairGenerator(opts, dbh, queries)

            def ranked():
                while not gen.has_finished():
                    block = gen.next()  # one queried frame: (query, candidate) pairs, most similar first
                    if block:
                        yield name_of.get(block[0][0]), [name_of.get(b) for _, b in block]
            pairs = cross_take_pairs(((q, c) for q, c in ranked() if q is not None), take_of,
                                     cfg.cross_take_num_images)
        new = [(a, b) for a, b in pairs if not dbh.exists_matches(ids[a], ids[b])]
    finally:
        dbh.close()
    # COLMAP's pair list separates names by spaces: a name holding one cannot be listed
    listed = [(a, b) for a, b in new if not any(c.isspace() for c in a + b)]
    if len(listed) < len(new):
        logger.warning("sfm: %d of %d cross-take pairs left unmatched: COLMAP's pair list cannot name photos "
                       "with spaces in their names", len(new) - len(listed), len(new))
    before = _pair_counts(db, cfg.min_num_matches)[1]
    if listed:
        path = db.parent / "cross_take_pairs.txt"
        path.write_text("".join(f"{a} {b}\n" for a, b in listed))
        po = pycolmap.ImportedPairingOptions()
        po.match_list_path = str(path)
        pycolmap.match_image_pairs(db, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)
    info = {"queries": len(queries), "pairs": len(pairs), "new_pairs": len(new),
            "verified": _pair_counts(db, cfg.min_num_matches)[1] - before, "unlisted": len(new) - len(listed),
            "seconds": round(time.perf_counter() - t0, 2)}
    logger.info("sfm: cross-take matching (%d takes): %d frames queried, %d new pairs, %d verified in %.1f s",
                len(takes), info["queries"], info["new_pairs"], info["verified"], info["seconds"])
    return info


def _pair_counts(db: Path, min_num_matches: int) -> tuple[int, int]:
    """(image pairs of ``db`` with a two-view geometry, those with at least ``min_num_matches`` verified inliers)."""
    pycolmap = load_pycolmap()
    dbh = pycolmap.Database.open(db)
    try:
        _, inliers = dbh.read_two_view_geometry_num_inliers()
    finally:
        dbh.close()
    return len(inliers), int(sum(n >= min_num_matches for n in inliers))


def _seeded_pipeline_options(cfg: SfmConfig):
    """COLMAP's incremental pipeline options with ``cfg``'s threads, seed (mapper and triangulation) and
    minimum matches: what mapping and the triangulation of known poses share."""
    pycolmap = load_pycolmap()
    opts = pycolmap.IncrementalPipelineOptions()
    opts.num_threads = cfg.num_threads
    opts.random_seed = cfg.seed
    opts.mapper.random_seed = cfg.seed
    opts.triangulation.random_seed = cfg.seed
    opts.min_num_matches = cfg.min_num_matches
    return opts


def incremental_options(cfg: SfmConfig, n_images: int):
    """The incremental mapper's options for a pool of ``n_images`` photos: :func:`_seeded_pipeline_options`,
    the initial pair's inliers (``cfg.init_min_num_inliers``), the principal point held; past
    ``cfg.global_ba_above`` photos, a global bundle adjustment each time the model grows by the factor
    ``cfg.global_ba_growth`` (COLMAP: 1.1), refined ``cfg.global_ba_refinements`` times at most (COLMAP: 5).
    Each new photo's local adjustment keeps COLMAP's two refinements (one folded office.mp4 cut into two
    takes: docs/sfm.md).

    The global adjustments are most of the incremental mapper's time on a long capture (the rendered
    1,000-frame walk: 79% of its mapping) and what makes it grow faster than the pool (docs/sfm.md,
    "Mapping past 1,000 photos")."""
    opts = _seeded_pipeline_options(cfg)
    opts.mapper.init_min_num_inliers = cfg.init_min_num_inliers
    opts.ba_refine_principal_point = False
    if n_images > cfg.global_ba_above:
        opts.ba_global_frames_ratio = opts.ba_global_points_ratio = cfg.global_ba_growth
        opts.ba_global_max_refinements = cfg.global_ba_refinements
    return opts


def _map(cfg: SfmConfig, db: Path, images: Path, out: Path, n_images: int, progress: bool,
         adjustments: list | None = None):
    """{id: Reconstruction} of COLMAP's incremental mapper on the matches of ``db``, with curate's options
    (:func:`incremental_options`). Pools of more photos than Ceres' direct-solve limit (1,000) are mapped by
    :func:`curate.sfm.mapping.incremental_mapping`, the same steps with each global adjustment's solver chosen
    from the model's shape (``cfg.direct_ba_max_fill``); ``adjustments`` (when given) gets one record per
    global adjustment past the limit (photos, fill per photo, solver, seconds)."""
    pycolmap = load_pycolmap()
    from tqdm import tqdm

    from curate.sfm import mapping
    opts = incremental_options(cfg, n_images)
    limit = mapping.ceres_direct_limit()
    bar = tqdm(total=n_images, desc="mapping", unit="img", disable=not progress, leave=False)
    count = [0]

    def on_image(k: int = 1):  # registrations over all models: the bar stops at the pool size
        k = min(k, n_images - count[0])
        count[0] += k
        bar.update(k)

    try:
        if n_images > limit and cfg.direct_ba_max_fill > 0:
            choice = mapping.SolverChoice(cfg.direct_ba_max_fill, limit)
            models = mapping.incremental_mapping(db, images, out, opts, choice, on_pair=lambda: on_image(2),
                                                 on_image=on_image)
            if adjustments is not None:
                adjustments.extend(choice.record)
        else:
            models = pycolmap.incremental_mapping(db, images, out, options=opts, initial_image_pair_callback=
                                                  lambda: on_image(2), next_image_callback=on_image)
    finally:
        bar.close()
    return models


def _map_global(cfg: SfmConfig, db: Path, images: Path, out: Path):
    """{id: Reconstruction} of COLMAP's global mapper (rotation averaging, then global positioning)
    on the matches of ``db`` (written to: pass a copy to keep the original)."""
    pycolmap = load_pycolmap()
    opts = pycolmap.GlobalPipelineOptions()
    opts.num_threads = cfg.num_threads
    opts.random_seed = cfg.seed
    opts.min_num_matches = cfg.min_num_matches
    opts.mapper.random_seed = cfg.seed
    out.mkdir(parents=True, exist_ok=True)
    return pycolmap.global_mapping(db, images, out, options=opts)


def _sizes(models: dict) -> list[int]:
    return sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)


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


def _video_takes(rec, when: dict) -> dict[str, list]:
    """{take: [(time, Image)] in time order} of the registered frames of ``rec`` that ``when``
    ({name: (take, time)}, :func:`_frame_times`) places in time: video frames, numbered photos."""
    takes: dict[str, list] = {}
    for im in rec.images.values():
        if im.has_pose and im.name in when:
            takes.setdefault(when[im.name][0], []).append((when[im.name][1], im))
    for frames in takes.values():
        frames.sort(key=lambda x: x[0])
    return dict(sorted(takes.items()))


def _frame_times(kept: list, numbered: bool = False) -> dict:
    """{working name: (take, seconds)} of the video frames among the PhotoRecords ``kept``; with
    ``numbered``, also the photos of each photo take (:func:`curate.sfm.prep.take_name`) whose names
    are numbered frames (:func:`curate.sfm.prep.looks_sequential`, which also makes them matched in
    sequence), their number standing for the time (a photo dropped or deleted between two is a
    longer time, not a faster step)."""
    from curate.sfm.prep import _trailing_number, looks_sequential, take_name
    out = {r.working: (r.extra["video_rel"], float(r.extra["time"])) for r in kept
           if r.extra.get("video_rel") is not None and r.extra.get("time") is not None}
    if numbered:
        takes: dict[str, list] = {}
        for r in kept:
            if r.working not in out and not r.extra.get("video"):
                takes.setdefault(take_name(r), []).append(r)
        for take, recs in takes.items():
            recs.sort(key=lambda r: r.rel)
            if looks_sequential([Path(r.rel).name for r in recs]):
                out.update((r.working, (take, float(_trailing_number(Path(r.rel).name)[1]))) for r in recs)
    return out


def _along(frames: list) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([x[0] for x in frames]), np.array([np.asarray(im.projection_center()) for _, im in frames]))


def drop_off_path(models: dict, kept: list) -> dict[str, list[str]]:
    """Deregister, in every model ({id: Reconstruction}), the video frames :func:`curate.sfm.continuity.off_path`
    finds on an island off their take's path; ``kept``: the PhotoRecords (a frame's ``extra`` holds its
    ``video_rel`` and ``time``). Returns {take: [names]} of the frames left out."""
    from curate.sfm.continuity import off_path
    when = _frame_times(kept)
    out: dict[str, list[str]] = {}
    for rec in models.values():
        for tk, frames in _video_takes(rec, when).items():
            for i in off_path(*_along(frames)):
                rec.deregister_frame(frames[i][1].frame_id)
                out.setdefault(tk, []).append(frames[i][1].name)
    return out


def jumps_along(rec, kept: list) -> dict[str, list[dict]]:
    """{take: [{"from", "to", "x_around"}]}: the one-way jumps (:func:`curate.sfm.continuity.path_jumps`)
    of every video take in the model ``rec``, and of every take of numbered photos (in name order:
    frames a user extracted from a video), each between two consecutive registered frames, at
    ``x_around`` times the speed around the step (``step_ratios``). Run after :func:`drop_off_path`
    (which leaves numbered photos alone: only a warning rests on their order)."""
    from curate.sfm.continuity import path_jumps
    out: dict[str, list[dict]] = {}
    for tk, frames in _video_takes(rec, _frame_times(kept, numbered=True)).items():
        for i, r in path_jumps(*_along(frames)):
            out.setdefault(tk, []).append({"from": frames[i - 1][1].name, "to": frames[i][1].name,
                                           "x_around": round(r, 1) if np.isfinite(r) else None})
    return out


def map_capture(cfg: SfmConfig, db: Path, images: Path, work: Path, n_images: int, stats: dict):
    """{id: Reconstruction} of the mapper ``cfg.mapper`` chooses; ``stats`` gets ``mapper`` (the one
    kept), when both ran ``mappers_tried`` ({mapper: model sizes, seconds}), and past 1,000 photos
    ``global_adjustments`` (the incremental mapper's solver of each global adjustment, :func:`_map`).

    ``auto`` runs the incremental mapper and, when its largest model holds less than
    ``cfg.min_registered_fraction`` of the ``n_images`` photos (the capture split, or frames
    were left out), the global mapper on a copy of the same matches. Its largest model is
    checked against every incremental part (:func:`part_agreement`, orientation disagreement <=
    ``cfg.max_part_disagreement_deg`` on 90% of the part's photos). Of it stay the parts it agrees
    with that :func:`join_parts` can tie to the largest of them, and the frames of no checked part
    that pass :func:`verify_frames` against those (against every other frame where no part agrees).
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
        inc = _map(cfg, db, images, work / "incremental", n_images, cfg.progress, adjustments)
        tried["incremental"] = {"model_sizes": _sizes(inc), "seconds": round(time.perf_counter() - t, 2)}
        if adjustments:
            stats["global_adjustments"] = adjustments
        largest = tried["incremental"]["model_sizes"][:1] or [0]
        if cfg.mapper == "incremental" or largest[0] >= cfg.min_registered_fraction * n_images:
            stats["mapper"] = "incremental"
            return inc
        logger.warning("sfm: the incremental mapper kept %d of %d photos in its largest model (models %s); "
                       "trying the global mapper on the same matches", largest[0], n_images,
                       tried["incremental"]["model_sizes"])
    t = time.perf_counter()
    gdb = work / "global.db"
    shutil.copy2(db, gdb)
    glob = _map_global(cfg, gdb, images, work / "global")
    tried["global"] = {"model_sizes": _sizes(glob), "seconds": round(time.perf_counter() - t, 2)}
    if cfg.mapper == "global":
        stats["mapper"] = "global"
        return glob
    stats["mappers_tried"] = tried
    i = (tried["incremental"]["model_sizes"][:1] or [0])[0]
    if not glob or tried["global"]["model_sizes"][0] <= i:
        logger.warning("sfm: the global mapper kept no more photos in one model; keeping the incremental models")
        stats["mapper"] = "incremental"
        return inc
    checks = part_agreement(glob, inc)
    tried["global"]["part_disagreement_deg"] = [d for d, _ in checks]
    ok = [d is not None and d <= cfg.max_part_disagreement_deg for d, _ in checks]
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
    dis = ", ".join("unchecked (under 10 photos in common)" if d is None else f"{d:g}"
                    for d in tried["global"]["part_disagreement_deg"])
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


def run_sfm(cfg: SfmConfig, photos: str | Path, run_dir: str | Path, force: bool = False) -> Path:
    """:func:`_run_sfm` in the claimed and locked run folder (:mod:`curate.core.runfolder`)."""
    from curate.core.runfolder import claimed  # runsafe
    with claimed(run_dir, [photos]):
        return _run_sfm(cfg, photos, run_dir, force)


def _run_sfm(cfg: SfmConfig, photos: str | Path, run_dir: str | Path, force: bool = False) -> Path:
    """Run the SfM stage on the photos of ``photos``; returns ``RUN/sfm`` (see the module docstring).

    Skipped (returns at once) when ``RUN/sfm/stage.json`` has the same key: same config
    (``num_threads`` and ``progress`` excluded) and same photo files (names and content).
    """
    pycolmap = load_pycolmap()

    photos, run_dir = Path(photos).resolve(), Path(run_dir).resolve()
    out = _sfm_dir(run_dir)
    refuse_inside(out, photos)
    key = input_key(cfg, photos)
    if begin_stage(out, key, force):
        logger.info("sfm: up to date (%s), skipped", out)
        return out
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
    check_free_space(out, len(names), matcher, cfg)     # COLMAP aborts the process on a full disk
    db, images = out / "database.db", out / "images"
    stats: dict = {"n_input_files": len(records), "n_kept": len(names), "camera_mode": "single" if single else
                   "per_image", "matcher": matcher, **({"videos": videos} if videos else {})}
    pycolmap.set_random_seed(cfg.seed)
    with colmap_log(out / "colmap.log"):
        logger.info("sfm: extracting SIFT features (%s camera, %s) ...", stats["camera_mode"], cfg.camera_model)
        t = time.perf_counter()
        _extract(cfg, db, images, names, single)
        timings["extract"] = round(time.perf_counter() - t, 2)
        logger.info("sfm: features extracted for %d images in %.1f s", len(names), timings["extract"])
        logger.info("sfm: %s matching ...", matcher)
        t = time.perf_counter()
        _match(cfg, db, matcher, takes_of(kept), stats)
        timings["match"] = round(time.perf_counter() - t, 2)
        stats["n_pairs_matched"], stats["n_pairs_verified"] = _pair_counts(db, cfg.min_num_matches)
        logger.info("sfm: %s matching, %d of %d pairs verified in %.1f s", matcher, stats["n_pairs_verified"],
                    stats["n_pairs_matched"], timings["match"])
        t = time.perf_counter()
        models = map_capture(cfg, db, images, out / "mapper", len(names), stats)
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
    best = max(models.values(), key=lambda r: r.num_reg_images())
    jumps = jumps_along(best, kept)
    if jumps:
        stats["path_jumps"] = jumps
    stats["model_sizes"] = _sizes(models)
    sparse = out / "sparse" / "0"
    sparse.mkdir(parents=True)
    best.write(sparse)
    others = sorted((r for r in models.values() if r is not best and r.num_reg_images() >= 2),
                    key=lambda r: -r.num_reg_images())
    for k, r in enumerate(others, 1):  # the other parts of a split capture, for --on-split each
        (out / "sparse" / str(k)).mkdir()
        r.write(out / "sparse" / str(k))
    stats["parts"] = [{"model": f"sparse/{k}", "n_registered": int(r.num_reg_images())}
                      for k, r in enumerate([best] + others)]
    for part, r in zip(stats["parts"][1:], others):   # --on-split each curates them: a fold there is named too
        if j := jumps_along(r, kept):
            part["path_jumps"] = j
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
    finish_stage(out, key, cfg, started, outputs={"sparse": "sparse/0", "cameras": "cameras.json"},
                 seed=cfg.seed, mode="sfm", photos=str(photos), timings=timings, stats=stats)
    return out


# ------------------------------------------------------------------ import
def raw_quaternions(model: Path) -> list[tuple[Path, str, np.ndarray]]:
    """(file, image name, [4] quaternion as written) of every image of the model in ``model`` (``images.bin`` or
    ``images.txt``), before pycolmap normalises them; [] when neither is readable."""
    import struct
    out = []
    b, t = model / "images.bin", model / "images.txt"
    try:
        if b.is_file():
            data = b.read_bytes()
            (n,), o = struct.unpack_from("<Q", data, 0), 8
            for _ in range(n):
                q = np.array(struct.unpack_from("<4d", data, o + 4))
                o += 4 + 32 + 24 + 4
                end = data.index(b"\0", o)
                name = data[o:end].decode("utf-8", "replace")
                o = end + 1
                (k,) = struct.unpack_from("<Q", data, o)
                o += 8 + 24 * k
                out.append((b, name, q))
        elif t.is_file():
            from curate.sfm.io import images_txt_rows
            out = [(t, name, np.array(q)) for name, q, _, _ in images_txt_rows(t, errors="replace")]
    except (OSError, ValueError, struct.error, IndexError):
        return out      # a broken file: pycolmap has already said so, or reads what there is
    return out


def read_colmap_model(model: Path, photos: Path | None):
    """A COLMAP model folder as :class:`curate.sfm.poses.Poses` (image paths under ``photos`` when given)."""
    pycolmap = load_pycolmap()
    from curate.sfm.poses import Poses
    try:
        rec = pycolmap.Reconstruction(model)
    except Exception as e:  # noqa: BLE001 - pycolmap raises its own error types
        said = re.sub(r"\[[\w./-]+:\d+\] Check failed: ", "COLMAP's check of ", str(e)).strip()
        raise ValueError(f"{model}: cannot read the COLMAP model ({said})") from None
    bad = [(f, n) for f, n, q in raw_quaternions(Path(model))
           if not (np.all(np.isfinite(q)) and np.linalg.norm(q) > 1e-6)]
    if bad:   # pycolmap normalises a zero quaternion to the identity: a made-up pose, never a silent one
        raise ValueError(f"{bad[0][0]}: image {bad[0][1]} has a rotation quaternion of zero length or not finite "
                         f"({len(bad)} image(s)); fix or remove it")
    cams, xyz, rgb, err = cameras_from_reconstruction(rec)
    files = [str((photos / n).resolve()) if photos is not None else n for n in cams.names]
    return Poses(cams, files, xyz, rgb, err, rec)


def read_cameras(source: str | Path, photos: str | Path | None = None) -> tuple[Cameras, list[str]]:
    """Cameras of a pose source (:func:`curate.sfm.poses.read_poses`), without writing anything:
    (cameras, image paths)."""
    from curate.sfm.poses import read_poses
    p = read_poses(source, photos)
    return p.cameras, p.files


def import_poses(cfg: SfmConfig, source: str | Path, run_dir: str | Path, photos: str | Path | None = None,
                 force: bool = False) -> Path:
    """:func:`_import_poses` in the claimed and locked run folder (:mod:`curate.core.runfolder`)."""
    from curate.core.runfolder import claimed  # runsafe
    with claimed(run_dir, [source, photos]):
        return _import_poses(cfg, source, run_dir, photos, force)


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
    from curate.sfm.ingest import probe_image
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
    m = match_photos(names, poses.files, folder, cfg.recursive)
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
    from curate.sfm.video import VIDEO_EXTS
    left += [{"original": str(p), "rel": p.relative_to(folder).as_posix(), "status": "skipped",
              "reason": ("a video: its frames have no names the poses could refer to" if p.suffix.lower() in VIDEO_EXTS
                         else f"no pose in {source} names this photo"), "working": "", "registered": False}
             for p in unposed]
    stats = {"folder": str(folder), "given": photos is not None, "n_poses": len(names), "n_matched": len(idx),
             "n_by_name": sum(m.how[i] == "name" for i in idx), "n_photos": m.n_photos if photos is not None else None,
             "n_unposed": len(unposed) if photos is not None else None,
             "poses_without_photo": [names[i] for i in range(len(names)) if m.files[i] is None][:50],
             "photos_without_pose": [p.relative_to(folder).as_posix() for p in unposed][:50]}
    if len(idx) < len(names):
        logger.warning("sfm import: %d of the %d poses of %s have no photo in %s (left out), e.g. %s", len(names) - len(idx),
                       len(names), source, folder, _examples(stats["poses_without_photo"]))
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


def _import_poses(cfg: SfmConfig, source: str | Path, run_dir: str | Path, photos: str | Path | None = None,
                  force: bool = False) -> Path:
    """Fill ``RUN/sfm`` from known poses instead of running SfM; returns ``RUN/sfm``.

    Args:
        source: a pose source (:func:`curate.sfm.poses.read_poses`: a transforms.json, a cameras.json, a
            COLMAP model folder, a folder holding one of them).
        photos: the folder of the photos the poses describe: each pose's photo is looked up there
            (:func:`curate.sfm.poses.match_photos`); poses without a photo, and photos without a pose,
            are left out and listed in ``images.json``; none matching is an error. Without it, a COLMAP
            model's usual ``images/`` folder, else the pose file's own image paths.

    With no 3D points in the source and ``cfg.triangulate == "auto"``, points are triangulated from
    the photos with the poses held fixed (:func:`triangulate_known_poses`).
    """
    from curate.sfm.poses import read_poses
    source = Path(source).resolve()
    photos = Path(photos).resolve() if photos is not None else None
    run_dir = Path(run_dir).resolve()
    out = _sfm_dir(run_dir)
    if photos is not None:
        _check_photo_folder(photos, source)
        refuse_inside(out, photos)
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
    if begin_stage(out, key, force):
        logger.info("sfm import: up to date (%s), skipped", out)
        return out
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
            sparse.mkdir(parents=True)
            rec.write(sparse)
        _, xyz, rgb, err = cameras_from_reconstruction(rec)
        stats["triangulation"] = {"status": "source", "reason": "the source has 3D points"}
    elif triangulate:
        rec, stats["triangulation"] = triangulate_known_poses(cfg, cams, originals, out)
        sparse.mkdir(parents=True)
        rec.write(sparse)
        _, xyz, rgb, err = cameras_from_reconstruction(rec)
    else:
        reason = ("--triangulate off" if cfg.triangulate == "off" else
                  "fewer than 2 readable photos (image names without a photo folder)")
        stats["triangulation"] = {"status": "off" if cfg.triangulate == "off" else "skipped", "reason": reason}
        rec = reconstruction_from_cameras(cams)
        sparse.mkdir(parents=True)
        rec.write(sparse)
        xyz = rgb = err = None
    stats.update(write_outputs(out, cams, xyz, rgb, err, records + left, originals, cfg.normalize_percentile))
    finish_stage(out, key, cfg, started, outputs={"sparse": "sparse/0", "cameras": "cameras.json"},
                 mode="import", source=str(source), photos=str(photos) if photos else None, stats=stats)
    logger.info("sfm import: %d cameras, %d points from %s", len(cams), stats["n_points"], source)
    return out


def pycolmap_reconstruction(path: str | Path):
    """The COLMAP model at ``path`` (pycolmap stays inside this module)."""
    pycolmap = load_pycolmap()
    return pycolmap.Reconstruction(str(path))


# ------------------------------------------------------------------ points for known poses
def _working_copy(src: str, dst: Path, size: tuple[int, int]) -> None:
    """``dst``: the photo ``src`` upright at ``size`` (width, height), JPEG (quality 95) or PNG by ``dst``'s
    suffix; the original's bytes when nothing changes."""
    from PIL import Image

    from curate.sfm.ingest import RAW_EXTS, decode_upright, read_image
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
    longer side at most ``cfg.max_image_size``, removed afterwards): SIFT features (:func:`_extract`,
    one camera when every image has the same intrinsics), matches verified as SfM verifies them
    (:func:`_match`, the matcher :func:`curate.sfm.prep.choose_matcher` picks; in one thread, so that the same
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

    from curate.sfm.ingest import PhotoRecord
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
            _extract(cfg, db, images, [names[i] for i in usable], single)
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
            _match(replace(cfg, num_threads=1), db, matcher)   # one thread: the same points on every run
            stats["match_seconds"] = round(time.perf_counter() - t, 2)
            stats["n_pairs_verified"] = _pair_counts(db, cfg.min_num_matches)[1]
            sub = cams[kept]
            work_cams = Cameras(sub.c2w, np.array([wk[i][0] for i in kept]), np.array([wk[i][1] for i in kept]),
                                np.array([wk[i][2] for i in kept]), np.array([wk[i][3] for i in kept]),
                                ww[kept], hh[kept], sub.dist, tuple(names[i] for i in kept))
            rec = reconstruction_from_cameras(work_cams, image_ids=[dbim[names[i]].image_id for i in kept],
                                              camera_ids=[dbim[names[i]].camera_id for i in kept])
            opts = _seeded_pipeline_options(replace(cfg, num_threads=1))   # its adjustment too: the same bytes
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


# ------------------------------------------------------------------ subset export
def write_subset_model(sparse_dir: str | Path, keep_names: list[str], out_dir: str | Path,
                       rename: dict[str, str] | None = None, sizes: dict[str, tuple[int, int]] | None = None,
                       min_track: int = 2, min_shared: int = 15) -> dict:
    """Write a COLMAP binary model holding only the images ``keep_names`` of the model in ``sparse_dir``.

    Same world frame and poses as the source. Each kept image keeps all its keypoints;
    a 3D point is kept when at least ``min_track`` kept images observe it (default 2: a
    point seen by one image only is not triangulated by that subset), with only those
    observations in its track; reprojection errors are recomputed.

    Args:
        sparse_dir: source model folder (binary or text), e.g. ``RUN/sfm/sparse/0``, or a ``pycolmap.Reconstruction``.
        keep_names: image names of the source model to keep (unknown names: ``ValueError``).
        out_dir: folder written (created): ``cameras.bin images.bin points3D.bin`` (+ rigs/frames).
        rename: optional source name -> name written in the new model (e.g. the original photo's).
        sizes: optional source name -> (width, height) of the images the new model describes
            (the originals): the camera is rescaled per axis (focal length and principal point;
            a single-focal model takes the mean scale) and the keypoints with it.
        min_track: fewest kept observations for a 3D point to be kept.
        min_shared: two kept images are connected when they observe at least this many kept
            points in common (COLMAP's fewest verified matches of a pair, 15 by default).

    Returns:
        {"n_images", "n_cameras", "n_points3D", "n_points3D_source", "n_images_with_points" (kept images
        observing at least one kept point), "components"}: ``components``,
        the sizes of the groups of kept images connected through shared points (largest first;
        one group: the subset is one connected set that 3DGS / NeRF tools can register as a whole).
    """
    pycolmap = load_pycolmap()

    src = pycolmap.Reconstruction(str(sparse_dir)) if isinstance(sparse_dir, (str, Path)) else sparse_dir
    rename, sizes = rename or {}, sizes or {}
    by_name = {src.image(i).name: i for i in src.reg_image_ids()}
    missing = [n for n in keep_names if n not in by_name]
    if missing:
        raise ValueError(f"{len(missing)} image(s) not in the model {sparse_dir}: {missing[:5]}")
    rec = pycolmap.Reconstruction()
    cam_ids: dict = {}
    keep_ids = set()
    for n in dict.fromkeys(keep_names):
        iid = by_name[n]
        im = src.image(iid)
        cam = src.camera(im.camera_id)
        w, h = sizes.get(n, (cam.width, cam.height))
        sx, sy = w / cam.width, h / cam.height
        key = (im.camera_id, int(w), int(h))
        if key not in cam_ids:
            new = pycolmap.Camera(camera_id=len(cam_ids) + 1, model=cam.model_name, width=cam.width,
                                  height=cam.height, params=list(cam.params))
            if (w, h) != (cam.width, cam.height):
                new.rescale(int(w), int(h))
            cam_ids[key] = new.camera_id
            rec.add_camera_with_trivial_rig(new)
        xy = np.array([p.xy for p in im.points2D], np.float64).reshape(-1, 2) * [sx, sy]
        out_im = pycolmap.Image(name=rename.get(n, n), keypoints=xy, camera_id=cam_ids[key], image_id=iid)
        rec.add_image_with_trivial_frame(out_im, im.cam_from_world())
        keep_ids.add(iid)
    shared: dict[tuple[int, int], int] = {}
    seeing: set[int] = set()
    for p in src.points3D.values():
        els = [e for e in p.track.elements if e.image_id in keep_ids]
        ids = sorted({e.image_id for e in els})
        if len(ids) >= min_track:
            rec.add_point3D(p.xyz, pycolmap.Track(els), p.color)
            seeing.update(ids)
            for a in range(len(ids)):
                for b in range(a + 1, len(ids)):
                    shared[(ids[a], ids[b])] = shared.get((ids[a], ids[b]), 0) + 1
    components = covisible_groups(sorted(keep_ids), [e for e, n in shared.items() if n >= min_shared])
    rec.update_point_3d_errors()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rec.write_binary(str(out_dir))
    logger.info("subset model: %d images, %d of %d points -> %s", rec.num_reg_images(), rec.num_points3D(),
                src.num_points3D(), out_dir)
    return {"n_images": rec.num_reg_images(), "n_cameras": rec.num_cameras(), "n_points3D": rec.num_points3D(),
            "n_points3D_source": src.num_points3D(), "n_images_with_points": len(seeing), "components": components}


def covisible_groups(nodes: list[int], edges: list[tuple[int, int]]) -> list[int]:
    """Sizes of the connected components of the graph (``nodes``, ``edges``), largest first."""
    parent = {n: n for n in nodes}

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    for a, b in edges:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
    sizes: dict[int, int] = {}
    for n in nodes:
        r = find(n)
        sizes[r] = sizes.get(r, 0) + 1
    return sorted(sizes.values(), reverse=True)
