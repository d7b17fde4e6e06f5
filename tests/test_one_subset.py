"""What curate says must be true (issue 34): one subset per capture, whatever the evaluation; figures
that belong to the selection they name; a verdict against random and FVS in words, with intervals."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from curate.cli import main

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"
TINY = ["--iters", "15", "--eval-size", "32", "--random-seeds", "1", "--workers", "1", "--res", "12",
        "--triangulate", "off", "--folds", "2", "--refine-iters", "40", "--refine-size", "32"]


def _run(out: Path, *extra: str) -> list[str]:
    return ["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(out), *TINY,
            *extra]


def _names(run: Path) -> list[str]:
    return (run / "export" / "images.txt").read_text().split()


def _rep(run: Path) -> dict:
    return json.loads((run / "report.json").read_text())


@pytest.mark.slow
@pytest.mark.parametrize("method", ["auto", "energy"])
def test_fast_and_evaluated_runs_export_the_same_frames(tmp_path, capsys, method):
    """`--no-evaluate` and the evaluated run choose among every registered photo, with the same grid:
    the same exported frames, none of them excluded by a hold-out."""
    fast, full = tmp_path / "fast", tmp_path / "full"
    assert main(_run(fast, "--budget", "12", "--method", method, "--no-evaluate")) == 0
    assert main(_run(full, "--budget", "12", "--method", method)) == 0
    assert _names(fast) == _names(full) and len(_names(fast)) == 12
    sel = json.loads((fast / "select" / "selection.json").read_text())
    assert sel["pool"] == list(range(160)) and sel["holdout"] == []
    rep = _rep(full)
    est = rep["estimate"]     # fold 0 holds out photos 0, 14, ..., 154; two folds hold out twice as many
    assert rep["evaluation"]["status"] == "current" and est["n_pool"] == 160 - 12 and est["n_holdout"] == 12 + 11
    # the estimate chose the same share of the photos left after the hold-out, by the same method
    assert rep["estimate"]["budget"] == round(12 * rep["estimate"]["n_pool"] / 160)
    assert _rep(fast)["evaluation"]["status"] == "not run" and "methods" not in _rep(fast)
    out = capsys.readouterr().out
    assert "12 of 160 photos chosen" in out and "verdict:" in out
    assert set(rep["paired"]) == {"selection-random", "selection-fvs", "selection-stride"}   # a walk: every n-th too
    page = (full / "report.html").read_text()
    assert "every n-th frame" in page and "2 folds" in page
    renders = page[page.index('class="renders"'):]
    assert "missing" not in renders[:renders.index("</table>")]      # each fold's renders found in its own unit


@pytest.mark.slow
def test_a_report_never_shows_another_selections_evaluation(tmp_path, capsys):
    """`curate select RUN --budget 8` after an evaluated run: the export follows (8 photos), the report
    and the terminal say the evaluation is out of date with the command that refreshes it, and show
    none of its figures; `curate evaluate RUN` makes it current again, for 8."""
    run = tmp_path / "run"
    assert main(_run(run, "--budget", "12")) == 0
    assert "selection" in _rep(run)["methods"]
    capsys.readouterr()
    assert main(["select", str(run), "--budget", "8"]) == 0
    out = capsys.readouterr().out
    assert "export" in out and "8 images" in out and f"curate evaluate {run}" in out and "out of date" in out
    rep = _rep(run)
    assert len(_names(run)) == 8 and rep["budget"] == 8
    assert rep["evaluation"]["status"] == "out of date" and rep["evaluation"]["of"]["exported_budget"] == 12
    assert "methods" not in rep and "paired" not in rep and "out of date" in rep["verdict"]["short"]
    page = (run / "report.html").read_text()
    assert "earlier selection (12 photos" in page and "How the selection compares" not in page
    assert main(["evaluate", str(run)]) == 0
    rec = json.loads((run / "evaluate" / "stage.json").read_text())   # recorded last, as every stage
    summ = json.loads((run / "evaluate" / "summary.json").read_text())
    assert rec["key"] == summ["key"] and rec["inputs"] == {
        "select": json.loads((run / "select" / "stage.json").read_text())["key"]}
    rep = _rep(run)
    assert (rep["evaluation"]["status"] == "current"
            and rep["estimate"]["budget"] == round(8 * rep["estimate"]["n_pool"] / 160))
    assert rep["methods"]["selection"]["n_train"] == rep["estimate"]["budget"]


def _finished_stages(run):
    """sfm, occupancy, select and export finished in ``run`` (keys s1, o1, x1, e1), and an evaluation
    that read selection x1."""
    from curate.core.stage import begin_stage, finish_stage, write_json_atomic
    for name, key in (("sfm", "s1"), ("occupancy", "o1"), ("select", "x1"), ("export", "e1")):
        begin_stage(run / name, key)
        finish_stage(run / name, key, {}, 0.0)
    write_json_atomic(run / "evaluate" / "summary.json", {"key": "v1", "inputs": {"select": "x1"}})


def test_stale_stages_follow_the_recorded_inputs(tmp_path):
    """A stage is out of date when a stage it reads was redone after it, or is itself out of date."""
    from curate.core.runfolder import claimed
    from curate.core.stage import begin_stage, finish_stage, stale_stages
    run = tmp_path / "run"
    with claimed(run):
        _finished_stages(run)
        assert stale_stages(run) == {}
        begin_stage(run / "select", "x2")                 # the selection is redone
        finish_stage(run / "select", "x2", {}, 0.0)
        assert set(stale_stages(run)) == {"evaluate", "export"}
        begin_stage(run / "occupancy", "o2", True)        # the occupancy too: select reads it
        finish_stage(run / "occupancy", "o2", {}, 0.0)
        st = stale_stages(run)
        assert set(st) == {"select", "evaluate", "export"} and "out of date" in st["evaluate"]


def test_the_refresh_command_redoes_the_first_stale_stage(tmp_path):
    """A run folder whose occupancy an earlier curate made (no inputs recorded): its selection, export
    and evaluation are all out of date, and `curate export` or `curate evaluate` alone would leave them
    so. The command the user is given starts from the occupancy."""
    from curate.core.runfolder import claimed
    from curate.core.stage import begin_stage, finish_stage, refresh_command, stale_stages, write_json_atomic
    run = tmp_path / "run"
    with claimed(run):
        _finished_stages(run)
        assert refresh_command(run, stale_stages(run), "evaluate") == f"curate evaluate {run}"
        begin_stage(run / "select", "x2")
        finish_stage(run / "select", "x2", {}, 0.0)
        st = stale_stages(run)
        assert refresh_command(run, st, "export") == f"curate export {run}"
        assert refresh_command(run, st, "evaluate") == f"curate evaluate {run}"
        rec = json.loads((run / "occupancy" / "stage.json").read_text())
        rec.pop("inputs", None)                           # as an earlier curate wrote it
        write_json_atomic(run / "occupancy" / "stage.json", rec)
        st = stale_stages(run)
        assert "earlier curate" in st["occupancy"]
        assert refresh_command(run, st, "export") == f"curate occupancy {run}"
        assert refresh_command(run, st, "evaluate") == f"curate occupancy {run} && curate evaluate {run}"


@pytest.mark.parametrize("p, words", [({"mean": 1.2, "lo": 0.3, "hi": 2.1}, "ahead of"),
                                      ({"mean": -0.8, "lo": -1.5, "hi": -0.1}, "behind"),
                                      ({"mean": 0.5, "lo": -0.2, "hi": 1.2}, "not told apart from"),
                                      ({"mean": 0.05, "lo": -0.2, "hi": 0.25}, "level with"),
                                      ({"mean": 0.05, "lo": -0.2, "hi": 0.25, "margin": 0.1, "decision": "undecided"},
                                       "not told apart from"),
                                      ({"mean": 0.5, "lo": -math.inf, "hi": math.inf, "n": 1}, "not told apart from")])
def test_compare_says_ahead_only_when_the_interval_excludes_zero_and_level_only_within_the_margin(p, words):
    from curate.report.verdict import compare
    assert compare(p) == words


def test_the_verdict_names_every_rival_with_its_interval_what_it_decides_and_the_coverage():
    from curate.report.verdict import verdict
    rep = {"n_candidates": 282, "run_dir": "RUN",
           "selection": {"chosen": list(range(60)), "method": "path",
                         "coverage": {"seen": 0.97, "seen_twice": 0.88, "n_nodes_seen": 500}},
           "evaluation": {"status": "current"}, "methods": {"selection": {}},
           "paired": {"selection-random": {"mean": 1.77, "lo": 0.52, "hi": 3.02, "decision": "ahead"},
                      "selection-fvs": {"mean": 1.06, "lo": -0.28, "hi": 2.40, "decision": "undecided"},
                      "selection-stride": {"mean": 0.05, "lo": -0.2, "hi": 0.25, "decision": "level", "margin": 0.3}},
           "gap_closed": 0.67,
           "estimate": {"budget": 55, "n_pool": 261, "n_holdout": 130, "holdout_every": 14, "n_folds": 6,
                        "planned_folds": 14, "stopped": "time", "minutes": 15}}
    v = verdict(rep)
    assert v["exported"].startswith("60 of 282 photos chosen") and "97%" in v["coverage"] and "88%" in v["coverage"]
    assert "ahead of random subsets of the same size (+1.77 dB, 95% interval +0.52 to +3.02)" in v["quality"]
    assert "not told apart from farthest-view sampling (FVS) (+1.06 dB, 95% interval -0.28 to +2.40)" in v["quality"]
    assert "level with every n-th frame, within 0.3 dB (+0.05 dB" in v["quality"]
    assert ("67% of the gap" in v["quality"] and "55 of the 261" in v["quality"]
            and "6 of 14 hold-out folds" in v["quality"])
    assert "`curate evaluate RUN --eval-minutes 30`" in v["quality"]          # how to narrow it: more time
    assert v["short"] == ("ahead of random +1.77 dB [+0.52, +3.02]; not told apart from FVS +1.06 dB [-0.28, +2.40]; "
                          "level with every n-th frame +0.05 dB [-0.20, +0.25]; gap closed 67%; 6 of 14 folds")
    assert v["against"] == {"random": "ahead of", "fvs": "not told apart from", "stride": "level with"}
    rep["estimate"] = {**rep["estimate"], "n_holdout": 12, "stopped": "every photo"}     # a small capture: said
    assert "Only 12 photos could be held out" in verdict(rep)["quality"]
    assert v["frames"] is None                                        # photos: nothing more to say
    rep["sfm"] = {"videos": [{"video": "room.mp4", "decoded": 1000, "candidates": 282}]}   # issue 50: "20 of 40" alone
    assert verdict(rep)["frames"] == ("The 282 candidates are the sharpest distinct frames of the 1000 in room.mp4 "
                                      "that SfM registered.")
    rep["estimate"] = {**rep["estimate"], "n_holdout": 282}                           # all held out, still undecided
    assert "Every photo has been held out once" in verdict(rep)["quality"]


def test_the_budget_advice_says_what_was_measured_and_exported_beside_the_law_and_its_error():
    """`--budget auto` without the evaluation: the law's range, and how far off it was on real captures;
    with the measurement before the selection: what was measured and exported, the law beside it."""
    from curate.report.verdict import verdict
    auto = {"budget": 60, "low": 48, "high": 62, "tolerance_db": 0.5, "kind": "walk"}
    rep = {"n_candidates": 160, "selection": {"chosen": list(range(60)), "budget_auto": auto}}
    hm = verdict(rep)["how_many"]
    assert hm.startswith("How many: --budget auto predicted 60 (48 to 62) for 0.5 dB from the poses alone")
    assert "a quarter" in hm and "An evaluated run measures it" in hm and "measured on this capture" not in hm
    measured = {**auto, "budget": 90, "predicted": 60, "source": "measured",
                "measured": {"budget": 90, "low": 75, "high": 110, "tolerance_db": 0.5}}
    rep = {"n_candidates": 160, "selection": {"chosen": list(range(90)), "budget_auto": measured}}
    hm = verdict(rep)["how_many"]
    assert ("measured on this capture, about 90 (75 to 110) photos come within 0.5 dB of all of them; "
            "90 were exported") in hm
    assert "predicted 60 (48 to 62)" in hm


def test_coverage_counts_what_the_chosen_see_of_what_the_capture_sees():
    from types import SimpleNamespace
    from curate.select.record import coverage
    # 4 nodes: node 0 seen by cams 0,1; node 1 by cam 1; node 2 by cam 2; node 3 by none
    idx = SimpleNamespace(cam=np.array([0, 1, 1, 2]), indptr=np.array([0, 2, 3, 4, 4]), n_nodes=4, n_cams=3)
    c = coverage(idx, [0, 1])
    assert c == {"seen": pytest.approx(2 / 3), "seen_twice": pytest.approx(1 / 3), "n_nodes_seen": 3}
    assert coverage(SimpleNamespace(cam=np.zeros(0, int), indptr=np.zeros(3, int), n_nodes=2, n_cams=2),
                    [0])["seen"] == 0.0


def test_the_budget_check_recovers_a_capture_that_needs_more_than_the_law_says():
    """Points measured on a capture whose alpha is three times the law's: the check advises the budget
    of that alpha (and a range around it); losses all within the tolerance: 'at most' the smallest."""
    from curate.evaluate.check import check_budgets, fit_check
    from curate.select.auto_budget import fewest_within
    rho_full = 1.0 / np.arange(1, 301) ** 0.8                 # a decreasing spacing curve, K = 300
    p, alpha = 1.47, 3 * 13.19
    pts = [{"k": k, "rho": float(rho_full[int(k * 300 / 280) - 1]), "lo": 0, "hi": 0} for k in (20, 40, 80)]
    for x, noise in zip(pts, (1.05, 0.95, 1.0)):
        x["loss"] = alpha * x["rho"] ** p * noise
    chk = fit_check(pts, p, rho_full, 0.5, 300 / 280)
    want = fewest_within(alpha * rho_full ** p, 0.5)
    assert chk.low <= want <= chk.high and abs(chk.budget - want) <= 0.05 * want
    assert fewest_within(13.19 * rho_full ** p, 0.5) < chk.low      # the law alone would advise too few
    small = [{**x, "loss": 0.01} for x in pts]
    chk = fit_check(small, p, rho_full, 0.5, 300 / 280)
    assert chk.budget is None and chk.high == round(20 * 300 / 280) and "or fewer" in chk.note
    assert check_budgets(40, 280) == [20, 80] and check_budgets(3, 6) == [4] and check_budgets(2, 4) == []


@pytest.mark.slow
def test_budget_auto_on_an_evaluated_run_exports_the_budget_it_measured(tmp_path, capsys):
    """`--budget auto` with the evaluation: the budget stage measures the method's learning curve on two folds
    before the selection, the selection exports that budget (the law's prediction kept beside it), the
    evaluation estimates that export and reuses the curve's trainings on all photos; without the evaluation
    the law's budget is exported and no training is made for it."""
    run, fast = tmp_path / "run", tmp_path / "fast"
    assert main(_run(run, "--budget", "auto")) == 0
    b = json.loads((run / "budget" / "budget.json").read_text())
    sel = json.loads((run / "select" / "selection.json").read_text())
    assert sel["budget"] == b["budget"] == len(_names(run)) and sel["budget_auto"]["source"] == "measured"
    assert sel["budget_auto"]["predicted"] == b["predicted"]["budget"] and sel["budget_auto"]["measured"]["points"]
    rep = _rep(run)
    assert rep["estimate"]["budget"] == round(b["budget"] * rep["estimate"]["n_pool"] / 160)
    assert f"{b['budget']} were exported" in rep["verdict"]["how_many"]
    curve_units = json.loads((run / "budget" / "stage.json").read_text())["units"]
    folds = json.loads((run / "evaluate" / "summary.json").read_text())["protocol"]["folds"]
    shared = set(curve_units) & {u for f in folds for u in f["units"]}
    assert shared == {"f00_all"}     # trained once, for the curve, and reused by the evaluation (all photos: fold 0)
    assert main(_run(fast, "--budget", "auto", "--no-evaluate")) == 0
    fsel = json.loads((fast / "select" / "selection.json").read_text())
    assert not (fast / "budget").exists() and fsel["budget_auto"]["source"] == "law"
    assert fsel["budget"] == fsel["budget_auto"]["predicted"] == b["predicted"]["budget"]
    assert "An evaluated run measures it" in _rep(fast)["verdict"]["how_many"]


@pytest.mark.slow
def test_the_same_command_gives_the_same_export_byte_for_byte(tmp_path):
    """Issue 49: the README's sample with known poses, run twice with the same command, triangulated 3,404 and
    3,402 points and exported different frames. Now the points, the subset and every exported file agree."""
    runs = [tmp_path / "a", tmp_path / "b"]
    for r in runs:
        assert main(["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(r),
                     "--budget", "15%", "--no-evaluate", "--export-mode", "copy"]) == 0

    def files(r: Path) -> dict:
        return {p.relative_to(r / "export").as_posix(): p.read_bytes() for p in sorted((r / "export").rglob("*"))
                if p.is_file() and p.name not in ("export.json", "stage.json", ".curate-stage")}   # paths, times
    a, b = files(runs[0]), files(runs[1])
    assert set(a) == set(b) and all(a[k] == b[k] for k in a), [k for k in a if a[k] != b.get(k)]
    pts = [np.load(r / "sfm" / "points.npy") for r in runs]
    assert pts[0].shape == pts[1].shape and np.array_equal(pts[0], pts[1])
    # and the same suggestions of where to shoot next
    for r in runs:
        assert main(["suggest", str(r), "--add", "3", "--candidates", "200", "--field", "none"]) == 0
    sug = [json.loads((r / "suggest" / "suggestions.json").read_text())["suggestions"] for r in runs]
    assert [s["c2w"] for s in sug[0]] == [s["c2w"] for s in sug[1]] and len(sug[0]) == 3
