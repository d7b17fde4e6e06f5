"""``curate batch``'s summary: one row per folder (``RUNS/<name>/batch.json``,
``RUNS/summary.json``) and the page ``RUNS/summary.html``."""

from __future__ import annotations

import html
import json
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.graph import first_unfinished
from curate.html.parts import fmt_num

if TYPE_CHECKING:
    from curate.batch.runner import Folder

METHODS = ("selection", "random", "fvs", "all")
"""The evaluation units a summary row has a PSNR for (the selection, whatever its method)."""


def make_row(item: Folder, status: str, reason: str = "", wall: float | None = None, cfg=None) -> dict:
    """A summary row; figures from ``RUN/report.json`` (ok) or what the run folder has (failed)."""
    rd = Path(item.run_dir)
    row = {"name": item.name, "folder": item.folder, "run_dir": item.run_dir, "poses": item.source,
           "status": status, "reason": reason, "failed_stage": None, "photos": None, "registered": None,
           "pool": None, "chosen": None, "chosen_names": [], "psnr": {m: None for m in METHODS},
           "psnr_random_std": None, "selection_minus_random": None,
           "wall_seconds": None if wall is None else round(wall, 2), "report": None, "resumed": False}
    if status == "ok" and RunPaths(rd).report_json.is_file():
        rep = json.loads(RunPaths(rd).report_json.read_text())
        sel = rep.get("selection", {})
        from curate.evaluate.units import legacy_keys
        m = legacy_keys(rep.get("methods", {}))
        paired = legacy_keys(rep.get("paired", {}))
        row.update(photos=rep.get("n_photos"), registered=rep.get("n_registered"),
                   pool=rep.get("n_candidates", rep.get("n_pool")), verdict=(rep.get("verdict") or {}).get("short"),
                   chosen=len(sel.get("chosen", [])), chosen_names=list(sel.get("chosen_names", [])),
                   psnr={k: (m[k]["psnr"] if k in m else None) for k in METHODS},
                   psnr_random_std=m.get("random", {}).get("psnr_std"),
                   selection_minus_random=paired.get("selection-random", {}).get("mean"),
                   report=f"{item.name}/report.html" if RunPaths(rd).report_html.is_file() else None)
    elif status == "failed":
        if cfg is not None and rd.is_dir():
            row["failed_stage"] = first_unfinished(cfg, rd)
        imgs = RunPaths(rd).images_json
        try:
            if imgs.is_file():
                photos = json.loads(imgs.read_text()).get("photos", [])
                row["photos"] = len(photos)
                row["registered"] = sum(1 for p in photos if p.get("registered"))
        except (ValueError, OSError):
            pass
    return row


def write_summary_html(out: Path, summ: dict) -> Path:
    """``RUNS/summary.html``: one self-contained table, each folder linking to its report."""
    e = html.escape
    # the PSNR columns only where some folder was evaluated (a --no-evaluate batch has none to show)
    evaluated = any(v is not None for r in summ["rows"] for v in (r.get("psnr") or {}).values())
    head = ("<tr><th class=l>folder</th><th>status</th><th>photos</th><th>registered</th><th>chosen</th>"
            + ("<th>PSNR selection</th><th>random (mean ± sd)</th><th>FVS</th><th>all</th><th>selection − random</th>"
               if evaluated else "")
            + "<th>wall</th><th class=l>report</th></tr>")
    body = []
    for r in summ["rows"]:
        p = r.get("psnr") or {}
        st = r["status"]
        status = (f"<span class=ok>ok</span>{' (resumed)' if r.get('resumed') else ''}" if st == "ok" else
                  f"<span class=bad>failed</span> in {e(str(r.get('failed_stage')))}<br><small>{e(r['reason'])}</small>"
                  if st == "failed" else e(st))
        rnd = fmt_num(p.get("random")) + (f" ± {r['psnr_random_std']:.2f}"
                                          if r.get("psnr_random_std") is not None else "")
        dif = r.get("selection_minus_random")
        link = f'<a href="{e(r["report"])}">report</a>' if r.get("report") else ""
        wall = "—" if r.get("wall_seconds") is None else f"{r['wall_seconds']:.0f} s"
        body.append(f"<tr><td class=l><b>{e(r['name'])}</b><br><small>{e(r['folder'])} ({e(r['poses'])})</small></td>"
                    f"<td>{status}</td><td>{_n(r.get('photos'))}</td><td>{_n(r.get('registered'))}</td>"
                    f"<td>{_n(r.get('chosen'))}</td>"
                    + (f"<td><b>{fmt_num(p.get('selection'))}</b></td><td>{rnd}</td>"
                       f"<td>{fmt_num(p.get('fvs'))}</td><td>{fmt_num(p.get('all'))}</td>"
                       f"<td>{fmt_num(dif, 2, True)}</td>" if evaluated else "")
                    + f"<td>{wall}</td>"
                    f"<td class=l>{link}</td></tr>")
    css = ("body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:24px;color:#222}"
           "table{border-collapse:collapse}td,th{border:1px solid #ddd;padding:4px 10px;text-align:right;"
           "vertical-align:top}th{background:#f4f4f4}.l{text-align:left}.ok{color:#2a7a2a;font-weight:600}"
           ".bad{color:#b00020;font-weight:600}small{color:#666}")
    page = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>curate batch</title>'
            f"<style>{css}</style></head><body>\n<h1>curate batch</h1>\n"
            f"<p>{summ['n_folders']} folders: {summ['n_ok']} ok, {summ['n_failed']} failed; executor "
            f"{e(summ['executor'])}; {summ['wall_seconds']:.0f} s. "
            + ("Held-out PSNR in dB (each folder's own hold-out views); " if evaluated else "Not evaluated; ")
            + f"budget {e(str(summ['config'].get('budget')))}.</p>\n"
            f"<table>{head}\n" + "\n".join(body) + "</table>\n"
            '<p><small>Written by curate batch. Self-contained; the report links are relative to this file.'
            "</small></p></body></html>\n")
    from curate.core.stage import write_text_atomic
    return write_text_atomic(out / "summary.html", page)


def _n(v) -> str:
    return "—" if v is None else str(v)
