"""Videos in: candidate frames chosen before SfM, so SfM never sees what the scene does not need.

A video is decoded with PyAV (FFmpeg inside the wheel, its decoder threads on: frame and
slice threading). For every frame, on small grey images scaled straight from the decoder's
picture (the frame is never converted to full-size RGB), the analysis measures its sharpness
(variance of the Laplacian at ``sharpness_side``) and how much the view changed since the
previous frame (mean absolute difference of grey thumbnails at ``analysis_side``). The walk is
cut into windows by accumulated change, not by time: a window closes when the view has changed
by ``VideoConfig.change_step`` since it opened, so a fast pan gives many windows and a walker
standing still gives none (frames whose change is below ``static_change`` add nothing). Each
window keeps its sharpest frame. Windows are decided as the frames come, so the same pass writes each window's frame
when the window closes (one decoded frame is held meanwhile): one decoding of the video. Only
when there are more windows than ``max_frames`` does the step grow (bisection) until the cap
holds, and a second pass writes the frames that choice adds (and the first pass's extra ones are
deleted from the working folder); the first pass stops writing as soon as the windows so far,
after a tenth of the video, are on course for more than 1.2 times the cap. The frames chosen
are those of :func:`choose` either way; what is written in the first pass only saves work.

Frames are written as working copies named by video and time, ``walk_000123.450.jpg``
(seconds, from each frame's own timestamp: variable frame rates are honoured; the prefix is
given by the caller, :mod:`curate.sfm.ingest`, which keeps every working name unique),
converted once, from the decoder's picture straight to the working size (FFmpeg's Lanczos
scaler), upright (the stream's display rotation applied), 8-bit sRGB (10-bit and HDR are
converted by FFmpeg). A damaged tail stops the decoding there, whether the decoder raises or
(with threads) just ends early: the last decoded time is checked against the duration the
file's header declares, and the summary's ``stopped`` says where it stopped; what was decoded
is used. Near-duplicates among the candidates are then dropped by the same test as photos
(:mod:`curate.sfm.quality`).
"""

from __future__ import annotations

import logging
import time as _time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from curate.sfm.config import VIDEO_EXTS, VideoConfig  # the options live with SfM's

__all__ = ["VIDEO_EXTS", "VideoConfig", "FrameInfo", "NoVideoStream", "analyse", "windows", "choose", "frame_name",
           "extract", "check_options"]

log = logging.getLogger(__name__)


class NoVideoStream(ValueError):
    """The file opens but holds no video stream (an audio-only .mp4, say): skipped with this reason."""


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


def check_options(cfg: VideoConfig) -> None:
    """ValueError naming the user's flag when an option that only matters for videos is out of range
    (checked when there is a video to read, so a photo-only run never fails on it)."""
    m = cfg.max_frames
    if not isinstance(m, (int, np.integer)) or isinstance(m, bool) or m < 2:
        raise ValueError(f"--max-frames must be an integer >= 2 (the most candidate frames a video gives), got {m!r}")


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


def _open(path: Path):
    """(container, its first video stream) with FFmpeg's decoder threads on; :class:`NoVideoStream`
    when the file holds no video stream (an audio-only file, say)."""
    import av
    container = av.open(str(path))
    if not container.streams.video:
        kinds = sorted({s.type for s in container.streams})
        container.close()
        what = f"only {' and '.join(kinds)}" if kinds else "no streams"
        raise NoVideoStream(f"no video stream in this file ({what}): nothing to take frames from")
    stream = container.streams.video[0]
    stream.thread_type = "AUTO"
    return container, stream


def _declared_end(container, stream) -> tuple[float | None, bool]:
    """(seconds at which the header says the video ends, or None; whether that is the video stream's
    own duration rather than the container's, which may count a longer audio track)."""
    if stream.duration and stream.time_base:
        return float(((stream.start_time or 0) + stream.duration) * stream.time_base), True
    if container.duration:
        start = container.start_time or 0
        return (start + container.duration) / 1e6, len(container.streams) == 1
    return None, False


class _Decode:
    """The frames of a video's first video stream, (index, time, av.VideoFrame), in order; after the
    loop, ``error`` says why the decoder raised ("" when it did not) and :meth:`stopped` whether it
    ended before the end the file declares."""

    def __init__(self, path: Path):
        self.path = path
        self.error = ""
        self.last_time: float | None = None
        self.n = 0
        self.end: float | None = None
        self.own_end = False
        self.rate = 30.0
        self._times: list[float] = []

    def __iter__(self):
        import av
        container, stream = _open(self.path)
        try:
            self.end, self.own_end = _declared_end(container, stream)
            self.rate = float(stream.average_rate or stream.guessed_rate or 30)
            i = 0
            try:
                for frame in container.decode(stream):
                    t = float(frame.time) if frame.time is not None else i / self.rate
                    self.last_time = t
                    self._times.append(t)
                    del self._times[:-31]
                    self.n = i + 1
                    yield i, t, frame
                    i += 1
            except (av.error.InvalidDataError, av.error.EOFError, OSError) as e:
                self.error = f"{type(e).__name__}: {e}"
        finally:
            container.close()

    def stopped(self) -> str:
        """Why the decoding ended before the video's end, or "" when it reached it."""
        if self.last_time is None:
            return self.error                        # nothing decoded: the caller says so
        dt = float(np.median(np.diff(self._times))) if len(self._times) > 1 else 1.0 / self.rate
        dt = dt if dt > 0 else 1.0 / self.rate
        short = False
        if self.end is not None:
            # the header's end is the last frame's time plus its duration; an audio track may run a little
            # longer than the picture, hence the wider margin when only the container's duration is known
            short = self.end - (self.last_time + dt) > max(2 * dt, 0.2 if self.own_end else 1.0)
        if short:
            msg = (f"decoding stopped at {self.last_time:.1f} s of {self.end:.1f} s: "
                   f"the file is damaged or cut after that point")
            return msg + (f" ({self.error})" if self.error else "")
        if self.error:
            return f"decoding stopped after {self.n} frames at {self.last_time:.1f} s: {self.error}"
        return ""


class _Windows:
    """:func:`windows` as the frames come: each window's sharpest frame is known when it closes."""

    def __init__(self, step: float, static: float, emit):
        self.step, self.static, self.emit = step, static, emit
        self.acc = step                      # the first frame opens a window
        self.best = None                     # (FrameInfo, frame) of the open window
        self.n = 0

    def add(self, f: FrameInfo, frame) -> None:
        self.acc += f.change if f.change >= self.static else 0.0
        if self.acc >= self.step or self.best is None:
            self.close()
            self.best, self.acc = (f, frame), 0.0
            self.n += 1
        elif f.sharpness > self.best[0].sharpness:   # ties: the earlier frame, as choose() does
            self.best = (f, frame)

    def close(self) -> None:
        if self.best is not None:
            self.emit(*self.best)
            self.best = None


def analyse(path: Path, cfg: VideoConfig, on_frame=None) -> tuple[list[FrameInfo], str, int]:
    """First pass: (per-frame measures, why decoding stopped early or "", display rotation).
    ``on_frame(info, frame)`` is called with every decoded frame (an ``av.VideoFrame``)."""
    out: list[FrameInfo] = []
    prev = None
    rotation = 0
    dec = _Decode(path)
    for i, t, frame in dec:
        rotation = int(getattr(frame, "rotation", 0) or 0)
        # both measures from the decoder's picture scaled straight to a small grey image (no full-size RGB);
        # the thumbnail is scaled from the frame too, not from the sharpness image: that saved no CPU beyond
        # the noise at 4K (decoding is the cost) and moved 43 of 1000 candidates of the benchmark walk (docs/sfm.md)
        w, h = _fit(frame.width, frame.height, cfg.analysis_side)
        small = frame.reformat(width=w, height=h, format="gray").to_ndarray().astype(np.float32) / 255.0
        sw, sh = _fit(frame.width, frame.height, cfg.sharpness_side)
        sharp = _laplacian_var(frame.reformat(width=sw, height=sh, format="gray").to_ndarray())
        change = 0.0 if prev is None else float(np.mean(np.abs(small - prev)))
        prev = small
        f = FrameInfo(i, t, sharp, change)
        out.append(f)
        if on_frame is not None:
            on_frame(f, frame)
    return out, dec.stopped(), rotation


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
    check_options(cfg)
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


def frame_name(video: Path, t: float, prefix: str | None = None) -> str:
    """Working-copy name of the frame at ``t`` seconds of ``video``: ``walk_000123.450.jpg``
    (``prefix`` instead of the video's stem when given)."""
    return f"{video.stem if prefix is None else prefix}_{t:010.3f}.jpg"


def _write(frame, t: float, i: int, rotation: int, path: Path, rel: str, out_dir: Path, max_size: int,
           prefix: str | None):
    """Write one frame's working copy (at most ``max_size`` on its longer side, upright); its record."""
    from PIL import Image
    from curate.core.images import PhotoRecord
    sw, sh = frame.width, frame.height                               # as stored
    w0, h0 = (sh, sw) if int(round((rotation or 0) / 90.0)) % 2 else (sw, sh)   # as shown
    s = min(1.0, max_size / max(w0, h0))
    if s < 1.0:          # scaled from the decoder's picture: one conversion, at the working size
        rgb = frame.reformat(width=max(1, round(sw * s)), height=max(1, round(sh * s)), format="rgb24",
                             interpolation="LANCZOS").to_ndarray()
    else:
        rgb = frame.to_ndarray(format="rgb24")
    im = Image.fromarray(np.ascontiguousarray(_upright(rgb, rotation)))
    name = frame_name(path, t, prefix)
    im.save(out_dir / name, format="JPEG", quality=95)
    w, h = im.size
    rec = PhotoRecord(original=str((out_dir / name).resolve()), rel=name, status="kept", working=name,
                      orig_width=w0, orig_height=h0, width=w, height=h, scale_x=w / w0, scale_y=h / h0,
                      format="jpeg")
    rec.extra.update(video=str(path.resolve()), video_rel=rel, time=round(t, 3), frame=i)
    return rec


def extract(path: Path, rel: str, out_dir: Path, max_size: int, cfg: VideoConfig, prefix: str | None = None):
    """Choose and write the candidate frames of the video ``path``, named ``{prefix}_{time}.jpg``
    (``prefix``: the video's stem by default); returns (records of the frames, a summary dict).
    The video is only read."""
    check_options(cfg)
    t0 = _time.perf_counter()
    written: dict[int, object] = {}
    container, stream = _open(path)
    try:
        end, _ = _declared_end(container, stream)
        start = float((stream.start_time or 0) * stream.time_base) if stream.time_base else 0.0
    finally:
        container.close()
    cap_binds = [False]

    def emit(f: FrameInfo, frame) -> None:
        # more windows than the cap (or on course for more than 1.2 x the cap, judged after a tenth of
        # the video): the step will grow and a second pass writes what that choice adds; the frames
        # written so far are kept where it chooses them too. Only the cost depends on this guess.
        seen = f.time - start
        if len(written) >= cfg.max_frames or (end is not None and end - start > 0 and seen > 0.1 * (end - start)
                                              and online.n * (end - start) / seen > 1.2 * cfg.max_frames):
            cap_binds[0] = True
        if cap_binds[0]:
            return
        written[f.index] = _write(frame, f.time, f.index, int(getattr(frame, "rotation", 0) or 0), path, rel,
                                  out_dir, max_size, prefix)

    online = _Windows(cfg.change_step, cfg.static_change, emit)
    info, note, rotation = analyse(path, cfg, on_frame=online.add)
    online.close()
    chosen, counts = choose(info, cfg)
    seconds = {"first_pass": round(_time.perf_counter() - t0, 2)}
    want = set(chosen)
    for k in sorted(set(written) - want):            # the cap made the windows longer: these were not chosen
        (out_dir / written.pop(k).working).unlink(missing_ok=True)
    missing = want - set(written)
    if missing:                                      # the frames the longer windows chose: a second pass
        t1 = _time.perf_counter()
        for i, t, frame in _Decode(path):
            if i in missing:
                written[i] = _write(frame, t, i, rotation, path, rel, out_dir, max_size, prefix)
                missing.discard(i)
                if not missing:
                    break
        seconds["second_pass"] = round(_time.perf_counter() - t1, 2)
    recs = [written[k] for k in chosen if k in written]
    summary = {"video": rel, **counts, "rotation": rotation, "stopped": note, "passes": 2 if "second_pass" in seconds
               else 1, "seconds": seconds}
    log.info("video %s: %d frames decoded, %d candidates (%d static, %d not the sharpest in their window)",
             rel, counts.get("decoded", 0), len(recs), counts.get("static", 0), counts.get("not_sharpest_in_window", 0))
    if note:
        log.warning("video %s: %s", rel, note)
    return recs, summary
