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
TINY = ["--iters", "15", "--eval-size", "32", "--random-seeds", "1", "--workers", "1", "--res", "12", "--triangulate", "off"]


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
    assert rep["evaluation"]["status"] == "current" and rep["estimate"]["n_pool"] + rep["estimate"]["n_holdout"] == 160
    # the estimate chose the same share of the photos left after the hold-out, by the same method
    assert rep["estimate"]["budget"] == round(12 * rep["estimate"]["n_pool"] / 160)
    assert _rep(fast)["evaluation"]["status"] == "not run" and "methods" not in _rep(fast)
    out = capsys.readouterr().out
    assert "12 of 160 photos chosen" in out and "verdict:" in out


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
    rep = _rep(run)
    assert rep["evaluation"]["status"] == "current" and rep["estimate"]["budget"] == round(8 * rep["estimate"]["n_pool"] / 160)
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
                                      ({"mean": 0.5, "lo": -0.2, "hi": 1.2}, "level with"),
                                      ({"mean": 0.5, "lo": -math.inf, "hi": math.inf, "n": 1}, "level with")])
def test_compare_says_ahead_only_when_the_interval_excludes_zero(p, words):
    from curate.report.verdict import compare
    assert compare(p) == words


def test_the_verdict_names_both_rivals_with_intervals_and_the_coverage():
    from curate.report.verdict import verdict
    rep = {"n_candidates": 282, "selection": {"chosen": list(range(60)), "method": "path",
                                              "coverage": {"seen": 0.97, "seen_twice": 0.88, "n_nodes_seen": 500}},
           "evaluation": {"status": "current"}, "methods": {"selection": {}},
           "paired": {"selection-random": {"mean": 1.77, "lo": 0.52, "hi": 3.02},
                      "selection-fvs": {"mean": 1.06, "lo": -0.28, "hi": 2.40}}, "gap_closed": 0.67,
           "estimate": {"budget": 55, "n_pool": 261, "n_holdout": 21, "holdout_every": 14}}
    v = verdict(rep)
    assert v["exported"].startswith("60 of 282 photos chosen") and "97%" in v["coverage"] and "88%" in v["coverage"]
    assert "ahead of random subsets of the same size (+1.77 dB, 95% interval +0.52 to +3.02)" in v["quality"]
    assert "level with farthest-view sampling (FVS) (+1.06 dB, 95% interval -0.28 to +2.40)" in v["quality"]
    assert "67% of the gap" in v["quality"] and "55 of the 261" in v["quality"]
    assert v["short"] == "ahead of random +1.77 dB [+0.52, +3.02]; level with FVS +1.06 dB [-0.28, +2.40]; gap closed 67%"
    assert v["against"] == {"random": "ahead of", "fvs": "level with"}


def test_the_budget_advice_says_its_range_and_whether_it_was_measured_on_the_capture():
    """`--budget auto` without the evaluation: the range and a warning that the rule was fitted on other
    captures; with the check: the measured advice, and the command when the export holds too few."""
    from curate.report.verdict import verdict
    auto = {"budget": 60, "low": 48, "high": 62, "tolerance_db": 0.5}
    rep = {"n_candidates": 160, "selection": {"chosen": list(range(60)), "budget_auto": auto}}
    hm = verdict(rep)["how_many"]
    assert hm.startswith("How many: --budget auto predicted 60 (48 to 62) for 0.5 dB from the poses alone")
    assert "fitted on other captures" in hm and "measured on this capture" not in hm
    rep.update(run_dir="RUN", budget_check={"budget": 90, "low": 75, "high": 110, "tolerance_db": 0.5})
    hm = verdict(rep)["how_many"]
    assert "measured on this capture, about 90 (75 to 110) come within 0.5 dB" in hm
    assert "`curate select RUN --budget 90`" in hm and "fitted on other captures" not in hm


def test_coverage_counts_what_the_chosen_see_of_what_the_capture_sees():
    from types import SimpleNamespace
    from curate.select.stage import coverage
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
