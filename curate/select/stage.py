"""The select stage: choose the budget from every registered photo -> ``RUN/select``.

The selection is a function of the capture and of the options that define a selection, never of
the evaluation: it chooses among all registered photos, with or without ``--no-evaluate``
(the evaluation estimates its quality by choosing again with frames held out:
:mod:`curate.evaluate.stage`).

``selection.json`` and ``nodes.npz``: :mod:`curate.select.record` (one schema, also for ``curate select POSES``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from curate.core.paths import RunPaths

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from curate.core.graph import RunContext
    from curate.core.runner import Done, Keyed


def key(ctx: "RunContext") -> "Keyed":
    """The stage's key (:attr:`curate.core.graph.Stage.key`): the selection's options and the budget as the run
    gives it (with ``auto``, the tolerance and the budget the budget stage measured on this capture, when it did).
    ``state``: (the run's plan, :mod:`curate.core.plan`; the measurement or None)."""
    from curate.core.plan import plan_of_run
    from curate.core.runner import Keyed
    cfg, run_dir = ctx.cfg, ctx.run_dir
    plan = plan_of_run(cfg, run_dir)
    parts = {"select": cfg.select, "budget": plan.budget}
    measured = None
    if plan.n_budget is None:
        from curate.core.budget import measured_budget
        parts["budget_tolerance"] = cfg.budget_tolerance
        measured = measured_budget(cfg, run_dir)     # how many, measured on this capture (evaluated runs)
        if measured is not None:
            parts["measured"] = measured["budget"]
    return Keyed(parts, state=(plan, measured))


def choose(ctx: "RunContext", keyed: "Keyed") -> "Done":
    """Selection among every registered photo -> ``RUN/select``."""
    from curate.core.runner import Done
    from curate.core.stage import write_json_atomic, writing
    from curate.core.run import load_node_grid
    from curate.select.energy import energy_of_subset
    from curate.select.record import coverage, selection_record
    from curate.select.select import select
    from curate.select.visibility import build_pair_index
    from curate.sfm.io import load_sfm

    cfg, run_dir = ctx.cfg, ctx.run_dir
    d = RunPaths(run_dir).select
    plan, measured = keyed.state
    sfm = load_sfm(run_dir)
    pool = list(range(len(sfm.cameras)))
    budget = plan.n_budget          # checked by the plan to leave something to choose; None: auto
    grid = load_node_grid(run_dir)
    pc = sfm.cameras[pool]
    t_vis = time.perf_counter()
    index = build_pair_index(pc, grid.nodes(), cfg.select.energy.bins, device=cfg.select.device, progress=True)
    t_vis = time.perf_counter() - t_vis
    auto = None
    if budget is None:
        from curate.select.auto_budget import choose_for_pool
        auto = choose_for_pool(pc, grid.nodes(), index, cfg.budget_tolerance)
        budget = auto.budget if measured is None else measured["budget"]
        log.info("%s", auto.note)
    if plan.method_note:
        log.info("select %s", plan.method_note)
    sel = select(pc, grid, budget, replace(cfg.select, method=plan.method), progress=True, index=index)
    sel.note = "; ".join(n for n in (plan.method_note, sel.note) if n)
    sel.seconds += t_vis  # the selection's time, visibility included (as when select builds it)
    terms = energy_of_subset(index, sel.chosen, cfg.select.energy, per_node=True)
    with writing(d / "nodes.npz"):
        np.savez_compressed(d / "nodes.npz", nodes=grid.nodes(), angular=terms.angular_per_node,
                            frequency=terms.frequency_per_node, flat=np.flatnonzero(grid.mask.reshape(-1)),
                            res=grid.res, box_min=grid.box_min, box_max=grid.box_max)
    rec = selection_record(sel, sfm.cameras, pool, [], 0, plan.budget_said, grid)
    rec["coverage"] = coverage(index, sel.chosen)
    if auto is not None:   # the law's prediction; with the measurement, what was measured and exported
        rec["budget_auto"] = {**auto.to_dict(), "predicted": auto.budget, "source": "law" if measured is None else
                              "measured", **({"measured": measured["check"]} if measured is not None else {})}
        rec["budget_auto"]["budget"] = budget
    write_json_atomic(d / "selection.json", rec)
    from curate.select.methods import method_label
    how = method_label(sel.method) + (" (auto)" if cfg.select.method == "auto" else "")
    why = (f"; {auto.note}" if measured is None else
           f"; budget auto: {budget} measured on this capture (the law predicted {auto.budget})") if auto else ""
    cov = rec["coverage"]
    sees = (f"; they see {100 * cov['seen']:.0f}% of the scene the capture sees" if cov["n_nodes_seen"] else "")
    return Done(f"{len(rec['chosen'])} of {len(pool)} photos by {how}{sees}; {sel.seconds:.2f}s{why}",
                {"selection": "selection.json", "nodes": "nodes.npz"}, seed=cfg.select.seed)
