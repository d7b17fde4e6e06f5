"""SIFT features into COLMAP's database, and read back for the capture's own visual words
(:mod:`curate.sfm.retrieval`: loop detection, retrieval matching, the pairs between takes).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from curate.sfm.config import SfmConfig
from curate.sfm.native import load as load_pycolmap

logger = logging.getLogger(__name__)


def extract(cfg: SfmConfig, db: Path, images: Path, names: list[str], single: bool) -> dict[str, int]:
    """SIFT features of ``names`` (working copies in ``images``) into ``db``.

    COLMAP's SIFT doubles each image first (its first octave -1), about three quarters of the extraction's work. A
    working copy whose longer side is at least ``cfg.sift_upsample_below`` is first read as it is; where that gives
    at least ``cfg.sift_min_features_undoubled`` features they are kept, else (a dark or plain photo) the photo is
    read again doubled, as COLMAP does. Returns ``{"doubled": n, "not_doubled": m}``."""
    pycolmap = load_pycolmap()
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = cfg.camera_model
    mode = pycolmap.CameraMode.SINGLE if single else pycolmap.CameraMode.PER_IMAGE
    # The photos enter the database in name order first, so their ids are too: the extractor's threads
    # finish in any order and number the photos as they finish, and the ids break ties in matching and
    # mapping (office.mp4's same frames, mapped whole in one run and split 357 + 21 in the next).
    pycolmap.Database.open(db).close()
    pycolmap.import_images(db, images, camera_mode=mode, image_names=sorted(names), options=reader)
    large = sorted(n for n, side in _longer_sides(pycolmap, db, names).items() if not doubled(cfg, side))
    kept: set[str] = set()
    if large:
        first = db.with_name(db.stem + ".undoubled.db")       # the first pass's own database, removed after
        leftovers = [first, *(first.with_name(first.name + x) for x in ("-wal", "-shm", "-journal"))]
        for f in leftovers:
            f.unlink(missing_ok=True)
        try:
            pycolmap.Database.open(first).close()
            pycolmap.import_images(first, images, camera_mode=mode, image_names=large, options=reader)
            _extract(pycolmap, cfg, first, images, large, mode, reader, octave=0)
            src, dst = pycolmap.Database.open(first), pycolmap.Database.open(db)
            try:
                ids = {im.name: im.image_id for im in dst.read_all_images()}
                for im in src.read_all_images():
                    if src.num_keypoints_for_image(im.image_id) >= cfg.sift_min_features_undoubled:
                        dst.write_keypoints(ids[im.name], src.read_keypoints(im.image_id))
                        dst.write_descriptors(ids[im.name], src.read_descriptors(im.image_id))
                        kept.add(im.name)
            finally:
                src.close()
                dst.close()
        finally:
            for f in leftovers:
                f.unlink(missing_ok=True)
    rest = [n for n in names if n not in kept]
    if rest:
        _extract(pycolmap, cfg, db, images, rest, mode, reader, octave=-1)
    if large:
        logger.info("sfm: %d of %d photos read as they are (SIFT's doubled octave left out), %d doubled",
                    len(kept), len(names), len(rest))
    return {"doubled": len(rest), "not_doubled": len(kept)}


def _extract(pycolmap, cfg: SfmConfig, db: Path, images: Path, names: list[str], mode, reader, octave: int) -> None:
    ext = pycolmap.FeatureExtractionOptions()
    ext.max_image_size = cfg.max_image_size
    ext.num_threads = cfg.num_threads
    ext.sift.max_num_features = cfg.max_num_features
    ext.sift.peak_threshold = cfg.sift_peak_threshold
    ext.sift.first_octave = octave
    pycolmap.extract_features(db, images, image_names=names, camera_mode=mode, reader_options=reader,
                              extraction_options=ext, device=pycolmap.Device.cpu if not pycolmap.has_cuda
                              else pycolmap.Device.auto)


def doubled(cfg: SfmConfig, side: int) -> bool:
    """Whether SIFT first reads a working copy whose longer side is ``side`` px doubled (its first octave -1,
    COLMAP's default): where that side, as SIFT reads it (at most ``cfg.max_image_size``), is under
    ``cfg.sift_upsample_below``. Else it is read as it is, and :func:`extract` reads it again doubled where that
    gives too few features."""
    return min(side, cfg.max_image_size) < cfg.sift_upsample_below


def _longer_sides(pycolmap, db: Path, names: list[str]) -> dict[str, int]:
    """Each photo's longer side in px, as the database's cameras record it (``import_images`` has read each
    working copy's header once; a shared camera has the size of every photo COLMAP imported into it)."""
    d = pycolmap.Database.open(db)
    try:
        cams = {c.camera_id: max(c.width, c.height) for c in d.read_all_cameras()}
        sides = {im.name: cams[im.camera_id] for im in d.read_all_images()}
    finally:
        d.close()
    return {n: sides.get(n, 0) for n in names}        # one COLMAP did not import: its default, doubled


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


def read_descriptors(db: Path) -> tuple[list[str], list[np.ndarray]]:
    """(the photos of COLMAP's database ``db`` in name order, each one's [n, 128] float32 SIFT descriptors)."""
    pycolmap = load_pycolmap()
    dbh = pycolmap.Database.open(db)
    try:
        images = sorted(dbh.read_all_images(), key=lambda im: im.name)
        out = []
        for im in images:
            d = dbh.read_descriptors(im.image_id).to_float()
            out.append(np.asarray(getattr(d, "data", d), np.float32).reshape(-1, 128))
    finally:
        dbh.close()
    return [im.name for im in images], out
