"""The paper's energy: hand-checked values, the fast path against the plain reference, and degenerate inputs."""

import math

import numpy as np
import pytest

from curate.select.bins import DirectionBins
from curate.core.cameras import Cameras, look_at
from curate.select.config import EnergyConfig
from curate.select.energy import compute_energy, energy_reference, total_variation
from curate.core.grid import NodeGrid, box_from_cameras
from curate.select.visibility import FrustumVisibility, build_pair_index, frustum_visible_reference
from conftest import random_pool


def cams_looking_at_origin(centres, size=100, f=50.0):
    return Cameras(look_at(np.asarray(centres, float), np.zeros(3)), f, f, size / 2, size / 2, size, size)


def test_one_node_two_cameras_by_hand():
    # One node at the origin, 5x10 "paper" bins (theta steps of 36 deg, phi steps of 36 deg).
    # Camera A at (0, 0, 2): direction +z, theta = 0 -> ring 0, phi = atan2(0, 0) = 0 -> phi bin 5.
    # Camera B at 2 (cos 18, sin 18, 0): theta = 90 deg -> ring 2, phi = 18 deg -> phi bin 5.
    # Uniform shares: ring 0 bin: (1 - cos 36) / 2 / 10 = 0.0095491503
    #                 ring 2 bin: (cos 72 - cos 108) / 2 / 10 = 0.0309016994
    # f = 1/2 in each of the two bins, so
    # TV = 1/2 [(1/2 - uA) + (1/2 - uB) + (1 - uA - uB)] = 1 - uA - uB = 0.9595491503
    # O_f = 2/2 = 1 -> 1^gamma = 1, and E = (1 - TV) + 1 = uA + uB + 1 = 1.0404508497.
    uA = (1 - math.cos(math.radians(36))) / 20
    uB = (math.cos(math.radians(72)) - math.cos(math.radians(108))) / 20
    assert math.isclose(uA, 0.0095491503, rel_tol=1e-8) and math.isclose(uB, 0.0309016994, rel_tol=1e-8)
    a18 = math.radians(18)
    cams = cams_looking_at_origin([[0, 0, 2], [2 * math.cos(a18), 2 * math.sin(a18), 0]])
    node = np.zeros((1, 3))
    e = compute_energy(cams, node, EnergyConfig(), per_node=True)
    assert e.views_per_node[0] == 2
    assert math.isclose(e.angular, uA + uB, rel_tol=1e-12)
    assert math.isclose(e.frequency, 1.0, rel_tol=1e-12)
    assert math.isclose(e.energy, 1.0404508497, rel_tol=1e-9)
    # Camera A alone: one bin holds everything, TV = 1 - uA, E = uA + 1.
    e1 = compute_energy(cams[0], node, EnergyConfig())
    assert math.isclose(e1.energy, 1 + uA, rel_tol=1e-12)
    # Add a third camera that does not see the node (looks away): N = 3, O_f = 2/3.
    away = Cameras(look_at([[0.0, 0, -3]], [[0.0, 0, -10]]), 50.0, 50.0, 50.0, 50.0, 100, 100)
    e3 = compute_energy(Cameras.concat([cams, away]), node, EnergyConfig(gamma=0.5))
    assert math.isclose(e3.frequency, (2 / 3) ** 0.5, rel_tol=1e-12)
    assert math.isclose(e3.angular, uA + uB, rel_tol=1e-12)


@pytest.mark.parametrize("binning", ["paper", "equal-area"])
@pytest.mark.parametrize("gamma", [0.05, 0.5, 1.0, 0.0])
@pytest.mark.parametrize("seed", [0, 1])
def test_fast_energy_matches_plain_reference(binning, gamma, seed):
    cams = random_pool(15, seed=seed)
    nodes = NodeGrid([-1, -1, -1], [1, 1, 1], 5).nodes()
    cfg = EnergyConfig(gamma=gamma, n_theta=4, n_phi=6, binning=binning)
    fast = compute_energy(cams, nodes, cfg)
    ref = energy_reference(cams, nodes, cfg)
    assert fast.energy > 0
    for k in ("energy", "angular", "frequency"):
        assert math.isclose(getattr(fast, k), getattr(ref, k), rel_tol=1e-9, abs_tol=1e-12), k


def test_fast_visibility_matches_reference_bitwise():
    cams = random_pool(30, seed=4)
    nodes = NodeGrid([-1, -1, -1], [1, 1, 1], 6).nodes()
    fast = FrustumVisibility()(cams, nodes)
    ref = np.array([frustum_visible_reference(cams, p) for p in nodes])
    assert fast.any() and np.array_equal(fast, ref)
    # The torch kernel inside the pair index gives the very same pairs.
    idx = build_pair_index(cams, nodes, DirectionBins(), chunk_pairs=97)
    pairs = np.zeros_like(fast)
    for p in range(len(nodes)):
        pairs[p, idx.cam[idx.indptr[p]:idx.indptr[p + 1]].astype(int)] = True
    assert np.array_equal(pairs, fast)


def test_pair_index_camera_major_view_consistent():
    cams = random_pool(40, seed=8)
    nodes = NodeGrid([-1, -1, -1], [1, 1, 1], 8).nodes()
    idx = build_pair_index(cams, nodes, DirectionBins(), chunk_pairs=500)
    mask = FrustumVisibility()(cams, nodes)
    for k in (0, 7, 39):
        n, b = idx.camera_pairs(k)
        assert np.array_equal(n, np.flatnonzero(mask[:, k]))
        assert np.array_equal(b, DirectionBins().assign(cams.centres[k] - nodes[n]))


def test_visibility_definition_edges():
    # Camera at the origin looking down +z, 100x100 image, f = 50, principal point (50, 50).
    cam = Cameras(np.eye(4)[None], 50.0, 50.0, 50.0, 50.0, 100, 100)
    pts = np.array([
        [0, 0, 1],        # centre of the image
        [0, 0, -1],       # behind
        [0, 0, 0],        # at the camera centre: depth 0, not observed
        [-1, -1, 1],      # u = v = 0: first pixel's corner, inside (0 <= u)
        [1, 0, 1],        # u = 100 = width: outside (u < width)
        [0.999, 0.999, 1],  # just inside the far corner
    ], float)
    assert FrustumVisibility()(cam, pts)[:, 0].tolist() == [True, False, False, True, False, True]


def test_empty_and_degenerate_sets_never_nan():
    nodes = NodeGrid([-1, -1, -1], [1, 1, 1], 4).nodes()
    cfg = EnergyConfig()
    e0 = compute_energy(Cameras.empty(), nodes, cfg, per_node=True)
    assert (e0.energy, e0.angular, e0.frequency) == (0.0, 0.0, 0.0)
    assert np.all(e0.angular_per_node == 0)
    e = compute_energy(random_pool(1, seed=0), np.zeros((0, 3)), cfg)
    assert e.energy == 0.0 and e.n_nodes == 0
    # Every camera at one point, and nodes exactly at that point.
    same = Cameras(look_at(np.zeros((3, 3)), np.eye(3)), 50.0, 50.0, 50.0, 50.0, 100, 100)
    e = compute_energy(same, np.zeros((2, 3)), cfg, per_node=True)
    assert e.energy == 0.0 and np.all(e.views_per_node == 0)


@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_extreme_scales_and_float32(scale, dtype):
    cams = random_pool(20, seed=11)
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 6)
    base = compute_energy(cams, grid.nodes(), EnergyConfig())
    c2w = cams.c2w.copy()
    c2w[:, :3, 3] *= scale
    scaled = Cameras(c2w.astype(dtype), cams.fx.astype(dtype), cams.fy.astype(dtype), cams.cx, cams.cy,
                     cams.width, cams.height)
    e = compute_energy(scaled, (grid.nodes() * scale).astype(dtype), EnergyConfig(), per_node=True)
    assert np.isfinite(e.energy) and np.all(np.isfinite(e.angular_per_node))
    if dtype == np.float64:
        assert math.isclose(e.energy, base.energy, rel_tol=1e-9)
    else:  # float32 rounding moves a few boundary nodes at most
        assert abs(e.energy - base.energy) <= 0.02 * base.energy


def test_far_cameras_from_tiny_scene():
    nodes = NodeGrid([-1e-6] * 3, [1e-6] * 3, 3).nodes()
    cams = cams_looking_at_origin([[1e6, 0, 0], [0, 1e6, 0], [0, 0, -1e6]], size=100, f=1e12)
    e = compute_energy(cams, nodes, EnergyConfig(), per_node=True)
    assert np.isfinite(e.energy) and np.all(e.views_per_node == 3)


def test_tv_bounds_and_unobserved():
    shares = DirectionBins().shares()
    rng = np.random.default_rng(0)
    h = rng.integers(0, 5, size=(500, 50))
    h[:10] = 0
    tv = total_variation(h, h.sum(1), shares)
    assert np.all(tv >= 0) and np.all(tv <= 1) and np.all(tv[:10] == 1)
    # A histogram proportional to the shares has TV 0.
    assert total_variation(shares[None] * 1e6, np.array([1e6]), shares)[0] < 1e-12


def test_config_validation():
    with pytest.raises(ValueError):
        EnergyConfig(gamma=-1)
    with pytest.raises(ValueError):
        EnergyConfig(binning="weird")
    with pytest.raises(ValueError):
        EnergyConfig(n_theta=0)


def test_box_from_cameras_non_degenerate():
    # Cameras all at one height (a walk): the box still has thickness in z.
    c = np.stack([np.linspace(0, 10, 20), np.zeros(20), np.full(20, 1.5)], 1)
    cams = Cameras(look_at(c, c + [0, 1, 0]), 50.0, 50.0, 50.0, 50.0, 100, 100)
    lo, hi = box_from_cameras(cams)
    assert np.all(hi - lo >= 1.0) and np.all(lo <= c.min(0)) and np.all(hi >= c.max(0))
    # An orbit: the looked-at point is inside the box.
    orbit = cams_looking_at_origin([[3, 0, 1], [0, 3, 1], [-3, 0, 1], [0, -3, 1]])
    lo, hi = box_from_cameras(orbit)
    assert np.all(lo <= 0) and np.all(hi >= 0)
