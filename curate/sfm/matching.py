"""Matching: the image pairs of a matcher (exhaustive, sequential with loop detection, spatial, retrieval; with
several takes, each take's frames with their most similar frames of the others) matched and verified, the same
pairs and matches on every run.

What runs COLMAP's own pair generation (exhaustive, sequential neighbours, spatial) is deterministic; which
photos look alike (loop detection, retrieval, the pairs between takes) comes from :mod:`curate.sfm.retrieval`,
whose words are seeded, where COLMAP's vocabulary tree is not. Those pairs are then matched by COLMAP as a list
(``match_image_pairs``). Verification RANSAC is seeded per pair (``cfg.seed``), so the threads' order does not
change the matches.

Every matcher's pairs go the same route (:func:`match_list`): COLMAP matches one pair on one thread the same way
every time, but not on several (:data:`MATCHING_THREADS`), so the list is cut into pieces, each matched on one
thread in a process of its own on a copy of the database, and their matches and two-view geometries are copied
into the database pair by pair: the same rows as one process matching the whole list, on N cores
(:data:`MATCHING_PROCESSES`; the rows checked and the time measured: docs/investigations/sfm.md#matching-in-pieces).

Guided matching chosen by auto, on photos of many features (:func:`weak_first`), guides only the pairs that
unguided matching leaves few verified matches: a guided match costs 3-4 unguided ones there
(docs/investigations/sfm.md#guided-where-weak).
"""

from __future__ import annotations

import logging
import os
import sqlite3
import tempfile
import time
from pathlib import Path

from curate.sfm.config import SfmConfig
from curate.sfm.native import load as load_pycolmap

logger = logging.getLogger(__name__)

MATCHING_THREADS = 1
"""Threads of each COLMAP matching and verification call on the CPU, whatever ``SfmConfig.num_threads`` says. Its CPU
matcher's nearest-neighbour search gave other matches in a few pairs on every run with two threads (office.mp4: 46
of 3,693 pairs differed between two runs, and the two models by up to 8.9 deg); on one thread two runs gave the same
bytes, at about 15% more time (85 s against 74 s for the stage on office.mp4;
docs/investigations/sfm.md#same-input-same-model). Extraction keeps every core: its features are the same bytes
on every run. With CUDA, COLMAP matches on the GPU (whether that is the same on every run is not measured).
Several cores match several pieces of the list at once instead, each on one thread (:func:`match_list`)."""

MATCHING_PROCESSES = None
"""Processes that match pieces of a pair list at once, each on one thread (:func:`match_list`): None follows
``SfmConfig.num_threads`` (-1: every core). The rows they write are the same whatever the number."""

MIN_PAIRS_PER_PROCESS = 64
"""A list is cut into pieces of at least this many pairs: a process takes about a second to start and a pair
about 20-60 ms to match (SIFT at 8,192 features, on one thread)."""

PIECES_PER_PROCESS = 3
"""Pieces per process: the pairs of one stretch of a walk can cost twice another's (guided matching where frames
overlap much), so each process takes a next piece when it is done with one."""


def match(cfg: SfmConfig, db: Path, matcher: str, takes: dict[str, list[str]] | None = None,
           stats: dict | None = None, guided_below: int = 0) -> None:
    """Match and verify the image pairs of ``matcher``; verification RANSAC is seeded by ``cfg.seed``.
    ``guided_below`` > 0 with guided matching: each pair guided only where fewer verified matches (:func:`weak_first`;
    0: every pair guided).

    COLMAP's default verification seed (-1) draws a new one per run: the office walk then got
    a different set of verified pairs, and a different model, on every run.

    ``takes`` ({take: image names}, :func:`curate.sfm.prep.takes_of`): with ``sequential`` and two or
    more takes, the frames of each take are also matched with their most similar frames of the other
    takes (:func:`_match_across_takes`; ``stats["cross_take"]`` says how many pairs).
    """
    pycolmap = load_pycolmap()
    if matcher == "exhaustive":
        info = generated(cfg, db, pycolmap.ExhaustivePairGenerator, pycolmap.ExhaustivePairingOptions(), matcher,
                         pycolmap.match_exhaustive, guided_below)
    elif matcher == "sequential":
        po = pycolmap.SequentialPairingOptions()
        po.overlap = cfg.sequential_overlap
        po.quadratic_overlap = cfg.sequential_quadratic
        po.loop_detection = False
        info = generated(cfg, db, pycolmap.SequentialPairGenerator, po, matcher, pycolmap.match_sequential,
                         guided_below)
        index = None
        if cfg.loop_detection:   # the capture's own words: offline, and the same pairs every run
            index = _index(cfg, db)
            names, pairs = loop_pairs(cfg, index)
            loops = match_pairs(cfg, db, pairs, "loop_pairs.txt", matcher, guided_below)
            if stats is not None:
                stats["loop_detection"] = {"queries": len(names), **loops}
        if cfg.cross_take_matching and takes and len(takes) >= 2:
            across = _match_across_takes(cfg, db, takes, index or _index(cfg, db), matcher, guided_below)
            if stats is not None:
                stats["cross_take"] = across
    elif matcher == "retrieval":   # each photo with its most similar ones, by words trained on this capture
        info = _retrieve(cfg, db, _index(cfg, db), cfg.retrieval_num_images, matcher, guided_below=guided_below)
    elif matcher == "spatial":
        po = pycolmap.SpatialPairingOptions()
        po.max_num_neighbors = cfg.spatial_neighbors
        po.ignore_z = True
        info = generated(cfg, db, pycolmap.SpatialPairGenerator, po, matcher, pycolmap.match_spatial, guided_below)
    else:
        raise ValueError(f"unknown matcher {matcher!r}")
    if stats is not None:   # the matcher's own pairs (sequential: the neighbours)
        stats["pairs"] = info


def loop_pairs(cfg: SfmConfig, index) -> tuple[list[str], list[tuple[str, str]]]:
    """(the queries, the pairs) of loop detection on ``index`` (:func:`_index`): every
    ``cfg.loop_detection_period``-th photo with its ``cfg.loop_detection_num_images`` most similar ones."""
    names = index.names[::cfg.loop_detection_period]
    return names, [(q, c) for q, cands in ranked(index, names, k=cfg.loop_detection_num_images) for c in cands]


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


def weak_first(cfg: SfmConfig, db: Path) -> int:
    """``cfg.guided_only_below_inliers`` where the photos of ``db`` hold a median of at least
    ``cfg.guided_selective_above_features`` SIFT features, else 0 (every pair guided): what :func:`match`'s
    ``guided_below`` is when guided matching was chosen by auto. Where features are many a guided match costs
    several unguided ones (4 times at 4,500 a photo, under twice at 1,100) and most pairs have plenty without
    it."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        n = sorted(r[0] for r in con.execute("SELECT rows FROM keypoints"))
    finally:
        con.close()
    median = n[len(n) // 2] if n else 0
    return cfg.guided_only_below_inliers if median >= cfg.guided_selective_above_features else 0


def guided(cfg: SfmConfig, matcher: str) -> bool:
    """Whether ``matcher``'s pairs are matched again along their verified geometry (``cfg.guided_matching``;
    ``auto``: for a sequence of frames)."""
    return cfg.guided_matching == "on" or (cfg.guided_matching == "auto" and matcher == "sequential")


def _options(cfg: SfmConfig, matcher: str):
    """(matching, verification options, device) of every matcher: verification RANSAC seeded by ``cfg.seed``."""
    return _options_of(cfg.seed, cfg.min_num_matches, guided(cfg, matcher))


def _options_of(seed: int, min_num_matches: int, guided_matching: bool):
    pycolmap = load_pycolmap()
    mo = pycolmap.FeatureMatchingOptions()
    mo.num_threads = MATCHING_THREADS
    mo.guided_matching = guided_matching
    vo = pycolmap.TwoViewGeometryOptions()
    vo.ransac.random_seed = seed
    vo.min_num_inliers = min_num_matches
    return mo, vo, pycolmap.Device.auto if pycolmap.has_cuda else pycolmap.Device.cpu


def generated(cfg: SfmConfig, db: Path, generator, options, matcher: str, whole, guided_below: int = 0) -> dict:
    """Match and verify the pairs COLMAP's pair ``generator`` (e.g. ``pycolmap.SequentialPairGenerator``) makes
    with ``options`` on ``db``, each in the order it gives (:func:`match_list`): what ``whole``
    (``pycolmap.match_sequential`` and its kin) matches, on several cores. Returns :func:`match_list`'s record.
    A capture with a photo whose name holds a space (``IMG 0001.jpg``), which COLMAP's pair list cannot name, is
    matched by ``whole`` itself, on one thread: the same rows, without the pieces; so is a list one process would
    match (``num_threads`` 1, the known poses' triangulation, CUDA): COLMAP's own matcher, as before the pieces,
    unless only the weak pairs are guided (``guided_below``): that is the list's two passes whatever the processes."""
    pycolmap = load_pycolmap()
    with pycolmap.Database.open(db) as dbh:
        name = {im.image_id: im.name for im in dbh.read_all_images()}
        pairs = [(name[a], name[b]) for a, b in generator(options, dbh).all_pairs()]
    weak_only = guided(cfg, matcher) and guided_below > 0
    if (processes(cfg, len(pairs)) == 1 and not weak_only) or any(c.isspace() for n in name.values() for c in n):
        t0 = time.perf_counter()
        before = pair_counts(db, cfg.min_num_matches)[1]
        mo, vo, dev = _options(cfg, matcher)
        whole(db, matching_options=mo, pairing_options=options, verification_options=vo, device=dev)
        return {"pairs": len(pairs), "new_pairs": len(pairs), "unlisted": 0, "processes": 1,
                "guided_pairs": len(pairs) if guided(cfg, matcher) else 0,
                "verified": pair_counts(db, cfg.min_num_matches)[1] - before,
                "seconds": round(time.perf_counter() - t0, 2)}
    return match_list(cfg, db, pairs, f"{matcher}_pairs.txt", matcher, guided_below)


def processes(cfg: SfmConfig, n_pairs: int) -> int:
    """How many processes match ``n_pairs`` pairs (:data:`MATCHING_PROCESSES`, :data:`MIN_PAIRS_PER_PROCESS`);
    1 with CUDA, where COLMAP matches on the GPU."""
    want = MATCHING_PROCESSES or (cfg.num_threads if cfg.num_threads > 0 else (os.cpu_count() or 1))
    if load_pycolmap().has_cuda:
        return 1
    return max(1, min(int(want), n_pairs // MIN_PAIRS_PER_PROCESS))


def match_list(cfg: SfmConfig, db: Path, pairs, list_name: str, matcher: str, guided_below: int = 0) -> dict:
    """Match and verify ``pairs`` ((name, name), each matched in the order given) not matched yet in ``db``:
    COLMAP's ``match_image_pairs`` on one thread, in :func:`processes` processes at once, each on a piece of the
    list and its own copy of the database (``python -m curate.sfm.matching``), whose new matches and two-view
    geometries are then copied into ``db`` (:func:`_merge`): the same rows as one process matching the whole list
    (a pair's matches do not depend on the others'). Pairs whose names hold spaces cannot be listed (COLMAP's list
    format): those are left unmatched, with a warning. With guided matching and ``guided_below`` > 0, each pair is
    guided only where unguided matching verifies fewer matches (:func:`_match_file`). Returns {"pairs",
    "new_pairs", "verified", "unlisted", "processes", "seconds", "guided_pairs" (pairs matched with guidance),
    and in pieces "pieces_cpu_s" (each piece's CPU seconds)}."""
    pycolmap = load_pycolmap()
    t0 = time.perf_counter()
    with pycolmap.Database.open(db) as dbh:
        ids = {im.name: im.image_id for im in dbh.read_all_images()}
        seen, uniq = set(), []
        for a, b in pairs:
            key = (a, b) if ids.get(a, 0) < ids.get(b, 0) else (b, a)
            if a != b and a in ids and b in ids and key not in seen:
                seen.add(key)
                uniq.append((a, b))
        new = [(a, b) for a, b in uniq if not dbh.exists_matches(ids[a], ids[b])]
    listed = [(a, b) for a, b in new if not any(c.isspace() for c in a + b)]
    if len(listed) < len(new):
        logger.warning("sfm: %d of %d pairs left unmatched: COLMAP's pair list cannot name photos with spaces in "
                       "their names", len(new) - len(listed), len(new))
    before = pair_counts(db, cfg.min_num_matches)[1]
    n_proc, pieces_cpu = processes(cfg, len(listed)), []
    n_guided = 0   # what _match_file returns, summed over the pieces
    if listed:
        path = db.parent / list_name
        path.write_text("".join(f"{a} {b}\n" for a, b in listed))
        if n_proc == 1:
            n_guided = _match_file(db, path, cfg.seed, cfg.min_num_matches, guided(cfg, matcher), guided_below)
        else:
            pieces_cpu, n_guided = _match_in_pieces(cfg, db, listed, n_proc, matcher, guided_below)
    info = {"pairs": len(uniq), "new_pairs": len(new),
            "verified": pair_counts(db, cfg.min_num_matches)[1] - before, "unlisted": len(new) - len(listed),
            "processes": n_proc, "guided_pairs": n_guided, "seconds": round(time.perf_counter() - t0, 2),
            **({"pieces_cpu_s": [None if c is None else round(c, 1) for c in pieces_cpu]} if pieces_cpu else {})}
    logger.info("sfm: %s: %d pairs matched in %d process(es), %d verified, in %.1f s", list_name,
                len(listed), n_proc, info["verified"], info["seconds"])
    return info


def _match_in_pieces(cfg: SfmConfig, db: Path, pairs: list, n_proc: int, matcher: str,
                     guided_below: int = 0) -> tuple[list[float | None], int]:
    """``pairs`` cut into ``n_proc`` x :data:`PIECES_PER_PROCESS` pieces in their order, each matched by a process of
    its own (``python -m curate.sfm.matching``, one thread) on a copy of ``db``, ``n_proc`` at a time; each piece's
    rows are copied into ``db`` as it ends (rows by pair id: the order they end in changes nothing) and its copy
    removed. COLMAP's log of each piece goes to COLMAP's log here. Returns (each piece's CPU seconds, in the order
    they ended; the pairs matched with guidance, :func:`_match_file`)."""
    import json
    import subprocess
    import sys

    pycolmap = load_pycolmap()
    k = min(len(pairs), n_proc * PIECES_PER_PROCESS)
    pieces = [pairs[len(pairs) * i // k: len(pairs) * (i + 1) // k] for i in range(k)]
    code = str(Path(__file__).resolve().parents[2])   # this curate, whatever the caller's path
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([code, *filter(None, [os.environ.get("PYTHONPATH")])]),
               OMP_NUM_THREADS="1")
    record: list[float | None] = []
    n_guided = 0
    with tempfile.TemporaryDirectory(prefix="match_", dir=db.parent) as tmp:
        todo, running = list(enumerate(pieces)), {}
        try:
            while todo or running:
                while todo and len(running) < n_proc:
                    i, piece = todo.pop(0)
                    job = {"db": str(db), "copy": str(Path(tmp) / f"{i}.db"), "list": str(Path(tmp) / f"{i}.txt"),
                           "seed": cfg.seed, "min_num_matches": cfg.min_num_matches,
                           "guided": guided(cfg, matcher), "guided_below": guided_below}
                    Path(job["list"]).write_text("".join(f"{a} {b}\n" for a, b in piece))
                    with open(Path(tmp) / f"{i}.err", "wb") as err:
                        running[i] = (job, subprocess.Popen([sys.executable, "-m", "curate.sfm.matching",
                                                             json.dumps(job)], env=env, stdout=subprocess.DEVNULL,
                                                            stderr=err))
                i = _wait_any(running)
                job, proc = running.pop(i)
                err = (Path(tmp) / f"{i}.err").read_text(errors="replace")
                log = Path(job["copy"]).with_suffix(".log")
                text = log.read_text(errors="replace") if log.is_file() else ""
                if proc.returncode != 0:
                    raise RuntimeError(f"sfm: matching piece {i + 1} of {k} failed ({proc.returncode}): "
                                       f"{(err or text)[-2000:]}")
                _merge(db, Path(job["copy"]))
                if text:
                    pycolmap.logging.info(text)
                cpu, weak = Path(job["copy"]).with_suffix(".cpu"), Path(job["copy"]).with_suffix(".guided")
                record.append(float(cpu.read_text()) if cpu.is_file() else None)   # not measured: no NaN in JSON
                n_guided += int(weak.read_text()) if weak.is_file() else 0
                for f in (job["copy"], job["list"], str(log), str(Path(tmp) / f"{i}.err"), str(cpu), str(weak)):
                    Path(f).unlink(missing_ok=True)
        finally:
            for _, proc in running.values():
                proc.kill()
                proc.wait()
    return record, n_guided


def _wait_any(running: dict) -> int:
    """The key of a process of ``running`` ({key: (job, Popen)}) that has ended, waiting for one."""
    while True:
        for i, (_, proc) in running.items():
            if proc.poll() is not None:
                return i
        time.sleep(0.05)


def copy_database(src: Path, dst: Path) -> Path:
    """``src`` (a COLMAP database) copied to ``dst`` through SQLite's backup, with what its write-ahead log holds
    and a file copy would leave behind; a log beside ``dst`` from an earlier copy is removed first. Returns ``dst``.

    Nothing is written beside ``src``: with no log there (no connection holds it open), it is read as immutable; a
    read-only reader of a database in WAL mode would otherwise leave an empty log and its index beside it, files
    a finished run folder's record does not list (``curate sfm --force`` then refused to clear the folder)."""
    src, dst = Path(src), Path(dst)
    for f in (dst, dst.with_name(dst.name + "-wal"), dst.with_name(dst.name + "-shm")):
        f.unlink(missing_ok=True)
    logged = src.with_name(src.name + "-wal").exists()
    a = sqlite3.connect(f"file:{src}?{'mode=ro' if logged else 'immutable=1'}", uri=True)
    b = sqlite3.connect(dst)
    try:
        a.backup(b)
    finally:
        b.close()
        a.close()
    return dst


def _match_piece(job: dict) -> None:
    """One piece of :func:`_match_in_pieces` (in its own process): ``job["db"]`` copied to ``job["copy"]``, the
    pairs of ``job["list"]`` matched and verified there on one thread, COLMAP's log beside the copy (.log)."""
    from curate.sfm.native import colmap_log
    copy_database(Path(job["db"]), Path(job["copy"]))
    with colmap_log(Path(job["copy"]).with_suffix(".log")):
        n = _match_file(Path(job["copy"]), Path(job["list"]), job["seed"], job["min_num_matches"], job["guided"],
                        job["guided_below"])
    import resource
    ru = resource.getrusage(resource.RUSAGE_SELF)
    Path(job["copy"]).with_suffix(".cpu").write_text(f"{ru.ru_utime + ru.ru_stime:.3f}")
    Path(job["copy"]).with_suffix(".guided").write_text(str(n))


def _match_file(db: Path, pairs_path: Path, seed: int, min_num_matches: int, guided_matching: bool,
                guided_below: int = 0) -> int:
    """Match and verify the pairs listed in ``pairs_path`` (COLMAP's ``match_image_pairs``, one thread) in ``db``.
    With ``guided_matching`` and ``guided_below`` > 0, in two passes: every pair unguided, then the pairs with at
    least ``min_num_matches`` and fewer than ``guided_below`` verified matches have their rows removed and are
    matched again with guidance, so that every pair's rows are those guiding every pair writes or, past
    ``guided_below``, the unguided ones (a pair's rows depend on that pair alone). A pair that fails verification
    unguided is not matched again: COLMAP guides only along a verified geometry, so its rows are the same either
    way (30 of 30 such pairs of the drone flight byte for byte). Returns the pairs matched with guidance."""
    pycolmap = load_pycolmap()
    po = pycolmap.ImportedPairingOptions()
    po.match_list_path = str(pairs_path)
    weak_only = guided_matching and guided_below > 0
    mo, vo, dev = _options_of(seed, min_num_matches, guided_matching and not weak_only)
    pycolmap.match_image_pairs(db, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)
    if not weak_only:
        return len(pairs_path.read_text().splitlines()) if guided_matching else 0
    weak = []
    with pycolmap.Database.open(db) as dbh:
        ids = {im.name: im.image_id for im in dbh.read_all_images()}
        for line in pairs_path.read_text().splitlines():
            a, b = (ids[n] for n in line.split())
            n = len(dbh.read_two_view_geometry(a, b).inlier_matches) if dbh.exists_two_view_geometry(a, b) else 0
            if min_num_matches <= n < guided_below:
                weak.append(line)
                dbh.delete_matches(a, b)
                if dbh.exists_two_view_geometry(a, b):
                    dbh.delete_two_view_geometry(a, b)
    if weak:
        again = pairs_path.with_name(pairs_path.stem + "_guided.txt")
        again.write_text("".join(f"{line}\n" for line in weak))
        po.match_list_path = str(again)
        mo, vo, dev = _options_of(seed, min_num_matches, True)
        pycolmap.match_image_pairs(db, matching_options=mo, pairing_options=po, verification_options=vo,
                                   device=dev)
        again.unlink()
    return len(weak)


def _merge(db: Path, piece: Path) -> None:
    """Copy the matches and two-view geometries of ``piece`` (a copy of ``db`` that matched more pairs) that
    ``db`` lacks into ``db``, each row as COLMAP wrote it (rows are kept by pair id: the order COLMAP reads them
    in, whatever the order they are written in)."""
    con = sqlite3.connect(str(db), timeout=60)
    try:
        con.execute("ATTACH DATABASE ? AS piece", (str(piece),))
        for table in ("matches", "two_view_geometries"):
            con.execute(f"INSERT INTO main.{table} SELECT * FROM piece.{table} WHERE pair_id NOT IN "
                        f"(SELECT pair_id FROM main.{table}) ORDER BY pair_id")
        con.commit()
        con.execute("DETACH DATABASE piece")
    finally:
        con.close()


def match_pairs(cfg: SfmConfig, db: Path, pairs, list_name: str, matcher: str, guided_below: int = 0) -> dict:
    """Match and verify the image ``pairs`` ((name, name), either order: each is matched in name order) not
    matched yet (:func:`match_list`, the list written beside ``db`` as ``list_name``). Returns {"pairs",
    "new_pairs", "verified", "unlisted" (names with spaces: COLMAP's list cannot name them), "processes",
    "seconds"}."""
    return match_list(cfg, db, sorted({tuple(sorted((a, b))) for a, b in pairs if a != b}), list_name, matcher,
                      guided_below)


def _retrieve(cfg: SfmConfig, db: Path, index, num_images: int, matcher: str, queries: list[str] | None = None,
              list_name: str = "retrieval_pairs.txt", guided_below: int = 0) -> dict:
    """Match each photo (those of ``queries``; all when None) with its ``num_images`` most similar photos."""
    qs = index.names if queries is None else [q for q in queries if q in set(index.names)]
    pairs = [(q, c) for q, cands in ranked(index, qs, k=num_images) for c in cands]
    return match_pairs(cfg, db, pairs, list_name, matcher, guided_below)


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


def _match_across_takes(cfg: SfmConfig, db: Path, takes: dict[str, list[str]], index, matcher: str,
                        guided_below: int = 0) -> dict:
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
    info = {"queries": len(queries), **match_pairs(cfg, db, pairs, "cross_take_pairs.txt", matcher, guided_below),
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


if __name__ == "__main__":   # one piece of a list (_match_in_pieces): python -m curate.sfm.matching JOB_JSON
    import json
    import sys
    _match_piece(json.loads(sys.argv[1]))
