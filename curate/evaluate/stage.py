"""The evaluate stage: the same field trained on every subset, scored on the held-out views -> ``RUN/evaluate``.

Units: the selection, ``random_seeds`` random subsets of the same size, farthest-view
sampling, and all pool images (the pool field of ``RUN/occupancy``). Each unit is a stage
of its own (``RUN/evaluate/<unit>/stage.json``), so a killed evaluation resumes; the
summary is ``RUN/evaluate/summary.json``. See :mod:`curate.evaluate.units`.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig


def eval_units(cfg: "RunConfig", run_dir: Path):
    """The evaluation units of this run, their stage keys and the selection record."""
    from curate.core.stage import stage_key
    from curate.evaluate.units import Unit
    from curate.occupancy.stage import key_of
    from curate.select.baselines import farthest_view, random_subset
    from curate.select.stage import read_selection
    from curate.sfm.io import load_sfm
    sel = read_selection(run_dir)
    pool, chosen = sel["pool"], sel["chosen"]
    cams = load_sfm(run_dir).cameras
    ev = cfg.evaluate
    units = []
    for m in ev.methods:
        if m == "selection":
            units.append(Unit("selection", "selection", None, chosen))  # whatever its method
        elif m == "random":
            for s in range(ev.random_seeds):
                units.append(Unit(f"random_s{s}", "random", s,
                                  [pool[k] for k in random_subset(len(pool), len(chosen), s)]))
        elif m == "fvs":
            units.append(Unit("fvs", "fvs", None, [pool[k] for k in farthest_view(cams[pool], len(chosen))]))
        elif m == "all":
            units.append(Unit("all", "all", None, list(pool)))
        else:
            raise ValueError(f"unknown evaluation method {m!r}")
    # the key: training settings + the subset + the held-out views (+ the pool field for 'all')
    train = replace(ev, workers=0, methods=(), random_seeds=0)
    sfm_key = key_of(run_dir / "sfm")
    occ_key = key_of(run_dir / "occupancy")
    keys = {u.key: stage_key({"train": train, "subset": u.subset, "holdout": sel["holdout"]},
                             [sfm_key] + ([occ_key] if u.key == "all" else [])) for u in units}
    return units, keys, sel


def run(cfg: "RunConfig", run_dir: Path, force: bool = False, executor=None) -> StageResult:
    """Train every unit (finished units are skipped) -> ``RUN/evaluate``.

    ``executor``: a ``concurrent.futures.Executor`` for the trainings (None: local processes).
    """
    from curate.core.stage import is_fresh, write_json_atomic
    from curate.evaluate.units import clear_evaluation, eval_cameras, run_units, summarize
    from curate.field.train import default_box
    from curate.occupancy.stage import load_split

    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    d = run_dir / "evaluate"
    units, keys, sel = eval_units(cfg, run_dir)
    if force:
        clear_evaluation(run_dir)  # only what curate wrote there (curate.core.runfolder)
    fresh = all(is_fresh(d / u.key, keys[u.key]) for u in units)
    sfm, paths, pool, hold = load_split(run_dir)
    if not hold:
        raise ValueError("no held-out views: set holdout_every >= 2 and register enough images")
    cams = eval_cameras(sfm.cameras, cfg.evaluate.max_side)
    pool_field = run_dir / "occupancy" / "field.pt"   # absent when the run skipped it (no evaluation): 'all' trains
    fp = {"all": str(pool_field)} if pool_field.is_file() else {}
    res = run_units(run_dir, units, keys, cfg.evaluate, cams, paths, hold, default_box(sfm.cameras), fp,
                    executor=executor)
    methods, paired, gap = summarize(res)
    write_json_atomic(d / "summary.json", {"methods": methods, "paired": paired, "gap_closed": gap})
    label = f"selection ({sel['method']})"
    txt = ", ".join(f"{label if m == 'selection' else m} {v['psnr']:.2f}" for m, v in methods.items())
    return StageResult("evaluate", d, not fresh, time.perf_counter() - t0,
                       f"held-out PSNR: {txt} ({len(hold)} views)")
