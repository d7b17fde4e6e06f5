"""Budgets: how many images to choose, as a count ("60"), a fraction of the pool ("15%") or
"auto" (the fewest predicted within a tolerance of all frames: :mod:`curate.select.auto_budget`).

Light (no heavy imports): the CLI, the pipeline and the benchmark scripts share it.
"""

from __future__ import annotations


AUTO = "auto"
"""The budget chosen from the pool (``--budget auto``)."""


def parse_budget(text) -> int | float | str:
    """'200' -> 200 (a count); '15%' -> 0.15 (a fraction of the pool, in (0, 1]); 'auto' -> AUTO.

    Raises ValueError on anything else (negative counts, 0% or over 100%, other words).
    """
    t = str(text).strip()
    if t.lower() == AUTO:
        return AUTO
    try:
        if t.endswith("%"):
            f = float(t[:-1]) / 100.0
            if not 0 < f <= 1:
                raise ValueError
            return f
        n = int(t)
        if n < 0:
            raise ValueError
        return n
    except ValueError:
        raise ValueError(f"a budget is a count (200), a percentage (15%) or 'auto', got {text!r}") from None


def budget_text(budget: int | float | str) -> str:
    """The inverse of :func:`parse_budget`: 200 -> '200', 0.15 -> '15%', AUTO -> 'auto'."""
    return f"{budget * 100:g}%" if isinstance(budget, float) else str(budget)


def resolve_budget(budget: int | float, n_pool: int) -> int:
    """A count stays; a fraction becomes round(fraction * pool), at least 1. AUTO is chosen from the
    pool's views by :func:`curate.select.auto_budget.choose_budget`, not here (ValueError)."""
    if budget == AUTO:
        raise ValueError("budget 'auto' is chosen from the pool's views (curate.select.auto_budget), not resolved")
    if isinstance(budget, float):
        return max(1, int(round(budget * n_pool)))
    return int(budget)
