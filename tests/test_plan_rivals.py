"""Each rival trained only in the folds its own comparison needs (issue 59, item 3): a rival decided is trained no
more, one whose need is beyond the capture or the time is not pursued, the selection is trained in every fold a
rival still needs, and each comparison pairs only the folds where both were trained."""

from __future__ import annotations

import json

import numpy as np
import pytest

from curate.core.stats import folds_moderated
from curate.evaluate.config import EvalConfig
from curate.evaluate.folds import Fold, fold_order, look_level, looks, plan_rivals, summarize
from curate.evaluate.units import Unit

N_PHOTOS = 373
RIVALS4 = ("selection", "random", "fvs", "stride")


class _Cams:
    def __init__(self, n):
        self.names = [f"{i:03d}.png" for i in range(n)]
        self.width = np.full(n, 8)
        self.height = np.full(n, 6)


def _evaluate(tmp_path, ahead: dict, sd: dict, minutes: float = 60.0):
    """The schedule and the product's Planner on fake folds of a 373-photo walk: per held-out photo, the selection
    scores ``ahead[rival]`` dB above each rival, with per-photo noise of sd ``sd[rival]`` (fixed per photo and
    rival); nothing is trained. Returns (folds, results, why, the unit keys trained, the planner, what it said)."""
    from PIL import Image
    from curate.evaluate import schedule
    from curate.evaluate.stage import Planner
    cams = _Cams(N_PHOTOS)
    paths = []
    for i in range(N_PHOTOS):
        p = tmp_path / "img" / cams.names[i]
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.new("RGB", (8, 6), (i % 256, 0, 0)).save(p)
        paths.append(str(p))
    noise = {m: np.random.default_rng(j).normal(0, 1, N_PHOTOS) for j, m in enumerate(RIVALS4)}

    def make_fold(o):
        hold = list(range(o, N_PHOTOS, 14))
        pool = [i for i in range(N_PHOTOS) if i % 14 != o]
        us = [Unit(f"f{o:02d}_{m}", m, None, pool[j:j + 20], o) for j, m in enumerate(RIVALS4)]
        return Fold(o, hold, pool, 20, "path", pool[:20], us)

    trained = []

    def train(args):
        _, u, *_ = args
        trained.append(u.key)
        hold = list(range(u.fold, N_PHOTOS, 14))
        base = 20.0 - ahead.get(u.method, 0.0)
        pv = [{"name": cams.names[c], "psnr": base + sd.get(u.method, 0.0) * float(noise[u.method][c]),
               "ssim": 0.5} for c in hold]
        m = {"method": u.method, "seed": u.seed, "subset": u.subset, "n_train": len(u.subset),
             "psnr": float(np.mean([v["psnr"] for v in pv])), "ssim": 0.5, "per_view": pv}
        d = tmp_path / "evaluate" / u.key
        d.mkdir(parents=True, exist_ok=True)
        (d / "metrics.json").write_text(json.dumps(m))
        (d / "stage.json").write_text(json.dumps({"key": u.key}))
        return m

    cfg = EvalConfig(workers=1, minutes=minutes)
    order = fold_order(14)
    said = []
    planner = Planner(cfg, 14, look_level(True, 14), True, say=said.append)
    folds, res, why = schedule.run_folds(tmp_path, cfg, make_fold, order, looks(14, True), planner.look, cams,
                                         paths, None, lambda u, f: u.key, True, progress=False, train=train)
    return folds, res, why, trained, planner, said


def test_each_rival_is_trained_only_in_the_folds_its_own_comparison_needs(tmp_path):
    """Random subsets far behind (decided after 2 folds), FVS a few tenths behind (undecided after 2: trained on
    to the folds its projection asks for), every n-th frame level but noisy beyond what 14 folds would decide (not
    pursued): random subsets and every n-th frame are not trained in fold 3; the selection is trained in exactly
    the folds FVS is; each comparison uses the folds both were trained in."""
    folds, res, why, trained, planner, said = _evaluate(
        tmp_path, {"random": 3.0, "fvs": 0.6, "stride": 0.0}, {"selection": 0.0, "random": 1.0, "fvs": 2.5,
                                                              "stride": 40.0})
    order = fold_order(14)
    in_fold = {m: [i for i, o in enumerate(order) if f"f{o:02d}_{m}" in trained] for m in RIVALS4}
    assert in_fold["random"] == [0, 1] and in_fold["stride"] == [0, 1]          # decided / not pursued after 2
    assert len(in_fold["fvs"]) > 2 and in_fold["fvs"] == list(range(len(in_fold["fvs"])))
    assert in_fold["selection"] == in_fold["fvs"]        # the selection wherever a rival still trains, no further
    assert planner.decided_at["random"] == 2 and planner.closed_at["stride"] == 2
    first = planner.record()["looks"][0]
    assert first["needs_folds"]["stride"] is None and first["training"] == ["fvs"]
    assert "random subsets: ahead, decided after 2 folds" in said[0]
    assert "FVS: " in said[0] and "more folds" in said[0]
    assert "every n-th frame: would" in said[0] and "not pursued" in said[0]
    # each comparison pairs only the folds both were trained in
    _, paired, _ = summarize(res, folds, look_level(True, 14), 0.3, rival_folds=planner.rival_folds())
    assert paired["selection-random"]["n_folds"] == 2 and paired["selection-stride"]["n_folds"] == 2
    assert paired["selection-fvs"]["n_folds"] == len(in_fold["fvs"])
    # the run's folds list the units trained, not those closed
    assert all(u.key in res for f in folds for u in f.units)
    assert not any(u.method == "random" for f in folds[2:] for u in f.units)


def test_a_rival_decided_at_the_first_look_is_not_trained_in_the_third_fold(tmp_path):
    folds, res, why, trained, planner, said = _evaluate(
        tmp_path, {"random": 3.0, "fvs": 0.0, "stride": 0.0}, {"random": 1.0, "fvs": 0.05, "stride": 0.05})
    assert why == "decided" and len(folds) == 2
    assert {k for k in trained if k.startswith(f"f{fold_order(14)[2]:02d}")} == set()


def test_a_comparison_pairs_only_the_folds_where_both_were_trained():
    """Three folds; FVS trained in the first two only: its interval is that of those two folds' differences, and
    the third fold's selection scores do not enter it."""
    rng = np.random.default_rng(5)
    folds, res, diffs = [], {}, []
    for i, o in enumerate((0, 7, 3)):
        hold = list(range(o, 100, 14))
        methods = ("selection", "fvs") if i < 2 else ("selection",)
        units = [Unit(f"f{o:02d}_{m}", m, None, [1, 2], o) for m in methods]
        sel = rng.normal(21.0, 1.0, len(hold))
        fvs = rng.normal(20.5, 1.0, len(hold))
        for m, v in (("selection", sel), ("fvs", fvs)):
            if m in methods:
                res[f"f{o:02d}_{m}"] = {"n_train": 2, "psnr": float(v.mean()), "ssim": 0.5,
                                        "per_view": [{"name": str(c), "psnr": float(x), "ssim": 0.5}
                                                     for c, x in zip(hold, v)]}
        if i < 2:
            diffs.append(sel - fvs)
        folds.append(Fold(o, hold, [], 2, "path", [1, 2], units))
    _, paired, _ = summarize(res, folds, 0.975, 0.3)
    want = folds_moderated(diffs, 0.975, 1.0, 8.0)
    got = paired["selection-fvs"]
    assert got["n_folds"] == 2 and got["n"] == sum(len(d) for d in diffs)
    assert (got["mean"], got["lo"], got["hi"]) == pytest.approx((want["mean"], want["lo"], want["hi"]))


def test_the_plan_counts_what_earlier_looks_committed_and_shares_the_selection():
    # FVS already planned to 6 folds (10 s a training, 2 at a time): the selection trains in folds 3-6 anyway, so
    # random subsets to 4 folds cost only their own 2 trainings (10 s) on top of FVS's 40 s
    assert plan_rivals({"random": 4}, 2, 1, 10.0, 2, 50.0, committed={"fvs": 6}) == (["random"], 4)
    assert plan_rivals({"random": 4}, 2, 1, 10.0, 2, 49.0, committed={"fvs": 6}) == ([], None)
    # a rival whose own need does not fit is left out; the cheaper ones are still taken
    assert plan_rivals({"random": 3, "fvs": 4, "stride": 14}, 2, 1, 10.0, 2, 40.0) == (["random", "fvs"], 4)


def test_a_rival_is_trained_to_its_own_need_not_to_the_largest(tmp_path):
    """Undecided after 2 folds, random subsets projected to need 3 folds and FVS 7: random subsets are trained in 3
    folds, looked at there (decided), and not trained in the folds FVS still needs (before issue 59's item 3 both
    were trained to 7)."""
    folds, res, why, trained, planner, said = _evaluate(
        tmp_path, {"random": 0.8, "fvs": 0.6, "stride": 0.0}, {"random": 2.5, "fvs": 2.5, "stride": 40.0})
    first = planner.record()["looks"][0]
    need_r, need_f = first["needs_folds"]["random"], first["needs_folds"]["fvs"]
    assert first["training"] == ["random", "fvs"] and need_r < need_f
    order = fold_order(14)
    in_fold = {m: [i for i, o in enumerate(order) if f"f{o:02d}_{m}" in trained] for m in RIVALS4}
    assert in_fold["random"] == list(range(need_r)) and planner.decided_at["random"] == need_r
    assert in_fold["fvs"] == in_fold["selection"] == list(range(len(folds)))
    assert 3 in planner.looked                               # random subsets' own look


def _null_ish(seed: int, mean: float):
    """14 folds of a 373-photo walk where the selection is ``mean`` dB above random subsets, per-photo sd 2.5."""
    rng = np.random.default_rng(seed)
    folds, res = [], {}
    for o in fold_order(14):
        hold = list(range(o, N_PHOTOS, 14))
        d = rng.normal(mean, 2.5, len(hold))
        units = [Unit(f"f{o:02d}_{m}", m, None, [0, 1], o) for m in ("selection", "random")]
        res[f"f{o:02d}_selection"] = {"n_train": 2, "psnr": 0, "ssim": 0, "per_view": [
            {"name": f"{c}", "psnr": 20 + x, "ssim": 0.5} for c, x in zip(hold, d)]}
        res[f"f{o:02d}_random"] = {"n_train": 2, "psnr": 0, "ssim": 0, "per_view": [
            {"name": f"{c}", "psnr": 20.0, "ssim": 0.5} for c in hold]}
        folds.append(Fold(o, hold, [], 2, "path", [0, 1], units))
    return folds, res


def test_a_later_evaluation_trains_to_the_folds_the_earlier_verdict_asked_for():
    """Undecided at its second look (5 folds), random subsets' last look is projected at 9 folds (at 80% power;
    --resolution-db 0, so that only the sign or the margin decides). When an earlier evaluation of the same
    selection said they need 12 (``curate evaluate RUN --eval-minutes M`` after a verdict that said so), the last
    look is at 12 instead, so the command adds the folds it promised."""
    from curate.evaluate.stage import Planner
    folds, res = _null_ish(2, 0.45)
    for extend, last in (({}, 9), ({"random": 12}, 12)):
        pl = Planner(EvalConfig(minutes=60, resolution_db=0.0), 14, look_level(True, 14), True, say=lambda m: None)
        pl.extend = extend
        first = pl.look(folds[:2], res)
        assert not first.stop and first.until["random"] == 5
        second = pl.look(folds[:5], res)
        assert not second.stop and second.until["random"] == second.until["selection"] == last
