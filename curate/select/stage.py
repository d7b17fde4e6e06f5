"""The select stage: choose the budget from every registered photo -> ``RUN/select``.

The selection is a function of the capture and of the options that define a selection, never of
the evaluation: it chooses among all registered photos, with or without ``--no-evaluate``
(the evaluation estimates its quality by choosing again with frames held out:
:mod:`curate.evaluate.stage`).

``selection.json`` has one schema, written by :func:`selection_record` for a run folder
and for ``curate select`` on a pose file alike: ``method`` (what ran), ``budget`` (the
resolved count), ``budget_text`` (as given; ``default`` with what it meant for this capture, "default: 15%
(a walk-through)"), ``pool`` (the candidates: every registered camera)
and ``holdout`` (empty: kept for older readers), ``holdout_every`` (0),
``chosen`` (camera indices in the order chosen), ``chosen_names``,
per-step ``energy`` / ``angular`` / ``frequency``, ``seconds``, ``n_nodes``, ``up_axis``,
``note``, ``box`` / ``res`` of the node grid, ``coverage`` (:func:`coverage`), and with
``--budget auto`` ``budget_auto`` (:class:`curate.select.auto_budget.BudgetChoice`: the predicted
loss curve and why). ``nodes.npz``: ``nodes`` [M,3], per-node
``angular`` and ``frequency`` of the chosen set, ``flat`` [M] grid indices, ``res``,
``box_min``, ``box_max``. Camera indices are into ``RUN/sfm/cameras.json``.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from curate.core.paths import RunPaths
from curate.core.stage import StageResult

log = logging.getLogger(__name__)

if TYPE_CHECKING:
    from curate.core.graph import RunContext
    from curate.core.cameras import Cameras
    from curate.core.grid import NodeGrid
    from curate.select.select import Selection


def up_axis(cams: "Cameras") -> int:
    """World axis closest to the cameras' mean up direction (-y of OpenCV cameras)."""
    up = -cams.c2w[:, :3, 1].mean(0)
    return int(np.argmax(np.abs(up)))


def coverage(index, chosen) -> dict:
    """How much of what the whole capture sees the chosen cameras see: over the scene's surface
    nodes seen by at least one camera of the pool (``index``: its pair index), the fraction seen by
    at least one (``seen``) and at least two (``seen_twice``) of ``chosen`` (pool indices).
    {"seen", "seen_twice", "n_nodes_seen"}; fractions are 0 when the pool sees no node."""
    cams = np.asarray(index.cam, np.int64)                                   # [P]
    node_of = np.repeat(np.arange(index.n_nodes), np.diff(index.indptr))     # [P]
    pick = np.zeros(index.n_cams, bool)
    pick[np.asarray(list(chosen), np.int64)] = True
    by_pool = np.bincount(node_of, minlength=index.n_nodes)                  # [M] cameras seeing each node
    by_chosen = np.bincount(node_of[pick[cams]], minlength=index.n_nodes)    # [M] chosen cameras seeing it
    n = int((by_pool > 0).sum())
    frac = (lambda m: float(m.sum() / n) if n else 0.0)
    return {"seen": frac(by_chosen >= 1), "seen_twice": frac(by_chosen >= 2), "n_nodes_seen": n}


def selection_record(sel: "Selection", cams: "Cameras", pool: list[int], holdout: list[int], holdout_every: int,
                     budget_text: str, grid: "NodeGrid") -> dict:
    """The ``selection.json`` record of ``sel`` (chosen indices into ``pool``) over all cameras ``cams``."""
    chosen = [int(pool[k]) for k in sel.chosen]
    return {**sel.to_dict(), "chosen": chosen, "initial": [], "chosen_names": [cams.names[i] for i in chosen],
            "budget": len(chosen), "budget_text": budget_text, "holdout_every": holdout_every,
            "holdout": list(holdout), "pool": list(pool), "n_nodes": len(grid.active_indices()),
            "up_axis": up_axis(cams), "res": int(grid.res), "box": grid.box_min.tolist() + grid.box_max.tolist()}


KIND_WORDS = {"walk": "a walk-through", "object": "an object capture"}


def budget_of_run(text: str, run_dir: Path) -> tuple[str, str]:
    """(the budget that applies to the run's registered photos, how it reads in a report): ``default``
    by the capture's kind (:func:`curate.core.budget.by_kind`, the kind from ``RUN/sfm/cameras.json``);
    any other budget as given, twice."""
    from curate.core.budget import DEFAULT, parse_budget
    if parse_budget(text) != DEFAULT:
        return str(text), str(text)
    from curate.core.cameras import Cameras
    from curate.sfm.io import sfm_dir
    return budget_of_pool(text, Cameras.load(sfm_dir(run_dir) / "cameras.json"))


def budget_of_pool(text: str, cams: "Cameras") -> tuple[str, str]:
    """:func:`budget_of_run` for a pool of cameras (``curate select POSES``)."""
    from curate.core.budget import DEFAULT, by_kind, parse_budget
    if parse_budget(text) != DEFAULT:
        return str(text), str(text)
    from curate.select.methods import capture_kind
    kind = capture_kind(cams)[0]
    b = by_kind(text, kind)
    return b, f"{DEFAULT}: {b} ({KIND_WORDS[kind]})"


def run(ctx: "RunContext") -> StageResult:
    """Selection among every registered photo -> ``RUN/select``."""
    from curate.core.budget import AUTO, check_fits, parse_budget, resolve_budget
    from curate.core.graph import BY_NAME
    from curate.core.stage import begin_stage, finish_stage, required_key, stage_key, write_json_atomic, writing
    from curate.occupancy.stage import load_node_grid
    from curate.select.energy import energy_of_subset
    from curate.select.select import select
    from curate.select.visibility import build_pair_index
    from curate.sfm.io import load_sfm

    t0 = time.perf_counter()
    cfg, run_dir, force = ctx.cfg, ctx.run_dir, ctx.force
    d = RunPaths(run_dir).select
    text, said = budget_of_run(cfg.budget, run_dir)
    b = parse_budget(text)
    parts = {"select": cfg.select, "budget": text}
    measured = None
    if b == AUTO:
        from curate.core.budget import measured_budget
        parts["budget_tolerance"] = cfg.budget_tolerance
        measured = measured_budget(cfg, run_dir)     # how many, measured on this capture (evaluated runs)
        if measured is not None:
            parts["measured"] = measured["budget"]
    key = stage_key(parts, [required_key(run_dir, "occupancy")])
    if begin_stage(d, key, force, owns=BY_NAME["select"].owns):
        return StageResult("select", d, False, time.perf_counter() - t0)
    sfm = load_sfm(run_dir)
    pool = list(range(len(sfm.cameras)))
    if b != AUTO:
        budget = resolve_budget(b, len(pool))
        check_fits(said, budget, len(pool))
    grid = load_node_grid(run_dir)
    pc = sfm.cameras[pool]
    t_vis = time.perf_counter()
    index = build_pair_index(pc, grid.nodes(), cfg.select.energy.bins, device=cfg.select.device, progress=True)
    t_vis = time.perf_counter() - t_vis
    auto = None
    if b == AUTO:
        from curate.select.auto_budget import choose_for_pool
        auto = choose_for_pool(pc, grid.nodes(), index, cfg.budget_tolerance)
        budget = auto.budget if measured is None else measured["budget"]
        log.info("%s", auto.note)
    sel = select(pc, grid, budget, cfg.select, progress=True, index=index)
    sel.seconds += t_vis  # the selection's time, visibility included (as when select builds it)
    terms = energy_of_subset(index, sel.chosen, cfg.select.energy, per_node=True)
    with writing(d / "nodes.npz"):
        np.savez_compressed(d / "nodes.npz", nodes=grid.nodes(), angular=terms.angular_per_node,
                            frequency=terms.frequency_per_node, flat=np.flatnonzero(grid.mask.reshape(-1)),
                            res=grid.res, box_min=grid.box_min, box_max=grid.box_max)
    rec = selection_record(sel, sfm.cameras, pool, [], 0, said, grid)
    rec["coverage"] = coverage(index, sel.chosen)
    if auto is not None:   # the law's prediction; with the measurement, what was measured and exported
        rec["budget_auto"] = {**auto.to_dict(), "predicted": auto.budget, "source": "law" if measured is None else
                              "measured", **({"measured": measured["check"]} if measured is not None else {})}
        rec["budget_auto"]["budget"] = budget
    write_json_atomic(d / "selection.json", rec)
    finish_stage(d, key, parts, t0,
                 outputs={"selection": "selection.json", "nodes": "nodes.npz"}, seed=cfg.select.seed,
                 owns=BY_NAME["select"].owns)
    from curate.select.methods import method_label
    how = method_label(sel.method) + (" (auto)" if cfg.select.method == "auto" else "")
    why = (f"; {auto.note}" if measured is None else
           f"; budget auto: {budget} measured on this capture (the law predicted {auto.budget})") if auto else ""
    cov = rec["coverage"]
    sees = (f"; they see {100 * cov['seen']:.0f}% of the scene the capture sees" if cov["n_nodes_seen"] else "")
    return StageResult("select", d, True, time.perf_counter() - t0,
                       f"{len(rec['chosen'])} of {len(pool)} photos by {how}{sees}; {sel.seconds:.2f}s{why}")


def read_selection(run_dir: Path) -> dict:
    """``RUN/select/selection.json``."""
    p = RunPaths(run_dir).selection
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no selection yet (run `curate select RUN` first)")
    try:
        rec = json.loads(p.read_text())
    except ValueError as e:                 # truncated, not JSON, not UTF-8
        raise ValueError(f"{p}: not a selection record of curate ({e}); `curate select {run_dir}` writes it "
                         "again") from None
    if not isinstance(rec, dict):
        raise ValueError(f"{p}: not a selection record of curate")
    return rec
