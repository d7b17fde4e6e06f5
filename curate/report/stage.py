"""The report stage: ``RUN/report.json`` (for programs) and ``RUN/report.html`` (for a person)."""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.graph import NAMES
from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.core.graph import RunContext

log = logging.getLogger(__name__)


def recorded_seconds(run_dir: Path) -> dict[str, float | None]:
    """Seconds each stage took when it actually ran (from the stage records; evaluate: all units summed)."""
    from curate.core.stage import read_stage
    out: dict[str, float | None] = {}
    for s in NAMES:
        if s == "report":
            continue
        if s == "evaluate":
            recs = [read_stage(p.parent) for p in sorted(RunPaths(run_dir).evaluate.glob("*/stage.json"))]
            out[s] = round(sum(r.get("seconds", 0) for r in recs if r), 2) if recs else None
        else:
            out[s] = (read_stage(run_dir / s) or {}).get("seconds")
    return out


def evaluation_status(run_dir: Path, stale: dict[str, str]) -> dict:
    """What the run's evaluation is worth now: ``status`` 'current' (it estimates the exported
    selection), 'out of date' (it estimates an earlier selection: ``why``, and ``of``: that
    selection's size and method) or 'not run'; ``refresh``: the command that (re)makes it."""
    from curate.core.stage import refresh_command
    summ = RunPaths(run_dir).summary
    refresh = refresh_command(run_dir, stale, "evaluate")
    if not summ.is_file():
        return {"status": "not run", "refresh": refresh}
    if "evaluate" not in stale:
        return {"status": "current", "refresh": refresh}
    try:
        pr = json.loads(summ.read_text()).get("protocol") or {}
    except (OSError, ValueError):
        pr = {}
    return {"status": "out of date", "why": stale["evaluate"], "refresh": refresh,
            "of": {"exported_budget": pr.get("exported_budget"), "method": pr.get("method")}}


def write_report(ctx: "RunContext") -> StageResult:
    """Write ``report.json`` and ``report.html``.

    ``ctx.timings``: this invocation's stages (:meth:`StageResult.timing`); ``report.json``
    ``stages`` adds ``compute_seconds``, the time each took when it actually ran;
    ``wall_seconds``: this invocation (``ctx.seconds``; ``curate report`` alone keeps the previous figure).
    """
    from curate.core.stage import config_dict, read_stage, stale_stages, versions, write_json_atomic
    from curate.report.verdict import verdict
    from curate.core.run import read_selection
    from curate.sfm.io import load_sfm
    t0 = time.perf_counter()
    cfg, run_dir, timings, wall = ctx.cfg, ctx.run_dir, ctx.timings, ctx.seconds
    photos = None if ctx.photos is None else str(ctx.photos)
    sfm = load_sfm(run_dir)
    sel = read_selection(run_dir)
    photos_rec = sfm.records.get("photos", [])
    recorded = recorded_seconds(run_dir)
    if not timings:  # `curate report` alone: the stages as recorded when they ran
        timings = [{"name": k, "seconds": None, "skipped": None} for k in recorded]
    timings = [{**t, "compute_seconds": recorded.get(t["name"])} for t in timings]
    from curate.html.parts import read_json
    before = read_json(RunPaths(run_dir).report_json)           # what the last report wrote (its page's record)
    before = before if isinstance(before, dict) else {}
    if wall is None:
        wall = before.get("wall_seconds")
    stale = stale_stages(run_dir)
    rep = {"photos": photos, "run_dir": str(run_dir), "budget": sel["budget"], "n_photos": len(photos_rec),
           "n_registered": len(sfm.cameras), "n_candidates": len(sel["pool"]),
           "wall_seconds": None if wall is None else round(wall, 2),
           "stages": timings, "compute_seconds": round(sum(v for v in recorded.values() if v), 2),
           "sfm": {"skipped": [{"file": r["original"], "reason": r.get("reason", "")} for r in photos_rec
                               if r.get("status") == "skipped"],
                   "dropped": [{"file": r["original"], "reason": r.get("reason", "")} for r in photos_rec
                               if r.get("status") == "dropped"],
                   "unregistered": [r["original"] for r in photos_rec
                                    if r.get("status") == "kept" and not r.get("registered")],
                   **(read_stage(RunPaths(run_dir).sfm) or {}).get("stats", {})},
           "selection": {k: v for k, v in sel.items() if k not in ("holdout", "pool")},
           "stale": stale, "config": config_dict(cfg), "version": versions()["curate"],
           "written_at": time.strftime("%Y-%m-%d %H:%M")}
    parts = []
    for f in sorted(RunPaths(run_dir).parts.glob("*/report.json"), key=lambda f: int(f.parent.name)
                    if f.parent.name.isdigit() else 0):  # --on-split each: the other parts' own runs
        pr = json.loads(f.read_text())
        parts.append({"part": f.parent.name, "n_registered": pr.get("n_registered"),
                      "n_chosen": len((pr.get("selection") or {}).get("chosen") or []),
                      "report": f"parts/{f.parent.name}/report.html", "export": f"parts/{f.parent.name}/export"})
    if parts:
        rep["parts"] = parts
    rep["evaluation"] = evaluation_status(run_dir, stale)
    if rep["evaluation"]["status"] == "current":   # figures only of the selection they describe
        summ = json.loads(RunPaths(run_dir).summary.read_text())
        rep.update({k: summ[k] for k in ("methods", "paired", "gap_closed", "budget_check") if k in summ})
        pr = summ.get("protocol") or {}
        rep["estimate"] = {"budget": pr.get("budget"), "n_pool": pr.get("n_pool", len(pr.get("pool", []))),
                           "n_holdout": len(pr.get("holdout", [])), "holdout_every": pr.get("holdout_every"),
                           "method": pr.get("method"), "shared_with_export": pr.get("shared_with_export"),
                           **{k: pr.get(k) for k in ("n_folds", "planned_folds", "stopped", "minutes", "level",
                                                     "margin_db", "resolution_db", "seconds") if k in pr}}
        need = (pr.get("plan") or {}).get("needs_minutes")
        if need is not None:  # what the undecided comparisons need here, as the evaluation projected it
            rep["estimate"]["needs_minutes"] = need
        folds = [n["folds"] for n in ((pr.get("plan") or {}).get("needs") or {}).values()
                 if isinstance(n, dict) and n.get("folds")]
        if folds:             # more folds would decide them (their minutes unknown when every training was reused)
            rep["estimate"]["needs_folds"] = max(folds)
    if (sel.get("budget_auto") or {}).get("measured"):   # how many, measured before the selection
        rep["budget_check"] = sel["budget_auto"]["measured"]
    try:                                         # what the run decided once its cameras were known
        from curate.core.plan import plan_of_run
        rep["plan"] = plan_of_run(cfg, run_dir).to_dict()
    except ValueError:                           # a budget given since that does not fit: said by its stage
        pass
    rep["verdict"] = verdict(rep)
    if before.get("html"):          # the page as curate last wrote it: a page the user changed since is kept
        rep["html"] = before["html"]
    write_json_atomic(RunPaths(run_dir).report_json, rep)
    from curate.report.run_report import write_html
    write_html(run_dir)
    return StageResult("report", RunPaths(run_dir).report_json, True, time.perf_counter() - t0,
                       f"{run_dir / 'report.json'} and report.html")
