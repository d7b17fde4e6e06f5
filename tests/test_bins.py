"""Direction bins: shares, edges, poles, and agreement with the sphere's own measure."""

import numpy as np
import pytest

from curate.select.bins import DirectionBins
from curate.select.energy import total_variation


@pytest.mark.parametrize("binning", ["paper", "equal-area"])
def test_shares_sum_to_one_and_match_solid_angle(binning):
    b = DirectionBins(5, 10, binning)
    u = b.shares()
    assert u.shape == (50,) and np.isclose(u.sum(), 1.0)
    # Uniform random directions fill each bin in proportion to its share: TV -> 0.
    d = np.random.default_rng(0).normal(size=(400_000, 3))
    h = np.bincount(b.assign(d), minlength=50)
    assert total_variation(h[None], np.array([h.sum()]), u)[0] < 0.01
    if binning == "equal-area":
        assert np.allclose(u, 1 / 50)
    else:  # polar bins are smaller than equatorial ones
        assert u[0] < u[20]


def test_poles_edges_and_phi_wrap():
    b = DirectionBins(5, 10, "paper")
    dirs = np.array([
        [0, 0, 1], [0, 0, -1],              # poles
        [-1, 0, 0], [-1, -0.0, 0],          # phi = +pi and -pi: the same bin
        [0, 0, 0],                          # zero vector: counts as +z
        [1e-300, 0, 1e300], [1e300, 1e300, 1e300], [1e-310, 1e-310, 0],
    ])
    out = b.assign(dirs)
    assert np.all((out >= 0) & (out < 50))
    assert out[0] // 10 == 0 and out[1] // 10 == 4
    assert out[2] == out[3] and out[2] % 10 == 0
    assert out[4] // 10 == 0  # the zero vector counts as +z
    # Directions exactly on a theta edge go to one of the two bins that meet there.
    for i in range(1, 5):
        t = i * np.pi / 5
        k = b.assign(np.array([[np.sin(t), 0.3, np.cos(t)]]))[0] // 10
        assert k in (i - 1, i)
    # On each phi edge, likewise.
    for j in range(10):
        p = -np.pi + j * 2 * np.pi / 10
        k = b.assign(np.array([[np.cos(p), np.sin(p), 0.1]]))[0] % 10
        assert k in ((j - 1) % 10, j)


def test_bin_layout_theta_major():
    b = DirectionBins(3, 4, "equal-area")
    # theta near 0 (cos ~ 1) -> ring 0; phi in [-pi, -pi/2) -> phi bin 0.
    assert b.assign(np.array([[-0.1, -0.1, 1.0]]))[0] == 0
    # theta near pi -> ring 2; phi in [pi/2, pi) -> phi bin 3.
    assert b.assign(np.array([[-0.1, 0.1, -1.0]]))[0] == 2 * 4 + 3
