"""How densely a subset covers the pool's views: the spacing curve behind ``--budget auto``.

A held-out view is rendered well when a training view sits close to it relative to how far
away the scene is (issue 7: held-out PSNR tracks the view distance of
:mod:`curate.select.medoids`). The *relative spacing* of a subset S of the pool is

    rho(S) = mean_i  min_{j in S} d(i, j) / D_i          (i over the pool)

with d the view distance of :func:`curate.select.medoids.view_distance` and D_i view i's
look-at depth: a dimensionless number, 0 when S is the whole pool. The *spacing curve*
rho(k), k = 1..K, is rho of the first k views of the farthest-point order in d (the order
view medoids start from): one pass, O(K^2) distances in rows of K, memory [K].

The pool's own spacing ``rho_nn`` (each view's nearest other view, relative to its depth) is
how far an unseen view on the same path is from the pool when every frame is kept.
"""

from __future__ import annotations

import numpy as np

from curate.select.medoids import view_distance


def spacing_curve(c: np.ndarray, a: np.ndarray, depths: np.ndarray, max_k: int | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    x = np.concatenate([c, a], axis=1)
    k = int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1)))
    nearest = np.full(K, np.inf)                                         # [K] distance to the nearest chosen view
    chosen = np.zeros(K, bool)
    order, rho = np.empty(n, np.int64), np.empty(n)
    for s in range(n):
        order[s], chosen[k] = k, True
        nearest = np.minimum(nearest, view_distance(c, a, [k], allk)[0])
        rho[s] = float(np.mean(nearest * inv))
        k = int(np.argmax(np.where(chosen, -1.0, nearest)))             # never a chosen view again; ties: lowest
    return order, rho


def pool_spacing(c: np.ndarray, a: np.ndarray, depths: np.ndarray, chunk: int = 1024) -> float:
    """rho_nn: the mean over the views ``c``, ``a`` [K, 3] of the view distance to their nearest
    other view, divided by their ``depths`` [K]. 0 for fewer than 2 views. Memory [chunk, K]."""
    K = len(c)
    if K < 2:
        return 0.0
    allk = np.arange(K)
    out = np.empty(K)
    for s in range(0, K, chunk):
        rows = allk[s:s + chunk]
        d = view_distance(c, a, rows, allk)                              # [r, K]
        d[np.arange(len(rows)), rows] = np.inf
        out[rows] = d.min(axis=1)
    return float(np.mean(out / np.asarray(depths, np.float64)))


def subset_spacing(c: np.ndarray, a: np.ndarray, depths: np.ndarray, subset, chunk: int = 2048) -> float:
    """rho(S) for the pool views ``c``, ``a`` [K, 3] and the pool indices ``subset``; memory [chunk, |S|]."""
    K = len(c)
    S = np.asarray(list(subset), np.int64)
    if K == 0 or len(S) == 0:
        return float("inf") if K else 0.0
    allk = np.arange(K)
    near = np.empty(K)
    for s in range(0, K, chunk):
        near[s:s + chunk] = view_distance(c, a, allk[s:s + chunk], S).min(axis=1)
    return float(np.mean(near / np.asarray(depths, np.float64)))
