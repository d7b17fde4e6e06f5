"""Self-contained HTML reports: ``RUN/report.html`` for ``curate run``.

``write_html(run_dir)`` reads ``RUN/report.json`` and the files of the run folder (see
``docs/architecture.md`` for the contract) and writes ``RUN/report.html``: inline SVG charts
(:mod:`curate.html.charts`) and data-URI images only, nothing fetched from the network, so the
file can be mailed or archived on its own.

The first screen answers "what was chosen, and is it good?" in plain words: warnings a user must
see first, the verdict (:mod:`curate.report.verdict`: the exported photos, how much of the scene
they see, how they compare with random subsets and farthest-view sampling, each with its 95%
interval) and the chosen photos' thumbnails. Then the evidence (the held-out comparison and its
renders side by side, when the run was evaluated), how many photos, where the cameras are and the
capture (counts that add up). Diagnostics for experts (the paper's energy, stage timings) are
folded away, each explained.

Every section degrades on its own: missing data gives a one-line note (or, for an evaluation that
was not run, no section at all), never an exception; an error while building a section is logged
and reported in the page.
"""

from __future__ import annotations

import logging
import os
import math
import time
from pathlib import Path
from typing import Callable

import numpy as np

from curate.core.paths import RunPaths
from curate.html import charts, plots
from curate.html.parts import CSS, duration, esc, fmt_num, note, read_json, safe_section
from curate.html.plots import colorbar, floorplan, heatmap_svg, top_down_axes

logger = logging.getLogger(__name__)

__all__ = ["write_html", "floorplan", "top_down_axes"]

METHOD_ORDER = ("selection", "random", "fvs", "stride", "all")
N_RENDER_VIEWS = 6
THUMB_SIDE = 160


def method_name(key: str | None) -> str:
    """A selection method's name for a reader (:func:`curate.select.methods.method_label`)."""
    from curate.select.methods import method_label
    return method_label(key) if key else "—"


def _load_rgb(path: str | Path, max_side: int) -> np.ndarray | None:
    """[H, W, 3] uint8, upright, longer side <= ``max_side`` (about); None when unreadable."""
    p = Path(path)
    if not p.is_file():
        return None
    try:
        from PIL import Image, ImageOps
        with Image.open(p) as im:
            im.draft("RGB", (2 * max_side, 2 * max_side))  # JPEG: decode at a reduced size
            im = ImageOps.exif_transpose(im).convert("RGB")
            im.thumbnail((max_side, max_side))
            return np.asarray(im)
    except Exception:  # noqa: BLE001 - RAW and exotic formats: the ingest decoder
        try:
            from PIL import Image

            from curate.core.images import read_image
            rgb, _ = read_image(p)
            im = Image.fromarray(rgb)
            im.thumbnail((max_side, max_side))
            return np.asarray(im)
        except Exception as e:  # noqa: BLE001
            logger.warning("report: cannot read %s: %s", p, e)
            return None


def _img(uri: str, alt: str = "", style: str = "", cls: str = "") -> str:
    return (f'<img src="{uri}" alt="{esc(alt)}"' + (f' style="{style}"' if style else "")
            + (f' class="{cls}"' if cls else "") + ">")


# ------------------------------------------------------------------ the run's data
class _Run:
    """Everything the report reads, loaded lazily and tolerant of missing files."""

    def __init__(self, run_dir: Path):
        self.dir = run_dir
        self.rep = read_json(RunPaths(run_dir).report_json) or {}
        self.sel = read_json(RunPaths(run_dir).selection) or {}
        if not self.sel and isinstance(self.rep.get("selection"), dict):
            self.sel = self.rep["selection"]
        from curate.evaluate.units import legacy_keys   # a report of curate 0.1 called the selection 'energy'
        self.methods: dict = legacy_keys(self.rep.get("methods") or {})
        self.paired: dict = legacy_keys(self.rep.get("paired") or {})
        self.sfm_rec: dict = read_json(RunPaths(run_dir).record("sfm")) or {}
        self.sfm_stats: dict = self.sfm_rec.get("stats") or {}
        self._cams = None
        self._records = None

    @property
    def evaluated(self) -> bool:
        """The report holds an evaluation of the exported selection."""
        return bool(self.methods)

    @property
    def cams(self):
        if self._cams is None:
            from curate.core.run import load_cameras
            p = RunPaths(self.dir).cameras
            self._cams = load_cameras(self.dir) if p.is_file() else False
        return self._cams or None

    @property
    def records(self) -> dict:
        if self._records is None:
            self._records = read_json(RunPaths(self.dir).images_json) or {}
        return self._records

    def image_path(self, name: str) -> Path | None:
        """The photo of camera ``name``: the SfM working copy, else the original (import)."""
        w = RunPaths(self.dir).working_images / name
        if w.is_file():
            return w
        for r in self.records.get("photos", []):
            if name in (r.get("working"), r.get("rel")) and r.get("original"):
                return Path(r["original"])
        p = Path(name)
        return p if p.is_absolute() and p.is_file() else None


# ------------------------------------------------------------------ the first screen
GENERIC_FOLDERS = {"images", "image", "photos", "pictures", "frames", "input", "inputs", "rgb", "color", "dcim"}
"""Photo folder names that say nothing of the capture: the report is titled by their parent's name."""


def _title(run: _Run) -> str:
    """The capture's name: the photo folder's (or video's) name (its parent's when it is called
    e.g. 'images'), else the run folder's."""
    src = run.rep.get("photos") or ""
    if not src:
        return Path(run.rep.get("run_dir") or run.dir).name
    p = Path(src)
    return p.parent.name if p.name.lower() in GENERIC_FOLDERS and p.parent.name else p.name


def _warnings(run: _Run) -> list[str]:
    """What the user must know before reading any figure (each a sentence)."""
    from curate.sfm.warn import path_warning, split_warning, step_warning
    r = run.rep
    each = ((r.get("config") or {}).get("sfm") or {}).get("on_split") == "each"
    out = [w for w in (split_warning(run.dir, each=each), path_warning(run.sfm_stats), step_warning(run.sfm_stats),
                       (read_json(RunPaths(run.dir).record("export")) or {}).get("warning")) if w]
    stale = r.get("stale") or {}
    if "export" in stale:
        from curate.core.stage import refresh_command, stale_root
        cmd, root = refresh_command(run.dir, stale, "export"), stale_root(stale, "export")
        if root != "export":   # the selection shown is out of date too: redo what it rests on
            out.append(f"the selection and the export in {run.dir} rest on an out-of-date {root} stage "
                       f"({stale[root]}): `{cmd}` redoes it and what follows")
        else:
            out.append(f"the export in {run.dir / 'export'} is of an earlier selection ({stale['export']}): "
                       f"`{cmd}` makes it match this one")
    for v in run.sfm_stats.get("videos") or []:
        if v.get("stopped"):   # a damaged or cut video: the capture after that point is not in this run
            out.append(f"video {v.get('video')}: {v['stopped']}; nothing after that point is in this run")
    return out


def _verdict(run: _Run) -> str:
    from curate.report.verdict import verdict
    v = run.rep.get("verdict") or verdict(run.rep)
    s = run.sel
    how = method_name(s.get("method"))
    exp = read_json(RunPaths(run.dir).export_json) or {}
    given = s.get("budget_text") or "auto"        # "default: auto (an object capture)" when the default chose auto
    lines = [f"<p><b>{esc(v['exported'].split(' (')[0])}</b>, by {esc(how)}"
             + (f" (how many: <code>--budget {esc(given.split(':')[0])}</code>"
                + (f", auto for {esc(given.split('(', 1)[1].rstrip(')'))}" if given.startswith("default") else "")
                + f", {esc(s['budget_auto'].get('tolerance_db', ''))} dB)" if s.get("budget_auto") else "")
             + (f", exported to <code>{esc(run.dir / 'export')}</code> "
                f"({esc(exp.get('n_images', '?'))} photos for COLMAP / 3DGS, nerfstudio and Instant-NGP)." if exp
                else ".") + "</p>"]
    if v.get("frames"):
        lines.append(f"<p>{esc(v['frames'])}</p>")
    if v.get("coverage"):
        lines.append(f"<p>{esc(v['coverage'])}</p>")
    q = v.get("quality", "")
    for words in ("ahead of", "behind", "level with", "not told apart from"):   # the words that matter, in bold
        q = q.replace(words, f"\x00{words}\x01")
    q = esc(q).replace("\x00", "<b>").replace("\x01", "</b>")
    lines.append(f"<p>{q}</p>")
    if v.get("how_many"):
        lines.append(f"<p>{esc(v['how_many'])}</p>")
    if s.get("note"):
        lines.append(f'<p class="small">How the method was chosen: {esc(_plain_note(s["note"]))}.</p>')
    return '<div class="verdict">' + "".join(lines) + "</div>"


def _plain_note(text: str) -> str:
    """The selection's note with method keys spelled out for a reader."""
    from curate.select.methods import REGISTRY
    for k in sorted(REGISTRY, key=len, reverse=True):
        text = text.replace(f"-> {k}", f"-> {method_name(k)}")
    return text


def _first_screen(run: _Run) -> str:
    r = run.rep
    from curate import __version__
    made = r.get("written_at") or time.strftime("%Y-%m-%d %H:%M")
    out = [f"<h1>Photo selection: {esc(_title(run))}</h1>",
           f'<p class="small">curate {esc(r.get("version", __version__))} · {esc(made)} · run folder '
           f"<code>{esc(r.get('run_dir') or run.dir)}</code></p>"]
    for w in _warnings(run):
        out.append(f'<div class="warnbox"><b>Warning:</b> {esc(w)}.</div>')
    if r.get("parts"):  # --on-split each: the other parts, each curated in its own run folder
        rows = "".join(f'<li>part {esc(p["part"])}: {esc(p["n_registered"])} photos, {esc(p["n_chosen"])} chosen: '
                       f'<a href="{esc(p["report"])}">report</a>, export in <code>{esc(p["export"])}</code></li>'
                       for p in r["parts"])
        out.append(f'<div class="warnbox"><b>The other parts of the capture</b> (this report is part 0, the '
                   f'largest; --on-split each):<ul>{rows}</ul></div>')
    out.append(_verdict(run))
    sug = read_json(run.dir / "suggest" / "suggestions.json")
    if sug:
        out.append(f'<p>Going back to film more? <a href="suggest/suggest.html">Where to shoot next</a>: '
                   f'{esc(sug.get("placed", "?"))} suggested camera poses, with how to reach each from your '
                   'capture.</p>')
    elif (why := _unanswered(run.dir)):
        out.append(f'<p class="small">Going back to film more? <code>curate suggest</code> found nowhere to propose '
                   f"for this capture: {esc(why)}.</p>")
    else:
        out.append(f'<p class="small">Going back to film more? <code>curate suggest {esc(run.dir)} --add 8</code> '
                   "proposes where to stand and look, from this capture.</p>")
    out.append(f"<h2>The chosen photos</h2>{safe_section(_thumbnails, run)}")
    return "\n".join(out)


def _thumbnails(run: _Run) -> str:
    names = run.sel.get("chosen_names") or []
    if not names:
        return note("No chosen photos recorded.")
    order = sorted(range(len(names)), key=lambda i: names[i])   # capture order (names sort by frame / time)
    out = []
    for i in order:
        n = names[i]
        p = run.image_path(n)
        rgb = _load_rgb(p, THUMB_SIDE) if p is not None else None
        im = _img(plots.jpeg_data_uri(rgb, THUMB_SIDE, 75), n) if rgb is not None else \
            '<div style="width:160px;height:100px;background:#eee;line-height:100px">no preview</div>'
        out.append(f'<figure>{im}<figcaption title="{esc(n)}">{esc(Path(n).name)}</figcaption></figure>')
    return (f'<p class="small">{len(names)} photos, in capture order (by name).</p><div class="thumbs">'
            + "".join(out) + "</div>")


# ------------------------------------------------------------------ the evidence
def _unit_label(run: _Run, k: str) -> str:
    est = run.rep.get("estimate") or {}
    n, m = est.get("budget"), est.get("n_pool")
    if k == "selection":
        return f"this method, {n} of {m}" if n else "this method"
    if k == "random":
        return f"random subsets of {n}" if n else "random subsets"
    if k == "fvs":
        return f"farthest-view sampling, {n}" if n else "farthest-view sampling (FVS)"
    if k == "stride":
        return f"every n-th frame, {n}" if n else "every n-th frame"
    if k == "all":
        return f"all {m} photos" if m else "all photos"
    return k


def _method_table(run: _Run) -> str:
    m = run.methods
    rows = []
    for k in [k for k in METHOD_ORDER if k in m] + sorted(set(m) - set(METHOD_ORDER)):
        v = m[k]
        psnr, ssim = fmt_num(v.get("psnr")), fmt_num(v.get("ssim"), 3)
        if k == "random":                 # the spread over draws, where it was measured
            psnr += f" ± {fmt_num(v['psnr_std'])}" if v.get("psnr_std") is not None else ""
            ssim += f" ± {fmt_num(v['ssim_std'], 3)}" if v.get("ssim_std") is not None else ""
        n = v.get("n_train")              # the folds' mean: a whole count when every fold trained as many
        n = "—" if n is None else (f"{n:.0f}" if float(n).is_integer() else f"{n:.1f}")
        cls = ' class="hl"' if k == "selection" else ""
        rows.append(f'<tr{cls}><td class="l">{esc(_unit_label(run, k))}</td><td>{psnr}</td><td>{ssim}</td>'
                    f'<td>{esc(n)}</td></tr>')
    est = run.rep.get("estimate") or {}
    nseeds = len((m.get("random") or {}).get("seeds") or [])
    draws = (m.get("random") or {}).get("units") or nseeds
    out = ['<table><tr><th class="l">trained on</th><th>PSNR (dB)</th><th>SSIM</th><th>photos</th></tr>'
           + "".join(rows) + "</table>",
           '<p class="small">PSNR: how close the trained model\'s render is to the real held-out photo, in dB (higher '
           'is better; 1 dB is a visible difference). SSIM: structural similarity, 0 to 1 (higher is better).'
           + (f" Random: mean ± spread over {draws} draws." if draws else "")
           + (f" Each figure is the mean over the {est['n_holdout']} photos held out by {est['n_folds']} folds"
              + (f"; all photos were trained on in the first folds only, and scored on their "
                 f"{m['all']['n_views']} held-out photos (the gap closed compares the three on those)"
                 if (m.get("all") or {}).get("n_views", est["n_holdout"]) < est["n_holdout"] else "") + "."
              if est.get("n_folds") else "") + "</p>"]
    if run.paired:
        pr = []
        names = {"selection-random": "this method − random", "selection-fvs": "this method − FVS",
                 "selection-stride": "this method − every n-th frame"}
        from curate.report.verdict import compare
        for k, p in run.paired.items():
            pr.append(f'<tr><td class="l">{esc(names.get(k, k))}</td><td>{fmt_num(p.get("mean"), 2, True)}</td>'
                      f'<td>{fmt_num(p.get("lo"), 2, True)} .. {fmt_num(p.get("hi"), 2, True)}</td>'
                      f'<td class="l">{esc(compare(p) or "—")}</td><td>{esc(p.get("n", "—"))}</td></tr>')
        level = f'{100 * float(est.get("level") or 0.95):.3g}%'
        out.append('<table><tr><th class="l">difference, per held-out photo</th><th>mean (dB)</th>'
                   f'<th>{level} interval</th><th class="l">in words</th><th>photos</th></tr>'
                   + "".join(pr) + "</table>")
        if est.get("n_folds"):
            margin = est.get("margin_db") or 0.3
            res = est.get("resolution_db")
            resolved = (f" (measured to ±{res:g} dB or closer: the evaluation stopped training that rival, its "
                        "difference is known that closely, its sign is not)" if res else "")
            out.append(f'<p class="small">Ahead or behind: the interval excludes 0. Level with: it lies within '
                       f'±{margin:g} dB. Not told apart: neither{resolved}; more folds would narrow it. The interval '
                       "counts each fold as one draw (its trainings share their noise), and is widened so that "
                       f"stopping at the first decided look keeps the verdict's error at 5% (each look at "
                       f"{100 * (est.get('level') or 0.95):.1f}%).</p>")
    gap = run.rep.get("gap_closed")
    if gap is not None:
        out.append(f"<p>Gap closed: <b>{100 * float(gap):.0f}%</b> of the way from random subsets to all photos "
                   "((this method − random) / (all − random)).</p>")
    elif all(k in m for k in ("selection", "random", "all")):
        out.append(note("Gap closed: not defined (all photos do not beat random subsets here)."))
    out.append(_bars(run))
    return "\n".join(out)


def _bars(run: _Run) -> str:
    m = run.methods
    keys = [k for k in METHOD_ORDER if k in m and m[k].get("psnr") is not None]
    if not keys:
        return ""
    short = {"selection": "this method", "random": "random", "fvs": "FVS", "stride": "every n-th", "all": "all photos"}
    return charts.bar_chart([short[k] for k in keys], [m[k]["psnr"] for k in keys],
                            [m[k].get("psnr_std") or 0.0 for k in keys],
                            title="Held-out PSNR (random: ± spread over draws)", ylabel="PSNR (dB)", width=560,
                            height=280)


def _renders(run: _Run) -> str:
    m = run.methods
    gt_dir = RunPaths(run.dir).gt
    if not gt_dir.is_dir():
        return note("No held-out renders in this run folder.")
    cols = []  # (label, key, per_view list)
    for k, label in (("selection", "this method"), ("random", "random"), ("fvs", "FVS"), ("stride", "every n-th"),
                     ("all", "all photos")):
        v = m.get(k)
        if not v:
            continue
        if k == "random" and v.get("runs"):   # curate 0.2: one hold-out, several draws
            runs = v.get("runs") or {}
            s = "0" if "0" in runs else (sorted(runs)[0] if runs else None)
            if s is None:
                continue
            v = runs[s]
        cols.append((label, v.get("key", k), {r["name"]: r for r in v.get("per_view", [])}))
    names = [n for n in cols[0][2] if all(n in c[2] for c in cols)] if cols else []   # rendered by every subset
    if not names:
        return note("No held-out views.")
    pick = [names[i] for i in np.unique(np.linspace(0, len(names) - 1, min(N_RENDER_VIEWS, len(names))).round()
                                        .astype(int))]
    width = f"{100 / (len(cols) + 1):.2f}%"
    head = "<tr>" + "".join(f'<th style="width:{width}">{esc(c)}</th>'
                            for c in ["held-out photo"] + [c[0] for c in cols]) + "</tr>"
    rows = []
    for n in pick:
        stem = Path(n).stem
        gt = _load_rgb(gt_dir / f"{stem}.png", 200)
        cells = [f"<td>{_img(plots.jpeg_data_uri(gt, 200, 85), 'held-out photo') if gt is not None else 'missing'}"
                 f"{esc(Path(n).name)}</td>"]
        for label, key, pv in cols:
            unit = pv.get(n, {}).get("unit", key)   # the fold's unit that rendered it
            r = _load_rgb(RunPaths(run.dir).evaluate / unit / "renders" / f"{stem}.png", 200)
            score = pv.get(n, {})
            txt = f"{fmt_num(score.get('psnr'))} dB" if score else ""
            cells.append(f"<td>{_img(plots.jpeg_data_uri(r, 200, 85), label) if r is not None else 'missing'}"
                         f"{txt}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<p class="small">{len(pick)} of {len(names)} held-out photos, and what the model trained on each '
            "subset renders in their place (random: the fold's first draw).</p>"
            f'<div class="scroll"><table class="renders">{head}{"".join(rows)}</table></div>')


def _budget_auto(run) -> str:
    b = run.sel.get("budget_auto")
    if not b:
        return note(f"Budget given: {run.sel.get('budget_text', '—')} (--budget auto predicts one from the "
                    "capture's views, and on an evaluated run measures it on the capture).")
    rep = getattr(run, "rep", None) or {}
    chk = b.get("measured") or rep.get("budget_check")
    law = b.get("predicted", b["budget"])
    pts = (chk or {}).get("points") or []
    n_pool = (chk or {}).get("n_pool") or (rep.get("estimate") or {}).get("n_pool") or 1
    measured = [(p["k"] * chk["pool"] / max(n_pool, 1), p["loss"]) for p in pts] if chk else []
    ratio = (chk["alpha"] / b["alpha"]) if chk and chk.get("alpha") and b.get("alpha") else None
    svg = charts.budget_chart(b["curve_k"], b["curve_loss_db"], b["tolerance_db"], law, measured,
                              [x * ratio for x in b["curve_loss_db"]] if ratio else None,
                              chk.get("budget") if chk else None)
    rng = f" ({b['low']} to {b['high']})" if b.get("low") is not None and b["low"] != b["high"] else ""
    txt = [f"<p>Predicted from the poses alone: <b>{law}{rng}</b> of {b['pool']} photos for "
           f"{b['tolerance_db']:g} dB ({esc(b['kind'])} law).</p>"]
    if chk:
        txt.append(f"<p>Measured on this capture: {esc(chk['note'])}"
                   + (f"; <b>{esc(b['budget'])}</b> exported" if b.get("source") == "measured" else "")
                   + ". The points: the same method at " + ", ".join(f"{p['k']}" for p in pts)
                   + f" of the {n_pool} photos left after holding out every "
                   f"{(rep.get('config') or {}).get('evaluate', {}).get('holdout_every', 14)}th, on two folds, each "
                   "trained and scored against all of them (shown at the capture's scale).</p>")
    checked = (BUDGET_CHECK_OBJECT if b.get("kind") == "object" else BUDGET_CHECK_WALK)
    return ("".join(txt) + svg + "<p class=\"small\">The prediction reads how far each view of the capture is "
            "from the nearest chosen one relative to the scene's depth, through a law calibrated per kind of capture "
            f"(docs/evaluation.md, \"How many photos\"). {checked}</p>")


BUDGET_CHECK_WALK = ("Checked on a real walk the law was not fitted on: on the office (its ground-truth poses, "
                     "and its video through curate's SfM) it advised 87-90 frames for 0.5 dB where 69-70 were "
                     "enough (0.30-0.32 dB lost). On one real phone video of a living room it advised about a "
                     "quarter of what was needed: an evaluated run measures it on the capture itself and exports "
                     "what it measured.")
BUDGET_CHECK_OBJECT = ("Calibrated on three real objects, each left out: for 0.5 dB it advised 40 of 57 photos for the "
                       "fox (39 measured), 48 of 55 for the skull (41) and 34 of 40 for the templering (more than 30 "
                       "needed). Object captures of 40-60 photos need most of them.")


def _camera_layout(run: _Run) -> str:
    cams = run.cams
    if cams is None or not len(cams):
        return note("No registered cameras (sfm/cameras.json missing).")
    k, a, b, _ = top_down_axes(cams.c2w, run.sel.get("up_axis"))
    est = run.rep.get("estimate") or {}
    hold = [i for i in ((read_json(RunPaths(run.dir).summary) or {}).get("protocol") or {}).get(
        "holdout", []) if 0 <= i < len(cams)] if run.evaluated else []
    chosen = [i for i in run.sel.get("chosen", []) if 0 <= i < len(cams)]
    c, d = cams.centres, cams.view_dirs
    axes = "xyz"
    svg = charts.camera_map(c[:, [a, b]], d[:, [a, b]], chosen, "Cameras seen from above",
                            extra_xy=c[hold][:, [a, b]] if hold else None, width=640, height=520,
                            labels=(f"all photos ({len(cams)})", f"chosen ({len(chosen)})",
                                    f"held out to evaluate ({len(hold)})"), axis_labels=(axes[a], axes[b]))
    return svg + (f'<p class="small">Each dot is a camera, its tick the way it looks; {axes[k]} is up. '
                  + (f"The held-out photos (every {est.get('holdout_every')}th) only serve the evaluation; they can be "
                     "chosen too." if hold else "") + "</p>")


def _capture(run: _Run) -> str:
    """Counts that add up, from the files found to the photos the selection chose among."""
    r, st = run.rep, run.sfm_stats
    sfm = r.get("sfm") or {}
    n_files = r.get("n_photos")
    skipped, dropped = sfm.get("skipped") or [], sfm.get("dropped") or []
    unreg = sfm.get("unregistered") or []
    reg = r.get("n_registered")
    rows = []
    for v in st.get("videos") or []:
        rows.append((f"video {v.get('video')}", f"{v.get('decoded')} frames decoded, {v.get('candidates')} kept as "
                     f"candidates (the sharpest of each stretch of view change; {v.get('static', 0)} frames of the "
                     "camera standing still left out)"))
    if n_files is not None:
        rows.append(("inputs", f"{n_files} photos" + (" and candidate frames" if st.get("videos") else "")))
    if skipped:
        rows.append(("skipped", f"{len(skipped)} unreadable or not photos (listed below)"))
    if dropped:
        rows.append(("dropped", f"{len(dropped)} near-duplicates or blurry (listed below)"))
    if n_files is not None:
        rows.append(("kept", f"{n_files - len(skipped) - len(dropped)}"))
    mapper = st.get("mapper")
    how = {"incremental": "COLMAP's incremental mapper", "global": "COLMAP's global mapper (GLOMAP)"}.get(mapper)
    if reg is not None:
        given = run.sfm_rec.get("mode") == "import"
        rows.append(("registered", f"{reg} with a pose" + (" (poses given)" if given else f", by {how}" if how else "")
                     + (f"; {len(unreg)} not registered (listed below)" if unreg else "")))
    tried = st.get("mappers_tried") or {}
    inc, glo = tried.get("incremental") or {}, tried.get("global")
    joined = inc.get("joined_sizes")
    if inc and (glo is not None or joined):
        glo = glo or {}
        rows.append(("mapping", f"the incremental mapper split the capture into models of "
                     f"{', '.join(map(str, inc.get('model_sizes', [])))} photos"
                     + (f"; the parts that share frames with the largest and agree on them joined it ({joined[0]} "
                        f"photos)" if joined else "")
                     + (f"; the global mapper mapped {(glo.get('model_sizes') or ['?'])[0]} in one model" +
                        (f", kept where it agrees with the parts and can tie them together ({glo.get('pruned_to')} "
                         f"photos)" if glo.get("pruned_to") else "") if glo else "")
                     + f"; curate used {how or mapper}" + _gain_said(mapper, glo)
                     + (f": the global model disagrees with every incremental part it could be checked against "
                        f"({', '.join(f'{d:g}' for d in glo.get('part_disagreement_deg') or [] if d is not None)} deg)"
                        if glo.get("refuted") else "")))
    rows.append(("candidates", f"{r.get('n_candidates', reg)}: the selection chooses among every registered photo"))
    if st.get("n_points") is not None:
        rows.append(("3D points", f"{st['n_points']} sparse points"))
    return '<dl class="kv">' + "".join(f"<dt>{esc(k)}</dt><dd>{esc(v)}</dd>" for k, v in rows) + "</dl>" \
        + _skipped(run)


def _gain_said(mapper: str | None, glo: dict) -> str:
    """Why the incremental model was used where the global one held more photos (``glo``: SfM's
    ``mappers_tried.global``, with ``gain`` and ``gain_needed``), or ""."""
    gain, need = glo.get("gain"), glo.get("gain_needed")
    if mapper != "incremental" or gain is None or need is None or gain >= need:
        return ""
    held = f"{gain} photo{'s' * (gain != 1)} more" if gain > 0 else "no more photos"
    return (f": the global model, the less accurate of the two, held {held} than the incremental one, under the "
            f"{need} it must gain to replace it")


def _skipped(run: _Run) -> str:
    sfm = run.rep.get("sfm") or {}
    out = []
    for key, what in (("skipped", "Skipped (unreadable or not photos)"), ("dropped", "Dropped (quality)")):
        items = sfm.get(key) or []
        if items:
            rows = "".join(f'<tr><td class="l">{esc(i.get("file"))}</td><td class="l">{esc(i.get("reason"))}</td></tr>'
                           for i in items)
            out.append(f'<p>{what}: {len(items)}</p><table><tr><th class="l">file</th><th class="l">reason</th></tr>'
                       f'{rows}</table>')
    unreg = sfm.get("unregistered") or []
    if unreg:
        from curate.sfm.warn import name_ranges
        out.append(f"<p>Not registered by SfM: {len(unreg)}: {esc(name_ranges([Path(u).name for u in unreg]))}</p>")
    return "\n".join(out)


# ------------------------------------------------------------------ for experts
def _floorplan(run: _Run) -> str:
    p = RunPaths(run.dir).nodes
    if not p.is_file():
        return note("No per-node energy terms (select/nodes.npz missing).")
    z = np.load(p)
    res = int(z["res"])
    cams = run.cams
    k, a, b, _ = top_down_axes(cams.c2w if cams is not None else None, run.sel.get("up_axis"))
    lo, hi = np.asarray(z["box_min"], float), np.asarray(z["box_max"], float)
    ext = np.maximum(hi - lo, 1e-9)
    side = 300
    s = side / max(ext[a], ext[b])
    w, h = max(int(round(ext[a] * s)), 40), max(int(round(ext[b] * s)), 40)
    axes = "xyz"
    dots, n_out = None, 0
    chosen = [i for i in run.sel.get("chosen", []) if cams is not None and 0 <= i < len(cams)]
    if chosen:
        c = cams.centres[chosen]
        u = ((c[:, a] - lo[a]) / ext[a] * (res - 1) + 0.5) / res * w  # node i is pixel i's centre
        v = (1 - ((c[:, b] - lo[b]) / ext[b] * (res - 1) + 0.5) / res) * h
        ok = (u >= 0) & (u <= w) & (v >= 0) & (v <= h)
        dots, n_out = np.stack([u[ok], v[ok]], 1), int((~ok).sum())
    figs = []
    for key, title in (("angular", "seen from all around"), ("frequency", "seen often enough")):
        m = floorplan(z[key], z["flat"], res, k, a, b)
        fin = m[np.isfinite(m)]
        vlo, vhi = (float(fin.min()), float(fin.max())) if fin.size else (0.0, 1.0)  # own range: contrast
        vhi = vhi if vhi > vlo else vlo + 1.0
        uri = plots.png_data_uri(plots.colormap(m, vlo, vhi), max(1, int(math.ceil(side / res))))
        figs.append(f'<div class="fig"><div style="height:20px"><b>{title}</b></div>' + heatmap_svg(uri, w, h, dots)
                    + "<br>" + colorbar(vlo, vhi, f"mean over the vertical ({axes[k]}) axis", max(w, 240))
                    + "</div>")
    cam_txt = ""
    if dots is not None:
        cam_txt = f" Red dots: the {len(dots)} chosen cameras" + (
            f" ({n_out} more stand outside the box)." if n_out else ".")
    return ('<div class="row">' + "".join(figs) + "</div>"
            f'<p class="small">The paper\'s energy scores each point of the scene\'s surface (a grid of {res}³ cells; '
            f'{len(z["flat"])} surface points) by two terms for the chosen photos. <b>Seen from all around</b>: '
            "1 minus the total-variation distance between the directions the point is seen from and an even spread "
            "over the sphere (1: from every side; near 0: from one side only). <b>Seen often enough</b>: the share "
            "of photos seeing the point, raised to a small power γ so that it saturates once the point is seen at "
            f"all. Seen from above: {axes[a]} to the right, {axes[b]} upwards; each pixel is the mean of its vertical "
            f"column; grey: no surface point.{cam_txt}</p>")


def _energy_curve(run: _Run) -> str:
    s = run.sel
    e = s.get("energy") or []
    if not e:
        return note("No energy trace (the selection method records none).")
    x = np.arange(1, len(e) + 1)
    figs = [charts.line_chart({"E": (x, np.asarray(e, float))}, "energy E", "photos chosen", "E", 370, 260)]
    for k, title, lab in (("angular", "seen from all around, summed", "sum of (1 − TV)"),
                          ("frequency", "seen often enough, summed", "sum of frequency^γ")):
        if s.get(k) and len(s[k]) == len(e):
            figs.append(charts.line_chart({k: (x, np.asarray(s[k], float))}, title, "photos chosen", lab, 370, 260))
    return ('<div class="row">' + "".join(figs) + '</div><p class="small">The energy after each chosen photo '
            "(in the order chosen), summed over the surface points: E = the two terms' sum. The paper's method "
            "chooses the photo that raises E most at each step; the other methods are scored on it after the "
            "fact.</p>")


def _timings(run: _Run) -> str:
    st = run.rep.get("stages") or []
    if not st:
        return note("No stage timings recorded.")
    labels = {"sfm": "photos to cameras (SfM)", "occupancy": "scene occupancy",
              "budget": "how many photos (trainings)", "select": "selection",
              "evaluate": "evaluation (trainings)", "export": "export"}
    rows = "".join(f'<tr><td class="l">{esc(labels.get(t.get("name"), t.get("name")))}</td>'
                   f'<td>{duration(t.get("compute_seconds"))}</td></tr>' for t in st if t.get("name") in labels)
    wall = run.rep.get("wall_seconds")
    return ('<table><tr><th class="l">stage</th><th>took, when it last ran</th></tr>' + rows + "</table>"
            '<p class="small">The evaluation\'s figure is its trainings\' time added up; they run side by side, one '
            "per core, so the clock time is shorter, and a training's own time grows when the machine is busy."
            + (f" The last <code>curate run</code> on this folder took {esc(duration(wall))} from start to end "
               "(stages it found unchanged were not redone)." if wall is not None else "") + "</p>")


def _unanswered(run_dir: Path) -> str | None:
    """Why ``curate suggest`` found nothing to propose for this capture, while the SfM and occupancy it read hold."""
    from curate.core.stage import read_stage
    rec = read_json(run_dir / "suggest" / "unanswered.json") or {}
    now = [(read_stage(run_dir / s) or {}).get("key", "") for s in ("sfm", "occupancy")]
    return rec.get("reason") if rec.get("inputs") == now else None


def _train(run: _Run) -> str:
    """The command lines that train on the export, and what it holds."""
    from curate.export.trainable import train_commands
    exp = read_json(RunPaths(run.dir).export_json)
    if not exp:
        return note("Not exported yet: curate export RUN writes the export.")
    model = exp.get("model") or {}
    cfg = exp.get("config") or {}
    held = [f"{esc(exp.get('n_images', '?'))} images"
            + (" undistorted, with PINHOLE cameras" if model.get("undistorted") else
               f" with {esc(model.get('camera_model', 'their'))} cameras"),
            f"{esc(model.get('n_points3D', 0))} SfM points (<code>sparse/0</code>, <code>sparse_pc.ply</code>)",
            {"hardlink": "hard links or copies of the photos: the folder travels alone (tar, rsync)",
             "copy": "copies of the photos: the folder travels alone (tar, rsync)",
             "link": "symbolic links to your photos: valid only beside them (<code>--export-mode hardlink</code> "
                     "for a folder that travels)"}.get(cfg.get("mode"), "")]
    if cfg.get("downscale"):
        held.append("downscaled copies in " + ", ".join(f"<code>images_{esc(f)}</code>" for f in cfg["downscale"]))
    rows = "".join(f'<tr><td class="l">{esc(t)}</td><td class="l"><code>{esc(c)}</code></td></tr>'
                   for t, c in train_commands(RunPaths(run.dir).export))
    groups = (read_json(RunPaths(run.dir).record("export")) or {}).get("connectivity")
    return (f"<p>The export holds {'; '.join(held)}.</p>"
            + f'<table><tr><th class="l">trainer</th><th class="l">command</th></tr>{rows}</table>'
            '<p class="small">nerfstudio reads <code>transforms.json</code> (and starts splatting from its '
            "<code>ply_file_path</code>); 3DGS and gsplat read <code>sparse/0</code> with <code>images/</code>.</p>"
            + (f'<p class="small">For a tool that registers the subset again: {esc(groups)}.</p>' if groups else ""))


def _details(title: str, body: str, open_: bool = False) -> str:
    return f"<details{' open' if open_ else ''}><summary><h2>{esc(title)}</h2></summary>\n{body}\n</details>"


SECTIONS: list[tuple[str, Callable[[_Run], str], str]] = [
    ("How the selection compares (held-out photos)", _method_table, "evaluated"),
    ("Held-out photos side by side", _renders, "evaluated"),
    ("Train on the export", _train, "always"),
    ("How many photos?", _budget_auto, "always"),
    ("Where the cameras are", _camera_layout, "always"),
    ("The capture", _capture, "always"),
    ("For experts: the paper's energy over the scene", lambda r: _floorplan(r) + _energy_curve(r), "folded"),
    ("For experts: time per stage", _timings, "folded"),
]
"""(title, section, when): 'evaluated' sections appear only with an evaluation of this selection;
'folded' ones are closed <details> a reader opens."""


def write_html(run_dir: str | Path) -> Path:
    """Write ``RUN/report.html`` from ``RUN/report.json`` and the run folder; returns its path.

    ``report.json``'s ``html`` records what was written (:func:`curate.core.runfolder.file_state`): a page the user
    changed since is kept as they left it, and a warning names it (curate never writes over a user's edit)."""
    from curate.core.runfolder import file_state, is_changed
    from curate.core.stage import write_json_atomic
    run_dir = Path(run_dir)
    html = RunPaths(run_dir).report_html
    was = (read_json(RunPaths(run_dir).report_json) or {}).get("html")
    if isinstance(was, dict) and os.path.lexists(html) and is_changed(html, was):
        logger.warning("report: %s was changed since curate wrote it: kept as you left it (move it out for a new "
                       "page; report.json is up to date)", html)
        return html
    run = _Run(run_dir)
    if not run.rep:
        logger.warning("report: %s missing or unreadable; the report will be mostly empty",
                       RunPaths(run_dir).report_json)
    body = [safe_section(_first_screen, run)]
    for title, fn, when in SECTIONS:
        if when == "evaluated" and not run.evaluated:
            continue
        text = safe_section(fn, run)
        body.append(_details(title, text) if when == "folded" else f"<h2>{esc(title)}</h2>\n{text}")
    page = ('<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<title>curate: {esc(_title(run))}</title><style>{CSS}</style></head><body>\n' + "\n".join(body)
            + '\n<p class="small">Written by curate. Self-contained: every image is embedded.</p></body></html>\n')
    from curate.core.stage import write_text_atomic
    out = write_text_atomic(html, page)
    rep = read_json(RunPaths(run_dir).report_json)
    if rep:
        write_json_atomic(RunPaths(run_dir).report_json, {**rep, "html": file_state(out)})
    logger.info("report: %s (%.0f kB)", out, out.stat().st_size / 1024)
    return out
