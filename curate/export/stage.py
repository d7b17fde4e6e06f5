"""The export stage: the chosen subset in the formats NeRF tools read -> ``RUN/export`` (see :mod:`curate.export.subset`)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig


def run(cfg: "RunConfig", run_dir: Path, force: bool = False) -> StageResult:
    """COLMAP model, transforms.json, image list and image links (or copies) of the selection."""
    from curate.core.stage import begin_stage, finish_stage, stage_key
    from curate.export.subset import export_subset
    from curate.occupancy.stage import key_of
    from curate.select.stage import read_selection
    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    d = run_dir / "export"
    key = stage_key({"mode": cfg.export_mode}, [key_of(run_dir / "select")])
    if begin_stage(d, key, force):
        return StageResult("export", d, False, time.perf_counter() - t0)
    sel = read_selection(run_dir)
    export_subset(run_dir, sel["chosen_names"], d, mode=cfg.export_mode)
    finish_stage(d, key, {"mode": cfg.export_mode}, t0, outputs={"sparse": "sparse/0", "transforms": "transforms.json",
                                                                 "list": "images.txt", "images": "images/"})
    return StageResult("export", d, True, time.perf_counter() - t0,
                       f"{len(sel['chosen_names'])} images ({cfg.export_mode}s) -> {d}")
