"""SIFT features into COLMAP's database, and a vocabulary tree trained on them (loop detection and the
retrieval of cross-take pairs, :mod:`curate.sfm.matching`) without a download.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from curate.sfm.config import SfmConfig
from curate.sfm.native import load as load_pycolmap, stdout_to

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


def build_vocab_tree(db: Path, path: Path, seed: int, max_descriptors: int = 100_000) -> Path:
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
    with stdout_to(db.parent / "colmap.log"):  # faiss prints clustering warnings on stdout
        index.build(bo, pycolmap.FeatureDescriptorsFloat(pycolmap.FeatureExtractorType.SIFT, desc))
    index.write(path)
    logger.info("sfm: vocabulary tree of %d words from %d descriptors in %.1f s", words, len(desc),
                time.perf_counter() - t)
    return path
