"""research/budget_real_fit.py: the calibration of `--budget auto` on real captures (issue 34)."""

from __future__ import annotations

import numpy as np
import pytest

from research.budget_real_fit import analyse, capture_alpha, measured_budget


def _capture(scene: str, kind: str, alpha: float, p: float, ks=(4, 8, 16, 32), pool: int = 60) -> dict:
    """A capture whose measured loss follows the law exactly: loss(k) = alpha * rho(k) ** p."""
    rho = 1.0 / np.arange(1, pool + 1)                                   # [pool], decreasing spacing
    pts = [{"k": k, "rho": float(rho[k - 1]), "loss": float(alpha * rho[k - 1] ** p), "sd": 0.1, "views": 10}
           for k in ks]
    return {"scene": scene, "kind": kind, "n": pool + 5, "pool": pool, "curve": rho.tolist(), "points": pts}


def test_each_captures_alpha_is_recovered_and_the_product_takes_the_highest():
    caps = [_capture("a", "object", 10.0, 1.0), _capture("b", "object", 30.0, 1.0), _capture("c", "object", 20.0, 1.0)]
    assert capture_alpha(caps[0], 1.0) == pytest.approx(10.0)
    res = analyse(caps, {"walk": 1.47, "object": 1.0})
    prod = res["product"]["object"]
    assert prod["alpha"] == pytest.approx(30.0) and prod["range"] == pytest.approx([10.0, 30.0])
    # left out: the highest of the others; a capture with the highest alpha is then advised its own budget
    loo = {(r["scene"], r["tol"]): r for r in res["loo"]}
    assert loo[("a", 0.5)]["alpha_loo"] == pytest.approx(30.0) and loo[("b", 0.5)]["alpha_loo"] == pytest.approx(20.0)
    b = loo[("b", 1.0)]
    assert b["predicted"] < b["measured"]        # b needs more than the others' law says: advised short


def test_captures_of_one_scene_never_predict_each_other():
    caps = [_capture("office", "walk", 9.6, 1.47, ks=(8, 16, 32, 48)),
            _capture("office_mp4", "walk", 9.4, 1.47, ks=(8, 16, 32, 48))]
    res = analyse(caps, {"walk": 1.47, "object": 1.0})
    assert {r["alpha_from"] for r in res["loo"]} == {"rendered walks"}


def test_the_measured_budget_is_interpolated_in_log_k_or_said_out_of_range():
    pts = [{"k": 10, "loss": 2.0}, {"k": 40, "loss": 0.0}]
    k, txt = measured_budget(pts, 1.0)
    assert k == pytest.approx(20.0) and txt == "20"
    assert measured_budget(pts, -0.5) == (None, "> 40")
    assert measured_budget(pts, 3.0) == (10.0, "<= 10")
