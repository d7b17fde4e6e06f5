"""Statistics for comparing selections honestly: hold-out split, paired differences with
confidence intervals, and summaries over seeds."""

from __future__ import annotations

import math

import numpy as np


def holdout_split(n: int, every: int = 14, offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(pool [n - t], held_out [t]) indices: every ``every``-th image (offset, offset + every,
    ...) is held out, as in the LLFF / mip-NeRF protocol. ``every <= 0`` holds out nothing.
    The offsets ``0 .. every - 1`` are the folds of a cross-validation: each image is held
    out by exactly one of them."""
    idx = np.arange(n)
    if every <= 0:
        return idx, idx[:0]
    if not 0 <= offset < every:
        raise ValueError(f"hold-out offset {offset} outside 0..{every - 1}")
    test = idx % every == offset
    return idx[~test], idx[test]


def t_quantile(p: float, dof: int) -> float:
    """Student-t quantile (scipy)."""
    from scipy.stats import t
    return float(t.ppf(p, dof))


def mean_ci(x, level: float = 0.95) -> dict:
    """Mean of ``x`` [n] with a two-sided t confidence interval; n < 2 gives an infinite interval."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    n = x.size
    if n == 0:
        return {"mean": float("nan"), "lo": float("nan"), "hi": float("nan"), "n": 0}
    m = float(x.mean())
    if n < 2:
        return {"mean": m, "lo": -math.inf, "hi": math.inf, "n": n}
    half = t_quantile(0.5 + level / 2, n - 1) * float(x.std(ddof=1)) / math.sqrt(n)
    return {"mean": m, "lo": m - half, "hi": m + half, "n": n}


def paired_difference(a, b, level: float = 0.95) -> dict:
    """Per-view paired difference ``a - b`` ([n] each, same views): mean and t CI.

    ``b`` may be [s, n] (several seeds of a baseline): each view's baseline is then its
    mean over seeds, as the per-view reference.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if b.ndim == 2:
        b = b.mean(0)
    if a.shape != b.shape:
        raise ValueError(f"paired views differ: {a.shape} vs {b.shape}")
    return mean_ci(a - b, level)


def seeds_summary(per_seed_means) -> dict:
    """Mean and sample std over seeds (std 0 for one seed)."""
    v = np.asarray(per_seed_means, float)
    return {"mean": float(v.mean()) if v.size else float("nan"),
            "std": float(v.std(ddof=1)) if v.size > 1 else 0.0, "n_seeds": int(v.size)}


def _finite_folds(diffs) -> list[np.ndarray]:
    """Each fold's differences as a float array without its non-finite values; empty folds left out."""
    folds = [np.asarray(d, float) for d in diffs]
    folds = [d[np.isfinite(d)] for d in folds]
    return [d for d in folds if d.size]


def folds_paired(diffs, level: float = 0.95) -> dict:
    """Per-view differences pooled over hold-out folds, with an interval that counts each fold as one draw.

    ``diffs``: one array per fold ([n_f] differences, one per held-out view of that fold). The mean is over
    every view (each counts once); its variance is the cluster-robust one, ``F / (F - 1) * sum_f (S_f - n_f
    m)^2 / N^2`` with ``S_f`` a fold's sum, so that what a fold's views share (its trainings' own noise, its
    random draw) widens the interval, with a t quantile on ``F - 1`` degrees of freedom. One fold: the per-view
    t interval (:func:`mean_ci`), which cannot see that noise. Non-finite differences are dropped, empty folds
    ignored. Returns {"mean", "lo", "hi", "n" (views), "n_folds", "dof", "level", "sd" (of the views)}.
    """
    folds = _finite_folds(diffs)
    F = len(folds)
    if F == 0:
        return {"mean": float("nan"), "lo": float("nan"), "hi": float("nan"), "n": 0, "n_folds": 0, "dof": 0,
                "level": level, "sd": float("nan")}
    x = np.concatenate(folds)
    sd = float(x.std(ddof=1)) if x.size > 1 else 0.0
    if F == 1:
        out = mean_ci(x, level)
        return {**out, "n_folds": 1, "dof": max(x.size - 1, 0), "level": level, "sd": sd}
    N, m = x.size, float(x.mean())
    s = np.array([d.sum() - d.size * m for d in folds])                  # [F] each fold's deviation
    se = math.sqrt(F / (F - 1) * float(np.sum(s * s))) / N
    half = t_quantile(0.5 + level / 2, F - 1) * se
    return {"mean": m, "lo": m - half, "hi": m + half, "n": int(N), "n_folds": F, "dof": F - 1, "level": level,
            "sd": sd}


def folds_moderated(diffs, level: float = 0.95, kappa0: float = 1.0, nu0: float = 0.0) -> dict:
    """Per-view differences pooled over hold-out folds, with an interval that uses what few folds give: the
    spread of the views within the folds, the spread between the folds, and a prior on how the two relate.

    The pooled mean's variance is written ``kappa * s_w^2 / N``: ``s_w^2`` the views' variance within their
    folds (``N - F`` degrees of freedom: many, even with two folds), ``kappa`` the *design effect* (how much more,
    or less, the mean varies than if every view were an independent draw: what a fold's views share, their
    trainings' noise and random draw, raises it; folds that interleave along one capture lower it). The folds
    estimate ``kappa`` (the cluster-robust variance of :func:`folds_paired` over ``s_w^2 / N``) with only
    ``F - 1`` degrees of freedom; the prior, ``kappa0`` worth ``nu0`` degrees of freedom (chosen against real
    captures and the null simulation: ``curate.evaluate.folds.KAPPA_PRIOR``), is pooled with it as a moderated
    variance is (a scaled inverse chi-square prior): ``V = (nu0 kappa0 s_w^2 / N + (F - 1) V_cr) / (nu0 + F - 1)``,
    with a t quantile on the Satterthwaite degrees of freedom of its two parts. ``nu0 = 0`` is
    :func:`folds_paired`'s interval (the folds alone); as folds are added the data outweigh the prior. One fold
    gives the prior's interval.

    ``diffs``: one array per fold. Non-finite differences are dropped, empty folds ignored. Returns
    :func:`folds_paired`'s keys (``dof`` now the Satterthwaite degrees of freedom, possibly fractional),
    ``kappa`` (the pooled design effect the interval used), ``kappa_folds`` (the folds' own estimate, None below
    two folds), ``sd_within`` (None without views to spread).
    """
    folds = _finite_folds(diffs)
    F = len(folds)
    if F == 0:
        return {"mean": float("nan"), "lo": float("nan"), "hi": float("nan"), "n": 0, "n_folds": 0, "dof": 0,
                "level": level, "sd": float("nan"), "kappa": None, "kappa_folds": None, "sd_within": None}
    x = np.concatenate(folds)
    N, m = x.size, float(x.mean())
    sd = float(x.std(ddof=1)) if N > 1 else 0.0
    dof_w = N - F
    if dof_w >= 2:
        ss = sum(float(np.sum((d - d.mean()) ** 2)) for d in folds)
        s2 = ss / dof_w
    elif N > 1:                       # one view a fold: the views' spread over all of them
        s2, dof_w = sd * sd, N - 1
    else:
        return {"mean": m, "lo": -math.inf, "hi": math.inf, "n": 1, "n_folds": F, "dof": 0, "level": level,
                "sd": sd, "kappa": None, "kappa_folds": None, "sd_within": None}
    v0 = s2 / N
    if F > 1:
        s = np.array([d.sum() - d.size * m for d in folds])
        v_cr = F / (F - 1) * float(np.sum(s * s)) / (N * N)
    else:
        v_cr = 0.0
    if nu0 + F - 1 <= 0:              # one fold and no prior: nothing says what the folds share
        out = mean_ci(x, level)
        return {**out, "n_folds": F, "dof": max(N - 1, 0), "level": level, "sd": sd, "kappa": None,
                "kappa_folds": None, "sd_within": math.sqrt(s2)}
    var, dof = moderated_variance(v0, v_cr, F, dof_w, kappa0, nu0)
    half = t_quantile(0.5 + level / 2, dof) * math.sqrt(var) if var > 0 else 0.0
    return {"mean": m, "lo": m - half, "hi": m + half, "n": int(N), "n_folds": F, "dof": round(float(dof), 2),
            "level": level, "sd": sd, "kappa": (var / v0) if v0 > 0 else None,
            "kappa_folds": (v_cr / v0) if (v0 > 0 and F > 1) else None, "sd_within": math.sqrt(s2)}


def moderated_variance(v0: float, v_cr: float, n_folds: int, dof_within: float, kappa0: float,
                       nu0: float) -> tuple[float, float]:
    """(variance, degrees of freedom) of :func:`folds_moderated`'s pooled mean: the prior's part ``nu0 kappa0 v0``
    and the folds' ``(F - 1) v_cr`` over ``nu0 + F - 1``, with the Satterthwaite degrees of freedom of the two
    (the prior's part also carries the uncertainty of ``v0``, on ``dof_within``)."""
    F = n_folds
    w = nu0 + F - 1
    a = nu0 * kappa0 * v0 / w if nu0 > 0 else 0.0
    b = (F - 1) * v_cr / w if F > 1 else 0.0
    var = a + b
    if var <= 0:
        return 0.0, float(w)
    dof_a = 1.0 / (1.0 / nu0 + 1.0 / max(dof_within, 1e-9)) if nu0 > 0 else math.inf
    den = (a * a / dof_a if a > 0 else 0.0) + (b * b / (F - 1) if b > 0 else 0.0)
    return var, (var * var / den if den > 0 else float(w))


DECIDED = ("ahead", "behind", "level", "resolved")
"""The decisions (:func:`decision`) at which the evaluation stops training a rival: all but 'undecided'."""


def decision(p: dict | None, margin: float, resolution: float = 0.0) -> str | None:
    """What an interval ``p`` (``lo``, ``hi``) decides about a difference: 'ahead' (above 0), 'behind' (below
    0), 'level' (inside ``[-margin, margin]``), 'resolved' (it holds 0 but is at most ``resolution`` wide on
    each side: the difference is measured that closely, its sign is not), 'undecided' (none of these); None
    without an interval."""
    if not p or p.get("lo") is None or p.get("hi") is None:
        return None
    lo, hi = float(p["lo"]), float(p["hi"])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "undecided"
    if lo > 0:
        return "ahead"
    if hi < 0:
        return "behind"
    if -margin <= lo and hi <= margin:
        return "level"
    return "resolved" if (hi - lo) / 2 <= resolution else "undecided"
