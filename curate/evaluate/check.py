"""The budget check's fit: how many photos this capture needs, from losses measured on the capture itself.

``--budget auto`` predicts a budget from the poses alone, with a law fitted on other captures
(:mod:`curate.select.auto_budget`); a capture may need more (exposure changes, blur, texture, pose error: what
the law never sees). The budget stage (:mod:`curate.evaluate.budget`) measures the loss against all photos
(``loss(k)``, dB, per held-out photo) at about half, once and twice the law's advice on two hold-out folds;
:func:`fit_check` fits the law's shape to those points, ``loss = alpha * rho(k) ** p`` with ``p`` the law's
and ``alpha`` this capture's (least squares in log, points losing at least :data:`MIN_LOSS`), and advises the
fewest photos of the whole capture whose predicted loss is within the tolerance, on the whole capture's
spacing curve. Its range: the same with ``alpha`` from each measured point alone (how far the points disagree
with the law's shape). Validation on real captures: docs/evaluation.md#how-many.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

MIN_LOSS = 0.05
"""Measured losses below this (dB) are noise on a log scale: left out of the fit."""


def check_budgets(k: int, n_pool: int) -> list[int]:
    """The check's extra budgets beside the estimate's ``k``: about half and twice it, within
    [3, n_pool - 2], without ``k`` itself (fewer when the pool is small)."""
    out = {max(3, int(round(k / 2))), min(n_pool - 2, 2 * k)}
    return sorted(b for b in out if 3 <= b <= n_pool - 2 and b != k)


@dataclass
class BudgetCheck:
    """What the measured check advises."""

    points: list[dict]
    """Each measured budget of the evaluation's split: ``k``, ``rho`` (its relative spacing), ``loss``
    (dB, mean over the held-out photos of all - subset) with its 95% interval ``lo``, ``hi``."""
    power: float
    """The law's exponent p (by the capture's kind)."""
    alpha: float | None
    """This capture's fitted alpha (None: no point lost at least MIN_LOSS)."""
    tolerance_db: float
    budget: int | None
    """The advised budget of the whole capture (None: every measured budget is already within the
    tolerance; then ``at_most`` holds)."""
    low: int | None
    """The range's low end (photos)."""
    high: int | None
    """The range's high end (photos)."""
    pool: int
    """Photos of the whole capture."""
    note: str
    """One sentence for a person."""

    def to_dict(self) -> dict:
        return asdict(self)


def fit_check(points: list[dict], power: float, rho_full: np.ndarray, tolerance_db: float,
              scale: float) -> BudgetCheck:
    """The check's advice from its measured ``points`` (``k`` of the split's pool, ``rho``, ``loss``,
    ``lo``, ``hi``), the law's ``power``, the whole capture's spacing curve ``rho_full`` [K] and the
    ratio ``scale`` = K / (the split's pool size)."""
    from curate.select.auto_budget import fewest_within
    K = len(rho_full)
    rho_full = np.asarray(rho_full, np.float64)
    use = [p for p in points if p["loss"] >= MIN_LOSS and p["rho"] > 0]

    def advise(alpha: float) -> int:
        k = fewest_within(alpha * rho_full ** power, tolerance_db)
        return K if k is None else k

    pts = sorted(points, key=lambda p: p["k"])
    if not use:
        k0 = int(round(pts[0]["k"] * scale)) if pts else None
        note = (f"measured on this capture: already {pts[0]['k']} photos of the split lose "
                f"{pts[0]['loss']:.2f} dB, within {tolerance_db:g} dB: about {k0} of {K} photos or fewer suffice"
                if pts else "no measured point")
        return BudgetCheck(points, power, None, tolerance_db, None, None, k0, K, note)
    la = np.log([p["loss"] for p in use]) - power * np.log([p["rho"] for p in use])
    alpha = float(np.exp(la.mean()))
    each = [advise(float(np.exp(x))) for x in la]
    k = advise(alpha)
    lo, hi = min(each + [k]), max(each + [k])
    more = k >= K
    note = ("measured on this capture: no budget below all its photos is predicted within "
            f"{tolerance_db:g} dB; keep them all" if more else
            f"measured on this capture: about {k} of {K} photos ({lo} to {hi}) come within {tolerance_db:g} dB "
            "of all photos")
    return BudgetCheck(points, power, alpha, tolerance_db, k, lo, hi, K, note)
