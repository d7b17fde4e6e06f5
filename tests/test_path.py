"""Method "path": frames evenly spaced along the capture path by view change
(curate/select/path.py), and its fallback to view medoids off a path."""

import itertools

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.core.grid import NodeGrid
from curate.select.baselines import stride_subset
from curate.select.medoids import embed, path_steps, view_depths
from curate.select.path import arc_length, path_select, snap, targets
from curate.select.config import SelectConfig
from curate.select.select import select
from curate.select.visibility import build_pair_index
from conftest import random_pool


def line_walk(steps, scale=1.0) -> Cameras:
    """Cameras along the x axis at the cumulative positions of ``steps``, all looking +y at a wall 2 m away."""
    x = np.concatenate([[0.0], np.cumsum(steps)])
    c = np.stack([x, np.zeros_like(x), np.full_like(x, 1.5)], 1)
    return Cameras(look_at(c, c + [0.0, 2.0, 0.0]), 100.0, 100.0, 50.0, 40.0, 100, 80).transformed(scale)


def test_targets_without_fixed_frames_are_evenly_spaced_with_half_steps_at_the_ends():
    s = np.linspace(0, 9, 10)
    assert np.allclose(targets(s, 3), [1.5, 4.5, 7.5])
    assert np.allclose(targets(s, 1), [4.5])
    assert len(targets(s, 0)) == 0


@pytest.mark.parametrize("fixed", [[3], [0, 9], [2, 6], [5, 6, 7], [0]])
@pytest.mark.parametrize("budget", [1, 2, 3, 5])
def test_targets_minimise_the_largest_spacing_against_brute_force(fixed, budget):
    """Every way of sharing the new frames among the pieces the fixed frames cut (an open end
    counts as half a gap: its frame serves one side): none leaves a smaller largest gap."""
    s = np.linspace(0, 9, 10)
    t = targets(s, budget, fixed)
    assert len(t) == budget and np.all(np.diff(t) >= 0) and np.all((t >= 0) & (t <= 9))

    def largest_gap(pos):
        p = np.sort(np.concatenate([pos, s[fixed]]))
        inner = np.diff(p).max() if len(p) > 1 else 0.0
        return max(inner, 2 * (p[0] - s[0]), 2 * (s[-1] - p[-1]))

    edges = np.concatenate([[s[0]], np.unique(s[fixed]), [s[-1]]])
    best = np.inf
    for alloc in itertools.product(range(budget + 1), repeat=len(edges) - 1):
        if sum(alloc) != budget:
            continue
        pos = []
        for k, m in enumerate(alloc):
            lo, hi = edges[k], edges[k + 1]
            open_lo, open_hi = k == 0 and lo not in s[fixed], k == len(alloc) - 1 and hi not in s[fixed]
            step = (hi - lo) / (m + 1 - 0.5 * open_lo - 0.5 * open_hi) if m else 0
            pos += [lo + (0.5 if open_lo else 1.0) * step + j * step for j in range(m)]
        best = min(best, largest_gap(np.array(pos)))
    assert largest_gap(t) <= best + 1e-9


def test_snap_gives_distinct_increasing_available_indices():
    s = np.array([0, 0, 0, 0, 1, 2, 3, 4, 5, 6.0])
    assert snap(s, targets(s, 3), np.arange(10)) == [4, 6, 8]
    got = snap(s, np.zeros(5), np.arange(10))                     # every target at one place
    assert got == sorted(set(got)) and len(got) == 5
    avail = np.array([1, 2, 5, 7])
    assert snap(np.arange(10.0), targets(np.arange(10.0), 6), avail) == [1, 2, 5, 7]   # more targets than frames
    assert snap(np.arange(10.0), np.array([3.0]), np.array([8])) == [8]
    assert snap(np.arange(10.0), np.zeros(0), avail) == []


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e4])
def test_a_steady_walk_gives_every_nth_frame_and_a_lingering_one_fewer_frames_where_it_lingers(scale):
    steady = line_walk(np.full(99, 0.1), scale)
    assert np.abs(np.array(path_select(steady, 10)) - stride_subset(100, 10)).max() <= 1   # within a frame
    linger = line_walk(np.concatenate([np.full(60, 0.03), np.full(39, 0.1)]), scale)   # 1.8 m in 60 frames, 3.9 m in 39
    got = np.array(path_select(linger, 9))
    assert np.sum(got < 60) == 3                                   # a third of the path, a third of the frames
    assert np.sum(np.array(stride_subset(100, 9)) < 60) == 5       # every n-th frame: by the clock


def test_a_second_pass_over_the_same_place_gets_its_own_frames():
    """Walking a stretch and back (0.3 m aside): each pass gets half the frames, as its half of the path."""
    there = line_walk(np.full(49, 0.1))
    back = Cameras(there.c2w[::-1].copy(), 100.0, 100.0, 50.0, 40.0, 100, 80)
    back.c2w[:, 1, 3] += 0.3                                       # back along the other side of the corridor
    walk = Cameras(np.concatenate([there.c2w, back.c2w]), 100.0, 100.0, 50.0, 40.0, 100, 80)
    got = np.array(path_select(walk, 8))
    assert np.sum(got < 50) == 4 and np.sum(got >= 50) == 4


def test_a_cut_between_sequences_counts_as_a_short_step():
    jump = line_walk(np.concatenate([np.full(49, 0.1), [100.0], np.full(49, 0.1)]))
    c, a = embed(jump, view_depths(jump, None))
    s = arc_length(c, a)
    assert s[50] - s[49] == pytest.approx(4.0)                     # PATH_CAP median steps, not 1000
    got = np.array(path_select(jump, 10))
    assert np.sum(got < 50) == 5


def test_initial_frames_are_kept_out_and_the_largest_gaps_filled_first():
    walk = line_walk(np.full(99, 0.1))
    got = path_select(walk, 3, initial=list(range(11)))
    assert not set(got) & set(range(11)) and len(got) == 3 and min(got) > 20


@pytest.mark.parametrize("budget", [0, 1, 5, 99, 100, 250])
def test_budgets_up_to_and_beyond_the_pool(budget):
    walk = line_walk(np.full(99, 0.1))
    got = path_select(walk, budget, initial=[50])
    assert len(got) == min(budget, 99) and len(set(got)) == len(got) and 50 not in got


def test_no_path_gives_none():
    walk = line_walk(np.full(99, 0.1))
    shuffled = walk[np.random.default_rng(0).permutation(len(walk))]
    assert path_select(shuffled, 10) is None
    assert path_select(walk[:2], 1) is None                        # too few to form a path
    c = np.zeros((6, 3))
    same = Cameras(look_at(c, c + [0.0, 1.0, 0.0]), 100.0, 100.0, 50.0, 40.0, 100, 80)
    assert path_steps(*embed(same, view_depths(same, None))) is None   # every step 0: no NaN, no path
    assert path_select(same, 3) is None


def test_select_runs_path_on_a_path_and_falls_back_to_medoids_with_a_note():
    grid = NodeGrid([-1, -1, -1], [12, 4, 3], 8)
    walk = line_walk(np.full(99, 0.1))
    index = build_pair_index(walk, grid.nodes(), SelectConfig().energy.bins)
    sel = select(walk, grid, 10, SelectConfig("path"), index=index)
    assert (sel.method == "path" and sel.chosen == path_select(walk, 10, nodes=grid.nodes(), index=index)
            and not sel.note)
    assert len(sel.energy) == 10 and np.all(np.isfinite(sel.energy))
    pool = random_pool(60, seed=2)                                 # photos in no order
    fb = select(pool, grid, 8, SelectConfig("path"))
    assert fb.method == "medoids" and "not in capture order" in fb.note
    assert fb.chosen == select(pool, grid, 8, SelectConfig("medoids")).chosen


def test_auto_spaces_a_walk_along_its_path():
    grid = NodeGrid([-1, -1, -1], [12, 4, 3], 8)
    walk = line_walk(np.concatenate([np.full(60, 0.03), np.full(39, 0.1)]))
    sel = select(walk, grid, 9, SelectConfig())
    assert sel.method == "path" and "walk-through" in sel.note and "-> path" in sel.note
    assert sel.chosen == select(walk, grid, 9, SelectConfig("path")).chosen
    assert np.sum(np.array(sel.chosen) < 60) == 3                  # not 5, as every n-th frame would give
