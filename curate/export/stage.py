"""The export stage: the chosen subset in the formats NeRF tools read -> ``RUN/export`` (see :mod:`curate.export.subset`)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig


EXPORTED = {"link": "linked", "copy": "copied"}
"""How the stage line says each export mode ("10 images (copied)")."""


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
    model = json.loads((d / "export.json").read_text())["model"]
    warn = connectivity_warning(model)
    finish_stage(d, key, {"mode": cfg.export_mode}, t0, outputs={"sparse": "sparse/0", "transforms": "transforms.json",
                                                                 "list": "images.txt", "images": "images/"},
                 model=model, warning=warn)
    return StageResult("export", d, True, time.perf_counter() - t0,
                       f"{len(sel['chosen_names'])} images ({EXPORTED[cfg.export_mode]}), {model['n_points3D']} points -> {d}",
                       warning=warn)


def connectivity_warning(model: dict) -> str | None:
    """A warning when the exported images do not form one set connected through shared SfM points
    (a tool that re-registers them, or 3DGS initialised from the points, sees separate pieces);
    None when they do, or when the poses came without points (nothing to judge by)."""
    comps = model.get("components") or []
    if model.get("n_points3D_source", 0) == 0 or len(comps) <= 1:
        return None
    return (f"the {sum(comps)} exported images form {len(comps)} groups that share no SfM points "
            f"(sizes {', '.join(map(str, comps[:8]))}{', ...' if len(comps) > 8 else ''}): a larger budget "
            "links them; COLMAP or 3DGS given this subset alone may see separate pieces")
