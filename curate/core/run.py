"""One reader of a run folder's results: what one stage wrote and the stages after it read.

The SfM stage's cameras (``RUN/sfm/cameras.json``), the occupancy stage's node grid (``RUN/occupancy/occupancy.npz``)
and the select stage's selection (``RUN/select/selection.json``) are read here and nowhere else, each once per
process while its file stays the same (:func:`curate.core.reads.kept`: a file a stage wrote again is read again);
the stage records go through the same cache (:func:`curate.core.stage.read_stage`). No stage imports another
stage's module to read its results: it reads them here (:mod:`curate.sfm.io` reads the rest of the SfM result).

The cameras and the grid are shared by every caller: their arrays are read-only (``cams[idx]``, ``at_most`` and
the like make new ones); the selection is parsed anew on each call.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.reads import kept, read_json

if TYPE_CHECKING:
    from curate.core.cameras import Cameras
    from curate.core.grid import NodeGrid


def _read_only(*arrays) -> None:
    for a in arrays:
        if a is not None:
            a.flags.writeable = False


def _cameras(path: Path) -> "Cameras":
    from curate.core.cameras import Cameras
    cams = Cameras.load(path)
    _read_only(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height, cams.dist)
    return cams


def load_cameras(run_dir: str | Path) -> "Cameras":
    """The registered cameras of the run's SfM stage (``RUN/sfm/cameras.json``: OpenCV camera-to-world, sorted by
    name); ``ValueError`` naming the file when it is not a cameras file, ``FileNotFoundError`` when it is absent."""
    return kept(RunPaths(run_dir).cameras, "cameras", _cameras)


def _node_grid(path: Path) -> "NodeGrid":
    import numpy as np
    from curate.core.grid import NodeGrid
    z = np.load(path)
    grid = NodeGrid(z["box_min"], z["box_max"], int(z["res"]), z["nodes_mask"])
    _read_only(grid.box_min, grid.box_max, grid.mask)
    return grid


def load_node_grid(run_dir: str | Path) -> "NodeGrid":
    """The selection's node grid (box, resolution, node band mask) from ``RUN/occupancy/occupancy.npz``."""
    return kept(RunPaths(run_dir).occupancy_npz, "node_grid", _node_grid)


def read_selection(run_dir: str | Path) -> dict:
    """``RUN/select/selection.json`` (its schema: :mod:`curate.select.record`); ``FileNotFoundError`` saying which
    command writes it when it is absent, ``ValueError`` when it is not a selection record."""
    p = RunPaths(run_dir).selection
    if not p.is_file():
        raise FileNotFoundError(f"{p}: no selection yet (run `curate select RUN` first)")
    try:
        rec = read_json(p)
    except ValueError as e:                 # truncated, not JSON, not UTF-8
        raise ValueError(f"{p}: not a selection record of curate ({e}); `curate select {run_dir}` writes it "
                         "again") from None
    if not isinstance(rec, dict):
        raise ValueError(f"{p}: not a selection record of curate")
    return rec
