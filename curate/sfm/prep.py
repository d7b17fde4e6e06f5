"""The SfM stage's steps that need no pycolmap: stage key, ingest + quality, choices, outputs."""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import re
import time
from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras
from curate.core.images import IMAGE_EXTS, PhotoRecord
from curate.sfm.ingest import find_images, ingest, source_root
from curate.sfm.quality import assess, phash, sharpness
from curate.sfm.config import VIDEO_EXTS, SfmConfig
from curate.sfm.io import normalization
from curate.core.stage import hash_files, stage_key, write_json_atomic

logger = logging.getLogger(__name__)

_NOT_IN_KEY = ("num_threads", "progress", "on_split", "triangulate")
"""SfmConfig fields that do not change what SfM computes (``triangulate`` is for imports only)."""


def input_key(cfg: SfmConfig, photos: Path) -> str:
    """Stage key: config (execution-only fields excluded) + names and content of every file of ``photos``."""
    root = source_root(photos)
    imgs, other = find_images(photos, cfg.recursive)
    files = sorted(imgs + other, key=lambda p: p.relative_to(root).as_posix())
    h = hashlib.sha256("\n".join(p.relative_to(root).as_posix() for p in files).encode("utf-8", "surrogateescape"))
    conf = {k: v for k, v in dataclasses.asdict(cfg).items() if k not in _NOT_IN_KEY}
    return stage_key({"mode": "sfm", **conf}, [hash_files(files, h), str(photos)])


def prepare_photos(cfg: SfmConfig, photos: Path, out: Path) -> tuple[list[PhotoRecord], list[PhotoRecord], dict]:
    """Ingest into ``out/images`` and assess quality. Returns (all records, kept records, timings)."""
    t = time.perf_counter()
    metrics: dict[str, tuple[float, np.ndarray]] = {}

    def on_image(rec: PhotoRecord, rgb: np.ndarray) -> None:
        metrics[rec.working] = (sharpness(rgb), phash(rgb))   # working names are unique (ingest.unique_names)

    threads = cfg.num_threads if cfg.num_threads > 0 else 2
    videos: list[dict] = []
    records = ingest(photos, out / "images", cfg.max_image_size, cfg.recursive, threads, on_image, cfg.progress,
                     video=cfg.video, video_summaries=videos)
    assign_takes(records)
    t_ingest = round(time.perf_counter() - t, 2)
    t = time.perf_counter()
    good = [r for r in records if r.status == "kept"]
    if len({r.working for r in good}) != len(good):   # ingest.unique_names guarantees it; never compare a photo
        raise RuntimeError("sfm: two kept inputs share a working name")   # with itself or lose its file
    if good:
        sharp = np.array([metrics[r.working][0] for r in good])
        blurry, dup_of, dup_dist = assess(sharp, np.stack([metrics[r.working][1] for r in good]), cfg.blur_fraction,
                                          cfg.dup_max_distance)
        med = float(np.median(sharp))
        for i, r in enumerate(good):
            r.extra.update(sharpness=float(sharp[i]), sharpness_rel=float(sharp[i] / med) if med > 0 else 0.0,
                           blurry=bool(blurry[i]),
                           duplicate_of=good[dup_of[i]].rel if dup_of[i] >= 0 else None,
                           hash_distance=int(dup_dist[i]) if dup_of[i] >= 0 else None)
            if cfg.drop_duplicates and dup_of[i] >= 0:
                r.status = "dropped"
                r.reason = f"near-duplicate of {good[dup_of[i]].rel} (hash distance {dup_dist[i]}, kept the sharper)"
            elif cfg.drop_blurry and blurry[i]:
                r.status = "dropped"
                r.reason = f"blurry: sharpness {sharp[i] / med:.2f} x median < {cfg.blur_fraction}"
        for r in good:
            if r.status == "dropped":
                (out / "images" / r.working).unlink(missing_ok=True)
                logger.info("dropped %s: %s", r.rel, r.reason)
    kept = [r for r in records if r.status == "kept"]
    n_blur = sum(bool(r.extra.get("blurry")) for r in records)
    logger.info("quality: %d kept, %d dropped, %d flagged blurry", len(kept), len(good) - len(kept), n_blur)
    return records, kept, {"ingest": t_ingest, "quality": round(time.perf_counter() - t, 2), "videos": videos}


def too_few_message(photos: Path, records: list[PhotoRecord], videos: list[dict], images_json: Path) -> str:
    """Why SfM cannot start (fewer than 2 usable photos), in one line naming the input and, for each
    video or skipped file that explains it, what happened to it."""
    n = sum(r.status == "kept" for r in records)
    why = []
    for v in videos:
        rel, dec, cand = v.get("video"), v.get("decoded", 0), v.get("candidates", 0)
        kept = sum(r.status == "kept" and r.extra.get("video_rel") == rel for r in records)
        if kept > 1:
            continue
        if dec == 1:
            why.append(f"{rel} holds a single frame")
        elif dec > 1 and cand <= 1:
            why.append(f"the camera never moved in {rel}: the video gave {cand} candidate frame of {dec} because "
                       f"the view never changed (SfM needs views from at least 2 places)")
        elif cand > 1:
            why.append(f"the camera never moved in {rel}: its {cand} candidate frames are near-duplicates of one "
                       f"another (SfM needs views from at least 2 places)")
        if v.get("stopped"):
            why.append(f"{rel}: {v['stopped']}")
    if Path(photos).is_file():
        why += [r.reason if r.rel == Path(photos).name else f"{r.rel}: {r.reason}" for r in records
                if r.status == "skipped"]
        if why:
            return f"sfm: {photos}: " + "; ".join(why) + f"; see {images_json}"
    if (below := _in_subfolders(Path(photos), {r.rel for r in records})) is not None:
        why.append(below)
    return (f"sfm: too few usable photos in {photos} ({n}; SfM needs at least 2)" + "".join(f"; {w}" for w in why)
            + f"; see {images_json}")


def _in_subfolders(folder: Path, seen: set[str], limit: int = 100_000) -> str | None:
    """Where photos or videos of ``folder`` lie in subfolders that were not read (``seen``: the relative paths read;
    a capture's ``images/`` beside its README): what to give instead, or None. Looks at ``limit`` files at most
    (this is an error's hint)."""
    from itertools import islice
    if not folder.is_dir():
        return None
    found = [p for p in islice(folder.rglob("*"), limit) if p.suffix.lower() in IMAGE_EXTS | VIDEO_EXTS and p.is_file()
             and not any(q.startswith(".") for q in p.relative_to(folder).parts)
             and p.relative_to(folder).as_posix() not in seen]
    if not found:
        return None
    subs = sorted({p.relative_to(folder).parts[0] for p in found})
    return (f"{len(found)} photos or videos lie in its subfolders ({', '.join(subs[:3])}"
            f"{', ...' if len(subs) > 3 else ''}): give {folder / subs[0]} instead, or add --recursive")


def _trailing_number(name: str) -> tuple[str, int] | None:
    m = re.match(r"^(.*?)(\d+)$", Path(name).stem)
    return (m.group(1), int(m.group(2))) if m else None


def looks_sequential(names: list[str]) -> bool:
    """True when the (sorted) names are numbered frames: a common prefix and increasing numbers."""
    nums = [_trailing_number(n) for n in names]
    if len(names) < 3 or any(x is None for x in nums):
        return False
    prefixes = {x[0] for x in nums}  # type: ignore[index]
    vals = [x[1] for x in nums]  # type: ignore[index]
    return len(prefixes) == 1 and all(b > a for a, b in zip(vals, vals[1:]))


# ------------------------------------------------------------------ takes
def take_name(rec: PhotoRecord | dict) -> str:
    """The take a photo belongs to: a video frame's take is its video (path relative to the photo
    folder, ``walk2.mp4``); a photo's is the folder it lies in: ``photos`` for the photo folder itself,
    ``photos in a/b/`` for a sub-folder (``--recursive``). A video file itself (skipped) is its own take."""
    extra = rec.extra if isinstance(rec, PhotoRecord) else (rec.get("extra") or {})
    rel = rec.rel if isinstance(rec, PhotoRecord) else rec["rel"]
    if extra.get("video_rel"):
        return str(extra["video_rel"])
    from curate.sfm.config import VIDEO_EXTS
    if Path(rel).suffix.lower() in VIDEO_EXTS:
        return rel
    parent = Path(rel).parent.as_posix()
    return "photos" if parent in ("", ".") else f"photos in {parent}/"


def assign_takes(records: list[PhotoRecord]) -> None:
    """Record each photo's take (:func:`take_name`) in ``extra["take"]`` (images.json)."""
    for r in records:
        r.extra["take"] = take_name(r)


def takes_of(kept: list[PhotoRecord]) -> dict[str, list[str]]:
    """{take: working names of its kept photos, in name order}; takes in order of their first photo."""
    out: dict[str, list[str]] = {}
    for r in sorted(kept, key=lambda r: r.working):
        out.setdefault(r.extra.get("take") or take_name(r), []).append(r.working)
    return out


def cross_take_pairs(ranked, take_of: dict[str, str], per_take: int) -> list[tuple[str, str]]:
    """The image pairs to match between takes, from a retrieval ranking.

    Args:
        ranked: iterable of (query name, candidate names, most similar first) (the visual words'
            answer for each queried frame; the query itself may be among the candidates).
        take_of: name -> take, for every name of ``ranked``.
        per_take: how many of each query's most similar frames of *each other* take to keep.
    Returns:
        Unique pairs (a, b), a < b, sorted: for every query its ``per_take`` most similar frames of
        every other take. Pairs within a take are never returned (sequential matching has those).
    """
    pairs: set[tuple[str, str]] = set()
    for q, cands in ranked:
        tq = take_of[q]
        got: dict[str, int] = {}
        for c in cands:
            tc = take_of.get(c)
            if tc is None or tc == tq or got.get(tc, 0) >= per_take:
                continue
            got[tc] = got.get(tc, 0) + 1
            pairs.add((q, c) if q < c else (c, q))
    return sorted(pairs)


def take_counts(kept: list[PhotoRecord], in_model: set[str], in_other_parts: set[str]) -> list[dict]:
    """Per take (:func:`takes_of` order): {"take", "kind" ('video' | 'photos'), "n_frames" (its kept photos),
    "n_in_model" (in the model curate uses), "n_in_other_parts" (in the other models of a split)}."""
    out = []
    video = {r.extra.get("take") or take_name(r) for r in kept if r.extra.get("video")}
    for t, names in takes_of(kept).items():
        out.append({"take": t, "kind": "video" if t in video else "photos", "n_frames": len(names),
                    "n_in_model": sum(n in in_model for n in names),
                    "n_in_other_parts": sum(n in in_other_parts for n in names)})
    return out


def takes_not_joined(takes: list[dict], min_fraction: float) -> list[dict]:
    """The takes of a capture of two or more that have under ``min_fraction`` of their frames in the model."""
    if len(takes) < 2:
        return []
    return [t for t in takes if t["n_in_model"] < min_fraction * t["n_frames"]]


def choose_matcher(cfg: SfmConfig, kept: list[PhotoRecord]) -> str:
    """'auto': exhaustive up to ``exhaustive_max_images``; beyond: spatial with GPS on most photos,
    sequential for video frames (one video or several: each take is matched along itself, and with
    the other takes by :func:`cross_take_pairs`) and numbered photos, exhaustive for a video with
    photos, else retrieval (photos in no order: each with its ``retrieval_num_images`` most similar)."""
    if cfg.matcher != "auto":
        return cfg.matcher
    n = len(kept)
    if n <= cfg.exhaustive_max_images:
        return "exhaustive"
    if sum(r.has_gps for r in kept) >= 0.9 * n:
        return "spatial"
    # Video frames, or numbered photos: sequential (several videos: each along itself, and with the
    # others by cross-take retrieval). A video with photos stays exhaustive: matched sequentially, the
    # office video with every 5th office photo of the other half split and left all the photos out
    # (docs/sfm.md#takes), where exhaustive matching kept 30 of 38.
    if in_order(kept):
        return "sequential"
    if any(r.extra.get("video") for r in kept):
        logger.warning("sfm: %d frames and photos: exhaustive matching (quadratic time)", n)
        return "exhaustive"
    return "retrieval"


def in_order(kept: list[PhotoRecord]) -> bool:
    """The photos are a sequence: every one a video frame, or names numbered in order (``frame_00001.jpg``)."""
    return bool(kept) and (all(r.extra.get("video") for r in kept) or looks_sequential([r.rel for r in kept]))


def choose_guided(cfg: SfmConfig, kept: list[PhotoRecord]) -> bool:
    """Whether the pairs are matched again along their verified geometry (``cfg.guided_matching``; ``auto``: for a
    sequence of frames, :func:`in_order`, whatever the matcher: a 41-frame video is matched exhaustively)."""
    return cfg.guided_matching == "on" or (cfg.guided_matching == "auto" and in_order(kept))


def choose_camera_mode(cfg: SfmConfig, kept: list[PhotoRecord]) -> bool:
    """True for one shared camera: 'single', or 'auto' with one make/model/focal length and one working size."""
    if cfg.camera_mode != "auto":
        return cfg.camera_mode == "single"
    keys = {(r.make, r.model, r.focal_mm, r.focal_35mm, r.width, r.height) for r in kept}
    return len(keys) == 1


def write_outputs(out: Path, cams: Cameras, xyz, rgb, err, records: list, file_paths: list[str],
                  pct: float) -> dict:
    """Write cameras.json, transforms.json, points*.npy, normalization.json and images.json; returns stats."""
    from curate.core.transforms_json import write_transforms

    cams.save(out / "cameras.json")
    write_transforms(out / "transforms.json", cams, file_paths)
    if xyz is not None:
        np.save(out / "points.npy", np.asarray(xyz, np.float32).reshape(-1, 3))
        np.save(out / "points_rgb.npy", np.asarray(rgb, np.uint8).reshape(-1, 3))
        np.save(out / "points_error.npy", np.asarray(err, np.float32).reshape(-1))
    else:
        np.save(out / "points.npy", np.zeros((0, 3), np.float32))
    norm = normalization(cams, xyz, pct)
    write_json_atomic(out / "normalization.json", norm)
    reg = set(cams.names)
    recs = [dataclasses.asdict(r) if isinstance(r, PhotoRecord) else dict(r) for r in records]
    for r in recs:
        key = r["working"] or r["rel"]
        r["registered"] = r["status"] == "kept" and key in reg
    summary = {s: sum(r["status"] == s for r in recs) for s in ("kept", "dropped", "skipped")}
    summary["registered"] = sum(r["registered"] for r in recs)
    write_json_atomic(out / "images.json", {"summary": summary, "photos": recs})
    n_kept = max(summary["kept"], 1)
    return {"n_registered": summary["registered"], "registered_fraction": summary["registered"] / n_kept,
            "n_points": int(0 if xyz is None else len(xyz)),
            "unregistered": [r["rel"] for r in recs if r["status"] == "kept" and not r["registered"]]}


def database_bytes(n_images: int, matcher: str, cfg: SfmConfig) -> int:
    """About how many bytes COLMAP's database of ``n_images`` photos takes, at most: every photo's features
    (keypoints and 128-byte descriptors) and the matches of the pairs ``matcher`` matches, 512 matches of 8
    bytes a pair in each of two tables (raw and verified), with half again to spare. Measured: 0.2-3.2 kB a
    pair and table on the real sets (the drone flight, exhaustive: 2,775 pairs, 8 MB of matches; the fox 3 MB;
    the office, sequential, 3,644 pairs, 2 MB), features 1 MB a photo at most."""
    per_image = cfg.max_num_features * (128 + 24)
    if matcher == "exhaustive":
        pairs = n_images * (n_images - 1) // 2
    else:
        pairs = n_images * (cfg.sequential_overlap + 10)
    return int(1.5 * (n_images * per_image + pairs * 2 * 512 * 8)) + (64 << 20)


def check_free_space(folder: Path, n_images: int, matcher: str, cfg: SfmConfig) -> None:
    """``RuntimeError`` (one line, naming the folder) when its disk has less free space than COLMAP's database
    will need (:func:`database_bytes`), with a copy of it for each process that matches a piece of the pairs
    (:func:`curate.sfm.matching.match_list`): COLMAP's SQLite cannot say "disk full" but aborts the whole
    process."""
    import os
    import shutil
    procs = cfg.num_threads if cfg.num_threads > 0 else (os.cpu_count() or 1)
    copies = procs if procs > 1 else 0      # matching in pieces: a copy of the database for each process at once
    need = database_bytes(n_images, matcher, cfg) * (1 + copies)
    free = shutil.disk_usage(folder).free
    if free < need:
        raise RuntimeError(f"not enough free space on the disk of {folder}: SfM of {n_images} photos needs about "
                           f"{_size(need)} for COLMAP's database"
                           + (f" and a copy for each of {copies} matching processes" if copies else "")
                           + f", {_size(free)} are free; free some space (or give --out on another disk), then "
                           "run the same command again")


def _size(n: int) -> str:
    return f"{n / 2**30:.1f} GB" if n >= 2**30 else f"{n / 2**20:.0f} MB"
