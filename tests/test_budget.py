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


def test_cli_refuses_a_bad_budget(capsys):
    from curate.cli import build_parser
    with pytest.raises(SystemExit):
        build_parser().parse_args(["select", "x.json", "--budget", "ten"])
    assert "--budget wants a count" in capsys.readouterr().err
