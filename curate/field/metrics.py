"""Render any camera with a trained field, and score renders (PSNR, SSIM).

Rays go through pixel centres (half-integers, the project's convention) of a pinhole
camera, with OpenCV ``k1 k2 p1 p2`` lens distortion undone (the rays of the real pixels).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

import numpy as np
import torch

from curate.core.cameras import Cameras

log = logging.getLogger(__name__)


def undistort(xd: np.ndarray, yd: np.ndarray, dist: np.ndarray, iters: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Invert OpenCV ``k1 k2 p1 p2`` distortion of normalised image coordinates (fixed point)."""
    k1, k2, p1, p2 = (float(v) for v in dist)
    x, y = xd.copy(), yd.copy()
    for _ in range(iters):
        r2 = x * x + y * y
        rad = 1 + k1 * r2 + k2 * r2 * r2
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x, y = (xd - dx) / rad, (yd - dy) / rad
    return x, y


def camera_rays(cams: Cameras, i: int, device: str | torch.device = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    """World rays of every pixel of camera ``i``, row-major.

    Returns:
        o: [H*W, 3] origins, d: [H*W, 3] unit directions (float32).
    """
    w, h = int(cams.width[i]), int(cams.height[i])
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)  # [H, W]
    x, y = (u - cams.cx[i]) / cams.fx[i], (v - cams.cy[i]) / cams.fy[i]
    if np.any(cams.dist[i] != 0):
        x, y = undistort(x, y, cams.dist[i])
    dc = np.stack([x, y, np.ones_like(u)], -1)
    d = dc.reshape(-1, 3) @ cams.rotations[i].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(cams.centres[i], d.shape)
    return (torch.as_tensor(np.ascontiguousarray(o), dtype=torch.float32, device=device),
            torch.as_tensor(d, dtype=torch.float32, device=device))


@torch.no_grad()
def render_image(field, cams: Cameras, i: int, chunk: int = 16384, with_depth: bool = False):
    """Render camera ``i`` of ``cams`` at its own resolution (use ``cams.scaled_images`` for another).

    Returns:
        rgb [H, W, 3] float32 numpy in [0, 1] (and depth [H, W] when ``with_depth``).
    """
    dev = field.centre.device
    o, d = camera_rays(cams, i, dev)
    rgb, depth = [], []
    for s in range(0, o.shape[0], chunk):
        out = field.render_rays(o[s:s + chunk], d[s:s + chunk])
        rgb.append(out["rgb"])
        depth.append(out["depth"])
    h, w = int(cams.height[i]), int(cams.width[i])
    img = torch.cat(rgb).clamp(0, 1).reshape(h, w, 3).cpu().numpy()
    if with_depth:
        return img, torch.cat(depth).reshape(h, w).cpu().numpy()
    return img


def psnr(pred: np.ndarray, gt: np.ndarray) -> float:
    """PSNR in dB of two [H, W, 3] images in [0, 1]."""
    mse = float(np.mean((np.asarray(pred, np.float64) - np.asarray(gt, np.float64)) ** 2))
    return float(-10 * np.log10(max(mse, 1e-12)))


def ssim(pred: np.ndarray, gt: np.ndarray) -> float:
    """SSIM of two [H, W, 3] images in [0, 1] (scikit-image, channel_axis=-1, data_range=1)."""
    from skimage.metrics import structural_similarity
    p, g = np.asarray(pred, np.float64), np.asarray(gt, np.float64)
    win = min(7, min(p.shape[:2]) // 2 * 2 - 1)
    return float(structural_similarity(p, g, channel_axis=-1, data_range=1.0, win_size=max(win, 3)))


def save_png(img: np.ndarray, path: str | Path) -> Path:
    """Write a [H, W, 3] float image in [0, 1] as an 8-bit PNG."""
    from PIL import Image
    from curate.core.stage import writing
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with writing(path):
        Image.fromarray((np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)).save(path)
    return path


def evaluate(field, cams: Cameras, images: Sequence[np.ndarray], out_dir: str | Path | None = None,
             prefix: str = "view") -> dict:
    """Render every camera, score against ``images`` ([H, W, 3] float, same sizes as ``cams``).

    Returns a dict with ``psnr`` / ``ssim`` (means) and ``per_view`` (list of dicts).
    Renders (side by side with the ground truth) go to ``out_dir`` as PNG when given.
    """
    if len(cams) != len(images):
        raise ValueError(f"{len(cams)} cameras for {len(images)} images")
    per = []
    for i in range(len(cams)):
        pred = render_image(field, cams, i)
        gt = np.asarray(images[i], np.float32)
        if gt.shape != pred.shape:
            raise ValueError(f"image {i}: shape {gt.shape} but camera renders {pred.shape}")
        rec = {"index": i, "name": cams.names[i], "psnr": psnr(pred, gt), "ssim": ssim(pred, gt)}
        per.append(rec)
        if out_dir is not None:
            save_png(np.concatenate([pred, gt], 1), Path(out_dir) / f"{prefix}_{i:03d}.png")
    return {"psnr": float(np.mean([r["psnr"] for r in per])) if per else float("nan"),
            "ssim": float(np.mean([r["ssim"] for r in per])) if per else float("nan"),
            "per_view": per}
