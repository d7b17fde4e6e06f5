"""The documented tie rules hold at every scale and offset: a node exactly at a camera's centre is
never seen by that camera, and a vertical direction always falls in the same azimuth bin."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings, strategies as st

from curate.core.cameras import Cameras, look_at
from curate.core.grid import NodeGrid
from curate.select.bins import DirectionBins
from curate.select.visibility import FrustumVisibility, frustum_visible_reference

SCALES = st.sampled_from([1e-6, 3.7e-4, 0.1, 1.0, 7.0, 123.456, 1e4, 1e6])
OFFSETS = st.sampled_from([0.0, 1e-3, -2.5, 1e3, -1e5, 1e6])


def cameras_on_nodes(seed: int, grid: NodeGrid, n: int = 12) -> tuple[Cameras, np.ndarray]:
    """n cameras placed exactly on grid nodes, looking at random other nodes; their node indices."""
    rng = np.random.default_rng(seed)
    nodes = grid.nodes()
    at = rng.choice(len(nodes), n, replace=False)
    tgt = nodes[rng.choice(len(nodes), n)] + rng.normal(0, 0.3, (n, 3))
    return Cameras(look_at(nodes[at], tgt), 60.0, 60.0, 40.0, 30.0, 80, 60), at


@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 10_000), scale=SCALES, offset=OFFSETS)
def test_a_node_at_a_camera_centre_is_unseen_at_every_scale_and_offset(seed, scale, offset):
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 5)
    cams, at = cameras_on_nodes(seed, grid)
    shift = np.array([offset, -0.5 * offset, 2.0 * offset])
    c2 = cams.transformed(scale, None, shift)
    # the scene's grid rebuilt from its scaled box: nodes and centres coincide up to the rounding of
    # each's own arithmetic (as a user's scaled scene gives them)
    g2 = NodeGrid(np.full(3, -1.0) * scale + shift, np.full(3, 1.0) * scale + shift, grid.res)
    for nodes in (grid.nodes() * scale + shift, g2.nodes()):
        vis = FrustumVisibility()(c2, nodes)                   # [M, K]
        assert not vis[at, np.arange(len(at))].any()
        for k in range(len(at)):                                # the plain-Python reference agrees
            assert frustum_visible_reference(c2, nodes[at[k]])[k] is False


@settings(max_examples=200, deadline=None)
@given(ex=st.floats(-1e-13, 1e-13), ey=st.floats(-1e-13, 1e-13), up=st.booleans(),
       scale=st.sampled_from([1e-300, 1e-6, 1.0, 1e6, 1e300]), n_phi=st.integers(1, 12), n_theta=st.integers(1, 6))
def test_a_vertical_direction_has_one_bin_at_every_scale(ex, ey, up, scale, n_phi, n_theta):
    bins = DirectionBins(n_theta, n_phi)
    z = 1.0 if up else -1.0
    ref = bins.assign(np.array([[0.0, 0.0, z]]))[0]
    d = np.array([[ex * scale, ey * scale, z * scale], [-0.0, -0.0, z * scale], [-0.0, 0.0, z * scale]])
    assert np.all(bins.assign(d) == ref)


def test_a_direction_just_off_vertical_keeps_its_azimuth():
    """The vertical rule takes only rounding noise: a real tilt keeps its azimuth bin."""
    bins = DirectionBins(5, 10)
    tilted = np.array([[-1e-6, -1e-6, 1.0]])                     # phi = -135 deg
    assert bins.assign(tilted)[0] == bins.assign(np.array([[-1.0, -1.0, 1e6]]))[0] != bins.assign(
        np.array([[0.0, 0.0, 1.0]]))[0]
