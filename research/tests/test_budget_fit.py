"""The --budget auto fit: the measured budget interpolates a measured curve, the predicted one
is the fewest within the tolerance, and the fit through the origin is least squares."""

import numpy as np
import pytest

from research.budget_fit import fit_alpha, measured_budget, predicted_budget
from research.harness_tables import ci


def test_measured_budget_interpolates_between_measured_budgets():
    rows = [{"k": 28, "loss_on": 2.0}, {"k": 42, "loss_on": 1.0}, {"k": 83, "loss_on": 0.2}]
    k, txt = measured_budget(rows, 0.5)
    assert k == pytest.approx(42 + (1.0 - 0.5) / 0.8 * 41) and txt == f"{k:.0f}"
    assert measured_budget(rows, 3.0) == (28.0, "<= 28")
    assert measured_budget(rows, 0.1) == (None, "> 83")
    assert measured_budget([], 0.5) == (None, "-")


def test_predicted_budget_is_the_fewest_within_tolerance():
    rho = np.array([1.0, 0.5, 0.2, 0.1, 0.05, 0.0])
    assert predicted_budget(rho, 10.0, 1.0) == 4           # 10 * rho[3] = 1.0
    assert predicted_budget(rho, 10.0, 100.0) == 2         # never below 2
    assert predicted_budget(rho, 10.0, 0.01) == 5          # none: K - 1


def test_fit_alpha_is_least_squares_through_the_origin():
    rows = [{"rho_sel": x, "loss_on": 3.0 * x + e} for x, e in ((0.1, 0.01), (0.2, -0.02), (0.4, 0.01))]
    x = np.array([0.1, 0.2, 0.4])
    y = 3.0 * x + np.array([0.01, -0.02, 0.01])
    assert fit_alpha(rows) == pytest.approx(x @ y / (x @ x))


def test_ci_marks_intervals_that_exclude_zero():
    assert ci({"mean": 0.5, "lo": 0.1, "hi": 0.9}).startswith("**")
    assert not ci({"mean": 0.1, "lo": -0.1, "hi": 0.3}).startswith("**")
    assert ci(None) == "-"


def test_measured_loss_at_interpolates_inside_the_measured_range_only():
    from research.budget_fit import measured_loss_at
    rows = [{"k": 28, "loss_on": 2.0}, {"k": 42, "loss_on": 1.0}]
    assert measured_loss_at(rows, 35) == pytest.approx(1.5)
    assert measured_loss_at(rows, 20) is None and measured_loss_at(rows, 50) is None
    assert measured_loss_at(rows, None) is None


def test_pool_and_subset_spacing_match_brute_force():
    from curate.select.medoids import view_distance
    from curate.select.spacing import spacing_curve
    from research.budget_fit import pool_spacing, subset_spacing
    rng = np.random.default_rng(3)
    c, a = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    d = rng.uniform(0.5, 3.0, 50)
    D = view_distance(c, a, np.arange(50), np.arange(50))
    np.fill_diagonal(D, np.inf)
    assert pool_spacing(c, a, d, chunk=7) == pytest.approx(np.mean(D.min(axis=1) / d))
    assert pool_spacing(c[:1], a[:1], d[:1]) == 0.0
    order, rho = spacing_curve(c, a, d)
    assert subset_spacing(c, a, d, order[:7], chunk=11) == pytest.approx(rho[6])
