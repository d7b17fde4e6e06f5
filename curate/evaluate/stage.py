"""The evaluate stage: how good is the exported selection, against its rivals? -> ``RUN/evaluate``.

The exported selection is chosen from every registered photo (:mod:`curate.select.stage`), so no photo of it
can be held out to test it. Its quality is estimated as cross-validation estimates a model trained on all the
data, over hold-out folds (:mod:`curate.evaluate.folds`): each fold holds out every ``holdout_every``-th
registered photo from its own offset, the same method (same options) chooses the same share of the photos
left, and the same field is trained on that choice, on random subsets of its size, on farthest-view sampling
(FVS), on every n-th frame (photos in capture order) and on all the photos left, each scored on the fold's
held-out photos. The differences are paired per held-out photo and pooled over the folds. Folds are added
(:mod:`curate.evaluate.schedule`) until every rival is decided (ahead, behind, or level within
``margin_db``), every photo has been held out once, or ``minutes`` are spent; ``--folds N`` trains exactly N.
Each training is a stage of its own (``RUN/evaluate/<unit>/stage.json``), so a killed evaluation resumes, and
a later one with more time reuses them.

``RUN/evaluate/summary.json``, then ``stage.json`` (last, as every stage's): ``key`` (the evaluation's options and the
selection it estimates), ``inputs`` ({"select": its key}: a later selection makes it out of date,
:func:`curate.core.stage.stale_stages`), ``methods``, ``paired``, ``gap_closed``
(:func:`curate.evaluate.folds.summarize`) and ``protocol`` (:func:`protocol`). How many photos ``--budget auto``
exports is measured before the selection, by :mod:`curate.evaluate.budget`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.graph import RunContext

log = logging.getLogger(__name__)

STOPPED = {"decided": "every rival decided", "every photo": "every photo held out once",
           "folds asked": "the folds asked for done", "time": "the time given was spent"}
"""Why the evaluation stopped adding folds (``protocol.stopped``), in words."""


def eval_key(cfg: "RunConfig", run_dir: Path) -> str:
    """The evaluation's key: its options (not the workers) and the selection it estimates."""
    from curate.core.stage import current_key, stage_key
    parts = {"evaluate": replace(cfg.evaluate, workers=0), "select": cfg.select}
    return stage_key(parts, [current_key(run_dir, "select") or "", current_key(run_dir, "sfm") or ""])


def unit_key(cfg: "RunConfig", sfm_key: str, unit, fold) -> str:
    """A training's stage key: the training settings, its subset and its fold's held-out photos."""
    from curate.core.stage import stage_key
    return stage_key({"train": cfg.evaluate.training(), "subset": unit.subset, "holdout": fold.holdout}, [sfm_key])


def protocol(cfg: "RunConfig", folds: list, exported: list[int], n_registered: int, planned: int, looks: list[int],
             level: float, stopped: str, seconds: float) -> dict:
    """``summary.json``'s ``protocol``: the folds (each :meth:`curate.evaluate.folds.Fold.record`), how many were
    planned, when they were looked at and at which level, why it stopped; and, for a reader of one figure, the
    first fold's ``budget``, ``method`` and ``shared_with_export``, ``n_pool`` and the held-out photos of all."""
    ev = cfg.evaluate
    f0 = folds[0]
    return {"holdout_every": ev.holdout_every, "n_registered": n_registered, "exported_budget": len(exported),
            "folds": [f.record(exported) for f in folds], "n_folds": len(folds), "planned_folds": planned,
            "looks": looks, "level": level, "margin_db": ev.margin_db, "minutes": ev.minutes, "stopped": stopped,
            "seconds": round(seconds, 1), "budget": f0.budget, "method": f0.method, "n_pool": len(f0.pool),
            "shared_with_export": f0.record(exported)["shared_with_export"],
            "holdout": sorted(c for f in folds for c in f.holdout)}


def evaluation_current(run_dir: Path, key: str) -> bool:
    """The evaluation finished with ``key`` and its files are there: its summary, its ground truth and every
    training it pooled (each unit's own record and files); an evaluation of an earlier curate, with only its
    ``summary.json`` (or no list of units), by its key alone."""
    from curate.core.stage import finished_record, read_stage, up_to_date
    d = RunPaths(run_dir).evaluate
    if read_stage(d) is None:
        return (finished_record(run_dir, "evaluate") or {}).get("key") == key
    now = up_to_date(d, key)
    if not now.fresh:
        if now.missing:
            log.warning("%s: %s missing: the evaluation is done again (its finished trainings are reused)", d,
                        ", ".join(now.missing[:3]))
        return False
    gone = [u for u in (read_stage(d) or {}).get("units") or () if not up_to_date(d / u, (read_stage(d / u) or
                                                                                          {}).get("key", "")).fresh]
    if gone:
        log.warning("%s: the training(s) %s are incomplete: done again", d, ", ".join(gone[:3]))
    return not gone


def wanted(cfg: "RunConfig", run_dir: Path) -> bool:
    """The stage runs: the run is evaluated (not ``--no-evaluate``)."""
    return cfg.run_evaluation


def run(ctx: "RunContext") -> StageResult:
    """Train the folds' units until decided (finished units are reused) -> ``RUN/evaluate``.

    ``ctx.executor``: a ``concurrent.futures.Executor`` for the trainings (None: local processes).
    """
    from curate.core.stage import finish_stage, inputs_of, write_json_atomic
    from curate.evaluate.folds import (ALL_FOLDS, decided, fold_order, in_capture_order, look_level, looks, plan_fold,
                                       planned_folds, summarize)
    from curate.evaluate.schedule import run_folds
    from curate.evaluate.units import EVAL_OWN, clear_evaluation, eval_cameras, evaluation_folder
    from curate.field.train import default_box
    from curate.core.run import load_node_grid, read_selection
    from curate.sfm.io import image_paths, load_sfm

    t0 = time.perf_counter()
    cfg, run_dir, force, executor = ctx.cfg, ctx.run_dir, ctx.force, ctx.executor
    d = RunPaths(run_dir).evaluate
    ev = cfg.evaluate
    key = eval_key(cfg, run_dir)
    if force:
        kept = clear_evaluation(run_dir)  # only what curate wrote there (curate.core.runfolder)
        if kept:
            log.warning("%s: kept %d file(s) of yours there (%s...): curate removes only what it wrote", d, len(kept),
                        kept[0].relative_to(d).as_posix())
    elif evaluation_current(run_dir, key):
        return StageResult("evaluate", d, False, time.perf_counter() - t0)
    evaluation_folder(run_dir)
    (d / "stage.json").unlink(missing_ok=True)   # an earlier evaluation's record: this one replaces it
    sel = read_selection(run_dir)
    exported = [int(c) for c in sel["chosen"]]
    sfm = load_sfm(run_dir)
    cams = sfm.cameras
    n = len(cams)
    grid = load_node_grid(run_dir)
    ordered = "stride" in ev.methods and in_capture_order(cams, grid.nodes())
    order = fold_order(ev.holdout_every, n)[:planned_folds(ev, n)]
    if not order:
        raise ValueError(f"no photo to hold out from {n} registered photos: register more photos")
    adaptive = ev.folds == 0
    look_at, level = looks(len(order), adaptive), look_level(adaptive, len(order))
    from curate.core.stage import current_key
    sfm_key = current_key(run_dir, "sfm") or ""

    def make_fold(offset: int):
        return plan_fold(ev, cfg.select, cams, grid, len(exported), offset, ordered,
                         with_all=order.index(offset) < ALL_FOLDS)

    def stop_at(folds, res) -> bool:
        return decided(summarize(res, folds, level, ev.margin_db)[1])

    def keyed(u, f):
        return unit_key(cfg, sfm_key, u, f)
    paths = image_paths(run_dir, list(cams.names), sfm.records)
    folds, res, stopped = run_folds(run_dir, ev, make_fold, order, look_at, stop_at, eval_cameras(cams, ev.max_side),
                                    paths, default_box(cams), keyed, adaptive, executor=executor)
    if stopped == "all folds" or (stopped == "decided" and not adaptive):   # --folds N: all N ran, as asked
        stopped = "every photo" if len(order) == min(ev.holdout_every, n) else "folds asked"
    methods, paired, gap = summarize(res, folds, level, ev.margin_db)
    seconds = time.perf_counter() - t0
    summary = {"key": key, "inputs": inputs_of(run_dir, "evaluate"), "methods": methods, "paired": paired,
               "gap_closed": gap,
               "protocol": protocol(cfg, folds, exported, n, len(order), look_at, level, stopped, seconds)}
    write_json_atomic(d / "summary.json", summary)
    finish_stage(d, key, {"evaluate": replace(ev, workers=0), "select": cfg.select}, t0,
                 outputs={"summary": "summary.json"}, owns=EVAL_OWN, stopped=stopped, n_folds=len(folds),
                 units=sorted(u.key for f in folds for u in f.units))
    txt = ", ".join(f"{m} {v['psnr']:.2f}" for m, v in methods.items())
    views = sum(len(f.holdout) for f in folds)
    return StageResult("evaluate", d, True, seconds,
                       f"{len(folds)} of {len(order)} folds ({views} held-out photos; {STOPPED[stopped]}); "
                       f"held-out PSNR {txt}")

