"""Property tests of the energy: bounds, and invariance under translating and scaling the whole scene."""

import numpy as np
from hypothesis import given, settings, strategies as st

from curate.select.config import EnergyConfig
from curate.select.energy import compute_energy
from curate.core.grid import NodeGrid
from conftest import random_pool


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 100_000), n=st.integers(0, 25), res=st.integers(1, 6),
       exp2=st.integers(-20, 20), shift=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3),
       binning=st.sampled_from(["paper", "equal-area"]), gamma=st.sampled_from([0.0, 0.05, 0.5]))
def test_energy_bounded_and_similarity_invariant(seed, n, res, exp2, shift, binning, gamma):
    cfg = EnergyConfig(gamma=gamma, binning=binning)
    cams = random_pool(n, seed=seed) if n else random_pool(1, seed=seed)[[]]
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], res)
    base = compute_energy(cams, grid.nodes(), cfg, per_node=True)
    M = grid.res ** 3
    assert np.all(base.angular_per_node >= 0) and np.all(base.angular_per_node <= 1)  # 0 <= TV <= 1
    assert np.all(base.frequency_per_node >= 0) and np.all(base.frequency_per_node <= 1)
    assert 0 <= base.energy <= 2 * M
    # Scale by a power of two (exact in floating point, 1e-6 .. 1e6) and translate.
    s, t = 2.0 ** exp2, np.asarray(shift)
    moved = cams.transformed(s, None, t)
    lo, hi = grid.box_min * s + t, grid.box_max * s + t
    e = compute_energy(moved, NodeGrid(lo, hi, res).nodes(), cfg)
    # Translation rounds coordinates, which may move a node across a frustum edge; the energy
    # changes by at most a few nodes' worth, never more.
    assert np.isfinite(e.energy)
    assert abs(e.energy - base.energy) <= 1e-9 * max(base.energy, 1) + 2.0 * 3
    if not np.any(t):
        assert abs(e.energy - base.energy) <= 1e-9 * max(base.energy, 1)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 100_000), exp2=st.integers(-20, 20))
def test_pure_scaling_is_exact(seed, exp2):
    cfg = EnergyConfig()
    cams = random_pool(12, seed=seed)
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 5)
    s = 2.0 ** exp2
    a = compute_energy(cams, grid.nodes(), cfg)
    b = compute_energy(cams.transformed(s), grid.nodes() * s, cfg)
    assert abs(a.energy - b.energy) <= 1e-9 * max(a.energy, 1)
