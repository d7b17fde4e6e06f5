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


def folds_paired(diffs, level: float = 0.95) -> dict:
    """Per-view differences pooled over hold-out folds, with an interval that counts each fold as one draw.

    ``diffs``: one array per fold ([n_f] differences, one per held-out view of that fold). The mean is over
    every view (each counts once); its variance is the cluster-robust one, ``F / (F - 1) * sum_f (S_f - n_f
    m)^2 / N^2`` with ``S_f`` a fold's sum, so that what a fold's views share (its trainings' own noise, its
    random draw) widens the interval, with a t quantile on ``F - 1`` degrees of freedom. One fold: the per-view
    t interval (:func:`mean_ci`), which cannot see that noise. Non-finite differences are dropped, empty folds
    ignored. Returns {"mean", "lo", "hi", "n" (views), "n_folds", "dof", "level", "sd" (of the views)}.
    """
    folds = [np.asarray(d, float) for d in diffs]
    folds = [d[np.isfinite(d)] for d in folds]
    folds = [d for d in folds if d.size]
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


def decision(p: dict | None, margin: float) -> str | None:
    """What an interval ``p`` (``lo``, ``hi``) decides about a difference: 'ahead' (above 0), 'behind' (below
    0), 'level' (inside ``[-margin, margin]``), 'undecided' (none of these); None without an interval."""
    if not p or p.get("lo") is None or p.get("hi") is None:
        return None
    lo, hi = float(p["lo"]), float(p["hi"])
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "undecided"
    if lo > 0:
        return "ahead"
    if hi < 0:
        return "behind"
    return "level" if -margin <= lo and hi <= margin else "undecided"
