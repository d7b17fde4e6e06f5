"""The occupancy stage: where the scene is, and the selection's node grid -> ``RUN/occupancy``.

Writes ``occupancy.npz`` (``box_min`` [3], ``box_max`` [3], ``res``, ``points_mask`` [R,R,R] bool
from the sparse points (all False without points), ``refined_mask`` [R,R,R] bool (the field's
refinement when one was trained, else the points' mask), ``nodes_mask`` [R,R,R] bool: the surface
band used as selection nodes) and, when a field is needed (:attr:`curate.core.plan.Plan.field`), ``field.pt`` +
``train.json``: a field trained on every registered photo. The stage depends on the capture and
its options only, never on the evaluation: a run with and without ``--no-evaluate`` gets the same
grid, hence the same selection. (The hold-out split belongs to the evaluation stage.)
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from curate.core.paths import RunPaths
from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.graph import RunContext
    from curate.core.runner import Done, Keyed

log = logging.getLogger(__name__)


def surface_band(mask: np.ndarray, k: int, outside_free: bool = False) -> np.ndarray:
    """[R,R,R] bool: occupied nodes next to free space, widened by ``k`` voxels each side.
    ``outside_free``: space outside the grid counts as free (a full grid's surface is then its outer
    shell: the box's walls); otherwise as occupied."""
    from curate.occupancy.masks import dilate
    if not mask.any():
        return mask
    if outside_free:
        pad = np.pad(mask, 1, constant_values=False)
        return surface_band(pad, k)[1:-1, 1:-1, 1:-1]
    interior = ~dilate(~mask, 1)
    shell = mask & ~interior
    return dilate(shell, k) if k > 0 else shell


def train_settings(cfg: "RunConfig") -> dict:
    """The refining field's training settings (part of the stage key): its own iterations and image size
    (:class:`curate.occupancy.masks.RefineConfig`), :class:`curate.field.config.FieldConfig`'s own settings (not
    the evaluation's cheaper field, :func:`curate.evaluate.config.evaluation_field`: this one is for the scene's
    surface), the evaluation's training seed."""
    from curate.field.config import FieldConfig
    ev = cfg.evaluate
    return {"field": FieldConfig(), "iters": cfg.refine.iters, "time_budget_s": ev.time_budget_s,
            "max_side": cfg.refine.max_side, "train_seed": ev.train_seed}


def key(ctx: "RunContext") -> "Keyed":
    """The stage's key (:attr:`curate.core.graph.Stage.key`): :func:`occupancy_parts` of the run."""
    return occupancy_parts(ctx.cfg, ctx.run_dir)


def occupancy_parts(cfg: "RunConfig", run_dir: Path, train_on: Sequence[int] | None = None) -> "Keyed":
    """What the occupancy's key holds: its options, the box, the cameras the field trains on (``train_on``), and
    the field's training settings only when the plan needs a field (:attr:`curate.core.plan.Plan.field`; a grid
    refined by a field serves a run that needs none). ``state``: (whether a field is needed, why). Nothing of the SfM
    result is read here: a stage that is up to date is skipped on its key alone."""
    from curate.core.plan import plan_of_run
    from curate.core.runner import Keyed
    plan = plan_of_run(cfg, run_dir)
    field_needed, why = plan.field, plan.field_why
    parts = {"occupancy": cfg.occupancy, "refine": cfg.refine, "band": cfg.surface_band, "train": train_settings(cfg)}
    if cfg.box is not None:
        parts["box"] = list(cfg.box)
    if train_on is not None:
        parts["train_on"] = [int(i) for i in train_on]
    if field_needed:
        return Keyed(parts, state=(True, why))
    return Keyed({**parts, "train": None}, serves=parts, state=(False, why))


def occupancy(cfg: "RunConfig", run_dir: Path, force: bool = False, train_on: Sequence[int] | None = None
              ) -> StageResult:
    """Field (when the plan needs one: :attr:`curate.core.plan.Plan.field`) and occupancy grid (points, refined,
    node band) -> ``RUN/occupancy``, through the stage runner. ``train_on``: the cameras the field trains on (None:
    every registered one; the research harness passes a hold-out fold's pool)."""
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_keyed
    return run_keyed(BY_NAME["occupancy"], RunContext(cfg, run_dir, force),
                     key_of=lambda ctx: occupancy_parts(ctx.cfg, ctx.run_dir, train_on))


def compute(ctx: "RunContext", keyed: "Keyed") -> "Done":
    """The stage's computation: the field trained on every registered photo (or on the key's ``train_on``) when
    one is needed, and the grid -> ``RUN/occupancy``."""
    from curate.core.grid import NodeGrid
    from curate.core.runner import Done
    from curate.core.stage import write_json_atomic, writing
    from curate.field.train import default_box, train_field
    from curate.occupancy.masks import occupancy_from_points, refine_occupancy
    from curate.sfm.io import image_paths, load_sfm

    cfg, run_dir = ctx.cfg, Path(ctx.run_dir)
    d = RunPaths(run_dir).occupancy
    ev = cfg.evaluate
    sfm = load_sfm(run_dir)
    field_needed, why = keyed.state
    train_on = keyed.parts.get("train_on")
    train_part = keyed.parts["train"]
    box = default_box(sfm.cameras)
    fld = st = None
    if field_needed:
        log.info("occupancy: training a field (%s)", why)
        paths = image_paths(run_dir, list(sfm.cameras.names), sfm.records)
        on = list(range(len(sfm.cameras))) if train_on is None else [int(i) for i in train_on]
        cams = sfm.cameras.at_most(cfg.refine.max_side)
        fld, st = train_field(train_part["field"], cams[on], [paths[i] for i in on], d, time_budget_s=ev.time_budget_s,
                              iters=cfg.refine.iters, seed=ev.train_seed, box=box, progress_desc="occupancy (field)")
        write_json_atomic(d / "train.json", {"iters": st.iters, "train_seconds": st.train_seconds,
                                             "stop_reason": st.stop_reason, "n_train": len(on)})
    else:
        log.info("occupancy: no field (%s)", why)
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
    # nothing says where the scene is (no points, no field): its surface is taken as the box's walls
    band = surface_band(rmask, cfg.surface_band, outside_free=bool(rmask.all()))
    with writing(d / "occupancy.npz"):
        np.savez_compressed(d / "occupancy.npz", box_min=grid.box_min, box_max=grid.box_max, res=R,
                            points_mask=pts_mask if pts_mask is not None else np.zeros((R,) * 3, bool),
                            refined_mask=rmask, nodes_mask=band)
    n = {"points": int(pts_mask.sum()) if pts_mask is not None else 0, "refined": int(rmask.sum()),
         "nodes": int(band.sum())}
    outputs = {"occupancy": "occupancy.npz", **({"field": "field.pt"} if fld is not None else {})}
    src = "refined by a field" if fld is not None else ("from the sparse points" if pts_mask is not None
                                                         else "unknown (no points, no field): the box's walls")
    return Done(f"scene occupancy {src} ({n['refined']} of {R}^3 cells), {n['nodes']} surface nodes"
                + (f"; field trained on {st.iters} iterations" if st is not None else ""), outputs,
                config={"occupancy": cfg.occupancy, "refine": cfg.refine, "train": train_part, "box": cfg.box},
                seed=ev.train_seed, record={"counts": n, "field": why, "train": {
                    "iters": st.iters, "train_seconds": st.train_seconds} if st is not None else None})
