"""The evaluation over hold-out folds: the pooled interval, what it decides, the fold order and the schedule that
adds folds until decided or out of time (issue 48)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from curate.core.stats import decision, folds_moderated, folds_paired, mean_ci, t_quantile
from curate.evaluate.config import EvalConfig
from curate.evaluate.folds import (KAPPA_PRIOR, LOOKS, Fold, decided, fold_order, look_level, looks,
                                   planned_folds)
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


def test_an_interval_measured_closely_enough_is_resolved_and_stops_its_rival():
    """--resolution-db: an interval that holds 0 but is at most that wide on each side is 'resolved' (its rival is
    trained no more); ahead, behind and level come first; 0 turns it off."""
    from curate.core.stats import DECIDED
    assert decision({"lo": -0.2, "hi": 0.7}, 0.3, 0.5) == "resolved"          # half-width 0.45
    assert decision({"lo": -0.2, "hi": 0.7}, 0.3, 0.0) == "undecided"
    assert decision({"lo": -0.2, "hi": 0.9}, 0.3, 0.5) == "undecided"         # half-width 0.55
    assert decision({"lo": 0.01, "hi": 0.2}, 0.3, 0.5) == "ahead"
    assert decision({"lo": -0.1, "hi": 0.2}, 0.3, 0.5) == "level"
    assert decision({"lo": -math.inf, "hi": math.inf}, 0.3, 0.5) == "undecided"
    assert "resolved" in DECIDED and "undecided" not in DECIDED
    assert decided({"a": {"decision": "resolved"}, "b": {"decision": "level"}})
    assert EvalConfig().resolution_db == 0.5 and EvalConfig(resolution_db=0).resolution_db == 0
    assert decided({"a": {"decision": "ahead"}, "b": {"decision": "level"}})
    assert not decided({"a": {"decision": "ahead"}, "b": {"decision": "undecided"}}) and not decided({})


def _null_capture(rng, photos, sigma, smooth, rho, tau):
    """Per fold (in the evaluation's order) the per-view differences of a capture where nothing differs: a part
    smooth along the capture (neighbouring photos fall in different folds), an independent part per photo, a
    fold effect (a training's luck, a random draw), centred on the capture's mean."""
    from scipy.signal import lfilter
    w = rng.normal(0, smooth, photos + 300)
    x = rng.normal(0, sigma, photos) + (lfilter([math.sqrt(1 - rho * rho)], [1, -rho], w)[300:] if rho else w[300:])
    folds = [x[o::14] + rng.normal(0, tau) for o in fold_order(14, photos)]
    m = float(np.concatenate(folds).mean())
    return [f - m for f in folds]


def _procedure(diffs, time_folds):
    """The evaluation's looks of one rival (curate.evaluate.stage.Planner): after FIRST_LOOK folds; undecided, at
    the folds the projection says decide it, if the time holds them; undecided there, once more at the folds the
    projection then says (or the end of the time)."""
    from curate.evaluate.folds import FIRST_LOOK, KAPPA_PRIOR, next_look
    level = look_level(True)
    F_max = min(len(diffs), time_folds)
    F, n_looks = min(FIRST_LOOK, F_max), 0
    while True:
        p = folds_moderated(diffs[:F], level, *KAPPA_PRIOR)
        n_looks += 1
        d = decision(p, 0.3, EvalConfig().resolution_db)
        if d != "undecided" or F >= F_max or n_looks >= LOOKS:
            return d
        g = next_look(p, 0.3, len(diffs), EvalConfig().resolution_db, last=n_looks == LOOKS - 1)
        if g is None or g > F_max:
            return d
        F = g


@pytest.mark.parametrize("sigma,smooth,rho,tau", [(2.8, 0.0, 0.0, 0.6), (1.5, 2.5, 0.9, 0.3)])
def test_the_looks_call_a_difference_that_is_not_there_in_under_five_percent(sigma, smooth, rho, tau):
    """Nothing differs; per-view noise as wide as on real walks (sd 2-3 dB), a fold effect larger than measured
    on real captures: the evaluation's procedure (three looks at most, the prior's interval, the plan between)
    calls a difference in under 5% of captures (docs/evaluation.md, "Intervals from two folds"; the full table:
    research/null_sim.py)."""
    rng = np.random.default_rng(7)
    reps = 600
    called = sum(_procedure(_null_capture(rng, 373, sigma, smooth, rho, tau), 8) in ("ahead", "behind")
                 for _ in range(reps))
    assert called / reps < 0.05


def test_folds_moderated_is_the_folds_alone_without_a_prior_and_the_prior_alone_with_a_sure_one():
    rng = np.random.default_rng(3)
    folds = [rng.normal(0.3, 2.0, 20) + rng.normal(0, 0.4) for _ in range(5)]
    old, new = folds_paired(folds, 0.95), folds_moderated(folds, 0.95, kappa0=1.0, nu0=0.0)
    assert (new["lo"], new["hi"], new["dof"]) == pytest.approx((old["lo"], old["hi"], old["dof"]))
    sure = folds_moderated(folds, 0.95, kappa0=2.0, nu0=1e9)
    sw = sure["sd_within"]
    half = t_quantile(0.975, 100 - 5) * math.sqrt(2.0 * sw * sw / 100)
    assert sure["hi"] - sure["mean"] == pytest.approx(half, rel=1e-3)
    assert sure["kappa"] == pytest.approx(2.0, rel=1e-6)


def test_two_folds_give_an_interval_a_user_can_act_on():
    """Two folds of 27 views each (a 373-photo walk), per-view sd 2 dB (1.5-2.4 on the real walks), fold means
    +1.3 and +0.7 dB: the folds alone (t on one degree of freedom) cannot decide; with the prior the interval
    excludes 0."""
    def fold(mean, seed):
        z = np.random.default_rng(seed).normal(size=27)
        return mean + 2.0 * (z - z.mean()) / z.std(ddof=1)
    folds = [fold(1.3, 1), fold(0.7, 2)]
    old = folds_paired(folds, look_level(True))
    new = folds_moderated(folds, look_level(True), *KAPPA_PRIOR)
    assert decision(old, 0.3) == "undecided" and decision(new, 0.3) == "ahead"
    assert new["mean"] == pytest.approx(1.0) and new["hi"] - new["lo"] < (old["hi"] - old["lo"]) / 5


def test_degenerate_differences_give_finite_moderated_intervals_never_nan():
    same = folds_moderated([np.zeros(4), np.zeros(3)], 0.975, *KAPPA_PRIOR)
    assert same["lo"] == same["hi"] == same["mean"] == 0.0 and decision(same, 0.3) == "level"
    const = folds_moderated([np.ones(3), np.zeros(4)], 0.975, *KAPPA_PRIOR)        # no spread within folds
    assert all(math.isfinite(const[k]) for k in ("mean", "lo", "hi")) and const["lo"] < const["mean"] < const["hi"]
    one_fold = folds_moderated([np.array([0.5, 1.5, 1.0])], 0.975, *KAPPA_PRIOR)   # the prior's interval
    assert math.isfinite(one_fold["lo"]) and one_fold["lo"] < 1.0 < one_fold["hi"]
    assert folds_moderated([np.array([1.0])], 0.975, *KAPPA_PRIOR)["lo"] == -math.inf
    p = folds_moderated([np.array([np.nan, 1.0, 2.0]), np.array([]), np.array([2.0, np.inf, 3.0, 2.5])], 0.975,
                        *KAPPA_PRIOR)
    assert p["n_folds"] == 2 and p["n"] == 5 and all(math.isfinite(p[k]) for k in ("mean", "lo", "hi"))
    assert folds_moderated([], 0.975, *KAPPA_PRIOR)["n"] == 0


def test_the_projection_says_how_many_folds_decide_and_they_do():
    """After two folds, the folds the projection asks for (the same capture, more of it) decide the comparison;
    a decided one needs none more; a difference of exactly the margin is never shown level."""
    from curate.evaluate.folds import KAPPA_PRIOR, folds_to_decide
    rng = np.random.default_rng(11)
    every = [rng.normal(0.45, 2.5, 27) for _ in range(14)]
    level = look_level(True)
    p2 = folds_moderated(every[:2], level, *KAPPA_PRIOR)
    assert decision(p2, 0.3) == "undecided"
    g = folds_to_decide(p2, 0.3, 14)
    assert g is not None and 2 < g <= 14
    assert decision(folds_moderated(every[:g + 1], level, *KAPPA_PRIOR), 0.3) == "ahead"
    done = folds_moderated([rng.normal(3.0, 1.0, 27) for _ in range(2)], level, *KAPPA_PRIOR)
    assert folds_to_decide(done, 0.3, 14) == 2
    far, edge = folds_to_decide({**p2, "mean": 0.9}, 0.3, 14), folds_to_decide({**p2, "mean": 0.3}, 0.3, 14)
    assert far is not None and (edge is None or edge > far)


def test_the_projection_with_a_resolution_asks_for_no_more_folds_and_they_resolve():
    """A difference near the margin would need most of the capture to be told apart from 0 or shown level; with
    --resolution-db 0.5 the projection asks for the folds that measure it to within 0.5 dB, and they do."""
    from curate.evaluate.folds import KAPPA_PRIOR, folds_to_decide
    rng = np.random.default_rng(5)
    every = [rng.normal(0.25, 1.6, 27) for _ in range(14)]
    level = look_level(True)
    p2 = folds_moderated(every[:2], level, *KAPPA_PRIOR)
    assert decision(p2, 0.3, 0.5) == "undecided"
    g0, g = folds_to_decide(p2, 0.3, 14), folds_to_decide(p2, 0.3, 14, resolution=0.5)
    assert g is not None and 2 < g and (g0 is None or g < g0)
    p = folds_moderated(every[:g + 1], level, *KAPPA_PRIOR)
    assert decision(p, 0.3, 0.5) in ("resolved", "ahead", "level") and (p["hi"] - p["lo"]) / 2 <= 0.5


def test_a_rivals_last_look_is_planned_where_a_difference_that_holds_is_likely_to_decide():
    """The last look goes where a mean that holds decides with about 80% chance (later than the even chance of the
    looks before it), to the capture's last fold where only that gives an even chance, and nowhere (not pursued)
    where not even that does."""
    from curate.evaluate.folds import folds_to_decide, next_look
    rng = np.random.default_rng(11)
    p = folds_moderated([rng.normal(0.45, 2.5, 27) for _ in range(3)], look_level(True), *KAPPA_PRIOR)
    even, last = next_look(p, 0.3, 14), next_look(p, 0.3, 14, last=True)
    assert even == folds_to_decide(p, 0.3, 14) and even is not None and last is not None and last > even
    assert next_look(p, 0.3, even, last=True) == even          # only the folds left give an even chance
    assert next_look(p, 0.3, even - 1, last=True) is None      # not even they do
    assert next_look({**p, "mean": 3.0, "lo": 1.0, "hi": 5.0}, 0.3, 14, last=True) == 3   # decided now


def test_the_plan_takes_the_rivals_the_time_decides_fewest_folds_first():
    from curate.evaluate.folds import plan_rivals
    needs = {"random": 3, "fvs": 6, "stride": None}
    # a training 10 s, 2 at a time: fold 3 with random and fvs 15 s, folds 4-6 with fvs only 10 s each
    assert plan_rivals(needs, 2, 1, 10.0, 2, 45.0) == (["random", "fvs"], 6)
    assert plan_rivals(needs, 2, 1, 10.0, 2, 44.0) == (["random"], 3)
    assert plan_rivals(needs, 2, 1, 10.0, 2, 9.0) == ([], None)
    assert plan_rivals({"stride": None}, 2, 1, 10.0, 2, 1e9) == ([], None)


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
    assert looks(2, adaptive=True) == [2] and looks(5, adaptive=True) == [2, 5] and looks(14, True) == [2, 14]
    assert look_level(True, 14) == 1 - 0.05 / LOOKS and look_level(True, 2) == 0.95   # one look: 95%
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
                                 {"methods": ("selection", "oracle")}, {"folds": 1.5}, {"resolution_db": -0.5},
                                 {"resolution_db": float("inf")}])
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


def _run(tmp_path, offsets, effect, cfg, look_at, adaptive, per_unit_s=0.0, seed=0, look=None):
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

    folds, res, why = schedule.run_folds(tmp_path, cfg, make_fold, offsets, look_at, look or stop_at, cams, paths,
                                         None, key, adaptive, progress=False, train=train)
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


def test_a_look_closes_rivals_and_no_fold_starts_beyond_the_look_it_plans(tmp_path):
    from curate.evaluate.schedule import Look
    cfg = EvalConfig(workers=1)
    order = fold_order(14)
    seen = []

    def look(folds, res):
        seen.append(len(folds))
        if len(folds) == 2:
            return Look(skip=frozenset({"random"}), next_look=4)
        return Look(stop=True)
    folds, res, why, made, trained = _run(tmp_path, order, {}, cfg, [2, 14], True, look=look)
    assert seen == [2, 4] and why == "decided" and len(folds) == 4 and len(made) == 4   # nothing started beyond
    assert [k for k in trained if "random" in k] == [f"f{o:02d}_random" for o in order[:2]]   # closed after two
    assert all(f"f{o:02d}_selection" in res for o in order[:4])


def test_the_planner_stops_when_every_rival_is_decided_and_says_the_cost_first(tmp_path):
    from curate.evaluate.stage import Planner
    cfg = EvalConfig(workers=1)
    order = fold_order(14)
    said = []
    planner = Planner(cfg, 14, look_level(True, 14), True, say=said.append)
    folds, res, why, made, trained = _run(tmp_path, order, {o: 1.0 for o in order}, cfg, looks(14, True), True,
                                          look=planner.look)
    assert why == "decided" and len(folds) == 2 and planner.decided_at == {"random": 2, "fvs": 2}
    rec = planner.record()["looks"][0]
    assert rec["folds"] == 2 and rec["decided"] == {"random": "ahead", "fvs": "level"}
    planner.trained(12.0, 2)
    assert "a training takes 12 s here (2 at a time)" in said[-1]
    assert "random subsets: ahead, decided after 2 folds" in said[0]


def test_the_planner_stops_a_rival_measured_to_the_resolution_and_trains_on_without_one():
    """A comparison whose interval after two folds holds 0 but is under --resolution-db wide on each side is
    resolved: the evaluation stops ("decided") and records it; with --resolution-db 0 the same folds are undecided
    and the plan trains that rival on."""
    from curate.evaluate.stage import Planner
    from curate.evaluate.units import Unit
    rng = np.random.default_rng(3)
    folds, res = [], {}
    for o in (0, 7):
        hold = list(range(o, 373, 14))
        d = rng.normal(0.2, 1.0, len(hold))
        folds.append(Fold(o, hold, [], 2, "path", [0, 1],
                          [Unit(f"f{o:02d}_{m}", m, None, [0, 1], o) for m in ("selection", "random")]))
        for m, x in (("selection", 20 + d), ("random", np.full(len(hold), 20.0))):
            res[f"f{o:02d}_{m}"] = {"n_train": 2, "psnr": 0, "ssim": 0, "per_view": [
                {"name": f"{c}", "psnr": float(v), "ssim": 0.5} for c, v in zip(hold, x)]}
    diffs = [np.array([v["psnr"] - 20.0 for v in res[f"f{o:02d}_selection"]["per_view"]]) for o in (0, 7)]
    p = folds_moderated(diffs, look_level(True, 14), *KAPPA_PRIOR)
    assert p["lo"] < 0 < p["hi"] and 0.3 < (p["hi"] - p["lo"]) / 2 <= 0.5     # the case this test is about
    said = []
    planner = Planner(EvalConfig(minutes=60.0), 14, look_level(True, 14), True, say=said.append)
    planner.trained(10.0, 2)
    lk = planner.look(folds, res)
    assert lk.stop and lk.why == "decided" and planner.decided_at == {"random": 2}
    assert planner.record()["looks"][0]["decided"] == {"random": "resolved"}
    assert "random subsets: resolved, decided after 2 folds" in said[-1]
    planner = Planner(EvalConfig(minutes=60.0, resolution_db=0.0), 14, look_level(True, 14), True, say=said.append)
    planner.trained(10.0, 2)
    lk = planner.look(folds, res)
    assert not lk.stop and "random" not in planner.decided_at and lk.until["random"] > 2


def test_a_rivals_last_look_waits_for_the_folds_the_selection_is_trained_to_anyway():
    """Random subsets at their second look (undecided) plan their last; FVS is already planned to 10 folds, so the
    selection is trained there anyway: the last look of random subsets is put there too, not earlier."""
    from curate.evaluate.stage import Planner
    from curate.evaluate.units import Unit
    rng = np.random.default_rng(4)
    folds, res = [], {}
    for o in fold_order(14)[:3]:
        hold = list(range(o, 373, 14))
        folds.append(Fold(o, hold, [], 2, "path", [0, 1],
                          [Unit(f"f{o:02d}_{m}", m, None, [0, 1], o) for m in ("selection", "random", "fvs")]))
        for m, x in (("selection", 20 + rng.normal(0.6, 2.5, len(hold))), ("random", np.full(len(hold), 20.0)),
                     ("fvs", np.full(len(hold), 20.0))):
            res[f"f{o:02d}_{m}"] = {"n_train": 2, "psnr": 0, "ssim": 0, "per_view": [
                {"name": f"{c}", "psnr": float(v), "ssim": 0.5} for c, v in zip(hold, x)]}
    planner = Planner(EvalConfig(minutes=600.0), 14, look_level(True, 14), True, say=lambda m: None)
    planner.trained(10.0, 2)
    planner.n_looks, planner.until = {"random": 1, "fvs": 1}, {"random": 3, "fvs": 10}
    lk = planner.look(folds, res)
    need = planner.record()["looks"][0]["needs_folds"]["random"]
    assert not lk.stop and planner.until["random"] == 10 == need and planner.until["fvs"] == 10


def test_the_planner_trains_on_what_the_time_decides_and_stops_when_nothing_is_left(tmp_path):
    """Undecided after two folds: a rival the time left would decide is trained on to the look the projection
    plans; with no time left, the evaluation stops there and says what it needs."""
    from curate.evaluate.stage import Planner
    from curate.evaluate.units import Unit
    rng = np.random.default_rng(2)

    def fold(o, d):
        hold = list(range(o, 373, 14))
        units = [Unit(f"f{o:02d}_{m}", m, None, [0, 1], o) for m in ("selection", "random")]
        res = {f"f{o:02d}_selection": {"n_train": 2, "psnr": 0, "ssim": 0,
                                       "per_view": [{"name": f"{c}", "psnr": 20 + x, "ssim": 0.5}
                                                    for c, x in zip(hold, d)]},
               f"f{o:02d}_random": {"n_train": 2, "psnr": 0, "ssim": 0,
                                    "per_view": [{"name": f"{c}", "psnr": 20.0, "ssim": 0.5} for c in hold]}}
        return Fold(o, hold, [], 2, "path", [0, 1], units), res
    folds, res = [], {}
    for o in (0, 7):
        f, r = fold(o, rng.normal(0.5, 2.5, 27))
        folds.append(f)
        res.update(r)
    for minutes, stops in ((60.0, False), (0.01, True)):
        said = []
        planner = Planner(EvalConfig(minutes=minutes), 14, look_level(True, 14), True, say=said.append)
        planner.trained(10.0, 2)
        planner.forecast(folds[:1], res)                        # after the first fold: what a decision needs
        assert "from the first fold, a decision needs" in said[-1] and "random subsets: about" in said[-1]
        assert planner.record()["forecast"]["random"] > 1
        lk = planner.look(folds, res)
        rec = planner.record()["looks"][0]
        assert rec["needs_folds"]["random"] is not None and rec["needs_folds"]["random"] > 2
        assert lk.stop == stops and "random subsets:" in said[-1]
        if not stops:
            assert lk.next_look == rec["needs_folds"]["random"] and "random" not in lk.skip
            assert lk.until == {"random": rec["needs_folds"]["random"], "fvs": 2, "stride": 2,
                                "selection": rec["needs_folds"]["random"]}
            assert f"random subsets: {rec['needs_folds']['random'] - 2} more folds, ~" in said[-1]
        else:
            assert lk.why == "needs time" and "beyond --eval-minutes: not pursued" in said[-1]


def test_an_undecided_verdict_says_how_many_more_minutes_here_would_decide_it():
    from curate.report.verdict import verdict
    rep = {"n_candidates": 371, "run_dir": "RUN", "selection": {"chosen": list(range(56)), "method": "path"},
           "evaluation": {"status": "current"}, "methods": {"selection": {}},
           "paired": {"selection-random": {"mean": 0.93, "lo": 0.21, "hi": 1.65, "decision": "ahead"},
                      "selection-fvs": {"mean": 0.43, "lo": -0.2, "hi": 1.06, "decision": "undecided",
                                        "needs": {"folds": 4, "minutes": 3.2}},
                      "selection-stride": {"mean": 0.02, "lo": -0.6, "hi": 0.64, "decision": "undecided",
                                           "needs": {"folds": None, "minutes": None}}},
           "estimate": {"budget": 52, "n_pool": 344, "n_holdout": 53, "holdout_every": 14, "n_folds": 2,
                        "planned_folds": 14, "stopped": "needs time", "minutes": 2, "needs_minutes": 3.2}}
    q = verdict(rep)["quality"]
    assert "about 4 more folds, 4 min here, would decide it if the difference holds" in q
    assert "not even every photo held out would tell them apart" in q
    assert "It stopped after 2 folds: the 2 minutes given would not decide the rest" in q
    assert "`curate evaluate RUN --eval-minutes 4`" in q
    rep["estimate"] = {**rep["estimate"], "needs_minutes": None}
    assert "even every photo held out would not decide the rest" in verdict(rep)["quality"]
    # every training reused (no cost a training to project minutes by), but more folds would decide one rival:
    rep["estimate"] = {**rep["estimate"], "needs_folds": 4}
    q = verdict(rep)["quality"]
    assert "would not decide the rest" in q and "even every photo held out would not decide" not in q
    assert "--eval-minutes 4`" in q


def test_a_resolved_verdict_says_how_closely_it_was_measured_and_asks_for_no_more_folds():
    from curate.report.verdict import verdict
    rep = {"n_candidates": 371, "run_dir": "RUN", "selection": {"chosen": list(range(56)), "method": "path"},
           "evaluation": {"status": "current"}, "methods": {"selection": {}},
           "paired": {"selection-random": {"mean": 0.66, "lo": 0.07, "hi": 1.24, "decision": "ahead"},
                      "selection-fvs": {"mean": 0.15, "lo": -0.32, "hi": 0.62, "decision": "resolved",
                                        "margin": 0.3, "resolution": 0.5}},
           "estimate": {"budget": 52, "n_pool": 344, "n_holdout": 106, "holdout_every": 14, "n_folds": 4,
                        "planned_folds": 14, "stopped": "decided", "minutes": 15, "resolution_db": 0.5}}
    v = verdict(rep)
    assert v["against"] == {"random": "ahead of", "fvs": "not told apart from"}
    assert "not told apart from farthest-view sampling (FVS), measured to ±0.47 dB (+0.15 dB" in v["quality"]
    assert "more folds" not in v["quality"]
    rep["paired"]["selection-fvs"]["level"] = 1 - 0.05 / 3                # a look of an evaluation that adds folds
    assert "(+0.15 dB, 98.3% interval -0.32 to +0.62)" in verdict(rep)["quality"]
    assert "when every rival was decided or its difference measured to ±0.5 dB" in v["quality"]
    rep["estimate"] = {**rep["estimate"], "stopped": "folds asked"}         # --folds 4, every rival decided there
    assert "trained the 4 folds asked for" not in verdict(rep)["quality"]
    rep["paired"]["selection-fvs"] = {**rep["paired"]["selection-fvs"], "decision": "undecided"}
    assert "It trained the 4 folds asked for: `curate evaluate RUN --folds 0` adds folds" in verdict(rep)["quality"]


def test_the_evaluation_trains_the_cheaper_field_and_the_refining_field_keeps_its_own():
    """The evaluation's field (2,048 rays, 48/24 samples, no pre-pass) is its own; the occupancy's refining field
    keeps FieldConfig's settings (its stage key unchanged); a 0.2 run folder's evaluation at 0.2's field takes
    today's, one the user had changed keeps it."""
    from curate.config import RunConfig, upgrade_config
    from curate.core.stage import config_dict, config_from_dict
    from curate.evaluate.config import evaluation_field
    from curate.field.config import FieldConfig
    from curate.occupancy.stage import train_settings
    ev = EvalConfig()
    assert ev.field == evaluation_field() != FieldConfig()
    assert (ev.field.batch_rays, ev.field.n_inner, ev.field.n_outer, ev.field.trans_thresh) == (2048, 48, 24, 0.0)
    assert train_settings(RunConfig())["field"] == FieldConfig()
    old = config_dict(RunConfig())
    old["evaluate"]["field"] = config_dict(FieldConfig())
    up = config_from_dict(RunConfig, upgrade_config(old, "0.2.1")).evaluate.field
    assert up == evaluation_field()
    old["evaluate"]["field"]["batch_rays"] = 8192                   # the user's own: kept
    assert config_from_dict(RunConfig, upgrade_config(old, "0.2.1")).evaluate.field.batch_rays == 8192
