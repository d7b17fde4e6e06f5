"""The budget stage: how many photos this capture needs, measured on the capture itself -> ``RUN/budget``.

``--budget auto`` predicts a budget from the poses alone, with a law fitted on other captures
(:mod:`curate.select.auto_budget`); a capture may need more (exposure changes, blur, texture, pose error: what
the law never sees). When the run is evaluated, this stage measures it before anything is chosen: on the first
two hold-out folds (:func:`curate.evaluate.folds.fold_order`), the selection's method chooses about half, once
and twice the law's advice, the same field as the evaluation's is trained on each and on all the photos left,
and the losses against all photos, paired per held-out photo over the two folds, are fitted
(:func:`curate.evaluate.check.fit_check`). The select stage then exports the measured budget
(:func:`curate.core.budget.measured_budget`), and the evaluation estimates that export; the law's prediction is kept
beside it. The trainings are evaluation units (``RUN/evaluate/f<offset>_curve_b<k>``, ``f<offset>_all``: the
evaluation reuses the latter).

``RUN/budget/budget.json``: ``predicted`` (the law's :class:`curate.select.auto_budget.BudgetChoice`),
``check`` (:class:`curate.evaluate.check.BudgetCheck`, with ``n_pool``: the folds' pool size its points are
counted in), ``budget`` (what the selection exports).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.budget import MEASURED_FOLDS, measured_parts

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.graph import RunContext
    from curate.core.runner import Done, Keyed


def wanted(cfg: "RunConfig", run_dir: Path) -> bool:
    """The stage runs: ``--budget auto`` (or ``default`` on an object capture) on an evaluated run with the
    check on. False while the run has no poses to tell the kind of capture by."""
    from curate.core.plan import plan_of_run
    if not (cfg.run_evaluation and cfg.budget_check):
        return False
    try:
        return plan_of_run(cfg, run_dir).n_budget is None
    except (FileNotFoundError, ValueError):        # no poses yet to plan by, or a budget that does not fit
        return False


def key(ctx: "RunContext") -> "Keyed":
    """The stage's key (:attr:`curate.core.graph.Stage.key`): :func:`curate.core.budget.measured_parts`."""
    from curate.core.runner import Keyed
    return Keyed(measured_parts(ctx.cfg))


def measure(ctx: "RunContext", keyed: "Keyed") -> "Done":
    """Measure the learning curve of the selection's method on the first folds -> ``RUN/budget``."""
    import numpy as np
    from dataclasses import replace

    from curate.core.plan import plan_of_run
    from curate.core.runner import Done
    from curate.core.stage import current_key, stage_key, write_json_atomic
    from curate.evaluate.check import fit_check
    from curate.evaluate.folds import curve_fold, curve_points, fold_order
    from curate.evaluate.schedule import run_folds
    from curate.evaluate.units import eval_cameras
    from curate.field.train import default_box
    from curate.core.run import load_node_grid
    from curate.select.auto_budget import LOSS_MODEL, choose_for_pool, pool_views
    from curate.select.spacing import spacing_curve
    from curate.select.visibility import build_pair_index
    from curate.sfm.io import image_paths, load_sfm

    cfg, run_dir, executor = ctx.cfg, ctx.run_dir, ctx.executor
    d = RunPaths(run_dir).budget
    ev = cfg.evaluate
    sfm = load_sfm(run_dir)
    cams = sfm.cameras
    grid = load_node_grid(run_dir)
    nodes = grid.nodes()
    index = build_pair_index(cams, nodes, cfg.select.energy.bins, device=cfg.select.device)
    law = choose_for_pool(cams, nodes, index, cfg.budget_tolerance)
    order = fold_order(ev.holdout_every, len(cams))[:MEASURED_FOLDS]
    sfm_key = current_key(run_dir, "sfm") or ""

    def keyed(u, f):   # as the evaluation keys its units: a shared one ('all') is trained once
        return stage_key({"train": ev.training(), "subset": u.subset, "holdout": f.holdout}, [sfm_key])
    chosen_by = replace(cfg.select, method=plan_of_run(cfg, run_dir).method)   # the exported selection's method
    folds, res, _ = run_folds(run_dir, ev, lambda o: curve_fold(ev, chosen_by, cams, grid, law.budget, o), order,
                              [len(order)], lambda f, r: False, eval_cameras(cams, ev.max_side),
                              image_paths(run_dir, list(cams.names), sfm.records), default_box(cams), keyed, False,
                              executor=executor)
    n_pool = int(np.median([len(f.pool) for f in folds]))

    def rho(c):
        return spacing_curve(*pool_views(c, nodes, build_pair_index(c, nodes, cfg.select.energy.bins)))[1]
    rho_pool = rho(cams[folds[0].pool])
    points = [{**p, "rho": float(rho_pool[min(p["k"], len(rho_pool)) - 1])} for p in curve_points(res, folds)]
    check = fit_check(points, LOSS_MODEL[law.kind][1], rho(cams), cfg.budget_tolerance, len(cams) / n_pool)
    budget = check.budget if check.budget is not None else check.high
    budget = int(min(max(budget if budget is not None else law.budget, 2), len(cams) - 1))
    write_json_atomic(d / "budget.json", {"predicted": law.to_dict(), "check": {**check.to_dict(), "n_pool": n_pool},
                                          "budget": budget})
    return Done(f"{budget} of {len(cams)} photos to export: {check.note} (the law predicted {law.budget})",
                {"budget": "budget.json"}, config={"tolerance": cfg.budget_tolerance, "train": ev.training()},
                record={"units": [u.key for f in folds for u in f.units]})
