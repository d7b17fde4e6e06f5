"""The spacing curve and ``--budget auto``: exact against a brute-force reference, scale-free,
finite on degenerate pools, and choosing by the capture's extent, not its frame rate."""

from __future__ import annotations

import numpy as np
import pytest

from curate.core.budget import AUTO, budget_text, parse_budget, resolve_budget
from curate.select.auto_budget import choose_budget, curve_budgets, predicted_loss
from curate.select.medoids import view_distance
from curate.select.spacing import spacing_curve


def circle_walk(n: int, turns: float = 1.0, radius: float = 2.0, depth: float = 3.0, seed: int = 0):
    """(c [n, 3], a [n, 3], depths [n]): a walk around a circle, looking outwards, with a little jitter."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi * turns, n, endpoint=False)
    c = np.stack([radius * np.cos(t), radius * np.sin(t), np.zeros(n)], 1) + rng.normal(0, 0.01, (n, 3))
    v = np.stack([np.cos(t), np.sin(t), np.zeros(n)], 1)
    d = np.full(n, depth)
    return c, c + d[:, None] * v, d


def reference_rho(c, a, depths, order):
    """rho after each pick, by brute force over the whole [K, K] distance matrix."""
    D = view_distance(c, a, np.arange(len(c)), np.arange(len(c)))
    return np.array([np.mean(D[:, order[:k]].min(axis=1) / depths) for k in range(1, len(order) + 1)])


def test_spacing_curve_matches_brute_force_and_is_farthest_point():
    rng = np.random.default_rng(3)
    c, a = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    depths = rng.uniform(0.5, 3.0, 40)
    order, rho = spacing_curve(c, a, depths)
    assert sorted(order.tolist()) == list(range(40))                   # every view once
    np.testing.assert_allclose(rho, reference_rho(c, a, depths, order), rtol=1e-12, atol=1e-15)
    D = view_distance(c, a, np.arange(40), np.arange(40))
    for k in range(1, 40):                                             # each pick: the farthest remaining view
        near = D[:, order[:k]].min(axis=1)
        assert near[order[k]] == pytest.approx(near.max())
    assert np.all(np.diff(rho) <= 1e-15) and rho[-1] == 0.0
    _, part = spacing_curve(c, a, depths, max_k=5)
    np.testing.assert_array_equal(part, rho[:5])


@pytest.mark.parametrize("scale", [1e-4, 1.0, 1e4])
def test_spacing_and_choice_are_scale_free(scale):
    c, a, d = circle_walk(120)
    _, rho = spacing_curve(c, a, d)
    _, rho_s = spacing_curve(c * scale, a * scale, d * scale)
    np.testing.assert_allclose(rho_s, rho, rtol=1e-9)
    assert choose_budget(c * scale, a * scale, d * scale).budget == choose_budget(c, a, d).budget


def test_degenerate_pools_stay_finite():
    c = np.zeros((10, 3))
    a = np.tile([0.0, 0.0, 1.0], (10, 1))
    order, rho = spacing_curve(c, a, np.ones(10))                       # ten copies of one view
    assert np.all(rho == 0.0) and len(order) == 10
    ch = choose_budget(c, a, np.ones(10))
    assert ch.budget == 2 and ch.predicted_loss_db == 0.0 and np.all(np.isfinite(ch.curve_loss_db))
    assert spacing_curve(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))[1].shape == (0,)
    with pytest.raises(ValueError, match="at least 3"):
        choose_budget(c[:2], a[:2], np.ones(2))
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="tolerance"):
            choose_budget(c, a, np.ones(10), bad)


def test_choice_is_the_fewest_within_tolerance_and_monotone():
    c, a, d = circle_walk(300)
    _, rho = spacing_curve(c, a, d)
    prev = None
    for tol in (2.0, 1.0, 0.5, 0.25):
        ch = choose_budget(c, a, d, tol)
        k = ch.budget
        loss = predicted_loss(rho, 'walk')
        assert loss[k - 1] <= tol < loss[k - 2]   # the fewest
        assert ch.predicted_loss_db == pytest.approx(loss[k - 1])
        assert prev is None or k >= prev                                 # a tighter tolerance never needs fewer
        prev = k
        assert ch.curve_k == sorted(set(ch.curve_k)) and ch.curve_k[-1] == 300


def test_budget_follows_the_path_not_the_frame_rate():
    """The same walk filmed at twice the frame rate needs about the same photos; a walk twice as
    long (two laps of new ground: a spiral) needs about twice as many."""
    k1 = choose_budget(*circle_walk(200)).budget
    k2 = choose_budget(*circle_walk(400)).budget
    assert abs(k2 - k1) <= 0.1 * k1
    c, a, d = circle_walk(400, turns=2.0)
    c = c + np.linspace(0, 8.0, 400)[:, None] * np.array([0.0, 0.0, 1.0])   # the second lap higher up
    a = a + np.linspace(0, 8.0, 400)[:, None] * np.array([0.0, 0.0, 1.0])
    k_long = choose_budget(c, a, d).budget
    assert 1.6 * k1 <= k_long <= 2.4 * k1


def test_no_budget_within_tolerance_takes_all_but_one():
    c, a, d = circle_walk(8)                                            # 8 views 45 deg apart: nothing to spare
    ch = choose_budget(c, a, d, 0.01)
    assert ch.budget == 7 and "little to spare" in ch.note


def test_curve_budgets():
    assert curve_budgets(5).tolist() == [1, 2, 3, 4, 5]
    ks = curve_budgets(10_000, 120)
    assert ks[0] == 1 and ks[-1] == 10_000 and len(ks) <= 120 and np.all(np.diff(ks) > 0)


def test_parse_auto():
    assert parse_budget("auto") == AUTO and parse_budget(" AUTO ") == AUTO
    assert budget_text(AUTO) == "auto"
    with pytest.raises(ValueError, match="chosen from the pool"):
        resolve_budget(AUTO, 100)
    with pytest.raises(ValueError, match="'auto'"):
        parse_budget("automatic")


def test_constants_are_the_calibration_in_the_evidence():
    """The loss law and its range in the product are the ones research/budget_real_fit.py calibrated
    on real captures and wrote to docs/evidence/budget_real.json, and the advice's range holds the
    point advice (the point is the range's high end: the conservative side)."""
    import json
    from pathlib import Path

    from curate.select.auto_budget import ALPHA_RANGE, LOSS_MODEL
    ev = json.loads((Path(__file__).resolve().parents[1] / "docs" / "evidence" / "budget_real.json").read_text())
    assert set(ev["product"]) == set(LOSS_MODEL) == set(ALPHA_RANGE)
    for kind, fit in ev["product"].items():
        assert LOSS_MODEL[kind] == pytest.approx((fit["alpha"], fit["p"]), abs=0.005)
        assert ALPHA_RANGE[kind] == pytest.approx(tuple(fit["range"]), abs=0.005)
        lo, hi = ALPHA_RANGE[kind]
        assert lo < hi and lo <= LOSS_MODEL[kind][0] <= hi
