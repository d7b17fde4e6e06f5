"""Two ways to map a large pool without the whole-pool incremental mapper's growing global adjustments:
measured, not adopted (docs/investigations/sfm.md#mapping-past-1000).

**Chunks of the capture order** (:func:`map_chunks`): the pool, in the order of its names, is cut into
chunks of ``size`` photos, neighbours sharing ``overlap``; the incremental mapper on the whole pool,
stopped once its model holds ``size`` photos, gives the start; from the chunk holding most of it,
outwards, each chunk is mapped on its own photos plus at most ``overlap`` registered photos outside it
that share most matches with it, grown from those already registered (held fixed, with their points),
so every chunk lands in one frame with no initial pair of its own; then every photo takes its pose
from the chunk it lies most inside of, the points are triangulated again from all the matches, and one
bundle adjustment refines the whole. Fails on office.mp4: a chunk cannot register the frames whose
matches to the registered part run through photos outside it (the whole-pool mapper crosses the walk's
weak stretch at frames 181-185 through frames the chunks leave out).

**Rounds** (:func:`map_rounds`): the whole-pool incremental mapper, stopped every ``size``
registrations (a snapshot) and resumed from it with every frame registered so far held fixed, so no
adjustment moves more than one round's frames; then one bundle adjustment of the whole. Without the
final adjustment the frames fixed too early cost accuracy (office.mp4: 8 frames over 5 deg); with it,
that one adjustment grows as fast as the mapper's own.

    python3 -m research.sfm_mappers /tmp/office_run --truth ../shared/data/office --mappers chunks:150:50,rounds:120
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import numpy as np

logger = logging.getLogger(__name__)

MIN_SHARED = 10
"""Fewest photos of a chunk the previous chunk must have registered for the chunk to grow from them."""


def chunk_spans(n: int, size: int, overlap: int) -> list[tuple[int, int]]:
    """[start, end) index spans of ``n`` photos in chunks of ``size`` photos, neighbours overlapping by at
    least ``overlap`` (the chunks spread evenly: every chunk holds ``size``, the overlaps absorb the rest).
    One span when ``n <= size``."""
    if size < 2 or not 0 <= overlap < size:
        raise ValueError(f"chunks of {size} photos overlapping by {overlap}: need size >= 2 and 0 <= overlap < size")
    if n <= size:
        return [(0, n)]
    k = math.ceil((n - overlap) / (size - overlap))
    starts = np.round(np.linspace(0, n - size, k)).astype(int)
    return [(int(s), int(s) + size) for s in starts]


def centrality(index: int, span: tuple[int, int]) -> int:
    """How far inside ``span`` the photo at ``index`` lies (photos from the nearer end); -1 outside it."""
    s, e = span
    return min(index - s, e - 1 - index) if s <= index < e else -1


def growth_order(n_spans: int, start: int) -> list[tuple[int, int | None]]:
    """(chunk, the chunk it grows from) in mapping order: ``start`` first (from the start model: None),
    then outwards to the last chunk, then from ``start`` back to the first."""
    return ([(start, None)] + [(k, k - 1) for k in range(start + 1, n_spans)]
            + [(k, k + 1) for k in range(start - 1, -1, -1)])


def registered_names(rec) -> list[str]:
    return [rec.image(i).name for i in rec.reg_image_ids()]


def copy_image(out, src, iid: int, keypoints: bool) -> None:
    """Add the registered image ``iid`` of the model ``src`` to the model ``out``: same id, name, camera
    (added when missing) and pose; with every keypoint of it (``keypoints``) or none."""
    import pycolmap
    im = src.image(iid)
    if not out.exists_camera(im.camera_id):
        out.add_camera_with_trivial_rig(src.camera(im.camera_id))
    kw = {"keypoints": np.array([p.xy for p in im.points2D], np.float64).reshape(-1, 2)} if keypoints else {}
    out.add_image_with_trivial_frame(pycolmap.Image(name=im.name, camera_id=im.camera_id, image_id=iid, **kw),
                                     im.cam_from_world())


def crop(results: dict, pick: dict[str, object]):
    """A new ``pycolmap.Reconstruction`` (one frame) of the images ``pick`` names, each taken from the model
    ``results[pick[name]]`` (pose, camera, every keypoint), with each model's points that two or more of
    the images taken from it see (tracks cut to them). Every 2D point then belongs to one 3D point at most."""
    import pycolmap
    out = pycolmap.Reconstruction()
    for key, rec in results.items():
        ids = set()
        for iid in rec.reg_image_ids():
            im = rec.image(iid)
            if pick.get(im.name) != key:
                continue
            copy_image(out, rec, iid, keypoints=True)
            ids.add(iid)
        for p in rec.points3D.values():
            els = [e for e in p.track.elements if e.image_id in ids]
            if len({e.image_id for e in els}) >= 2:
                out.add_point3D(p.xyz, pycolmap.Track(els), p.color)
    return out


def match_graph(db: Path, min_num_matches: int) -> dict[str, dict[str, int]]:
    """{name: {name: verified inliers}} of the image pairs of ``db`` with at least ``min_num_matches``."""
    import pycolmap
    dbh = pycolmap.Database.open(db)
    try:
        name = {im.image_id: im.name for im in dbh.read_all_images()}
        pairs, inliers = dbh.read_two_view_geometry_num_inliers()
    finally:
        dbh.close()
    graph: dict[str, dict[str, int]] = {n: {} for n in name.values()}
    for pid, k in zip(pairs, inliers):
        if k >= min_num_matches:
            a, b = pycolmap.pair_id_to_image_pair(pid)
            graph[name[a]][name[b]] = graph[name[b]][name[a]] = int(k)
    return graph


def seed_names(held: dict[str, int], span_names: list[str], graph: dict, extra: int) -> list[str]:
    """The photos a chunk grows from: those of ``span_names`` already registered (``held``: name -> index),
    and at most ``extra`` registered photos outside it, those with the most verified inliers to the chunk's
    photos (a loop's other pass, the far side of a hard stretch: what the whole-pool mapper registers
    the chunk with)."""
    inside = set(span_names)
    mine = [n for n in span_names if n in held]
    score: dict[str, int] = {}
    for n in span_names:
        for m, k in graph.get(n, {}).items():
            if m in held and m not in inside:
                score[m] = score.get(m, 0) + k
    return mine + sorted(score, key=lambda m: (-score[m], held[m]))[:extra]


def _start_model(cfg, db: Path, images: Path, out: Path, size: int, n_images: int):
    """The incremental mapper's first model on the whole pool, stopped once it holds ``size`` photos
    (COLMAP's snapshot at that count; the mapper is cancelled after it): a Reconstruction, or None."""
    import pycolmap

    from curate.sfm.reconstruction import incremental_options
    opts = incremental_options(cfg, n_images)
    opts.multiple_models = False
    snaps = out / "snapshots"
    snaps.mkdir(parents=True, exist_ok=True)
    opts.snapshot_path, opts.snapshot_frames_freq = str(snaps), size
    token = pycolmap.CancellationToken()

    def on_image():
        if any(snaps.iterdir()):
            token.cancel()

    try:
        found = pycolmap.incremental_mapping(db, images, out, options=opts, next_image_callback=on_image,
                                             cancellation_token=token)
    except InterruptedError:  # cancelled at the snapshot
        return pycolmap.Reconstruction(sorted(snaps.iterdir())[-1])
    return max(found.values(), key=lambda r: r.num_reg_images(), default=None)


def _map_chunk(cfg, db: Path, images: Path, out: Path, names: list[str], seed):
    """The incremental mapper on the photos ``names``, grown from the model ``seed`` (its frames held
    fixed) or, when ``seed`` is None, from an initial pair of its own: the model that holds the seed (or
    the largest), or None."""
    import pycolmap

    from curate.sfm.reconstruction import incremental_options
    opts = incremental_options(cfg, len(names))
    opts.image_names = list(names)
    out.mkdir(parents=True, exist_ok=True)
    kw = {}
    if seed is not None:
        opts.fix_existing_frames = True
        opts.multiple_models = False
        seed.write(out)
        kw["input_path"] = out
    found = pycolmap.incremental_mapping(db, images, out / "models", options=opts, **kw)
    return max(found.values(), key=lambda r: r.num_reg_images(), default=None)


def map_chunks(cfg, db: Path, images: Path, out: Path, names: list[str], stats: dict, size: int = 400,
               overlap: int = 100) -> dict:
    """{id: Reconstruction}: the photos ``names`` (capture order) mapped chunk by chunk (module
    docstring), largest model first. ``stats`` gets ``chunks``: the spans, per chunk its photos
    registered and seconds, and the join's seconds."""
    spans = chunk_spans(len(names), size, overlap)
    index = {n: i for i, n in enumerate(names)}
    info: dict = {"size": size, "overlap": overlap, "spans": spans, "chunks": {}}
    stats["chunks"] = info
    t0 = time.perf_counter()
    start = _start_model(cfg, db, images, out / "start", size, len(names))
    info["start"] = {"n_registered": int(start.num_reg_images()) if start else 0,
                     "seconds": round(time.perf_counter() - t0, 2)}
    if start is None or start.num_reg_images() < MIN_SHARED:
        first = 0
    else:
        held = [index[n] for n in registered_names(start)]
        first = max(range(len(spans)), key=lambda k: sum(spans[k][0] <= i < spans[k][1] for i in held))
    graph = match_graph(db, cfg.min_num_matches)
    results: dict[object, object] = {}           # chunk -> its model; "start" -> the start model
    group: dict[object, int] = {}                # chunk -> the model (frame) it belongs to
    picks: dict[int, dict[str, tuple[int, object]]] = {}   # frame -> name -> (centrality, chunk)
    if start is not None:
        results["start"], group["start"] = start, 0
        picks[0] = {n: (-1, "start") for n in registered_names(start)}
    for k, prev in growth_order(len(spans), first):
        s, e = spans[k]
        g = group.get("start" if prev is None else prev)
        held = {n: index[n] for n in picks.get(g, {})} if g is not None else {}
        chosen = seed_names(held, names[s:e], graph, overlap)
        seed = None
        if sum(s <= index[n] < e for n in chosen) >= MIN_SHARED:
            seed = crop(results, {n: picks[g][n][1] for n in chosen})
        else:
            chosen, g = [], max(picks, default=-1) + 1
        t = time.perf_counter()
        rec = _map_chunk(cfg, db, images, out / f"chunk_{k}", sorted(set(names[s:e]) | set(chosen), key=index.get),
                         seed)
        if rec is not None and rec.num_reg_images() >= 2:
            results[k], group[k] = rec, g
            pk = picks.setdefault(g, {})
            for n in registered_names(rec):
                c = centrality(index[n], spans[k])
                if n not in pk or c > pk[n][0]:
                    pk[n] = (c, k)
        info["chunks"][k] = {"span": [s, e], "seeded_with": len(chosen),
                             "n_registered": int(rec.num_reg_images()) if rec is not None else 0,
                             "seconds": round(time.perf_counter() - t, 2)}
        logger.info("sfm: chunk %d of %d (photos %d-%d): %d registered%s in %.0f s", k + 1, len(spans), s, e - 1,
                    info["chunks"][k]["n_registered"], f" (grown from {len(chosen)})" if seed is not None else
                    " (a model of its own)", time.perf_counter() - t)
    info["map_seconds"] = round(time.perf_counter() - t0, 2)
    t = time.perf_counter()
    models = []
    for g, pk in sorted(picks.items()):
        chunks = {k: results[k] for k in results if k != "start" and group[k] == g}
        if chunks:
            models.append(_join(cfg, db, images, out / f"joined_{g}", chunks, {n: c for n, (_, c) in pk.items()
                                                                                 if c != "start"}, info))
    info["join_seconds"] = round(time.perf_counter() - t, 2)
    return dict(enumerate(sorted(models, key=lambda r: -r.num_reg_images())))


def _join(cfg, db: Path, images: Path, out: Path, results: dict, pick: dict[str, int], info: dict):
    """One model of the chunk models ``results`` ({chunk: Reconstruction}, one frame): each photo at its
    pose in the chunk ``pick`` names for it (the one it lies most inside of), points triangulated from all
    the matches, one bundle adjustment of the whole. A single chunk's model is returned as it is."""
    import pycolmap

    from curate.sfm.reconstruction import seeded_pipeline_options
    if len(results) == 1:
        return next(iter(results.values()))
    poses = pycolmap.Reconstruction()
    for k, src in results.items():
        for iid in src.reg_image_ids():
            im = src.image(iid)
            if pick.get(im.name) != k:
                continue
            copy_image(poses, src, iid, keypoints=False)
    opts = seeded_pipeline_options(cfg)
    out.mkdir(parents=True, exist_ok=True)
    t = time.perf_counter()
    rec = pycolmap.triangulate_points(poses, db, images, out, clear_points=True, options=opts,
                                      refine_intrinsics=False)
    info["triangulate_seconds"] = round(info.get("triangulate_seconds", 0.0) + time.perf_counter() - t, 2)
    t = time.perf_counter()
    ba = pycolmap.BundleAdjustmentOptions()
    ba.refine_principal_point = False
    pycolmap.bundle_adjustment(rec, ba)
    info["points_filtered"] = int(pycolmap.ObservationManager(rec).filter_all_points3D(
        opts.mapper.filter_max_reproj_error, opts.mapper.filter_min_tri_angle))
    info["adjust_seconds"] = round(info.get("adjust_seconds", 0.0) + time.perf_counter() - t, 2)
    return rec


def map_rounds(cfg, db: Path, images: Path, out: Path, n_images: int, stats: dict, size: int = 250,
               final_ba: bool = True, iterative_ba: bool = False) -> dict:
    """{0: Reconstruction}: the whole-pool incremental mapper (curate's options for ``n_images`` photos) in
    rounds of ``size`` registrations, the frames of earlier rounds held fixed; then (``final_ba``) one
    bundle adjustment of the whole (``iterative_ba``: Ceres' iterative Schur solver past 100 images
    instead of its sparse direct one). ``stats["rounds"]``: per round its registered count and seconds."""
    import pycolmap

    from curate.sfm.reconstruction import incremental_options
    info: dict = {"rounds": []}
    stats["rounds"] = info
    seed = None
    r = 0
    t0 = time.perf_counter()
    while True:
        opts = incremental_options(cfg, n_images)
        opts.multiple_models = False
        snaps = out / f"round_{r}" / "snapshots"
        snaps.mkdir(parents=True, exist_ok=True)
        opts.snapshot_path, opts.snapshot_frames_freq = str(snaps), size
        kw = {}
        if seed is not None:
            opts.fix_existing_frames = True
            kw["input_path"] = seed
        token = pycolmap.CancellationToken()

        def on_image():
            if any(snaps.iterdir()):
                token.cancel()
        t = time.perf_counter()
        try:
            found = pycolmap.incremental_mapping(db, images, out / f"round_{r}" / "models", options=opts,
                                                 next_image_callback=on_image, cancellation_token=token, **kw)
        except InterruptedError:
            seed = sorted(snaps.iterdir())[-1]
            n = pycolmap.Reconstruction(seed).num_reg_images()
            info["rounds"].append({"n_registered": int(n), "seconds": round(time.perf_counter() - t, 2)})
            logger.info("sfm: round %d: %d registered in %.0f s", r, n, time.perf_counter() - t)
            r += 1
            continue
        best = max(found.values(), key=lambda m: m.num_reg_images())
        info["rounds"].append({"n_registered": int(best.num_reg_images()),
                               "seconds": round(time.perf_counter() - t, 2)})
        break
    info["map_seconds"] = round(time.perf_counter() - t0, 2)
    if final_ba and r > 0:
        t = time.perf_counter()
        ba = pycolmap.BundleAdjustmentOptions()
        ba.refine_principal_point = False
        if iterative_ba:
            ba.ceres.max_num_images_direct_sparse_cpu_solver = 100
        pycolmap.bundle_adjustment(best, ba)
        info["adjust_seconds"] = round(time.perf_counter() - t, 2)
    return {0: best}
