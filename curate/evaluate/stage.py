"""The evaluate stage: how good is the exported selection? -> ``RUN/evaluate``.

The exported selection is chosen from every registered photo (:mod:`curate.select.stage`), so no
photo of it can be held out to test it. Its quality is estimated as cross-validation estimates a
model trained on all the data: every ``holdout_every``-th registered photo is held out, the same
method (same options) chooses the same fraction of the photos left, and the same field is trained
on that choice, on ``random_seeds`` random subsets of its size, on farthest-view sampling (FVS) of
its size and on all the photos left, each scored on the held-out photos
(:mod:`curate.evaluate.units`). Each unit is a stage of its own (``RUN/evaluate/<unit>/stage.json``),
so a killed evaluation resumes.

``RUN/evaluate/summary.json``: ``key`` (of this evaluation: settings and units), ``inputs``
({"select": the key of the selection it estimates}: a later selection makes it out of date,
:func:`curate.core.stage.stale_stages`), ``methods``, ``paired``, ``gap_closed``
(:func:`curate.evaluate.units.summarize`) and ``protocol`` (:func:`plan`: the split, the budgets,
the estimate's own subset and how many of its photos the exported selection shares).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig


def eval_budget(n_exported: int, n_all: int, n_pool: int) -> int:
    """The estimate's budget: the exported fraction ``n_exported / n_all`` of the ``n_pool`` photos
    left after the hold-out, rounded, at least 2 and fewer than ``n_pool``."""
    k = int(round(n_exported * n_pool / max(n_all, 1)))
    return int(min(max(k, 2), max(n_pool - 1, 2)))


@dataclass
class Plan:
    """What the evaluation trains: its units, their stage keys and the protocol record."""

    units: list
    """[curate.evaluate.units.Unit]: selection, random_s<k>, fvs, all."""
    keys: dict
    """{unit key: stage key}."""
    protocol: dict
    """``holdout_every``, ``holdout`` and ``pool`` (camera indices), ``n_registered``, ``budget`` (the
    estimate's), ``exported_budget``, ``method`` (what the estimate's selection ran), ``chosen`` (its
    camera indices), ``shared_with_export`` (how many of them the exported selection has too)."""
    key: str
    """The evaluation's key: its settings and every unit's key."""


def plan(cfg: "RunConfig", run_dir: Path) -> Plan:
    """The evaluation of the run's exported selection (see the module docstring)."""
    from curate.core.stage import stage_key
    from curate.core.stats import holdout_split
    from curate.evaluate.units import Unit
    from curate.occupancy.stage import key_of, load_node_grid
    from curate.select.baselines import farthest_view, random_subset
    from curate.select.select import select
    from curate.select.stage import read_selection
    from curate.sfm.io import load_sfm
    ev = cfg.evaluate
    exported = read_selection(run_dir)
    cams = load_sfm(run_dir).cameras
    n_all = len(cams)
    pool, hold = (v.tolist() for v in holdout_split(n_all, ev.holdout_every))
    if not hold:
        raise ValueError(f"no photo to hold out from {n_all} registered photos: register more photos, or lower "
                         "--holdout-every (at least 2)")
    if len(pool) < 3:
        raise ValueError(f"only {len(pool)} registered photos left after holding out every {ev.holdout_every}th: "
                         "too few to evaluate (use --no-evaluate)")
    k = eval_budget(len(exported["chosen"]), n_all, len(pool))
    grid = load_node_grid(run_dir)
    sel = select(cams[pool], grid, k, cfg.select)
    chosen = [pool[i] for i in sel.chosen]
    units = []
    for m in ev.methods:
        if m == "selection":
            units.append(Unit("selection", "selection", None, chosen))  # whatever its method
        elif m == "random":
            units += [Unit(f"random_s{s}", "random", s, [pool[i] for i in random_subset(len(pool), k, s)])
                      for s in range(ev.random_seeds)]
        elif m == "fvs":
            units.append(Unit("fvs", "fvs", None, [pool[i] for i in farthest_view(cams[pool], k)]))
        elif m == "all":
            units.append(Unit("all", "all", None, list(pool)))
        else:
            raise ValueError(f"unknown evaluation method {m!r}")
    check = []
    if exported.get("budget_auto") and cfg.budget_check and "all" in ev.methods:
        from curate.evaluate.check import check_budgets
        for b in check_budgets(k, len(pool)):   # the same method at other budgets: the loss curve here
            units.append(Unit(f"check_b{b}", "check", None, [pool[i] for i in select(cams[pool], grid, b,
                                                                                     cfg.select).chosen]))
            check.append(b)
    # a unit's key: the training settings, its subset and the held-out views
    train = replace(ev, workers=0, methods=(), random_seeds=0)
    sfm_key = key_of(run_dir / "sfm")
    keys = {u.key: stage_key({"train": train, "subset": u.subset, "holdout": hold}, [sfm_key]) for u in units}
    protocol = {"holdout_every": ev.holdout_every, "holdout": hold, "pool": pool, "n_registered": n_all,
                "budget": k, "exported_budget": len(exported["chosen"]), "method": sel.method, "chosen": chosen,
                "shared_with_export": len(set(chosen) & set(exported["chosen"])), "check_budgets": check}
    return Plan(units, keys, protocol, stage_key({"units": keys, "protocol": protocol}))


def budget_check(cfg: "RunConfig", run_dir: Path, cams, protocol: dict, res: dict):
    """The measured check (:mod:`curate.evaluate.check`) from the trained units ``res``: the loss of the
    estimate's selection and of the check's budgets against all photos, on the split's held-out photos."""
    from curate.core.stats import paired_difference
    from curate.evaluate.check import fit_check
    from curate.occupancy.stage import load_node_grid
    from curate.select.auto_budget import LOSS_MODEL, pool_views
    from curate.select.spacing import spacing_curve
    from curate.select.stage import read_selection
    from curate.select.visibility import build_pair_index
    nodes = load_node_grid(run_dir).nodes()
    bins = cfg.select.energy.bins

    def curve(c):
        return spacing_curve(*pool_views(c, nodes, build_pair_index(c, nodes, bins)))[1]
    pool = protocol["pool"]
    rho_pool, rho_full = curve(cams[pool]), curve(cams)
    all_pv = [v["psnr"] for v in res["all"]["per_view"]]
    points = []
    for key, r in res.items():
        if r["method"] in ("check", "selection"):
            d = paired_difference(all_pv, [v["psnr"] for v in r["per_view"]])
            points.append({"k": r["n_train"], "rho": float(rho_pool[r["n_train"] - 1]), "loss": d["mean"],
                           "lo": d["lo"], "hi": d["hi"]})
    auto = read_selection(run_dir)["budget_auto"]
    return fit_check(sorted(points, key=lambda x: x["k"]), LOSS_MODEL[auto["kind"]][1], rho_full,
                     auto["tolerance_db"], len(cams) / len(pool))


def run(cfg: "RunConfig", run_dir: Path, force: bool = False, executor=None) -> StageResult:
    """Train every unit of :func:`plan` (finished units are skipped) -> ``RUN/evaluate``.

    ``executor``: a ``concurrent.futures.Executor`` for the trainings (None: local processes).
    """
    from curate.core.stage import current_key, inputs_of, is_fresh, write_json_atomic
    from curate.evaluate.units import clear_evaluation, eval_cameras, run_units, summarize
    from curate.field.train import default_box
    from curate.sfm.io import image_paths, load_sfm

    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    d = run_dir / "evaluate"
    p = plan(cfg, run_dir)
    if force:
        clear_evaluation(run_dir)  # only what curate wrote there (curate.core.runfolder)
    fresh = current_key(run_dir, "evaluate") == p.key and all(is_fresh(d / u.key, p.keys[u.key]) for u in p.units)
    sfm = load_sfm(run_dir)
    paths = image_paths(run_dir, list(sfm.cameras.names), sfm.records)
    cams = eval_cameras(sfm.cameras, cfg.evaluate.max_side)
    hold = p.protocol["holdout"]
    res = run_units(run_dir, p.units, p.keys, cfg.evaluate, cams, paths, hold, default_box(sfm.cameras),
                    executor=executor)
    methods, paired, gap = summarize({k: v for k, v in res.items() if v["method"] != "check"})
    summary = {"key": p.key, "inputs": inputs_of(run_dir, "evaluate"), "methods": methods, "paired": paired,
               "gap_closed": gap, "protocol": p.protocol}
    if p.protocol["check_budgets"] and "all" in res and "selection" in res:
        summary["budget_check"] = budget_check(cfg, run_dir, sfm.cameras, p.protocol, res).to_dict()
    write_json_atomic(d / "summary.json", summary)
    pr = p.protocol
    order = ("selection", "random", "fvs", "all")      # as the report lists them
    txt = ", ".join(f"{m} {methods[m]['psnr']:.2f}" for m in sorted(methods, key=lambda m: (
        order.index(m) if m in order else len(order), m)))
    return StageResult("evaluate", d, not fresh, time.perf_counter() - t0,
                       f"estimate: {pr['method']} chose {pr['budget']} of {len(pr['pool'])} with {len(hold)} held out; "
                       f"held-out PSNR {txt}")
