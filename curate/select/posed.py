"""Posed cameras outside a run folder: ``curate select POSES --out DIR`` chooses a subset of a pose file
(:func:`select_posed`), ``curate score POSES`` scores a set of cameras with the paper's energy (:func:`score_posed`).

The pose file is read by :func:`curate.sfm.poses.read_poses` (transforms.json, a COLMAP model, a cameras.json);
the node grid spans ``--box`` or the cameras' box (:func:`grid_for`); the selection is written with the run
folder's schema (:mod:`curate.select.record`). What the user did wrong is a ``ValueError`` (or
``FileNotFoundError``) naming it: the command line prints it as its one-line error.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.cameras import Cameras
    from curate.core.grid import NodeGrid

def read_poses(path: str | Path) -> tuple["Cameras", list[str]]:
    """(cameras, image paths) of a pose source (:func:`curate.sfm.poses.read_poses`)."""
    from curate.sfm.poses import read_poses as read
    p = read(Path(path))
    return p.cameras, p.files


def grid_for(cfg: "RunConfig", cams: "Cameras") -> "NodeGrid":
    """The node grid of ``cfg.occupancy.res`` nodes a side over ``cfg.box``, else over the cameras' box."""
    from curate.core.grid import NodeGrid, box_from_cameras
    if cfg.box is not None:
        lo, hi = cfg.box[:3], cfg.box[3:]
    else:
        if len(cams) == 0:
            raise ValueError("no cameras: give --box or a non-empty input")
        lo, hi = box_from_cameras(cams)
    return NodeGrid(lo, hi, cfg.occupancy.res)


def relpath(path: str, start: Path) -> str:
    """``path`` relative to the folder ``start`` when both are on one file system root; else absolute."""
    import os
    p = Path(path)
    if not p.is_absolute():
        p = Path.cwd() / p
    try:
        return os.path.relpath(p.resolve(), Path(start).resolve())
    except ValueError:  # pragma: no cover - another drive (Windows)
        return str(p.resolve())


def select_posed(cfg: "RunConfig", source: str | Path, out: str | Path, progress: bool = True,
                 say: Callable[[str], None] | None = print) -> dict:
    """Choose ``cfg.budget`` cameras of the pose file ``source`` with ``cfg.select`` and write ``out``:
    ``transforms.json`` (image paths relative to it, so the folder moves with its photos), ``selected.txt`` and
    ``selection.json`` (:func:`curate.select.record.selection_record`, with the options). ``say``: where the
    ``--budget auto`` note goes before the selection runs (None: nowhere). Returns
    ``{"chosen", "energy" (the last step's; 0 when the method has none), "seconds", "out", "n_cameras", "method",
    "has_energy"}``."""
    import json
    from curate.core.budget import AUTO, budget_of_pool, check_fits, parse_budget, resolve_budget
    from curate.core.stage import config_dict, write_json_atomic
    from curate.core.transforms_json import write_transforms
    from curate.select.record import selection_record
    from curate.select.select import select

    cams, files = read_poses(source)
    if len(cams) == 0:
        raise ValueError(f"{source}: the pool has no cameras")
    grid = grid_for(cfg, cams)
    index = auto = None
    text, said = budget_of_pool(cfg.budget, cams)
    if parse_budget(text) == AUTO:
        from curate.select.auto_budget import choose_for_pool
        from curate.select.visibility import build_pair_index
        index = build_pair_index(cams, grid.nodes(), cfg.select.energy.bins, device=cfg.select.device)
        try:
            auto = choose_for_pool(cams, grid.nodes(), index, cfg.budget_tolerance)
        except ValueError as e:
            raise ValueError(f"{source}: {e}") from None
        budget = auto.budget
        if say is not None:
            say(auto.note)
    else:
        budget = resolve_budget(parse_budget(text), len(cams))
        check_fits(said, budget, len(cams), f"cameras of {source}")
    sel = select(cams, grid, budget, cfg.select, progress=progress, index=index)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    chosen = sel.chosen
    rel = [relpath(files[k], out) for k in chosen]
    write_transforms(out / "transforms.json", cams[chosen], rel)
    (out / "selected.txt").write_text("".join(Path(files[k]).name + "\n" for k in chosen))
    rec = {**selection_record(sel, cams, list(range(len(cams))), [], 0, said, grid),
           **({"budget_auto": auto.to_dict()} if auto is not None else {}),
           "config": json.loads(json.dumps(config_dict(cfg.select), default=str))}
    write_json_atomic(out / "selection.json", rec)
    return {"chosen": chosen, "energy": sel.energy[-1] if sel.energy else 0.0, "seconds": sel.seconds,
            "out": str(out), "n_cameras": len(cams), "method": sel.method, "has_energy": bool(sel.energy)}


def score_posed(cfg: "RunConfig", source: str | Path) -> dict:
    """The paper's energy of the cameras of ``source`` over the node grid (:func:`grid_for`), its two terms and
    how much of the grid they see: the figures ``curate score`` prints (``--json``: as they are)."""
    import numpy as np
    from curate.select.select import score_cameras
    cams, _ = read_poses(source)
    ecfg = cfg.select.energy
    grid = grid_for(cfg, cams)
    t = score_cameras(cams, grid, ecfg, per_node=True, device=cfg.select.device)
    views = t.views_per_node
    seen = views > 0
    return {**t.summary(), "res": grid.res, "box": grid.box_min.tolist() + grid.box_max.tolist(),
            "gamma": ecfg.gamma, "bins": [ecfg.n_theta, ecfg.n_phi], "binning": ecfg.binning,
            "observed_fraction": float(seen.mean()) if views.size else 0.0,
            "median_views_observed": float(np.median(views[seen])) if np.any(seen) else 0.0}


def score_lines(s: dict) -> list[str]:
    """:func:`score_posed`'s figures in words, a line each."""
    n = max(s["n_nodes"], 1)
    box = ", ".join(f"{v:.4g}" for v in s["box"])
    return [f"{s['n_cameras']} cameras, {s['n_nodes']} nodes ({s['res']}^3) in box [{box}]",
            f"  energy     E = {s['energy']:.2f}   (each node scores up to 2: at most {2 * s['n_nodes']})",
            f"  angular    sum(1 - TV) = {s['angular']:.2f}   mean {s['angular'] / n:.3f} per node"
            " (1: seen from directions spread evenly over the sphere; ~0.02: from one direction)",
            f"  frequency  sum(O_f^gamma) = {s['frequency']:.2f}   mean {s['frequency'] / n:.3f} per node"
            f" (gamma {s['gamma']}: near 1 once a node is seen at all)",
            f"  coverage   {100 * s['observed_fraction']:.1f}% of nodes seen by at least one camera;"
            f" median {s['median_views_observed']:.0f} views per seen node"]
