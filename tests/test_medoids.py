"""View medoids (curate.select.medoids): a Voronoi local optimum of the mean view distance, checked by brute force."""

import dataclasses

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.select.config import EnergyConfig
from curate.core.grid import NodeGrid
from curate.select.config import MedoidsConfig
from curate.select.medoids import medoids_select, view_depths
from curate.select.config import SelectConfig
from curate.select.select import Selection, select
from curate.core.stage import config_from_dict
from curate.select.visibility import build_pair_index
from conftest import random_pool

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


# ------------------------------------------------------------------ brute-force reference
@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("initial", [(), (5,), (0, 7)])
@pytest.mark.parametrize("depth", [None, 0.7])
def test_voronoi_local_optimum_and_cost(seed, initial, depth):
    power = 1.0
    K, budget = 12, 3
    cams, nodes, idx = pool_index(K, seed)
    cfg = MedoidsConfig(depth=depth, path_weights=False)
    chosen, cost = medoids_select(cams, budget, cfg, initial, nodes, idx)
    check_basic(chosen, K, budget, initial)
    depths = np.full(K, depth) if depth is not None else view_depths(cams, nodes, idx)
    D = ref_distances(cams, depths)
    final = check_local_optimum(D, initial, chosen, power)
    assert len(cost) >= 1 and np.all(np.isfinite(cost))
    assert np.all(np.diff(cost) <= 1e-12 * max(1.0, cost[0]))
    assert np.isclose(cost[-1], final, rtol=1e-10, atol=0)
    # the iteration is worth something: no worse than the greedy farthest-point start alone
    start, _ = medoids_select(cams, budget, MedoidsConfig(depth=depth, max_iters=0, path_weights=False),
                              initial, nodes, idx)
    assert final <= mean_min(D, list(initial) + start, power) + 1e-12


def test_larger_pool_local_optimum():
    cams, nodes, idx = pool_index(40, 3)
    chosen, cost = medoids_select(cams, 7, MedoidsConfig(path_weights=False), (), nodes, idx)
    D = ref_distances(cams, view_depths(cams, nodes, idx))
    assert np.isclose(cost[-1], check_local_optimum(D, (), chosen), rtol=1e-10)


# ------------------------------------------------------------------ budgets and degenerate pools
def test_budgets_and_empty_pool():
    cams = random_pool(10, seed=1)
    assert medoids_select(cams, 0) == ([], [])
    assert medoids_select(cams, -3) == ([], [])
    chosen, cost = medoids_select(cams, 50)
    assert sorted(chosen) == list(range(10)) and cost[-1] == 0.0
    chosen, _ = medoids_select(cams, 50, initial=[2, 4, 2])
    assert sorted(chosen) == [0, 1, 3, 5, 6, 7, 8, 9]
    assert medoids_select(cams, 3, initial=range(10)) == ([], [])
    assert medoids_select(Cameras.empty(), 4) == ([], [])
    assert view_depths(Cameras.empty(), None).shape == (0,)


def test_identical_cameras_distinct_no_nan():
    dup = Cameras.concat([random_pool(1, seed=3)] * 6)
    for kw in [{}, {"nodes": GRID.nodes(), "index": build_pair_index(dup, GRID.nodes(), EnergyConfig().bins)}]:
        chosen, cost = medoids_select(dup, 4, **kw)
        check_basic(chosen, 6, 4)
        assert np.all(np.isfinite(cost)) and cost[-1] == 0.0
    assert np.all(np.isfinite(view_depths(dup, None)))


def test_rotation_on_the_spot_separated_by_depth():
    yaw = np.radians(np.r_[np.linspace(-10, 10, 6), 180 + np.linspace(-10, 10, 6)])
    c = np.zeros((12, 3))
    cams = Cameras(look_at(c, np.c_[np.cos(yaw), np.sin(yaw), np.zeros(12)]), 300.0, 300.0, 160, 120, 320, 240)
    for cfg in [MedoidsConfig(), MedoidsConfig(depth=3.0)]:       # fallback depth (no nodes), fixed depth
        chosen, cost = medoids_select(cams, 2, cfg)
        assert sorted(k // 6 for k in chosen) == [0, 1]            # one per direction group
        assert np.all(np.isfinite(cost)) and cost[-1] > 0
        assert chosen[0] in (2, 3, 8, 9) or chosen[1] in (2, 3, 8, 9)   # a middle view of its group


# ------------------------------------------------------------------ scale covariance
@pytest.mark.parametrize("seed", [0, 4])
def test_scale_covariance(seed):
    cams, nodes, idx = pool_index(30, seed)
    ref_fixed, _ = medoids_select(cams, 6, MedoidsConfig(depth=0.8))
    ref_nodes, ref_cost = medoids_select(cams, 6, MedoidsConfig(), (3,), nodes, idx)
    for s in (1e-4, 1e4):
        sc = cams.transformed(s)
        assert medoids_select(sc, 6, MedoidsConfig(depth=0.8 * s))[0] == ref_fixed
        chosen, cost = medoids_select(sc, 6, MedoidsConfig(), (3,), nodes * s, idx)   # same (combinatorial) pairs
        assert chosen == ref_nodes and np.allclose(np.array(cost) / s, ref_cost, rtol=1e-9)


# ------------------------------------------------------------------ view depths
def test_view_depths_median_of_observed_nodes():
    cams = Cameras.concat([random_pool(15, seed=2),
                           Cameras(look_at([[9.0, 9, 9]], [[20.0, 20, 20]]), 277.0, 277.0, 160, 120, 320, 240)])
    nodes = GRID.nodes()
    idx = build_pair_index(cams, nodes, EnergyConfig().bins)
    seen = [[] for _ in range(len(cams))]
    for p in range(idx.n_nodes):
        for q in range(idx.indptr[p], idx.indptr[p + 1]):
            seen[int(idx.cam[q])].append(np.linalg.norm(nodes[p] - cams.centres[int(idx.cam[q])]))
    assert not seen[15] and sum(map(bool, seen)) >= 10           # the last camera looks away
    fallback = np.median(np.concatenate([s for s in seen if s]))
    dep = view_depths(cams, nodes, idx)
    assert np.all(np.isfinite(dep)) and np.all(dep > 0)
    assert np.allclose(dep, [np.median(s) if s else fallback for s in seen], rtol=1e-12, atol=0)
    # no pairs at all: the centres' RMS spread; coincident centres: still finite and positive
    far = view_depths(cams, nodes[:0], build_pair_index(cams, nodes[:0], EnergyConfig().bins))
    c = cams.centres
    assert np.allclose(far, np.sqrt(np.mean(np.sum((c - c.mean(0)) ** 2, 1))))
    one = Cameras.concat([cams[15]] * 3)
    assert np.all(np.isfinite(view_depths(one, nodes, build_pair_index(one, nodes, EnergyConfig().bins))))
    assert np.all(view_depths(one, None) > 0)


# ------------------------------------------------------------------ why the method exists
def test_burst_does_not_absorb_the_budget():
    n = 30
    x = np.linspace(0.0, 10.0, n)
    path = look_at(np.c_[x, np.zeros(n), np.zeros(n)], np.c_[x, np.full(n, 5.0), np.zeros(n)])
    yaw = np.radians(np.linspace(-40, 40, 20))
    burst = look_at(np.tile([5.1, 0, 0], (20, 1)), np.c_[5.1 + 5 * np.sin(yaw), 5 * np.cos(yaw), np.zeros(20)])
    cams = Cameras(np.concatenate([path, burst]), 300.0, 300.0, 160, 120, 320, 240)
    for cfg in [MedoidsConfig(depth=5.0), MedoidsConfig(depth=1.0)]:
        chosen, _ = medoids_select(cams, 6, cfg)
        assert sum(k >= n for k in chosen) <= 2
        xs = np.sort(cams.centres[chosen, 0])                    # spread along the path
        assert xs[0] < 2.0 and xs[-1] > 8.0 and np.max(np.diff(xs)) < 3.5


# ------------------------------------------------------------------ end to end
def test_select_medoids_end_to_end_and_config_roundtrip():
    cams = random_pool(25, seed=8)
    cfg = SelectConfig("medoids", medoids=MedoidsConfig(depth=None, max_iters=50))
    s = select(cams, GRID, 5, cfg, initial=[1])
    assert isinstance(s, Selection) and s.method == "medoids"
    check_basic(s.chosen, 25, 5, [1])
    assert s.objective and np.all(np.isfinite(s.objective)) and np.all(np.diff(s.objective) <= 1e-12)
    assert len(s.energy) == 5 and np.all(np.isfinite(s.energy))
    assert s.to_dict()["objective"] == s.objective
    idx = build_pair_index(cams, GRID.nodes(), EnergyConfig().bins)
    assert s.chosen == medoids_select(cams, 5, cfg.medoids, [1], GRID.nodes(), idx)[0]
    for c in (cfg, SelectConfig("medoids", medoids=MedoidsConfig(depth=2.5, max_iters=3))):
        assert config_from_dict(SelectConfig, dataclasses.asdict(c)) == c
    with pytest.raises(ValueError):
        MedoidsConfig(depth=0.0)
    with pytest.raises(ValueError):
        MedoidsConfig(depth=float("nan"))
    with pytest.raises(ValueError):
        MedoidsConfig(max_iters=-1)
