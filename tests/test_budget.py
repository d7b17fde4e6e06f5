"""Budgets as the CLI, the pipeline and the harness read them."""

import pytest

from curate.core.budget import budget_text, parse_budget, resolve_budget


@pytest.mark.parametrize("text, value", [("60", 60), (" 7 ", 7), ("0", 0), ("15%", 0.15), ("100%", 1.0),
                                         ("0.5%", 0.005)])
def test_parse_and_round_trip(text, value):
    b = parse_budget(text)
    assert b == pytest.approx(value) and type(b) is type(value)
    assert parse_budget(budget_text(b)) == pytest.approx(b)


@pytest.mark.parametrize("text", ["ten", "-3", "0%", "101%", "%", "", "1.5", "nan%"])
def test_bad_budgets_are_refused(text):
    with pytest.raises(ValueError, match="count .* a percentage .*, .auto. or .default."):
        parse_budget(text)


def test_resolve():
    assert resolve_budget(60, 346) == 60                       # a count stays, even above the pool
    assert resolve_budget(0.17, 346) == 59                     # the harness's office budget
    assert resolve_budget(0.001, 20) == 1                      # a fraction never resolves to nothing
    assert resolve_budget(1.0, 43) == 43


@pytest.mark.parametrize("budget,said", [("ten", "--budget wants a count (200), a percentage (15%), 'auto' or "
                                                   "'default', got 'ten'"),
                                          ("1", "--budget 1: choose at least 2 images"), ("0%", "got '0%'")])
def test_cli_refuses_a_bad_budget_in_one_line_before_any_work(tmp_path, capsys, budget, said):
    """The budget is checked once, by its option (RunConfig), whatever the command: one line, exit 2, no folder
    made; whether it fits the registered photos is the plan's (tests/test_house.py)."""
    from curate.cli import main
    (tmp_path / "p.json").write_text("{}")
    for argv in (["select", str(tmp_path / "p.json"), "--out", str(tmp_path / "o1")],
                 ["run", str(tmp_path), "--out", str(tmp_path / "o2")]):
        assert main([*argv, "--budget", budget]) == 2
        err = capsys.readouterr().err
        assert said in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o1").exists() and not (tmp_path / "o2").exists()
