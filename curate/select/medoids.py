"""View medoids: the subset whose views lie closest, on average, to the pool's views.

A held-out (or novel) view is rendered well when a training view sits near it: on real
captures, held-out PSNR tracks the distance from a held-out view to its nearest chosen
camera (issue 7). The held-out views of a capture come from the same path as the pool,
so the subset that minimises the *mean* distance from every pool view to its nearest
chosen view is what the test rewards: the k-medoids of the pool's views. Farthest-view
sampling (k-center) minimises the *largest* distance instead, and spends cameras on
outliers; the paper's energy looks at the scene's nodes, not at the views.

View distance (a metric, scale-covariant, no tuned weights)::

    d(i, j) = |c_i - c_j| + |a_i - a_j|,     a_i = c_i + D_i v_i

with c the camera centres, v the viewing directions and a_i the point the camera looks
at, D_i deep: the median depth of the scene nodes camera i observes (from the selection's
pair index). Two cameras side by side looking the same way are |dc| apart twice; one
camera turned by theta on the spot moves its look-at point by 2 D sin(theta / 2). A
camera that observes no node uses the median depth of all observations (or the
centres' spread when there are none).

Algorithm: farthest-point initialisation in ``d`` (deterministic: the first pick is the
view nearest the mean of the (c, a) embedding), then Voronoi iteration (assign every
pool view to its nearest medoid; move each medoid to the member with the least summed
distance to its cluster) until nothing moves. Each iteration lowers the summed distance
or stops, so it ends. ``initial`` cameras are fixed medoids. Memory is [K, B] for the
assignment and [m, m] per cluster, never [K, K].

Path weights (``MedoidsConfig.path_weights``): a video samples its path unevenly (the
walker lingers, speeds up; frames are dropped or held out), and the plain mean counts
frames. Weighing each view by the stretch of path it stands for (:func:`path_weights`)
makes the mean one along the path: a weighted k-medoids, same algorithm.
"""

from __future__ import annotations

import warnings

import numpy as np

from curate.select.baselines import farthest_point
from curate.core.cameras import Cameras
from curate.select.config import MedoidsConfig  # noqa: F401  (their home: the config)


def view_depths(cams: Cameras, nodes: np.ndarray | None, index=None) -> np.ndarray:
    """[K] look-at depth per camera: median distance to the nodes it observes (``index``
    pairs); cameras with none take the median over all pairs, or the centres' RMS spread."""
    K = len(cams)
    c = cams.centres
    spread = float(np.sqrt(np.mean(np.sum((c - c.mean(0)) ** 2, axis=1)))) if K else 0.0
    fallback = spread if spread > 0 else 1.0
    out = np.full(K, np.nan)
    if index is not None and nodes is not None and index.n_pairs > 0:
        node_of = np.repeat(np.arange(index.n_nodes), np.diff(index.indptr))      # [P]
        depth = np.linalg.norm(np.asarray(nodes, np.float64)[node_of] - c[index.cam.astype(np.int64)], axis=1)  # [P]
        for k in range(K):                                    # the index's camera-major view of its pairs
            seg = depth[index.cam_pos[index.cam_indptr[k]:index.cam_indptr[k + 1]]]
            if len(seg):
                out[k] = np.median(seg)
        fallback = float(np.median(depth)) if np.median(depth) > 0 else fallback
    out[~(out > 0)] = fallback
    return out


def embed(cams: Cameras, depths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centres [K, 3], look-at points [K, 3]) of the view distance."""
    c = cams.centres
    return c, c + np.asarray(depths, np.float64)[:, None] * cams.view_dirs


def view_distance(c: np.ndarray, a: np.ndarray, rows, cols) -> np.ndarray:
    """[len(rows), len(cols)] view distances between the embedded views ``rows`` and ``cols``."""
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    dc = np.linalg.norm(c[rows][:, None] - c[cols][None], axis=2)
    da = np.linalg.norm(a[rows][:, None] - a[cols][None], axis=2)
    return dc + da


def central_view(c: np.ndarray, a: np.ndarray) -> int:
    """The view nearest the mean of the (c, a) embedding [K, 6] (K >= 1): where farthest-point
    orders in the view distance start."""
    x = np.concatenate([c, a], axis=1)
    return int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1)))


class PathOrderWarning(UserWarning):
    """Path weights were asked for, but the views are not in capture order: plain weights."""


PATH_CAP = 4.0
"""A step between consecutive views counts for at most this many median steps (a cut in
the video, a second sequence)."""
PATH_ORDER_MIN = 0.6
"""Views count as a path when at least this share of them has its previous or next view
among its two nearest views (:func:`path_order_share`; ``research/holdout_holes.py`` prints
it: 0.78-0.98 on the office, the synthetic room and the object sets)."""
PATH_ORDER_SAMPLE = 512
"""The share is measured on this many views, evenly spread in capture order (all of a
smaller pool): memory and time [512, K]."""


def path_order_share(c: np.ndarray, a: np.ndarray) -> float:
    """Share of the embedded views ``c``, ``a`` [K, 3] (K >= 3) whose previous or next view is
    among their two nearest views, measured on ``PATH_ORDER_SAMPLE`` views evenly spread in
    order (all of a smaller pool). Memory [512, K]."""
    K = len(c)
    rows = np.unique(np.linspace(0, K - 1, min(K, PATH_ORDER_SAMPLE)).astype(np.int64))   # [r] views tested
    d = view_distance(c, a, rows, np.arange(K))                   # [r, K]
    d[np.arange(len(rows)), rows] = np.inf
    d2 = np.partition(d, 1, axis=1)[:, 1]                         # [r] the second-nearest distance
    prev = np.where(rows > 0, d[np.arange(len(rows)), np.maximum(rows - 1, 0)], np.inf)
    nxt = np.where(rows < K - 1, d[np.arange(len(rows)), np.minimum(rows + 1, K - 1)], np.inf)
    return float(np.mean(np.minimum(prev, nxt) <= d2))


def path_steps(c: np.ndarray, a: np.ndarray) -> np.ndarray | None:
    """[K-1] view distance between consecutive embedded views ``c``, ``a`` [K, 3] in capture
    order, in median steps, each capped at ``PATH_CAP``. None when the views do not form a
    path: fewer than 3, every step 0, or less than ``PATH_ORDER_MIN`` of the views with a
    neighbour in capture order among their two nearest views (:func:`path_order_share`).
    Memory [512, K]."""
    if len(c) < 3:
        return None
    step = np.linalg.norm(c[1:] - c[:-1], axis=1) + np.linalg.norm(a[1:] - a[:-1], axis=1)   # [K-1]
    med = float(np.median(step))
    if not (np.isfinite(med) and med > 0):
        return None
    if path_order_share(c, a) < PATH_ORDER_MIN:
        return None
    return np.minimum(step / med, PATH_CAP)


def path_weights(c: np.ndarray, a: np.ndarray) -> np.ndarray | None:
    """[K] weights, mean 1, of embedded views ``c``, ``a`` [K, 3] in capture order: half the
    view distance to the previous plus to the next view (a path end: its one step), each
    step capped at ``PATH_CAP`` median steps (:func:`path_steps`). None when the views do
    not form a path. Memory [512, K]."""
    step = path_steps(c, a)
    if step is None:
        return None
    K = len(c)
    w = np.empty(K)
    w[1:-1] = 0.5 * (step[:-1] + step[1:])
    w[0], w[-1] = step[0], step[-1]
    return w / w.mean()


def medoids_select(cams: Cameras, budget: int, cfg: MedoidsConfig = MedoidsConfig(), initial=(),
                   nodes: np.ndarray | None = None, index=None) -> tuple[list[int], list[float]]:
    """Choose ``budget`` more pool views (k-medoids with ``initial`` fixed).

    With ``cfg.path_weights`` each view's distance is weighted by :func:`path_weights` (the
    cameras in capture order): a weighted k-medoids.

    Returns (chosen, cost): chosen in the order of their farthest-point initialisation,
    cost the (weighted) mean view distance from a pool view to its medoid after each Voronoi
    iteration (the first entry: after initialisation).
    """
    K = len(cams)
    initial = [int(k) for k in dict.fromkeys(initial)]
    budget = min(max(0, int(budget)), K - len(initial))
    if budget <= 0:
        return [], []
    depths = (np.full(K, cfg.depth) if cfg.depth is not None else view_depths(cams, nodes, index))
    c, a = embed(cams, depths)
    allk = np.arange(K)

    # farthest-point initialisation in the view distance, from the view nearest the mean (c, a)
    chosen = farthest_point(K, budget, lambda k: view_distance(c, a, [k], allk)[0], central_view(c, a), initial)

    w = np.ones(K)                                                # [K] weight of each view's distance
    if cfg.path_weights:
        pw = path_weights(c, a)
        if pw is None:
            warnings.warn("medoids: the views are not in capture order (or too few); path weights ignored",
                          PathOrderWarning)
        else:
            w = pw

    # Voronoi iteration; medoids 0..len(initial)-1 are fixed
    med = np.array(initial + chosen, np.int64)
    n_fixed = len(initial)
    costs = []
    for _ in range(cfg.max_iters + 1):
        D = np.empty((K, len(med)))
        for s in range(0, K, 2048):                               # [K, B] in chunks
            D[s:s + 2048] = view_distance(c, a, allk[s:s + 2048], med)
        assign = np.argmin(D, axis=1)                             # ties: the earlier medoid
        costs.append(float((w * D[allk, assign]).mean()))
        if len(costs) > cfg.max_iters:
            break
        moved = False
        for j in range(n_fixed, len(med)):
            served = np.flatnonzero(assign == j)                 # the views medoid j serves
            if len(served) == 0:
                continue
            cand = served[~np.isin(served, np.delete(med, j))]   # never another medoid
            if len(cand) == 0:
                continue
            ws = w[served]                                       # [s]
            tot = view_distance(c, a, cand, served) @ ws          # [m] cluster cost with each as medoid
            cur = float(view_distance(c, a, [med[j]], served)[0] @ ws)
            if tot.min() < cur - 1e-12 * abs(cur):
                med[j] = cand[int(np.argmin(tot))]               # ties: the lowest index
                moved = True
        if not moved:
            break
    return [int(k) for k in med[n_fixed:]], costs
