"""View medoids (curate.select.medoids): a Voronoi local optimum of the mean view distance, checked by brute force."""

import dataclasses

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.select.energy import EnergyConfig
from curate.core.grid import NodeGrid
from curate.select.medoids import MedoidsConfig, medoids_select, view_depths
from curate.select.select import SelectConfig, Selection, select
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
@pytest.mark.parametrize("depth,power", [(None, 1.0), (0.7, 1.0), (None, 2.0)])
def test_voronoi_local_optimum_and_cost(seed, initial, depth, power):
    K, budget = 12, 3
    cams, nodes, idx = pool_index(K, seed)
    cfg = MedoidsConfig(depth=depth, power=power, path_weights=False)
    chosen, cost = medoids_select(cams, budget, cfg, initial, nodes, idx)
    check_basic(chosen, K, budget, initial)
    depths = np.full(K, depth) if depth is not None else view_depths(cams, nodes, idx)
    D = ref_distances(cams, depths)
    final = check_local_optimum(D, initial, chosen, power)
    assert len(cost) >= 1 and np.all(np.isfinite(cost))
    assert np.all(np.diff(cost) <= 1e-12 * max(1.0, cost[0]))
    assert np.isclose(cost[-1], final, rtol=1e-10, atol=0)
    # the iteration is worth something: no worse than the greedy farthest-point start alone
    start, _ = medoids_select(cams, budget, MedoidsConfig(depth=depth, max_iters=0, power=power, path_weights=False), initial, nodes, idx)
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
    for bad in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError):
            MedoidsConfig(power=bad)



@pytest.mark.parametrize("share, budget, initial", [(0.25, 8, ()), (0.5, 7, [3]), (0.01, 6, ()), (1.0, 5, [2])])
def test_energy_share_medoids_then_the_paper_greedy(share, budget, initial):
    """energy_share: round(share * budget) cameras by the paper's greedy on top of the medoids
    of the rest; share 0 is plain medoids, share 1 the paper's greedy alone."""
    from curate.select.greedy import greedy_select
    cams = random_pool(30, seed=11)
    idx = build_pair_index(cams, GRID.nodes(), EnergyConfig().bins)
    s = select(cams, GRID, budget, SelectConfig("medoids", medoids=MedoidsConfig(energy_share=share)),
               initial=initial, index=idx)
    check_basic(s.chosen, 30, budget, initial)
    n_e = int(round(share * budget))
    med = medoids_select(cams, budget - n_e, MedoidsConfig(), initial, GRID.nodes(), idx)[0]
    assert s.chosen[:budget - n_e] == med
    assert s.chosen[budget - n_e:] == greedy_select(idx, n_e, EnergyConfig(), list(initial) + med).chosen
    assert np.all(np.isfinite(s.energy)) and len(s.energy) == budget
    if share == 1.0:
        assert s.chosen == select(cams, GRID, budget, SelectConfig("energy"), initial=initial, index=idx).chosen
    plain = select(cams, GRID, budget, SelectConfig("medoids", medoids=MedoidsConfig(energy_share=0.0)), index=idx)
    assert plain.chosen == medoids_select(cams, budget, MedoidsConfig(), (), GRID.nodes(), idx)[0]
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError):
            MedoidsConfig(energy_share=bad)


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
    from curate.select.medoids import blur_penalty, embed
    K, budget = 14, 3
    cams, nodes, idx = pool_index(K, seed)
    sharp = np.random.default_rng(seed).lognormal(0.0, 0.6, K)
    depths = view_depths(cams, nodes, idx)
    D = ref_distances(cams, depths)
    pen, tau = ref_blur_penalty(D, sharp)
    got_pen, got_tau, _ = blur_penalty(*embed(cams, depths), sharp)
    assert np.allclose(got_pen, pen, atol=1e-12) and np.isclose(got_tau, tau, rtol=1e-12)
    cfg = MedoidsConfig(power=power, sharpness_weight=weight, path_weights=False)
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
    cfg = MedoidsConfig(depth=1.0)
    assert medoids_select(cams, 1, cfg)[0] == [4]       # the medoid of the walk
    assert medoids_select(cams, 1, cfg, sharpness=sharp)[0] == [4]      # weight 0: sharpness ignored
    assert medoids_select(cams, 1, dataclasses.replace(cfg, sharpness_weight=1.0))[0] == [4]   # no sharpness given
    got = medoids_select(cams, 1, dataclasses.replace(cfg, sharpness_weight=1.0), sharpness=sharp)[0]
    assert got in ([3], [5])                           # the nearest sharp frame
    with pytest.raises(ValueError, match="sharpness has 3 entries"):
        medoids_select(cams, 1, dataclasses.replace(cfg, sharpness_weight=1.0), sharpness=np.ones(3))


def test_blur_penalty_degenerate_inputs_never_nan():
    from curate.select.medoids import blur_penalty, embed
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
    chosen, cost = medoids_select(dup, 3, MedoidsConfig(sharpness_weight=2.0), sharpness=np.arange(1.0, 6.0))
    check_basic(chosen, 5, 3)
    assert np.all(np.isfinite(cost))
    pen, tau, nbrs = blur_penalty(c[:1], a[:1], [1.0])
    assert np.all(pen == 0) and tau == 0.0 and nbrs.shape == (1, 0)
    for bad in (-0.1, np.nan, np.inf):
        with pytest.raises(ValueError, match="sharpness_weight"):
            MedoidsConfig(sharpness_weight=bad)


def test_uses_sharpness_only_when_view_medoids_run_with_a_weight():
    """Callers read every photo for sharpness only when select() would use it."""
    from curate.select.baselines import hemisphere_cameras
    from curate.select.select import capture_kind, uses_sharpness
    x = np.linspace(0.0, 2.0, 9)
    c = np.c_[x, np.zeros(9), np.zeros(9)]
    walk = Cameras(look_at(c, c + [0.0, 1.0, 0.0]), 300.0, 300.0, 160, 120, 320, 240)
    obj = hemisphere_cameras([0.0, 0.0, 0.0], 2.0, 12, 300.0, 320, 240)
    assert capture_kind(walk)[0] == "walk" and capture_kind(obj)[0] == "object"
    w = MedoidsConfig(sharpness_weight=1.0)
    assert uses_sharpness(walk, SelectConfig("auto", medoids=w))
    assert not uses_sharpness(obj, SelectConfig("auto", medoids=w))          # auto runs the energy there
    assert uses_sharpness(obj, SelectConfig("medoids", medoids=w))
    assert not uses_sharpness(walk, SelectConfig("medoids"))                  # weight 0
    assert not uses_sharpness(walk, SelectConfig("fvs", medoids=w))
