"""How densely a subset covers the pool's views: the spacing curve behind ``--budget auto``.

A held-out view is rendered well when a training view sits close to it relative to how far
away the scene is (issue 7: held-out PSNR tracks the view distance of
:mod:`curate.select.medoids`). The *relative spacing* of a subset S of the pool is

    rho(S) = mean_i  min_{j in S} d(i, j) / D_i          (i over the pool)

with d the view distance of :func:`curate.select.medoids.view_distance` and D_i view i's
look-at depth: a dimensionless number, 0 when S is the whole pool. The *spacing curve*
rho(k), k = 1..K, is rho of the first k views of the farthest-point order in d (the order
view medoids start from, :func:`curate.select.baselines.farthest_point`): one pass, O(K^2)
distances in rows of K, memory [K].
"""

from __future__ import annotations

import numpy as np

from curate.select.baselines import farthest_point
from curate.select.medoids import central_view, view_distance


def spacing_curve(c: np.ndarray, a: np.ndarray, depths: np.ndarray,
                  max_k: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(order [k], rho [k]) for embedded views ``c``, ``a`` [K, 3] with look-at ``depths`` [K] > 0.

    ``order``: the farthest-point order in the view distance, from the view nearest the mean
    of the (c, a) embedding (as :func:`curate.select.medoids.medoids_select` starts); ties go
    to the lowest index. ``rho[k - 1]``: the mean over the pool of the distance to the nearest
    of ``order[:k]``, divided by each view's depth. ``k`` runs to ``max_k`` (default K);
    rho is non-increasing and 0 once every distinct view is chosen. Empty for K = 0.
    """
    c, a = np.asarray(c, np.float64), np.asarray(a, np.float64)
    K = len(c)
    n = K if max_k is None else max(0, min(int(max_k), K))
    if K == 0 or n == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    inv = 1.0 / np.asarray(depths, np.float64)                           # [K]
    allk = np.arange(K)
    nearest = np.full(K, np.inf)                                         # [K] distance to the nearest chosen view
    rho = []

    def dist_to(k: int) -> np.ndarray:                                   # called once per pick, in order
        nonlocal nearest
        row = view_distance(c, a, [k], allk)[0]
        nearest = np.minimum(nearest, row)
        rho.append(float(np.mean(nearest * inv)))
        return row

    order = farthest_point(K, n, dist_to, central_view(c, a))
    return np.asarray(order, np.int64), np.asarray(rho)
