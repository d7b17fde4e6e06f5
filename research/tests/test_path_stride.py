"""Frames evenly spaced along the capture path (research/path_stride.py)."""

import itertools

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from research.path_stride import arc_length, path_stride, snap, targets


def line_walk(steps) -> Cameras:
    """Cameras along the x axis at the cumulative positions of ``steps``, all looking +y at a wall 2 m away."""
    x = np.concatenate([[0.0], np.cumsum(steps)])
    c = np.stack([x, np.zeros_like(x), np.full_like(x, 1.5)], 1)
    return Cameras(look_at(c, c + [0.0, 2.0, 0.0]), 100.0, 100.0, 50.0, 40.0, 100, 80)


def test_targets_without_fixed_frames_are_evenly_spaced_with_half_steps_at_the_ends():
    s = np.linspace(0, 9, 10)
    assert np.allclose(targets(s, 3), [1.5, 4.5, 7.5])
    assert len(targets(s, 0)) == 0


@pytest.mark.parametrize("fixed", [[3], [0, 9], [2, 6], [5, 6, 7]])
@pytest.mark.parametrize("budget", [1, 2, 3, 5])
def test_targets_allocation_minimises_the_largest_spacing(fixed, budget):
    """Brute force over every way of sharing the new frames among the pieces the fixed frames
    cut: none leaves a smaller largest gap (an open end counts half a gap, as its frame serves
    one side)."""
    s = np.linspace(0, 9, 10)
    t = targets(s, budget, fixed)
    assert len(t) == budget and np.all(np.diff(t) >= 0)

    def largest_gap(pos):
        p = np.sort(np.concatenate([pos, s[fixed]]))
        inner = np.diff(p).max() if len(p) > 1 else 0.0
        return max(inner, 2 * (p[0] - s[0]), 2 * (s[-1] - p[-1]))

    got = largest_gap(t)
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
    assert got <= best + 1e-9


def test_snap_gives_distinct_increasing_indices_of_the_available_frames():
    s = np.array([0, 0, 0, 0, 1, 2, 3, 4, 5, 6.0])
    assert snap(s, targets(s, 3), np.arange(10)) == [4, 6, 8]
    got = snap(s, np.full(5, 0.0), np.arange(10))                 # all targets at one place
    assert got == sorted(set(got)) and len(got) == 5
    avail = np.array([1, 2, 5, 7])
    assert set(snap(np.arange(10.0), targets(np.arange(10.0), 4), avail)) == set(avail.tolist())


def test_a_steady_walk_gives_every_nth_frame_and_a_lingering_one_fewer_frames_where_it_lingers():
    from curate.select.baselines import stride_subset
    steady = line_walk(np.full(99, 0.1))
    assert np.abs(np.array(path_stride(steady, 10)) - stride_subset(100, 10)).max() <= 1   # within a frame
    linger = line_walk(np.concatenate([np.full(60, 0.03), np.full(39, 0.1)]))   # 1.8 m in 60 frames, 3.9 m in 39
    got = np.array(path_stride(linger, 9))
    assert np.sum(got < 60) == 3                 # a third of the path, a third of the frames
    assert np.sum(np.array(stride_subset(100, 9)) < 60) == 5                  # the clock: by frames


def test_path_stride_keeps_initial_frames_out_and_fills_the_largest_gaps():
    walk = line_walk(np.full(99, 0.1))
    got = path_stride(walk, 3, initial=[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10])
    assert not set(got) & set(range(11)) and len(got) == 3
    assert min(got) > 20                                           # nothing crowds the fixed stretch


def test_path_stride_needs_capture_order():
    walk = line_walk(np.full(99, 0.1))
    shuffled = walk[np.random.default_rng(0).permutation(len(walk))]
    assert path_stride(shuffled, 10) is None
    assert arc_length(walk.centres[:2], walk.centres[:2]) is None  # too few to form a path
