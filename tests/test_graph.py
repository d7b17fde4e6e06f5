"""The stage graph is declared once (:mod:`curate.core.graph`): the pipeline's order, the stage commands'
checks and refreshes, the staleness and the batch summary's failed stage all follow it."""

from __future__ import annotations

import inspect

import pytest

from curate.config import RunConfig
from curate.core import graph
from curate.core.graph import BY_NAME, NAMES, STAGES


def test_every_stage_runs_through_one_signature_and_names_stages_before_it():
    """A keyed stage's key function takes the RunContext and its computation the RunContext and the key (the
    runner calls both); a stage that keys itself takes one RunContext; what a stage reads, needs and is keyed on
    are stages that come before it, so the pipeline's order computes every input first."""
    for i, s in enumerate(STAGES):
        fn = graph._function(s.runs)
        if s.key is not None:
            assert list(inspect.signature(graph._function(s.key)).parameters) == ["ctx"], s.name
            assert list(inspect.signature(fn).parameters) == ["ctx", "keyed"], s.name
            assert set(s.keyed_on) <= set(NAMES[:i]), s.name
        else:
            assert list(inspect.signature(fn).parameters) == ["ctx"], s.name
        assert set(s.reads) | set(s.needs) <= set(NAMES[:i]), s.name
        if s.when is not None:
            assert list(inspect.signature(graph._function(s.when)).parameters) == ["cfg", "run_dir"], s.name
    assert NAMES[0] == "sfm" and NAMES[-1] == "report"


def test_a_stage_command_redoes_only_the_cheap_stages_computed_from_it():
    """`curate occupancy RUN` redoes the selection and the export (seconds), not the evaluation (training);
    `curate evaluate RUN` redoes nothing after it: the export does not read the evaluation."""
    assert graph.redone_after("occupancy") == ("select", "export")
    assert graph.redone_after("select") == ("export",)
    assert graph.redone_after("evaluate") == () and graph.redone_after("export") == ()
    assert graph.downstream("occupancy") == ("budget", "select", "evaluate", "export")


def test_the_run_folder_entries_curate_writes_are_every_stages_and_its_own():
    """What an adopted folder may not already hold: every stage's output, run.json and the parts of a split."""
    assert set(graph.RUN_WRITES) == {"run.json", "parts", "sfm", "occupancy", "budget", "select", "evaluate",
                                     "export", "report.json", "report.html"}


@pytest.mark.parametrize("evaluated", [True, False])
def test_the_first_unfinished_stage_skips_the_stages_this_run_does_not_have(tmp_path, evaluated):
    """A batch row names the stage a failed run stopped in: the evaluation only when the run has one."""
    cfg = RunConfig(budget="12", run_evaluation=evaluated)
    for s in ("sfm", "occupancy", "select"):
        (tmp_path / s).mkdir()
        (tmp_path / s / "stage.json").write_text("{}")
    assert graph.first_unfinished(cfg, tmp_path) == ("evaluate" if evaluated else "export")
    (tmp_path / "evaluate").mkdir()
    (tmp_path / "evaluate" / "stage.json").write_text("{}")
    assert graph.first_unfinished(cfg, tmp_path) == "export"
    assert not BY_NAME["budget"].applies(cfg, tmp_path)          # a count budget is not measured

