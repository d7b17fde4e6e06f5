"""``curate run``: photos -> SfM -> occupancy -> selection -> evaluation -> report -> export.

Each stage is a plain function ``stage_x(cfg, run_dir, ..., force) -> Path`` writing its
own folder of the run (``RUN/<stage>/``, a ``stage.json`` record last). A stage's key
hashes its resolved config with the keys of the stages it reads, so a re-run skips a
stage whose inputs and options did not change, and redoes everything downstream of a
change. Run-folder contract (besides ``RUN/sfm/``, see :mod:`curate.sfm.colmap`):

* ``RUN/occupancy/``: ``occupancy.npz`` (``box_min`` [3], ``box_max`` [3], ``res``,
  ``points_mask`` [R,R,R] bool (from the sparse points; all False without points),
  ``refined_mask`` [R,R,R] bool (confirmed by the field), ``nodes_mask`` [R,R,R] bool
  (the surface band used as selection nodes)); ``field.pt`` + ``train.json``: the field
  trained on the whole pool (it also serves as the 'all' ceiling of the evaluation);
  ``split.json``: ``{"holdout_every", "holdout": [camera indices], "pool": [indices]}``.
* ``RUN/select/``: ``selection.json`` (``method``, ``budget``, ``holdout_every``,
  ``holdout``, ``pool``, ``chosen`` (camera indices in the order chosen),
  ``chosen_names``, per-step ``energy`` / ``angular`` / ``frequency``, ``seconds``,
  ``n_nodes``, ``up_axis``, ``sharpness``: [pool] image sharpness when view medoids used
  it, else null) and ``nodes.npz`` (``nodes`` [M,3], per-node ``angular``
  and ``frequency`` of the chosen set, ``flat`` [M] grid indices, ``res``, ``box_min``,
  ``box_max``).
* ``RUN/evaluate/``: see :mod:`curate.evaluate.units`.
* ``RUN/report.json``, ``RUN/report.html``: see :func:`stage_report`.
* ``RUN/export/``: see :mod:`curate.export.subset`.

Camera indices are into ``RUN/sfm/cameras.json`` (registered cameras, sorted by name).
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from curate.evaluate.units import EvalConfig
from curate.occupancy.masks import OccupancyConfig, RefineConfig
from curate.select.select import SelectConfig
from curate.sfm.config import SfmConfig

log = logging.getLogger(__name__)


@dataclass
class RunConfig:
    """Every option of ``curate run``."""

    budget: str = "15%"
    """Images to choose: a count ('60') or a fraction of the pool ('15%')."""
    sfm: SfmConfig = field(default_factory=SfmConfig)
    """SfM stage options."""
    occupancy: OccupancyConfig = field(default_factory=OccupancyConfig)
    """Occupancy from the sparse points; ``occupancy.res`` is also the selection's node grid."""
    refine: RefineConfig = field(default_factory=RefineConfig)
    """Refinement of the occupancy by the pool field's density."""
    surface_band: int = 1
    """Selection nodes: the refined occupied set's surface, widened by this many voxels on each side."""
    select: SelectConfig = field(default_factory=SelectConfig)
    """Selection method and energy."""
    evaluate: EvalConfig = field(default_factory=EvalConfig)
    """Evaluation protocol (hold-out split, trainings)."""
    run_evaluation: bool = True
    """Train and score the subsets (off: selection, report and export only)."""
    export_mode: str = "link"
    """'link' (symlinks to the original photos) or 'copy'."""


def _key_of(stage_dir: Path) -> str:
    from curate.core.stage import read_stage
    rec = read_stage(stage_dir)
    if rec is None:
        raise FileNotFoundError(f"{stage_dir}: stage not finished")
    return rec["key"]


def _summary(name: str, t0: float, skipped: bool, text: str, timings: list | None) -> None:
    dt = time.perf_counter() - t0
    if timings is not None:
        timings.append({"name": name, "seconds": round(dt, 2), "skipped": skipped})
    print(f"{name:10s} {'skipped (unchanged)' if skipped else text}  [{dt:.1f}s]", flush=True)


# ------------------------------------------------------------------------ inputs
def image_paths(run_dir: Path, names: list[str], records: dict) -> list[str]:
    """The image file of each registered camera: the SfM working copy, else the original photo."""
    by: dict[str, tuple[str, dict]] = {}
    for r in records.get("photos", []):
        if r.get("working"):
            by[r["working"]] = ("working", r)
        if r.get("rel"):
            by.setdefault(r["rel"], ("original", r))
    out = []
    for n in names:
        if n not in by:
            raise FileNotFoundError(f"no photo recorded for camera {n!r} in {run_dir}/sfm/images.json")
        kind, r = by[n]
        out.append(str(run_dir / "sfm" / "images" / n) if kind == "working" else r["original"])
    return out


def photo_sharpness(run_dir: Path, sfm, idx: list[int]) -> np.ndarray:
    """[len(idx)] image sharpness of the photos of cameras ``idx``: as the SfM stage recorded
    it (``sfm/images.json``), else measured now (imported poses); NaN when unreadable."""
    from curate.sfm.quality import files_sharpness
    by: dict[str, float] = {}
    for r in sfm.records.get("photos", []):
        v = (r.get("extra") or {}).get("sharpness")
        for k in (r.get("working"), r.get("rel")):
            if k and v is not None:
                by[k] = float(v)
    names = [sfm.cameras.names[i] for i in idx]
    out = np.array([by.get(n, np.nan) for n in names], np.float64)
    miss = np.flatnonzero(~np.isfinite(out))
    if len(miss):
        paths = image_paths(run_dir, names, sfm.records)
        out[miss] = files_sharpness([paths[i] for i in miss], progress=True)
    return out


def load_split(run_dir: Path, every: int):
    """Registered cameras, their image paths, (pool, holdout) indices, sfm result."""
    from curate.sfm.io import load_sfm
    from curate.core.stats import holdout_split
    sfm = load_sfm(run_dir)
    paths = image_paths(run_dir, list(sfm.cameras.names), sfm.records)
    pool, hold = holdout_split(len(sfm.cameras), every)
    if len(pool) < 2:
        raise ValueError(f"only {len(pool)} registered images left for the pool after the hold-out")
    return sfm, paths, pool.tolist(), hold.tolist()


def up_axis(cams) -> int:
    """World axis closest to the cameras' mean up direction (-y of OpenCV cameras)."""
    up = -cams.c2w[:, :3, 1].mean(0)
    return int(np.argmax(np.abs(up)))


def surface_band(mask: np.ndarray, k: int) -> np.ndarray:
    """[R,R,R] bool: occupied nodes next to free space, widened by ``k`` voxels each side."""
    from curate.occupancy.masks import dilate
    if not mask.any():
        return mask
    interior = ~dilate(~mask, 1)
    shell = mask & ~interior
    return dilate(shell, k) if k > 0 else shell


# ------------------------------------------------------------------------ stages
def stage_occupancy(cfg: RunConfig, run_dir: Path, force: bool = False, timings: list | None = None) -> Path:
    """Pool field + occupancy grid (points, refined, node band) -> ``RUN/occupancy``."""
    from curate.evaluate.units import eval_cameras
    from curate.core.grid import NodeGrid
    from curate.occupancy.masks import occupancy_from_points, refine_occupancy
    from curate.core.stage import begin_stage, finish_stage, stage_key, write_json_atomic
    from curate.field.train import default_box, train_field

    t0 = time.perf_counter()
    d = run_dir / "occupancy"
    ev = cfg.evaluate
    train_part = {"field": ev.field, "iters": ev.iters, "time_budget_s": ev.time_budget_s, "max_side": ev.max_side,
                  "train_seed": ev.train_seed, "holdout_every": ev.holdout_every}
    key = stage_key({"occupancy": cfg.occupancy, "refine": cfg.refine, "band": cfg.surface_band, "train": train_part},
                    [_key_of(run_dir / "sfm")])
    if begin_stage(d, key, force):
        _summary("occupancy", t0, True, "", timings)
        return d
    sfm, paths, pool, hold = load_split(run_dir, ev.holdout_every)
    cams = eval_cameras(sfm.cameras, ev.max_side)
    box = default_box(sfm.cameras)
    fld, st = train_field(ev.field, cams[pool], [paths[i] for i in pool], d, time_budget_s=ev.time_budget_s,
                          iters=ev.iters, seed=ev.train_seed, box=box)
    write_json_atomic(d / "train.json", {"iters": st.iters, "train_seconds": st.train_seconds,
                                         "stop_reason": st.stop_reason, "n_train": len(pool)})
    R = cfg.occupancy.res
    try:
        grid = occupancy_from_points(sfm.points, sfm.cameras, cfg.occupancy)
        pts_mask = grid.mask
    except ValueError as e:  # no or too few points (e.g. a transforms.json import): the field alone
        log.info("occupancy from points unavailable (%s): the field's density alone", e)
        grid = NodeGrid(box[0], box[1], R)
        pts_mask = None
    refined = refine_occupancy(fld, grid, cfg=cfg.refine if pts_mask is not None else replace(cfg.refine, mode="field"))
    rmask = refined.mask
    if not rmask.any():
        log.warning("the field confirms no occupied node: using the point occupancy (or every node)")
        rmask = pts_mask if pts_mask is not None else np.ones((R,) * 3, bool)
    band = surface_band(rmask, cfg.surface_band)
    np.savez_compressed(d / "occupancy.npz", box_min=grid.box_min, box_max=grid.box_max, res=R,
                        points_mask=pts_mask if pts_mask is not None else np.zeros((R,) * 3, bool),
                        refined_mask=rmask, nodes_mask=band)
    write_json_atomic(d / "split.json", {"holdout_every": ev.holdout_every, "holdout": hold, "pool": pool})
    n = {"points": int(pts_mask.sum()) if pts_mask is not None else 0, "refined": int(rmask.sum()),
         "nodes": int(band.sum())}
    finish_stage(d, key, {"occupancy": cfg.occupancy, "refine": cfg.refine, "train": train_part}, t0,
                 outputs={"occupancy": "occupancy.npz", "field": "field.pt", "split": "split.json"},
                 seed=ev.train_seed, counts=n, train={"iters": st.iters, "train_seconds": st.train_seconds})
    _summary("occupancy", t0, False, f"{n['refined']} occupied nodes of {R}^3 ({n['points']} from points), "
             f"{n['nodes']} selection nodes; pool field {st.iters} it", timings)
    return d


def load_node_grid(run_dir: Path):
    """The selection's NodeGrid (box, resolution, node band mask) from ``RUN/occupancy``."""
    from curate.core.grid import NodeGrid
    z = np.load(run_dir / "occupancy" / "occupancy.npz")
    return NodeGrid(z["box_min"], z["box_max"], int(z["res"]), z["nodes_mask"])


def stage_select(cfg: RunConfig, run_dir: Path, force: bool = False, timings: list | None = None) -> Path:
    """Greedy selection over the pool -> ``RUN/select``."""
    from curate.select.energy import energy_of_subset
    from curate.select.select import select, uses_sharpness
    from curate.core.stage import begin_stage, finish_stage, stage_key, write_json_atomic
    from curate.select.visibility import build_pair_index

    t0 = time.perf_counter()
    d = run_dir / "select"
    key = stage_key({"select": cfg.select, "budget": cfg.budget}, [_key_of(run_dir / "occupancy")])
    if begin_stage(d, key, force):
        _summary("select", t0, True, "", timings)
        return d
    from curate.core.budget import parse_budget, resolve_budget
    from curate.sfm.io import load_sfm
    sfm = load_sfm(run_dir)
    split = json.loads((run_dir / "occupancy" / "split.json").read_text())
    pool = split["pool"]
    grid = load_node_grid(run_dir)
    budget = resolve_budget(parse_budget(cfg.budget), len(pool))
    pc = sfm.cameras[pool]
    t_vis = time.perf_counter()
    index = build_pair_index(pc, grid.nodes(), cfg.select.energy.bins, device=cfg.select.device, progress=True)
    t_vis = time.perf_counter() - t_vis
    sharp = None
    if uses_sharpness(pc, cfg.select):
        sharp = photo_sharpness(run_dir, sfm, pool)      # [pool]: view medoids avoid blurred frames
    sel = select(pc, grid, budget, cfg.select, progress=True, index=index, sharpness=sharp)
    sel.seconds += t_vis  # the selection's time, visibility included (as when select builds it)
    chosen = [pool[k] for k in sel.chosen]
    terms = energy_of_subset(index, sel.chosen, cfg.select.energy, per_node=True)
    np.savez_compressed(d / "nodes.npz", nodes=grid.nodes(), angular=terms.angular_per_node,
                        frequency=terms.frequency_per_node, flat=np.flatnonzero(grid.mask.reshape(-1)),
                        res=grid.res, box_min=grid.box_min, box_max=grid.box_max)
    rec = {**sel.to_dict(), "chosen": chosen, "initial": [], "chosen_names": [sfm.cameras.names[i] for i in chosen],
           "budget": budget, "holdout_every": split["holdout_every"], "holdout": split["holdout"], "pool": pool,
           "n_nodes": int(grid.mask.sum()), "up_axis": up_axis(sfm.cameras),
           "sharpness": None if sharp is None else [None if not np.isfinite(v) else float(v) for v in sharp]}
    write_json_atomic(d / "selection.json", rec)
    finish_stage(d, key, {"select": cfg.select, "budget": cfg.budget}, t0,
                 outputs={"selection": "selection.json", "nodes": "nodes.npz"}, seed=cfg.select.seed)
    e = f", E = {sel.energy[-1]:.1f}" if sel.energy else ""
    how = sel.method if sel.method == cfg.select.method else f"{cfg.select.method}: {sel.method}"
    _summary("select", t0, False, f"{len(chosen)} of {len(pool)} pool images ({how}{e}), "
             f"{rec['n_nodes']} nodes, {sel.seconds:.2f}s", timings)
    return d


def eval_units(cfg: RunConfig, run_dir: Path):
    """The evaluation units of this run and their stage keys."""
    from curate.select.baselines import farthest_view, random_subset
    from curate.evaluate.units import Unit
    from curate.sfm.io import load_sfm
    from curate.core.stage import stage_key
    sel = json.loads((run_dir / "select" / "selection.json").read_text())
    pool, chosen = sel["pool"], sel["chosen"]
    cams = load_sfm(run_dir).cameras
    ev = cfg.evaluate
    units = []
    for m in ev.methods:
        if m == "energy":
            units.append(Unit("energy", "energy", None, chosen))  # "energy": the selection, whatever its method
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
    sfm_key = _key_of(run_dir / "sfm")
    occ_key = _key_of(run_dir / "occupancy")
    keys = {u.key: stage_key({"train": train, "subset": u.subset, "holdout": sel["holdout"]},
                             [sfm_key] + ([occ_key] if u.key == "all" else [])) for u in units}
    return units, keys, sel


def stage_evaluate(cfg: RunConfig, run_dir: Path, force: bool = False, timings: list | None = None,
                   executor=None) -> Path:
    """Train every unit (finished units are skipped) -> ``RUN/evaluate``.

    ``executor``: a ``concurrent.futures.Executor`` for the trainings (None: local processes).
    """
    from curate.evaluate.units import clear_evaluation, eval_cameras, run_units, summarize
    from curate.core.stage import is_fresh, write_json_atomic
    from curate.field.train import default_box

    t0 = time.perf_counter()
    d = run_dir / "evaluate"
    units, keys, sel = eval_units(cfg, run_dir)
    if force:
        clear_evaluation(run_dir)  # only what curate wrote there (runfolder)
    fresh = all(is_fresh(d / u.key, keys[u.key]) for u in units)
    sfm, paths, pool, hold = load_split(run_dir, cfg.evaluate.holdout_every)
    if not hold:
        raise ValueError("no held-out views: set holdout_every > 0 and register enough images")
    cams = eval_cameras(sfm.cameras, cfg.evaluate.max_side)
    fp = {"all": str(run_dir / "occupancy" / "field.pt")}
    res = run_units(run_dir, units, keys, cfg.evaluate, cams, paths, hold, default_box(sfm.cameras), fp,
                    executor=executor)
    methods, paired, gap = summarize(res)
    write_json_atomic(d / "summary.json", {"methods": methods, "paired": paired, "gap_closed": gap})
    # the unit "energy" is the selection, whatever its method (report.json keeps the key)
    label = f"selection ({sel['method']})"
    txt = ", ".join(f"{label if m == 'energy' else m} {v['psnr']:.2f}"
                    for m, v in methods.items())
    _summary("evaluate", t0, fresh, f"held-out PSNR: {txt} ({len(hold)} views)", timings)
    return d


def recorded_seconds(run_dir: Path) -> dict[str, float | None]:
    """Seconds each stage took when it actually ran (from the stage records; evaluate: all units summed)."""
    from curate.core.stage import read_stage
    out: dict[str, float | None] = {}
    for s in ("sfm", "occupancy", "select", "evaluate", "export"):
        if s == "evaluate":
            recs = [read_stage(p.parent) for p in sorted((run_dir / "evaluate").glob("*/stage.json"))]
            out[s] = round(sum(r.get("seconds", 0) for r in recs if r), 2) if recs else None
        else:
            out[s] = (read_stage(run_dir / s) or {}).get("seconds")
    return out


def stage_report(cfg: RunConfig, run_dir: Path, photos: str | None, timings: list, wall: float | None) -> Path:
    """``RUN/report.json`` (machine-readable) and ``RUN/report.html`` (for a person).

    ``stages``: this invocation's stages (``seconds`` here, ``skipped`` when unchanged) with
    ``compute_seconds``, the time each took when it actually ran; ``wall_seconds``: this
    invocation (``curate report`` alone keeps the previous figure).
    """
    from curate.sfm.io import load_sfm
    from curate.core.stage import read_stage, write_json_atomic
    sfm = load_sfm(run_dir)
    sel = json.loads((run_dir / "select" / "selection.json").read_text())
    photos_rec = sfm.records.get("photos", [])
    recorded = recorded_seconds(run_dir)
    if not timings:  # `curate report` alone: the stages as recorded when they ran
        timings = [{"name": k, "seconds": None, "skipped": None} for k in recorded]
    timings = [{**t, "compute_seconds": recorded.get(t["name"])} for t in timings]
    if wall is None and (run_dir / "report.json").is_file():
        wall = json.loads((run_dir / "report.json").read_text()).get("wall_seconds")
    rep = {"photos": photos, "run_dir": str(run_dir), "budget": sel["budget"], "n_photos": len(photos_rec),
           "n_registered": len(sfm.cameras), "n_pool": len(sel["pool"]), "n_holdout": len(sel["holdout"]),
           "holdout_every": sel["holdout_every"], "wall_seconds": None if wall is None else round(wall, 2),
           "stages": timings, "compute_seconds": round(sum(v for v in recorded.values() if v), 2),
           "sfm": {"skipped": [{"file": r["original"], "reason": r.get("reason", "")} for r in photos_rec
                               if r.get("status") == "skipped"],
                   "dropped": [{"file": r["original"], "reason": r.get("reason", "")} for r in photos_rec
                               if r.get("status") == "dropped"],
                   "unregistered": [r["original"] for r in photos_rec
                                    if r.get("status") == "kept" and not r.get("registered")],
                   **(read_stage(run_dir / "sfm") or {}).get("stats", {})},
           "selection": {k: v for k, v in sel.items() if k not in ("holdout", "pool")},
           "config": _config_dict(cfg)}
    summ = run_dir / "evaluate" / "summary.json"
    if cfg.run_evaluation and summ.is_file():
        rep.update(json.loads(summ.read_text()))
    write_json_atomic(run_dir / "report.json", rep)
    try:
        from curate.report.run_report import write_html
        write_html(run_dir)
    except ImportError:  # pragma: no cover - report module not present
        log.warning("no HTML report (curate.report.run_report missing)")
    return run_dir / "report.json"


def _config_dict(cfg: RunConfig) -> dict:
    from curate.core.stage import config_dict
    return config_dict(cfg)


def stage_export(cfg: RunConfig, run_dir: Path, force: bool = False, timings: list | None = None) -> Path:
    """The chosen subset in the formats NeRF tools read -> ``RUN/export``."""
    from curate.export.subset import export_subset
    from curate.core.stage import begin_stage, finish_stage, stage_key
    t0 = time.perf_counter()
    d = run_dir / "export"
    key = stage_key({"mode": cfg.export_mode}, [_key_of(run_dir / "select")])
    if begin_stage(d, key, force):
        _summary("export", t0, True, "", timings)
        return d
    sel = json.loads((run_dir / "select" / "selection.json").read_text())
    export_subset(run_dir, sel["chosen_names"], d, mode=cfg.export_mode)
    finish_stage(d, key, {"mode": cfg.export_mode}, t0, outputs={"sparse": "sparse/0", "transforms": "transforms.json",
                                                                 "list": "images.txt", "images": "images/"})
    _summary("export", t0, False, f"{len(sel['chosen_names'])} images ({cfg.export_mode}s) -> {d}", timings)
    return d


RUN_WRITES = ("run.json", "report.json", "report.html", "sfm", "occupancy", "select", "evaluate", "export")
"""Top-level entries of a run folder that ``run`` writes (refused where an adopted folder has them)."""


def run(cfg: RunConfig, photos: str | Path | None, run_dir: str | Path, poses: str | Path | None = None,
        force: bool = False, executor=None, adopt: bool = False) -> Path:
    """:func:`_run` inside the claimed and locked run folder (:mod:`curate.core.runfolder`;
    ``adopt``: accept a non-empty folder curate did not create)."""
    from curate.core import runfolder  # runsafe: claim + lock, before any work
    with runfolder.claimed(run_dir, inputs=[photos, poses], adopt=adopt, writes=RUN_WRITES):
        return _run(cfg, photos, run_dir, poses, force, executor)


def _run(cfg: RunConfig, photos: str | Path | None, run_dir: str | Path, poses: str | Path | None = None,
         force: bool = False, executor=None) -> Path:
    """The whole pipeline into ``run_dir``; returns the path of ``report.json``.

    ``photos``: the photo folder (SfM), or with ``poses`` (a COLMAP model or a
    transforms.json) the folder the poses' image paths are relative to. ``executor``:
    a ``concurrent.futures.Executor`` for the evaluation's trainings (None: local processes).
    """
    from curate.sfm.colmap import import_poses, run_sfm
    from curate.core.stage import write_json_atomic, config_dict, versions
    t_start = time.perf_counter()
    run_dir = Path(run_dir)
    if photos is not None and run_dir.resolve().is_relative_to(Path(photos).resolve()):
        raise ValueError(f"the run folder {run_dir} is inside the photo folder {photos}: curate never writes there")
    run_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(run_dir / "run.json", {"config": config_dict(cfg), "photos": str(photos) if photos else None,
                                             "poses": str(poses) if poses else None, "versions": versions()})
    timings: list = []
    t0 = time.perf_counter()
    had = (run_dir / "sfm" / "stage.json").is_file()
    if poses:
        import_poses(cfg.sfm, poses, run_dir, photos=photos, force=force)
    else:
        run_sfm(cfg.sfm, photos, run_dir, force=force)
    rec = json.loads((run_dir / "sfm" / "stage.json").read_text())
    skipped = had and not force and time.perf_counter() - t0 < 0.5 * max(rec.get("seconds", 0), 1e-9)
    _summary("sfm", t0, skipped, f"{len(json.loads((run_dir / 'sfm' / 'cameras.json').read_text())['cameras'])} "
             "cameras registered", timings)
    stage_occupancy(cfg, run_dir, force, timings)
    stage_select(cfg, run_dir, force, timings)
    if cfg.run_evaluation:
        stage_evaluate(cfg, run_dir, force, timings, executor)
    stage_export(cfg, run_dir, force, timings)
    t0 = time.perf_counter()
    out = stage_report(cfg, run_dir, str(photos) if photos else None, timings, time.perf_counter() - t_start)
    _summary("report", t0, False, f"{out} and report.html", None)
    return out
