"""The --budget auto fit: the measured budget interpolates a measured curve, the predicted one
is the fewest within the tolerance, and the fit through the origin is least squares."""

import numpy as np
import pytest

from research.budget_fit import fit_alpha, measured_budget, predicted_budget
from research.harness_tables import ci, tables


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


def test_tables_name_the_candidate_and_count_gap_and_frames_saved():
    """One scene at two budgets: the candidate's column is named, the gap closed is (cand - random) /
    (all - random), frames saved is the first budget within 0.3 dB of all frames."""
    rows = [{"scene": "w", "budget": b, "pool": 100, "method": m, "psnr": v}
            for b, vals in ((10, {"medoids_plain": 29.0, "fvs": 28.0, "stride": 28.5, "random": 27.0}),
                            (20, {"medoids_plain": 29.8, "fvs": 29.0, "stride": 29.9, "random": 28.0}))
            for m, v in vals.items()] + [{"scene": "w", "budget": 10, "pool": 100, "method": "all", "psnr": 30.0}]
    paired = [{"scene": "w", "budget": 10, "pair": "medoids_plain-random", "mean": 2.0, "lo": 1.0, "hi": 3.0}]
    md = tables({"rows": rows, "paired": paired}, "medoids_plain")
    lines = md.splitlines()
    assert "| `medoids_plain` | FVS |" in lines[0] and "`auto`" not in md
    assert lines[2].startswith("| w | 10 of 100 | 30.00 | 29.00 | 28.00 | 28.50 | 27.00 | **+2.00 (+1.00 to +3.00)** |")
    assert lines[2].endswith("| 67% |") and lines[3].endswith("| 90% |")     # 2 / 3 and 1.8 / 2
    assert lines[-1] == "| w | 20 | > 20 | 20 | > 20 |"


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


@pytest.mark.parametrize("kind", ["walk", "object"])
def test_predicted_budget_with_the_products_constants_is_choose_budget(kind):
    """predict_run chooses from one spacing curve with predicted_budget: the same budget as the
    product's choose_budget at every tolerance (argument order included)."""
    from curate.select.auto_budget import LOSS_MODEL, choose_budget
    from curate.select.spacing import spacing_curve
    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    c = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], 1) + rng.normal(0, 0.01, (120, 3))
    a = c + np.stack([np.cos(t + 1), np.sin(t + 1), rng.normal(0, 0.1, 120)], 1)
    depths = np.full(120, 1.5)
    _, rho = spacing_curve(c, a, depths)
    alpha, power = LOSS_MODEL[kind]
    for tol in (0.05, 0.3, 0.5, 1.0, 3.0):
        assert predicted_budget(rho, alpha, tol, power) == choose_budget(c, a, depths, tol, kind).budget
