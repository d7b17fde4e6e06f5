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
    assert 5 < summary["decoded"] < 30 and "decoding stopped at" in summary["stopped"]
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


@pytest.mark.slow
def test_the_sfm_stage_leaves_out_a_frame_its_steps_blame_and_says_so(tmp_path, monkeypatch):
    """The stage's wiring of the step rule (``curate.sfm.continuity.lone_refuted``, its own test in
    tests/test_continuity.py; a real blamed frame: docs/investigations/sfm.md#refuted-frame): a frame the rule
    blames is not in the model curate uses, ``stats.refuted_frames`` names it and the split warning says why."""
    from curate import cli
    from curate.sfm import continuity
    from curate.sfm.warn import split_warning
    v = write_video(tmp_path / "walk.mp4", walk_frames(24, 0))
    blamed: list = []

    def blame_one(steps, *a, **k):          # the frame in the middle of the first take's checked steps
        if not blamed and len(steps) >= 3:
            blamed.append(steps[len(steps) // 2][0])
        return [n for n in blamed if any(n in st[:2] for st in steps)]
    monkeypatch.setattr(continuity, "lone_refuted", blame_one)
    assert cli.main(["sfm", str(v), "--out", str(tmp_path / "run")]) == 0
    assert len(blamed) == 1
    st = json.loads((tmp_path / "run" / "sfm" / "stage.json").read_text())["stats"]
    assert st["refuted_frames"] == {"walk.mp4": blamed}
    cams = json.loads((tmp_path / "run" / "sfm" / "cameras.json").read_text())["cameras"]
    assert blamed[0] not in {c["name"] for c in cams} and blamed[0] in st["unregistered"]
    w = split_warning(tmp_path / "run")
    assert f"1 placed where their own matches with the next frames refute them: {blamed[0]})" in w, w


def write_audio_only(path: Path, seconds: float = 0.5) -> Path:
    """A file holding one AAC audio stream (silence) and no video stream."""
    out = av.open(str(path), "w")
    s = out.add_stream("aac", rate=44100, layout="mono")
    for k in range(int(seconds * 44100 / 1024) + 1):
        f = av.AudioFrame.from_ndarray(np.zeros((1, 1024), np.float32), format="fltp", layout="mono")
        f.sample_rate, f.pts = 44100, k * 1024
        for p in s.encode(f):
            out.mux(p)
    for p in s.encode():
        out.mux(p)
    out.close()
    return path


def cut(path: Path, fraction: float) -> Path:
    """A copy of ``path`` holding its first ``fraction`` of bytes (a transfer or a recording cut short)."""
    data = path.read_bytes()
    out = path.with_name(path.stem + "_cut" + path.suffix)
    out.write_bytes(data[: int(len(data) * fraction)])
    return out


def test_a_video_cut_short_says_where_decoding_stopped(tmp_path, caplog):
    """With threaded decoding FFmpeg raises nothing at a cut: the end is found by the last decoded
    time against the duration the file's header declares, and said in the summary and the log."""
    whole = write_video(tmp_path / "walk.mkv", walk_frames(125, 0), [100 * i for i in range(125)])
    damaged = cut(whole, 0.9)
    out = tmp_path / "frames"
    out.mkdir()
    recs, summary = extract(whole, "walk.mkv", out, 1600, VideoConfig())
    assert summary["decoded"] == 125 and summary["stopped"] == ""
    with caplog.at_level("WARNING", logger="curate.sfm.video"):
        recs, summary = extract(damaged, "walk_cut.mkv", out, 1600, VideoConfig())
    assert 90 < summary["decoded"] < 125 and recs
    last = max(r.extra["time"] for r in recs)
    assert summary["stopped"].startswith("decoding stopped at ") and " of 12.4 s: the file is damaged or cut" \
        in summary["stopped"], summary["stopped"]
    stopped_at = float(summary["stopped"].split()[3])
    assert abs(stopped_at - (summary["decoded"] - 1) * 0.1) < 0.051 and last <= stopped_at + 0.05
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert any("walk_cut.mkv" in m and "decoding stopped at" in m for m in warned), warned


def test_a_variable_frame_rate_video_that_ends_with_a_long_frame_is_not_called_cut(tmp_path):
    """The last frame shown for a long time (a phone's variable frame rate) is not a damaged tail."""
    times = [0, 40, 80, 120, 160, 200, 240, 1200]
    v = write_video(tmp_path / "vfr.mkv", walk_frames(8, 0), times)
    out = tmp_path / "frames"
    out.mkdir()
    _, summary = extract(v, "vfr.mkv", out, 1600, VideoConfig())
    assert summary["decoded"] == 8 and summary["stopped"] == ""


def test_the_cap_binding_takes_a_second_pass_that_writes_only_the_chosen_frames(tmp_path):
    """One decoding writes each window's frame as it closes; when the windows outnumber --max-frames,
    the longer windows' frames are written by a second pass and the first pass's extras deleted:
    the frames on disk are exactly the chosen ones, and the same as choose() picks."""
    v = write_video(tmp_path / "long.mp4", walk_frames(40, 0))
    for cap, passes in ((1000, 1), (6, 2)):
        cfg = VideoConfig(max_frames=cap, change_step=1e-4)
        out = tmp_path / f"frames{cap}"
        out.mkdir()
        recs, summary = extract(v, "long.mp4", out, 1600, cfg)
        info, _, _ = analyse(v, cfg)
        chosen, _ = choose(info, cfg)
        assert summary["passes"] == passes and [r.extra["frame"] for r in recs] == chosen
        assert sorted(p.name for p in out.iterdir()) == sorted(r.working for r in recs)
        assert len(recs) <= cap


def test_the_first_pass_converts_frames_only_at_the_working_size(tmp_path):
    """A frame larger than --max-size is scaled straight from the decoder's picture: the working copy
    has the working size and the picture of the frame (no full-size RGB in between)."""
    src = [np.asarray(Image.fromarray(f).resize((640, 480), Image.BICUBIC)) for f in walk_frames(3, 50)]
    v = write_video(tmp_path / "big.mp4", src)
    out = tmp_path / "frames"
    out.mkdir()
    recs, _ = extract(v, "big.mp4", out, 200, VideoConfig(change_step=1e-6, static_change=0.0))
    for r in recs:
        im = Image.open(out / r.working)
        assert im.size == (200, 150) and (r.orig_width, r.orig_height) == (640, 480)
        ref = np.asarray(Image.fromarray(src[r.extra["frame"]]).resize((200, 150), Image.LANCZOS), np.float32)
        assert np.abs(np.asarray(im, np.float32) - ref).mean() < 6.0


def test_a_photo_named_like_a_frame_keeps_its_name_and_nothing_is_compared_with_itself(tmp_path):
    """clip.mp4 beside a photo clip_000000.000.jpg (a frame of the clip copied out, say): the photo keeps
    its name, the clip's frames are named by its whole file name, every working name is unique, no
    record is a near-duplicate of itself and every kept record has its file."""
    from curate.sfm.config import SfmConfig
    from curate.sfm.prep import prepare_photos
    folder = tmp_path / "cap"
    folder.mkdir()
    write_video(folder / "clip.mp4", walk_frames(10, 0))
    with av.open(str(folder / "clip.mp4")) as c:                                   # the clip's first frame,
        first = next(c.decode(video=0)).to_ndarray(format="rgb24")                 # copied out as curate does
    Image.fromarray(first).save(folder / "clip_000000.000.jpg", quality=95)
    Image.fromarray(walk_frames(1, 80)[0]).save(folder / "clip_000000.040.jpg", quality=95)  # another picture
    before = {p.name: sha(p) for p in folder.iterdir()}
    out = tmp_path / "run" / "sfm"
    cfg = SfmConfig(progress=False, video=VideoConfig(change_step=1e-6, static_change=0.0))
    records, kept, t = prepare_photos(cfg, folder, out)
    names = [r.working for r in records if r.working]
    assert len(names) == len(set(names)) == 12
    by = {r.rel: r for r in records}
    assert by["clip_000000.000.jpg"].working == "clip_000000.000.jpg"            # a photo keeps its name
    assert by["clip_000000.040.jpg"].working == "clip_000000.040.jpg"
    frames = {r.working for r in records if r.extra.get("video")}
    assert frames == {f"clip.mp4_{0.04 * i:010.3f}.jpg" for i in range(10)}
    assert t["videos"][0]["frame_prefix"] == "clip.mp4"
    for r in records:
        assert r.extra.get("duplicate_of") != r.rel, r.rel
    dropped = [r for r in records if r.status == "dropped"]
    assert len(dropped) == 1 and {dropped[0].rel, dropped[0].extra["duplicate_of"]} == \
        {"clip_000000.000.jpg", "clip.mp4_000000.000.jpg"}                        # the photo and the frame it was
    assert all((out / "images" / r.working).is_file() for r in kept) and len(kept) == 11
    assert not (out / "images" / dropped[0].working).exists()
    assert {p.name: sha(p) for p in folder.iterdir()} == before


def test_working_names_are_unique_and_unchanged_where_nothing_clashes():
    from curate.sfm.ingest import unique_names, working_name
    tags, prefixes = unique_names(["IMG_1.JPG", "a.png", "raw/IMG_2.CR2"], ["walk.mp4", "sub/other.mov"])
    assert set(tags.values()) == {""} and prefixes == {"walk.mp4": "walk", "sub/other.mov": "other"}
    photos = ["a__b.jpg", "a/b.jpg", "x.tif", "x.tif.png", "walk_000001.000.jpg", "c/walk.mp4_000000.000.jpg"]
    videos = ["walk.mp4", "walk.mov", "c/walk.mp4", "d/walk.mp4"]
    tags, prefixes = unique_names(photos, videos)
    assert tags["a__b.jpg"] == "" and tags["a/b.jpg"] == "~2"                     # fewer folder levels first
    assert working_name("a/b.jpg", "jpeg", tags["a/b.jpg"]) == "a__b~2.jpg"
    assert {working_name("x.tif", "tiff", tags["x.tif"]), working_name("x.tif.png", "png", tags["x.tif.png"])} \
        == {"x.tif.png", "x.tif~2.png"}
    assert prefixes == {"walk.mov": "walk.mov", "walk.mp4": "walk.mp4", "c/walk.mp4": "c__walk.mp4~2",
                        "d/walk.mp4": "d__walk.mp4"}
    from curate.sfm.video import frame_name
    names = {working_name(p, f, tags[p]) for p in photos for f in ("jpeg", "png")}
    for rel, pre in prefixes.items():
        for t in (0.0, 1.0, 2.5):
            assert frame_name(Path(rel), t, pre) not in names
    assert len(set(prefixes.values())) == len(videos)
    tags, prefixes = unique_names(["walk.mp4_000000.000.jpg", "walk_000000.000.jpg"], ["walk.mp4"])
    assert prefixes == {"walk.mp4": "walk.mp4~2"}


def test_recursive_photos_whose_flat_names_clash_both_keep_their_files(tmp_path):
    from curate.sfm.ingest import ingest
    folder = tmp_path / "cap"
    (folder / "a").mkdir(parents=True)
    pics = walk_frames(2, 10)
    Image.fromarray(pics[0]).save(folder / "a__b.jpg", quality=95)
    Image.fromarray(pics[1]).save(folder / "a" / "b.jpg", quality=95)
    recs = ingest(folder, tmp_path / "w", 1600, recursive=True, progress=False)
    by = {r.rel: r for r in recs}
    assert by["a__b.jpg"].working == "a__b.jpg" and by["a/b.jpg"].working == "a__b~2.jpg"
    for rel, pic in (("a__b.jpg", pics[0]), ("a/b.jpg", pics[1])):
        got = np.asarray(Image.open(tmp_path / "w" / by[rel].working), np.float32)
        assert np.abs(got - pic).mean() < 3.0                                    # each file holds its own photo


def test_an_audio_only_file_is_skipped_with_its_reason(tmp_path):
    from curate.sfm.ingest import ingest
    folder = tmp_path / "cap"
    folder.mkdir()
    for p in sorted(SAMPLE.glob("*.jpg"))[:3]:
        (folder / p.name).write_bytes(p.read_bytes())
    write_audio_only(folder / "voice.mp4")
    recs = ingest(folder, tmp_path / "w", 1600, progress=False)
    by = {r.rel: r for r in recs}
    assert by["voice.mp4"].status == "skipped" and "no video stream" in by["voice.mp4"].reason
    assert "only audio" in by["voice.mp4"].reason and "IndexError" not in by["voice.mp4"].reason
    assert sum(r.status == "kept" for r in recs) == 3


def test_max_frames_is_checked_only_when_there_is_a_video(tmp_path):
    """--max-frames 0 fails a run with a video, naming only that flag; a photo-only ingest ignores it."""
    from curate.sfm.ingest import ingest
    folder = tmp_path / "cap"
    folder.mkdir()
    for p in sorted(SAMPLE.glob("*.jpg"))[:3]:
        (folder / p.name).write_bytes(p.read_bytes())
    cfg = VideoConfig(max_frames=0)
    assert sum(r.status == "kept" for r in ingest(folder, tmp_path / "w1", 1600, video=cfg, progress=False)) == 3
    write_video(folder / "walk.mp4", walk_frames(4, 0))
    with pytest.raises(ValueError) as e:
        ingest(folder, tmp_path / "w2", 1600, video=cfg, progress=False)
    assert str(e.value).startswith("--max-frames") and "change_step" not in str(e.value)
    assert "static_change" not in str(e.value)
    assert not (tmp_path / "w2").exists() or not list((tmp_path / "w2").iterdir())


@pytest.mark.slow
def test_curate_batch_takes_a_video_as_one_capture(tmp_path):
    """`curate batch walk.mp4` curates the video as `curate run walk.mp4` does, into RUNS/walk."""
    from curate import cli
    v = write_video(tmp_path / "walk.mp4", walk_frames(24, 0))
    before = sha(v)
    runs = tmp_path / "runs"
    assert cli.main(["batch", str(v), "--out", str(runs), "--budget", "4", "--no-evaluate"]) == 0
    row = json.loads((runs / "summary.json").read_text())["rows"][0]
    assert row["status"] == "ok" and row["name"] == "walk", row
    assert (runs / "walk" / "report.json").is_file() and sha(v) == before


def test_batch_plans_a_video_as_one_capture(tmp_path):
    """`curate batch walk.mp4 photos/`: the video is a capture of its own (SfM on its frames), its run
    folder named by its stem; its resume key follows the file."""
    from curate.batch.runner import folder_key, plan
    from curate.config import RunConfig
    v = write_video(tmp_path / "walk.mp4", walk_frames(4, 0))
    items = plan([v], tmp_path / "runs")
    assert len(items) == 1 and items[0].name == "walk" and items[0].source == "sfm"
    assert items[0].photos == str(v.resolve()) and items[0].poses is None
    k1 = folder_key(items[0], RunConfig())
    write_video(v, walk_frames(5, 0))
    assert folder_key(items[0], RunConfig()) != k1
