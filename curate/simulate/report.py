"""Self-contained HTML report of a ``curate simulate`` run (``OUT/report.html``).

``write_simulate_html(out_dir)`` reads ``OUT/report.json`` (see :mod:`curate.simulate.experiment`)
and shares the page style and helpers of :mod:`curate.report.run_report`.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from curate.html import charts
from curate.html.parts import CSS, duration, esc, fmt_num, note, read_json, safe_section
from curate.html.plots import top_down_axes

logger = logging.getLogger(__name__)

__all__ = ["write_simulate_html"]


SIM_LABEL = {"ours": "ours (progressive energy)", "random": "random", "hemisphere": "hemisphere", "fvs": "FVS"}


def _sim_tables(rep: dict) -> str:
    table, ssim = rep.get("table") or {}, rep.get("ssim") or {}
    if not table:
        return note("No results table.")
    tests = [t for t in next(iter(table.values())) if t != "average"]
    cols = tests + ["average"]
    best = {c: max(table[m].get(c, -math.inf) for m in table) for c in cols}
    head = ('<tr><th class="l">train set ↓ / test set →</th>' + "".join(f"<th>{esc(c)}</th>" for c in cols) + "</tr>")
    rows = []
    for m, row in table.items():
        cells = "".join(f"<td>{'<b>' if row.get(c) == best[c] else ''}{fmt_num(row.get(c))}"
                        f"{'</b>' if row.get(c) == best[c] else ''}</td>" for c in cols)
        cls = ' class="hl"' if m == "ours" else ""
        rows.append(f'<tr{cls}><td class="l">{esc(SIM_LABEL.get(m, m))}</td>{cells}</tr>')
    pv = rep.get("per_view") or {}
    n_views = {len(v.get("psnr", [])) for r in pv.values() for v in r.values()}
    n_txt = f"{n_views.pop()} views of " if len(n_views) == 1 else ""
    out = [f"<p>PSNR (dB) on {n_txt}each test set, for the field trained on each "
           "method's cameras (best of each column in bold):</p><table>" + head + "".join(rows) + "</table>"]
    if ssim:
        srows = "".join(f'<tr><td class="l">{esc(SIM_LABEL.get(m, m))}</td>'
                        + "".join(f"<td>{fmt_num(row.get(t), 3)}</td>" for t in tests) + "</tr>"
                        for m, row in ssim.items())
        out.append("<p>SSIM:</p><table>" + '<tr><th class="l">train set</th>'
                   + "".join(f"<th>{esc(t)}</th>" for t in tests) + "</tr>" + srows + "</table>")
    if "ours" in pv:
        from curate.core.stats import paired_difference
        prow = []
        for m in [m for m in pv if m != "ours"]:
            cells = []
            for t in tests:
                try:
                    d = paired_difference(pv["ours"][t]["psnr"], pv[m][t]["psnr"])
                    cells.append(f"<td>{fmt_num(d['mean'], 2, True)} <span class='small'>[{fmt_num(d['lo'], 2, True)}, "
                                 f"{fmt_num(d['hi'], 2, True)}]</span></td>")
                except (KeyError, ValueError):
                    cells.append("<td>—</td>")
            prow.append(f'<tr><td class="l">ours − {esc(m)}</td>{"".join(cells)}</tr>')
        if prow:
            out.append("<p>Paired per-view PSNR differences (same test views), mean [95% CI]:</p><table>"
                       '<tr><th class="l">difference</th>' + "".join(f"<th>{esc(t)}</th>" for t in tests) + "</tr>"
                       + "".join(prow) + "</table>")
    return "\n".join(out)


def _sim_layouts(rep: dict) -> str:
    from curate.core.cameras import Cameras
    cams = {m: Cameras.from_dict(d) for m, d in (rep.get("cameras") or {}).items()}
    if not cams:
        return note("No cameras recorded.")
    tests = [Cameras.from_dict(d) for d in (rep.get("test_cameras") or {}).values()]
    test = Cameras.concat(tests) if tests else Cameras.empty()
    k, a, b, _ = top_down_axes(Cameras.concat(list(cams.values())).c2w)
    axes = "xyz"
    figs = []
    for m, c in cams.items():
        both = Cameras.concat([c, test])
        figs.append(charts.camera_map(both.centres[:, [a, b]], both.view_dirs[:, [a, b]], range(len(c)),
                                     f"{SIM_LABEL.get(m, m)}", width=268, height=250,
                                     labels=(f"test views ({len(test)})", f"training ({len(c)})", "")))
    return ('<div class="row">' + "".join(figs) + f'</div><p class="small">Seen from above: {axes[a]} to the right, '
            f"{axes[b]} upwards; ticks show the viewing directions.</p>")


def write_simulate_html(out_dir: str | Path) -> Path:
    """Write ``out_dir/report.html`` for a ``curate simulate`` run from its ``report.json``; returns its path.

    Sections: header, the paper-style table (train method x test set, PSNR and SSIM, paired
    differences ours - other per test set), average PSNR bars, the training cameras of each
    method seen from above, the energy curve of the progressive placement, timings.
    """
    out_dir = Path(out_dir)
    rep = read_json(out_dir / "report.json") or {}
    table = rep.get("table") or {}

    def header(_):
        items = [("scene", f"{rep.get('scene', '—')} (seed {rep.get('scene_seed', '—')})"),
                 ("budget", f"{rep.get('budget', '—')} training cameras per method"),
                 ("nodes", rep.get("n_nodes", "—")),
                 ("proposal time", f"{fmt_num(rep.get('propose_seconds_per_camera'), 2)} s per camera (ours, median)"),
                 ("wall time", duration(rep.get("wall_seconds")))]
        return ("<h1>curate simulate: camera placement comparison</h1><dl class='kv'>"
                + "".join(f"<dt>{esc(k)}</dt><dd>{esc(v)}</dd>" for k, v in items) + "</dl>")

    def bars(_):
        if not table:
            return note("No results.")
        ms = list(table)
        return charts.bar_chart(ms, [table[m].get("average") for m in ms], title="PSNR averaged over the test sets",
                               ylabel="PSNR (dB)", width=480, height=280)

    def curve(_):
        e = rep.get("energy_curve") or []
        if not e:
            return note("No energy curve (progressive placement not run).")
        x = np.arange(1, len(e) + 1)
        return charts.line_chart({"E": (x, np.asarray(e, float))}, "Energy during progressive placement",
                                "cameras placed", "E", 480, 280)

    def timings(_):
        t = rep.get("timings") or {}
        if not t:
            return note("No timings.")
        return ('<table><tr><th class="l">step</th><th>seconds</th></tr>' + "".join(
            f'<tr><td class="l">{esc(k)}</td><td>{fmt_num(v, 2)}</td></tr>' for k, v in t.items()) + "</table>")

    body = [safe_section(header, rep)]
    for title, fn in (("Results", _sim_tables), ("Average PSNR", bars), ("Training cameras", _sim_layouts),
                      ("Energy curve", curve), ("Timings", timings)):
        body.append(f"<h2>{esc(title)}</h2>\n{safe_section(fn, rep)}")
    page = ('<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>curate simulate report</title>'
            f'<style>{CSS}</style></head><body>\n' + "\n".join(body) + "\n</body></html>\n")
    out = out_dir / "report.html"
    out.write_text(page, encoding="utf-8")
    logger.info("simulate report: %s", out)
    return out
