"""Node grid: nodes on the faces, flat order, masks that skip nodes at no cost."""

import numpy as np
import pytest

from curate.select.config import EnergyConfig
from curate.select.energy import compute_energy
from curate.core.grid import NodeGrid
from curate.select.select import score_cameras
from curate.select.visibility import build_pair_index
from conftest import random_pool


def test_nodes_span_box_including_faces():
    g = NodeGrid([0, -1, 2], [4, 1, 3], 5)
    n = g.all_nodes()
    assert n.shape == (125, 3)
    assert np.allclose(n.min(0), [0, -1, 2]) and np.allclose(n.max(0), [4, 1, 3])
    assert np.allclose(g.axes[0], [0, 1, 2, 3, 4])
    # Flat index (ix * R + iy) * R + iz.
    assert np.allclose(n[(2 * 5 + 1) * 5 + 4], [2, -0.5, 3])


def test_mask_keeps_only_active_nodes_and_skipped_cost_nothing():
    cams = random_pool(30, seed=2)
    full = NodeGrid([-1, -1, -1], [1, 1, 1], 8)
    mask = np.zeros((8, 8, 8), bool)
    mask[2:6, 1:7, 3:5] = True
    g = full.with_mask(mask)
    assert len(g.nodes()) == mask.sum()
    cfg = EnergyConfig()
    per = compute_energy(cams, full.all_nodes(), cfg, per_node=True)
    sub = score_cameras(cams, g, cfg)
    keep = mask.ravel()
    assert np.isclose(sub.energy, per.angular_per_node[keep].sum() + per.frequency_per_node[keep].sum())
    # The work (pairs stored) scales with the active nodes only.
    assert build_pair_index(cams, g.nodes(), cfg.bins).n_pairs == per.views_per_node[keep].sum()
    vol = g.scatter(np.ones(len(g.nodes())), fill=0.0)
    assert vol.shape == (8, 8, 8) and np.array_equal(vol.astype(bool), mask)


def test_invalid_grids():
    with pytest.raises(ValueError):
        NodeGrid([0, 0, 0], [-1, 1, 1], 4)
    with pytest.raises(ValueError):
        NodeGrid([0, 0, 0], [1, 1, 1], 0)
    with pytest.raises(ValueError):
        NodeGrid([0, 0, 0], [1, 1, 1], 4, mask=np.ones((3, 3, 3), bool))
    with pytest.raises(ValueError):
        NodeGrid([0, 0, np.nan], [1, 1, 1], 4)
    # A flat box (zero thickness) is allowed: all nodes lie on one plane.
    assert np.allclose(NodeGrid([0, 0, 1], [1, 1, 1], 3).nodes()[:, 2], 1)
