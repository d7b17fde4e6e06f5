"""Budgets: how many images to choose, as a count ("60"), a fraction of the pool ("15%"), "auto"
(the fewest predicted within a tolerance of all frames: :mod:`curate.select.auto_budget`) or
"default" (one of those by the kind of capture: :data:`DEFAULT_BY_KIND`).

Light (no heavy imports): the CLI, the pipeline and the benchmark scripts share it.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.reads import read_json

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.cameras import Cameras


AUTO = "auto"
"""The budget chosen from the pool (``--budget auto``)."""

DEFAULT = "default"
"""The budget by the kind of capture (:func:`by_kind`), known once the cameras are posed."""

DEFAULT_BY_KIND = {"walk": "15%", "object": AUTO}
"""What ``default`` means for each kind of capture (``curate.select.methods.capture_kind``): a walk-through
keeps 15% of its frames; an object capture keeps what ``auto`` advises, most of a capture of 40-60
photos (measured on the three real object sets: 34-48 of 40-57, docs/evaluation.md#how-many),
where 15% kept 10 of 65 skull photos."""


def parse_budget(text) -> int | float | str:
    """'200' -> 200 (a count); '15%' -> 0.15 (a fraction of the pool, in (0, 1]); 'auto' -> AUTO;
    'default' -> DEFAULT.

    Raises ValueError on anything else (negative counts, 0% or over 100%, other words).
    """
    t = str(text).strip()
    if t.lower() in (AUTO, DEFAULT):
        return t.lower()
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
        raise ValueError(f"a budget is a count (200), a percentage (15%), 'auto' or 'default', got {text!r}") from None


def budget_text(budget: int | float | str) -> str:
    """The inverse of :func:`parse_budget`: 200 -> '200', 0.15 -> '15%', AUTO -> 'auto'."""
    return f"{budget * 100:g}%" if isinstance(budget, float) else str(budget)


def by_kind(text: str, kind: str) -> str:
    """The budget ``text`` that applies to a capture of ``kind`` ("walk" | "object"): ``default`` becomes
    :data:`DEFAULT_BY_KIND`'s entry, any other budget stays as given."""
    return DEFAULT_BY_KIND[kind] if parse_budget(text) == DEFAULT else str(text)


def resolve_budget(budget: int | float, n_pool: int) -> int:
    """A count stays; a fraction becomes round(fraction * pool), at least 1. AUTO is chosen from the
    pool's views by :func:`curate.select.auto_budget.choose_budget`, not here (ValueError)."""
    if budget == DEFAULT:
        raise ValueError("budget 'default' depends on the kind of capture (by_kind), not resolved")
    if budget == AUTO:
        raise ValueError("budget 'auto' is chosen from the pool's views (curate.select.auto_budget), not resolved")
    if isinstance(budget, float):
        return max(1, int(round(budget * n_pool)))
    return int(budget)


def check_fits(said: str, n_budget: int, n_pool: int, what: str = "registered photos") -> None:
    """ValueError unless the budget ``said`` (as the user gave it, resolved to ``n_budget``) leaves something
    to choose from ``n_pool`` candidates (``what`` they are): at least 2, fewer than all of them. The one
    check of a resolved budget (the pipeline, the select stage, ``curate select POSES``)."""
    if n_budget > n_pool:
        raise ValueError(f"budget {said} is more than all {n_pool} {what}: nothing to choose; give a smaller budget")
    if n_budget == n_pool:
        raise ValueError(f"budget {said} is all {n_pool} {what}: nothing to choose; give a smaller budget")
    if n_budget < 2:
        raise ValueError(f"budget {said} is {n_budget} of the {n_pool} {what}: choose at least 2")


KIND_WORDS = {"walk": "a walk-through", "object": "an object capture"}
"""How a report names each kind of capture (``curate.select.methods.capture_kind``)."""


def budget_of_pool(text: str, cams: "Cameras") -> tuple[str, str]:
    """(the budget that applies to the pool ``cams``, how it reads in a report): ``default`` by the capture's kind
    (:func:`by_kind`); any other budget as given, twice. A run's: :attr:`curate.core.plan.Plan.budget`; ``curate
    select POSES``'s: its cameras'."""
    if parse_budget(text) != DEFAULT:
        return str(text), str(text)
    from curate.select.methods import capture_kind
    kind = capture_kind(cams)[0]
    b = by_kind(text, kind)
    return b, f"{DEFAULT}: {b} ({KIND_WORDS[kind]})"


MEASURED_FOLDS = 2
"""Hold-out folds the budget stage measures the learning curve on (:mod:`curate.evaluate.budget`)."""


def measured_parts(cfg: "RunConfig") -> dict:
    """The options the budget stage's key holds: the tolerance, the selection's options, the trainings' settings
    (beside the keys of the scene: occupancy and SfM, :data:`curate.core.graph.STAGES`)."""
    return {"tolerance": cfg.budget_tolerance, "select": cfg.select, "train": cfg.evaluate.training(),
            "holdout_every": cfg.evaluate.holdout_every, "folds": MEASURED_FOLDS}


def measured_key(cfg: "RunConfig", run_dir: str | Path) -> str:
    """The budget stage's key (:func:`measured_parts` and the scene's keys), as the stage runner computes it."""
    from curate.core.graph import BY_NAME
    from curate.core.stage import current_key, stage_key
    return stage_key(measured_parts(cfg), [current_key(run_dir, s) or "" for s in BY_NAME["budget"].keyed_on])


def measured_budget(cfg: "RunConfig", run_dir: str | Path) -> dict | None:
    """``RUN/budget/budget.json`` when the budget stage measured it for these options on this scene (its key is
    :func:`measured_key`'s) and the curve gave a budget, else None: the select stage then uses the law."""
    from curate.core.stage import read_stage
    rec = read_stage(RunPaths(run_dir).budget)
    if not rec or rec.get("key") != measured_key(cfg, run_dir):
        return None
    try:
        out = read_json(RunPaths(run_dir).budget_json)
    except (OSError, ValueError):
        return None
    chk = out.get("check") or {}
    return out if chk.get("budget") is not None or chk.get("high") is not None else None   # no curve: the law
