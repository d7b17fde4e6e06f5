"""Pool coverage (research.coverage): lazy greedy against brute force, degenerate pools, the default method."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings, strategies as st

from curate.core.cameras import Cameras
from research.coverage import (CoverageConfig, cell_coverage_greedy, cell_coverage_value, cell_similarity,
                             coverage_select, facility_location_bruteforce, facility_location_greedy,
                             facility_location_value, pose_similarity)
from curate.select.config import EnergyConfig
from curate.core.grid import NodeGrid
from research.variants import Variant, select_variant
from curate.select.visibility import build_pair_index
from tests.conftest import random_pool


def pool_index(n=40, res=6, seed=0):
    cams = random_pool(n, seed=seed)
    return cams, build_pair_index(cams, NodeGrid([-1, -1, -1], [1, 1, 1], res).nodes(), EnergyConfig().bins)


def cell_coverage_bruteforce(index, budget, views, power=1.0):
    chosen = []
    for _ in range(min(budget, index.n_cams)):
        vals = [(cell_coverage_value(index, chosen + [j], views, power), j)
                for j in range(index.n_cams) if j not in chosen]
        best = max(v for v, _ in vals)
        chosen.append(min(j for v, j in vals if v >= best - 1e-11 * max(1.0, best)))
    return chosen


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), K=st.integers(1, 20), density=st.floats(0.0, 1.0),
       budget=st.integers(0, 25), rounded=st.booleans(), weighted=st.booleans(), n_init=st.integers(0, 3))
def test_facility_location_lazy_equals_bruteforce(seed, K, density, budget, rounded, weighted, n_init):
    rng = np.random.default_rng(seed)
    D = rng.random((K, K)) * (rng.random((K, K)) < density)
    if rounded:            # many exact ties
        D = np.round(D, 1)
    np.fill_diagonal(D, 1.0)
    w = rng.random(K) + 0.1 if weighted else None
    init = [int(k) for k in rng.choice(K, min(n_init, K - 1), replace=False)] if K > 1 else []
    fast = facility_location_greedy(sp.csc_matrix(D), budget, w, init)
    assert fast.chosen == facility_location_bruteforce(D, budget, w, init)
    if fast.chosen:
        assert np.isclose(fast.objective[-1], facility_location_value(sp.csc_matrix(D), init + fast.chosen, w))
        assert np.all(np.diff(fast.objective) >= -1e-12)   # monotone


@pytest.mark.parametrize("similarity", ["cells", "pose", "cells+pose"])
def test_coverage_select_on_real_similarities_equals_bruteforce(similarity):
    cams, idx = pool_index(30, 6, seed=2)
    cfg = CoverageConfig(similarity=similarity)
    chosen, obj = coverage_select(cams, idx, 8, cfg)
    from research.coverage import similarity as sim
    S = sim(cfg, cams, idx, 8)
    assert chosen == facility_location_bruteforce(S, 8)
    assert len(set(chosen)) == 8 and np.all(np.isfinite(obj))


@pytest.mark.parametrize("views,power", [(1, 1.0), (2, 1.0), (3, 0.5), (2, 0.0)])
def test_cell_coverage_lazy_equals_bruteforce(views, power):
    _, idx = pool_index(25, 5, seed=4)
    tr = cell_coverage_greedy(idx, 7, views, power)
    assert tr.chosen == cell_coverage_bruteforce(idx, 7, views, power)
    assert np.isclose(tr.objective[-1], cell_coverage_value(idx, tr.chosen, views, power))


def test_cell_similarity_definition():
    cams, idx = pool_index(12, 5, seed=1)
    S = cell_similarity(idx, 0.0).toarray()
    cells = [set(idx.nb[idx.cam_pos[idx.cam_indptr[k]:idx.cam_indptr[k + 1]]].tolist()) for k in range(12)]
    for i in range(12):
        for j in range(12):
            ref = 1.0 if i == j else (len(cells[i] & cells[j]) / len(cells[i]) if cells[i] else 0.0)
            assert np.isclose(S[i, j], ref)


def test_pose_similarity_symmetric_and_bounded():
    cams = random_pool(30, seed=5)
    S = pose_similarity(cams, 0.4, 30.0).toarray()
    assert np.allclose(S, S.T) and np.allclose(np.diag(S), 1.0) and S.min() >= 0 and S.max() <= 1


# ------------------------------------------------------------------ degenerate pools
GRID = NodeGrid([-1, -1, -1], [1, 1, 1], 5)


@pytest.mark.parametrize("method", ["coverage", "coverage+energy"])
@pytest.mark.parametrize("cov", [CoverageConfig(), CoverageConfig(similarity="pose"),
                                 CoverageConfig(similarity="cells+pose"), CoverageConfig(objective="cells")])
def test_degenerate_pools_never_nan(method, cov):
    cfg = Variant(method, coverage=cov)
    one = random_pool(1, seed=0)
    s = select_variant(cfg, one, GRID, 5)                          # budget > pool, one camera
    assert s.chosen == [0] and np.all(np.isfinite(s.objective))
    dup = Cameras.concat([random_pool(1, seed=3)] * 6)    # duplicate cameras
    s = select_variant(cfg, dup, GRID, 4)
    assert sorted(s.chosen) == sorted(set(s.chosen)) and len(s.chosen) == 4
    assert np.all(np.isfinite(s.objective)) and np.all(np.isfinite(s.energy))
    pool = random_pool(15, seed=6)
    empty = NodeGrid([-1, -1, -1], [1, 1, 1], 4, np.zeros((4, 4, 4), bool))   # empty node set
    s = select_variant(cfg, pool, empty, 5)
    assert len(set(s.chosen)) == 5 and np.all(np.isfinite(s.objective))
    s = select_variant(cfg, pool, GRID, 40)                        # budget > pool
    assert sorted(s.chosen) == list(range(15))
    assert select_variant(cfg, pool, GRID, 0).chosen == []


def test_coincident_centres_pose_scale():
    from research.coverage import default_pos_scale
    dup = Cameras.concat([random_pool(1, seed=3)] * 5)
    assert default_pos_scale(dup, 2) > 0


def test_coverage_deterministic():
    cams = random_pool(60, seed=11)
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 8)
    a = select_variant(Variant("coverage"), cams, grid, 12)
    b = select_variant(Variant("coverage"), cams, grid, 12)
    assert a.chosen == b.chosen and len(set(a.chosen)) == 12


