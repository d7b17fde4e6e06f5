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
