"""Hold-out split and the confidence intervals the reports rely on."""

import numpy as np
import pytest

from curate.core.stats import holdout_split, mean_ci, paired_difference, seeds_summary, t_quantile


def test_holdout_every_14th():
    pool, test = holdout_split(373, 14)
    assert test.tolist()[:3] == [0, 14, 28] and len(test) == 27 and len(pool) == 346
    assert not set(pool) & set(test)
    assert holdout_split(5, 0)[1].size == 0


def test_holdout_offsets_are_folds():
    """Offsets 0..every-1 hold out each image exactly once; a bad offset is an error."""
    held = np.concatenate([holdout_split(66, 7, o)[1] for o in range(7)])
    assert sorted(held.tolist()) == list(range(66))
    pool, test = holdout_split(66, 7, 3)
    assert test.tolist()[:2] == [3, 10] and not set(pool) & set(test) and len(pool) + len(test) == 66
    with pytest.raises(ValueError, match="offset"):
        holdout_split(66, 7, 7)


def test_t_quantile_and_ci_by_hand():
    assert abs(t_quantile(0.975, 9) - 2.2622) < 1e-3
    x = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    # mean 3, sd 1.5811, se 0.7071, t(0.975, 4) = 2.7764 -> half-width 1.9632
    ci = mean_ci(x)
    assert ci["mean"] == 3 and abs(ci["hi"] - 4.9632) < 1e-3 and abs(ci["lo"] - 1.0368) < 1e-3


def test_paired_difference_uses_per_view_seed_mean():
    a = np.array([20.0, 21.0, 22.0])
    b = np.array([[19.0, 20.0, 21.0], [19.0, 20.0, 21.0]])
    d = paired_difference(a, b)
    assert d["mean"] == 1.0 and d["lo"] == d["hi"] == 1.0  # constant difference: zero width
    with pytest.raises(ValueError):
        paired_difference(a, b[:, :2])
    assert seeds_summary([17.31, 17.24, 16.71])["std"] == pytest.approx(0.328, abs=1e-3)
