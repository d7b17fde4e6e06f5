"""Options of the occupancy stage (:class:`OccupancyConfig`, :class:`RefineConfig`): the CLI binds its flags to these
fields. Light to import (no torch): ``curate --help`` reads them."""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Literal, get_args

RefineField = Literal["auto", "always"]
REFINE_FIELD = get_args(RefineField)
"""``RefineConfig.field`` choices."""


@dataclass
class OccupancyConfig:
    """Settings of :func:`occupancy_from_points`."""

    res: int = 32
    """Nodes per axis of the scene grid the selection is scored on (more: finer and slower)."""
    nb_neighbors: int = 20
    """open3d statistical outlier removal: neighbours considered per point."""
    std_ratio: float = 2.0
    """open3d statistical outlier removal: a point whose mean neighbour distance exceeds the
    global mean by this many standard deviations is removed."""
    percentile: float = 1.0
    """The box spans the [p, 100 - p] percentiles of the (cleaned) points per axis."""
    pad: float = 0.05
    """Padding of the box, as a fraction of its largest side."""
    camera_inside_frac: float = 0.5
    """When at least this fraction of camera centres lies inside the points' box (a walk
    through a room), the box is grown to hold the cameras' [p, 100-p] percentile box too;
    otherwise (an object capture) the box is around the points only."""
    dilation: int = 1
    """Voxels of dilation of the occupied set (26-neighbourhood per step)."""
    min_points: int = 10
    """Fewer points (after cleaning) is a ValueError."""

    def __post_init__(self) -> None:
        if not (isinstance(self.res, numbers.Integral) and 2 <= self.res <= 512):
            raise ValueError(f"--res (nodes per axis) must be an integer in [2, 512], got {self.res!r}")
        if self.dilation < 0 or self.nb_neighbors < 1 or not (0 <= self.percentile < 50) or self.pad < 0:
            raise ValueError("occupancy: dilation >= 0, nb_neighbors >= 1, 0 <= percentile < 50 and pad >= 0")


@dataclass
class RefineConfig:
    """Settings of :func:`refine_occupancy`."""

    threshold: float = 0.1
    """A node is occupied when the field's opacity across one voxel (max over ``supersample^3``
    points of its cell) exceeds this."""
    supersample: int = 3
    """Points per axis at which each voxel is probed."""
    mode: str = "intersect_dilated"
    """How the field's occupancy combines with the point prior: 'field' (ignore the prior),
    'union', 'intersection', or 'intersect_dilated' (field AND prior dilated by
    ``prior_dilation``: the field confirms and sharpens, the prior removes floaters far
    from any point)."""
    prior_dilation: int = 2
    """Dilation (voxels) of the prior for 'intersect_dilated'."""
    field: RefineField = "auto"
    """When a radiance field refines the occupancy: 'auto' (only for the paper's energy, when the
    sparse points are too few to give the scene's surface, e.g. poses without points) or 'always'
    (the paper's refinement on every run: one more training)."""
    iters: int = 800
    """Training iterations of the refining field.

    Its own, not the evaluation's: the evaluation's field is chosen for decisions per CPU-minute
    (docs/evaluation.md), this one for the scene's surface."""
    max_side: int = 240
    """Longer side, in pixels, of the images the refining field trains on."""

    def __post_init__(self) -> None:
        if self.field not in REFINE_FIELD:
            raise ValueError(f"refine field must be one of {REFINE_FIELD}, got {self.field!r}")
        for name, lo in (("iters", 1), ("max_side", 16)):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < lo:
                raise ValueError(f"refine {name} must be an integer >= {lo}, got {v!r}")


