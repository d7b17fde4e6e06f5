"""Small, dependency-free charts for self-contained HTML reports.

Line charts, scatter plots and bar charts are inline SVG strings; heat maps and image
strips are PNG data URIs (PIL). Nothing is fetched from the network.
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np

PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f"]
_VIRIDIS = np.array([[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], float)


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return [lo]
    step = 10 ** math.floor(math.log10((hi - lo) / n))
    for m in (1, 2, 5, 10):
        if (hi - lo) / (step * m) <= n:
            step *= m
            break
    t = math.ceil(lo / step) * step
    out = []
    while t <= hi + 1e-9 * step:
        out.append(round(t, 12))
        t += step
    return out


def _fmt(v: float) -> str:
    return f"{v:.4g}"


class _Frame:
    """Maps data coordinates into a plot area with axes, ticks and labels."""

    def __init__(self, xlim, ylim, width, height, title, xlabel, ylabel, equal=False, xticks=True):
        self.w, self.h = width, height
        self.l, self.r, self.t, self.b = 58, 14, 28, 42
        x0, x1 = xlim
        y0, y1 = ylim
        if x1 <= x0:
            x0, x1 = x0 - 0.5, x1 + 0.5
        if y1 <= y0:
            y0, y1 = y0 - 0.5, y1 + 0.5
        if equal:  # same scale on both axes (maps, floor plans)
            pw, ph = width - self.l - self.r, height - self.t - self.b
            s = max((x1 - x0) / pw, (y1 - y0) / ph)
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            x0, x1, y0, y1 = cx - s * pw / 2, cx + s * pw / 2, cy - s * ph / 2, cy + s * ph / 2
        self.x0, self.x1, self.y0, self.y1 = x0, x1, y0, y1
        self.parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
                      f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="11">',
                      f'<text x="{width / 2}" y="16" text-anchor="middle" font-size="13" font-weight="bold">'
                      f'{html.escape(title)}</text>']
        self._axes(xlabel, ylabel, xticks)

    def X(self, x):
        return self.l + (np.asarray(x, float) - self.x0) / (self.x1 - self.x0) * (self.w - self.l - self.r)

    def Y(self, y):
        return self.h - self.b - (np.asarray(y, float) - self.y0) / (self.y1 - self.y0) * (self.h - self.t - self.b)

    def _axes(self, xlabel, ylabel, xticks):
        p, L, R, T, B = self.parts, self.l, self.w - self.r, self.t, self.h - self.b
        p.append(f'<rect x="{L}" y="{T}" width="{R - L}" height="{B - T}" fill="none" stroke="#999"/>')
        for t in _ticks(self.x0, self.x1) if xticks else []:
            x = float(self.X(t))
            p.append(f'<line x1="{x:.1f}" y1="{B}" x2="{x:.1f}" y2="{B + 4}" stroke="#666"/>'
                     f'<text x="{x:.1f}" y="{B + 15}" text-anchor="middle">{_fmt(t)}</text>')
        for t in _ticks(self.y0, self.y1):
            y = float(self.Y(t))
            p.append(f'<line x1="{L - 4}" y1="{y:.1f}" x2="{L}" y2="{y:.1f}" stroke="#666"/>'
                     f'<line x1="{L}" y1="{y:.1f}" x2="{R}" y2="{y:.1f}" stroke="#eee"/>'
                     f'<text x="{L - 6}" y="{y + 4:.1f}" text-anchor="end">{_fmt(t)}</text>')
        p.append(f'<text x="{(L + R) / 2}" y="{self.h - 6}" text-anchor="middle">{html.escape(xlabel)}</text>')
        p.append(f'<text x="14" y="{(T + B) / 2}" text-anchor="middle" transform="rotate(-90 14 {(T + B) / 2})">'
                 f'{html.escape(ylabel)}</text>')

    def legend(self, names):
        for i, n in enumerate(names):
            y = self.t + 14 + 15 * i
            self.parts.append(f'<rect x="{self.w - self.r - 130}" y="{y - 9}" width="10" height="10" '
                              f'fill="{PALETTE[i % len(PALETTE)]}"/><text x="{self.w - self.r - 115}" y="{y}">'
                              f'{html.escape(str(n))}</text>')

    def svg(self) -> str:
        return "".join(self.parts) + "</svg>"


def _lim(arrs, pad=0.05):
    v = np.concatenate([np.asarray(a, float).ravel() for a in arrs if len(a)]) if any(len(a) for a in arrs) else np.zeros(1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    d = (hi - lo) * pad or 0.5
    return lo - d, hi + d


def line_chart(series: dict, title: str, xlabel: str, ylabel: str, width: int = 520, height: int = 300) -> str:
    """SVG line chart; ``series`` maps a name to (x [n], y [n])."""
    xs = [s[0] for s in series.values()]
    ys = [s[1] for s in series.values()]
    f = _Frame(_lim(xs, 0), _lim(ys), width, height, title, xlabel, ylabel)
    for i, (x, y) in enumerate(zip(xs, ys)):
        if len(x) == 0:
            continue
        pts = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(f.X(x), f.Y(y)))
        f.parts.append(f'<polyline points="{pts}" fill="none" stroke="{PALETTE[i % len(PALETTE)]}" stroke-width="2"/>')
        if len(x) < 30:
            for a, b in zip(f.X(x), f.Y(y)):
                f.parts.append(f'<circle cx="{a:.1f}" cy="{b:.1f}" r="2.5" fill="{PALETTE[i % len(PALETTE)]}"/>')
    if len(series) > 1:
        f.legend(series.keys())
    return f.svg()


def camera_map(xy: np.ndarray, dirs_xy: np.ndarray, chosen, title: str, extra_xy: np.ndarray | None = None,
               width: int = 520, height: int = 420, labels=("pool", "chosen", "held out")) -> str:
    """Top-down SVG of camera centres [N, 2] with view-direction ticks [N, 2]; ``chosen`` highlighted,
    ``extra_xy`` [E, 2] (e.g. held-out views) drawn as hollow squares."""
    xy = np.asarray(xy, float).reshape(-1, 2)
    pts = [xy] + ([np.asarray(extra_xy, float).reshape(-1, 2)] if extra_xy is not None else [])
    allp = np.concatenate(pts) if sum(len(p) for p in pts) else np.zeros((1, 2))
    f = _Frame(_lim([allp[:, 0]]), _lim([allp[:, 1]]), width, height, title, "x", "y", equal=True)
    span = max(f.x1 - f.x0, f.y1 - f.y0)
    d = np.asarray(dirs_xy, float).reshape(-1, 2)
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where(norm > 0, d / np.where(norm > 0, norm, 1), 0) * 0.03 * span
    chosen = set(int(k) for k in chosen)
    for k in range(len(xy)):
        on = k in chosen
        col, r = (PALETTE[1], 3.5) if on else ("#aaa", 2.0)
        x, y = float(f.X(xy[k, 0])), float(f.Y(xy[k, 1]))
        x2, y2 = float(f.X(xy[k, 0] + d[k, 0])), float(f.Y(xy[k, 1] + d[k, 1]))
        f.parts.append(f'<line x1="{x:.1f}" y1="{y:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="{col}"/>'
                       f'<circle cx="{x:.1f}" cy="{y:.1f}" r="{r}" fill="{col}"/>')
    if extra_xy is not None:
        for p in np.asarray(extra_xy, float).reshape(-1, 2):
            f.parts.append(f'<rect x="{float(f.X(p[0])) - 3:.1f}" y="{float(f.Y(p[1])) - 3:.1f}" width="6" height="6" '
                           f'fill="none" stroke="{PALETTE[2]}" stroke-width="1.5"/>')
    for i, (name, col) in enumerate(zip(labels, ("#aaa", PALETTE[1], PALETTE[2]))):
        if i == 2 and extra_xy is None:
            break
        y = f.t + 14 + 15 * i
        f.parts.append(f'<circle cx="{f.l + 10}" cy="{y - 4}" r="4" fill="{col}"/>'
                       f'<text x="{f.l + 18}" y="{y}">{html.escape(name)}</text>')
    return f.svg()


def bar_chart(names, values, errors=None, title: str = "", ylabel: str = "", width: int = 520, height: int = 300) -> str:
    """SVG bar chart with optional error bars (e.g. std over seeds)."""
    v = np.asarray(values, float)
    e = np.zeros_like(v) if errors is None else np.nan_to_num(np.asarray(errors, float))
    lo = float(np.nanmin(v - e)) if v.size else 0.0
    hi = float(np.nanmax(v + e)) if v.size else 1.0
    base = lo - 0.15 * (hi - lo or 1.0)
    f = _Frame((0, max(len(v), 1)), (base, hi + 0.05 * (hi - lo or 1.0)), width, height, title, "", ylabel,
               xticks=False)  # bars are labelled by name instead
    for i, (n, val, err) in enumerate(zip(names, v, e)):
        x0, x1 = float(f.X(i + 0.15)), float(f.X(i + 0.85))
        yv, yb = float(f.Y(val)), float(f.Y(base))
        f.parts.append(f'<rect x="{x0:.1f}" y="{yv:.1f}" width="{x1 - x0:.1f}" height="{yb - yv:.1f}" '
                       f'fill="{PALETTE[i % len(PALETTE)]}"/>'
                       f'<text x="{(x0 + x1) / 2:.1f}" y="{f.h - f.b + 15}" text-anchor="middle">{html.escape(str(n))}</text>'
                       f'<text x="{(x0 + x1) / 2:.1f}" y="{yv - 4:.1f}" text-anchor="middle">{_fmt(val)}</text>')
        if err > 0:
            xm = (x0 + x1) / 2
            f.parts.append(f'<line x1="{xm:.1f}" y1="{float(f.Y(val - err)):.1f}" x2="{xm:.1f}" '
                           f'y2="{float(f.Y(val + err)):.1f}" stroke="#000"/>')
    return f.svg()


def colormap(a: np.ndarray, lo: float | None = None, hi: float | None = None) -> np.ndarray:
    """[H, W] values -> [H, W, 3] uint8 (viridis-like); NaN is light grey."""
    a = np.asarray(a, float)
    fin = np.isfinite(a)
    lo = float(np.min(a[fin])) if lo is None and fin.any() else (lo or 0.0)
    hi = float(np.max(a[fin])) if hi is None and fin.any() else (hi if hi is not None else 1.0)
    t = np.clip((np.where(fin, a, lo) - lo) / ((hi - lo) or 1.0), 0, 1) * (len(_VIRIDIS) - 1)
    i = np.minimum(t.astype(int), len(_VIRIDIS) - 2)
    w = (t - i)[..., None]
    rgb = _VIRIDIS[i] * (1 - w) + _VIRIDIS[i + 1] * w
    rgb[~fin] = 225
    return rgb.astype(np.uint8)


def png_data_uri(img: np.ndarray, scale: int = 1) -> str:
    """[H, W, 3] uint8 (or float in [0, 1]) image -> a PNG data URI, nearest-upscaled by ``scale``."""
    from PIL import Image
    a = np.asarray(img)
    if a.dtype != np.uint8:
        a = (np.clip(a, 0, 1) * 255 + 0.5).astype(np.uint8)
    if scale > 1:
        a = a.repeat(scale, 0).repeat(scale, 1)
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def jpeg_data_uri(img: np.ndarray, max_side: int = 160, quality: int = 80) -> str:
    """A thumbnail of an [H, W, 3] uint8 image as a JPEG data URI."""
    from PIL import Image
    im = Image.fromarray(np.asarray(img, np.uint8))
    im.thumbnail((max_side, max_side))
    buf = io.BytesIO()
    im.save(buf, format="JPEG", quality=quality)
    return "data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode()


# ------------------------------------------------------------------ floor plans (the reports' maps)
def top_down_axes(c2w: np.ndarray | None, up_axis: int | None = None) -> tuple[int, int, int, float]:
    """(up axis k, horizontal axis a, horizontal axis b, sign) of a view from above.

    The up axis is ``up_axis`` when given, else the world axis most aligned with the
    cameras' mean up (-y of OpenCV cameras; axis 2 without cameras). ``(a, b)`` are
    ordered so that a map with ``a`` to the right and ``b`` upwards is seen from above
    (not mirrored): ``a x b`` points up.
    """
    up = -np.asarray(c2w, float)[:, :3, 1].mean(0) if c2w is not None and len(c2w) else np.array([0, 0, 1.0])
    k = int(np.argmax(np.abs(up))) if up_axis is None else int(up_axis)
    sign = 1.0 if up[k] >= 0 else -1.0
    a, b = (k + 1) % 3, (k + 2) % 3
    if sign < 0:
        a, b = b, a
    return k, a, b, sign


def floorplan(values: np.ndarray, flat: np.ndarray, res: int, up: int, a: int, b: int) -> np.ndarray:
    """Per-node values [M] at flat grid indices [M] -> [R_b, R_a] map averaged over the vertical axis.

    Columns without any node are NaN. Row 0 is the largest ``b`` (the map is drawn with
    ``b`` upwards), column 0 the smallest ``a``.
    """
    vol = np.full(res ** 3, np.nan)
    vol[np.asarray(flat, np.int64)] = np.asarray(values, float)
    vol = vol.reshape(res, res, res)
    have = np.isfinite(vol)
    s = np.where(have, vol, 0.0).sum(axis=up)
    n = have.sum(axis=up)
    m = np.where(n > 0, s / np.maximum(n, 1), np.nan)  # 2-D over the two remaining axes, in index order
    rest = [ax for ax in range(3) if ax != up]
    if rest != [a, b]:
        m = m.T  # now [R_a, R_b]
    return m.T[::-1]


def colorbar(lo: float, hi: float, label: str, width: int = 260) -> str:
    """Horizontal SVG colour bar of :func:`colormap` over [lo, hi] with round ticks."""
    stops = "".join(f'<stop offset="{i / (len(_VIRIDIS) - 1):.2f}" stop-color="rgb({int(c[0])},{int(c[1])},'
                    f'{int(c[2])})"/>' for i, c in enumerate(_VIRIDIS))
    gid = f"cb{abs(hash((lo, hi, label))) % 10 ** 8}"
    span = (hi - lo) or 1.0
    ticks = "".join(f'<line x1="{x:.1f}" y1="20" x2="{x:.1f}" y2="24" stroke="#666"/>'
                    f'<text x="{x:.1f}" y="35" text-anchor="middle">{_fmt(t)}</text>'
                    for t in _ticks(lo, hi, 6) for x in [10 + (t - lo) / span * (width - 20)])
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="52" font-family="sans-serif" '
            f'font-size="11"><defs><linearGradient id="{gid}">{stops}</linearGradient></defs>'
            f'<rect x="10" y="6" width="{width - 20}" height="14" fill="url(#{gid})" stroke="#999"/>{ticks}'
            f'<text x="{width / 2}" y="49" text-anchor="middle" fill="#555">{html.escape(label)}</text></svg>')


def heatmap_svg(img_uri: str, w: int, h: int, dots: np.ndarray | None = None) -> str:
    """SVG of a heat map image [w x h px] with optional markers at pixel positions ``dots`` [N, 2]."""
    marks = "" if dots is None else "".join(
        f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3.2" fill="#d62728" stroke="#fff" stroke-width="1"/>' for x, y in dots)
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}">'
            f'<image href="{img_uri}" width="{w}" height="{h}" preserveAspectRatio="none" '
            f'style="image-rendering:pixelated"/>{marks}</svg>')
