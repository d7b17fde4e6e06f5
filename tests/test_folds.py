"""The evaluation over hold-out folds: the pooled interval, what it decides, the fold order and the schedule that
adds folds until decided or out of time (issue 48)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from curate.core.stats import decision, folds_paired, mean_ci
from curate.evaluate.config import EvalConfig
from curate.evaluate.folds import LOOKS, Fold, decided, fold_order, look_level, looks, planned_folds
from curate.evaluate.units import Unit


# ------------------------------------------------------------------ the pooled interval
def test_one_fold_gives_the_per_view_interval():
    x = np.array([0.5, 1.2, -0.3, 0.8, 2.0])
    p, q = folds_paired([x]), mean_ci(x)
    assert p["n_folds"] == 1 and p["n"] == 5
    assert (p["mean"], p["lo"], p["hi"]) == pytest.approx((q["mean"], q["lo"], q["hi"]))


def test_a_fold_effect_widens_the_interval_beyond_the_views_alone():
    rng = np.random.default_rng(0)
    folds = [rng.normal(0, 1, 30) + off for off in (2.0, -2.0, 1.5, -1.5, 0.0)]   # folds far apart
    p, flat = folds_paired(folds), mean_ci(np.concatenate(folds))
    assert p["n_folds"] == 5 and p["dof"] == 4 and p["n"] == 150
    assert p["mean"] == pytest.approx(flat["mean"])
    assert p["hi"] - p["lo"] > 3 * (flat["hi"] - flat["lo"])


def test_folds_without_a_fold_effect_give_about_the_per_view_width():
    rng = np.random.default_rng(1)
    folds = [rng.normal(0.4, 2.0, 40) for _ in range(14)]
    p, flat = folds_paired(folds), mean_ci(np.concatenate(folds))
    assert 0.7 < (p["hi"] - p["lo"]) / (flat["hi"] - flat["lo"]) < 1.5


def test_degenerate_differences_give_finite_intervals_never_nan():
    same = folds_paired([np.zeros(4), np.zeros(3)])                  # every view identical: zero width
    assert same["lo"] == same["hi"] == same["mean"] == 0.0
    assert decision(same, 0.3) == "level"
    p = folds_paired([np.array([np.nan, 1.0]), np.array([]), np.array([2.0, np.inf, 3.0])])
    assert p["n_folds"] == 2 and p["n"] == 3 and all(math.isfinite(p[k]) for k in ("mean", "lo", "hi"))
    empty = folds_paired([])
    assert empty["n"] == 0 and decision(empty, 0.3) == "undecided"
    one = folds_paired([np.array([1.0])])
    assert one["lo"] == -math.inf and decision(one, 0.3) == "undecided"


def test_decision_reads_the_interval_against_zero_and_the_margin():
    assert decision({"lo": 0.1, "hi": 0.9}, 0.3) == "ahead"
    assert decision({"lo": -0.9, "hi": -0.01}, 0.3) == "behind"
    assert decision({"lo": -0.2, "hi": 0.25}, 0.3) == "level"
    assert decision({"lo": -0.2, "hi": 0.35}, 0.3) == "undecided"
    assert decision({"lo": -math.inf, "hi": math.inf}, 0.3) == "undecided"
    assert decision(None, 0.3) is None
    assert decided({"a": {"decision": "ahead"}, "b": {"decision": "level"}})
    assert not decided({"a": {"decision": "ahead"}, "b": {"decision": "undecided"}}) and not decided({})


def test_stopping_at_a_decided_look_keeps_the_error_near_five_percent():
    """No true difference, a fold effect and wide per-view noise: a procedure that looks after the first folds
    and at the end, and stops at the first look where the interval excludes 0, must call a difference in
    about 5% of captures, not the ~10% a plain 95% interval at each look gives."""
    rng = np.random.default_rng(7)
    M, n_views, reps = 14, 21, 1500
    at = looks(M, adaptive=True)
    assert at == [4, 14] and len(at) == LOOKS
    wrong = plain = 0
    for _ in range(reps):
        folds = [rng.normal(0, 0.3) + rng.normal(0, 4.2, n_views) for _ in range(M)]
        called = [decision(folds_paired(folds[:k], look_level(True)), 0.3) in ("ahead", "behind") for k in at]
        called95 = [decision(folds_paired(folds[:k], 0.95), 0.3) in ("ahead", "behind") for k in at]
        wrong += any(called)
        plain += any(called95)
    assert wrong / reps < 0.07
    assert plain / reps > wrong / reps


# ------------------------------------------------------------------ the fold plan
def test_folds_are_spread_over_the_capture_and_cover_every_offset():
    o = fold_order(14)
    assert sorted(o) == list(range(14)) and o[:4] == [0, 7, 3, 10]
    for n in (1, 2, 5, 8):
        assert sorted(fold_order(n)) == list(range(n))
    assert fold_order(0) == []


def test_a_small_capture_plans_no_fold_that_holds_out_nothing():
    assert planned_folds(EvalConfig(), 300) == 14
    assert planned_folds(EvalConfig(), 9) == 9
    assert planned_folds(EvalConfig(folds=3), 300) == 3
    assert planned_folds(EvalConfig(folds=20), 300) == 14
    assert looks(14, adaptive=False) == [14] and look_level(False) == 0.95
    assert looks(2, adaptive=True) == [2] and looks(5, adaptive=True) == [4, 5]
    assert look_level(True, 14) == 1 - 0.05 / LOOKS and look_level(True, 3) == 0.95   # one look: 95%
    for n in range(1, 15):   # fewer photos than --holdout-every: only offsets that hold out a photo, in order
        o = fold_order(14, n)
        assert sorted(o) == list(range(n)) and o == [x for x in fold_order(14) if x < n]
        assert len(o) == planned_folds(EvalConfig(), n)


def test_one_held_out_view_gives_no_infinite_figure():
    """One fold of one held-out view: its interval is infinite; summary.json gets None, never Infinity."""
    import json
    from curate.evaluate.folds import summarize
    from curate.evaluate.units import Unit
    units = [Unit(f"f00_{m}", m, None, [1, 2], 0) for m in ("selection", "random", "all")]
    fold = Fold(0, [0], [1, 2], 2, "path", [1, 2], units)
    res = {f"f00_{m}": {"n_train": 2, "psnr": v, "per_view": [{"name": "a.jpg", "psnr": v, "ssim": 0.5}]}
           for m, v in (("selection", 21.0), ("random", 20.0), ("all", 22.0))}
    methods, paired, gap = summarize(res, [fold], 0.95, 0.3)
    p = paired["selection-random"]
    assert p["mean"] == 1.0 and p["lo"] is None and p["hi"] is None and p["decision"] == "undecided"
    json.dumps(paired, allow_nan=False)
    assert gap == 0.5


@pytest.mark.parametrize("bad", [{"folds": -1}, {"minutes": 0}, {"minutes": float("nan")}, {"margin_db": -0.1},
                                 {"methods": ("selection", "oracle")}, {"folds": 1.5}])
def test_bad_evaluation_options_are_refused(bad):
    with pytest.raises(ValueError):
        EvalConfig(**bad)


# ------------------------------------------------------------------ the schedule
class _Cams:
    """Just what the schedule reads of the cameras: names and sizes."""

    def __init__(self, n):
        self.names = [f"{i:03d}.png" for i in range(n)]
        self.width = np.full(n, 8)
        self.height = np.full(n, 6)


def _run(tmp_path, offsets, effect, cfg, look_at, adaptive, per_unit_s=0.0, seed=0):
    """Run the schedule over fake folds whose trainings score the selection ``effect[offset]`` dB above its
    rivals on every held-out photo (plus noise), without training anything."""
    import time
    from PIL import Image
    from curate.evaluate import schedule
    from curate.evaluate.folds import summarize
    n = 70
    cams = _Cams(n)
    paths = []
    for i in range(n):
        p = tmp_path / "img" / cams.names[i]
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (8, 6), (i, 0, 0)).save(p)
        paths.append(str(p))
    rng = np.random.default_rng(seed)
    made = []

    def make_fold(o):
        hold = list(range(o, n, 14))
        pool = [i for i in range(n) if i % 14 != o]
        us = [Unit(f"f{o:02d}_{m}", m, None, pool[:5] if m != "all" else pool, o)
              for m in ("selection", "random", "fvs")]
        us[2].subset = pool[:5]                     # fvs chose exactly the selection's subset: trained once
        made.append(o)
        return Fold(o, hold, pool, 5, "path", pool[:5], us)

    trained = []

    def train(args):
        _, u, *_ = args
        time.sleep(per_unit_s)
        trained.append(u.key)
        hold = list(range(u.fold, n, 14))
        base = 20 + (effect.get(u.fold, 0.0) if u.method == "selection" else 0.0)
        pv = [{"name": cams.names[c], "psnr": base + float(rng.normal(0, 0.05)), "ssim": 0.5} for c in hold]
        m = {"method": u.method, "seed": u.seed, "subset": u.subset, "n_train": len(u.subset),
             "psnr": float(np.mean([v["psnr"] for v in pv])), "ssim": 0.5, "per_view": pv}
        d = tmp_path / "evaluate" / u.key           # what a training leaves: its record and metrics
        d.mkdir(parents=True, exist_ok=True)
        (d / "metrics.json").write_text(json.dumps(m))
        (d / "stage.json").write_text(json.dumps({"key": key(u, None)}))
        return m

    def stop_at(folds, res):
        return decided(summarize(res, folds, 0.975, 0.3)[1])

    def key(u, f):
        return u.key if u.method != "fvs" else f"f{u.fold:02d}_selection"

    folds, res, why = schedule.run_folds(tmp_path, cfg, make_fold, offsets, look_at, stop_at, cams, paths, None,
                                         key, adaptive, progress=False, train=train)
    return folds, res, why, made, trained


def test_folds_stop_at_the_first_look_that_decides(tmp_path):
    cfg = EvalConfig(workers=1)
    order = fold_order(14)
    folds, res, why, made, trained = _run(tmp_path, order, {o: 1.0 for o in order}, cfg, [4, 14], True)
    assert why == "decided" and [f.offset for f in folds] == order[:4]
    assert len(made) <= 5                       # at most the fold in hand when the look decided
    assert not any(k.endswith("_fvs") for k in trained)       # the duplicate subset trained once, copied
    assert all(f"f{o:02d}_fvs" in res for o in order[:4])


def test_undecided_folds_run_to_the_end(tmp_path):
    cfg = EvalConfig(workers=1)
    order = fold_order(14)
    effect = {o: (1.0 if i % 2 else -1.0) for i, o in enumerate(order)}   # the folds disagree
    folds, res, why, made, trained = _run(tmp_path, order, effect, cfg, [4, 14], True)
    assert why == "all folds" and len(folds) == 14


def test_no_fold_is_started_past_the_time_given_but_the_first_two_always_run(tmp_path):
    cfg = EvalConfig(workers=1, minutes=0.5 / 60)          # half a second
    order = fold_order(14)
    effect = {o: (1.0 if i % 2 else -1.0) for i, o in enumerate(order)}
    folds, res, why, made, trained = _run(tmp_path, order, effect, cfg, [4, 14], True, per_unit_s=0.1)
    assert why == "time" and 2 <= len(folds) < 14
    # a fixed number of folds ignores the time
    folds, *_ = _run(tmp_path / "b", order[:4], effect, replace(cfg, folds=4), [4], False, per_unit_s=0.05)
    assert len(folds) == 4
