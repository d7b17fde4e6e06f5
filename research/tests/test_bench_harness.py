"""The selection-quality harness: pooling hold-out folds, the oracle subset, the synthetic room, hold-out holes."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

import numpy as np
import pytest



def load_script(name: str):
    """The module ``research.<name>``."""
    return importlib.import_module(f"research.{name}")


@pytest.fixture(scope="module")
def harness():
    return load_script("harness")


def _fold(rng, n_views: int, shift: float, n_random: int = 2, off=None):
    """(per_view, per_run, prox, n_hold, B, n_pool, off-path per_view) as run_fold returns it:
    'a' beats random by ``shift``."""
    rand_runs = [rng.normal(20, 1, n_views) for _ in range(n_random)]
    rand = np.mean(rand_runs, axis=0)
    a = rand + shift + rng.normal(0, 0.1, n_views)
    prox = {m: [{"pos": 1.0, "pos90": 2.0, "ang": 3.0, "ang90": 4.0, "cell": 0.5, "view": 1.5,
                 "view_per": rng.uniform(0, 1, n_views)} for _ in range(k)]
            for m, k in (("a", 1), ("random", n_random))}
    return {"a": a, "random": rand}, {"a": [a], "random": rand_runs}, prox, n_views, 7, 50, off


def test_folds_pool_every_view_once(harness, capsys):
    """The pooled table pairs the methods over the views of all folds: its PSNR is the mean
    of the concatenated views and its paired difference counts every fold's views."""
    rng = np.random.default_rng(0)
    folds = [_fold(rng, n, s) for n, s in ((10, 1.0), (9, 0.5), (10, 0.8))]
    args = argparse.Namespace(candidate="a")
    ev = argparse.Namespace(max_side=160, iters=600)
    default = argparse.Namespace(method="auto")
    h = harness.Bench(args, ev, ["a", "random"], default, {}, [], [], {})
    harness.report_folds(h, "fox", folds)
    rows = {r["method"]: r for r in h.rows}
    assert {r["scene"] for r in h.rows} == {"fox-folds"}
    want = np.concatenate([f[0]["a"] for f in folds]).mean()
    assert rows["a"]["psnr"] == pytest.approx(want, abs=1e-3)
    assert len(rows["random"]["runs"]) == 2          # run r of every fold make run r
    (pair,) = [p for p in h.paired if p["pair"] == "a-random"]
    assert pair["n"] == 29
    diffs = np.concatenate([f[0]["a"] - f[0]["random"] for f in folds])
    assert pair["mean"] == pytest.approx(diffs.mean(), abs=1e-3) and pair["lo"] > 0
    assert "3 folds pooled" in capsys.readouterr().out


def test_offpath_views_are_averaged_over_folds_then_paired(harness, capsys):
    """Every fold scores the same off-path views: each view's PSNR is averaged over the folds,
    and the methods are paired over the views (n = views, not views x folds)."""
    rng = np.random.default_rng(2)
    offs = [{"a": rng.normal(22, 1, 6) + 0.3, "random": rng.normal(22, 1, 6)} for _ in range(3)]
    folds = [_fold(rng, 10, 1.0, off=o) for o in offs]
    h = harness.Bench(argparse.Namespace(candidate="a"), argparse.Namespace(max_side=160, iters=600),
                      ["a", "random"], argparse.Namespace(method="auto"), {}, [], [], {})
    harness.report_folds(h, "room", folds)
    rows = {(r["scene"], r["method"]): r for r in h.rows}
    assert rows[("room-offpath-folds", "a")]["psnr"] == pytest.approx(np.mean([o["a"] for o in offs]), abs=1e-3)
    (pair,) = [p for p in h.paired if p["scene"] == "room-offpath-folds" and p["pair"] == "a-random"]
    per_view = np.mean([o["a"] - o["random"] for o in offs], axis=0)
    assert pair["n"] == 6 and pair["mean"] == pytest.approx(per_view.mean(), abs=1e-3)
    assert "3 folds averaged per off-path view" in capsys.readouterr().out
    harness.report_folds(h, "room", folds[:2] + [_fold(rng, 10, 1.0)])   # a fold without off-path views
    assert sum(r["scene"] == "room-offpath-folds" for r in h.rows) == 2       # no second off-path table


def test_folds_drop_a_method_missing_from_a_fold(harness):
    rng = np.random.default_rng(1)
    folds = [_fold(rng, 8, 1.0), _fold(rng, 8, 1.0)]
    del folds[1][0]["a"], folds[1][1]["a"]
    h = harness.Bench(argparse.Namespace(candidate="a"), argparse.Namespace(max_side=160, iters=600),
                      ["a", "random"], argparse.Namespace(method="auto"), {}, [], [], {})
    harness.report_folds(h, "skull", folds)
    assert [r["method"] for r in h.rows] == ["random"] and not h.paired


def test_oracle_takes_each_held_out_views_nearest_first(harness):
    """Round robin: every held-out view gets its nearest pool view before any gets a second;
    no view twice; a budget above the pool takes the pool."""
    d = np.array([[0.1, 0.2, 5.0, 6.0, 7.0],
                  [0.3, 9.0, 0.2, 0.4, 8.0]])        # [H=2, K=5]
    assert harness.oracle_subset(d, 2) == [0, 2]
    assert harness.oracle_subset(d, 4) == [0, 2, 1, 3]
    assert sorted(harness.oracle_subset(d, 50)) == [0, 1, 2, 3, 4]
    assert harness.oracle_subset(d[:0], 3) == []


@pytest.mark.slow
def test_room_scene_has_a_walk_and_free_space_test_views(harness, tmp_path, monkeypatch):
    """The synthetic room (small here): a walk with its photos, and off-path test views in
    free space, rendered once; real scenes have no off-path views."""
    from curate.simulate.progressive import scene_oracle
    from curate.simulate.synthetic import make_scene
    from curate.core.transforms_json import read_transforms
    monkeypatch.setattr(harness, "ROOM_WALK", (12, 6))
    monkeypatch.setattr(harness, "ROOM_OFFPATH", 5)
    tj = harness.scene_poses("room", tmp_path)      # rendered where offpath_views looks
    walk, walk_paths = read_transforms(tj)
    off, off_paths = harness.offpath_views("room", tmp_path, None)
    assert len(walk) == 18 and len(off) == 5
    assert all(Path(p).is_file() for p in list(walk_paths) + list(off_paths))
    occupied, min_depth = scene_oracle(make_scene("livingroom", seed=0))
    assert not np.any(occupied(off.centres)) and np.all(min_depth(off) >= 0.3)
    stamp = tj.stat().st_mtime_ns
    assert harness.scene_poses("room", tmp_path) == tj and tj.stat().st_mtime_ns == stamp    # not rendered again
    assert harness.offpath_views("fox", tmp_path, None) is None


def test_beside_holes_marks_the_neighbours_of_held_out_frames():
    """research/holdout_holes.py: a pool frame is beside a hole when frame i - 1 or i + 1 is held out."""
    mod = load_script("holdout_holes")
    from curate.core.stats import holdout_split
    pool, hold = holdout_split(30, 7, 2)                       # held out: 2, 9, 16, 23
    got = pool[mod.beside_holes(pool, hold)]
    assert got.tolist() == [1, 3, 8, 10, 15, 17, 22, 24]
    pool, hold = holdout_split(30, 7, 0)                       # frame 0 held out: only frame 1 beside it
    assert pool[mod.beside_holes(pool, hold)].tolist() == [1, 6, 8, 13, 15, 20, 22, 27, 29]
    assert not mod.beside_holes(np.arange(5), np.zeros(0, int)).any()


def test_stale_units_are_those_holding_another_subset_under_the_same_name(harness, tmp_path):
    """A harness re-run must not silently retrain over an earlier result: a unit folder whose
    finished record has another key (e.g. a method whose default changed) is reported; the same
    key, no folder, or a half-written one (no record) is not."""
    import time
    from curate.core.stage import finish_stage
    ev = tmp_path / "evaluate"
    finish_stage(ev / "q_medoids_b59_t0", "k-old", {}, time.perf_counter())
    finish_stage(ev / "q_stride_b59_t0", "k-same", {}, time.perf_counter())
    (ev / "q_fvs_b59_t0").mkdir(parents=True)                 # a training that died before its record
    keys = {"q_medoids_b59_t0": "k-new", "q_stride_b59_t0": "k-same", "q_fvs_b59_t0": "k-fvs",
            "q_random_s0_b59_t0": "k-r"}
    assert harness.stale_units(tmp_path, keys) == ["q_medoids_b59_t0"]
    assert harness.stale_units(tmp_path, {"q_stride_b59_t0": "k-same"}) == []


def test_default_label_follows_autos_rule(harness, monkeypatch):
    """The default's unit folders are named by its config and by auto's rule by kind of
    capture: a changed rule (e.g. objects: FVS -> energy) must not reuse the old folders,
    while a method other than auto does not depend on the rule."""
    from curate.select import methods
    from curate.select.config import SelectConfig
    rule, tag = harness.default_label(SelectConfig())
    assert f"object={methods.OBJECT_METHOD}" in rule and f"walk={methods.WALK_METHOD}" in rule
    assert harness.default_label(SelectConfig()) == (rule, tag)        # stable across calls
    fixed = harness.default_label(SelectConfig(method="fvs"))
    monkeypatch.setattr(methods, "OBJECT_METHOD", "fvs")
    rule2, tag2 = harness.default_label(SelectConfig())
    assert "object=fvs" in rule2 and tag2 != tag
    assert harness.default_label(SelectConfig(method="fvs")) == fixed == ("", fixed[1])


def test_random_draws_differ_between_folds(harness):
    """The folds' pools differ by a shift of one image, so one seed in every fold picks nearly
    the same cameras; the random mean over folds must average independent draws: each fold
    > 0 draws with its own seeds (fold 0 keeps seeds 0, 1, ...), in its own unit folders,
    unless --shared-seeds asks for the old draws (the figures measured with them)."""
    from curate.select.baselines import random_subset
    from curate.core.stats import holdout_split
    n, every, B = 373, 14, 59

    def cams(fold, draw, shared):
        pool, _ = holdout_split(n, every, fold)
        return set(pool[random_subset(len(pool), B, harness.random_seed(fold, draw, shared))].tolist())

    def near(x, y):          # share of x's cameras with y's camera at most one image away
        return np.mean([any(abs(i - j) <= 1 for j in y) for i in x])

    assert [harness.random_seed(0, d) for d in range(3)] == [0, 1, 2]
    seeds = {harness.random_seed(f, d) for f in range(every) for d in range(3)}
    assert len(seeds) == 3 * every                               # every (fold, draw) its own seed
    assert near(cams(1, 0, True), cams(2, 0, True)) > 0.9        # the old draws repeat across folds
    assert near(cams(1, 0, False), cams(2, 0, False)) < 0.6      # per-fold draws do not
    h = argparse.Namespace(args=argparse.Namespace(shared_seeds=False), label={"default": "default-x"})
    assert harness.unit_label(h, "random", 0) == "random"        # fold 0: the same units as before
    assert harness.unit_label(h, "random", 3) == "randomf"
    assert harness.unit_label(h, "default", 3) == "default-x"
    h.args.shared_seeds = True
    assert harness.unit_label(h, "random", 3) == "random"


def test_centred_r2_ignores_what_makes_a_view_hard():
    """research/view_distance_fit.py: r^2 is taken within each held-out view (PSNR and the
    feature centred per view), so a view's own difficulty does not count as explained."""
    mod = load_script("view_distance_fit")
    rng = np.random.default_rng(0)
    d = [rng.uniform(0, 1, 5) for _ in range(20)]                 # 20 views, 5 subsets each
    hard = rng.normal(0, 10, 20)                                  # per-view offsets, far larger
    exact = [(h - 2 * x, x) for h, x in zip(hard, d)]
    assert mod.centred_r2(exact) == pytest.approx(1.0)
    # a feature that only tracks the views' difficulty explains nothing within a view
    assert mod.centred_r2([(h + rng.normal(0, 1, 5), np.full(5, h)) for h in hard]) == pytest.approx(0.0, abs=1e-9)
    noisy = [(h - 2 * x + rng.normal(0, 0.3, 5), x) for h, x in zip(hard, d)]
    assert 0.5 < mod.centred_r2(noisy) < 1.0
    # one feature: the squared correlation of the centred values
    y = np.concatenate([p - p.mean() for p, _ in noisy]); x = np.concatenate([f - f.mean() for _, f in noisy])
    assert mod.centred_r2(noisy) == pytest.approx((x @ y) ** 2 / ((x @ x) * (y @ y)))


def test_centred_r2_with_two_features_and_the_second_nearest_view():
    """view_distance_fit's "d, d2" row: PSNR fitted on the nearest and second-nearest chosen
    view together explains what the nearest alone cannot, and never less than it."""
    mod = load_script("view_distance_fit")
    rng = np.random.default_rng(1)
    d1 = [rng.uniform(0, 1, 6) for _ in range(30)]
    d2 = [a + rng.uniform(0, 1, 6) for a in d1]
    hard = rng.normal(0, 10, 30)
    both = [(h - 2 * a - 0.5 * b, np.stack([a, b], 1)) for h, a, b in zip(hard, d1, d2)]
    assert mod.centred_r2(both) == pytest.approx(1.0)
    one = mod.centred_r2([(p, f[:, 0]) for p, f in both])
    assert 0.5 < one < 1.0 - 1e-6
    junk = [(p, np.stack([f[:, 0], rng.normal(size=6)], 1)) for p, f in both]
    assert one - 1e-12 <= mod.centred_r2(junk) <= 1.0
    assert mod.centred_r2([(np.full(6, 3.0), f) for _, f in both]) == 0.0   # PSNR constant within views
    np.testing.assert_array_equal(mod.nearest_two(np.array([[3.0, 1.0, 2.0]])), [1.0, 2.0])
    np.testing.assert_array_equal(mod.nearest_two(np.array([[0.5]])), [0.5, 0.5])


def test_unit_keys_round_trip(harness):
    """Scripts that read a harness run back (view_distance_fit) parse its unit folder names
    with UNIT_KEY: every name unit_key writes must parse back to what it was made of, also
    for labels holding underscores, digits and the default's hash."""
    cases = [("medoids_path", 59, 0, 0, None), ("medoids_p025_plain", 104, 1, 13, None),
             ("randomf", 59, 0, 7, 1), ("random", 6, 0, 0, 0), ("default-0f0613", 35, 2, 3, None),
             ("fvs_rot1", 10, 0, 1, None)]
    for label, b, t, fold, draw in cases:
        key = harness.unit_key(label, b, t, fold, draw)
        m = harness.UNIT_KEY.match(key)
        assert m is not None, key
        assert (m["label"], int(m["budget"]), int(m["seed"]), int(m["fold"] or 0)) == (label, b, t, fold)
        assert (None if m["draw"] is None else int(m["draw"])) == draw
    assert harness.unit_key("random", 59, 0, 0, 1) == "q_random_s1_b59_t0"     # fold 0: the old names
    assert harness.UNIT_KEY.match("all_o3") is None                             # the pool field is no unit
    # reading back: a method takes its own units only (any draw and seed), not a variant's or another fold's
    assert harness.is_unit("q_medoids_b59_t1_o2", "medoids", 59, 2)
    assert harness.is_unit("q_randomf_s1_b59_t0_o2", "randomf", 59, 2)
    assert not harness.is_unit("q_medoids_p2_b59_t0_o2", "medoids", 59, 2)
    assert not harness.is_unit("q_medoids_b59_t0", "medoids", 59, 2)
    assert not harness.is_unit("q_medoids_b35_t0_o2", "medoids", 59, 2)


def test_error_weights_degenerate_and_monotone():
    """research/field_weighted_medoids.py: beta 0 leaves the path weights; a perfectly rendered
    view (MSE 0) or no reference view gives finite weights, never NaN; views near harder
    reference views weigh more for beta > 0 and less for beta < 0."""
    mod = load_script("field_weighted_medoids")
    rng = np.random.default_rng(1)
    base = rng.uniform(0.5, 1.5, 8)
    D = rng.uniform(0, 1, (8, 5))
    err = np.array([0.0, 1e-3, 1e-2, 2e-2, 5e-2])                   # one reference view rendered exactly
    assert np.allclose(mod.error_weights(D, err, base, 0.0, 3), base)
    for beta in (-1.0, 1.0, 2.0):
        w = mod.error_weights(D, err, base, beta, 3)
        assert np.all(np.isfinite(w)) and np.all(w > 0)
    assert np.allclose(mod.error_weights(np.zeros((8, 0)), err[:0], base, 1.0, 3), base)
    # two views, each next to one reference view (k = 1): the harder neighbour weighs more
    D2 = np.array([[0.1, 5.0], [5.0, 0.1]])
    up = mod.error_weights(D2, np.array([1e-3, 1e-2]), np.ones(2), 1.0, 1)
    down = mod.error_weights(D2, np.array([1e-3, 1e-2]), np.ones(2), -1.0, 1)
    assert up[1] > up[0] and down[1] < down[0]
    assert np.allclose(mod.error_weights(D2, np.array([1e-3, 1e-2]), np.ones(2), 1.0, 99),
                       np.ones(2))                                    # k capped: both see both -> equal


def test_holdout_blocks_hold_out_contiguous_blocks_away_from_the_pool(harness):
    """--holdout-blocks N:L:G: N blocks of L consecutive frames held out, none of the G frames
    each side in the pool, the rest in it; the folds hold out different frames; a fold that
    does not fit is refused."""
    n = 100
    pool, hold = harness.holdout_blocks(n, 4, 5, 3, fold=0)
    assert len(hold) == 20 and len(set(hold.tolist()) & set(pool.tolist())) == 0
    runs = np.split(hold, np.flatnonzero(np.diff(hold) > 1) + 1)
    assert [len(r) for r in runs] == [5, 5, 5, 5]
    dist = np.abs(pool[:, None] - hold[None, :]).min(1)
    assert dist.min() == 4                                       # G + 1 frames to the nearest held-out one
    assert len(pool) == n - 20 - 4 * 2 * 3
    _, hold1 = harness.holdout_blocks(n, 4, 5, 3, fold=1)
    assert not set(hold1.tolist()) & set(hold.tolist())
    assert hold1.max() < n
    with pytest.raises(ValueError, match="fold"):
        harness.holdout_blocks(n, 4, 5, 3, fold=4)               # a 25-frame stretch fits 3 blocks of 5 + 2 x 3
    assert harness.parse_blocks("") is None and harness.parse_blocks("6:4:3") == (6, 4, 3)
    with pytest.raises(SystemExit, match="N:L:G"):
        harness.parse_blocks("6:4")


def test_psnr_plot_is_written_for_every_scene(harness, tmp_path):
    """The harness ends by drawing PSNR against budget (it crashed there on a moved import)."""
    series = {"walk-loop": {"default": [(42, 24.1), (21, 22.0)], "random": [(21, 21.5), (42, 23.2)]},
              "walk-turn": {"default": [(42, 23.0)]}}
    p = harness.write_psnr_plot(series, tmp_path)
    svg = p.read_text()
    assert p.parent == tmp_path and svg.startswith("<svg")
    assert "walk-loop: held-out PSNR" in svg and "walk-turn: held-out PSNR" in svg
    many = {f"walk-two_sessions-kitchen-offpath-{i}": {"default": [(42, 20.0 + i)]} for i in range(16)}
    assert harness.write_psnr_plot(many, tmp_path).is_file()          # a name the file system takes


def test_walk_spec_parses_kinds_and_rooms(harness):
    """walk-<kind>[-<room>][-s<seed>]: the fast loop with blur and its control without; another
    trajectory of a kind by its seed (default WALK_SEED, what every earlier figure used)."""
    assert harness.walk_spec("walk-blur") == ("blur", "livingroom", True, harness.WALK_SEED)
    assert harness.walk_spec("walk-fast-kitchen") == ("fast", "kitchen", False, 1)
    assert harness.walk_spec("walk-turn") == ("turn", "livingroom", False, 1)
    assert harness.walk_spec("walk-loop-office-s2") == ("loop", "office", False, 2)
    assert harness.walk_spec("walk-linger-s7") == ("linger", "livingroom", False, 7)
    assert harness.walk_spec("office") is None
    for bad in ("walk-jog", "walk-loop-garage", "walk-loop-kitchen-x", "walk-loop-kitchen-s2-s3", "walk-s2"):
        with pytest.raises(SystemExit, match="unknown walk scene"):
            harness.walk_spec(bad)


def test_variant_names_read_back_as_their_own_units(harness):
    """A variant's unit folders must parse back to that variant: a name ending in _s<digits>
    would read as a random draw of another method (and its PSNR would be lost)."""
    for name in harness._variants():
        key = harness.unit_key(name, 42, 0, 0)
        assert harness.is_unit(key, name, 42, 0), name
    assert not harness.is_unit(harness.unit_key("medoids_s50", 42, 0, 0), "medoids_s50", 42, 0)
