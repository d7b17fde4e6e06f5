"""Several takes of one place (two videos, a video and photos): each photo knows its take, the takes
are matched with one another, and a take that did not join the others is named loudly."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from curate.sfm.config import TAKE_MIN_FRACTION, SfmConfig
from curate.core.images import PhotoRecord
from curate.sfm.prep import (assign_takes, choose_matcher, cross_take_pairs, take_counts, take_name, takes_not_joined,
                             takes_of)
from curate.sfm.warn import split_warning, take_warning

SAMPLE = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk" / "images"


def frame(video: str, t: float, i: int) -> PhotoRecord:
    """A kept video frame as :func:`curate.sfm.video.extract` records it."""
    name = f"{Path(video).stem}_{t:010.3f}.jpg"
    r = PhotoRecord(original=f"/run/sfm/images/{name}", rel=name, working=name)
    r.extra.update(video=f"/photos/{video}", video_rel=video, time=t, frame=i)
    return r


def photo(rel: str) -> PhotoRecord:
    return PhotoRecord(original=f"/photos/{rel}", rel=rel, working=rel.replace("/", "__"))


def test_each_photo_knows_its_take():
    """A video's frames are its take; the photos of a folder are one take (a sub-folder another); a
    video that could not be read is its own take."""
    recs = [frame("walk.mp4", 0.1, 1), frame("sub/walk2.mov", 0.2, 2), photo("IMG_1.jpg"), photo("a/b/IMG_2.jpg"),
            PhotoRecord(original="/photos/bad.mp4", rel="bad.mp4", status="skipped")]
    assign_takes(recs)
    assert [r.extra["take"] for r in recs] == ["walk.mp4", "sub/walk2.mov", "photos", "photos in a/b/", "bad.mp4"]
    assert take_name({"rel": "x/y.jpg", "extra": {}}) == "photos in x/"           # an images.json record
    t = takes_of(recs[:4])
    assert sorted(t) == ["photos", "photos in a/b/", "sub/walk2.mov", "walk.mp4"]
    assert t["walk.mp4"] == [recs[0].working] and t["photos in a/b/"] == ["a__b__IMG_2.jpg"]


def test_videos_are_matched_in_order_and_a_video_with_photos_exhaustively():
    """Beyond the exhaustive limit, two videos are matched sequentially (each take along itself;
    across takes by retrieval), photos in no order by retrieval (each with its most similar photos:
    near-linear, where exhaustive is quadratic); a video with photos, numbered or not, gets exhaustive matching
    (matched sequentially, office.mp4's first half with every 5th photo of the second split and
    left every photo out; exhaustive matching kept 30 of 38)."""
    cfg = SfmConfig(exhaustive_max_images=10)
    a = [frame("a.mp4", 0.1 * i, i) for i in range(12)]
    b = [frame("b.mp4", 0.1 * i, i) for i in range(12)]
    numbered = [photo(f"{i:05d}.jpg") for i in range(200, 260, 5)]
    unordered = [photo(n) for n in ("kitchen.jpg", "sofa.jpg", "door.jpg", "window.jpg")]
    many = [photo(f"{w}_{k}.jpg") for w in ("kitchen", "sofa", "door") for k in "abcd"]   # 12, in no order
    for recs, want in [(a + b, "sequential"), (numbered, "sequential"), (a + numbered, "exhaustive"),
                       (a + unordered, "exhaustive"), (a[:5] + b[:5], "exhaustive"), (many, "retrieval"),
                       (many[:10], "exhaustive")]:
        assign_takes(recs)
        assert choose_matcher(cfg, recs) == want


def test_cross_take_pairs_link_each_query_to_the_other_takes_best():
    """Each query keeps its N most similar frames of each *other* take, however far down the ranking
    its own take pushes them; pairs within a take are never added; a pair found from both sides counts once."""
    take_of = {**{f"a{i}": "A" for i in range(6)}, **{f"b{i}": "B" for i in range(6)},
               **{f"c{i}": "C" for i in range(3)}}
    ranked = [("a0", ["a0", "a1", "a2", "a3", "b4", "a4", "b1", "c2", "b2", "c0"]),  # own take first, as retrieval does
              ("b4", ["b4", "b3", "a0", "b5", "a5", "a1"]),
              ("c0", ["c0", "c1", "c2"])]                                           # nothing of another take ranked
    pairs = cross_take_pairs(ranked, take_of, per_take=2)
    assert pairs == [("a0", "b1"), ("a0", "b4"), ("a0", "c0"), ("a0", "c2"), ("a5", "b4")]
    assert all(take_of[p] != take_of[q] for p, q in pairs)
    assert cross_take_pairs(ranked, take_of, per_take=1) == [("a0", "b4"), ("a0", "c2")]
    assert cross_take_pairs([], take_of, per_take=3) == []


def test_cross_take_pairs_grow_linearly_with_the_frames():
    """With a ranking of every frame (the worst case), the pairs are at most queries x N x (takes - 1)."""
    rng = np.random.default_rng(0)
    for n in (50, 200, 800):
        names = [f"{t}{i:04d}" for t in "ABC" for i in range(n)]
        take_of = {x: x[0] for x in names}
        queries = names[::2]
        ranked = ((q, list(rng.permutation(names))) for q in queries)
        pairs = cross_take_pairs(ranked, take_of, per_take=5)
        assert len(pairs) <= len(queries) * 5 * 2
        assert len(pairs) >= 0.9 * len(queries) * 5 * 2   # random rankings rarely repeat a pair


def test_per_take_counts_and_which_take_did_not_join():
    kept = [frame("walk1.mp4", 0.1 * i, i) for i in range(10)] + [frame("walk2.mp4", 0.1 * i, i) for i in range(8)] \
        + [photo(f"{i:03d}.jpg") for i in range(5)]
    assign_takes(kept)
    model = {r.working for r in kept[:10] + kept[18:22]}            # walk1 whole, 4 of the 5 photos
    other = {r.working for r in kept[10:17]}                        # walk2: 7 frames in a model of their own
    takes = take_counts(kept, model, other)
    assert takes == [{"take": "photos", "kind": "photos", "n_frames": 5, "n_in_model": 4, "n_in_other_parts": 0},
                     {"take": "walk1.mp4", "kind": "video", "n_frames": 10, "n_in_model": 10, "n_in_other_parts": 0},
                     {"take": "walk2.mp4", "kind": "video", "n_frames": 8, "n_in_model": 0, "n_in_other_parts": 7}]
    assert [t["take"] for t in takes_not_joined(takes, TAKE_MIN_FRACTION)] == ["walk2.mp4"]
    w = take_warning({"takes": takes})
    assert w.startswith("take walk2.mp4: 0 of 8 frames in the model (7 in a model of their own): it shares too "
                        "little with the other takes"), w
    assert "film a stretch that overlaps another take" in w and "photos" not in w.split(":")[0]
    # one take is never "not joined" (a split of one take is the split warning's); every take in: no warning
    assert take_warning({"takes": takes[2:]}) is None
    assert take_warning({"takes": takes[:2]}) is None and take_warning({}) is None
    # the threshold: under a tenth of its frames in the model
    almost = dict(takes[2], n_frames=100, n_in_model=9)
    enough = dict(takes[2], n_frames=100, n_in_model=10)
    assert takes_not_joined([takes[1], almost], 0.1) == [almost] and takes_not_joined([takes[1], enough], 0.1) == []


def test_the_take_that_did_not_join_leads_the_sfm_warning(tmp_path):
    """The stage's warning (end of `curate run`, top of the report) names the take first, then the split."""
    d = tmp_path / "sfm"
    d.mkdir()
    takes = [{"take": "walk1.mp4", "kind": "video", "n_frames": 90, "n_in_model": 90, "n_in_other_parts": 0},
             {"take": "walk2.mp4", "kind": "video", "n_frames": 70, "n_in_model": 0, "n_in_other_parts": 70}]
    lost = [f"walk2_{0.1 * i:010.3f}.jpg" for i in range(70)]
    stats = {"model_sizes": [90, 70], "n_kept": 160, "n_registered": 90, "unregistered": lost, "takes": takes}
    (d / "stage.json").write_text(json.dumps({"stats": stats}))
    w = split_warning(tmp_path)
    assert w.startswith("take walk2.mp4: 0 of 70 frames in the model (70 in a model of their own)"), w
    assert ". The capture split into 2 models (90, 70 photos): curate uses the largest, 90 of 160" in w
    stats["takes"] = takes[:1]
    (d / "stage.json").write_text(json.dumps({"stats": stats}))
    assert split_warning(tmp_path).startswith("the capture split into 2 models")


# ------------------------------------------------------------------ end to end (COLMAP)
def _video(path: Path, frames: list[np.ndarray]) -> Path:
    from research.takes import write_video
    write_video(frames, path)
    return path


@pytest.mark.slow
def test_two_overlapping_takes_make_one_model_and_a_foreign_take_is_named(tmp_path):
    """Two takes of one room (the second a pass the other way, over part of the first) come back as
    one model; a take of another room joins nothing and the SfM warning names it.

    The second take covers frames 69..20 of the sample walk: its frames 89..74 hang on the rest by a
    seam of about 20 points, and the global model placed them a quarter of the walk off on one CI run
    (37 deg after alignment); such a part is now left out (`join_parts`), so a take over it would not
    come back whole, and that stretch is not what this test is about."""
    pytest.importorskip("pycolmap")
    pytest.importorskip("av")
    from PIL import Image

    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk
    from curate.sfm.colmap import run_sfm
    from curate.sfm.io import load_sfm
    from research.align import pose_errors
    from curate.core.transforms_json import read_transforms
    frames = [np.asarray(Image.open(p).convert("RGB")) for p in sorted(SAMPLE.glob("*.jpg"))]
    folder = tmp_path / "capture"
    folder.mkdir()
    _video(folder / "walk1.mp4", frames[0:50])
    _video(folder / "walk2.mp4", frames[69:19:-1])                 # frames 69..20: back over 20..49 of walk1
    scene = make_scene("office", 3)
    cams, _ = hand_held_walk(20, "loop", seed=3, width=320, height=240, room=scene.interior)
    other, _ = scene.render(cams)
    _video(folder / "other_room.mp4", list(other))
    run = tmp_path / "run"
    run_sfm(SfmConfig(matcher="sequential", max_image_size=320, progress=False), folder, run)
    st = json.loads((run / "sfm" / "stage.json").read_text())["stats"]
    takes = {t["take"]: t for t in st["takes"]}
    assert set(takes) == {"walk1.mp4", "walk2.mp4", "other_room.mp4"}
    for t in ("walk1.mp4", "walk2.mp4"):     # joined: most of each take in the one model; the checks of a global
        # model may leave out a few frames at the seam (5 of 42 on one CI run, 0-2 of ~40 in 13 runs here), a
        # take left in its own model would have under half its frames in it
        assert takes[t]["n_in_model"] >= 0.8 * takes[t]["n_frames"], takes
    assert takes["other_room.mp4"]["n_in_model"] == 0, takes
    assert st["cross_take"]["verified"] > 0, st["cross_take"]
    recs = json.loads((run / "sfm" / "images.json").read_text())["photos"]
    assert {r["extra"]["take"] for r in recs} == set(takes)
    w = split_warning(run)
    n_other = takes["other_room.mp4"]["n_frames"]
    assert w is not None and w.startswith(f"take other_room.mp4: 0 of {n_other} frames in the model"), w
    # the joined takes sit in one frame: their poses agree with the rendered walk after one alignment
    truth, _ = read_transforms(SAMPLE.parent / "transforms.json")
    of = {r["working"]: (r["extra"]["video_rel"], r["extra"]["frame"]) for r in recs if r["status"] == "kept"}
    src = {"walk1.mp4": list(range(0, 50)), "walk2.mp4": list(range(69, 19, -1))}
    got = load_sfm(run).cameras
    keep = [i for i, n in enumerate(got.names) if of[n][0] in src]
    sub = got[keep]
    from curate.core.cameras import Cameras
    est = Cameras(sub.c2w, sub.fx, sub.fy, sub.cx, sub.cy, sub.width, sub.height,
                  names=tuple(truth.names[src[of[n][0]][of[n][1]]] for n in sub.names))
    e = pose_errors(est, truth)
    assert e["rotation_deg_median"] < 2.0, e
