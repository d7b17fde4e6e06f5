"""Pieces shared by curate's HTML pages (the run report, the simulation report): the style
sheet and small, safe formatters. No heavy imports."""

from __future__ import annotations

import html
import logging
import math
from pathlib import Path
from typing import Callable

logger = logging.getLogger("curate.report.run_report")

CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;max-width:1160px;margin:24px auto;padding:0 16px;
color:#222;line-height:1.4}
h1{font-size:24px;margin-bottom:4px}h2{font-size:18px;border-bottom:1px solid #ddd;padding-bottom:4px;margin-top:32px}
table{border-collapse:collapse;margin:8px 0}td,th{border:1px solid #ddd;padding:4px 10px;text-align:right}
th{background:#f4f4f4}td.l,th.l{text-align:left}tr.hl td{background:#fff6e0;font-weight:600}
.note{color:#777;font-style:italic}.warnbox{border:2px solid #c0392b;background:#fdecea;padding:10px 14px;\
margin:12px 0;border-radius:4px}.small{font-size:12px;color:#555}.row{display:flex;flex-wrap:wrap;gap:18px;
align-items:flex-start}.fig{text-align:center;font-size:12px;color:#444}.fig img{display:block;margin:0 auto 3px}
.thumbs{display:flex;flex-wrap:wrap;gap:6px}.thumbs figure{margin:0;width:164px;font-size:11px;text-align:center;
overflow:hidden;text-overflow:ellipsis;white-space:nowrap}.thumbs img{max-width:160px;max-height:160px}
.renders{table-layout:fixed;width:100%}.renders th{text-align:center;font-weight:600;font-size:12px}
.renders td{text-align:center;vertical-align:top;font-size:12px;padding:3px}.renders img{width:100%;display:block;
margin:0 auto 2px}details{margin-top:24px}details summary{cursor:pointer}details summary h2{display:inline;border:0}\
.scroll{max-width:100%;overflow-x:auto}svg{max-width:100%;height:auto}
dl.kv{display:grid;grid-template-columns:max-content auto;gap:2px 14px;margin:8px 0}\
dl.kv dt{color:#666}dl.kv dd{margin:0}
.verdict{font-size:16px;margin:10px 0;padding:8px 14px;background:#f0f6ff;border-left:4px solid #1f77b4}
.verdict p{margin:6px 0}code{background:#f4f4f4;padding:0 3px;border-radius:3px}
"""


def esc(x) -> str:
    """HTML-escaped text."""
    return html.escape(str(x))


def fmt_num(v, nd: int = 2, signed: bool = False) -> str:
    """A number for a table cell; '—' for None / NaN."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "—"
    try:
        return f"{float(v):+.{nd}f}" if signed else f"{float(v):.{nd}f}"
    except (TypeError, ValueError):
        return esc(v)


def note(text: str) -> str:
    """An italic one-line note (a section with nothing to show)."""
    return f'<p class="note">{esc(text)}</p>'


def read_json(path: Path) -> dict | None:
    """The JSON file's content; None when it is missing or unreadable (read once while it stays the same:
    :func:`curate.core.reads.read_json`)."""
    from curate.core.reads import read_json as read
    try:
        return read(path)
    except (OSError, ValueError):
        return None


def duration(s) -> str:
    """Seconds as '12.3 s' or '2.5 min (150 s)'; '—' for None."""
    if s is None:
        return "—"
    s = float(s)
    return f"{s:.1f} s" if s < 120 else f"{s / 60:.1f} min ({s:.0f} s)"


def safe_section(fn: Callable, run) -> str:
    """``fn(run)``; a note in its place when it raises (one broken section must not lose the report)."""
    try:
        return fn(run)
    except Exception as e:  # noqa: BLE001 - one broken section must not lose the report
        logger.warning("report: section %s failed: %s: %s", fn.__name__, type(e).__name__, e)
        return note(f"Not available ({type(e).__name__}: {e}).")
