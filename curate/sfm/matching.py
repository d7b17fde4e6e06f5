"""Matching: the image pairs of a matcher (exhaustive, sequential with loop detection, spatial, retrieval; with
several takes, each take's frames with their most similar frames of the others) matched and verified, seeded.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from curate.sfm.config import SfmConfig
from curate.sfm.features import build_vocab_tree
from curate.sfm.native import load as load_pycolmap, stdout_to

logger = logging.getLogger(__name__)


def match(cfg: SfmConfig, db: Path, matcher: str, takes: dict[str, list[str]] | None = None,
           stats: dict | None = None) -> None:
    """Match and verify the image pairs of ``matcher``; verification RANSAC is seeded by ``cfg.seed``.

    COLMAP's default verification seed (-1) draws a new one per run: the office walk then got
    a different set of verified pairs, and a different model, on every run.

    ``takes`` ({take: image names}, :func:`curate.sfm.prep.takes_of`): with ``sequential`` and two or
    more takes, the frames of each take are also matched with their most similar frames of the other
    takes (:func:`_match_across_takes`; ``stats["cross_take"]`` says how many pairs).
    """
    pycolmap = load_pycolmap()
    mo, vo, dev = _options(cfg)
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(db, matching_options=mo, verification_options=vo, device=dev)
    elif matcher == "sequential":
        po = pycolmap.SequentialPairingOptions()
        po.overlap = cfg.sequential_overlap
        po.quadratic_overlap = cfg.sequential_quadratic
        po.loop_detection = False
        tree = None
        if cfg.loop_detection:  # with a vocabulary tree built from this capture's own features: offline
            tree = build_vocab_tree(db, db.parent / "vocab_tree.bin", cfg.seed, cfg.vocab_tree_descriptors)
            po.loop_detection = True
            po.vocab_tree_path = str(tree)
            po.loop_detection_period = cfg.loop_detection_period
            po.loop_detection_num_images = cfg.loop_detection_num_images
        pycolmap.match_sequential(db, matching_options=mo, pairing_options=po, verification_options=vo,
                                  device=dev)
        if cfg.cross_take_matching and takes and len(takes) >= 2:
            if tree is None:
                tree = build_vocab_tree(db, db.parent / "vocab_tree.bin", cfg.seed, cfg.vocab_tree_descriptors)
            info = _match_across_takes(cfg, db, takes, tree, mo, vo, dev)
            if stats is not None:
                stats["cross_take"] = info
    elif matcher == "retrieval":   # each photo with its most similar ones, by a tree trained on this capture
        _retrieve(cfg, db, build_vocab_tree(db, db.parent / "vocab_tree.bin", cfg.seed, cfg.vocab_tree_descriptors),
                  cfg.retrieval_num_images)
    elif matcher == "spatial":
        po = pycolmap.SpatialPairingOptions()
        po.max_num_neighbors = cfg.spatial_neighbors
        po.ignore_z = True
        pycolmap.match_spatial(db, matching_options=mo, pairing_options=po, verification_options=vo,
                               device=dev)
    else:
        raise ValueError(f"unknown matcher {matcher!r}")


def _options(cfg: SfmConfig):
    """(matching, verification options, device) of every matcher: verification RANSAC seeded by ``cfg.seed``."""
    pycolmap = load_pycolmap()
    mo = pycolmap.FeatureMatchingOptions()
    mo.num_threads = cfg.num_threads
    mo.guided_matching = cfg.guided_matching
    vo = pycolmap.TwoViewGeometryOptions()
    vo.ransac.random_seed = cfg.seed
    vo.min_num_inliers = cfg.min_num_matches
    return mo, vo, pycolmap.Device.auto if pycolmap.has_cuda else pycolmap.Device.cpu


def _retrieve(cfg: SfmConfig, db: Path, tree: Path, num_images: int, queries: Path | None = None) -> None:
    """Match each photo (those listed in ``queries``, one name a line; all when None) with its ``num_images``
    most similar photos by the vocabulary ``tree``."""
    pycolmap = load_pycolmap()
    mo, vo, dev = _options(cfg)
    po = pycolmap.VocabTreePairingOptions()
    po.vocab_tree_path = str(tree)
    po.num_images = num_images
    po.num_threads = cfg.num_threads
    if queries is not None:
        po.match_list_path = str(queries)
    with stdout_to(db.parent / "colmap.log"):
        pycolmap.match_vocabtree(db, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)


def rematch_left_out(cfg: SfmConfig, db: Path, left_out: list[str]) -> dict:
    """Retrieval's second round: the photos ``left_out`` of the first model, each matched with its
    ``cfg.retrieval_rematch_num_images`` most similar photos (the first round's tree). Returns {"photos",
    "num_images", "verified" (new verified pairs), "unlisted" (names with spaces: COLMAP's list cannot name
    them), "seconds"}."""
    t0 = time.perf_counter()
    listed = [n for n in left_out if not any(c.isspace() for c in n)]
    before = pair_counts(db, cfg.min_num_matches)[1]
    if listed:
        path = db.parent / "retrieval_second_round.txt"
        path.write_text("".join(n + "\n" for n in listed))
        _retrieve(cfg, db, db.parent / "vocab_tree.bin", cfg.retrieval_rematch_num_images, path)
    return {"photos": len(listed), "num_images": cfg.retrieval_rematch_num_images,
            "verified": pair_counts(db, cfg.min_num_matches)[1] - before, "unlisted": len(left_out) - len(listed),
            "seconds": round(time.perf_counter() - t0, 2)}


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
        with stdout_to(db.parent / "colmap.log"):
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
    before = pair_counts(db, cfg.min_num_matches)[1]
    if listed:
        path = db.parent / "cross_take_pairs.txt"
        path.write_text("".join(f"{a} {b}\n" for a, b in listed))
        po = pycolmap.ImportedPairingOptions()
        po.match_list_path = str(path)
        pycolmap.match_image_pairs(db, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)
    info = {"queries": len(queries), "pairs": len(pairs), "new_pairs": len(new),
            "verified": pair_counts(db, cfg.min_num_matches)[1] - before, "unlisted": len(new) - len(listed),
            "seconds": round(time.perf_counter() - t0, 2)}
    logger.info("sfm: cross-take matching (%d takes): %d frames queried, %d new pairs, %d verified in %.1f s",
                len(takes), info["queries"], info["new_pairs"], info["verified"], info["seconds"])
    return info


def pair_counts(db: Path, min_num_matches: int) -> tuple[int, int]:
    """(image pairs of ``db`` with a two-view geometry, those with at least ``min_num_matches`` verified inliers)."""
    pycolmap = load_pycolmap()
    dbh = pycolmap.Database.open(db)
    try:
        _, inliers = dbh.read_two_view_geometry_num_inliers()
    finally:
        dbh.close()
    return len(inliers), int(sum(n >= min_num_matches for n in inliers))
