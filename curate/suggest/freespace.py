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
camera stood near while looking along it. Carving it up to the nearest hit of the rays beside it was measured and
not adopted: a neighbour's hit on another surface carries the ray through the wall; docs/suggest.md.)
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


def cast_free_space(cams: Cameras, occ: np.ndarray, box_min, box_max, probe: tuple[int, int] = (32, 24),
                    step: float | None = None, near: float | None = None, chunk: int = 1 << 21) -> FreeSpace:
    """Observed free space of ``cams`` in the occupancy ``occ`` [R, R, R] over the box (module docstring).

    Args:
        step: sample spacing along the rays (default: half the smallest voxel side).
        near: hits nearer than this are ignored (default: the largest voxel side).
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
    N, P = len(cams), int(probe[0]) * int(probe[1])
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
        for s in range(0, P, per):
            d = dirs[k, s:s + per]                                               # [p, 3]
            flat = voxel_index(c[None, None, :] + ts[None, :, None] * d[:, None, :], lo, hi, R)   # [p, S]
            o = (flat >= 0) & occ_flat[np.maximum(flat, 0)] & (ts[None, :] >= near)
            has = o.any(1)
            first = np.where(has, o.argmax(1), 0)                                # a miss carves nothing
            hit[k, s:s + per] = np.where(has, ts[first], np.inf)
            carve = (np.arange(S)[None, :] < first[:, None]) & (flat >= 0)
            free[flat[carve]] = True
        h = hit[k][np.isfinite(hit[k])]
        if h.size:
            med[k] = float(np.median(h))
    free &= ~occ_flat
    return FreeSpace(free.reshape(occ.shape), hit, axis_cos, med)
