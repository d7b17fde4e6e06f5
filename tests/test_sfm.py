"""SfM stage on real data (reduced sizes), pose import, skipping unchanged work."""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from research.align import pose_errors, umeyama
from curate.core.cameras import Cameras, look_at
from curate.sfm.io import load_sfm, original_cameras

from test_ingest import make_mixed_folder, need, sha_tree

pycolmap = pytest.importorskip("pycolmap")
from curate.sfm.colmap import run_sfm  # noqa: E402
from curate.sfm.config import SfmConfig  # noqa: E402
from curate.sfm.pose_import import import_poses  # noqa: E402


def small_cfg(**kw) -> SfmConfig:
    return SfmConfig(**{"max_image_size": 480, "progress": False, **kw})


SAME_MODEL_DEG, SAME_MODEL_CENTRE = 0.2, 1e-3
"""What "the same model" means for two runs of `curate sfm` (docs/investigations/sfm.md#same-input-same-model): the
same registered frames, every frame's orientation within 0.2 deg and its centre within 0.1% of the scene's extent
(no alignment: the runs share their frame). Most runs are equal to the last bit; on a loaded machine a few verified
pairs came out otherwise (2 of 2,211 on the fox) and the poses moved by up to 0.1 deg (office.mp4 with a cut)."""


def assert_same_model(a: Cameras, b: Cameras) -> None:
    from curate.core.cameras import rotation_angle_deg
    assert b.names == a.names
    rot = rotation_angle_deg(np.einsum("nji,njk->nik", a.c2w[:, :3, :3], b.c2w[:, :3, :3]))
    extent = float(np.linalg.norm(np.ptp(a.centres, axis=0)))
    assert float(np.max(rot)) <= SAME_MODEL_DEG, float(np.max(rot))
    assert float(np.abs(b.centres - a.centres).max()) <= SAME_MODEL_CENTRE * extent
    assert np.allclose(b.fx, a.fx, rtol=1e-4)


def fox_cfg(**kw) -> SfmConfig:
    """The fox's SfM in the tests: 320 px working copies (1600 px photos), where 480 px cost 2.7 times the wall time
    (108 s against 40 s on the 2-core machine; both register 67 of 67 photos, 0.58 and 0.63 deg from the published
    poses at the median: docs/results.md#test-time, ``research.fox_sizes``)."""
    return small_cfg(**{"max_image_size": 320, **kw})


@pytest.fixture(scope="module")
def fox_run(tmp_path_factory):
    photos = need("fox/images")
    run = tmp_path_factory.mktemp("fox_run")
    run_sfm(fox_cfg(), photos, run)
    return run


# ------------------------------------------------------------------ align utilities
def test_umeyama_recovers_similarity():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(20, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R = q * np.sign(np.linalg.det(q))
    dst = 2.5 * src @ R.T + [1, -2, 3]
    s, R2, t = umeyama(src, dst)
    assert s == pytest.approx(2.5) and np.allclose(R2, R) and np.allclose(t, [1, -2, 3])


def test_pose_errors_zero_for_similar_copy():
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    c = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.full(12, 0.5)], 1)
    ref = Cameras(look_at(c, np.zeros((12, 3))), 500, 500, 320, 240, 640, 480,
                  names=tuple(f"{i}.jpg" for i in range(12)))
    R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    est = Cameras(ref.transformed(0.3, R, [5, 0, 0]).c2w, 500, 500, 320, 240, 640, 480,
                  names=tuple(f"images/{i}.png" for i in range(12)))
    e = pose_errors(est, ref)
    assert e["n_matched"] == 12 and e["rotation_deg_median"] < 1e-6 and e["centre_rel_median"] < 1e-9


# ------------------------------------------------------------------ determinism and the initial pair
@pytest.mark.parametrize("matcher", ["exhaustive", "sequential"])
def test_verification_and_mapper_are_seeded(monkeypatch, tmp_path, matcher):
    """Verification RANSAC gets cfg.seed (COLMAP's -1 reseeds every run), the mapper the strict initial pair."""
    from curate.sfm import mapping, matching, reconstruction
    got: dict = {}
    _, vo, _ = matching._options(small_cfg(seed=7, loop_detection=False), matcher)
    assert vo.ransac.random_seed == 7 and vo.min_num_inliers == SfmConfig().min_num_matches
    monkeypatch.setattr(mapping, "incremental_mapping", lambda db, im, out, options, *a, **kw:
                        got.update(kw, options=options) or {})
    reconstruction.map_incremental(small_cfg(seed=7, init_min_num_inliers=150, register_min_inliers=25),
                                   tmp_path / "database.db", tmp_path, tmp_path / "m", 3, progress=False)
    o = got["options"]
    assert o.mapper.init_min_num_inliers == 150 and o.mapper.random_seed == 7 and o.random_seed == 7
    assert o.mapper.abs_pose_min_num_inliers == 25
    with pytest.raises(ValueError, match="register_min_inliers"):
        SfmConfig(register_min_inliers=3)


def test_matching_and_mapping_run_on_one_thread_whatever_the_threads_asked(monkeypatch, tmp_path):
    """Ceres sums a multi-threaded adjustment in the order its threads finish: the same matches mapped twice on
    two threads gave poses 0.09 deg apart, and the mappers decide on such differences; COLMAP's CPU matcher on two
    threads gave other matches in 46 of 3,693 pairs of office.mp4 between two runs."""
    from curate.sfm import mapping, matching, reconstruction
    got: dict = {}
    monkeypatch.setattr(mapping, "incremental_mapping", lambda db, im, out, options, *a, **kw:
                        got.update(inc=options) or {})
    monkeypatch.setattr(pycolmap, "global_mapping", lambda *a, **kw: got.update(glob=kw["options"]) or {})
    for threads in (-1, 2, 8):
        cfg = small_cfg(num_threads=threads)
        reconstruction.map_incremental(cfg, tmp_path / "db", tmp_path, tmp_path / "m", 10, progress=False)
        reconstruction.map_global(cfg, tmp_path / "db", tmp_path, tmp_path / "g")
        assert got["inc"].num_threads == 1 and got["glob"].num_threads == got["glob"].mapper.num_threads == 1
        assert matching._options(cfg, "sequential")[0].num_threads == 1


@pytest.mark.parametrize("asked, sequence, on", [("auto", True, True), ("auto", False, False), ("on", False, True),
                                                 ("off", True, False), (True, False, True), (False, True, False)])
def test_guided_matching_is_on_for_a_sequence_of_frames_by_default(asked, sequence, on):
    """office.mp4 with a second cut out at a turn mapped as 205 + 166 frames (the 205 placed 32 deg off) without
    it, 361 of 361 with it: on for a video's frames or numbered photos, whatever the matcher (41 frames are
    matched exhaustively). A run folder of curate 0.2 said true or false: on or off."""
    from curate.core.images import PhotoRecord
    from curate.sfm.prep import choose_guided
    names = [f"frame_{i:04d}.jpg" for i in range(5)] if sequence else ["kitchen.jpg", "sofa.jpg", "door.jpg"]
    kept = [PhotoRecord(original=n, rel=n, working=n) for n in names]
    cfg = small_cfg(guided_matching=asked)
    assert cfg.guided_matching in ("auto", "on", "off") and choose_guided(cfg, kept) is on
    video = [PhotoRecord(original="a", rel="a", working=f"walk_{t:010.3f}.jpg") for t in (3.0, 1.0)]
    for r in video:
        r.extra["video"] = "/x/walk.mp4"
    assert choose_guided(small_cfg(), video)
    with pytest.raises(ValueError, match="guided matching"):
        small_cfg(guided_matching="sometimes")


def test_expected_observations_count_each_matched_keypoint_once(tmp_path):
    """The observations the matches promise: keypoints with a verified inlier match, each counted once however many
    pairs it is matched in, in pairs with at least min_num_matches inliers; a database without pairs promises 0."""
    from curate.sfm.reconstruction import expected_observations
    db = pycolmap.Database.open(tmp_path / "d.db")
    cid = db.write_camera(pycolmap.Camera(model="SIMPLE_PINHOLE", width=100, height=100, params=[100, 50, 50]))
    ids = []
    for i in range(3):
        ids.append(db.write_image(pycolmap.Image(name=f"{i}.jpg", camera_id=cid)))
        db.write_keypoints(ids[-1], np.random.default_rng(i).random((40, 2)).astype(np.float32) * 100)
    db.close()
    assert expected_observations(tmp_path / "d.db", 15) == 0
    db = pycolmap.Database.open(tmp_path / "d.db")
    for (a, b), pairs in (((0, 1), [(k, k) for k in range(20)]), ((1, 2), [(k, k + 1) for k in range(10, 30)]),
                          ((0, 2), [(k, k) for k in range(5)])):          # the last: under 15 inliers
        g = pycolmap.TwoViewGeometry()
        g.config = 2
        g.inlier_matches = np.array(pairs, dtype=np.uint32)
        db.write_two_view_geometry(ids[a], ids[b], g)
    db.close()
    # image 0: keypoints 0-19; image 1: 0-19 and 10-29 (30 distinct); image 2: 11-30
    assert expected_observations(tmp_path / "d.db", 15) == 20 + 30 + 20
    assert expected_observations(tmp_path / "d.db", 21) == 0


def test_matches_with_many_observations_adjust_the_whole_model_less_often(monkeypatch, tmp_path):
    """Matches that promise more observations than global_ba_above_observations get the sparser global adjustment
    schedule (a global adjustment costs its observations, not its photos), whatever the count of photos, as do pools
    past global_ba_above photos; the rest keep COLMAP's own. Every pool keeps COLMAP's two local refinements: one
    folded office.mp4 cut into two takes (docs/sfm.md)."""
    from curate.sfm import mapping
    from curate.sfm import reconstruction as sfm
    colmap_default = pycolmap.IncrementalPipelineOptions()
    got: dict = {}
    monkeypatch.setattr(mapping, "incremental_mapping", lambda db, im, out, options, *a, **kw:
                        got.update(kw, options=options) or {})
    cfg = small_cfg()
    assert cfg.global_ba_growth > colmap_default.ba_global_frames_ratio   # the default is the sparser schedule
    promised = {"n": 0}
    monkeypatch.setattr(sfm, "expected_observations", lambda db, m: promised["n"])
    cheaper = (cfg.global_ba_growth, cfg.global_ba_refinements)
    colmap = (colmap_default.ba_global_frames_ratio, colmap_default.ba_global_max_refinements)
    for obs, n, (ratio, refinements) in [(cfg.global_ba_above_observations, cfg.global_ba_above, colmap),
                                         (cfg.global_ba_above_observations + 1, 40, cheaper),
                                         (1000, cfg.global_ba_above + 1, cheaper)]:
        promised["n"] = obs
        schedule: dict = {}
        sfm.map_incremental(cfg, tmp_path / "database.db", tmp_path, tmp_path / "m", n, progress=False,
                            schedule=schedule)
        assert schedule == {"expected_observations": obs, "global_ba_growth": pytest.approx(ratio)}
        o = got["options"]
        assert o.ba_global_frames_ratio == pytest.approx(ratio) and o.ba_global_points_ratio == pytest.approx(ratio)
        assert o.ba_global_max_refinements == refinements
        assert o.ba_local_max_refinements == colmap_default.ba_local_max_refinements
        assert o.mapper.init_min_num_inliers == cfg.init_min_num_inliers   # the rest as for any pool
    with pytest.raises(ValueError, match="global_ba_growth"):
        SfmConfig(global_ba_growth=1.0)
    with pytest.raises(ValueError, match="min_global_gain"):
        SfmConfig(min_global_gain=1.5)


class _Image:
    def __init__(self, name, frame_id):
        self.name, self.frame_id, self.has_pose = name, frame_id, True


class _Model:
    """The little of a pycolmap.Reconstruction that map_capture uses."""

    def __init__(self, n, names=None):
        names = names or [f"x{i}" for i in range(n)]
        self.images = {k: _Image(nm, k) for k, nm in enumerate(names)}

    def num_reg_images(self):
        return sum(im.has_pose for im in self.images.values())

    def reg_image_ids(self):
        return [k for k, im in self.images.items() if im.has_pose]

    def image(self, k):
        return self.images[k]

    def deregister_frame(self, frame_id):
        self.images[frame_id].has_pose = False


def _patch_verify(monkeypatch, fn):
    """``verify_frames`` where map_capture calls it (curate.sfm.reconstruction) and where join_parts does
    (curate.sfm.parts)."""
    from curate.sfm import parts, reconstruction
    for mod in (reconstruction, parts):
        monkeypatch.setattr(mod, "verify_frames", fn)


@pytest.mark.parametrize("inc, glob, kept, tried", [
    ([10], [10], "incremental", False),           # one model of every photo: the global mapper never runs
    ([5, 4], [10], "global", True),               # the capture split: the global mapper kept it whole
    ([6, 4], [5, 3], "incremental", True),        # the global mapper did worse: the incremental model stays
    ([], [9], "global", True),                    # the incremental mapper found nothing
])
def test_auto_mapper_tries_global_when_the_capture_splits(monkeypatch, tmp_path, inc, glob, kept, tried):
    from curate.sfm import reconstruction as sfm
    calls = []
    monkeypatch.setattr(sfm, "part_agreement", lambda g, p: [(1.0, set())] * len(p))   # the global model agrees
    _patch_verify(monkeypatch, lambda rec, names, deg, trusted=None:      # and its frames check out
                  {x: {"ok": True, "why": ""} for x in names})
    monkeypatch.setattr(sfm, "map_incremental", lambda *a, **k: calls.append("inc") or
                        {i: _Model(n) for i, n in enumerate(inc)})
    monkeypatch.setattr(sfm, "map_global", lambda *a, **k: calls.append("glob") or
                        {i: _Model(n) for i, n in enumerate(glob)})
    (tmp_path / "database.db").write_bytes(b"db")
    stats: dict = {}
    models = sfm.map_capture(small_cfg(), tmp_path / "database.db", tmp_path, tmp_path / "m", 10, stats)
    assert stats["mapper"] == kept and ("glob" in calls) == tried
    assert sfm.model_sizes(models) == (glob[:1] if kept == "global" else inc)
    if tried:
        assert stats["mappers_tried"]["incremental"]["model_sizes"] == inc
        assert stats["mappers_tried"]["global"]["model_sizes"] == glob
    assert (tmp_path / "database.db").read_bytes() == b"db"   # the global mapper ran on a copy


@pytest.mark.parametrize("inc, glob, gain, kept", [
    ([69, 13], [71, 13], 0.05, "incremental"),   # a foreign take keeps the incremental model short: 2 more won't do
    ([60, 30], [92], 0.05, "global"),            # a capture split in two, made whole
    ([80, 13], [85], 0.05, "global"),            # exactly 5 of the 100 photos more
    ([81, 13], [85], 0.05, "incremental"),       # 4 more
    ([69, 13], [71, 13], 0.0, "global"),         # no gain asked: any photo more
    ([69, 13], [69, 13], 0.0, "incremental"),    # ... but at least one
    ([], [3], 0.05, "global"),                   # no incremental model at all: any global one is better
])
def test_a_global_model_must_gain_enough_photos_to_replace_the_incremental_one(monkeypatch, tmp_path, inc, glob,
                                                                               gain, kept):
    """Three takes, the third of another place (on a fresh machine): the incremental mapper kept 369 of
    434 photos (the foreign take's 63 apart), the global mapper 371, agreeing with every part, and the
    global model had 12 frames over 5 deg where the incremental one had none. On the real walks measured
    the global model is the less accurate: it must gain ``min_global_gain`` of the pool to be kept."""
    from curate.sfm import reconstruction as sfm
    monkeypatch.setattr(sfm, "part_agreement", lambda g, p: [(1.0, set())] * len(p))
    _patch_verify(monkeypatch, lambda rec, names, deg, trusted=None:
                  {x: {"ok": True, "why": ""} for x in names})
    monkeypatch.setattr(sfm, "map_incremental", lambda *a, **k: {i: _Model(n) for i, n in enumerate(inc)})
    monkeypatch.setattr(sfm, "map_global", lambda *a, **k: {i: _Model(n) for i, n in enumerate(glob)})
    (tmp_path / "database.db").write_bytes(b"db")
    stats: dict = {}
    models = sfm.map_capture(small_cfg(min_global_gain=gain), tmp_path / "database.db", tmp_path, tmp_path / "m",
                             100, stats)
    assert stats["mapper"] == kept
    assert sfm.model_sizes(models) == (glob[:1] if kept == "global" else inc)
    g = stats["mappers_tried"]["global"]
    i = (inc or [0])[0]
    if glob[0] > i:
        assert g["gain"] == glob[0] - i and g["gain_needed"] == (max(1, round(gain * 100)) if inc else 1)


@pytest.mark.parametrize("dis, ties, alone, kept, n", [
    ([1.2, 2.9, 0.5], True, False, "global", 10),         # agrees with every part and ties them together: whole
    ([1.2, 2.9, 0.5], False, True, "incremental", 5),     # agrees, but nothing ties the smaller parts to the largest
    ([1.2, 2.9, 14.0], True, True, "global", 8),          # bent the smallest part: it leaves, however its frames
                                                          # look alone
    ([14.0, 1.0, 1.0], True, True, "incremental", 5),     # bent the largest: what is left is no larger than it
    ([1.0, None, 1.0], True, False, "global", 7),         # a part too small to check, whose frames fail on their own
    ([1.0, None, 1.0], True, True, "global", 10),         # ... or pass on their own: kept (issue 36)
])
def test_the_global_model_keeps_only_the_parts_it_agrees_with(monkeypatch, tmp_path, dis, ties, alone, kept, n):
    """office.mp4 without loop detection: the global mapper registered all 371 frames but turned two
    incremental parts (24 and 13 frames) by 16 and 21 deg; each part alone was right. A bent whole
    is no better than sound parts: only the parts it agrees with stay in it, and only where their
    frames tie them to the largest of them (a two-take walk: a part tied by 22 points was put a quarter
    of the walk off on a CI run, every part still agreeing)."""
    from curate.sfm import reconstruction as sfm
    a, b, c = [f"a{i}" for i in range(5)], [f"b{i}" for i in range(3)], [f"c{i}" for i in range(2)]
    monkeypatch.setattr(sfm, "map_incremental", lambda *a_, **k: {0: _Model(5, a), 1: _Model(3, b), 2: _Model(2, c)})
    monkeypatch.setattr(sfm, "map_global", lambda *a_, **k: {0: _Model(10, a + b + c)})
    monkeypatch.setattr(sfm, "part_agreement", lambda g, p: list(zip(dis, (set(a), set(b), set(c)))))
    unchecked = set().union(*(set(p) for d, p in zip(dis, (a, b, c)) if d is None))
    calls = []

    def verify(rec, names, deg, trusted=None):   # a frame of a checked part passes when the seam holds
        calls.append((set(names), set(trusted or ())))
        return {x: {"ok": alone if x in unchecked else ties, "why": "" if ties else "too few"} for x in names}
    _patch_verify(monkeypatch, verify)
    (tmp_path / "database.db").write_bytes(b"db")
    stats: dict = {}
    models = sfm.map_capture(small_cfg(), tmp_path / "database.db", tmp_path, tmp_path / "m", 10, stats)
    g = stats["mappers_tried"]["global"]
    assert stats["mapper"] == kept and g["part_disagreement_deg"] == dis
    assert sfm.model_sizes(models) == ([n] if kept == "global" else [5, 3, 2])
    refuted = set().union(*(set(p) for d, p in zip(dis, (a, b, c)) if d is not None and d > 3.0))
    anchor = next(set(p) for d, p in zip(dis, (a, b, c)) if d is not None and d <= 3.0)
    checked = set().union(*(nm for nm, _ in calls))
    assert not checked & (refuted | anchor)            # a refuted part is never checked, nor the anchor
    assert checked >= unchecked
    for nm, trusted in calls:                          # no frame vouches for itself or its own part
        assert anchor <= trusted and not nm & trusted
    assert [j["joined"] for j in g["joins"]] == [ties] * len(g["joins"])


@pytest.mark.parametrize("mapper, calls_expected", [("incremental", ["inc"]), ("global", ["glob"])])
def test_a_named_mapper_runs_alone(monkeypatch, tmp_path, mapper, calls_expected):
    from curate.sfm import reconstruction as sfm
    calls = []
    monkeypatch.setattr(sfm, "map_incremental", lambda *a, **k: calls.append("inc") or {0: _Model(3)})
    monkeypatch.setattr(sfm, "map_global", lambda *a, **k: calls.append("glob") or {0: _Model(3)})
    (tmp_path / "database.db").write_bytes(b"db")
    stats: dict = {}
    sfm.map_capture(small_cfg(mapper=mapper), tmp_path / "database.db", tmp_path, tmp_path / "m", 10, stats)
    assert calls == calls_expected and stats["mapper"] == mapper


def test_global_mapper_is_seeded(monkeypatch, tmp_path):
    from curate.sfm import reconstruction as sfm
    got: dict = {}
    monkeypatch.setattr(pycolmap, "global_mapping", lambda *a, **kw: got.update(kw) or {})
    sfm.map_global(small_cfg(seed=5, min_num_matches=20), tmp_path / "db", tmp_path, tmp_path / "g")
    o = got["options"]
    assert o.random_seed == 5 and o.mapper.random_seed == 5 and o.min_num_matches == 20
    assert o.mapper.rotation_averaging.random_seed == 5 and o.mapper.global_positioning.random_seed == 5


def test_visual_words_are_the_same_every_run_and_rank_a_photos_look_alikes_first(tmp_path):
    """COLMAP's vocabulary tree is not seeded (three builds, three trees): loop detection matched other pairs on
    every run. The capture's own words are: the same descriptors give the same words, vectors and ranking."""
    from curate.sfm import retrieval
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(6, 128)).astype(np.float32) * 3      # three "places", two kinds of texture each
    desc = []
    for i in range(12):                                             # photos 0-3 place 0, 4-7 place 1, 8-11 place 2
        place = i // 4
        pick = rng.choice([2 * place, 2 * place + 1], 300)
        desc.append(centres[pick] + rng.normal(size=(300, 128)).astype(np.float32))
    names = [f"f{i:02d}.jpg" for i in range(12)]

    def index(seed):
        from curate.sfm.features import tree_sample
        sample = tree_sample(iter(desc), 12, 2000, np.random.default_rng(seed))
        top, leaves, off = retrieval.train(sample, seed, (8, 4))
        hist = np.stack([np.bincount(retrieval.words(d, top, leaves, off), minlength=int(off[-1])) for d in desc])
        return retrieval.Index(top, leaves, off, names, retrieval.tfidf(hist))

    a, b = index(0), index(0)
    assert (a.vectors != b.vectors).nnz == 0 and a.n_words == b.n_words
    ranks = dict(retrieval.ranked(a, names, k=3))
    assert ranks == dict(retrieval.ranked(b, names, k=3))
    for i, n in enumerate(names):
        assert {int(c[1:3]) // 4 for c in ranks[n]} == {i // 4}, (n, ranks[n])   # its own place's photos first
    assert np.all(np.isfinite(retrieval.tfidf(np.zeros((3, 5))).toarray()))         # photos without words: no NaN
    retrieval.save(a, tmp_path / "visual_words.npz")                                  # kept for the second round
    c = retrieval.load(tmp_path / "visual_words.npz")
    assert (c.vectors != a.vectors).nnz == 0 and dict(retrieval.ranked(c, names, k=3)) == ranks


def test_vocabulary_tree_sample_is_bounded_and_even():
    """The tree trains on a fixed-size sample however large the pool (its time must not grow with it),
    drawn from every image."""
    from curate.sfm.features import tree_sample
    rng = np.random.default_rng(0)
    for n_images in (10, 400, 3000):
        per = [np.full((300, 4), i, np.float32) for i in range(n_images)]
        d = tree_sample(iter(per), n_images, 20_000, rng)
        assert len(d) == min(20_000, n_images * 300)
        counts = np.bincount(d[:, 0].astype(int), minlength=n_images)
        assert counts.min() >= 1 and counts.max() <= max(8, 20_000 // n_images)
    assert tree_sample(iter([]), 0, 1000, rng).shape[0] == 0


# ------------------------------------------------------------------ mixed folder: bad files, input untouched, skip
@pytest.mark.slow
def test_sfm_on_mixed_folder_and_skip_unchanged(tmp_path):
    photos = make_mixed_folder(tmp_path / "photos", n_good=10, size=400)
    before = sha_tree(photos)
    run = tmp_path / "run"
    out = run_sfm(small_cfg(max_image_size=400), photos, run)
    assert sha_tree(photos) == before
    rec = json.loads((out / "images.json").read_text())
    st = {r["rel"]: r for r in rec["photos"]}
    for bad in ("zz_truncated.jpg", "zz_text.jpg", "zz_empty.jpg", "notes.txt"):
        assert st[bad]["status"] == "skipped" and st[bad]["reason"]
    res = load_sfm(run)
    assert len(res.cameras) >= 10, rec["summary"]
    assert res.points.shape[1] == 3 and len(res.points) > 100
    for f in ("sparse/0/cameras.bin", "sparse/0/images.bin", "transforms.json", "cameras.json", "points_rgb.npy",
              "normalization.json", "colmap.log", "stage.json"):
        assert (out / f).is_file(), f
    assert (out / "colmap.log").stat().st_size > 0
    # normalisation maps the scene into the unit box
    s, c = res.normalization["scale"], np.array(res.normalization["centre"])
    assert np.all(np.abs(s * (res.cameras.centres - c)) <= 1 + 1e-9)
    # original-photo cameras: the originals here are 225x400, same as the working copies
    oc, paths = original_cameras(res.cameras, res.records)
    assert set(oc.height) == {400} and all(Path(p).is_file() for p in paths)
    # same inputs and options: skipped at once, record untouched
    stage = (out / "stage.json").read_text()
    t = time.perf_counter()
    run_sfm(small_cfg(max_image_size=400), photos, run)
    assert time.perf_counter() - t < 5 and (out / "stage.json").read_text() == stage
    # an option that changes the result: reruns
    run_sfm(small_cfg(max_image_size=400, max_num_features=2048), photos, run)
    new = json.loads((out / "stage.json").read_text())
    assert new["key"] != json.loads(stage)["key"] and new["config"]["max_num_features"] == 2048
    # a changed photo: reruns
    (photos / "notes.txt").write_text("changed\n")
    key = new["key"]
    run_sfm(small_cfg(max_image_size=400, max_num_features=2048), photos, run)
    assert json.loads((out / "stage.json").read_text())["key"] != key


def test_photo_ids_follow_name_order_whatever_order_extraction_finishes(tmp_path):
    """Image ids break ties in matching and mapping, so the same photos must get the same ids in every
    run: a slow first photo (large, textured) finishes extraction after the small ones behind it."""
    import sqlite3

    from PIL import Image

    from curate.sfm.features import extract
    rng = np.random.default_rng(0)
    photos = tmp_path / "photos"
    photos.mkdir()
    names = [f"p{i:02d}.png" for i in range(12)]
    for i, name in enumerate(names):
        side = 1600 if i == 0 else 96
        Image.fromarray(rng.integers(0, 255, (side, side, 3), dtype=np.uint8)).save(photos / name)
    db = tmp_path / "database.db"
    extract(small_cfg(max_image_size=1600, num_threads=2), db, photos, names[::-1], False)
    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT name FROM images ORDER BY image_id").fetchall()
        n_kp = con.execute("SELECT COUNT(*) FROM keypoints WHERE rows > 0").fetchone()[0]
        n_cameras = con.execute("SELECT COUNT(*) FROM cameras").fetchone()[0]
    assert [r[0] for r in rows] == names and n_kp == n_cameras == len(names)


def test_large_photos_skip_sifts_doubled_octave_unless_they_have_too_few_features(tmp_path):
    """A working copy of 1,000 px or more is read by SIFT as it is (about a quarter of the work of COLMAP's doubled
    first octave); one that gives too few features that way (a plain photo) is read again doubled, as is every
    smaller copy, and those get COLMAP's own features (the same points). No file of the first pass is left behind."""
    import sqlite3

    from PIL import Image, ImageFilter

    from curate.sfm.features import extract
    src = sorted(need("drone/images").iterdir())[0]
    photos = tmp_path / "photos"
    photos.mkdir()
    im = Image.open(src).convert("RGB")                                    # 1600 x 1200, a textured aerial view
    im.save(photos / "a_textured.jpg")
    im.filter(ImageFilter.GaussianBlur(12)).save(photos / "b_plain.jpg")    # large, but few features as it is
    im.resize((800, 600)).save(photos / "c_small.jpg")
    names = ["a_textured.jpg", "b_plain.jpg", "c_small.jpg"]
    cfg = SfmConfig(num_threads=1, progress=False)
    assert cfg.sift_upsample_below == 1000 and cfg.max_image_size >= 1600

    def keypoints(folder: Path, c: SfmConfig) -> tuple[dict, dict]:
        folder.mkdir()
        db = folder / "database.db"
        counts = extract(c, db, photos, names, False)
        dbh = pycolmap.Database.open(db)
        try:
            # where SIFT found each point, as a set (a point with two orientations is two rows); not the orientation,
            # which COLMAP's CPU SIFT computes partly from the image the same thread read before, when of one size
            kp = {im.name: np.unique(np.asarray(dbh.read_keypoints(im.image_id))[:, :2], axis=0)
                  for im in dbh.read_all_images()}
        finally:
            dbh.close()
        with sqlite3.connect(db) as con:
            assert [r[0] for r in con.execute("SELECT name FROM images ORDER BY image_id")] == names
        assert not [p.name for p in folder.iterdir() if not p.name.startswith("database.db")]   # -wal, -shm: SQLite's
        return counts, kp

    counts, kp = keypoints(tmp_path / "auto", cfg)
    colmap_counts, colmap = keypoints(tmp_path / "colmap", replace(cfg, sift_upsample_below=cfg.max_image_size + 1))
    assert colmap_counts == {"doubled": 3, "not_doubled": 0}
    assert counts == {"doubled": 2, "not_doubled": 1}
    assert cfg.sift_min_features_undoubled <= len(kp["a_textured.jpg"]) < len(colmap["a_textured.jpg"])
    for name in ("b_plain.jpg", "c_small.jpg"):
        assert np.array_equal(kp[name], colmap[name]), name
    # 0: every photo tried as it is first; the plain one, and the small one (under 1,024 features as it is), still
    # fall back to the doubled octave
    counts0, kp0 = keypoints(tmp_path / "never", replace(cfg, sift_upsample_below=0))
    assert counts0 == {"doubled": 2, "not_doubled": 1}
    assert all(np.array_equal(kp0[n], colmap[n]) for n in ("b_plain.jpg", "c_small.jpg"))


@pytest.fixture(scope="module")
def fox_features(tmp_path_factory):
    """24 of the fox's photos' SIFT features (320 px) in a COLMAP database, not matched."""
    from curate.sfm.features import extract
    photos = need("fox/images")
    names = sorted(p.name for p in photos.iterdir())[:24]
    db = tmp_path_factory.mktemp("fox_features") / "database.db"
    extract(small_cfg(max_image_size=320), db, photos, names, True)
    return db


def _match_rows(db: Path) -> dict:
    import sqlite3
    with sqlite3.connect(db) as con:
        return {t: con.execute(f"SELECT * FROM {t} ORDER BY pair_id").fetchall()
                for t in ("matches", "two_view_geometries")}


def _frames_db(path: Path, n: int) -> list[str]:
    """A COLMAP database of ``n`` frames (names only, imported in reverse order): their names in order."""
    names = [f"frame_{i:04d}.jpg" for i in range(n)]
    with pycolmap.Database.open(path) as dbh:
        cam = dbh.write_camera(pycolmap.Camera.create_from_model_name(1, "SIMPLE_PINHOLE", 100.0, 64, 48))
        for nm in names[::-1]:
            dbh.write_image(pycolmap.Image(name=nm, camera_id=cam))
    return names


@pytest.mark.parametrize("quadratic, want", [(True, [1, 2, 4, 8, 16, 32]), (False, [1, 2, 3, 4, 5, 6])])
def test_sequential_matching_pairs_each_frame_with_the_neighbours_its_options_name(tmp_path, monkeypatch,
                                                                                    quadratic, want):
    """What ``SfmConfig.sequential_overlap`` and ``sequential_quadratic`` say a frame is matched with: with the
    quadratic neighbours (the default) frames i + 1, 2, 4, ... 2^(N-1), which replace the next N in COLMAP 4's
    pairing (they were added to them before); without, the next N. The list is in name order, whatever order the
    frames were imported in, and holds no other pair (loop detection off)."""
    from curate.sfm import matching
    db = tmp_path / "database.db"
    names = _frames_db(db, 40)
    listed: list = []
    monkeypatch.setattr(matching, "processes", lambda cfg, n: 2)   # the list route, not COLMAP's whole matcher
    monkeypatch.setattr(matching, "match_list", lambda cfg, db, pairs, *a, **k: listed.extend(pairs) or {})
    cfg = small_cfg(sequential_overlap=6, sequential_quadratic=quadratic, loop_detection=False)
    matching.match(cfg, db, "sequential")
    index = {n: i for i, n in enumerate(names)}
    got = {}
    for a, b in listed:
        got.setdefault(index[a], []).append(index[b] - index[a])
    assert len(listed) == len(set(listed)) and set(got) == set(range(39))
    for i, steps in got.items():
        assert sorted(steps) == [s for s in want if i + s < 40], (i, steps)


@pytest.mark.slow
@pytest.mark.parametrize("matcher, guided", [("exhaustive", "off"), ("sequential", "on")])
def test_matching_in_pieces_on_several_processes_writes_what_one_thread_writes(fox_features, tmp_path, monkeypatch,
                                                                              matcher, guided):
    """COLMAP's matcher on one thread gives the same matches every run, on two it does not (46 of 3,693 pairs of
    office.mp4 differed): the pair list is cut into pieces matched on one thread each, in processes of their own,
    and their rows copied into the database. Those rows are COLMAP's own matcher's (``match_exhaustive`` /
    ``match_sequential`` on one thread), byte for byte, guided matching included, whatever the number of
    processes and pieces."""
    import shutil

    from curate.sfm import matching
    cfg = small_cfg(guided_matching=guided, loop_detection=False, num_threads=1)
    ref = tmp_path / "ref" / "database.db"
    ref.parent.mkdir()
    shutil.copy2(fox_features, ref)
    mo, vo, dev = matching._options(cfg, matcher)
    if matcher == "exhaustive":
        pycolmap.match_exhaustive(ref, matching_options=mo, verification_options=vo, device=dev)
    else:
        po = pycolmap.SequentialPairingOptions()
        po.overlap, po.quadratic_overlap, po.loop_detection = cfg.sequential_overlap, cfg.sequential_quadratic, False
        pycolmap.match_sequential(ref, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)
    want = _match_rows(ref)
    assert len(want["two_view_geometries"]) >= 80
    monkeypatch.setattr(matching, "MIN_PAIRS_PER_PROCESS", 16)
    for n in (1, 2, 3):
        monkeypatch.setattr(matching, "MATCHING_PROCESSES", n)
        db = tmp_path / f"p{n}" / "database.db"
        db.parent.mkdir()
        shutil.copy2(fox_features, db)
        stats: dict = {}
        matching.match(cfg, db, matcher, None, stats)
        assert stats["pairs"]["processes"] == n
        assert _match_rows(db) == want, n
        assert not list(db.parent.glob("match_*")), "the pieces' copies are removed"


@pytest.mark.slow
def test_a_real_part_that_shares_frames_joins_with_its_points_triangulated(fox_features, tmp_path):
    """24 fox photos mapped in one model, then cut into two parts sharing 10 photos (0-16 and 7-23), the second moved
    to another world frame, as the incremental mapper leaves a split: joined (curate.sfm.reconstruction.join_split,
    with the capture's own matches), every photo is back at its pose in the model, the first part's poses untouched,
    and each added photo sees points triangulated from the matches."""
    import shutil

    from curate.sfm import matching, reconstruction
    cfg = small_cfg(loop_detection=False)
    db = tmp_path / "database.db"
    shutil.copy2(fox_features, db)
    mo, vo, dev = matching._options(cfg, "exhaustive")
    pycolmap.match_exhaustive(db, matching_options=mo, verification_options=vo, device=dev)
    images = need("fox/images")
    whole = reconstruction.map_incremental(cfg, db, images, tmp_path / "map", 24, progress=False)
    whole = max(whole.values(), key=lambda r: r.num_reg_images())
    ids = sorted(whole.reg_image_ids(), key=lambda i: whole.image(i).name)
    assert len(ids) == 24
    pose = {whole.image(i).name: np.asarray(whole.image(i).cam_from_world().matrix()) for i in ids}
    a, b = pycolmap.Reconstruction(whole), pycolmap.Reconstruction(whole)
    for i in ids[17:]:
        a.deregister_frame(a.image(i).frame_id)
    for i in ids[:7]:
        b.deregister_frame(b.image(i).frame_id)
    b.transform(pycolmap.Sim3d(0.3, pycolmap.Rotation3d(np.array([0.2, -0.4, 0.1])), np.array([1.0, 2.0, -3.0])))
    record: dict = {}
    joined = reconstruction.join_split(cfg, db, images, tmp_path / "joined", {0: a, 1: b}, record)
    rec = joined[0]
    assert len(joined) == 1 and rec.num_reg_images() == 24 and record["joins"][0]["shared"] == 10
    scale = np.linalg.norm(np.ptp([whole.image(i).projection_center() for i in ids], axis=0))
    for i in ids:
        im = rec.image(i)
        got = np.asarray(im.cam_from_world().matrix())
        assert np.abs(got[:, :3] - pose[im.name][:, :3]).max() < 2e-3, im.name          # rotation, within 0.1 deg
        assert np.abs(got[:, 3] - pose[im.name][:, 3]).max() < 2e-3 * scale, im.name
        if i in ids[:17]:
            assert np.abs(got - np.asarray(a.image(i).cam_from_world().matrix())).max() < 1e-12   # held
        else:
            assert im.num_points3D >= 30, (im.name, im.num_points3D)
    assert rec.num_points3D() > a.num_points3D()


@pytest.mark.slow
def test_with_many_features_only_the_pairs_with_few_matches_are_guided(fox_features, tmp_path, monkeypatch):
    """Guided matching costs several unguided matches where photos have many features (4 times at 4,500 a photo)
    and adds little to a pair that has plenty: there auto guides only the pairs whose unguided verification keeps
    fewer than ``guided_only_below_inliers`` matches. Each such pair's rows are the rows guiding every pair writes
    (a pair that fails unguided is not matched again: its rows are the same guided), each other pair's the
    unguided rows, byte for byte, on one process or two; the record counts the pairs matched again;
    photos with fewer features than ``guided_selective_above_features`` have every pair guided."""
    import shutil
    import sqlite3

    from curate.sfm import matching
    cfg = small_cfg(guided_matching="on", loop_detection=False, num_threads=1)
    po = pycolmap.SequentialPairingOptions()
    po.overlap, po.quadratic_overlap, po.loop_detection = cfg.sequential_overlap, cfg.sequential_quadratic, False
    refs = {}
    for guided in ("on", "off"):
        ref = tmp_path / guided / "database.db"
        ref.parent.mkdir()
        shutil.copy2(fox_features, ref)
        mo, vo, dev = matching._options(small_cfg(guided_matching=guided), "sequential")
        pycolmap.match_sequential(ref, matching_options=mo, pairing_options=po, verification_options=vo, device=dev)
        refs[guided] = {t: {r[0]: r for r in rows} for t, rows in _match_rows(ref).items()}
    inliers = {pid: r[1] for pid, r in refs["off"]["two_view_geometries"].items()}
    below = int(np.median(list(inliers.values())))
    weak = {pid for pid, n in inliers.items() if n < below}   # those that fail unguided are the same guided
    assert 10 <= len(weak) <= len(inliers) - 10 and any(n < cfg.min_num_matches for n in inliers.values())
    assert any(refs["on"]["two_view_geometries"][p] != refs["off"]["two_view_geometries"][p] for p in inliers)
    monkeypatch.setattr(matching, "MIN_PAIRS_PER_PROCESS", 16)
    for n in (1, 2):
        monkeypatch.setattr(matching, "MATCHING_PROCESSES", n)
        db = tmp_path / f"p{n}" / "database.db"
        db.parent.mkdir()
        shutil.copy2(fox_features, db)
        stats: dict = {}
        matching.match(cfg, db, "sequential", None, stats, guided_below=below)
        assert stats["pairs"]["processes"] == n
        assert stats["pairs"]["guided_pairs"] == sum(cfg.min_num_matches <= inliers[p] for p in weak)
        got = _match_rows(db)
        for t in ("matches", "two_view_geometries"):
            assert [r[0] for r in got[t]] == sorted(refs["off"][t]), (n, t)
            for r in got[t]:
                assert r == refs["on" if r[0] in weak else "off"][t][r[0]], (n, t, r[0])
        assert not list(db.parent.glob("match_*")) and not list(db.parent.glob("*_guided.txt"))
    with sqlite3.connect(fox_features) as con:
        counts = sorted(r[0] for r in con.execute("SELECT rows FROM keypoints"))
    median = counts[len(counts) // 2]   # half the photos have at least as many
    auto = small_cfg(guided_only_below_inliers=below)
    assert matching.weak_first(replace(auto, guided_selective_above_features=median), fox_features) == below
    assert matching.weak_first(replace(auto, guided_selective_above_features=median + 1), fox_features) == 0
    assert matching.weak_first(replace(auto, guided_only_below_inliers=0, guided_selective_above_features=0),
                               fox_features) == 0
    with pytest.raises(ValueError, match="guided_only_below_inliers"):
        small_cfg(guided_only_below_inliers=-1)


@pytest.mark.slow
def test_sfm_records_which_pairs_auto_guided(tmp_path):
    """`curate sfm` with guided matching by auto passes the photos' threshold to the matcher and records it and
    the pairs it guided: past ``guided_selective_above_features`` only some pairs, under it (or with ``on``) all."""
    photos = tmp_path / "photos"
    photos.mkdir()
    for p in sorted(need("fox/images").iterdir())[:12]:
        (photos / p.name).symlink_to(p)
    seen = {}
    for name, kw in (("weak", {"guided_selective_above_features": 0, "guided_only_below_inliers": 150}),
                     ("all", {"guided_selective_above_features": 10 ** 6}),
                     ("on", {"guided_matching": "on", "guided_selective_above_features": 0})):
        run_sfm(small_cfg(max_image_size=320, **kw), photos, tmp_path / name)
        st = json.loads((tmp_path / name / "sfm" / "stage.json").read_text())["stats"]
        seen[name] = (st["guided_only_below_inliers"], st["pairs"]["guided_pairs"], st["pairs"]["new_pairs"])
    below, guided, pairs = seen["weak"]
    assert below == 150 and 0 < guided < pairs, seen
    assert seen["all"] == (0, pairs, pairs) and seen["on"] == (0, pairs, pairs), seen


@pytest.mark.slow
def test_photos_with_spaces_in_their_names_are_matched_as_colmap_matches_them(fox_features, tmp_path, monkeypatch):
    """COLMAP's pair list cannot name a photo whose name holds a space (``IMG 0001.jpg``, common on phones and
    cameras): such a capture is matched by COLMAP's own matcher on one thread, every pair, the same rows as
    before the pieces, not left unmatched."""
    import shutil

    from curate.sfm import matching
    cfg = small_cfg(guided_matching="off", loop_detection=False, num_threads=2)
    dbs = []
    for name in ("ref", "new"):
        db = tmp_path / name / "database.db"
        db.parent.mkdir()
        shutil.copy2(fox_features, db)
        with pycolmap.Database.open(db) as dbh:
            for im in dbh.read_all_images():
                if im.image_id % 2 == 0:
                    im.name = "fox " + im.name
                    dbh.update_image(im)
        dbs.append(db)
    mo, vo, dev = matching._options(cfg, "exhaustive")
    pycolmap.match_exhaustive(dbs[0], matching_options=mo, verification_options=vo, device=dev)
    monkeypatch.setattr(matching, "MIN_PAIRS_PER_PROCESS", 16)
    stats: dict = {}
    matching.match(cfg, dbs[1], "exhaustive", None, stats)
    want = _match_rows(dbs[0])
    assert len(want["two_view_geometries"]) >= 80 and stats["pairs"]["unlisted"] == 0
    assert _match_rows(dbs[1]) == want


def test_a_part_inside_the_largest_model_is_no_split():
    """COLMAP may keep a first model of a few photos that the next model also registers: nothing is
    lost, so it is dropped (no split reported); a part with a photo of its own stays."""
    from curate.sfm.model import reconstruction_from_cameras
    from curate.sfm.parts import without_contained
    a = np.linspace(0, 1, 6)
    c2w = look_at(np.stack([np.cos(a), np.sin(a), np.full(6, 0.3)], 1), np.zeros((6, 3)))
    cams = Cameras(c2w, np.full(6, 300.0), np.full(6, 300.0), np.full(6, 160.0), np.full(6, 120.0),
                   np.full(6, 320), np.full(6, 240), names=tuple(f"f{i}.jpg" for i in range(6)))
    whole = reconstruction_from_cameras(cams[np.arange(5)])
    inside = reconstruction_from_cameras(cams[np.array([1, 2, 3])])
    own = reconstruction_from_cameras(cams[np.array([3, 4, 5])])
    assert list(without_contained({0: inside, 1: whole})) == [1]
    assert sorted(without_contained({0: whole, 1: inside, 2: own})) == [0, 2]
    assert list(without_contained({0: inside})) == [0]


def test_refuses_run_folder_inside_photos(tmp_path):
    (tmp_path / "a.jpg").write_bytes(b"")
    with pytest.raises(ValueError, match="inside the photo folder"):
        run_sfm(small_cfg(), tmp_path, tmp_path / "run")


def test_too_few_photos_is_an_error_with_records(tmp_path):
    photos = make_mixed_folder(tmp_path / "photos", n_good=1)
    (photos / "extra.png").unlink()
    with pytest.raises(RuntimeError, match="usable photos"):
        run_sfm(small_cfg(), photos, tmp_path / "run")
    j = json.loads((tmp_path / "run" / "sfm" / "images.json").read_text())
    assert j["summary"]["kept"] == 1 and j["summary"]["skipped"] == 4
    assert not (tmp_path / "run" / "sfm" / "stage.json").exists()


def test_photos_only_in_a_subfolder_are_named_in_the_error(tmp_path):
    """A capture's folder whose photos lie in images/ beside its README (the drone set's layout): the error says
    where they are and how to give them, and curate wrote nothing beside them."""
    photos = tmp_path / "capture"
    make_mixed_folder(photos / "images", n_good=3)
    (photos / "README.md").write_text("a capture\n")
    before = sorted(p.relative_to(photos) for p in photos.rglob("*"))
    with pytest.raises(RuntimeError, match="usable photos") as e:
        run_sfm(small_cfg(), photos, tmp_path / "run")
    msg = str(e.value)
    assert "lie in its subfolders (images)" in msg and str(photos / "images") in msg and "--recursive" in msg
    assert sorted(p.relative_to(photos) for p in photos.rglob("*")) == before
    flat = make_mixed_folder(tmp_path / "flat", n_good=1)
    (flat / "extra.png").unlink()
    with pytest.raises(RuntimeError) as e:   # too few in the folder itself, none below: no such hint
        run_sfm(small_cfg(), flat, tmp_path / "run2")
    assert "subfolders" not in str(e.value)


@pytest.mark.slow
def test_curates_mapping_loop_maps_as_colmaps_pipeline_with_either_solver(fox_run, tmp_path, monkeypatch):
    """The fox's matches mapped by COLMAP's pipeline and by curate.sfm.mapping (COLMAP's steps in Python,
    each global adjustment's solver chosen by the fill), with Ceres' direct-solve limit lowered to 55
    photos (above its dense-solve limit, 50) so that the choice is made: with a fill bar no model reaches (every
    adjustment direct, as COLMAP solves a model of 67 photos) and with one every model passes (iterative past 55
    photos), the same photos registered in one model, at the same poses. The stage's own path
    (``map_capture`` → ``map_incremental``, the product's options) chooses the direct solver for the fox by the
    default bar, records each choice in the stage's stats and, without COLMAP's repeated final refinement,
    registers the same photos at poses within 0.1 deg of COLMAP's, with fewer global refinements: none after the
    one before the last try where nothing registered in between."""
    import shutil

    from curate.sfm import mapping
    from curate.sfm.model import cameras_from_reconstruction
    from curate.sfm.reconstruction import incremental_options, map_capture
    sfm_dir, cfg = fox_run / "sfm", fox_cfg()
    n = sum(1 for _ in (sfm_dir / "images").iterdir())
    models, choices, refinements = {}, {}, {}
    real = mapping._Loop.global_refinement

    def counted(who):
        count = refinements.setdefault(who, [])
        monkeypatch.setattr(mapping._Loop, "global_refinement", lambda self, *a: count.append(1) or real(self, *a))

    for who, max_fill in (("colmap", None), ("direct", 1e9), ("iterative", 1.0)):
        db = tmp_path / f"{who}.db"
        shutil.copy2(sfm_dir / "database.db", db)
        opts = incremental_options(cfg, n)
        pycolmap.set_random_seed(0)
        if who == "colmap":
            models[who] = pycolmap.incremental_mapping(db, sfm_dir / "images", tmp_path / who, options=opts)
        else:
            choices[who] = mapping.SolverChoice(max_fill, 55)
            counted(who)
            models[who] = mapping.incremental_mapping(db, sfm_dir / "images", tmp_path / who, opts, choices[who],
                                                      repeat_final_refinement=True)
    # the stage's path, its default options: the final refinement once
    monkeypatch.setattr(mapping, "ceres_direct_limit", lambda: 55)
    counted("once")
    shutil.copy2(sfm_dir / "database.db", tmp_path / "cap.db")
    stats: dict = {}
    models["once"] = map_capture(fox_cfg(mapper="incremental"), tmp_path / "cap.db", sfm_dir / "images",
                                 tmp_path / "cap", n, stats)
    monkeypatch.setattr(mapping._Loop, "global_refinement", real)
    assert stats["mapper"] == "incremental" and stats["global_adjustments"]
    assert {e["solver"] for e in stats["global_adjustments"]} == {"direct"}     # the fox fills < 270 per photo
    assert len(refinements["once"]) < len(refinements["direct"]), refinements
    assert {e["solver"] for e in choices["direct"].record} == {"direct"}
    assert {e["solver"] for e in choices["iterative"].record} == {"iterative"}
    assert choices["direct"].record and choices["iterative"].record
    assert all(e["photos"] > 55 and e["seconds"] >= 0 and e["fill_per_photo"] > 1 for e in choices["direct"].record)
    sizes = {k: sorted((r.num_reg_images() for r in m.values()), reverse=True) for k, m in models.items()}
    assert sizes["direct"] == sizes["iterative"] == sizes["once"] == sizes["colmap"], sizes
    assert sizes["colmap"][0] >= 0.95 * n, sizes
    cams = {k: cameras_from_reconstruction(max(m.values(), key=lambda r: r.num_reg_images()), warn=False)[0]
            for k, m in models.items()}
    for who in ("direct", "iterative", "once"):
        assert set(cams[who].names) == set(cams["colmap"].names)
        e = pose_errors(cams[who], cams["colmap"])
        assert e["rotation_deg_max"] < {"direct": 0.05, "iterative": 0.5, "once": 0.1}[who] \
            and e["centre_rel_median"] < 1e-2, (who, e)
    assert (tmp_path / "direct" / "0" / "images.bin").is_file()   # written where COLMAP writes its models


# ------------------------------------------------------------------ fox: accuracy, import
@pytest.mark.slow
def test_fox_sfm_matches_published_poses(fox_run):
    from curate.core.transforms_json import read_transforms
    ref, _ = read_transforms(need("fox") / "transforms.json")
    res = load_sfm(fox_run)
    assert len(res.cameras) >= 0.95 * len(ref)
    e = pose_errors(res.cameras, ref)
    assert e["rotation_deg_median"] <= 1.0, e
    assert e["centre_rel_median"] <= 0.02, e
    st = json.loads((fox_run / "sfm" / "stage.json").read_text())
    assert st["stats"]["matcher"] == "exhaustive" and st["stats"]["camera_mode"] == "single"
    assert set(st["timings"]) >= {"ingest", "extract", "match", "map"}


def test_import_transforms_json(tmp_path):
    from curate.core.transforms_json import read_transforms
    src = need("fox") / "transforms.json"
    ref, files = read_transforms(src)
    out = import_poses(small_cfg(triangulate="off"), src, tmp_path / "run")  # points: test_pose_import.py
    res = load_sfm(tmp_path / "run")
    assert res.cameras.names == ref.names
    for k in ("c2w", "fx", "fy", "cx", "cy", "width", "height", "dist"):
        assert np.allclose(getattr(res.cameras, k), getattr(ref, k)), k
    back, files2 = read_transforms(out / "transforms.json", contained=False)   # curate's record of the originals
    resolved = [str(Path(f).resolve()) for f in files]  # the import records resolved paths
    assert files2 == resolved and np.allclose(back.c2w, ref.c2w)
    # the COLMAP model written for it holds the same cameras
    res2 = import_poses(small_cfg(), out / "sparse" / "0", tmp_path / "run2")
    c2 = load_sfm(tmp_path / "run2").cameras
    # (COLMAP stores unit quaternions: the file's slightly non-orthonormal rotations come back to ~1e-7)
    assert np.allclose(c2.c2w, ref.c2w, atol=1e-5) and np.allclose(c2.dist, ref.dist)
    assert res2.is_dir()


@pytest.mark.slow
def test_a_photo_folder_gives_the_same_model_on_every_run_and_any_number_of_threads(fox_run, tmp_path):
    """The fox's 67 photos mapped again, on one thread where the first run had every core: the same photos
    registered with the same poses (:func:`assert_same_model`; verification is seeded per pair, the mapper runs on
    one thread)."""
    run_sfm(fox_cfg(num_threads=1), need("fox/images"), tmp_path / "again")
    a, b = load_sfm(fox_run).cameras, load_sfm(tmp_path / "again").cameras
    assert len(a) >= 60
    assert_same_model(a, b)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["binary", "text"])
def test_import_colmap_model(fox_run, tmp_path, fmt):
    model = fox_run / "sfm" / "sparse" / "0"
    if fmt == "text":
        rec = pycolmap.Reconstruction(model)
        model = tmp_path / "text_model"
        model.mkdir()
        rec.write_text(model)
        for f in model.glob("*.bin"):
            f.unlink()
    src = load_sfm(fox_run)
    import_poses(fox_cfg(), model, tmp_path / "run", photos=fox_run / "sfm" / "images")
    res = load_sfm(tmp_path / "run")
    assert res.cameras.names == src.cameras.names
    for k in ("c2w", "fx", "fy", "cx", "cy", "dist"):
        assert np.allclose(getattr(res.cameras, k), getattr(src.cameras, k), atol=1e-6), k
    assert len(res.points) == len(src.points)
    assert all(r["registered"] and Path(r["original"]).is_file() for r in res.records["photos"])
    # a second import of the same source is skipped
    t = time.perf_counter()
    import_poses(fox_cfg(), model, tmp_path / "run", photos=fox_run / "sfm" / "images")
    assert time.perf_counter() - t < 2


# ------------------------------------------------------------------ templering
@pytest.mark.slow
def test_templering_sfm_matches_ground_truth(tmp_path):
    from research.datasets import load_templering
    folder = need("templering")
    ref = load_templering(folder)
    photos = tmp_path / "photos"  # only the PNGs (the folder also holds the calibration text files)
    photos.mkdir()
    for p in sorted(folder.glob("*.png")):
        (photos / p.name).symlink_to(p)
    run_sfm(small_cfg(), photos, tmp_path / "run")
    res = load_sfm(tmp_path / "run")
    assert len(res.cameras) >= 0.95 * len(ref), len(res.cameras)
    e = pose_errors(res.cameras, ref)
    assert e["rotation_deg_median"] <= 1.0, e
    assert e["centre_rel_median"] <= 0.02, e


def test_a_split_capture_is_said_loudly_and_can_stop(tmp_path):
    """When SfM keeps only part of the capture, the sfm stage says which photos are lost (by runs of
    frame numbers) and the models' sizes; `--on-split stop` stops instead of curating half a room."""
    from dataclasses import replace as dc_replace
    from curate.config import RunConfig
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.core.runfolder import claimed
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    cfg = RunConfig()
    cfg = dc_replace(cfg, sfm=dc_replace(cfg.sfm, progress=False, triangulate="off"))

    def sfm(cfg):
        with claimed(tmp_path, [sample]):
            return run_stage(BY_NAME["sfm"], RunContext(cfg, tmp_path, photos=sample, poses=sample / "transforms.json"))
    res = sfm(cfg)
    assert res.ran and res.warning is None
    rec_path = tmp_path / "sfm" / "stage.json"
    rec = json.loads(rec_path.read_text())
    lost = [f"images/frame_{i:04d}.jpg" for i in range(80, 150)]
    rec["stats"].update({"model_sizes": [90, 70], "n_kept": 160, "n_registered": 90, "unregistered": lost})
    rec_path.write_text(json.dumps(rec))
    res = sfm(cfg)
    assert not res.ran
    assert "split into 2 models (90, 70 photos)" in res.warning and "90 of 160" in res.warning
    assert "frame_0080.jpg..images/frame_0149.jpg (70)" in res.warning
    with pytest.raises(ValueError, match="stopped: --on-split stop"):
        sfm(dc_replace(cfg, sfm=dc_replace(cfg.sfm, on_split="stop")))


def test_part_agreement_on_reconstructions():
    """Parts in their own frames (moved, turned, scaled) agree with a whole model of the same cameras;
    a part bent against it (its cameras turned by 0, 3, ..., 33 deg in turn) does not; a part with
    too few common images is None."""
    from scipy.spatial.transform import Rotation

    from curate.sfm.model import reconstruction_from_cameras
    from curate.sfm.parts import part_agreement
    ang = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    c = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.full(30, 1.0)], 1)
    whole = Cameras(look_at(c, np.zeros((30, 3))), 500, 500, 320, 240, 640, 480,
                    names=tuple(f"f{i:02d}.jpg" for i in range(30)))
    R = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
    sound = whole[np.arange(0, 15)].transformed(2.0, R, [1, 2, 3])
    bent = whole[np.arange(15, 27)]
    turn = Rotation.from_rotvec([[0, np.radians(3 * j), 0] for j in range(len(bent))]).as_matrix()
    c2w = bent.c2w.copy()
    c2w[:, :3, :3] = turn @ c2w[:, :3, :3]
    bent = Cameras(c2w, 500, 500, 320, 240, 640, 480, names=bent.names)
    tiny = whole[np.arange(27, 30)]
    glob = {0: reconstruction_from_cameras(whole)}
    parts = {k: reconstruction_from_cameras(p) for k, p in enumerate((sound, bent, tiny))}
    (d0, n0), (d1, n1), (d2, _) = part_agreement(glob, parts)
    assert d0 < 1e-3 and d1 > 5 and d2 is None
    assert n0 == set(sound.names) and n1 == set(bent.names)


def test_a_part_bent_only_at_its_end_disagrees():
    """office.mp4 without loop detection: the global model agreed with the median of the largest
    incremental part (2.1 deg) and turned a tenth of its frames by 12-13 deg. The check reads
    the part's 90th percentile: a part with 15% of its frames turned by 12 deg does not agree; one
    with a single stray frame still does."""
    from scipy.spatial.transform import Rotation

    from curate.sfm.model import reconstruction_from_cameras
    from curate.sfm.parts import part_agreement
    ang = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    c = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.full(40, 1.0)], 1)
    whole = Cameras(look_at(c, np.zeros((40, 3))), 500, 500, 320, 240, 640, 480,
                    names=tuple(f"f{i:02d}.jpg" for i in range(40)))
    glob = {0: reconstruction_from_cameras(whole)}

    def turned(k):   # the part of all 40 cameras, its first k turned by 12 deg about the vertical
        c2w = whole.c2w.copy()
        c2w[:k, :3, :3] = Rotation.from_rotvec([0, 0, np.radians(12)]).as_matrix() @ c2w[:k, :3, :3]
        return reconstruction_from_cameras(Cameras(c2w, 500, 500, 320, 240, 640, 480, names=whole.names))

    (end, _), = part_agreement(glob, {0: turned(6)})
    (stray, _), = part_agreement(glob, {0: turned(1)})
    assert end > 3.0 and stray < 3.0


def test_the_warning_says_which_parts_the_global_model_could_not_tie(tmp_path):
    """When the global model is kept pruned, the end-of-run warning says why photos are missing: the
    parts it bends, the parts too few points tie to the rest, the frames that failed their own check."""
    from curate.sfm.warn import split_warning
    (tmp_path / "sfm").mkdir()
    lost = [f"walk2_{0.1 * i:010.3f}.jpg" for i in range(15)]
    glob = {"model_sizes": [93, 17], "pruned_to": 76, "joins": [{"photos": 15, "frames_passed": 0, "joined": False}],
            "verified": {"checked": 3, "kept": 1, "refused": {"a.jpg": "x", "b.jpg": "y"}}}
    stats = {"mapper": "global", "model_sizes": [76], "n_kept": 91, "n_registered": 76, "unregistered": lost,
             "mappers_tried": {"incremental": {"model_sizes": [75, 17, 15]}, "global": glob}}
    (tmp_path / "sfm" / "stage.json").write_text(json.dumps({"stats": stats}))
    w = split_warning(tmp_path)
    assert w.startswith("the incremental mapper split the capture (75, 17, 15 photos) and the global mapper placed "
                        "93 in one model"), w
    assert "of parts too few points tie to the rest (1 part, 15 photos)" in w and "(2 of 3)" in w
    assert "curate uses the largest, 76 of 91 photos; 15 are left out" in w
    glob["joins"][0]["joined"] = True
    (tmp_path / "sfm" / "stage.json").write_text(json.dumps({"stats": stats}))
    assert "too few points" not in split_warning(tmp_path)


@pytest.mark.slow
def test_photos_in_no_order_past_the_exhaustive_limit_are_matched_by_retrieval_and_come_back_whole(tmp_path):
    """A folder of photos with no order (names that are not a sequence, no GPS) past the exhaustive limit is
    matched by retrieval (each photo with its most similar, a vocabulary tree trained on the capture: pairs
    grow linearly, not quadratically) and comes back as one model, its poses agreeing with the truth."""
    import hashlib
    import os
    from curate.core.transforms_json import read_transforms
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    photos = tmp_path / "photos"
    photos.mkdir()
    back = {}
    for p in sorted((sample / "images").glob("*.jpg")):
        h = hashlib.sha1(p.name.encode()).hexdigest()[:10] + ".jpg"     # no order left in the names
        os.link(p, photos / h)
        back[h] = p.name
    run = tmp_path / "run"
    run_sfm(SfmConfig(max_image_size=320, exhaustive_max_images=40, retrieval_num_images=20, progress=False),
            photos, run)
    st = json.loads((run / "sfm" / "stage.json").read_text())["stats"]
    n = st["n_kept"]
    assert st["matcher"] == "retrieval"
    assert st["n_pairs_matched"] <= n * 20 < n * (n - 1) // 2          # at most N per photo, not every pair
    got = load_sfm(run).cameras
    assert len(got) >= 0.9 * n, st["model_sizes"]
    recs = {r["working"]: r["rel"] for r in json.loads((run / "sfm" / "images.json").read_text())["photos"]}
    truth, _ = read_transforms(sample / "transforms.json")
    est = Cameras(got.c2w, got.fx, got.fy, got.cx, got.cy, got.width, got.height,
                  names=tuple(back[recs[nm]] for nm in got.names))
    e = pose_errors(est, truth)
    assert e["rotation_deg_median"] < 1.0, e


class _NamedModel:
    """A stand-in for a pycolmap.Reconstruction: the names of its registered images."""

    def __init__(self, names):
        self.names = list(names)

    def num_reg_images(self):
        return len(self.names)

    def reg_image_ids(self):
        return range(len(self.names))

    def image(self, i):
        return type("Image", (), {"name": self.names[i]})()


def test_retrieval_maps_again_only_when_the_model_leaves_photos_out_and_keeps_the_larger(monkeypatch, tmp_path):
    """Retrieval's second round: a model holding at least 90% of the photos is kept as it is (no more
    matching); under that, the photos it left out (and only those) are matched again and the capture mapped
    again, and the larger of the two largest models is kept."""
    from curate.sfm import colmap
    names = [f"p{i:03d}.jpg" for i in range(20)]
    asked = []
    monkeypatch.setattr(colmap, "rematch_left_out", lambda cfg, db, left: asked.append(left) or {
        "photos": len(left), "num_images": 120, "verified": 7})
    again = {"m": {0: _NamedModel(names[:19])}}
    monkeypatch.setattr(colmap, "map_capture", lambda *a, **k: again["m"])
    whole = {0: _NamedModel(names[:18]), 1: _NamedModel(names[18:])}
    stats: dict = {}
    assert colmap._second_round(SfmConfig(), tmp_path / "db", tmp_path, tmp_path, names, whole, stats) is whole
    assert asked == [] and "retrieval_second_round" not in stats
    split = {0: _NamedModel(names[:12]), 1: _NamedModel(names[12:])}
    got = colmap._second_round(SfmConfig(), tmp_path / "db", tmp_path, tmp_path, names, split, stats)
    assert asked == [names[12:]] and got is again["m"]
    assert stats["retrieval_second_round"]["model_sizes_before"] == [12, 8]
    assert stats["retrieval_second_round"]["model_sizes_after"] == [19]
    again["m"] = {0: _NamedModel(names[:10])}                                 # mapped again, worse: the first is kept
    assert colmap._second_round(SfmConfig(), tmp_path / "db", tmp_path, tmp_path, names, split, {}) is split


# ------------------------------------------------------------------ the same input, the same model (issue 58)
FAST_TURN_FRAMES = range(40, 122, 3)
"""The fast-turn clip's frames of office.mp4 (docs/results.md#test-time: every second frame, 41, no longer split
without guided matching on 2026-11-30's build, so the clip is every third)."""


@pytest.fixture(scope="module")
def fast_turn_runs(tmp_path_factory):
    """28 frames of office.mp4 at a third of its frame rate (every third of frames 40-121), across a fast turn,
    mapped three times with the default options in fresh run folders (the last on one thread), then once without
    guided matching: (root, [Cameras], [stats], the run without guided matching's stats)."""
    from research.takes import _decode, write_video
    root = tmp_path_factory.mktemp("fast_turn")
    frames = _decode(need("office") / "office.mp4")
    write_video([frames[i] for i in FAST_TURN_FRAMES], root / "cap" / "walk.mp4")
    del frames
    cams, stats = [], []
    for k, threads in enumerate((-1, -1, 1)):
        run_sfm(SfmConfig(progress=False, num_threads=threads), root / "cap" / "walk.mp4", root / f"run{k}")
        cams.append(load_sfm(root / f"run{k}").cameras)
        stats.append(json.loads((root / f"run{k}" / "sfm" / "stage.json").read_text())["stats"])
    run_sfm(SfmConfig(progress=False, guided_matching="off"), root / "cap" / "walk.mp4", root / "unguided")
    return root, cams, stats, json.loads((root / "unguided" / "sfm" / "stage.json").read_text())["stats"]


@pytest.mark.slow
def test_a_video_that_turns_fast_stays_one_model_and_three_runs_give_the_same_model(fast_turn_runs):
    """Without guided matching the incremental mapper splits the fast turn's frames (15, 13 and 3 frames on
    2026-11-30) and keeps a part; with it (the default for a sequence of frames) it maps all 28 in one model, within
    a few degrees of the ground truth (1.3 deg median, 4.9 at worst, measured). Three runs, the last on one thread,
    register the same frames with the same poses: the capture's own visual words are seeded and the mappers run on
    one thread."""
    from curate.core.cameras import rotation_disagreement
    from research.datasets import load_office
    from research.takes import truth_of
    root, cams, stats, unguided = fast_turn_runs
    n = len(FAST_TURN_FRAMES)
    assert unguided["model_sizes"][0] < n - 5, unguided["model_sizes"]         # the clip is hard: it splits
    assert stats[0]["mapper"] == "incremental" and "mappers_tried" not in stats[0], stats[0].get("mappers_tried")
    assert stats[0]["model_sizes"] == [n] and len(cams[0]) == n
    recs = [r for r in json.loads((root / "run0" / "sfm" / "images.json").read_text())["photos"]
            if r["status"] == "kept"]
    of = truth_of(recs, {"videos": {"walk.mp4": list(FAST_TURN_FRAMES)}, "photos": {}})
    truth = load_office(need("office"))
    err = rotation_disagreement(truth.rotations[[of[nm] for nm in cams[0].names]], cams[0].rotations)
    assert float(np.median(err)) < 2.5 and float(err.max()) < 10, np.round(err, 1)   # one model, not bent at the turn
    for c in cams[1:]:
        assert_same_model(cams[0], c)


@pytest.mark.slow
def test_each_step_of_a_real_walk_is_checked_against_its_own_matches(fast_turn_runs):
    """Every step between consecutive frames of the fast turn's model fits the frames' own verified matches (the
    stage records 27 steps checked and none refuted); the same model with one frame tilted and rolled by 5 deg is
    refuted at that frame's two steps, and the warning names them (the blurred walk's wrong model, the cut's fold:
    docs/investigations/sfm.md#steps-their-matches-refute); the stage would leave that frame out."""
    from curate.sfm.continuity import unexplained_steps
    from curate.sfm.warn import step_warning
    from research.path_check import kept_records
    root, _, stats, _ = fast_turn_runs
    steps = len(FAST_TURN_FRAMES) - 1
    part = stats[0]["parts"][0]
    assert part["steps_checked"] == {"walk.mp4": steps} and "unexplained_steps" not in part, part
    assert step_warning(stats[0]) is None
    run = root / "run0"
    rec = pycolmap.Reconstruction(run / "sfm" / "sparse" / "0")
    kept = kept_records(run)
    assert unexplained_steps(rec, kept, run / "sfm" / "database.db") == {
        "walk.mp4": {"checked": steps, "unexplained": []}}
    by_name = sorted((im.name, im) for im in rec.images.values())
    name, im = by_name[20]
    # tilted and rolled by 5 deg: a pan alone would move the points along a sideways step's epipolar lines, unseen
    axis = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    turn = pycolmap.Rotation3d(np.r_[axis * np.sin(np.radians(2.5)), np.cos(np.radians(2.5))])
    pose = im.cam_from_world()
    rec.frame(im.frame_id).set_cam_from_world(im.camera_id, pycolmap.Rigid3d(turn * pose.rotation, pose.translation))
    bad = unexplained_steps(rec, kept, run / "sfm" / "database.db")["walk.mp4"]
    assert bad["checked"] == steps
    assert [(b["from"], b["to"]) for b in bad["unexplained"]] == [(by_name[19][0], name), (name, by_name[21][0])]
    assert all(b["fit"] < 0.5 and b["inliers"] >= 15 for b in bad["unexplained"])
    w = step_warning({"parts": [{**part, "unexplained_steps": {"walk.mp4": bad["unexplained"]}}]})
    assert w.startswith(f"video walk.mp4: 2 of {steps} steps between consecutive frames are not what the frames' "
                        "own "), w
    # the stage leaves that frame out (its two steps refuted, each neighbour's other step fitting), and the model
    # that is left has a step from frame 19 to 21 that fits
    from curate.sfm.continuity import drop_refuted
    assert drop_refuted({0: rec}, kept, run / "sfm" / "database.db") == {"walk.mp4": [name]}
    assert not rec.image(im.image_id).has_pose and rec.num_reg_images() == steps
    assert unexplained_steps(rec, kept, run / "sfm" / "database.db")["walk.mp4"]["unexplained"] == []


@pytest.mark.slow
def test_a_stretch_whose_frames_see_few_points_of_the_model_is_registered_not_split_off(tmp_path):
    """office.mp4's frames 150-199 at its full rate, across the fast turn where the whole walk split (12 frames,
    each seeing fewer than 30 of the model's points, never tried and left to a wrong part of their own): every frame
    in one incremental model, its orientations within a few degrees of the ground truth. Measured: 2.9 deg median,
    7.0 at worst, at the clip's end, with the packages setup.sh installed until 2026-11-28; 4.7 deg median and the
    clip's last four frames 11-20 deg off with those it installed on 2026-11-29 (av 18.1.0, pillow 13.0.0, numpy
    2.4.6, pycolmap 4.2.1), the same code (fc6bd94 gives the same figures): an open accuracy question of issue 58, so
    the bound is on the median and on all but the last four frames. Not those packages: with av 18.0.0 or pillow
    12.3.0 the clip is the same bytes and the figures the same, as with numpy 2.4.5; pycolmap 4.2.0 gives 4.1 deg
    median and the same 20 deg end, 4.1.1 and 4.0.4 split the clip (29 frames kept). The same matches mapped with
    COLMAP's 30 inliers split, so the clip still tests what it was cut for."""
    from curate.core.cameras import rotation_disagreement
    from curate.sfm import reconstruction
    from research.datasets import load_office
    from research.takes import _decode, truth_of, write_video
    frames = _decode(need("office") / "office.mp4")
    write_video(frames[150:200], tmp_path / "cap" / "walk.mp4")
    del frames
    run_sfm(SfmConfig(progress=False), tmp_path / "cap" / "walk.mp4", tmp_path / "run")
    stats = json.loads((tmp_path / "run" / "sfm" / "stage.json").read_text())["stats"]
    assert stats["mapper"] == "incremental" and "mappers_tried" not in stats, stats.get("mappers_tried")
    assert stats["model_sizes"] == [50]
    cams = load_sfm(tmp_path / "run").cameras
    recs = [r for r in json.loads((tmp_path / "run" / "sfm" / "images.json").read_text())["photos"]
            if r["status"] == "kept"]
    of = truth_of(recs, {"videos": {"walk.mp4": list(range(150, 200))}, "photos": {}})
    truth = load_office(need("office"))
    err = rotation_disagreement(truth.rotations[[of[n] for n in cams.names]], cams.rotations)
    assert len(err) == 50 and np.median(err) < 5 and np.sort(err)[-5] < 10, np.round(err, 1)
    sfm = tmp_path / "run" / "sfm"
    old = reconstruction.map_incremental(SfmConfig(progress=False, register_min_inliers=30), sfm / "database.db",
                                         sfm / "images", tmp_path / "at30", 50, progress=False)
    assert max(r.num_reg_images() for r in old.values()) < 50


@pytest.mark.parametrize("dis", [[14.0, None, 9.0], [3.5, None, None]])
def test_a_global_model_every_checked_part_refutes_is_not_kept(monkeypatch, tmp_path, dis):
    """office.mp4 with motion blur (research/flip.py): the incremental mapper split it into parts of 29 frames and
    fewer, the global mapper placed 233 frames that disagree with both parts it could be checked against (15 and
    38 deg); the frames no part covers passed their own check against the model's points, and the 50 kept lay
    141 deg from the truth (median). A global model every checked part refutes keeps nothing, its frames'
    own checks included: the incremental models stay."""
    from curate.sfm import reconstruction as sfm
    a, b, c = [f"a{i}" for i in range(5)], [f"b{i}" for i in range(3)], [f"c{i}" for i in range(2)]
    d = [f"d{i}" for i in range(8)]                   # frames of no part: without the rule they pass and stay
    monkeypatch.setattr(sfm, "map_incremental", lambda *a_, **k: {0: _Model(5, a), 1: _Model(3, b), 2: _Model(2, c)})
    monkeypatch.setattr(sfm, "map_global", lambda *a_, **k: {0: _Model(18, a + b + c + d)})
    monkeypatch.setattr(sfm, "part_agreement", lambda g, p: list(zip(dis, (set(a), set(b), set(c)))))
    calls = []
    _patch_verify(monkeypatch, lambda rec, names, deg, trusted=None: calls.append(names) or
                  {x: {"ok": True, "why": ""} for x in names})
    (tmp_path / "database.db").write_bytes(b"db")
    stats: dict = {}
    models = sfm.map_capture(small_cfg(), tmp_path / "database.db", tmp_path, tmp_path / "m", 18, stats)
    assert stats["mapper"] == "incremental" and sfm.model_sizes(models) == [5, 3, 2]
    assert stats["mappers_tried"]["global"]["refuted"] is True and not calls
