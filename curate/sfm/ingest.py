"""Ingest a folder of photos: find, decode, orient, downscale into working copies.

Input formats: JPEG, PNG, TIFF (through Pillow) and camera RAW (``.dng .cr2 .cr3
.nef .arw .orf .rw2 .raf .pef .srw .kdc``, through rawpy with the camera white
balance, 8-bit sRGB output). EXIF orientation is applied (``ImageOps.exif_transpose``;
rawpy applies the RAW's own flip), so a working copy is upright.

Each good photo gets a *working copy* in ``out_dir`` whose longer side is at most
``max_size`` pixels: JPEG (quality 95, EXIF kept so COLMAP can read focal length and
GPS) for JPEG and RAW sources, PNG for PNG and TIFF sources. A JPEG that needs neither
rotation nor resizing is copied byte for byte. Working names are the photo's path
relative to the input folder with ``/`` replaced by ``__``, plus ``.jpg``/``.png``
when the original extension differs (``a/IMG_1.CR2`` -> ``a__IMG_1.CR2.jpg``); a video's
frames are named by video and time (``walk_000123.450.jpg``, :mod:`curate.sfm.video`).

Working names are unique across photos and video frames (:func:`unique_names`): where two
inputs would get the same name, the first in the order below keeps it and the other is
named apart, deterministically, so a name never changes unless it clashes. Photos come
first (fewest folder levels, then path order); a photo that clashes gets ``~2`` (``~3``...)
before its extension (``a__b.jpg`` in the folder and ``a/b.jpg`` with ``--recursive``: the
second is ``a__b~2.jpg``). Videos follow: a video's frames are named by its stem unless a
photo is named like one of its frames or an earlier video has the same stem; then by its whole
relative path (``clip.mp4_000000.000.jpg``, ``a__walk.mp4_000001.500.jpg``).

Files that cannot be used (unsupported extension, empty, truncated, not an image,
undecodable RAW) are *skipped* with a reason; the run goes on. The input folder is
only ever read.
"""

from __future__ import annotations

import logging
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from curate.core.images import IMAGE_EXTS, PhotoRecord, broken_said, read_image

logger = logging.getLogger(__name__)



NOT_UTF8 = ("its file name is not UTF-8 text (bytes of another encoding, such as Latin-1): curate names every photo in "
            "its records and exports; rename it")
"""Why a photo whose name is not UTF-8 is skipped (and listed): never fatal."""


def text_name(p: str | Path) -> bool:
    """True when the path ``p`` is text (a name the file system gave in bytes that are not UTF-8 is read by Python
    with surrogates: :func:`os.fsdecode`), so it can be written to a JSON record, a page or a COLMAP model."""
    try:
        str(p).encode("utf-8")
        return True
    except UnicodeEncodeError:
        return False


def printable(s: str | Path) -> str:
    """``s`` with the bytes of a name that are not UTF-8 written as ``\\xe9``: what a record says of such a file."""
    return str(s).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


def find_images(folder: str | Path, recursive: bool = False) -> tuple[list[Path], list[Path]]:
    """Files of ``folder`` (sorted by relative path), split into (image-like, other).

    Hidden files (name starting with ``.``) are ignored; directories are entered only
    when ``recursive``. A link that leads to no file (its target gone, or a loop) is kept, so that it is
    skipped and listed with its reason like any unreadable file, never dropped without a word.
    """
    folder = Path(folder)
    if folder.is_file():   # one video (or photo) given instead of a folder
        return ([folder], []) if folder.suffix.lower() in IMAGE_EXTS else ([], [folder])
    if not folder.is_dir():
        raise FileNotFoundError(f"photo folder {folder} does not exist")
    it = folder.rglob("*") if recursive else folder.iterdir()
    files = sorted((p for p in it if (p.is_file() or p.is_symlink() and not p.is_dir()) and not any(
        part.startswith(".") for part in p.relative_to(folder).parts)),
        key=lambda p: p.relative_to(folder).as_posix())
    imgs = [p for p in files if p.suffix.lower() in IMAGE_EXTS]
    other = [p for p in files if p.suffix.lower() not in IMAGE_EXTS]
    return imgs, other


def working_name(rel: str, fmt: str, tag: str = "") -> str:
    """Working-copy file name for the photo at ``rel`` (relative posix path); ``tag`` (``~2``) goes
    before the extension of a name that would clash (:func:`unique_names`)."""
    flat = rel.replace("/", "__")
    want = ".png" if fmt in ("png", "tiff") else ".jpg"
    ok = {".png"} if want == ".png" else {".jpg", ".jpeg"}
    suffix = Path(flat).suffix
    if suffix.lower() in ok:
        return flat[: len(flat) - len(suffix)] + tag + suffix
    return flat + tag + want


def _frame_pattern(prefix: str):
    """The working names of a video's frames with this prefix (:func:`curate.sfm.video.frame_name`)."""
    import re
    return re.compile(re.escape(prefix) + r"_-?\d+\.\d{3}\.jpg")


def unique_names(photos: list[str], videos: list[str]) -> tuple[dict[str, str], dict[str, str]]:
    """Working names unique across photos and video frames: (photo rel -> tag for
    :func:`working_name`, video rel -> prefix of its frames' names), see the module docstring.

    A photo's name depends on its format (known once decoded), so both names it could get
    (JPEG and PNG copy) are reserved. A video's frame names are ``{prefix}_{seconds}.jpg``: two
    different prefixes never give the same name, so a prefix is free when no other video has it
    and no photo's name matches its pattern.
    """
    order = lambda r: (r.count("/"), r)  # noqa: E731
    taken: set[str] = set()
    tags: dict[str, str] = {}
    for rel in sorted(photos, key=order):
        k = 1
        while True:
            tag = "" if k == 1 else f"~{k}"
            names = {working_name(rel, "jpeg", tag), working_name(rel, "png", tag)}
            if not names & taken:
                break
            k += 1
        taken |= names
        tags[rel] = tag
    prefixes: dict[str, str] = {}
    for rel in sorted(videos, key=order):
        flat = rel.replace("/", "__")
        k = 0
        while True:
            p = Path(rel).stem if k == 0 else flat if k == 1 else f"{flat}~{k}"
            pat = _frame_pattern(p)
            if p not in prefixes.values() and not any(pat.fullmatch(n) for n in taken):
                break
            k += 1
        prefixes[rel] = p
        if k:
            logger.info("video %s: its frames are named %s_<seconds>.jpg (%s_<seconds>.jpg would clash with "
                        "another input's names)", rel, p, Path(rel).stem)
    return tags, prefixes


def _resize(rgb: np.ndarray, max_size: int) -> np.ndarray:
    from PIL import Image
    h, w = rgb.shape[:2]
    if max_size <= 0 or max(h, w) <= max_size:
        return rgb
    s = max_size / max(h, w)
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    return np.asarray(Image.fromarray(rgb).resize((nw, nh), Image.LANCZOS))


def ingest_one(path: Path, folder: Path, out_dir: Path, max_size: int,
               tag: str = "") -> tuple[PhotoRecord, np.ndarray | None]:
    """Read one photo and write its working copy (named by :func:`working_name` with ``tag``).
    Returns the record and the working image [H, W, 3]."""
    from PIL import Image

    rel = path.relative_to(folder).as_posix()
    rec = PhotoRecord(original=str(path.resolve()), rel=rel)
    try:
        rgb, info = read_image(path)
    except (OSError, ValueError) as e:
        rec.status, rec.reason = "skipped", str(e)
        return rec, None
    rec.format = info["format"]
    for k in ("orientation", "make", "model", "focal_mm", "focal_35mm", "has_gps"):
        if k in info:
            setattr(rec, k, info[k])
    rec.orig_height, rec.orig_width = rgb.shape[:2]
    small = _resize(rgb, max_size)
    rec.height, rec.width = small.shape[:2]
    rec.scale_x, rec.scale_y = rec.width / rec.orig_width, rec.height / rec.orig_height
    rec.working = working_name(rel, rec.format, tag)
    dst = out_dir / rec.working
    if rec.format == "jpeg" and small is rgb and rec.orientation == 1:
        shutil.copyfile(path, dst)  # nothing to change: keep the original bytes
    elif dst.suffix.lower() == ".png":
        Image.fromarray(small).save(dst, format="PNG", compress_level=1)
    else:
        kw = {"exif": info["exif"]} if info.get("exif") else {}
        Image.fromarray(small).save(dst, format="JPEG", quality=95, **kw)
    return rec, small


def source_root(photos: str | Path) -> Path:
    """The folder a capture's file names are relative to: the photo folder, or a single video's folder."""
    photos = Path(photos)
    return photos.parent if photos.is_file() else photos


def ingest(folder: str | Path, out_dir: str | Path, max_size: int = 1600, recursive: bool = False,
           num_threads: int = 2, on_image=None, progress: bool = True, video=None,
           video_summaries: list | None = None) -> list[PhotoRecord]:
    """Ingest every file of ``folder`` into working copies in ``out_dir``.

    Args:
        on_image: optional ``callback(record, rgb [H, W, 3] uint8)`` for every kept image
            (quality metrics are computed through it, so each photo is decoded once).
        video: :class:`curate.sfm.video.VideoConfig` for the videos among the files (or ``folder``
            itself, one video): their candidate frames become records of their own, named by video
            and time (:mod:`curate.sfm.video`); each video's summary goes to ``video_summaries``.
    Returns:
        One record per file in the folder (kept or skipped) and per candidate video frame, sorted
        by relative path.
    """
    from tqdm import tqdm
    from curate.sfm.video import VIDEO_EXTS, NoVideoStream, VideoConfig, check_options, extract

    path, out_dir = Path(folder), Path(out_dir)
    folder = source_root(path)
    out_dir.mkdir(parents=True, exist_ok=True)
    imgs, other = find_images(path, recursive)
    odd = [p for p in imgs + other if not text_name(p)]            # names not UTF-8: skipped and listed, never fatal
    imgs, other = [p for p in imgs if text_name(p)], [p for p in other if text_name(p)]
    broken = [p for p in imgs + other if not p.is_file()]          # links to nothing: listed, never dropped
    imgs, other = [p for p in imgs if p.is_file()], [p for p in other if p.is_file()]
    videos = [p for p in other if p.suffix.lower() in VIDEO_EXTS]
    other = [p for p in other if p.suffix.lower() not in VIDEO_EXTS]
    video = video or VideoConfig()
    if videos:
        check_options(video)          # an option for videos is checked when there is one (ValueError: the flag)
    rel_of = {p: p.relative_to(folder).as_posix() for p in imgs + videos}
    tags, prefixes = unique_names([rel_of[p] for p in imgs], [rel_of[p] for p in videos])
    records = [PhotoRecord(original=str(p.resolve()), rel=p.relative_to(folder).as_posix(), status="skipped",
                           reason=f"unsupported extension {p.suffix!r}") for p in other]
    records += [PhotoRecord(original=str(p.absolute()), rel=p.relative_to(folder).as_posix(), status="skipped",
                            reason=broken_said(p)) for p in broken]
    records += [PhotoRecord(original=printable(p.absolute()), rel=printable(p.relative_to(folder).as_posix()),
                            status="skipped", reason=NOT_UTF8) for p in odd]
    for v in videos:
        rel = rel_of[v]
        try:
            frames, summary = extract(v, rel, out_dir, max_size, video, prefix=prefixes[rel])
        except NoVideoStream as e:    # an audio-only file: the reason as it is
            records.append(PhotoRecord(original=str(v.resolve()), rel=rel, status="skipped", reason=str(e)))
            continue
        except Exception as e:  # noqa: BLE001 - PyAV's errors: an unreadable video is skipped, like a photo
            records.append(PhotoRecord(original=str(v.resolve()), rel=rel, status="skipped",
                                       reason=f"cannot decode the video: {type(e).__name__}: {e}"))
            continue
        if video_summaries is not None:
            video_summaries.append({**summary, "frame_prefix": prefixes[rel]})
        if not frames:
            records.append(PhotoRecord(original=str(v.resolve()), rel=rel, status="skipped",
                                       reason="no decodable frame" + (f" ({summary['stopped']})"
                                                                      if summary.get("stopped") else "")))
        if on_image is not None:
            from PIL import Image
            for r in frames:
                with Image.open(out_dir / r.working) as im:
                    on_image(r, np.asarray(im.convert("RGB")))
        records += frames

    def work(p: Path) -> PhotoRecord:
        rec, rgb = ingest_one(p, folder, out_dir, max_size, tags[rel_of[p]])
        if rgb is not None and on_image is not None:
            on_image(rec, rgb)
        return rec

    with ThreadPoolExecutor(max(1, num_threads)) as pool:
        recs = list(tqdm(pool.map(work, imgs), total=len(imgs), desc="ingest", unit="img",
                         disable=not progress, leave=False))
    records += recs
    records.sort(key=lambda r: r.rel)
    n_skip = sum(r.status == "skipped" for r in records)
    logger.info("ingest: %d photos read, %d files skipped", len(records) - n_skip, n_skip)
    for r in records:
        if r.status == "skipped":
            logger.warning("skipped %s: %s", r.rel, r.reason)
    return records
