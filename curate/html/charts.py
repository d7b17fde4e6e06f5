"""Charts of the HTML reports, drawn by matplotlib (Agg) as self-contained inline SVG.

Each function returns an ``<svg>`` element (no XML prologue, no external reference) sized in
CSS pixels. matplotlib is imported on first use, so importing this module costs nothing.
"""

from __future__ import annotations

import io
import re

import numpy as np

PALETTE = ("#4c72b0", "#dd8452", "#55a868", "#c44e52", "#8172b3", "#937860", "#da8bc3")
"""Series colours, in order."""

_DPI = 100.0


def figure(width: int, height: int):
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    plt.rcParams.update({"svg.fonttype": "none", "font.size": 9, "axes.spines.top": False,
                         "axes.spines.right": False, "svg.hashsalt": "curate"})
    fig, ax = plt.subplots(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
    return fig, ax


def svg(fig) -> str:
    """The figure as an inline ``<svg>`` string (deterministic ids), the figure closed."""
    import matplotlib.pyplot as plt
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None, "Creator": None})
    plt.close(fig)
    s = buf.getvalue()
    s = re.sub(r"<metadata>.*?</metadata>\s*", "", s[s.index("<svg"):], flags=re.S)   # RDF: not needed inline
    return re.sub(r'\s+xmlns:(dc|cc|rdf)="[^"]*"', "", s)


def _finite(a) -> np.ndarray:
    a = np.asarray(a, np.float64).ravel()
    return a[np.isfinite(a)]


def line_chart(series: dict, title: str, xlabel: str, ylabel: str, width: int = 520, height: int = 300) -> str:
    """Line chart; ``series`` maps a name to (x [n], y [n]) (non-finite points are skipped)."""
    fig, ax = figure(width, height)
    for i, (name, (x, y)) in enumerate(series.items()):
        x, y = np.asarray(x, np.float64).ravel(), np.asarray(y, np.float64).ravel()
        ok = np.isfinite(x) & np.isfinite(y) if len(x) == len(y) else np.zeros(0, bool)
        if ok.any():
            ax.plot(x[ok], y[ok], color=PALETTE[i % len(PALETTE)], lw=1.8, label=str(name),
                    marker="o" if ok.sum() < 30 else None, ms=3)
    ax.set_title(title)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if len(series) > 1:
        ax.legend(frameon=False)
    return svg(fig)


def budget_chart(k, loss, tolerance: float, chosen: int, measured=None, check_loss=None, advised: int | None = None,
                 width: int = 520, height: int = 300) -> str:
    """``--budget auto``: the predicted loss [n] against the budgets ``k`` [n], the tolerance as a
    dashed line, the chosen budget as a dot; ``measured``: the budget check's points [(k, loss dB)]
    as crosses, ``check_loss`` [n] its fitted curve at ``k`` and ``advised`` its budget."""
    fig, ax = figure(width, height)
    k, loss = np.asarray(k, np.float64).ravel(), np.asarray(loss, np.float64).ravel()
    ok = np.isfinite(k) & np.isfinite(loss) if len(k) == len(loss) else np.zeros(0, bool)
    ax.plot(k[ok], loss[ok], color=PALETTE[0], lw=1.8, label="predicted from the poses")
    ax.axhline(tolerance, color="#888888", lw=1, ls="--", label=f"tolerance {tolerance:g} dB")
    if ok.any():
        at = float(np.interp(chosen, k[ok], loss[ok]))
        ax.plot([chosen], [at], "o", color=PALETTE[0], ms=7, label=f"predicted budget: {chosen}")
    top = max(5.0 * tolerance, 2.0)
    if check_loss is not None and len(check_loss) == len(k):
        cl = np.asarray(check_loss, np.float64)
        ax.plot(k[ok], cl[ok], color=PALETTE[1], lw=1.8, ls="-.", label="fitted to the measured points")
        if advised is not None:
            ax.plot([advised], [float(np.interp(advised, k[ok], cl[ok]))], "o", color=PALETTE[1], ms=7,
                    label=f"measured budget: {advised}")
    if measured:
        mk, ml = np.asarray(measured, np.float64).reshape(-1, 2).T
        ax.plot(mk, ml, "x", color=PALETTE[2], ms=8, mew=2, label="measured on this capture")
        top = max(top, float(np.nanmax(ml)) * 1.2)
    ax.set_xscale("log")
    ax.set_ylim(0, min(top, float(loss[ok].max()) * 1.05) if ok.any() and loss[ok].max() > top / 5 else top)
    ax.set_title("Held-out PSNR lost against all photos")
    ax.set_xlabel("photos chosen (log scale)")
    ax.set_ylabel("dB below all photos")
    ax.legend(frameon=False, fontsize=8)
    return svg(fig)


def bar_chart(names, values, errors=None, title: str = "", ylabel: str = "", width: int = 520,
              height: int = 300) -> str:
    """Bar chart with optional error bars (e.g. std over seeds). Each bar's value is written above
    its error bar, never through it. When the bars are close to each other the value axis is cut
    (it would hide the differences) and the chart says where it starts."""
    v = np.asarray(values, np.float64).ravel()
    e = np.zeros_like(v) if errors is None else np.nan_to_num(np.asarray(errors, np.float64).ravel())
    fig, ax = figure(width, height)
    x = np.arange(len(v))
    ok = np.isfinite(v)
    ax.bar(x[ok], v[ok], color=[PALETTE[i % len(PALETTE)] for i in x[ok]], width=0.7,
           yerr=np.where(e[ok] > 0, e[ok], np.nan), capsize=4, error_kw={"elinewidth": 1.2})
    ax.set_xticks(x, [str(n) for n in names])
    top = v + e
    if ok.any():
        lo, hi = float(np.min((v - e)[ok])), float(np.max(top[ok]))
        span = max(hi - lo, 1e-9)
        base = 0.0 if lo <= 0 or lo < 4 * span else lo - 0.6 * span      # cut only when it hides the differences
        ax.set_ylim(base, hi + 0.25 * span + (0 if base else 0.05 * hi))
        pad = 0.04 * (ax.get_ylim()[1] - base)
        for xi, vi, ti in zip(x[ok], v[ok], top[ok]):
            ax.text(xi, ti + pad, f"{vi:.2f}", ha="center", va="bottom")
        if base > 0:
            ax.set_title((title + "\n" if title else "") + f"(value axis starts at {base:.1f}, not 0)", fontsize=9)
        else:
            ax.set_title(title)
    else:
        ax.set_title(title)
    for xi in x[~ok]:
        ax.text(xi, 0, "n/a", ha="center", va="bottom", color="#777")
    ax.set_ylabel(ylabel)
    return svg(fig)


def camera_map(xy: np.ndarray, dirs_xy: np.ndarray, chosen, title: str, extra_xy: np.ndarray | None = None,
               width: int = 520, height: int = 420, labels=("pool", "chosen", "held out"),
               axis_labels: tuple[str, str] = ("x", "y")) -> str:
    """Top-down map of camera centres [N, 2] with view-direction ticks [N, 2]; ``chosen`` highlighted,
    ``extra_xy`` [E, 2] (e.g. held-out views) drawn as hollow squares. The legend shows each mark as
    it is drawn (the legend is made from the drawn marks). ``axis_labels``: the world axes plotted
    horizontally and vertically."""
    return svg(camera_map_figure(xy, dirs_xy, chosen, title, extra_xy, width, height, labels, axis_labels)[0])


def camera_map_figure(xy, dirs_xy, chosen, title, extra_xy=None, width=520, height=420,
                      labels=("pool", "chosen", "held out"), axis_labels=("x", "y")):
    """(figure, axes) of :func:`camera_map`."""
    xy = np.asarray(xy, np.float64).reshape(-1, 2)
    d = np.asarray(dirs_xy, np.float64).reshape(-1, 2)
    fig, ax = figure(width, height)
    allp = np.concatenate([xy] + ([np.asarray(extra_xy, np.float64).reshape(-1, 2)] if extra_xy is not None else []))
    allp = allp[np.all(np.isfinite(allp), axis=1)]
    span = float(np.ptp(allp, axis=0).max()) if len(allp) > 1 else 1.0
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where(norm > 0, d / np.where(norm > 0, norm, 1.0), 0.0) * 0.03 * (span or 1.0)
    on = np.zeros(len(xy), bool)
    on[[int(k) for k in chosen if 0 <= int(k) < len(xy)]] = True
    for mask, col, size, lab in ((~on, "#aaaaaa", 8, labels[0]), (on, PALETTE[1], 22, labels[1])):
        if mask.any():
            seg = np.stack([xy[mask], xy[mask] + d[mask]], 1)
            from matplotlib.collections import LineCollection
            ax.add_collection(LineCollection(seg, colors=col, linewidths=1))
            ax.scatter(xy[mask, 0], xy[mask, 1], s=size, color=col, label=lab, zorder=3)
    if extra_xy is not None and len(extra_xy):
        e = np.asarray(extra_xy, np.float64).reshape(-1, 2)
        ax.scatter(e[:, 0], e[:, 1], s=30, marker="s", facecolors="none", edgecolors=PALETTE[2], linewidths=1.4,
                   label=labels[2], zorder=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title)
    ax.set_xlabel(axis_labels[0])
    ax.set_ylabel(axis_labels[1])
    ax.legend(frameon=False, loc="best", fontsize=8)
    return fig, ax


def text_of(svg: str) -> str:
    """The text an SVG chart shows (for tests): its ``<text>`` contents joined."""
    return " ".join(re.findall(r"<text[^>]*>([^<]*)</text>", svg))
