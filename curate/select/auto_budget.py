"""``--budget auto``: the smallest budget predicted to come within a tolerance of all frames.

From the pool alone (no training): the spacing curve rho(k) of :mod:`curate.select.spacing`
(how far, relative to the scene's depth, a pool view is from the nearest of k well-spread
views) predicts how much held-out PSNR a budget of k loses against every frame::

    loss(k) = alpha * rho(k) ** p        [dB],   (alpha, p) = LOSS_MODEL[kind]

with ``kind`` the capture's kind (walk-through or object capture:
:func:`curate.select.methods.capture_kind`). The constants are calibrated on real captures by
``research/budget_real.py`` (the product's default selection and evaluation settings, learning
curves at five or six budgets, two or three hold-out folds) and ``research/budget_real_fit.py``
(docs/evidence/budget_real.json; docs/evaluation.md#how-many): alpha per capture is
fitted with the power p of ``research/budget_fit.py``'s fit on rendered walks; the product takes
the *highest* alpha seen for the kind (an advice short of what a capture needs costs quality, one
beyond it a little training time) and the lowest-to-highest spread as the advice's range. Objects:
the fox, the skull, the templering; walks: the office walk and office.mp4 (one real scene) and
the rendered walks. The prediction is of the loss on views along the capture (the held-out
protocol), at the evaluation's training settings; it is a rule of thumb with a measured error, not
a guarantee: the measured check of :mod:`curate.evaluate.check` runs on the capture itself when
the run is evaluated.

The choice is the smallest k in [2, K - 1] with loss(k) <= tolerance; when none is, K - 1
with a note that the capture has little to spare.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

LOSS_MODEL = {"walk": (13.19, 1.47), "object": (32.47, 1.0)}
"""(alpha, p) by capture kind: held-out PSNR lost, in dB, is alpha * rho ** p at relative spacing
rho (docs/evidence/budget_real.json, "product")."""

ALPHA_RANGE = {"walk": (9.37, 13.83), "object": (12.71, 32.47)}
"""(low, high) alpha by capture kind: the spread over the captures the law was calibrated on; the
advice's range is the budgets these give (docs/evidence/budget_real.json, "product")."""

CURVE_POINTS = 120
"""The predicted curve is kept (selection.json, the report) at about this many budgets."""


@dataclass
class BudgetChoice:
    """What ``--budget auto`` chose, and the curve it chose from."""

    budget: int
    """Images chosen."""
    pool: int
    """Images in the pool."""
    tolerance_db: float
    """The allowed predicted loss against all frames, dB."""
    kind: str
    """The capture's kind ('walk' or 'object'), which picks the loss constant."""
    predicted_loss_db: float
    """The predicted loss at ``budget``, dB."""
    rho: float
    """The relative spacing at ``budget``."""
    curve_k: list[int]
    """Budgets of the kept curve (ascending)."""
    curve_loss_db: list[float]
    """The predicted loss at each of ``curve_k``, dB."""
    note: str
    """One sentence: what it chose and why."""
    alpha: float = 0.0
    """The law's alpha used (dB)."""
    power: float = 1.0
    """The law's exponent p."""
    low: int | None = None
    """The advice's range, low end: the budget with the lowest alpha of :data:`ALPHA_RANGE`."""
    high: int | None = None
    """The advice's range, high end: the budget with the highest alpha."""

    def to_dict(self) -> dict:
        return asdict(self)


def predicted_loss(rho: np.ndarray, kind: str = "walk") -> np.ndarray:
    """[k] predicted loss in dB against all frames for relative spacings ``rho`` [k] of a capture
    of ``kind`` ('walk' or 'object')."""
    alpha, p = LOSS_MODEL[kind]
    return alpha * np.asarray(rho, np.float64) ** p


def curve_budgets(K: int, n: int = CURVE_POINTS) -> np.ndarray:
    """About ``n`` budgets in [1, K], ascending and distinct: dense at small k (geometric), then even."""
    if K <= n:
        return np.arange(1, K + 1)
    g = np.geomspace(1, K, n // 2)
    lin = np.linspace(1, K, n - n // 2)
    return np.unique(np.round(np.concatenate([g, lin])).astype(np.int64))


def fewest_within(loss: np.ndarray, tolerance_db: float) -> int | None:
    """The smallest budget k in [2, K - 1] with ``loss[k - 1] <= tolerance_db`` for the predicted
    loss [K] at budgets 1..K; None when there is none."""
    K = len(loss)
    ok = np.flatnonzero(np.asarray(loss)[1:K - 1] <= tolerance_db)       # budgets 2 .. K-1
    return int(ok[0]) + 2 if len(ok) else None


def choose_budget(c: np.ndarray, a: np.ndarray, depths: np.ndarray, tolerance_db: float = 0.5,
                  kind: str = "walk") -> BudgetChoice:
    """The smallest budget whose predicted loss is within ``tolerance_db`` of all frames.

    ``c``, ``a`` [K, 3]: the pool's embedded views (:func:`curate.select.medoids.embed`);
    ``depths`` [K] > 0 their look-at depths; ``kind`` the capture's ('walk' or 'object'). Needs
    K >= 3 (a budget of 2 to K - 1).
    """
    from curate.select.spacing import spacing_curve
    if not (np.isfinite(tolerance_db) and tolerance_db > 0):
        raise ValueError(f"the budget tolerance must be > 0 dB, got {tolerance_db}")
    K = len(c)
    if K < 3:
        raise ValueError(f"--budget auto needs a pool of at least 3 images, got {K}")
    _, rho = spacing_curve(c, a, depths)                                 # [K]
    loss = predicted_loss(rho, kind)                                     # [K]
    k = fewest_within(loss, tolerance_db)
    if k is not None:
        note = (f"budget auto: {k} of {K} images ({kind}), the fewest predicted within {tolerance_db:g} dB of all "
                f"frames (predicted loss {loss[k - 1]:.2f} dB; relative spacing {rho[k - 1]:.3f})")
    else:
        k = K - 1
        note = (f"budget auto: no budget below the whole pool is predicted within {tolerance_db:g} dB of all "
                f"frames (at {K - 1} of {K}: {loss[K - 2]:.2f} dB): the capture has little to spare; "
                f"{k} images chosen")
    alpha, power = LOSS_MODEL[kind]
    lo, hi = (fewest_within(a * rho ** power, tolerance_db) or K - 1 for a in ALPHA_RANGE[kind])
    if (lo, hi) != (k, k):
        note = note.replace(f"budget auto: {k} of", f"budget auto: {k} ({lo} to {hi}) of", 1)
    ks = curve_budgets(K)
    return BudgetChoice(k, K, float(tolerance_db), kind, float(loss[k - 1]), float(rho[k - 1]),
                        ks.tolist(), [round(float(x), 4) for x in loss[ks - 1]], note, alpha, power, lo, hi)


def choose_for_pool(cams, nodes: np.ndarray | None, index, tolerance_db: float = 0.5) -> BudgetChoice:
    """:func:`choose_budget` for the pool ``cams`` with its selection nodes [N, 3] and their pair
    ``index`` (the look-at depths of view medoids: :func:`curate.select.medoids.view_depths`); the
    capture's kind from its poses (:func:`curate.select.methods.capture_kind`)."""
    from curate.select.methods import capture_kind
    return choose_budget(*pool_views(cams, nodes, index), tolerance_db, capture_kind(cams)[0])


def pool_views(cams, nodes: np.ndarray | None, index) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c [K, 3], a [K, 3], depths [K]): the pool's views embedded as view medoids embed them, with
    the look-at depths of the nodes each camera sees (:func:`curate.select.medoids.view_depths`)."""
    from curate.select.medoids import embed, view_depths
    depths = view_depths(cams, nodes, index)
    c, a = embed(cams, depths)
    return c, a, depths
