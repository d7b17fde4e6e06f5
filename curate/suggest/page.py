"""``RUN/suggest/suggest.html``: where to shoot next, for a person planning a re-shoot.

Self-contained (inline SVG and data-URI images, nothing fetched). Sections: what was done and the capture's
units; the floor plan (seen from above: how thinly each part of the scene is covered, before and after the
suggestions, the captured path, the chosen subset and the suggestions as numbered arrows, each with a dotted
line from the frame its instruction starts at); one card per suggestion (the nearest frame's thumbnail, the
walking instruction, the field's render of the suggested view when a field is trained, height, pitch and
energy gain); the files for tools; how the poses were chosen (the feasibility envelope, timings).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from curate.core.paths import RunPaths
from curate.html.parts import CSS, esc, note

log = logging.getLogger(__name__)

THUMB = 220
"""Longer side of the nearest frames' thumbnails in the page (pixels)."""
ARROW = "#1f4fd1"
PATH = "#555555"
CHOSEN = "#2ca02c"

PAGE_CSS = """
.cards{display:grid;grid-template-columns:repeat(auto-fill,minmax(540px,1fr));gap:14px}
.card{border:1px solid #ddd;border-radius:6px;padding:10px 12px;background:#fcfcfc}
.card h3{margin:0 0 6px 0;font-size:16px}.card .num{display:inline-block;background:#1f4fd1;color:#fff;
border-radius:50%;width:24px;height:24px;text-align:center;line-height:24px;margin-right:6px}
.card .imgs{display:flex;gap:10px}.card figure{margin:0;font-size:11px;color:#555;text-align:center}
.card img{max-width:250px;max-height:190px;display:block;border:1px solid #ccc}
.card .instr{font-size:15px;margin:8px 0 4px 0}
"""


def _load_thumb(path: str, side: int) -> np.ndarray | None:
    try:
        from PIL import Image, ImageOps
        with Image.open(path) as im:
            im.draft("RGB", (2 * side, 2 * side))
            im = ImageOps.exif_transpose(im).convert("RGB")
            im.thumbnail((side, side))
            return np.asarray(im)
    except Exception as e:  # noqa: BLE001 - a missing or unreadable photo: no thumbnail, never a failed page
        log.info("suggest page: no thumbnail of %s (%s)", path, e)
        return None


def floor_plan_svg(rec: dict, inp, pl, used: np.ndarray) -> str:
    """The floor plans (now, with the path, the chosen subset and the suggestions; and after the suggestions) as
    one inline SVG (module docstring)."""
    from curate.html.charts import figure, svg
    from curate.html.plots import floorplan, top_down_axes
    cams = inp.cams
    k, a, b, _ = top_down_axes(cams.c2w)
    res = inp.res
    flat = np.flatnonzero(used.ravel())
    lo, hi = inp.box_min, inp.box_max
    score_b = pl.before.angular_per_node + pl.before.frequency_per_node
    score_a = pl.after.angular_per_node + pl.after.frequency_per_node
    maps = [floorplan(v, flat, res, k, a, b) for v in (1 - 0.5 * score_b, score_a - score_b)]
    ranges = []
    for m, (plo, phi) in zip(maps, ((2, 98), (50, 99))):
        fin = m[np.isfinite(m)]
        lo_, hi_ = (float(np.percentile(fin, plo)), float(np.percentile(fin, phi))) if fin.size else (0.0, 1.0)
        ranges.append((lo_, hi_ if hi_ > lo_ + 1e-9 else lo_ + 1e-3))
    ranges[1] = (0.0, max(ranges[1][1], 1e-6))
    half = 0.5 * (hi - lo) / max(res - 1, 1)
    extent = (lo[a] - half[a], hi[a] + half[a], lo[b] - half[b], hi[b] + half[b])
    c, s_xyz = cams.centres, np.array([x["centre"] for x in rec["suggestions"]]).reshape(-1, 3)
    # the view: the box, or the cameras' and suggestions' extent when the box is much larger (an SfM box)
    pts = np.concatenate([c[:, [a, b]], s_xyz[:, [a, b]]])
    pad = 0.25 * max(float(np.ptp(pts[:, 0])), float(np.ptp(pts[:, 1])), 1e-6)
    view = (max(extent[0], pts[:, 0].min() - pad), min(extent[1], pts[:, 0].max() + pad),
            max(extent[2], pts[:, 1].min() - pad), min(extent[3], pts[:, 1].max() + pad))
    ext_a, ext_b = view[1] - view[0], view[3] - view[2]
    w = 1120
    main_w = 0.64 * w
    h = int(np.clip(main_w * ext_b / max(ext_a, 1e-9), 320, 820)) + 70
    fig, _ = figure(w, h)
    fig.clf()
    gs = fig.add_gridspec(2, 2, width_ratios=(2.0, 1.0), height_ratios=(1.0, 0.035), wspace=0.12, hspace=0.32)
    axs = [fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])]
    cax = [fig.add_subplot(gs[1, 0]), fig.add_subplot(gs[1, 1])]
    import matplotlib
    cmaps = [matplotlib.colormaps[n].copy() for n in ("YlOrRd", "Blues")]
    for cm in cmaps:
        cm.set_bad("#efefef")
    sd = np.array([x["view_dir"] for x in rec["suggestions"]]).reshape(-1, 3)
    L = 0.1 * max(ext_a, ext_b)
    for i_ax, (ax, m, title) in enumerate(zip(axs, maps, ("how thin your capture is now",
                                                          f"what the {len(s_xyz)} suggested photos add"))):
        im = ax.imshow(np.ma.masked_invalid(m), extent=extent, origin="upper", cmap=cmaps[i_ax], vmin=ranges[i_ax][0],
                       vmax=ranges[i_ax][1], interpolation="nearest", aspect="equal")
        cb = fig.colorbar(im, cax=cax[i_ax], orientation="horizontal")
        cb.set_label("thin: 1 − node score / 2 (column mean)" if i_ax == 0 else "score added (column mean)")
        if i_ax == 0:
            ax.plot(c[:, a], c[:, b], "-", color=PATH, lw=0.9, alpha=0.85, label="captured path")
            ax.plot(c[:1, a], c[:1, b], "o", ms=6, mfc="white", mec=PATH, mew=1.2, label="start")
            ch = [i for i in inp.chosen if 0 <= i < len(cams)]
            if ch:
                ax.plot(c[ch, a], c[ch, b], "o", ms=3.4, color=CHOSEN, label=f"chosen subset ({len(ch)})")
            for i in range(len(s_xyz)):
                ref = rec["suggestions"][i]["nearest"]["frame"]
                ax.plot([c[ref, a], s_xyz[i, a]], [c[ref, b], s_xyz[i, b]], ":", color=ARROW, lw=1.0)
        for i in range(len(s_xyz)):
            dxy = np.array([sd[i, a], sd[i, b]])
            n = float(np.linalg.norm(dxy))
            dxy = dxy / n * L if n > 1e-6 else np.zeros(2)
            ax.annotate("", xy=(s_xyz[i, a] + dxy[0], s_xyz[i, b] + dxy[1]), xytext=(s_xyz[i, a], s_xyz[i, b]),
                        arrowprops=dict(arrowstyle="-|>", color=ARROW, lw=2.0, mutation_scale=14), zorder=4)
            ax.plot(s_xyz[i, a], s_xyz[i, b], "o", ms=15 if i_ax == 0 else 11, color=ARROW, mec="white", mew=1.2,
                    zorder=5, label="suggestion (arrow: where it looks)" if i == 0 and i_ax == 0 else None)
            ax.text(s_xyz[i, a], s_xyz[i, b], str(i + 1), color="white", fontsize=8.5 if i_ax == 0 else 7,
                    ha="center", va="center", fontweight="bold", zorder=6)
        ax.set_title(title)
        ax.set_xlabel("xyz"[a])
        ax.set_xlim(view[0], view[1])
        ax.set_ylim(view[2], view[3])
    for ax in axs:
        ax.set_ylabel("xyz"[b])
    pos = axs[1].get_position()          # the legend under the small map, where the figure has room
    fig.legend(*axs[0].get_legend_handles_labels(), loc="upper left", bbox_to_anchor=(pos.x0, pos.y0 - 0.07),
               ncol=1, frameon=False, fontsize=9)
    return svg(fig)


def _cards(rec: dict, inp, d: Path) -> str:
    from curate.html.plots import jpeg_data_uri, png_data_uri
    out = []
    units = "m" if rec["units"] == "m" else "units"
    for s in rec["suggestions"]:
        ref = s["nearest"]["frame"]
        rgb = _load_thumb(inp.paths[ref], THUMB) if inp.paths[ref] else None
        thumb = (f'<img src="{jpeg_data_uri(rgb, THUMB, 80)}" alt="nearest frame">' if rgb is not None
                 else '<div style="width:200px;height:130px;background:#eee;line-height:130px">no photo</div>')
        figs = [f"<figure>{thumb}<figcaption>start: {esc(s['nearest_label'])}</figcaption></figure>"]
        if s.get("preview") and (d / s["preview"]).is_file():
            from PIL import Image
            with Image.open(d / s["preview"]) as im:
                prev = np.asarray(im.convert("RGB"))
            figs.append(f'<figure><img src="{png_data_uri(prev)}" alt="preview"><figcaption>the field\'s render of '
                        "the suggested view (blurry: thinly covered)</figcaption></figure>")
        out.append(
            f'<div class="card"><h3><span class="num">{s["index"]}</span>{esc(s["name"])}</h3>'
            f'<div class="imgs">{"".join(figs)}</div>'
            f'<p class="instr">{esc(s["nearest"]["text"])}</p>'
            f'<p class="small">height {s["height"]:.2f} {units} along the capture\'s up, pitch {s["pitch_deg"]:+.0f}°; '
            f'energy gain {s["energy_gain"]:.2f}</p></div>')
    return '<div class="cards">' + "".join(out) + "</div>"


def _how(rec: dict) -> str:
    env, t = rec["envelope"], rec["timing"]
    u = "m" if rec["units"] == "m" else "units"
    p = env["pitch_deg"]
    cfg = rec.get("config") or {}
    hp, pp = cfg.get("height_percentiles", (5, 95)), cfg.get("pitch_percentiles", (5, 95))
    cp, vp = cfg.get("clearance_percentile", 10), cfg.get("view_percentile", 10)
    rows = [("capture", f"{rec['n_capture']} registered frames (every one counts as already taken)"),
            ("objective", f"the paper's energy over {rec['n_nodes']} nodes"
             + (f" ({rec['n_frontier']} of them unobserved voxels at the edge of the seen free space)"
                if rec.get("n_frontier") else " (the occupied surface band)")
             + f"; occupancy from {rec['occupancy']}"),
            *((("where", f"an object capture: on its view sphere, {o['radii'][0]:.2f} to {o['radii'][1]:.2f} {u} "
                          f"from the object's centre, at elevations {o['elevation_deg'][0]:+.0f}° to "
                          f"{o['elevation_deg'][1]:+.0f}° (the capture filmed {o['captured_elevation_deg'][0]:+.0f}° "
                          f"to {o['captured_elevation_deg'][1]:+.0f}°), looking at the centre, no roll; "
                          f"{100 * rec.get('feasible_share', 0):.0f}% of the sphere feasible"),)
              if (o := rec.get("orbit")) else
              (("where", f"in the {rec['free_voxels']} voxels the capture's rays crossed as free space before the "
                         f"surfaces they hit; {rec.get('feasible_voxels', 0)} of them at the capture's heights and "
                         "clear of occupied nodes and of space it did not see"),
               ("heights", f"{env['heights'][0]:.2f} to {env['heights'][1]:.2f} {u} along the capture's up (its "
                           f"{hp[0]:g}th to {hp[1]:g}th percentile)"),
               ("pitches", f"{p[0]:+.0f}° to {p[1]:+.0f}° (the capture's {pp[0]:g}th to {pp[1]:g}th percentile), "
                           "no roll"))),
            ("clearance", f"centre at least {env['clearance']:.2f} {u} from occupied nodes"
                          + ("" if rec.get("orbit") else " and from space the capture did not see to be empty")
                          + f" (the capture's {cp:g}th percentile, at least one voxel, at most a quarter of its "
                          f"typical viewing distance); nothing occupied nearer than {env['view_margin']:.2f} {u} in "
                          f"view (the {vp:g}th percentile of the nearest surfaces it saw, at least one voxel, at most "
                          "half the typical viewing distance)"),
            ("placement", "greedy, as Algorithm 1: "
                          f"{int(np.median(rec['n_candidates'])) if rec['n_candidates'] else 0} "
                          "feasible random candidates per photo, each scored by the energy of the capture, the "
                          "photos placed before it and itself"),
            ("time", f"{t['ms_per_camera']:.0f} ms per placed photo, {t['ms_per_candidate']:.2f} ms per candidate "
                     f"(scoring alone {t['ms_per_candidate_scoring']:.2f} ms)")]
    return '<dl class="kv">' + "".join(f"<dt>{esc(k)}</dt><dd>{esc(v)}</dd>" for k, v in rows) + "</dl>"


def write_page(run_dir: Path, d: Path, rec: dict, inp, pl, used: np.ndarray) -> Path:
    """Write ``d/suggest.html``; returns its path."""
    from curate.core.stage import write_text_atomic
    units = ("metres (--metres: your poses are in metres)" if rec["units"] == "m" else
             "the capture's own units: SfM does not know the scale, and a pose file may be rescaled "
             "(--metres if yours are in metres)")
    e0, e1 = rec["energy_before"], rec["energy"][-1] if rec["energy"] else rec["energy_before"]
    c = inp.cams.centres
    path_len = float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum()) if len(c) > 1 else 0.0
    u = "m" if rec["units"] == "m" else "units"
    scale = (f" For scale: your captured path is {path_len:.1f} {u} long, and what you filmed was typically "
             f"{rec['envelope']['look_depth']:.1f} {u} away from the camera.")
    back = (' · <a href="../report.html">the run\'s report</a>' if RunPaths(run_dir).report_html.is_file() else "")
    head = (f"<h1>Where to shoot next</h1><p class=\"small\">{esc(run_dir)}{back}</p>"
            f'<p class="verdict">{len(rec["suggestions"])} more photos, in the order of what they add: the energy '
            f"of the capture (Kopanas &amp; Drettakis 2023) rises from {e0:.1f} to {e1:.1f} "
            f"({100 * (e1 - e0) / max(abs(e0), 1e-9):+.1f}%).</p>"
            f'<p>Distances are in {esc(units)}. Each instruction starts from the frame of your capture nearest to '
            "the suggested view: find that moment in your video (or that photo), stand there, then move and turn as "
            "it says. <i>Left</i>, <i>right</i>, <i>forward</i> are as seen by the camera at that frame."
            f"{esc(scale)}</p>")
    try:
        plan = floor_plan_svg(rec, inp, pl, used)
    except Exception as e:  # noqa: BLE001 - a failed figure must not lose the page
        log.warning("suggest page: floor plan failed: %s: %s", type(e).__name__, e)
        plan = note(f"Floor plan not available ({type(e).__name__}: {e}).")
    plan_note = ('<p class="small">Seen from above. Colour: how thinly each column of the scene is covered, averaged '
                 "over its nodes: 1 − score / 2, where a node scores up to 2 in the paper's energy (up to 1 for being "
                 "seen from directions spread evenly over the sphere, up to 1 for being seen at all); red: thin, pale: "
                 "well covered, grey: no node; the colour scale spans this capture's own range. Right: how much the "
                 "suggested photos raise the nodes' scores (blue: most). Grey line: the "
                 "captured path (open circle: its start); green: the subset curate chose; blue: the suggestions, "
                 "numbered in order, arrows pointing where they look, dotted lines from the frame each instruction "
                 "starts at.</p>")
    files = ("<ul>" + "".join(f'<li><a href="{f}">{f}</a>: {esc(w)}</li>' for f, w in (
        ("transforms.json", "nerfstudio / instant-ngp poses (OpenGL convention), file names suggest_XX.jpg"),
        ("images.txt", "COLMAP text poses, with cameras.txt (PINHOLE)"),
        ("suggestions.json", "everything on this page, for programs"))) + "</ul>"
             + '<p class="small">Same world frame as the run\'s cameras (RUN/sfm/cameras.json).</p>')
    body = [head, "<h2>Floor plan</h2>", plan, plan_note, "<h2>The suggested photos</h2>", _cards(rec, inp, d),
            "<h2>Files for tools</h2>", files, "<h2>How they were chosen</h2>", _how(rec)]
    if rec.get("field") is None:
        body.insert(6, note("No trained field in this run: no previews (`curate suggest RUN --field train` trains "
                            "one)."))
    page = ('<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>curate: where to shoot next</title>'
            f"<style>{CSS}{PAGE_CSS}</style></head><body>\n" + "\n".join(body)
            + '\n<p class="small">Written by curate suggest. Self-contained: every image is embedded.</p>'
              "</body></html>\n")
    return write_text_atomic(d / "suggest.html", page)

