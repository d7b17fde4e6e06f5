"""Videos in: frames named by video and time, rotation and variable frame rate honoured, a damaged
tail decoded as far as it goes, static stretches collapsed, the sharpest frame of each window kept,
the pool capped, and the video never written."""

from __future__ import annotations

import hashlib
import json
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageFilter

av = pytest.importorskip("av", reason="PyAV is not installed (pip install av; scripts/setup.sh does)")

from curate.sfm.video import VideoConfig, analyse, choose, extract, frame_name  # noqa: E402

SAMPLE = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk" / "images"


def write_video(path: Path, frames: list[np.ndarray], times_ms: list[int] | None = None, rotation: int = 0,
                codec: str = "mpeg4", pix_fmt: str = "yuv420p", options: dict | None = None) -> Path:
    """A ``codec`` video (MPEG-4 by default) of ``frames`` [H, W, 3] uint8 at ``times_ms`` (default
    40 ms apart), stored as ``pix_fmt``."""
    out = av.open(str(path), "w")
    s = out.add_stream(codec, rate=1000)
    s.height, s.width = frames[0].shape[:2]
    s.pix_fmt = pix_fmt
    s.codec_context.time_base = Fraction(1, 1000)
    s.codec_context.bit_rate = 4_000_000
    if options:
        s.options = options
    if rotation:
        s.set_display_rotation(rotation)
    times_ms = times_ms or [40 * i for i in range(len(frames))]
    for f, t in zip(frames, times_ms):
        fr = av.VideoFrame.from_ndarray(np.ascontiguousarray(f), format="rgb24").reformat(format=pix_fmt)
        fr.pts = t
        for p in s.encode(fr):
            out.mux(p)
    for p in s.encode():
        out.mux(p)
    out.close()
    return path


def walk_frames(n: int, start: int = 0) -> list[np.ndarray]:
    return [np.asarray(Image.open(p).convert("RGB")) for p in sorted(SAMPLE.glob("*.jpg"))[start:start + n]]


def sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_frames_are_named_by_their_own_timestamps(tmp_path):
    times = [0, 50, 83, 133, 166, 300, 333, 700]                     # variable frame rate
    v = write_video(tmp_path / "walk.mp4", walk_frames(8, 0), times)
    before = sha(v)
    out = tmp_path / "frames"
    out.mkdir()
    recs, summary = extract(v, "walk.mp4", out, 1600, VideoConfig(change_step=1e-6, static_change=0.0))
    assert summary["decoded"] == 8 and len(recs) == 8                 # every frame a window of its own
    assert [r.extra["time"] for r in recs] == [t / 1000 for t in times]
    assert [r.working for r in recs] == [frame_name(v, t / 1000) for t in times]
    assert recs[5].working == "walk_000000.300.jpg" and all((out / r.working).is_file() for r in recs)
    assert all(r.extra["video"] == str(v.resolve()) for r in recs)
    assert sha(v) == before


def test_a_portrait_phone_video_comes_out_upright(tmp_path):
    """A phone stores portrait video as landscape frames with a display rotation (-90: turn a quarter
    clockwise to show): the candidates are the frames as shown."""
    f = np.zeros((120, 160, 3), np.uint8)
    f[:, :80] = 255                                                   # left half white as stored
    v = write_video(tmp_path / "phone.mp4", [f] * 3, rotation=-90)
    out = tmp_path / "frames"
    out.mkdir()
    recs, summary = extract(v, "phone.mp4", out, 1600, VideoConfig())
    assert summary["rotation"] == -90
    a = np.asarray(Image.open(out / recs[0].working).convert("L"), float)
    assert a.shape == (160, 120)                                      # portrait
    assert a[:70].mean() > 200 and a[90:].mean() < 50                 # the stored left half is now on top


def test_static_stretch_collapses_and_the_sharpest_frame_of_a_window_is_kept(tmp_path):
    walk = walk_frames(6, 20)
    still = walk_frames(1, 40)[0]
    blurred = np.asarray(Image.fromarray(still).filter(ImageFilter.GaussianBlur(3)))
    stretch = [blurred] * 4 + [still] + [blurred] * 4                 # the walker stands still, one sharp frame
    v = write_video(tmp_path / "w.mp4", walk + stretch + walk_frames(6, 60))
    cfg = VideoConfig(change_step=0.03, static_change=0.02)
    info, note, _ = analyse(v, cfg)
    chosen, counts = choose(info, cfg)
    assert note == "" and counts["decoded"] == len(info) == 21
    in_stretch = [k for k in chosen if 6 <= k < 15]
    assert in_stretch == [10]                                         # one frame for the stretch: the sharp one
    assert counts["static"] >= 7 and counts["candidates"] == len(chosen) < 21


def test_the_pool_is_capped(tmp_path):
    v = write_video(tmp_path / "long.mp4", walk_frames(40, 0))
    info, _, _ = analyse(v, VideoConfig())
    for cap in (3, 10):
        chosen, counts = choose(info, VideoConfig(max_frames=cap, change_step=1e-4))
        assert 2 <= len(chosen) <= cap and counts["change_step"] > 1e-4
        assert chosen == sorted(set(chosen))


def test_a_truncated_video_gives_its_good_part(tmp_path):
    v = write_video(tmp_path / "cut.mkv", walk_frames(30, 0))     # Matroska: readable up to a cut
    data = v.read_bytes()
    cut = tmp_path / "cut_tail.mkv"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    out = tmp_path / "frames"
    out.mkdir()
    recs, summary = extract(cut, "cut_tail.mkv", out, 1600, VideoConfig(change_step=1e-6, static_change=0.0))
    assert 5 < summary["decoded"] < 30
    assert len(recs) == summary["candidates"] and all((out / r.working).is_file() for r in recs)


def test_a_10_bit_hevc_video_gives_8_bit_frames_of_the_same_picture(tmp_path):
    """Phones record HDR as 10-bit HEVC: the candidate frames are ordinary 8-bit RGB JPEGs with the
    video's picture (a range conversion; no HDR tone mapping)."""
    src = walk_frames(6, 10)
    if "libx265" not in av.codecs_available:                  # pragma: no cover - a PyAV without x265
        pytest.skip("this PyAV has no HEVC encoder")
    v = write_video(tmp_path / "hdr.mkv", src, codec="libx265", pix_fmt="yuv420p10le",
                    options={"crf": "12", "x265-params": "log-level=none"})
    with av.open(str(v)) as c:
        assert c.streams.video[0].codec_context.pix_fmt == "yuv420p10le"
    d = tmp_path / "frames"
    d.mkdir()
    recs, summary = extract(v, "hdr.mkv", d, 1600, VideoConfig(change_step=1e-6, static_change=0.0))
    assert summary["decoded"] == 6 and recs
    for r in recs:
        im = Image.open(d / r.working)
        assert im.mode == "RGB" and im.size == (src[0].shape[1], src[0].shape[0])
        a = np.asarray(im, np.float32)
        assert np.abs(a - src[r.extra["frame"]]).mean() < 6.0       # the same picture, 0..255


def test_ingest_takes_a_video_among_photos_or_alone(tmp_path):
    from curate.sfm.ingest import ingest
    folder = tmp_path / "cap"
    folder.mkdir()
    for p in sorted(SAMPLE.glob("*.jpg"))[:3]:
        (folder / p.name).write_bytes(p.read_bytes())
    v = write_video(folder / "walk.mp4", walk_frames(10, 30))
    (folder / "notes.txt").write_text("x")
    before = {p.name: sha(p) for p in folder.iterdir()}
    summaries: list = []
    recs = ingest(folder, tmp_path / "w1", 1600, video=VideoConfig(change_step=1e-6, static_change=0.0),
                  video_summaries=summaries, progress=False)
    kept = [r for r in recs if r.status == "kept"]
    assert len(kept) == 3 + 10 and summaries[0]["decoded"] == 10
    assert {r.rel for r in recs if r.status == "skipped"} == {"notes.txt"}
    assert sum(1 for r in kept if r.extra.get("video")) == 10
    recs = ingest(v, tmp_path / "w2", 1600, progress=False)          # the video alone, as `curate sfm walk.mp4`
    assert recs and all(r.extra.get("video_rel") == "walk.mp4" for r in recs)
    assert {p.name: sha(p) for p in folder.iterdir()} == before


@pytest.mark.slow
def test_curate_sfm_on_a_video(tmp_path):
    """`curate sfm walk.mp4 --out RUN`: candidates, registered cameras named by video and time, and
    the per-video counts in the stage record."""
    from curate import cli
    v = write_video(tmp_path / "walk.mp4", walk_frames(24, 0))
    before = sha(v)
    assert cli.main(["sfm", str(v), "--out", str(tmp_path / "run")]) == 0
    st = json.loads((tmp_path / "run" / "sfm" / "stage.json").read_text())["stats"]
    assert st["videos"][0]["decoded"] == 24 and st["videos"][0]["candidates"] >= 8
    cams = json.loads((tmp_path / "run" / "sfm" / "cameras.json").read_text())["cameras"]
    assert len(cams) >= 0.8 * st["n_kept"] and all(c["name"].startswith("walk_0000") for c in cams)
    assert sha(v) == before
