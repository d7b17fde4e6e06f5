"""The view-medoid variants measured and not adopted (research.medoids_variants): cost powers, an energy share,
a sharpness prior."""

import dataclasses

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.select.config import EnergyConfig
from curate.core.grid import NodeGrid
from curate.select.medoids import embed, path_weights, view_depths
from research.medoids_variants import MedoidsVariantConfig as M, medoids_select
from research.variants import Variant, select_variant
from curate.select.config import SelectConfig
from curate.select.select import select
from curate.select.visibility import build_pair_index
from tests.conftest import random_pool

GRID = NodeGrid([-1, -1, -1], [1, 1, 1], 6)

# plain view medoids (the reference tests set path_weights=False; tests/test_medoids_path.py
# has the weighted ones). Random pools are no capture path: path weights (on by default)
# fall back to plain ones, with a warning.
pytestmark = pytest.mark.filterwarnings("ignore:medoids. the views are not in capture order")


def pool_index(n, seed, scale=1.0):
    cams = random_pool(n, seed=seed, scale=scale)
    nodes = GRID.nodes() * scale
    return cams, nodes, build_pair_index(cams, nodes, EnergyConfig().bins)


def ref_distances(cams, depths):
    """[K, K] d(i, j) = |c_i - c_j| + |a_i - a_j|, a = c + D v, in plain loops."""
    K = len(cams)
    c = cams.c2w[:, :3, 3]
    a = [c[k] + depths[k] * cams.c2w[k, :3, 2] / np.linalg.norm(cams.c2w[k, :3, 2]) for k in range(K)]
    D = np.zeros((K, K))
    for i in range(K):
        for j in range(K):
            D[i, j] = np.linalg.norm(c[i] - c[j]) + np.linalg.norm(a[i] - a[j])
    return D


def mean_min(D, med, power=1.0):
    return float(np.mean([min(D[i, m] for m in med) ** power for i in range(len(D))]))


def check_local_optimum(D, initial, chosen, power=1.0):
    D0, D = D, D ** power
    med = list(initial) + list(chosen)
    assign = [min(range(len(med)), key=lambda j: (D[i, med[j]], j)) for i in range(len(D))]
    for j in range(len(initial), len(med)):           # fixed medoids never move
        members = [i for i in range(len(D)) if assign[i] == j]
        cur = sum(D[med[j], i] for i in members)
        for m in members:                             # moving medoid j to any member of its cluster
            assert sum(D[m, i] for i in members) >= cur - 1e-9 * max(1.0, cur)
    return mean_min(D0, med, power)


def check_basic(chosen, K, budget, initial=()):
    assert len(chosen) == min(budget, K - len(set(initial)))
    assert len(set(chosen)) == len(chosen)
    assert all(0 <= k < K and isinstance(k, int) for k in chosen)
    assert not set(chosen) & set(initial)




@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("initial", [(), (5,)])
def test_power_two_local_optimum(seed, initial):
    K, budget = 12, 3
    cams, nodes, idx = pool_index(K, seed)
    chosen, cost = medoids_select(cams, budget, M(power=2.0, path_weights=False), initial, nodes, idx)
    check_basic(chosen, K, budget, initial)
    D = ref_distances(cams, view_depths(cams, nodes, idx))
    final = check_local_optimum(D, initial, chosen, 2.0)
    assert np.isclose(cost[-1], final, rtol=1e-10, atol=0)
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError):
            M(power=bad)


@pytest.mark.parametrize("share, budget, initial", [(0.25, 8, ()), (0.5, 7, ()), (0.01, 6, ()), (1.0, 5, ())])
def test_energy_share_medoids_then_the_paper_greedy(share, budget, initial):
    """energy_share: round(share * budget) cameras by the paper's greedy on top of the medoids
    of the rest; share 0 is plain medoids, share 1 the paper's greedy alone."""
    from curate.select.greedy import greedy_select
    cams = random_pool(30, seed=11)
    idx = build_pair_index(cams, GRID.nodes(), EnergyConfig().bins)
    s = select_variant(Variant("medoids", medoids=M(energy_share=share)), cams, GRID, budget, index=idx)
    check_basic(s.chosen, 30, budget, initial)
    n_e = int(round(share * budget))
    med = medoids_select(cams, budget - n_e, M(), initial, GRID.nodes(), idx)[0]
    assert s.chosen[:budget - n_e] == med
    assert s.chosen[budget - n_e:] == greedy_select(idx, n_e, EnergyConfig(), list(initial) + med).chosen
    assert np.all(np.isfinite(s.energy)) and len(s.energy) == budget
    if share == 1.0:
        assert s.chosen == select(cams, GRID, budget, SelectConfig("energy"), initial=initial, index=idx).chosen
    plain = select_variant(Variant("medoids", medoids=M(energy_share=0.0)), cams, GRID, budget, index=idx)
    assert plain.chosen == medoids_select(cams, budget, M(), (), GRID.nodes(), idx)[0]
    # the adopted product method: the variant with its knobs at their neutral values
    from curate.select.config import MedoidsConfig
    from curate.select.medoids import medoids_select as product
    assert plain.chosen == product(cams, budget, MedoidsConfig(), (), GRID.nodes(), idx)[0]
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError):
            M(energy_share=bad)


# ------------------------------------------------------------------ sharpness (blurred frames give way)
def ref_blur_penalty(D, sharp, k=6):
    """Plain loops: -clip(ln(s_i / median(s_i and its k nearest)), -1, 1) and tau."""
    K = len(D)
    pen, near = np.zeros(K), np.zeros(K)
    for i in range(K):
        others = sorted((D[i, j], j) for j in range(K) if j != i)
        near[i] = others[0][0]
        group = [sharp[i]] + [sharp[j] for _, j in others[:min(k, K - 1)]]
        pen[i] = -np.clip(np.log(sharp[i] / np.median(group)), -1, 1)
    return pen, float(np.median(near))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("weight,power", [(0.5, 1.0), (3.0, 1.0), (1.0, 2.0)])
def test_sharpness_local_optimum_against_reference(seed, weight, power):
    from curate.select.medoids import embed
    from research.medoids_variants import blur_penalty
    K, budget = 14, 3
    cams, nodes, idx = pool_index(K, seed)
    sharp = np.random.default_rng(seed).lognormal(0.0, 0.6, K)
    depths = view_depths(cams, nodes, idx)
    D = ref_distances(cams, depths)
    pen, tau = ref_blur_penalty(D, sharp)
    got_pen, got_tau, _ = blur_penalty(*embed(cams, depths), sharp)
    assert np.allclose(got_pen, pen, atol=1e-12) and np.isclose(got_tau, tau, rtol=1e-12)
    cfg = M(power=power, sharpness_weight=weight, path_weights=False)
    chosen, cost = medoids_select(cams, budget, cfg, (), nodes, idx, sharp)
    check_basic(chosen, K, budget)
    C = D ** power + weight * tau ** power * pen[None, :]          # [view, medoid] per-view cost
    assign = [min(chosen, key=lambda m: (C[i, m], chosen.index(m))) for i in range(K)]
    for m in chosen:               # no member, nor any of the medoid's 6 nearest views, is a cheaper medoid
        members = [i for i in range(K) if assign[i] == m]
        near = [j for _, j in sorted((D[m, j], j) for j in range(K) if j != m)[:6] if j not in chosen]
        cur = sum(C[i, m] for i in members)
        assert all(sum(C[i, x] for i in members) >= cur - 1e-9 * max(1.0, abs(cur)) for x in members + near)
        if not members:            # a medoid serving nobody: no view would be cheaper serving itself
            assert all(C[x, assign[x]] - C[x, x] <= 1e-9 * max(1.0, abs(cost[-1])) for x in range(K)
                       if x not in chosen)
    assert np.isclose(cost[-1], np.mean([C[i, assign[i]] for i in range(K)]), rtol=1e-10, atol=1e-12)
    assert np.all(np.isfinite(cost)) and np.all(np.diff(cost) <= 1e-12 * max(1.0, abs(cost[0])))


def test_blurred_frame_gives_way_to_a_sharp_neighbour():
    x = np.linspace(0.0, 2.0, 9)                       # a straight walk, every frame looking ahead (+y)
    c = np.c_[x, np.zeros(9), np.zeros(9)]
    cams = Cameras(look_at(c, c + [0.0, 1.0, 0.0]), 300.0, 300.0, 160, 120, 320, 240)
    sharp = np.ones(9)
    sharp[4] = 0.3                                     # the middle frame: motion blur
    cfg = M(depth=1.0)
    assert medoids_select(cams, 1, cfg)[0] == [4]       # the medoid of the walk
    assert medoids_select(cams, 1, cfg, sharpness=sharp)[0] == [4]      # weight 0: sharpness ignored
    assert medoids_select(cams, 1, dataclasses.replace(cfg, sharpness_weight=1.0))[0] == [4]   # no sharpness given
    got = medoids_select(cams, 1, dataclasses.replace(cfg, sharpness_weight=1.0), sharpness=sharp)[0]
    assert got in ([3], [5])                           # the nearest sharp frame
    with pytest.raises(ValueError, match="sharpness has 3 entries"):
        medoids_select(cams, 1, dataclasses.replace(cfg, sharpness_weight=1.0), sharpness=np.ones(3))


def test_blur_penalty_degenerate_inputs_never_nan():
    from curate.select.medoids import embed
    from research.medoids_variants import blur_penalty
    cams = random_pool(8, seed=2)
    c, a = embed(cams, np.ones(8))
    pen, tau, nbrs = blur_penalty(c, a, np.ones(8))
    assert np.all(pen == 0) and tau > 0 and nbrs.shape == (8, 6)   # uniform sharpness: no penalty
    assert all(i not in nbrs[i] for i in range(8))
    s = np.array([1.0, 0.0, np.nan, np.inf, -1.0, 1.0, 1.0, 1e-300])
    pen = blur_penalty(c, a, s)[0]
    assert np.all(np.isfinite(pen)) and np.all(np.abs(pen) <= 1)
    assert np.all(pen[[1, 2, 3, 4]] == 1.0) and pen[7] == 1.0       # unusable / black images: avoided
    assert np.all(blur_penalty(c, a, np.full(8, np.nan))[0] == 0)   # nothing to compare with
    pen, tau, _ = blur_penalty(*embed(cams.transformed(1e4), np.full(8, 1e4)), np.linspace(1, 2, 8) * 1e6)
    ref, ref_tau, _ = blur_penalty(c, a, np.linspace(1, 2, 8))
    assert np.allclose(pen, ref) and np.isclose(tau / 1e4, ref_tau)  # scale-free in both
    dup = Cameras.concat([random_pool(1, seed=3)] * 5)
    pen, tau, _ = blur_penalty(*embed(dup, np.ones(5)), np.arange(1.0, 6.0))
    assert tau == 0.0 and np.all(np.isfinite(pen))                  # coincident views: no offset
    chosen, cost = medoids_select(dup, 3, M(sharpness_weight=2.0), sharpness=np.arange(1.0, 6.0))
    check_basic(chosen, 5, 3)
    assert np.all(np.isfinite(cost))
    pen, tau, nbrs = blur_penalty(c[:1], a[:1], [1.0])
    assert np.all(pen == 0) and tau == 0.0 and nbrs.shape == (1, 0)
    for bad in (-0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="sharpness_weight"):
            M(sharpness_weight=bad)




def walk(x, y=None, yaw=None):
    """Cameras at (x, y, 0) along a walk, looking ahead (+y) turned by ``yaw``."""
    y = np.zeros(len(x)) if y is None else y
    yaw = np.zeros(len(x)) if yaw is None else yaw
    c = np.c_[x, y, np.zeros(len(x))]
    d = np.c_[np.sin(yaw), np.cos(yaw), np.zeros(len(x))]
    return Cameras(look_at(c, c + d), 300.0, 300.0, 160, 120, 320, 240)


def test_explicit_weights():
    """``weights`` replaces the path weights: the path weights themselves give the same
    subset as ``path_weights=True``, uniform ones the plain subset; bad weights are an error."""
    rng = np.random.default_rng(4)
    x = np.cumsum(rng.uniform(0.05, 0.6, 40))
    cams = walk(x, 0.1 * rng.standard_normal(40), 0.3 * rng.standard_normal(40))
    cfg = M(depth=1.0, path_weights=False)
    w = path_weights(*embed(cams, np.ones(40)))
    assert medoids_select(cams, 6, cfg, weights=3 * w) == \
        medoids_select(cams, 6, M(depth=1.0, path_weights=True))
    assert medoids_select(cams, 6, cfg, weights=np.full(40, 0.2)) == medoids_select(cams, 6, cfg)
    for bad in (np.ones(39), np.zeros(40), np.r_[np.ones(39), np.nan], np.r_[np.ones(39), -1.0]):
        with pytest.raises(ValueError, match="weights"):
            medoids_select(cams, 6, cfg, weights=bad)


