#!/usr/bin/env python
"""Benchmark video ingest: the candidate-selection (analysis) pass and the extraction of a long 4K walk.

    python3 -m research.bench.bench_video [--office ../shared/data/office] [--seconds 120] [--fps 30]

A phone records 4K at 30-60 fps: a 2-minute walk is 3,600-7,200 frames of 3840x2160. This
script makes such a walk once (cached under ``--work``, never in the repository): a hand-held
loop through the synthetic living room (:func:`curate.simulate.walks.hand_held_walk`,
:mod:`curate.simulate.synthetic`) rendered at ``--render-size`` (320x180) and ``--fps``, with
motion blur for a 1/60 s shutter, stored losslessly (FFV1); then upscaled (bicubic) by FFmpeg's
scaler to ``--size`` (3840x2160) and encoded as H.264 (x264 ``superfast``, CRF 20, a key frame
every second, as phones do; ``--codec libx265`` for HEVC): 39.5 Mbit/s, a phone's bit rate
for 4K at 30 fps (``--grain`` adds film grain, and bit rate, for a harder case). Then, for that
video (and ``office.mp4`` with ``--office``), each of ``--repeats`` times in this process:

* ``analysis``: :func:`curate.sfm.video.analyse` + :func:`curate.sfm.video.choose` (decode every
  frame, measure view change and sharpness, choose the candidates): the candidate selection;
* ``extract``: :func:`curate.sfm.video.extract`, the whole of what ingest does with a video
  (choose and write the candidates' working copies at ``--max-size``),
* ``per_frame`` (with ``--what per_frame``, the walk only): CPU milliseconds a frame of decoding,
  of a working copy made the old way (full-size RGB, Pillow's Lanczos) and the new way (FFmpeg's
  Lanczos from the decoder's picture), of the JPEG, and how much the two copies differ;
* ``sfm_ingest`` (office.mp4 only): :func:`curate.sfm.prep.prepare_photos`, what the SfM stage
  does before COLMAP (ingest and the quality checks: ``timings.ingest`` and ``quality`` of
  ``RUN/sfm/stage.json``, the figures of :mod:`research.bench.bench_capture`),

recording wall and CPU seconds (the process's, decoder threads included), the machine's load
average, frames decoded and candidates, and the realtime factor (seconds of work per second of
video). Prints one JSON line per measurement and, as the LAST line, ``{"videos": [...]}``. Only
``curate.*`` is imported, so ``PYTHONPATH=OTHER_CHECKOUT python research/bench/bench_video.py``
times another version of curate on the same files.
"""

from __future__ import annotations

import argparse
from fractions import Fraction
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

EXPOSURE_S = 1 / 60
"""Shutter time of the rendered walk (motion blur = angular speed x exposure x focal length)."""


def _render_chunk(args):
    """Rendered uint8 frames [k, H, W, 3] of cameras ``idx`` of the walk (in a worker process)."""
    layout, seed, n, fps, w, h, idx = args
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk, motion_blur
    scene = make_scene(layout, seed)
    cams, omega = hand_held_walk(n, "loop", seed=seed, room=scene.interior, fps=fps, width=w, height=h)
    out = []
    for i in idx:
        rgb, _ = scene.render(cams[int(i)])
        out.append(motion_blur(rgb[0], omega[i], float(cams.fx[i]), fps * EXPOSURE_S))
    return idx, np.stack(out)


def render_small(work: Path, n: int, fps: int, w: int, h: int, layout: str = "livingroom", seed: int = 0,
                 jobs: int = 2) -> Path:
    """The walk's ``n`` frames at ``w`` x ``h``, losslessly (FFV1 in Matroska); rendered once, cached
    (chunks of 30 frames are kept until the video is whole, so an interrupted render resumes)."""
    import av
    from multiprocessing import Pool
    out = work / f"walk_{layout}_s{seed}_{n}f_{fps}fps_{w}x{h}.mkv"
    if out.is_file():
        return out
    chunks_dir = work / (out.stem + "_chunks")
    chunks_dir.mkdir(parents=True, exist_ok=True)
    todo = [(layout, seed, n, fps, w, h, list(range(a, min(a + 30, n)))) for a in range(0, n, 30)
            if not (chunks_dir / f"{a:06d}.npy").is_file()]
    t = time.perf_counter()
    with Pool(jobs) as pool:
        for k, (idx, frames) in enumerate(pool.imap_unordered(_render_chunk, todo)):
            np.save(chunks_dir / f"{idx[0]:06d}.npy", frames)
            print(f"rendered chunk {k + 1}/{len(todo)} ({time.perf_counter() - t:.0f} s)", file=sys.stderr, flush=True)
    c = av.open(str(out) + ".part", "w", format="matroska")
    s = c.add_stream("ffv1", rate=fps)
    s.width, s.height, s.pix_fmt = w, h, "yuv444p"
    for a in range(0, n, 30):
        for rgb in np.load(chunks_dir / f"{a:06d}.npy"):
            for p in s.encode(av.VideoFrame.from_ndarray(rgb, format="rgb24")):
                c.mux(p)
    for p in s.encode():
        c.mux(p)
    c.close()
    os.replace(str(out) + ".part", out)
    for f in chunks_dir.iterdir():
        f.unlink()
    chunks_dir.rmdir()
    return out


def upscale(small: Path, out: Path, width: int, height: int, fps: int, codec: str = "libx264",
            crf: int = 20, grain: float = 0.0) -> Path:
    """``small`` upscaled (bicubic) to ``width`` x ``height``, plus fixed film grain when ``grain`` > 0
    (Gaussian, ``grain`` grey levels, one of 8 fixed patterns a frame), encoded with ``codec`` (CRF
    ``crf``, a key frame every ``fps`` frames); cached."""
    import av
    if out.is_file():
        return out
    rng = np.random.default_rng(0)
    noise = [np.round(rng.normal(0, grain, (height, width))).astype(np.int16) for _ in range(8)] if grain > 0 else []
    src = av.open(str(small))
    dst = av.open(str(out) + ".part", "w", format="mp4")
    s = dst.add_stream(codec, rate=fps)
    s.width, s.height, s.pix_fmt = width, height, "yuv420p"
    s.options = {"crf": str(crf), "preset": "superfast", "g": str(fps)}
    if codec == "libx265":
        s.options["x265-params"] = "log-level=none"
    t = time.perf_counter()
    for i, f in enumerate(src.decode(video=0)):
        big = f.reformat(width=width, height=height, format="yuv420p", interpolation="BICUBIC")
        if noise:
            y = big.to_ndarray()[:height]                # the luma plane of the planar frame
            _copy_plane(big.planes[0], np.clip(y.astype(np.int16) + noise[i % 8], 0, 255).astype(np.uint8))
        big.pts, big.time_base = i, Fraction(1, fps)
        for p in s.encode(big):
            dst.mux(p)
        if i % 300 == 0:
            print(f"encoded {i} frames ({time.perf_counter() - t:.0f} s)", file=sys.stderr, flush=True)
    for p in s.encode():
        dst.mux(p)
    dst.close()
    src.close()
    os.replace(str(out) + ".part", out)
    return out


def _copy_plane(plane, a: np.ndarray) -> None:
    """Write [H, W] uint8 ``a`` into a frame plane whose rows are padded to ``line_size`` bytes."""
    buf = np.frombuffer(plane, np.uint8).reshape(-1, plane.line_size)
    buf[: a.shape[0], : a.shape[1]] = a


def _cpu() -> float:
    t = os.times()
    return t.user + t.system


def _probe(video: Path) -> dict:
    import av
    with av.open(str(video)) as c:
        s = c.streams.video[0]
        dur = float(s.duration * s.time_base) if s.duration else (c.duration or 0) / 1e6
        return {"video": video.name, "width": s.width, "height": s.height, "codec": s.codec_context.name,
                "fps": float(s.average_rate or 0), "seconds_of_video": round(dur, 2),
                "mbit_per_s": round(video.stat().st_size * 8 / 1e6 / max(dur, 1e-9), 1)}


def _timed(fn):
    """(fn(), wall seconds, CPU seconds of this process with its threads, load average before)."""
    load = os.getloadavg()[0]
    t, c = time.perf_counter(), _cpu()
    out = fn()
    return out, round(time.perf_counter() - t, 2), round(_cpu() - c, 2), round(load, 2)


def _sha(times: list[float]) -> str:
    import hashlib
    return hashlib.sha256(json.dumps(times).encode()).hexdigest()[:12]


def measure(video: Path, scratch: Path, max_size: int, repeats: int, save: Path | None = None,
            ingest: bool = False, max_frames: int = 1000, what: tuple = ("analysis", "extract")) -> list[dict]:
    """Time the analysis pass and the whole extraction of ``video`` (frames written under ``scratch``,
    deleted after), ``repeats`` times each; the candidates' times go to ``save`` (JSON) when given,
    and their hash to the records (two versions of curate chose the same frames when the hashes agree)."""
    import curate
    from curate.sfm.video import VideoConfig, analyse, choose, extract, windows
    cfg = VideoConfig(max_frames=max_frames)
    meta = {**_probe(video), "curate": str(Path(curate.__file__).parent), "max_frames": max_frames}
    out = []

    def record(kind: str, r: int, wall: float, cpu: float, load: float, **extra) -> None:
        rec = {**meta, "what": kind, "repeat": r, "wall_s": wall, "cpu_s": cpu,
               "realtime_factor": round(wall / meta["seconds_of_video"], 3), "load_before": load, **extra}
        print(json.dumps(rec), flush=True)
        out.append(rec)

    for r in range(repeats):
        if "analysis" in what:
            def first_pass():
                info, _, _ = analyse(video, cfg)
                return info, choose(info, cfg)
            (info, (chosen, counts)), wall, cpu, load = _timed(first_pass)
            times = [round(info[k].time, 3) for k in chosen]
            if save is not None and r == 0:
                save.write_text(json.dumps({"video": video.name, "times": times}))
            record("analysis", r, wall, cpu, load, decoded=counts["decoded"], candidates=counts["candidates"],
                   windows_at_change_step=len(windows(info, cfg.change_step, cfg.static_change)),
                   candidates_sha=_sha(times))
        if "extract" in what:
            with tempfile.TemporaryDirectory(dir=scratch) as d:
                (recs, summary), wall, cpu, load = _timed(lambda: extract(video, video.name, Path(d), max_size, cfg))
            record("extract", r, wall, cpu, load, decoded=summary.get("decoded"), candidates=len(recs),
                   candidates_sha=_sha([round(x.extra["time"], 3) for x in recs]), passes=summary.get("passes"),
                   pass_seconds=summary.get("seconds"), stopped=summary.get("stopped"))
        if ingest:
            from curate.sfm.config import SfmConfig
            from curate.sfm.prep import prepare_photos
            with tempfile.TemporaryDirectory(dir=scratch) as d:
                (_, kept, timings), wall, cpu, load = _timed(
                    lambda: prepare_photos(SfmConfig(progress=False), video, Path(d) / "sfm"))
            record("sfm_ingest", r, wall, cpu, load, n_kept=len(kept), ingest_s=timings.get("ingest"),
                   quality_s=timings.get("quality"))
    return out


def per_frame(video: Path, max_size: int, n_decode: int = 90, n_convert: int = 10) -> dict:
    """CPU milliseconds a frame of ``video``: decoding alone (threaded, its first ``n_decode`` frames)
    and, on ``n_convert`` of them, a working copy at ``max_size`` made the old way (full-size RGB,
    then Pillow's Lanczos) and the new way (FFmpeg's Lanczos from the decoder's picture), JPEG q95,
    and the mean absolute difference of the two copies (0..255)."""
    import io

    import av
    from PIL import Image
    frames = []
    with av.open(str(video)) as c:
        s = c.streams.video[0]
        s.thread_type = "AUTO"
        c0 = _cpu()
        for i, f in enumerate(c.decode(s)):
            if i % max(1, n_decode // n_convert) == 0 and len(frames) < n_convert:
                frames.append(f)
            if i + 1 >= n_decode:
                break
        decode = (_cpu() - c0) / (i + 1) * 1000
    sc = min(1.0, max_size / max(frames[0].width, frames[0].height))
    w, h = round(frames[0].width * sc), round(frames[0].height * sc)
    old = lambda f: np.asarray(Image.fromarray(f.to_ndarray(format="rgb24")).resize((w, h), Image.LANCZOS))  # noqa: E731
    new = lambda f: f.reformat(width=w, height=h, format="rgb24", interpolation="LANCZOS").to_ndarray()  # noqa: E731
    out = {"video": video.name, "what": "per_frame_cpu_ms", "decode": round(decode, 1), "working_size": [w, h]}
    for name, fn in (("old_rgb_then_pillow_lanczos", old), ("new_ffmpeg_lanczos", new)):
        c0 = _cpu()
        for f in frames:
            a = fn(f)
        out[name] = round((_cpu() - c0) / len(frames) * 1000, 1)
    c0 = _cpu()
    for f in frames:
        Image.fromarray(a).save(io.BytesIO(), format="JPEG", quality=95)
    out["jpeg_q95"] = round((_cpu() - c0) / len(frames) * 1000, 1)
    out["mean_abs_diff_old_new"] = round(float(np.mean([np.abs(old(f).astype(np.float32) - new(f)).mean()
                                                        for f in frames])), 3)
    print(json.dumps(out), flush=True)
    return out


def _save(a, video: Path) -> Path | None:
    return a.work / f"candidates_{a.tag}_{video.stem}.json" if a.tag else None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=120.0, help="length of the rendered walk")
    ap.add_argument("--fps", type=int, default=30, help="frame rate of the rendered walk")
    ap.add_argument("--render-size", default="320x180", help="WxH the walk is rendered at")
    ap.add_argument("--size", default="3840x2160", help="WxH of the video (upscaled)")
    ap.add_argument("--codec", default="libx264", help="encoder of the video (libx264, libx265)")
    ap.add_argument("--grain", type=float, default=0.0, help="film grain of the video (grey levels; 0: none)")
    ap.add_argument("--office", type=Path, default=None, help="also office.mp4 of this folder")
    ap.add_argument("--no-walk", action="store_true", help="only office.mp4")
    ap.add_argument("--work", type=Path, default=Path("/tmp/curate_bench_video"), help="videos (cached)")
    ap.add_argument("--max-size", type=int, default=1600, help="longer side of the working copies")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--max-frames", type=int, default=1000, help="VideoConfig.max_frames (the cap of candidates)")
    ap.add_argument("--what", default="analysis,extract",
                    help="which of analysis,extract,per_frame to time (per_frame: CPU a frame of the walk, by step)")
    ap.add_argument("--tag", default="", help="write each video's candidate times to WORK/candidates_TAG_VIDEO.json")
    ap.add_argument("--jobs", type=int, default=2, help="rendering processes")
    ap.add_argument("--make-only", action="store_true", help="make the video and stop")
    a = ap.parse_args(argv)
    records = []
    if not a.no_walk:
        n = int(round(a.seconds * a.fps))
        rw, rh = (int(v) for v in a.render_size.split("x"))
        w, h = (int(v) for v in a.size.split("x"))
        a.work.mkdir(parents=True, exist_ok=True)
        small = render_small(a.work, n, a.fps, rw, rh, jobs=a.jobs)
        video = upscale(small, a.work / f"{small.stem}_{w}x{h}_{a.codec}{f'_grain{a.grain:g}' if a.grain else ''}.mp4",
                        w, h, a.fps, a.codec, grain=a.grain)
        if a.make_only:
            print(json.dumps(_probe(video)))
            return 0
        what = tuple(a.what.split(","))
        if "per_frame" in what:
            records.append(per_frame(video, a.max_size))
        records += measure(video, a.work, a.max_size, a.repeats, _save(a, video), max_frames=a.max_frames,
                           what=what)
    if a.office is not None:
        v = a.office / "office.mp4"
        a.work.mkdir(parents=True, exist_ok=True)
        records += measure(v, a.work, a.max_size, a.repeats, _save(a, v), ingest=True, max_frames=a.max_frames,
                           what=tuple(a.what.split(",")))
    print(json.dumps({"videos": records}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
