"""Images of the HTML reports: floor plans (heat maps), colour bars, thumbnails as data URIs.

Heat maps and image strips are PNG / JPEG data URIs (PIL), colour bars small inline SVG;
the charts are drawn by matplotlib in :mod:`curate.html.charts`. Nothing is fetched from
the network.
"""

from __future__ import annotations

import base64
import html
import io
import math

import numpy as np

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
