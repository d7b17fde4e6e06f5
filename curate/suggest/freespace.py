"""The space a capture observed as free: its cameras' rays cast through the occupancy grid.

Grid convention (the occupancy stage's, :func:`curate.occupancy.masks.voxelise`): ``R^3`` nodes spanning the
box ``[box_min, box_max]`` (node ``i`` at ``box_min + i * voxel``, ``voxel = (box_max - box_min) / (R - 1)``),
and a point belongs to the node nearest to it (its *voxel*, the cell centred on the node); points more than
half a voxel outside the box belong to none.

Each camera casts a ``probe`` grid of rays (pixel centres of a ``W x H`` image with the camera's field of
view), sampled every ``step`` along the ray. A ray's *hit* is its first sample in an occupied voxel, at least
``near`` from the camera (occupied voxels nearer than that are taken as noise of the occupancy: a camera
stood there). Every voxel a ray's samples traverse before its hit is *observed free*. A ray that hits nothing
carves nothing: a plain wall has no SfM points, so its rays hit nothing, and the space behind it is never taken
for free. (The rule before carved such a ray up to the median depth of the camera's hits, through a wall the
camera stood near while looking along it. ``fill`` > 0 carves it up to the nearest hit among the rays within
``fill`` probe cells, their z-depth taken along its own direction: measured and not adopted, a neighbour's hit
on another surface carries the ray through the wall; docs/suggest.md.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from curate.core.cameras import Cameras


@dataclass
class FreeSpace:
    """Observed free space of a capture.

    Attributes:
        free: [R, R, R] bool, voxels some ray traversed before its hit (occupied voxels excluded).
        hit_depth: [N, P] distance along each probe ray (unit direction) to its hit; inf where it hits nothing.
        axis_cos: [N, P] cosine between each probe ray and its camera's optical axis (``hit_depth * axis_cos``
            is a z-depth).
        median_depth: [N] median hit distance of each camera's rays (nan when none hits).
    """

    free: np.ndarray
    hit_depth: np.ndarray
    axis_cos: np.ndarray
    median_depth: np.ndarray

    def nearest_surface(self) -> np.ndarray:
        """[N] z-depth of the nearest hit in each camera's view (inf when none)."""
        return (self.hit_depth * self.axis_cos).min(1) if self.hit_depth.size else np.zeros(len(self.hit_depth))


def voxel_size(box_min, box_max, res: int) -> np.ndarray:
    """[3] node spacing of an ``res^3`` grid over the box."""
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    return (hi - lo) / max(res - 1, 1)


def voxel_index(points: np.ndarray, box_min, box_max, res: int) -> np.ndarray:
    """[...] flat index ``(i * R + j) * R + k`` of each point's voxel (points [..., 3]); -1 outside the grid."""
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    span = np.where(hi > lo, hi - lo, 1.0)
    g = np.rint((np.asarray(points, float) - lo) / span * (res - 1)).astype(np.int64)
    inside = np.all((g >= 0) & (g < res), axis=-1)
    flat = (g[..., 0] * res + g[..., 1]) * res + g[..., 2]
    return np.where(inside, flat, -1)


def probe_directions(cams: Cameras, probe: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(unit world directions [N, P, 3], cosines to the optical axis [N, P]) of a ``probe`` = (W, H) grid of
    pixel-centre rays spanning each camera's image, row-major."""
    W, H = int(probe[0]), int(probe[1])
    u, v = np.meshgrid((np.arange(W) + 0.5) / W, (np.arange(H) + 0.5) / H)
    x = (u.ravel()[None] * cams.width[:, None] - cams.cx[:, None]) / cams.fx[:, None]    # [N, P]
    y = (v.ravel()[None] * cams.height[:, None] - cams.cy[:, None]) / cams.fy[:, None]
    dc = np.stack([x, y, np.ones_like(x)], -1)
    dc /= np.linalg.norm(dc, axis=-1, keepdims=True)
    return np.einsum("npj,nij->npi", dc, cams.rotations), dc[..., 2]


def fill_depth(zdepth: np.ndarray, fill: int) -> np.ndarray:
    """[H, W] the nearest z-depth within ``fill`` cells of each cell of ``zdepth`` [H, W] (inf = no hit); a cell's
    own hit is kept."""
    from scipy.ndimage import minimum_filter
    if fill <= 0:
        return zdepth
    return np.where(np.isfinite(zdepth), zdepth, minimum_filter(zdepth, size=2 * int(fill) + 1, mode="nearest"))


def cast_free_space(cams: Cameras, occ: np.ndarray, box_min, box_max, probe: tuple[int, int] = (32, 24),
                    step: float | None = None, near: float | None = None, fill: int = 0,
                    chunk: int = 1 << 21) -> FreeSpace:
    """Observed free space of ``cams`` in the occupancy ``occ`` [R, R, R] over the box (module docstring).

    Args:
        step: sample spacing along the rays (default: half the smallest voxel side).
        near: hits nearer than this are ignored (default: the largest voxel side).
        fill: a ray that hits nothing carves up to the nearest hit within this many probe cells (0: nothing).
        chunk: samples evaluated at once (bounds memory: ~40 bytes each).
    """
    occ = np.asarray(occ, bool)
    R = occ.shape[0]
    if occ.shape != (R, R, R):
        raise ValueError(f"occupancy must be [R, R, R], got {occ.shape}")
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    vox = voxel_size(lo, hi, R)
    step = 0.5 * float(vox.min()) if step is None else float(step)
    near = float(vox.max()) if near is None else float(near)
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    W, H = int(probe[0]), int(probe[1])
    N, P = len(cams), W * H
    free = np.zeros(R ** 3, bool)
    hit = np.full((N, P), np.inf)
    med = np.full(N, np.nan)
    if N == 0:
        return FreeSpace(free.reshape(occ.shape), hit, np.ones((0, P)), med)
    corners = np.array([[a, b, c] for a in (lo[0], hi[0]) for b in (lo[1], hi[1]) for c in (lo[2], hi[2])])
    occ_flat = occ.ravel()
    dirs, axis_cos = probe_directions(cams, probe)
    for k in range(N):   # one camera at a time, samples in chunks of rays: memory stays bounded
        c = cams.centres[k]
        t_max = float(np.linalg.norm(corners - c, axis=1).max()) + step
        ts = (np.arange(int(np.ceil(t_max / step))) + 0.5) * step               # [S]
        S = len(ts)
        per = max(1, chunk // max(S, 1))
        lim_parts, flat_parts = [], []
        for s in range(0, P, per):
            d = dirs[k, s:s + per]                                               # [p, 3]
            flat = voxel_index(c[None, None, :] + ts[None, :, None] * d[:, None, :], lo, hi, R)   # [p, S]
            o = (flat >= 0) & occ_flat[np.maximum(flat, 0)] & (ts[None, :] >= near)
            has = o.any(1)
            first = np.where(has, o.argmax(1), S)
            hit[k, s:s + per] = np.where(has, ts[np.minimum(first, S - 1)], np.inf)
            lim_parts.append(first)
            flat_parts.append(flat)
        h = hit[k][np.isfinite(hit[k])]
        if h.size:
            med[k] = float(np.median(h))
        # a miss carves up to the nearest hit beside it: its neighbours' z-depth along its own direction
        z = fill_depth((hit[k] * axis_cos[k]).reshape(H, W), fill).ravel()
        miss_lim = np.where(np.isfinite(z), np.searchsorted(ts, z / np.maximum(axis_cos[k], 1e-9)), 0)   # [P]
        for s, (first, flat) in zip(range(0, P, per), zip(lim_parts, flat_parts)):
            lim = np.where(first < S, first, miss_lim[s:s + per])
            carve = (np.arange(S)[None, :] < lim[:, None]) & (flat >= 0)
            free[flat[carve]] = True
    free &= ~occ_flat
    return FreeSpace(free.reshape(occ.shape), hit, axis_cos, med)
