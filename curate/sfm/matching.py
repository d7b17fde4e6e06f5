"""Matching: the image pairs of a matcher (exhaustive, sequential with loop detection, spatial, retrieval; with
several takes, each take's frames with their most similar frames of the others) matched and verified, the same
pairs and matches on every run.

What runs COLMAP's own pair generation (exhaustive, sequential neighbours, spatial) is deterministic; which
photos look alike (loop detection, retrieval, the pairs between takes) comes from :mod:`curate.sfm.retrieval`,
whose words are seeded, where COLMAP's vocabulary tree is not. Those pairs are then matched by COLMAP as a list
(``match_image_pairs``). Verification RANSAC is seeded per pair (``cfg.seed``), so the threads' order does not
change the matches.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from curate.sfm.config import SfmConfig
from curate.sfm.native import load as load_pycolmap

logger = logging.getLogger(__name__)

MATCHING_THREADS = 1
"""Threads of COLMAP's matching and verification on the CPU, whatever ``SfmConfig.num_threads`` says. Its CPU
matcher's nearest-neighbour search gave other matches in a few pairs on every run with two threads (office.mp4: 46
of 3,693 pairs differed between two runs, and the two models by up to 8.9 deg); on one thread two runs gave the same
bytes, at about 15% more time (85 s against 74 s for the stage on office.mp4;
docs/investigations/sfm.md#same-input-same-model). Extraction keeps every core: its features are the same bytes
on every run. With CUDA, COLMAP matches on the GPU (whether that is the same on every run is not measured)."""


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
    mo, vo, dev = _options(cfg, matcher)
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(db, matching_options=mo, verification_options=vo, device=dev)
    elif matcher == "sequential":
        po = pycolmap.SequentialPairingOptions()
        po.overlap = cfg.sequential_overlap
        po.quadratic_overlap = cfg.sequential_quadratic
        po.loop_detection = False
        pycolmap.match_sequential(db, matching_options=mo, pairing_options=po, verification_options=vo,
                                  device=dev)
        index = None
        if cfg.loop_detection:   # the capture's own words: offline, and the same pairs every run
            index = _index(cfg, db)
            names = index.names[::cfg.loop_detection_period]
            pairs = [(q, c) for q, cands in ranked(index, names, k=cfg.loop_detection_num_images) for c in cands]
            info = match_pairs(cfg, db, pairs, "loop_pairs.txt", matcher)
            if stats is not None:
                stats["loop_detection"] = {"queries": len(names), **info}
        if cfg.cross_take_matching and takes and len(takes) >= 2:
            info = _match_across_takes(cfg, db, takes, index or _index(cfg, db), matcher)
            if stats is not None:
                stats["cross_take"] = info
    elif matcher == "retrieval":   # each photo with its most similar ones, by words trained on this capture
        _retrieve(cfg, db, _index(cfg, db), cfg.retrieval_num_images, matcher)
    elif matcher == "spatial":
        po = pycolmap.SpatialPairingOptions()
        po.max_num_neighbors = cfg.spatial_neighbors
        po.ignore_z = True
        pycolmap.match_spatial(db, matching_options=mo, pairing_options=po, verification_options=vo,
                               device=dev)
    else:
        raise ValueError(f"unknown matcher {matcher!r}")


def ranked(index, queries, k=None, candidates=None):
    """:func:`curate.sfm.retrieval.ranked` (imported here so that the matchers read as one module)."""
    from curate.sfm.retrieval import ranked as _ranked
    return _ranked(index, list(queries), candidates, k)


def _index(cfg: SfmConfig, db: Path):
    """The capture's visual words (:func:`curate.sfm.retrieval.build`), kept beside the database
    (``visual_words.npz``) for the retrieval's second round."""
    from curate.sfm.retrieval import build, load, save
    path = db.parent / "visual_words.npz"
    if path.is_file():
        try:
            return load(path)
        except (KeyError, ValueError, OSError):   # another version's file, or cut short: learned again
            logger.info("sfm: %s cannot be read; learning the visual words again", path)
    index = build(db, cfg.seed, cfg.vocab_tree_descriptors)
    save(index, path)
    return index


def guided(cfg: SfmConfig, matcher: str) -> bool:
    """Whether ``matcher``'s pairs are matched again along their verified geometry (``cfg.guided_matching``;
    ``auto``: for a sequence of frames)."""
    return cfg.guided_matching == "on" or (cfg.guided_matching == "auto" and matcher == "sequential")


def _options(cfg: SfmConfig, matcher: str):
    """(matching, verification options, device) of every matcher: verification RANSAC seeded by ``cfg.seed``."""
    pycolmap = load_pycolmap()
    mo = pycolmap.FeatureMatchingOptions()
    mo.num_threads = MATCHING_THREADS
    mo.guided_matching = guided(cfg, matcher)
    vo = pycolmap.TwoViewGeometryOptions()
    vo.ransac.random_seed = cfg.seed
    vo.min_num_inliers = cfg.min_num_matches
    return mo, vo, pycolmap.Device.auto if pycolmap.has_cuda else pycolmap.Device.cpu


def match_pairs(cfg: SfmConfig, db: Path, pairs, list_name: str, matcher: str) -> dict:
    """Match and verify the image ``pairs`` ((name, name), either order) not matched yet, through a pair list
    written beside ``db`` (``list_name``). Returns {"pairs", "new_pairs", "verified", "unlisted" (names with
    spaces: COLMAP's list cannot name them)}."""
    pycolmap = load_pycolmap()
    dbh = pycolmap.Database.open(db)
    try:
        ids = {im.name: im.image_id for im in dbh.read_all_images()}
        uniq = sorted({tuple(sorted((a, b))) for a, b in pairs if a != b and a in ids and b in ids})
        new = [(a, b) for a, b in uniq if not dbh.exists_matches(ids[a], ids[b])]
    finally:
        dbh.close()
    listed = [(a, b) for a, b in new if not any(c.isspace() for c in a + b)]
    if len(listed) < len(new):
        logger.warning("sfm: %d of %d pairs left unmatched: COLMAP's pair list cannot name photos with spaces in "
                       "their names", len(new) - len(listed), len(new))
    before = pair_counts(db, cfg.min_num_matches)[1]
    if listed:
        mo, vo, dev = _options(cfg, matcher)
        path = db.parent / list_name
        path.write_text("".join(f"{a} {b}\n" for a, b in listed))
        po = pycolmap.ImportedPairingOptions()
        po.match_list_path = str(path)
        pycolmap.match_image_pairs(db, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)
    return {"pairs": len(uniq), "new_pairs": len(new), "verified": pair_counts(db, cfg.min_num_matches)[1] - before,
            "unlisted": len(new) - len(listed)}


def _retrieve(cfg: SfmConfig, db: Path, index, num_images: int, matcher: str, queries: list[str] | None = None,
              list_name: str = "retrieval_pairs.txt") -> dict:
    """Match each photo (those of ``queries``; all when None) with its ``num_images`` most similar photos."""
    qs = index.names if queries is None else [q for q in queries if q in set(index.names)]
    pairs = [(q, c) for q, cands in ranked(index, qs, k=num_images) for c in cands]
    return match_pairs(cfg, db, pairs, list_name, matcher)


def rematch_left_out(cfg: SfmConfig, db: Path, left_out: list[str]) -> dict:
    """Retrieval's second round: the photos ``left_out`` of the first model, each matched with its
    ``cfg.retrieval_rematch_num_images`` most similar photos (the first round's words). Returns {"photos",
    "num_images", "verified" (new verified pairs), "unlisted" (names with spaces: COLMAP's list cannot name
    them), "seconds"}."""
    t0 = time.perf_counter()
    info = _retrieve(cfg, db, _index(cfg, db), cfg.retrieval_rematch_num_images, "retrieval", left_out,
                     "retrieval_second_round.txt")
    return {"photos": len(left_out), "num_images": cfg.retrieval_rematch_num_images, "verified": info["verified"],
            "unlisted": info["unlisted"], "seconds": round(time.perf_counter() - t0, 2)}


def _match_across_takes(cfg: SfmConfig, db: Path, takes: dict[str, list[str]], index, matcher: str) -> dict:
    """Match every ``cfg.cross_take_period``-th frame of each take with its ``cfg.cross_take_num_images``
    most similar frames of each other take (:func:`curate.sfm.prep.cross_take_pairs`).

    Sequential matching pairs neighbours in name order, which are frames of one take; its loop
    detection ranks every frame against all others, so a frame's most similar ones are its own take's
    neighbours and a second take seldom gets in. Here each queried frame's whole ranking (the capture's
    own words, every frame indexed) is read to its end and only the other takes' best frames are kept:
    (frames / period) x num_images x (takes - 1) pairs at most, linear in the frames. Returns {"queries",
    "pairs", "new_pairs", "verified", "unlisted", "seconds"}.
    """
    from curate.sfm.prep import cross_take_pairs
    t0 = time.perf_counter()
    take_of = {n: t for t, names in takes.items() for n in names if n in set(index.names)}
    queries = [n for names in takes.values() for n in names[::cfg.cross_take_period] if n in take_of]
    pairs = cross_take_pairs(ranked(index, queries, candidates=sorted(take_of)), take_of, cfg.cross_take_num_images)
    info = {"queries": len(queries), **match_pairs(cfg, db, pairs, "cross_take_pairs.txt", matcher),
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
