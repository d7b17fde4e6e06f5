"""The research variants of method "path" (research/path_stride.py): at their neutral values
they are the product's method; their knobs move it as documented."""

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.select.baselines import stride_subset
from curate.select.config import PathConfig
from curate.select.path import path_select
from research.path_stride import path_stride


def walk(steps, turn_deg=0.0) -> Cameras:
    """Cameras along x at the cumulative positions of ``steps``, looking +y, each turned by
    ``turn_deg`` more than the last."""
    x = np.concatenate([[0.0], np.cumsum(steps)])
    c = np.stack([x, np.zeros_like(x), np.full_like(x, 1.5)], 1)
    ang = np.radians(turn_deg) * np.arange(len(x))
    look = c + 2.0 * np.stack([np.sin(ang), np.cos(ang), np.zeros_like(ang)], 1)
    return Cameras(look_at(c, look), 100.0, 100.0, 50.0, 40.0, 100, 80)


@pytest.mark.parametrize("budget", [1, 7, 30])
@pytest.mark.parametrize("look_scale", [0.5, 1.0])
def test_power_one_is_the_product(budget, look_scale):
    w = walk(np.concatenate([np.full(60, 0.03), np.full(39, 0.1)]), turn_deg=0.5)
    assert path_stride(w, budget, initial=[10], look_scale=look_scale) == \
        path_select(w, budget, PathConfig(look_scale), initial=[10])


def test_power_zero_counts_frames_like_every_nth_frame():
    w = walk(np.concatenate([np.full(60, 0.03), np.full(39, 0.1)]))
    assert np.abs(np.array(path_stride(w, 9, power=0.0)) - stride_subset(100, 9)).max() <= 1


def test_a_smaller_look_scale_gives_turning_fewer_frames():
    """First 50 frames turn on the spot (0 m, 3 degrees a frame), then 49 walk 0.1 m a frame."""
    steps = np.concatenate([np.full(50, 1e-4), np.full(49, 0.1)])
    x = np.concatenate([[0.0], np.cumsum(steps)])
    c = np.stack([x, np.zeros_like(x), np.full_like(x, 1.5)], 1)
    ang = np.radians(np.minimum(np.arange(100), 50) * 3.0)
    w = Cameras(look_at(c, c + 2.0 * np.stack([np.sin(ang), np.cos(ang), np.zeros(100)], 1)),
                100.0, 100.0, 50.0, 40.0, 100, 80)
    full = np.sum(np.array(path_stride(w, 20)) < 50)
    half = np.sum(np.array(path_stride(w, 20, look_scale=0.5)) < 50)
    assert half < full


def test_no_path_gives_none():
    w = walk(np.full(99, 0.1))
    assert path_stride(w[np.random.default_rng(0).permutation(100)], 10) is None
