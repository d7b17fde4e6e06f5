"""The occupancy stage: the hold-out split, the pool field and the selection's node grid -> ``RUN/occupancy``.

Writes ``split.json`` (``{"holdout_every", "holdout": [camera indices], "pool": [indices]}``:
every later stage reads the split from here), ``field.pt`` + ``train.json`` (the field
trained on the pool; also the evaluation's all-images ceiling) and ``occupancy.npz``
(``box_min`` [3], ``box_max`` [3], ``res``, ``points_mask`` [R,R,R] bool from the sparse
points (all False without points), ``refined_mask`` [R,R,R] bool confirmed by the field,
``nodes_mask`` [R,R,R] bool: the surface band used as selection nodes).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig

log = logging.getLogger(__name__)


def key_of(stage_dir: Path) -> str:
    """The key of a finished stage (FileNotFoundError when it has not finished)."""
    from curate.core.stage import read_stage
    rec = read_stage(stage_dir)
    if rec is None:
        raise FileNotFoundError(f"{stage_dir}: stage not finished")
    return rec["key"]


def surface_band(mask: np.ndarray, k: int) -> np.ndarray:
    """[R,R,R] bool: occupied nodes next to free space, widened by ``k`` voxels each side."""
    from curate.occupancy.masks import dilate
    if not mask.any():
        return mask
    interior = ~dilate(~mask, 1)
    shell = mask & ~interior
    return dilate(shell, k) if k > 0 else shell


def read_split(run_dir: Path) -> dict:
    """``RUN/occupancy/split.json``: ``holdout_every``, ``holdout`` and ``pool`` (camera indices)."""
    p = Path(run_dir) / "occupancy" / "split.json"
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no hold-out split yet (run the occupancy stage first)")
    return json.loads(p.read_text())


def load_split(run_dir: Path):
    """(sfm result, image path of every registered camera, pool indices, held-out indices), the split
    as the occupancy stage wrote it."""
    from curate.sfm.io import image_paths, load_sfm
    sfm = load_sfm(run_dir)
    paths = image_paths(run_dir, list(sfm.cameras.names), sfm.records)
    split = read_split(run_dir)
    return sfm, paths, list(split["pool"]), list(split["holdout"])


def load_node_grid(run_dir: Path):
    """The selection's NodeGrid (box, resolution, node band mask) from ``RUN/occupancy``."""
    from curate.core.grid import NodeGrid
    z = np.load(Path(run_dir) / "occupancy" / "occupancy.npz")
    return NodeGrid(z["box_min"], z["box_max"], int(z["res"]), z["nodes_mask"])


def check_budget_fits(text: str, n_budget: int, n_pool: int) -> None:
    """ValueError unless the budget ``text`` (resolved to ``n_budget``) leaves something to choose from
    a pool of ``n_pool`` images: at least 2 images, fewer than the whole pool."""
    if n_budget < 2:
        raise ValueError(f"budget {text} is {n_budget} image(s) of a pool of {n_pool}: choose at least 2")
    if n_budget >= n_pool:
        raise ValueError(f"budget {text} is {n_budget} images, the whole pool of {n_pool} (after the hold-out) "
                         "or more: nothing to choose; give a smaller budget")


def train_settings(cfg: "RunConfig") -> dict:
    """The pool field's training settings (part of the stage key)."""
    ev = cfg.evaluate
    return {"field": ev.field, "iters": ev.iters, "time_budget_s": ev.time_budget_s, "max_side": ev.max_side,
            "train_seed": ev.train_seed, "holdout_every": ev.holdout_every}


def needs_field(cfg: "RunConfig", cams, n_points: int) -> tuple[bool, str]:
    """(train the pool field?, why). The field serves the evaluation (its all-images ceiling) and
    refines the occupancy the paper's energy scores; path spacing, view medoids, FVS, every n-th frame and
    random need neither. So with the evaluation off, the field is trained only for the energy
    on a capture whose SfM points cannot give its occupancy (a pose import without points)."""
    from curate.select.select import resolve_method
    if cfg.run_evaluation:
        return True, "the evaluation's all-images field"
    method, _ = resolve_method(cams, cfg.select.method)
    if method == "energy" and n_points < cfg.occupancy.min_points:
        return True, "the energy needs an occupancy the sparse points cannot give"
    return False, f"not needed: {method} without evaluation (occupancy from the sparse points)"


def run(cfg: "RunConfig", run_dir: Path, force: bool = False) -> StageResult:
    """Split, pool field (when needed: :func:`needs_field`) and occupancy grid (points, refined,
    node band) -> ``RUN/occupancy``."""
    from curate.core.budget import AUTO, parse_budget, resolve_budget
    from curate.core.grid import NodeGrid
    from curate.core.stage import begin_stage, finish_stage, is_fresh, stage_key, write_json_atomic
    from curate.core.stats import holdout_split
    from curate.evaluate.units import eval_cameras
    from curate.field.train import default_box, train_field
    from curate.occupancy.masks import occupancy_from_points, refine_occupancy
    from curate.sfm.io import image_paths, load_sfm

    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    d = run_dir / "occupancy"
    ev = cfg.evaluate
    sfm = load_sfm(run_dir)
    field_needed, why = needs_field(cfg, sfm.cameras, 0 if sfm.points is None else len(sfm.points))
    parts = {"occupancy": cfg.occupancy, "refine": cfg.refine, "band": cfg.surface_band, "train": train_settings(cfg)}
    if cfg.box is not None:
        parts["box"] = list(cfg.box)
    deps = [key_of(run_dir / "sfm")]
    key_field = stage_key(parts, deps)
    if not field_needed and not force and is_fresh(d, key_field):
        return StageResult("occupancy", d, False, time.perf_counter() - t0)  # one with the field serves too
    train_part = parts["train"] if field_needed else None
    key = key_field if field_needed else stage_key({**parts, "train": None}, deps)
    if begin_stage(d, key, force):
        return StageResult("occupancy", d, False, time.perf_counter() - t0)
    paths = image_paths(run_dir, list(sfm.cameras.names), sfm.records)
    pool, hold = (v.tolist() for v in holdout_split(len(sfm.cameras), ev.holdout_every))
    if len(pool) < 2:
        raise ValueError(f"only {len(pool)} registered images left for the pool after holding out every "
                         f"{ev.holdout_every}th")
    b = parse_budget(cfg.budget)
    if b == AUTO:                                     # chosen from the pool by the select stage
        if len(pool) < 3:
            raise ValueError(f"budget auto: a pool of {len(pool)} images leaves nothing to choose")
    else:
        check_budget_fits(cfg.budget, resolve_budget(b, len(pool)), len(pool))
    write_json_atomic(d / "split.json", {"holdout_every": ev.holdout_every, "holdout": hold, "pool": pool})
    box = default_box(sfm.cameras)
    fld = st = None
    if field_needed:
        cams = eval_cameras(sfm.cameras, ev.max_side)
        fld, st = train_field(ev.field, cams[pool], [paths[i] for i in pool], d, time_budget_s=ev.time_budget_s,
                              iters=ev.iters, seed=ev.train_seed, box=box)
        write_json_atomic(d / "train.json", {"iters": st.iters, "train_seconds": st.train_seconds,
                                             "stop_reason": st.stop_reason, "n_train": len(pool)})
    else:
        log.info("occupancy: no pool field (%s)", why)
    R = cfg.occupancy.res
    user_box = (np.array(cfg.box[:3]), np.array(cfg.box[3:])) if cfg.box is not None else None
    try:
        grid = occupancy_from_points(sfm.points, sfm.cameras, cfg.occupancy, box=user_box)
        pts_mask = grid.mask
    except ValueError as e:  # no or too few points (e.g. a transforms.json import): the field alone
        log.info("occupancy from points unavailable (%s): the field's density alone", e)
        lo, hi = user_box if user_box is not None else box
        grid = NodeGrid(lo, hi, R)
        pts_mask = None
    if fld is not None:
        refined = refine_occupancy(fld, grid, cfg=cfg.refine if pts_mask is not None
                                   else replace(cfg.refine, mode="field"))
        rmask = refined.mask
    else:
        rmask = pts_mask if pts_mask is not None else np.ones((R,) * 3, bool)
    if not rmask.any():
        log.warning("the field confirms no occupied node: using the point occupancy (or every node)")
        rmask = pts_mask if pts_mask is not None else np.ones((R,) * 3, bool)
    band = surface_band(rmask, cfg.surface_band)
    np.savez_compressed(d / "occupancy.npz", box_min=grid.box_min, box_max=grid.box_max, res=R,
                        points_mask=pts_mask if pts_mask is not None else np.zeros((R,) * 3, bool),
                        refined_mask=rmask, nodes_mask=band)
    n = {"points": int(pts_mask.sum()) if pts_mask is not None else 0, "refined": int(rmask.sum()),
         "nodes": int(band.sum())}
    outputs = {"occupancy": "occupancy.npz", "split": "split.json", **({"field": "field.pt"} if fld is not None else {})}
    finish_stage(d, key, {"occupancy": cfg.occupancy, "refine": cfg.refine, "train": train_part, "box": cfg.box}, t0,
                 outputs=outputs, seed=ev.train_seed, counts=n, field=why,
                 train={"iters": st.iters, "train_seconds": st.train_seconds} if st is not None else None)
    return StageResult("occupancy", d, True, time.perf_counter() - t0,
                       f"{n['refined']} occupied nodes of {R}^3 ({n['points']} from points), "
                       f"{n['nodes']} selection nodes; " + (f"pool field {st.iters} it" if st is not None
                                                            else "no pool field (not needed)"))
