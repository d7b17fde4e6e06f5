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


def extract(cfg: SfmConfig, db: Path, images: Path, names: list[str], single: bool) -> None:
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
