"""Where the scene is: an occupancy grid from points, refined by a trained radiance field.

``occupancy_from_points``: sparse SfM points (plus dense points when present) ->
open3d statistical outlier removal -> a robust scene box (percentiles, cameras
considered) -> voxels at the node grid's resolution (the voxel of node ``i`` is the
cell centred on it) -> dilation by ``dilation`` voxels -> a :class:`NodeGrid` whose mask
is the occupied nodes.

``refine_occupancy``: nodes where the field's opacity across one voxel exceeds a
threshold; combined with the point-based prior (see :class:`RefineConfig.mode`).
"""

from __future__ import annotations

import logging

import numpy as np
import torch

from curate.core.cameras import Cameras
from curate.core.grid import NodeGrid
from curate.occupancy.config import REFINE_FIELD, OccupancyConfig, RefineConfig  # noqa: F401  (their home)

log = logging.getLogger(__name__)


def _clean(points: np.ndarray, cfg: OccupancyConfig) -> np.ndarray:
    """Statistical outlier removal (open3d). [P, 3] -> [P', 3]."""
    if len(points) <= cfg.nb_neighbors + 1:
        return points
    import open3d as o3d
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points.astype(np.float64)))
    _, keep = pc.remove_statistical_outlier(nb_neighbors=cfg.nb_neighbors, std_ratio=cfg.std_ratio)
    return points[np.asarray(keep, dtype=np.int64)]


def scene_box(points: np.ndarray, cams: Cameras | None = None, cfg: OccupancyConfig = OccupancyConfig()
              ) -> tuple[np.ndarray, np.ndarray]:
    """Robust scene box (box_min [3], box_max [3]) from [P, 3] points (already cleaned) and cameras."""
    p = cfg.percentile
    lo, hi = np.percentile(points, p, axis=0), np.percentile(points, 100 - p, axis=0)
    if cams is not None and len(cams):
        c = cams.centres
        inside = np.all((c >= lo) & (c <= hi), axis=1).mean()
        if inside >= cfg.camera_inside_frac:
            lo = np.minimum(lo, np.percentile(c, p, axis=0))
            hi = np.maximum(hi, np.percentile(c, 100 - p, axis=0))
    side = hi - lo
    big = float(side.max())
    if big <= 0:
        raise ValueError("all points at one spot: no scene box")
    side_min = np.maximum(side, 0.05 * big)  # never a flat box
    grow = side_min - side
    pad = cfg.pad * big
    return lo - 0.5 * grow - pad, hi + 0.5 * grow + pad


def voxelise(points: np.ndarray, grid: NodeGrid) -> np.ndarray:
    """[R, R, R] bool: nodes whose cell (centred on the node) holds at least one of [P, 3] points."""
    r = grid.res
    span = np.where(grid.box_max > grid.box_min, grid.box_max - grid.box_min, 1.0)
    idx = np.round((points - grid.box_min) / span * (r - 1)).astype(np.int64)
    ok = np.all((idx >= 0) & (idx < r), axis=1)
    m = np.zeros((r, r, r), bool)
    m[tuple(idx[ok].T)] = True
    return m


def dilate(mask: np.ndarray, k: int) -> np.ndarray:
    """Binary dilation by ``k`` steps of the 26-neighbourhood (a (2k+1)^3 cube)."""
    if k <= 0:
        return mask
    t = torch.from_numpy(mask.astype(np.float32))[None, None]
    return (torch.nn.functional.max_pool3d(t, 2 * k + 1, 1, k)[0, 0] > 0).numpy()


def occupancy_from_points(points: np.ndarray, cams: Cameras | None = None, cfg: OccupancyConfig = OccupancyConfig(),
                          dense_points: np.ndarray | None = None, box: tuple | None = None) -> NodeGrid:
    """Occupancy NodeGrid from sparse [P, 3] (and optional dense [Q, 3]) points.

    ``box`` overrides the robust box. ValueError when too few points survive or the
    occupied set is empty.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if dense_points is not None:
        dp = np.asarray(dense_points, np.float64).reshape(-1, 3)
        pts = np.concatenate([pts, dp[np.all(np.isfinite(dp), axis=1)]])
    if len(pts) < cfg.min_points:
        raise ValueError(f"occupancy needs at least {cfg.min_points} points, got {len(pts)}")
    clean = _clean(pts, cfg)
    log.info("occupancy: %d points, %d after outlier removal", len(pts), len(clean))
    if len(clean) < cfg.min_points:
        raise ValueError(f"only {len(clean)} points left after outlier removal")
    lo, hi = box if box is not None else scene_box(clean, cams, cfg)
    grid = NodeGrid(lo, hi, cfg.res)
    mask = dilate(voxelise(clean, grid), cfg.dilation)
    if not mask.any():
        raise ValueError("empty occupancy: no point falls inside the scene box")
    return grid.with_mask(mask)


def field_occupancy(field, grid: NodeGrid, cfg: RefineConfig = RefineConfig()) -> np.ndarray:
    """[R, R, R] float: the field's max opacity across one voxel, per node of ``grid``."""
    r, s = grid.res, max(1, cfg.supersample)
    vox = (grid.box_max - grid.box_min) / max(r - 1, 1)  # [3]
    offs = (np.arange(s) + 0.5) / s - 0.5
    sub = np.stack(np.meshgrid(offs, offs, offs, indexing="ij"), -1).reshape(-1, 3) * vox  # [s^3, 3]
    nodes = grid.all_nodes()  # [R^3, 3]
    vlen = float(np.prod(vox)) ** (1 / 3)
    best = np.zeros(len(nodes))
    for o in sub:
        sig = field.density_world(nodes + o)
        best = np.maximum(best, 1 - np.exp(-np.clip(sig * vlen, 0, 50)))
    return best.reshape(r, r, r)


def refine_occupancy(field, grid: NodeGrid, threshold: float | None = None,
                     cfg: RefineConfig = RefineConfig()) -> NodeGrid:
    """The refined occupancy grid (same box and resolution as ``grid``); ``grid.mask`` is the prior
    (None: no prior, i.e. mode 'field')."""
    thr = cfg.threshold if threshold is None else threshold
    f = field_occupancy(field, grid, cfg) > thr
    prior = grid.mask
    if prior is None or cfg.mode == "field":
        m = f
    elif cfg.mode == "union":
        m = f | prior
    elif cfg.mode == "intersection":
        m = f & prior
    elif cfg.mode == "intersect_dilated":
        m = f & dilate(prior, cfg.prior_dilation)
    else:
        raise ValueError(f"unknown refine mode {cfg.mode!r}")
    log.info("refined occupancy: field %d, prior %s, result %d nodes", f.sum(),
             "-" if prior is None else int(prior.sum()), m.sum())
    return grid.with_mask(m)
