"""Occupancy grids from points, and their refinement by a field."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from curate.core.cameras import Cameras, look_at
from curate.core.grid import NodeGrid
from curate.occupancy.masks import (OccupancyConfig, RefineConfig, occupancy_from_points, refine_occupancy,
                              scene_box)

BOX_LO, BOX_HI = np.array([0.0, -1.0, 0.0]), np.array([2.0, 1.0, 0.6])


def _box_points(n=20000, outliers=40, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(BOX_LO, BOX_HI, (n, 3))
    far = rng.uniform(-1, 1, (outliers, 3))
    far = 30.0 * far / np.linalg.norm(far, axis=1, keepdims=True)  # isolated points 30 units away
    return np.concatenate([p, far])


def _dist_to_box(x):
    return np.linalg.norm(np.maximum(0, np.maximum(BOX_LO - x, x - BOX_HI)), axis=1)


def test_occupancy_covers_box_and_drops_outliers():
    cfg = OccupancyConfig(res=32, dilation=1)
    g = occupancy_from_points(_box_points(), None, cfg)
    # robust box: near the true box, not stretched to the outliers 30 units away
    assert np.all(g.box_min > BOX_LO - 0.3) and np.all(g.box_max < BOX_HI + 0.3)
    nodes = g.all_nodes()
    m = g.mask.ravel()
    vox = (g.box_max - g.box_min) / (g.res - 1)
    inside = _dist_to_box(nodes) == 0
    assert m[inside].mean() > 0.97  # the occupied voxels cover the box
    far = _dist_to_box(nodes) > (cfg.dilation + 1) * vox.max()
    assert not np.any(m & far)  # none far outside


def test_room_box_includes_cameras():
    """A walk through a room: cameras inside the points' box -> the box holds them too."""
    rng = np.random.default_rng(1)
    walls = rng.uniform([-3, -2, 0], [3, 2, 2.5], (5000, 3))
    c = rng.uniform([-2.5, -1.5, 1.2], [2.5, 1.5, 1.8], (20, 3))
    cams = Cameras(look_at(c, c + [1.0, 0, 0]), 100, 100, 50, 50, 100, 100)
    lo, hi = scene_box(walls, cams)
    assert np.all(lo <= c.min(0)) and np.all(hi >= c.max(0))


def test_object_box_excludes_far_cameras():
    rng = np.random.default_rng(2)
    obj = rng.normal(size=(3000, 3)) * 0.2
    a = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    c = np.stack([5 * np.cos(a), 5 * np.sin(a), np.ones_like(a)], 1)
    cams = Cameras(look_at(c, np.zeros((12, 3))), 100, 100, 50, 50, 100, 100)
    lo, hi = scene_box(obj, cams)
    assert np.all(hi - lo < 2.0)


def test_empty_and_degenerate_inputs():
    with pytest.raises(ValueError, match="at least"):
        occupancy_from_points(np.zeros((3, 3)))
    with pytest.raises(ValueError):
        occupancy_from_points(np.ones((100, 3)))  # all points at one spot
    pts = _box_points(outliers=0)
    far_box = (np.array([50.0, 50, 50]), np.array([51.0, 51, 51]))
    with pytest.raises(ValueError, match="empty occupancy"):
        occupancy_from_points(pts, box=far_box)


class _BallField:
    """Stub field: density 100 per world unit inside a ball of radius 0.5 at (1, 0, 0.3), else 0."""

    def density_world(self, x):
        x = np.asarray(x)
        return np.where(np.linalg.norm(x - [1.0, 0.0, 0.3], axis=1) < 0.5, 100.0, 0.0)


def test_refine_occupancy_modes():
    g = occupancy_from_points(_box_points(), None, OccupancyConfig(res=24))
    f = _BallField()
    only = refine_occupancy(f, g, 0.5, RefineConfig(mode="field"))
    near_ball = np.linalg.norm(g.all_nodes() - [1.0, 0.0, 0.3], axis=1) < 0.5
    assert np.all(only.mask.ravel()[near_ball])
    vox = float(np.max((g.box_max - g.box_min) / (g.res - 1)))
    far = np.linalg.norm(g.all_nodes() - [1.0, 0.0, 0.3], axis=1) > 0.5 + vox
    assert not np.any(only.mask.ravel()[far])
    inter = refine_occupancy(f, g, 0.5, RefineConfig(mode="intersection"))
    union = refine_occupancy(f, g, 0.5, RefineConfig(mode="union"))
    assert np.all(inter.mask <= only.mask) and np.all(inter.mask <= g.mask)
    assert np.all(union.mask >= only.mask) and np.all(union.mask >= g.mask)
    with pytest.raises(ValueError):
        refine_occupancy(f, g, 0.5, RefineConfig(mode="nope"))


def test_prior_mask_limits_field_cells():
    from curate.field.model import FieldConfig, RadianceField
    from curate.field.model import prior_mask
    f = RadianceField(FieldConfig(res_schedule=(33,)), [-1] * 3, [1] * 3)
    m = np.zeros((8, 8, 8), bool)
    m[:4] = True  # x < 0 half occupied
    pm = prior_mask(f, NodeGrid([-1] * 3, [1] * 3, 8, m))
    c = f.node_contracted()
    inner = c.abs().amax(-1) <= 1
    assert torch.all(pm[~inner])  # outside the box: never restricted
    assert torch.all(pm[inner & (c[..., 0] < -0.2)]) and not torch.any(pm[inner & (c[..., 0] > 0.2)])
