"""Videos in: candidate frames chosen before SfM, so SfM never sees what the scene does not need.

A video is decoded twice with PyAV (FFmpeg inside the wheel). The first pass measures, per
frame at a small size, its sharpness (variance of the Laplacian) and how much the view changed
since the previous frame (mean absolute difference of grey thumbnails). The walk is cut into
windows by accumulated change, not by time: a window closes when the view has changed by
``VideoConfig.change_step`` since it opened, so a fast pan gives many windows and a walker
standing still gives none (frames whose change is below ``static_change`` add nothing). The
step grows (bisection) until there are at most ``max_frames`` windows. Each window keeps its
sharpest frame. The second pass writes those frames as working copies named by video and time,
``walk_000123.450.jpg`` (seconds, from each frame's own timestamp: variable frame rates are
honoured), upright (the stream's display rotation applied), 8-bit sRGB (10-bit and HDR are
converted by FFmpeg). A damaged tail stops the decoding there; what was decoded is used and the
rest is recorded. Near-duplicates among the candidates are then dropped by the same test as
photos (:mod:`curate.sfm.quality`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from curate.sfm.config import VIDEO_EXTS, VideoConfig  # the options live with SfM's

__all__ = ["VIDEO_EXTS", "VideoConfig", "FrameInfo", "analyse", "windows", "choose", "frame_name", "extract"]

log = logging.getLogger(__name__)


@dataclass
class FrameInfo:
    """What the first pass measured of one decoded frame."""

    index: int
    """Position in decoding order."""
    time: float
    """Seconds from the stream's start (from the frame's timestamp)."""
    sharpness: float
    """Variance of the Laplacian of the grey frame at ``sharpness_side``."""
    change: float
    """Mean absolute grey difference to the previous frame (0 for the first), 0..1."""


def _fit(w: int, h: int, side: int) -> tuple[int, int]:
    s = min(1.0, side / max(w, h))
    return max(2, int(round(w * s / 2)) * 2), max(2, int(round(h * s / 2)) * 2)


def _upright(a: np.ndarray, rotation: int) -> np.ndarray:
    """[H, W, ...] rotated by the stream's display rotation (degrees counter-clockwise, as FFmpeg reports)."""
    k = int(round((rotation or 0) / 90.0)) % 4
    return np.rot90(a, k) if k else a


def _laplacian_var(g: np.ndarray) -> float:
    g = g.astype(np.float32)
    lap = -4 * g[1:-1, 1:-1] + g[:-2, 1:-1] + g[2:, 1:-1] + g[1:-1, :-2] + g[1:-1, 2:]
    return float(lap.var()) if lap.size else 0.0


def _frames(path: Path):
    """Yield (index, time, av.VideoFrame) of the first video stream; stops at a damaged tail,
    recording why in the generator's return value (StopIteration.value)."""
    import av
    container = av.open(str(path))
    try:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        i = 0
        try:
            for frame in container.decode(stream):
                t = float(frame.time) if frame.time is not None else i / float(stream.average_rate or 30)
                yield i, t, frame
                i += 1
        except (av.error.InvalidDataError, av.error.EOFError, OSError) as e:
            return f"decoding stopped after {i} frames: {type(e).__name__}: {e}"
        return ""
    finally:
        container.close()


def analyse(path: Path, cfg: VideoConfig) -> tuple[list[FrameInfo], str, int]:
    """First pass: (per-frame measures, why decoding stopped early or "", display rotation)."""
    out: list[FrameInfo] = []
    prev = None
    rotation = 0
    gen = _frames(path)
    while True:
        try:
            i, t, frame = next(gen)
        except StopIteration as stop:
            note = stop.value or ""
            break
        rotation = int(getattr(frame, "rotation", 0) or 0)
        w, h = _fit(frame.width, frame.height, cfg.analysis_side)
        small = frame.reformat(width=w, height=h, format="gray").to_ndarray().astype(np.float32) / 255.0
        sw, sh = _fit(frame.width, frame.height, cfg.sharpness_side)
        sharp = _laplacian_var(frame.reformat(width=sw, height=sh, format="gray").to_ndarray())
        change = 0.0 if prev is None else float(np.mean(np.abs(small - prev)))
        prev = small
        out.append(FrameInfo(i, t, sharp, change))
    return out, note, rotation


def windows(info: list[FrameInfo], step: float, static: float) -> list[list[int]]:
    """Frames grouped into windows of accumulated view change ``step``; static frames add no change."""
    groups: list[list[int]] = []
    acc = step  # the first frame opens a window
    for f in info:
        c = f.change if f.change >= static else 0.0
        acc += c
        if acc >= step or not groups:
            groups.append([f.index])
            acc = 0.0
        else:
            groups[-1].append(f.index)
    return groups


def choose(info: list[FrameInfo], cfg: VideoConfig) -> tuple[list[int], dict]:
    """Indices of the candidate frames (the sharpest of each window) and counts of why the others went."""
    if not info:
        return [], {"decoded": 0, "candidates": 0}
    step = cfg.change_step
    groups = windows(info, step, cfg.static_change)
    if len(groups) > cfg.max_frames:          # bisection on the step until the cap holds
        lo, hi = step, step
        while len(windows(info, hi, cfg.static_change)) > cfg.max_frames:
            lo, hi = hi, hi * 2
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if len(windows(info, mid, cfg.static_change)) > cfg.max_frames:
                lo = mid
            else:
                hi = mid
        step = hi
        groups = windows(info, step, cfg.static_change)
    chosen = [max(g, key=lambda k: (info[k].sharpness, -k)) for g in groups]
    static = sum(1 for f in info[1:] if f.change < cfg.static_change)
    return chosen, {"decoded": len(info), "candidates": len(chosen), "static": static,
                    "not_sharpest_in_window": len(info) - len(chosen), "change_step": round(step, 5)}


def frame_name(video: Path, t: float) -> str:
    """Working-copy name of the frame at ``t`` seconds of ``video``: ``walk_000123.450.jpg``."""
    return f"{video.stem}_{t:010.3f}.jpg"


def extract(path: Path, rel: str, out_dir: Path, max_size: int, cfg: VideoConfig):
    """Choose and write the candidate frames of the video ``path``; returns (records of the frames,
    a summary dict). The video is only read."""
    from PIL import Image
    from curate.sfm.ingest import PhotoRecord
    info, note, rotation = analyse(path, cfg)
    chosen, counts = choose(info, cfg)
    want = set(chosen)
    recs = []
    gen = _frames(path)
    for i, t, frame in gen:
        if i not in want:
            continue
        rgb = _upright(frame.to_ndarray(format="rgb24"), rotation)
        h0, w0 = rgb.shape[:2]
        s = min(1.0, max_size / max(w0, h0))
        im = Image.fromarray(np.ascontiguousarray(rgb))
        if s < 1.0:
            im = im.resize((max(1, round(w0 * s)), max(1, round(h0 * s))), Image.LANCZOS)
        name = frame_name(path, t)
        im.save(out_dir / name, format="JPEG", quality=95)
        w, h = im.size
        rec = PhotoRecord(original=str((out_dir / name).resolve()), rel=name, status="kept", working=name,
                          orig_width=w0, orig_height=h0, width=w, height=h, scale_x=w / w0, scale_y=h / h0,
                          format="jpeg")
        rec.extra.update(video=str(path.resolve()), video_rel=rel, time=round(t, 3), frame=i)
        recs.append(rec)
        if len(recs) == len(want):
            gen.close()
            break
    summary = {"video": rel, **counts, "rotation": rotation, "stopped": note}
    log.info("video %s: %d frames decoded, %d candidates (%d static, %d not the sharpest in their window)%s",
             rel, counts.get("decoded", 0), len(recs), counts.get("static", 0), counts.get("not_sharpest_in_window", 0),
             f"; {note}" if note else "")
    return recs, summary
