"""Baselines: random, farthest-view sampling, every n-th frame, hemisphere."""

import numpy as np

from curate.select.baselines import (farthest_view, fibonacci_hemisphere, hemisphere_cameras, hemisphere_subset,
                                     random_subset, stride_subset)
from curate.core.cameras import Cameras, look_at
from curate.core.grid import NodeGrid
from curate.select.config import SelectConfig
from curate.select.select import select
from conftest import random_pool


def test_random_subset_seeded_distinct_and_excludes_initial():
    a = random_subset(100, 20, seed=1, initial=[0, 1])
    assert a == random_subset(100, 20, seed=1, initial=[0, 1])
    assert a != random_subset(100, 20, seed=2, initial=[0, 1])
    assert len(set(a)) == 20 and not {0, 1} & set(a)
    assert len(random_subset(5, 10, seed=0)) == 5


def test_fvs_on_a_line_by_hand():
    # Cameras on the x axis at 0, 1, ..., 10. Start: nearest the centroid (x = 5); then the
    # farthest (x = 0 and 10 tie at 5: lowest index), then x = 10. Now x = 2, 3, 7, 8 all lie
    # 2 from their nearest chosen camera: x = 2 (lowest). Then x = 3 is 1 from x = 2, so x = 7.
    c = np.stack([np.arange(11.0), np.zeros(11), np.zeros(11)], 1)
    cams = Cameras(look_at(c, c + [0, 1, 0]), 50.0, 50.0, 50.0, 50.0, 100, 100)
    assert farthest_view(cams, 3) == [5, 0, 10]
    assert farthest_view(cams, 5) == [5, 0, 10, 2, 7]
    # With initial cameras, the first pick is the farthest from them.
    assert farthest_view(cams, 1, initial=[0]) == [10]


def test_fvs_rotation_weight_separates_co_located_views():
    c = np.zeros((3, 3))
    cams = Cameras(look_at(c, [[1, 0, 0], [1.0, 0.01, 0], [-1, 0, 0]]), 50.0, 50.0, 50.0, 50.0, 100, 100)
    assert farthest_view(cams, 1, initial=[0], rot_weight=1.0) == [2]


def test_hemisphere_cameras_look_at_centre_from_above():
    cams = hemisphere_cameras([1.0, 2.0, 3.0], 2.0, 30, fx=100.0, width=100, height=80)
    assert np.allclose(np.linalg.norm(cams.centres - [1, 2, 3], axis=1), 2.0)
    assert np.all(cams.centres[:, 2] > 3.0)
    uv, z = cams.project(np.array([[1.0, 2.0, 3.0]]))
    assert np.allclose(uv[:, 0], [50, 40]) and np.all(z > 0)
    d = fibonacci_hemisphere(500)
    assert abs(d[:, 0].mean()) < 0.02 and abs(d[:, 1].mean()) < 0.02 and np.all(d[:, 2] > 0)


def test_hemisphere_subset_picks_spread_views():
    pool = hemisphere_cameras([0.0, 0, 0], 3.0, 200, fx=100.0, width=100, height=100)
    chosen = hemisphere_subset(pool, 10, center=[0, 0, 0])
    assert len(set(chosen)) == 10
    dirs = pool.centres[chosen] / 3.0
    assert np.linalg.norm(dirs.mean(0)[:2]) < 0.3  # spread around the pole, not clustered


def test_select_dispatch_fills_energy_for_every_method():
    cams = random_pool(40, seed=9)
    grid = NodeGrid([-1, -1, -1], [1, 1, 1], 6)
    results = {m: select(cams, grid, 8, SelectConfig(method=m, seed=3))
               for m in ("energy", "random", "fvs", "stride", "medoids", "path")}
    for m, sel in results.items():
        assert len(sel.chosen) == 8 and len(sel.energy) == 8 and np.all(np.isfinite(sel.energy)), m
    # Greedy maximises the energy step by step: its first pick beats any other single camera,
    # and its final value is at least that of the baselines here.
    assert all(results["energy"].energy[-1] >= r.energy[-1] for r in results.values())


def test_stride_spaces_frames_evenly_in_name_order():
    assert stride_subset(12, 3) == [2, 6, 10]
    s = stride_subset(346, 59)
    assert len(set(s)) == 59 and s == sorted(s) and 0 <= s[0] and s[-1] < 346
    assert set(np.diff(s)) <= {5, 6}
    assert stride_subset(5, 9) == [0, 1, 2, 3, 4] and stride_subset(5, 0) == [] and stride_subset(0, 3) == []
    got = stride_subset(12, 3, initial=[0, 1, 2])          # spaced over the 9 views not fixed
    assert got == [4, 7, 10] and not {0, 1, 2} & set(got)
    cams = random_pool(20, seed=1)
    sel = select(cams, NodeGrid([-1] * 3, [1] * 3, 6), 4, SelectConfig("stride"))
    assert sel.chosen == stride_subset(20, 4) and len(sel.energy) == 4 and np.all(np.isfinite(sel.energy))
