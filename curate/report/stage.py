"""The report stage: ``RUN/report.json`` (for programs) and ``RUN/report.html`` (for a person)."""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.stage import STAGES, StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig

log = logging.getLogger(__name__)


def recorded_seconds(run_dir: Path) -> dict[str, float | None]:
    """Seconds each stage took when it actually ran (from the stage records; evaluate: all units summed)."""
    from curate.core.stage import read_stage
    out: dict[str, float | None] = {}
    for s in STAGES:
        if s == "report":
            continue
        if s == "evaluate":
            recs = [read_stage(p.parent) for p in sorted((run_dir / "evaluate").glob("*/stage.json"))]
            out[s] = round(sum(r.get("seconds", 0) for r in recs if r), 2) if recs else None
        else:
            out[s] = (read_stage(run_dir / s) or {}).get("seconds")
    return out


def run(cfg: "RunConfig", run_dir: Path, photos: str | None = None, timings: list[dict] | None = None,
        wall: float | None = None) -> StageResult:
    """Write ``report.json`` and ``report.html``.

    ``timings``: this invocation's stages (:meth:`StageResult.timing`); ``report.json``
    ``stages`` adds ``compute_seconds``, the time each took when it actually ran;
    ``wall_seconds``: this invocation (``curate report`` alone keeps the previous figure).
    """
    from curate.core.stage import config_dict, read_stage, write_json_atomic
    from curate.select.stage import read_selection
    from curate.sfm.io import load_sfm
    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    sfm = load_sfm(run_dir)
    sel = read_selection(run_dir)
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
           "config": config_dict(cfg)}
    parts = []
    for f in sorted((run_dir / "parts").glob("*/report.json"), key=lambda f: int(f.parent.name)
                    if f.parent.name.isdigit() else 0):  # --on-split each: the other parts' own runs
        pr = json.loads(f.read_text())
        parts.append({"part": f.parent.name, "n_registered": pr.get("n_registered"),
                      "n_chosen": len((pr.get("selection") or {}).get("chosen") or []),
                      "report": f"parts/{f.parent.name}/report.html", "export": f"parts/{f.parent.name}/export"})
    if parts:
        rep["parts"] = parts
    summ = run_dir / "evaluate" / "summary.json"
    if cfg.run_evaluation and summ.is_file():
        rep.update(json.loads(summ.read_text()))
    write_json_atomic(run_dir / "report.json", rep)
    from curate.report.run_report import write_html
    write_html(run_dir)
    return StageResult("report", run_dir / "report.json", True, time.perf_counter() - t0,
                       f"{run_dir / 'report.json'} and report.html")
