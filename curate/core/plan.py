"""The run's plan: what a run decides once its cameras are known, decided once (issue 60, item 3).

After SfM, the capture's kind (:func:`curate.select.methods.capture_kind`: a walk-through or an object capture),
the method that ``auto`` becomes (:func:`curate.select.methods.resolve_method`), the budget that applies (``default``
by the kind; a count or a percentage resolved on the registered photos and checked to leave something to choose,
:func:`curate.core.budget.check_fits`) and whether the occupancy trains a field (:func:`field_needed`) are decided
here, once per run folder and options (:func:`plan_of_run`, kept while the SfM result and those options are the
same). The pipeline makes it right after SfM, before any training (a budget that does not fit stops the run there);
the occupancy, the budget stage, the selection, every fold of the evaluation and the report read it; the report
records it (``report.json`` ``plan``).

What is not in it: whether the photos are in capture order (every n-th frame as a rival), which needs the scene's
depth from the occupancy grid (:func:`curate.evaluate.folds.in_capture_order`), and what ``auto`` measures (the
budget stage's curve).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from curate.core.paths import RunPaths

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.cameras import Cameras


@dataclasses.dataclass(frozen=True)
class Plan:
    """What a run decided once its cameras were known."""

    n_registered: int
    """Registered photos: the pool the budget is of."""
    kind: Literal["walk", "object"]
    """The kind of capture (:func:`curate.select.methods.capture_kind`)."""
    kind_angle_deg: float
    """The cameras' median angle to their nearest common point, in degrees (small: an object capture)."""
    method: str
    """The selection method that runs (``auto`` resolved)."""
    method_note: str
    """Why ``auto`` became :attr:`method` ("" when the method was given)."""
    budget: str
    """The budget that applies (``default`` resolved by :attr:`kind`): a count, a percentage or ``auto``."""
    budget_said: str
    """The budget as a report says it (``default: 15% (a walk-through)``)."""
    n_budget: int | None
    """The budget as a count of the registered photos, checked to leave something to choose; None for ``auto``
    (chosen from the pool by the law, or measured by the budget stage)."""
    field: bool
    """The occupancy trains a field to refine the scene's surface."""
    field_why: str
    """Why (or why not)."""

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def field_needed(refine_field: str, method: str, n_points: int, min_points: int) -> tuple[bool, str]:
    """(train a field to refine the occupancy?, why). Never for the evaluation: the same in both modes.
    ``refine_field`` 'always': yes; 'auto': only for the paper's energy (it scores the scene's surface) when the
    sparse points are too few to give it (poses without points). Path spacing and view medoids read only a look-at
    depth from the occupancy (every node of the box without points); FVS, every n-th frame and random read the poses
    only. ``method``: the method that runs (``auto`` resolved)."""
    if refine_field == "always":
        return True, "--refine field always"
    if method != "energy":
        return False, f"not needed: {method} needs no surface"
    if n_points < min_points:
        return True, f"the energy scores the scene's surface, and {n_points} sparse points cannot give it"
    return False, f"not needed: the energy's surface comes from the {n_points} sparse points"


def make_plan(cfg: "RunConfig", cams: "Cameras", n_points: int) -> Plan:
    """The plan of a run with options ``cfg`` whose SfM registered ``cams`` with ``n_points`` sparse points.
    ValueError (one line, as the budget was given) when the budget leaves nothing to choose."""
    from curate.core.budget import AUTO, budget_of_pool, check_fits, parse_budget, resolve_budget
    from curate.select.methods import capture_kind, resolve_method
    n = len(cams)
    kind, angle = capture_kind(cams)
    method, note = resolve_method(cams, cfg.select.method, (kind, angle))
    text, said = budget_of_pool(cfg.budget, cams)
    b = parse_budget(text)
    if b == AUTO:
        if n < 3:
            raise ValueError(f"budget {said}: {n} registered photos leave nothing to choose")
        n_budget = None
    else:
        n_budget = resolve_budget(b, n)
        check_fits(said, n_budget, n)
    field, why = field_needed(cfg.refine.field, method, n_points, cfg.occupancy.min_points)
    return Plan(n, kind, round(float(angle), 3), method, note, text, said, n_budget, field, why)


_PLANS: dict[tuple, Plan] = {}
"""Plans made in this process, by run folder, SfM result and the options they depend on."""


def plan_of_run(cfg: "RunConfig", run_dir: str | Path) -> Plan:
    """:func:`make_plan` for the run folder's SfM result, made once while that result (its key) and the options
    the plan depends on stay the same."""
    from curate.core.run import load_cameras
    from curate.core.stage import read_stage
    rec = read_stage(RunPaths(run_dir).sfm) or {}
    memo = (str(Path(run_dir).resolve()), rec.get("key"), cfg.budget, cfg.select.method, cfg.refine.field,
            cfg.occupancy.min_points)
    if memo[1] is not None and memo in _PLANS:
        return _PLANS[memo]
    cams = load_cameras(run_dir)
    n_points = (rec.get("stats") or {}).get("n_points")
    if n_points is None:         # a record without the count: the points file says it
        import numpy as np
        p = RunPaths(run_dir).sfm / "points.npy"
        n_points = int(np.load(p, mmap_mode="r").shape[0]) if p.is_file() else 0
    plan = make_plan(cfg, cams, int(n_points))
    if memo[1] is not None:
        _PLANS[memo] = plan
    return plan
